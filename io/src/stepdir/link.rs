//! The host end of the serial link: runs in its own thread, turns the
//! setpoints the servo tick queues into compressed step commands, keeps
//! them ahead of the MCU by the configured lead, and watches the link.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serialport::SerialPort;

use super::clock::{Clock, ClockEstimate};
use super::protocol::{
    ChannelTiming, Command, Deframer, Reply, Status, StepRun, MAX_CHANNELS, VERSION,
};
use super::stepgen::{check_run, count_at, crossings, next_run, LastStep};
use super::{StepDirConfig, TracePoint};
use crate::fault::FaultCell;
use crate::{HalConfigError, HalFault};

/// One servo tick's worth of setpoints, from `exchange` to the link thread.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TickMsg {
    /// Servo period, s.
    pub period: f64,
    /// Drives enabled.
    pub enable: bool,
    /// Position per channel, in steps.
    pub steps: [f64; MAX_CHANNELS],
}

/// State the link thread shares with the tick and with observers.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    pub fault: FaultCell,
    pub stop: AtomicBool,
    /// Setpoints the link thread has turned into steps.
    pub processed: AtomicU64,
    /// Frames sent and not yet answered, plus step commands waiting for
    /// queue room in the MCU.
    pub busy: AtomicUsize,
    /// Steps taken per channel as the MCU last reported.
    pub executed: [AtomicI64; MAX_CHANNELS],
    /// Step commands sent.
    pub commands: AtomicU64,
    /// Steps sent.
    pub steps: AtomicU64,
    /// Smallest lead seen: first step time of a command minus the
    /// estimated MCU clock when it was sent, ticks.
    pub min_lead: AtomicI64,
}

/// Per-channel step generator state.
struct Channel {
    steps_per_mm: f64,
    timing: ChannelTiming,
    /// Step counter (floor(u + ½) of the last setpoint).
    count: i64,
    /// Last setpoint, in steps.
    u: f64,
    /// Steps generated and not yet compressed, all in `pending_forward`.
    pending: Vec<u64>,
    pending_forward: bool,
    last: LastStep,
}

struct InFlight {
    seq: u8,
    sent_ns: u64,
    steps: bool,
}

/// The link: port, clock estimate, generators and flow control.
pub(crate) struct Link {
    port: Box<dyn SerialPort>,
    port_name: String,
    clock: Arc<dyn Clock>,
    shared: Arc<Shared>,
    trace: Option<Sender<TracePoint>>,
    est: ClockEstimate,
    clock_hz: u32,
    seq: u8,
    deframer: Deframer,
    inflight: VecDeque<InFlight>,
    outbox: VecDeque<Command>,
    free: u16,
    channels: Vec<Channel>,
    /// MCU time of the last setpoint, ticks (f64 so periods do not round).
    t_prev: Option<f64>,
    last_sync_ns: u64,
    lead_ticks: f64,
    /// Extra lead a run may be held back to grow longer before it is sent.
    hold_ticks: f64,
    tol_ticks: u64,
    ack_timeout_ns: u64,
    sync_interval_ns: u64,
}

/// How long `open` waits for each handshake answer.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(2);
/// How long a read waits for bytes before the loop does its other work.
const READ_TIMEOUT: Duration = Duration::from_millis(1);
/// Runs are held back at most this long for compression, s.
const HOLD_S: f64 = 0.004;

impl Link {
    /// Open the port, identify and configure the MCU and take a first clock
    /// sample. Blocks up to a few seconds; not for the servo thread.
    pub fn open(
        config: &StepDirConfig,
        initial_steps: &[f64],
        clock: Arc<dyn Clock>,
        shared: Arc<Shared>,
        trace: Option<Sender<TracePoint>>,
    ) -> Result<Link, HalConfigError> {
        let dev = |reason: String| HalConfigError::Device {
            backend: "stepdir",
            reason,
        };
        let port = serialport::new(&config.port, config.baud)
            .timeout(READ_TIMEOUT)
            .open()
            .map_err(|e| dev(format!("cannot open serial port {}: {e}", config.port)))?;
        // Answers to a previous connection's last frames may still wait in
        // the port: they would look like answers to this one's.
        port.clear(serialport::ClearBuffer::Input).map_err(|e| {
            dev(format!(
                "{}: cannot clear the input buffer: {e}",
                config.port
            ))
        })?;
        let mut link = Link {
            port,
            port_name: config.port.clone(),
            clock,
            shared,
            trace,
            est: ClockEstimate::new(1),
            clock_hz: 1,
            seq: 0,
            deframer: Deframer::default(),
            inflight: VecDeque::new(),
            outbox: VecDeque::new(),
            free: 0,
            channels: Vec::new(),
            t_prev: None,
            last_sync_ns: 0,
            lead_ticks: 0.0,
            hold_ticks: 0.0,
            tol_ticks: 0,
            ack_timeout_ns: (config.ack_timeout_ms * 1e6) as u64,
            sync_interval_ns: (config.sync_interval_ms * 1e6) as u64,
        };
        let port = config.port.clone();
        let Reply::Ident {
            version,
            channels,
            clock_hz,
            queue_slots,
        } = link.handshake(Command::Hello)?
        else {
            return Err(dev(format!("{port}: the MCU did not identify itself")));
        };
        if version != VERSION {
            return Err(dev(format!(
                "{port}: the MCU speaks protocol version {version}, kerf speaks {VERSION}"
            )));
        }
        if (channels as usize) < config.joints.len() || clock_hz == 0 {
            return Err(dev(format!(
                "{port}: the MCU has {channels} step channels at {clock_hz} Hz, {} are configured",
                config.joints.len()
            )));
        }
        link.clock_hz = clock_hz;
        link.est = ClockEstimate::new(clock_hz);
        link.free = queue_slots;
        let ticks = |us: f64| (us * clock_hz as f64 * 1e-6).ceil();
        link.lead_ticks = ticks(config.lead_ms * 1000.0);
        link.hold_ticks = ticks(HOLD_S * 1e6);
        // The edge is within tol + ½ tick of the crossing (see stepgen).
        link.tol_ticks = (config.max_error_us * clock_hz as f64 * 1e-6 - 0.5)
            .floor()
            .max(0.0) as u64;
        for (j, (jc, &u)) in config.joints.iter().zip(initial_steps).enumerate() {
            let timing = jc.timing(clock_hz).map_err(|reason| {
                dev(format!(
                    "joint entry for joint {}: {reason} at the MCU's {clock_hz} Hz",
                    jc.joint
                ))
            })?;
            link.handshake(Command::Config {
                channel: j as u8,
                invert_dir: jc.invert_direction,
                timing,
            })?;
            link.channels.push(Channel {
                steps_per_mm: jc.steps_per_mm,
                timing,
                count: count_at(u),
                u,
                pending: Vec::new(),
                pending_forward: true,
                last: LastStep::default(),
            });
        }
        let sent = link.clock.now_ns();
        link.handshake(Command::Clock { host_ns: sent })?;
        link.shared.min_lead.store(i64::MAX, Ordering::Relaxed);
        Ok(link)
    }

    /// Send `cmd` and wait for its answer (handshake only).
    fn handshake(&mut self, cmd: Command) -> Result<Reply, HalConfigError> {
        let dev = |reason: String| HalConfigError::Device {
            backend: "stepdir",
            reason,
        };
        let sent_ns = self.clock.now_ns();
        self.send(cmd, sent_ns)
            .map_err(|f| dev(format!("{}: {f}", self.port_name)))?;
        let deadline = Instant::now() + HANDSHAKE_TIMEOUT;
        while Instant::now() < deadline {
            match self.receive() {
                Ok(Some(reply)) => return Ok(reply),
                Ok(None) => {}
                Err(f) => return Err(dev(format!("{}: {f}", self.port_name))),
            }
        }
        Err(dev(format!(
            "{}: no answer from the MCU within {} s (is it connected and running the kerf step firmware?)",
            self.port_name,
            HANDSHAKE_TIMEOUT.as_secs()
        )))
    }

    fn send(&mut self, cmd: Command, now_ns: u64) -> Result<(), HalFault> {
        let frame = cmd.encode(self.seq);
        self.port
            .write_all(frame.bytes())
            .map_err(|_| HalFault::Link {
                reason: "cannot write to the serial port (port gone?)",
            })?;
        let steps = matches!(cmd, Command::Steps { .. });
        if steps {
            self.free = self.free.saturating_sub(1);
        }
        self.inflight.push_back(InFlight {
            seq: self.seq,
            sent_ns: now_ns,
            steps,
        });
        self.seq = self.seq.wrapping_add(1);
        Ok(())
    }

    /// Read what the port has (waiting up to the read timeout) and handle
    /// every complete reply; returns the last one.
    fn receive(&mut self) -> Result<Option<Reply>, HalFault> {
        let mut buf = [0u8; 256];
        let n = match self.port.read(&mut buf) {
            Ok(0) => {
                return Err(HalFault::Link {
                    reason: "the serial port closed (MCU gone)",
                })
            }
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(None),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => return Ok(None),
            Err(_) => {
                return Err(HalFault::Link {
                    reason: "cannot read from the serial port (port gone?)",
                })
            }
        };
        let now = self.clock.now_ns();
        let mut last = None;
        for &b in &buf[..n] {
            let Some(frame) = self.deframer.push(b) else {
                continue;
            };
            let frame = frame.map_err(|e| HalFault::Link { reason: e.reason() })?;
            let (seq, reply) = (frame.seq, Reply::decode(frame.kind, frame.payload));
            let reply = reply.map_err(|e| HalFault::Link { reason: e.reason() })?;
            let Some(sent) = self.inflight.pop_front() else {
                return Err(HalFault::Link {
                    reason: "the MCU answered a frame that was not sent",
                });
            };
            if sent.seq != seq {
                return Err(HalFault::Link {
                    reason: "the MCU's answer is out of sequence (lost frame)",
                });
            }
            match reply {
                Reply::Ack { free, status } => self.status(free, status)?,
                Reply::Clock {
                    clock,
                    free,
                    status,
                    positions,
                    channels,
                } => {
                    self.status(free, status)?;
                    if !self.est.sample(sent.sent_ns, now, clock) {
                        return Err(HalFault::Link {
                            reason: "the MCU clock rate is implausible (more than 1000 ppm off)",
                        });
                    }
                    for (cell, &p) in self
                        .shared
                        .executed
                        .iter()
                        .zip(&positions[..channels as usize])
                    {
                        cell.store(p as i64, Ordering::Relaxed);
                    }
                }
                Reply::Nak { reason } => {
                    return Err(HalFault::Link {
                        reason: reason.reason(),
                    })
                }
                Reply::Ident { .. } => {}
            }
            last = Some(reply);
        }
        Ok(last)
    }

    /// Take in an MCU status report answering a frame. `free` counts the
    /// slots free after that frame; step commands sent since are still
    /// in flight and will take slots.
    fn status(&mut self, free: u16, status: u8) -> Result<(), HalFault> {
        match Status::from_u8(status) {
            Some(Status::Ok) => {}
            Some(s) => return Err(HalFault::Link { reason: s.reason() }),
            None => {
                return Err(HalFault::Link {
                    reason: "the MCU reported an unknown status",
                })
            }
        }
        let later = self.inflight.iter().filter(|f| f.steps).count();
        self.free = free.saturating_sub(later as u16);
        Ok(())
    }

    /// Turn one tick's setpoints into steps (queued in `outbox`).
    fn take_tick(&mut self, msg: &TickMsg, now_mcu: f64) -> Result<(), HalFault> {
        let target = now_mcu + self.lead_ticks + self.hold_ticks;
        let Some(t_prev) = self.t_prev else {
            // The first setpoint fixes the time base; the joints are where
            // `open` put them.
            self.t_prev = Some(target);
            self.trace_point(target);
            return self.adopt(msg);
        };
        let moving = msg.enable && self.channels.iter().zip(&msg.steps).any(|(c, &u)| u != c.u);
        let t = if moving {
            t_prev + msg.period * 1e9 * self.est.rate()
        } else {
            // At rest the time base may slip freely: no steps fall between,
            // so stretching or shrinking the gap changes nothing but the
            // lead, which is set back to its target here.
            t_prev.max(target)
        };
        if !msg.enable {
            self.t_prev = Some(t);
            self.trace_point(t);
            return self.adopt(msg);
        }
        for (j, ch) in self.channels.iter_mut().enumerate() {
            let u = msg.steps[j];
            if u != ch.u {
                let pending = &mut ch.pending;
                let forward = &mut ch.pending_forward;
                let mut reversed = false;
                ch.count = crossings(ch.count, (t_prev, ch.u), (t, u), |s| {
                    if !pending.is_empty() && s.forward != *forward {
                        reversed = true;
                    }
                    if pending.is_empty() {
                        *forward = s.forward;
                    }
                    if !reversed {
                        pending.push(s.time);
                    }
                });
                if reversed {
                    // A move within one period never reverses (it is
                    // linear), but pending steps from earlier periods may
                    // run the other way: send them, then redo this period.
                    Self::flush_channel(j, ch, &mut self.outbox, self.tol_ticks, None)?;
                    let before = count_at(ch.u);
                    ch.count = crossings(before, (t_prev, ch.u), (t, u), |s| {
                        ch.pending_forward = s.forward;
                        ch.pending.push(s.time);
                    });
                }
                ch.u = u;
            }
        }
        self.t_prev = Some(t);
        self.trace_point(t);
        Ok(())
    }

    fn adopt(&mut self, msg: &TickMsg) -> Result<(), HalFault> {
        for (j, ch) in self.channels.iter_mut().enumerate() {
            Self::flush_channel(j, ch, &mut self.outbox, self.tol_ticks, None)?;
            ch.u = msg.steps[j];
            ch.count = count_at(ch.u);
        }
        Ok(())
    }

    fn trace_point(&self, t: f64) {
        if let Some(trace) = &self.trace {
            let mut positions = [0.0; MAX_CHANNELS];
            for (p, ch) in positions.iter_mut().zip(&self.channels) {
                *p = ch.u / ch.steps_per_mm;
            }
            // A dropped receiver only means nobody watches any more.
            let _ = trace.send(TracePoint { time: t, positions });
        }
    }

    /// Compress a channel's pending steps into commands. With `hold_after`
    /// set, the last (open) run is kept back while its first step is later
    /// than that time, so the next tick's steps can extend it.
    fn flush_channel(
        j: usize,
        ch: &mut Channel,
        outbox: &mut VecDeque<Command>,
        tol: u64,
        hold_after: Option<f64>,
    ) -> Result<(), HalFault> {
        let mut at = 0;
        while at < ch.pending.len() {
            let run = next_run(&ch.pending[at..], tol);
            let closes = at + run.count as usize == ch.pending.len();
            if closes && hold_after.is_some_and(|h| run.first as f64 > h) {
                break;
            }
            Self::queue_run(j, ch, outbox, run)?;
            at += run.count as usize;
        }
        ch.pending.drain(..at);
        Ok(())
    }

    fn queue_run(
        j: usize,
        ch: &mut Channel,
        outbox: &mut VecDeque<Command>,
        run: StepRun,
    ) -> Result<(), HalFault> {
        check_run(&mut ch.last, ch.pending_forward, &run, &ch.timing).map_err(|e| {
            HalFault::Drive {
                joint: j,
                reason: e.reason(),
            }
        })?;
        outbox.push_back(Command::Steps {
            channel: j as u8,
            forward: ch.pending_forward,
            run,
        });
        Ok(())
    }

    /// One pass of the link loop: read answers, take queued setpoints,
    /// send what is due, check deadlines.
    pub fn poll(&mut self, ticks: &mut rtrb::Consumer<TickMsg>) -> Result<(), HalFault> {
        self.receive()?;
        let now = self.clock.now_ns();
        let now_mcu = self.est.mcu_at(now);
        let mut taken = 0;
        while let Ok(msg) = ticks.pop() {
            self.take_tick(&msg, now_mcu)?;
            taken += 1;
        }
        // Hold runs back only while they are comfortably ahead of the lead.
        let hold = now_mcu + self.lead_ticks + self.hold_ticks / 2.0;
        for (j, ch) in self.channels.iter_mut().enumerate() {
            Self::flush_channel(j, ch, &mut self.outbox, self.tol_ticks, Some(hold))?;
        }
        while self.free > 0 {
            let Some(cmd) = self.outbox.pop_front() else {
                break;
            };
            if let Command::Steps { run, .. } = cmd {
                let lead = run.first as i64 - now_mcu as i64;
                self.shared.min_lead.fetch_min(lead, Ordering::Relaxed);
                self.shared.commands.fetch_add(1, Ordering::Relaxed);
                self.shared
                    .steps
                    .fetch_add(run.count as u64, Ordering::Relaxed);
            }
            self.send(cmd, now)?;
        }
        if now.saturating_sub(self.last_sync_ns) >= self.sync_interval_ns {
            self.last_sync_ns = now;
            self.send(Command::Clock { host_ns: now }, now)?;
        }
        if let Some(oldest) = self.inflight.front() {
            if now.saturating_sub(oldest.sent_ns) > self.ack_timeout_ns {
                return Err(HalFault::Link {
                    reason: "no acknowledgement from the MCU within ack_timeout_ms",
                });
            }
        }
        // Published last, so an observer that sees `processed` reach a
        // tick also sees `busy` as this pass left it.
        self.shared
            .busy
            .store(self.inflight.len() + self.outbox.len(), Ordering::Release);
        self.shared.processed.fetch_add(taken, Ordering::Release);
        Ok(())
    }

    /// After a fault: tell the MCU to stop (best effort; the port may be
    /// gone).
    pub fn stop_mcu(&mut self) {
        let now = self.clock.now_ns();
        let _ = self.send(Command::Stop, now);
        let _ = self.port.flush();
        // Take in the answers still coming (briefly; the MCU may be gone),
        // so that a reconnection does not read them as its own.
        let deadline = Instant::now() + Duration::from_millis(100);
        while !self.inflight.is_empty() && Instant::now() < deadline {
            if let Err(HalFault::Link { .. }) = self.receive_any() {
                break;
            }
        }
    }

    /// Read answers without judging them (after a fault).
    fn receive_any(&mut self) -> Result<(), HalFault> {
        let mut buf = [0u8; 256];
        let n = match self.port.read(&mut buf) {
            Ok(0) => return Err(HalFault::Link { reason: "closed" }),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(()),
            Err(_) => {
                return Err(HalFault::Link {
                    reason: "read error",
                })
            }
        };
        for &b in &buf[..n] {
            if let Some(Ok(frame)) = self.deframer.push(b) {
                if self.inflight.front().is_some_and(|f| f.seq == frame.seq) {
                    self.inflight.pop_front();
                }
            }
        }
        Ok(())
    }
}

/// The link thread's body: poll until told to stop or a fault.
pub(crate) fn run(mut link: Link, mut ticks: rtrb::Consumer<TickMsg>) {
    let shared = link.shared.clone();
    while !shared.stop.load(Ordering::Relaxed) {
        if let Err(fault) = link.poll(&mut ticks) {
            shared.fault.raise(fault);
            link.stop_mcu();
            break;
        }
    }
    if !shared.stop.load(Ordering::Relaxed) {
        return;
    }
    // Orderly shutdown: stop the MCU so it does not run out of steps mid-move.
    link.stop_mcu();
}
