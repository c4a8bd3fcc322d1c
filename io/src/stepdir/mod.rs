//! The `stepdir` backend: stepper (or step/dir servo) drives fed by a
//! step-generator microcontroller on a serial line.
//!
//! The servo tick only queues its setpoints ([`Hal::exchange`] pushes them
//! into a lock-free queue and reads atomics). A link thread turns them into
//! step times ([`stepgen`]), compresses them into runs, and sends them over
//! the serial [`protocol`] with a lead of `lead_ms` ahead of the MCU's
//! clock, so a host stall shorter than the lead never starves motion. The
//! MCU answers every frame; a missing answer, a CRC error, a closed port
//! or an MCU status other than Ok latches a fault that stops motion until
//! [`Hal::clear_fault`].
//!
//! Feedback is open loop: the position is the commanded position rounded
//! to whole steps (where the motor will be, `lead_ms` later, when the MCU
//! takes the steps). The MCU's own step counters are in
//! [`StepDirHal::executed_steps`].
//!
//! [`mcu`] is a simulated MCU speaking the protocol; the `kerf-sim-mcu`
//! binary serves it on a pseudo-terminal.

pub mod clock;
mod link;
pub mod mcu;
pub mod protocol;
pub mod stepgen;

use std::sync::atomic::Ordering;
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::thread::JoinHandle;

use serde::Deserialize;

use self::clock::{Clock, Monotonic};
use self::link::{Link, Shared, TickMsg};
use self::protocol::{ChannelTiming, MAX_CHANNELS};
use self::stepgen::count_at;
use crate::{Feedback, Hal, HalConfigError, HalFault, Setpoints, MAX_JOINTS};

/// `[hal.stepdir]`: the serial link and its joints.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StepDirConfig {
    /// Serial device of the MCU, e.g. `/dev/ttyACM0`.
    pub port: String,
    /// Baud rate (ignored by USB CDC devices and pseudo-terminals).
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// How far ahead of the MCU clock steps are sent, ms (at least 50).
    #[serde(default = "default_lead_ms")]
    pub lead_ms: f64,
    /// A frame not answered within this long is a link fault, ms.
    #[serde(default = "default_ack_timeout_ms")]
    pub ack_timeout_ms: f64,
    /// How often the MCU clock is sampled, ms.
    #[serde(default = "default_sync_interval_ms")]
    pub sync_interval_ms: f64,
    /// Largest error of a step edge from the trajectory's crossing, µs
    /// (compression tolerance plus half a clock tick; at most 5).
    #[serde(default = "default_max_error_us")]
    pub max_error_us: f64,
    /// `[[hal.stepdir.joints]]`: one entry per joint, channel = entry
    /// order by joint number.
    pub joints: Vec<StepJointConfig>,
}

/// One `[[hal.stepdir.joints]]` entry.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StepJointConfig {
    /// Machine joint number (0-based).
    pub joint: usize,
    /// Steps per mm (per degree for rotary joints).
    pub steps_per_mm: f64,
    /// Reverse the direction pin.
    #[serde(default)]
    pub invert_direction: bool,
    /// Highest step rate the drive accepts, steps/s (0: limited only by
    /// pulse and space).
    #[serde(default)]
    pub max_step_rate: f64,
    /// Step pulse width, µs.
    #[serde(default = "default_pulse_us")]
    pub min_pulse_us: f64,
    /// Least time between pulses, µs.
    #[serde(default = "default_pulse_us")]
    pub min_space_us: f64,
    /// Least time from a direction change to the next step, µs.
    #[serde(default = "default_dir_us")]
    pub dir_setup_us: f64,
    /// Least time from a step pulse's end to a direction change, µs.
    #[serde(default = "default_dir_us")]
    pub dir_hold_us: f64,
}

fn default_baud() -> u32 {
    1_000_000
}
fn default_lead_ms() -> f64 {
    60.0
}
fn default_ack_timeout_ms() -> f64 {
    50.0
}
fn default_sync_interval_ms() -> f64 {
    10.0
}
fn default_max_error_us() -> f64 {
    2.0
}
fn default_pulse_us() -> f64 {
    2.0
}
fn default_dir_us() -> f64 {
    1.0
}

/// The least lead the protocol allows, ms.
pub const MIN_LEAD_MS: f64 = 50.0;
/// The largest edge error allowed, µs.
pub const MAX_EDGE_ERROR_US: f64 = 5.0;

impl StepDirConfig {
    /// Check every value, naming the key of the first bad one.
    pub fn validate(&self) -> Result<(), HalConfigError> {
        let key = |k: &str, r: String| Err(HalConfigError::key(format!("stepdir.{k}"), r));
        if self.port.is_empty() {
            return key("port", "give the MCU's serial device".into());
        }
        if !(self.lead_ms >= MIN_LEAD_MS && self.lead_ms <= 1000.0) {
            return key(
                "lead_ms",
                format!("{} is out of range {MIN_LEAD_MS} to 1000", self.lead_ms),
            );
        }
        if !(self.ack_timeout_ms >= 1.0 && self.ack_timeout_ms <= 10_000.0) {
            return key(
                "ack_timeout_ms",
                format!("{} is out of range 1 to 10000", self.ack_timeout_ms),
            );
        }
        if !(self.sync_interval_ms >= 1.0 && self.sync_interval_ms < self.ack_timeout_ms) {
            return key(
                "sync_interval_ms",
                format!(
                    "{} must be at least 1 and below ack_timeout_ms",
                    self.sync_interval_ms
                ),
            );
        }
        if !(self.max_error_us > 0.0 && self.max_error_us <= MAX_EDGE_ERROR_US) {
            return key(
                "max_error_us",
                format!(
                    "{} is out of range (0, {MAX_EDGE_ERROR_US}]",
                    self.max_error_us
                ),
            );
        }
        if self.joints.is_empty() || self.joints.len() > MAX_CHANNELS {
            return key(
                "joints",
                format!(
                    "list 1 to {MAX_CHANNELS} joints, found {}",
                    self.joints.len()
                ),
            );
        }
        for (i, j) in self.joints.iter().enumerate() {
            let k = |f: &str| format!("joints[{i}].{f}");
            if !(j.steps_per_mm.is_finite() && j.steps_per_mm.abs() > 0.0) {
                return key(
                    &k("steps_per_mm"),
                    format!("{} is not a usable scale", j.steps_per_mm),
                );
            }
            for (name, v) in [
                ("min_pulse_us", j.min_pulse_us),
                ("min_space_us", j.min_space_us),
                ("dir_setup_us", j.dir_setup_us),
                ("dir_hold_us", j.dir_hold_us),
            ] {
                if !(0.0..=1000.0).contains(&v) {
                    return key(&k(name), format!("{v} is out of range 0 to 1000"));
                }
            }
            if j.min_pulse_us <= 0.0 {
                return key(&k("min_pulse_us"), "a step pulse must have a width".into());
            }
            if !(j.max_step_rate >= 0.0 && j.max_step_rate.is_finite()) {
                return key(
                    &k("max_step_rate"),
                    format!("{} is not a rate", j.max_step_rate),
                );
            }
        }
        Ok(())
    }
}

impl StepJointConfig {
    /// The joint's timing in ticks of a `clock_hz` clock. The space is
    /// widened if `max_step_rate` asks for more than pulse + space.
    pub fn timing(&self, clock_hz: u32) -> Result<ChannelTiming, String> {
        let ticks = |us: f64| (us * clock_hz as f64 * 1e-6).ceil();
        let pulse = ticks(self.min_pulse_us);
        let mut space = ticks(self.min_space_us);
        if self.max_step_rate > 0.0 {
            let period = (clock_hz as f64 / self.max_step_rate).ceil();
            space = space.max(period - pulse);
        }
        let fit = |v: f64, name: &str| {
            if v <= u16::MAX as f64 {
                Ok(v as u16)
            } else {
                Err(format!(
                    "{name} does not fit the protocol's 16-bit tick count"
                ))
            }
        };
        Ok(ChannelTiming {
            pulse: fit(pulse, "min_pulse_us")?,
            space: fit(space, "min_space_us")?,
            dir_setup: fit(ticks(self.dir_setup_us), "dir_setup_us")?,
            dir_hold: fit(ticks(self.dir_hold_us), "dir_hold_us")?,
        })
    }
}

/// A setpoint's place in MCU time, reported to an observer (tests, plots):
/// the trajectory runs linearly between consecutive trace points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint {
    /// MCU time of the setpoint, ticks.
    pub time: f64,
    /// Joint positions, mm, in channel order.
    pub positions: [f64; MAX_CHANNELS],
}

/// Options for [`StepDirHal::open_with`].
#[derive(Clone)]
pub struct Options {
    /// The host clock the link uses for its time base and deadlines.
    pub clock: Arc<dyn Clock>,
    /// Where to report each setpoint's MCU time, if anywhere.
    pub trace: Option<Sender<TracePoint>>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            clock: Arc::new(Monotonic),
            trace: None,
        }
    }
}

/// The `stepdir` backend.
pub struct StepDirHal {
    config: StepDirConfig,
    options: Options,
    shared: Arc<Shared>,
    ticks: rtrb::Producer<TickMsg>,
    thread: Option<JoinHandle<()>>,
    /// Per joint: steps per mm and the last feedback position (mm).
    scale: [f64; MAX_JOINTS],
    held: [f64; MAX_JOINTS],
    joints: usize,
}

/// Setpoints the tick may queue ahead of the link thread: 1 s at 1 kHz.
const TICK_QUEUE: usize = 1024;

impl StepDirHal {
    /// Open the MCU link for `config.joints` (in order) starting at
    /// `initial` (mm), on the monotonic clock.
    pub fn open(config: &StepDirConfig, initial: &[f64]) -> Result<StepDirHal, HalConfigError> {
        StepDirHal::open_with(config, initial, Options::default())
    }

    /// [`StepDirHal::open`] with a chosen clock and an optional trace.
    pub fn open_with(
        config: &StepDirConfig,
        initial: &[f64],
        options: Options,
    ) -> Result<StepDirHal, HalConfigError> {
        config.validate()?;
        if initial.len() != config.joints.len() {
            return Err(HalConfigError::key(
                "stepdir.joints",
                format!(
                    "{} entries for {} joints",
                    config.joints.len(),
                    initial.len()
                ),
            ));
        }
        let mut scale = [0.0; MAX_JOINTS];
        let mut held = [0.0; MAX_JOINTS];
        for (i, j) in config.joints.iter().enumerate() {
            scale[i] = j.steps_per_mm;
            held[i] = count_at(initial[i] * j.steps_per_mm) as f64 / j.steps_per_mm;
        }
        let (ticks, thread, shared) = start(config, initial, &options)?;
        Ok(StepDirHal {
            config: config.clone(),
            options,
            shared,
            ticks,
            thread: Some(thread),
            scale,
            held,
            joints: initial.len(),
        })
    }

    /// Steps taken per joint as the MCU last reported them.
    pub fn executed_steps(&self, joint: usize) -> i64 {
        self.shared.executed[joint].load(Ordering::Relaxed)
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<HalFault> {
        self.shared.fault.get()
    }

    /// Link statistics.
    pub fn stats(&self) -> LinkStats {
        let min_lead = self.shared.min_lead.load(Ordering::Relaxed);
        LinkStats {
            processed: self.shared.processed.load(Ordering::Acquire),
            busy: self.shared.busy.load(Ordering::Acquire),
            commands: self.shared.commands.load(Ordering::Relaxed),
            steps: self.shared.steps.load(Ordering::Relaxed),
            min_lead_ticks: (min_lead != i64::MAX).then_some(min_lead),
        }
    }

    fn stop_thread(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Counters of the link thread.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkStats {
    /// Setpoints turned into steps.
    pub processed: u64,
    /// Frames awaiting an answer plus step commands awaiting MCU queue room.
    pub busy: usize,
    /// Step commands sent.
    pub commands: u64,
    /// Steps sent.
    pub steps: u64,
    /// Smallest lead of a step command over the estimated MCU clock when
    /// it was sent, ticks (None before the first).
    pub min_lead_ticks: Option<i64>,
}

type Started = (rtrb::Producer<TickMsg>, JoinHandle<()>, Arc<Shared>);

fn start(
    config: &StepDirConfig,
    initial: &[f64],
    options: &Options,
) -> Result<Started, HalConfigError> {
    let shared = Arc::new(Shared::default());
    let steps: Vec<f64> = config
        .joints
        .iter()
        .zip(initial)
        .map(|(j, &p)| p * j.steps_per_mm)
        .collect();
    let link = Link::open(
        config,
        &steps,
        options.clock.clone(),
        shared.clone(),
        options.trace.clone(),
    )?;
    let (producer, consumer) = rtrb::RingBuffer::new(TICK_QUEUE);
    let thread = std::thread::Builder::new()
        .name("kerf-stepdir".into())
        .spawn(move || link::run(link, consumer))
        .map_err(|e| HalConfigError::Device {
            backend: "stepdir",
            reason: format!("cannot start the link thread: {e}"),
        })?;
    Ok((producer, thread, shared))
}

impl Hal for StepDirHal {
    fn name(&self) -> &str {
        "stepdir"
    }

    fn joint_count(&self) -> usize {
        self.joints
    }

    fn exchange(
        &mut self,
        period: f64,
        out: &Setpoints,
        feedback: &mut Feedback,
    ) -> Result<(), HalFault> {
        if let Some(f) = self.shared.fault.get() {
            for (fb, &p) in feedback.joints.iter_mut().zip(&self.held[..self.joints]) {
                fb.position = p;
                fb.velocity = 0.0;
            }
            return Err(f);
        }
        let mut msg = TickMsg {
            period,
            enable: out.enable,
            steps: [0.0; MAX_CHANNELS],
        };
        for i in 0..self.joints {
            let scale = self.scale[i];
            let target = if out.enable {
                out.joints[i].position * scale
            } else {
                self.held[i] * scale
            };
            msg.steps[i] = target;
            let p = count_at(target) as f64 / scale;
            feedback.joints[i].velocity = (p - self.held[i]) / period;
            feedback.joints[i].position = p;
            self.held[i] = p;
        }
        feedback.spindle_current = 0.0;
        if self.ticks.push(msg).is_err() {
            let fault = HalFault::Link {
                reason: "the step link thread stopped taking setpoints",
            };
            self.shared.fault.raise(fault);
            return Err(fault);
        }
        Ok(())
    }

    fn clear_fault(&mut self) -> Result<(), HalFault> {
        if self.shared.fault.get().is_none() {
            return Ok(());
        }
        self.stop_thread();
        let initial: Vec<f64> = self.held[..self.joints].to_vec();
        match start(&self.config, &initial, &self.options) {
            Ok((ticks, thread, shared)) => {
                self.ticks = ticks;
                self.thread = Some(thread);
                self.shared = shared;
                Ok(())
            }
            Err(_) => Err(HalFault::Link {
                reason: "the MCU cannot be reached again (port gone or not answering)",
            }),
        }
    }
}

impl Drop for StepDirHal {
    fn drop(&mut self) {
        self.stop_thread();
    }
}
