//! The `can` backend: CiA 402 servo drives on a CANopen bus.
//!
//! At start-up the master puts the drives in NMT pre-operational, writes
//! their configuration over SDO (heartbeat time, mode of operation, PDO
//! mapping), reads each drive's position and starts them (NMT start). Then,
//! once per servo tick, the CAN thread sends each drive an RPDO (controlword
//! 0x6040 and target position 0x607A in cyclic synchronous position mode,
//! or target velocity 0x60FF in cyclic synchronous velocity mode with the
//! position loop closed here) followed by SYNC; the drives answer with a
//! TPDO (statusword 0x6041, position actual 0x6064). The controlword walks
//! each drive through shutdown → switch on → enable operation, and the
//! operator's reset ([`Hal::clear_fault`]) through fault reset.
//!
//! A drive fault (statusword or EMCY), a heartbeat older than
//! `heartbeat_timeout_ms`, missing process data or a failing interface
//! latch a fault: the drives are switched off (controlword shutdown) and
//! stay off until the reset.
//!
//! The bus is the [`bus::Bus`] trait: [`bus::SocketCan`] on Linux SocketCAN
//! interfaces, or [`sim::SimBus`], in-process simulated drives (`bus =
//! "sim"`), which the tests use because this machine's kernel has no CAN.

pub mod bus;
pub mod cia402;
mod master;
pub mod sim;

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::thread::JoinHandle;

use serde::Deserialize;

use self::bus::Bus;
use self::master::{Master, Shared, TickMsg};
use crate::clock::{Clock, Monotonic};
use crate::{Feedback, Hal, HalConfigError, HalFault, Setpoints, MAX_JOINTS};

/// Drive operating mode.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Cyclic synchronous position (mode 8): the drive closes the position
    /// loop on target position 0x607A.
    #[default]
    Csp,
    /// Cyclic synchronous velocity (mode 9): kerf closes the position loop
    /// (PD with velocity feedforward) and sends target velocity 0x60FF.
    Csv,
}

/// Which bus the drives are on.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum BusKind {
    /// A Linux SocketCAN interface (`interface`).
    #[default]
    Socketcan,
    /// Simulated ideal drives in this process (offline runs and tests).
    Sim,
}

/// `[hal.can]`: the bus and its drives.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CanConfig {
    /// `socketcan` (default) or `sim`.
    #[serde(default)]
    pub bus: BusKind,
    /// SocketCAN interface name, e.g. `can0`.
    #[serde(default)]
    pub interface: String,
    /// `csp` (default) or `csv`.
    #[serde(default)]
    pub mode: Mode,
    /// Heartbeat period the drives are told to produce, ms.
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u16,
    /// A drive whose heartbeat is older than this is lost, ms.
    #[serde(default = "default_heartbeat_timeout_ms")]
    pub heartbeat_timeout_ms: f64,
    /// How long to wait for each SDO answer at start-up, ms.
    #[serde(default = "default_sdo_timeout_ms")]
    pub sdo_timeout_ms: f64,
    /// CSV position gain, 1/s (velocity per mm of following error).
    #[serde(default = "default_kp")]
    pub kp: f64,
    /// CSV derivative gain, s·(1/s) (velocity per mm/s of error change).
    #[serde(default)]
    pub kd: f64,
    /// `[[hal.can.drives]]`, one per joint.
    pub drives: Vec<DriveConfig>,
}

/// One `[[hal.can.drives]]` entry.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DriveConfig {
    /// Machine joint number (0-based).
    pub joint: usize,
    /// CANopen node id, 1 to 127.
    pub node: u8,
    /// Drive position increments per mm (per degree for rotary joints);
    /// target velocity is in increments per second.
    pub counts_per_mm: f64,
}

fn default_heartbeat_ms() -> u16 {
    20
}
fn default_heartbeat_timeout_ms() -> f64 {
    60.0
}
fn default_sdo_timeout_ms() -> f64 {
    200.0
}
fn default_kp() -> f64 {
    100.0
}

impl CanConfig {
    /// Check every value, naming the key of the first bad one.
    pub fn validate(&self) -> Result<(), HalConfigError> {
        let key = |k: &str, r: String| Err(HalConfigError::key(format!("can.{k}"), r));
        if self.bus == BusKind::Socketcan && self.interface.is_empty() {
            return key(
                "interface",
                "name the SocketCAN interface, e.g. \"can0\"".into(),
            );
        }
        if self.heartbeat_ms == 0 {
            return key(
                "heartbeat_ms",
                "drives must send heartbeats (at least 1 ms)".into(),
            );
        }
        // Written so that NaN fails too.
        if self
            .heartbeat_timeout_ms
            .partial_cmp(&(self.heartbeat_ms as f64))
            != Some(std::cmp::Ordering::Greater)
        {
            return key(
                "heartbeat_timeout_ms",
                format!(
                    "{} must exceed heartbeat_ms ({})",
                    self.heartbeat_timeout_ms, self.heartbeat_ms
                ),
            );
        }
        if !(self.sdo_timeout_ms > 0.0 && self.sdo_timeout_ms <= 10_000.0) {
            return key(
                "sdo_timeout_ms",
                format!("{} is out of range (0, 10000]", self.sdo_timeout_ms),
            );
        }
        if !(self.kp >= 0.0 && self.kp.is_finite()) {
            return key("kp", format!("{} is not a gain", self.kp));
        }
        if !(self.kd >= 0.0 && self.kd.is_finite()) {
            return key("kd", format!("{} is not a gain", self.kd));
        }
        if self.drives.is_empty() {
            return key("drives", "list at least one drive".into());
        }
        for (i, d) in self.drives.iter().enumerate() {
            if !(1..=127).contains(&d.node) {
                return key(
                    &format!("drives[{i}].node"),
                    format!("{} is not a node id (1 to 127)", d.node),
                );
            }
            if let Some(other) = self.drives[..i].iter().position(|o| o.node == d.node) {
                return key(
                    &format!("drives[{i}].node"),
                    format!("node {} is already drives[{other}]", d.node),
                );
            }
            if !(d.counts_per_mm.is_finite() && d.counts_per_mm != 0.0) {
                return key(
                    &format!("drives[{i}].counts_per_mm"),
                    format!("{} is not a usable scale", d.counts_per_mm),
                );
            }
        }
        Ok(())
    }
}

/// The `can` backend.
pub struct CanHal {
    shared: Arc<Shared>,
    ticks: rtrb::Producer<TickMsg>,
    thread: Option<JoinHandle<()>>,
    wake: std::thread::Thread,
    joints: usize,
    previous: [f64; MAX_JOINTS],
}

/// Ticks the servo may queue ahead of the CAN thread.
const TICK_QUEUE: usize = 256;

impl CanHal {
    /// Start the drives of `config` (in order) at joint positions `initial`
    /// (mm) on the configured bus.
    pub fn open(config: &CanConfig, initial: &[f64]) -> Result<CanHal, HalConfigError> {
        config.validate()?;
        let clock: Arc<dyn Clock> = Arc::new(Monotonic);
        let bus: Box<dyn Bus> = match config.bus {
            BusKind::Socketcan => {
                Box::new(bus::SocketCan::open(&config.interface).map_err(|e| {
                    HalConfigError::Device {
                        backend: "can",
                        reason: e.to_string(),
                    }
                })?)
            }
            BusKind::Sim => Box::new(sim::SimBus::new(
                config
                    .drives
                    .iter()
                    .map(|d| sim::SimDrive::new(d.node))
                    .collect(),
                clock.clone(),
            )),
        };
        CanHal::with_bus(config, initial, bus, clock)
    }

    /// Start the drives on a given bus, reading time from `clock`.
    pub fn with_bus(
        config: &CanConfig,
        initial: &[f64],
        bus: Box<dyn Bus>,
        clock: Arc<dyn Clock>,
    ) -> Result<CanHal, HalConfigError> {
        config.validate()?;
        if initial.len() != config.drives.len() {
            return Err(HalConfigError::key(
                "can.drives",
                format!(
                    "{} drives for {} joints",
                    config.drives.len(),
                    initial.len()
                ),
            ));
        }
        let shared = Arc::new(Shared::default());
        let master =
            Master::start(config, initial, bus, clock, shared.clone()).map_err(|reason| {
                HalConfigError::Device {
                    backend: "can",
                    reason,
                }
            })?;
        let (producer, consumer) = rtrb::RingBuffer::new(TICK_QUEUE);
        let thread = std::thread::Builder::new()
            .name("kerf-can".into())
            .spawn(move || master::run(master, consumer))
            .map_err(|e| HalConfigError::Device {
                backend: "can",
                reason: format!("cannot start the CAN thread: {e}"),
            })?;
        let mut previous = [0.0; MAX_JOINTS];
        previous[..initial.len()].copy_from_slice(initial);
        Ok(CanHal {
            shared,
            ticks: producer,
            wake: thread.thread().clone(),
            thread: Some(thread),
            joints: initial.len(),
            previous,
        })
    }

    /// Ticks the CAN thread has handled.
    pub fn processed(&self) -> u64 {
        self.shared.processed.load(Ordering::Acquire)
    }

    /// Last statusword of drive `i` (in joint order).
    pub fn statusword(&self, i: usize) -> u16 {
        self.shared.statusword[i].load(Ordering::Relaxed)
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<HalFault> {
        self.shared.fault.get()
    }
}

impl Hal for CanHal {
    fn name(&self) -> &str {
        "can"
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
        let mut msg = TickMsg {
            period,
            enable: out.enable,
            position: [0.0; MAX_JOINTS],
            velocity: [0.0; MAX_JOINTS],
        };
        for i in 0..self.joints {
            msg.position[i] = out.joints[i].position;
            msg.velocity[i] = out.joints[i].velocity;
            let p = f64::from_bits(self.shared.position[i].load(Ordering::Relaxed));
            feedback.joints[i].position = p;
            feedback.joints[i].velocity = (p - self.previous[i]) / period;
            self.previous[i] = p;
        }
        feedback.spindle_current = 0.0;
        let pushed = self.ticks.push(msg).is_ok();
        // Wakes the CAN thread: a futex wake, no allocation or lock.
        self.wake.unpark();
        if let Some(f) = self.shared.fault.get() {
            return Err(f);
        }
        if !pushed {
            let f = HalFault::Link {
                reason: "the CAN thread stopped taking setpoints",
            };
            self.shared.fault.raise(f);
            return Err(f);
        }
        Ok(())
    }

    fn clear_fault(&mut self) -> Result<(), HalFault> {
        // The CAN thread runs the drives' fault reset on its next cycles;
        // a fault that still stands is latched again there.
        self.shared.reset.store(true, Ordering::Release);
        self.shared.fault.clear();
        Ok(())
    }
}

impl Drop for CanHal {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.wake.unpark();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
