//! The CiA 402 master: start-up configuration over SDO, then one cycle per
//! servo tick (RPDOs, SYNC, TPDOs, controlword state machine, heartbeat
//! and process-data watchdogs). Runs in the CAN thread.

use std::sync::atomic::{AtomicBool, AtomicU16, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use super::bus::{Bus, BusError, Frame};
use super::cia402::{self, cw, obj, DriveState, SdoAnswer};
use super::{CanConfig, Mode};
use crate::clock::Clock;
use crate::fault::FaultCell;
use crate::{HalFault, MAX_JOINTS};

/// One servo tick's setpoints for the CAN thread.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TickMsg {
    /// Servo period, s.
    pub period: f64,
    /// Drives enabled.
    pub enable: bool,
    /// Commanded position per drive, mm.
    pub position: [f64; MAX_JOINTS],
    /// Commanded velocity per drive, mm/s.
    pub velocity: [f64; MAX_JOINTS],
}

/// What the CAN thread shares with the tick and observers.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    pub fault: FaultCell,
    pub stop: AtomicBool,
    /// The operator asked for a fault reset.
    pub reset: AtomicBool,
    /// Ticks handled.
    pub processed: AtomicU64,
    /// Measured position per drive, mm (f64 bits).
    pub position: [AtomicU64; MAX_JOINTS],
    /// Last statusword per drive.
    pub statusword: [AtomicU16; MAX_JOINTS],
}

struct Drive {
    node: u8,
    counts_per_mm: f64,
    /// Drive counts at the joint's initial position.
    count0: i64,
    initial: f64,
    statusword: u16,
    /// Position actual, counts (sign-extended from the TPDO's i32).
    actual: i64,
    /// Heartbeat last seen, host ns.
    heartbeat_ns: u64,
    /// Cycles since the last TPDO.
    missed_tpdo: u32,
    /// Velocity commanded over the current interval, mm/s (CSV).
    velocity: f64,
    /// Previous commanded position, mm (CSV).
    previous: Option<f64>,
    previous_error: f64,
    /// Cycles into a fault reset (None: no reset under way).
    resetting: Option<u32>,
}

/// The master's state, owned by the CAN thread.
pub(crate) struct Master {
    bus: Box<dyn Bus>,
    clock: Arc<dyn Clock>,
    shared: Arc<Shared>,
    mode: Mode,
    kp: f64,
    kd: f64,
    heartbeat_timeout_ns: u64,
    drives: Vec<Drive>,
    period_set: bool,
}

/// A PDO not received for this many cycles in a row is a fault.
const MAX_MISSED_TPDO: u32 = 3;
/// Cycles a fault reset may take before the fault stands.
const MAX_RESET_CYCLES: u32 = 10;

fn fault(joint: usize, reason: &'static str) -> HalFault {
    HalFault::Drive { joint, reason }
}

impl Master {
    /// Configure every drive (NMT pre-operational, SDO writes, PDO
    /// mapping, NMT start) and read its position. Blocking; start-up only.
    pub fn start(
        config: &CanConfig,
        initial: &[f64],
        bus: Box<dyn Bus>,
        clock: Arc<dyn Clock>,
        shared: Arc<Shared>,
    ) -> Result<Master, String> {
        let now = clock.now_ns();
        let mut m = Master {
            bus,
            clock,
            shared,
            mode: config.mode,
            kp: config.kp,
            kd: config.kd,
            heartbeat_timeout_ns: (config.heartbeat_timeout_ms * 1e6) as u64,
            drives: Vec::new(),
            period_set: false,
        };
        let sdo_timeout = Duration::from_secs_f64(config.sdo_timeout_ms * 1e-3);
        m.send(&Frame::new(cia402::NMT, &[cia402::NMT_PRE_OPERATIONAL, 0]))
            .map_err(|e| e.to_string())?;
        for (d, &p) in config.drives.iter().zip(initial) {
            let node = d.node;
            let mode = match config.mode {
                Mode::Csp => cia402::MODE_CSP,
                Mode::Csv => cia402::MODE_CSV,
            };
            let target = match config.mode {
                Mode::Csp => obj::TARGET_POSITION,
                Mode::Csv => obj::TARGET_VELOCITY,
            };
            let rpdo = (cia402::RPDO1_BASE + node as u16) as u32;
            let tpdo = (cia402::TPDO1_BASE + node as u16) as u32;
            let writes: [((u16, u8), u32, usize); 14] = [
                (obj::HEARTBEAT_TIME, config.heartbeat_ms as u32, 2),
                (obj::MODES_OF_OPERATION, mode as u8 as u32, 1),
                // A PDO is disabled while its mapping changes (CiA 301).
                (obj::RPDO1_COB_ID, rpdo | cia402::PDO_DISABLED, 4),
                ((obj::RPDO1_MAP, 0), 0, 1),
                (
                    (obj::RPDO1_MAP, 1),
                    cia402::map_entry(obj::CONTROLWORD, 0, 16),
                    4,
                ),
                ((obj::RPDO1_MAP, 2), cia402::map_entry(target, 0, 32), 4),
                ((obj::RPDO1_MAP, 0), 2, 1),
                (obj::RPDO1_TYPE, 1, 1),
                (obj::RPDO1_COB_ID, rpdo, 4),
                (obj::TPDO1_COB_ID, tpdo | cia402::PDO_DISABLED, 4),
                ((obj::TPDO1_MAP, 0), 0, 1),
                (
                    (obj::TPDO1_MAP, 1),
                    cia402::map_entry(obj::STATUSWORD, 0, 16),
                    4,
                ),
                (
                    (obj::TPDO1_MAP, 2),
                    cia402::map_entry(obj::POSITION_ACTUAL, 0, 32),
                    4,
                ),
                ((obj::TPDO1_MAP, 0), 2, 1),
            ];
            for (object, value, size) in writes
                .into_iter()
                .chain([(obj::TPDO1_TYPE, 1, 1), (obj::TPDO1_COB_ID, tpdo, 4)])
            {
                m.sdo_write(node, object, &value.to_le_bytes()[..size], sdo_timeout)?;
            }
            let actual = m.sdo_read(node, (obj::POSITION_ACTUAL, 0), sdo_timeout)?;
            let count0 = i32::from_le_bytes(actual) as i64;
            m.drives.push(Drive {
                node,
                counts_per_mm: d.counts_per_mm,
                count0,
                initial: p,
                statusword: 0,
                actual: count0,
                heartbeat_ns: now,
                missed_tpdo: 0,
                velocity: 0.0,
                previous: None,
                previous_error: 0.0,
                resetting: None,
            });
        }
        for d in &m.drives {
            let node = d.node;
            m.bus
                .send(&Frame::new(cia402::NMT, &[cia402::NMT_START, node]))
                .map_err(|e| e.to_string())?;
        }
        m.publish();
        Ok(m)
    }

    fn send(&mut self, f: &Frame) -> Result<(), BusError> {
        self.bus.send(f)
    }

    /// Wait for node's answer to an SDO request, skipping other traffic.
    fn sdo_wait(
        &mut self,
        node: u8,
        object: (u16, u8),
        timeout: Duration,
    ) -> Result<SdoAnswer, String> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            let f = self
                .bus
                .recv_timeout(left)
                .map_err(|e| e.to_string())?
                .ok_or_else(|| {
                    format!(
                        "node {node}: no SDO answer for object {:#06x}:{} within {} ms",
                        object.0,
                        object.1,
                        timeout.as_millis()
                    )
                })?;
            if f.id != cia402::SDO_TX_BASE + node as u16 {
                continue;
            }
            match cia402::sdo_answer(&f) {
                Some(SdoAnswer::Abort { object: o, code }) => {
                    return Err(format!(
                        "node {node}: the drive refused object {:#06x}:{} (SDO abort code {code:#010x})",
                        o.0, o.1
                    ))
                }
                Some(a) => return Ok(a),
                None => return Err(format!("node {node}: malformed SDO answer {:02x?}", f.bytes())),
            }
        }
    }

    fn sdo_write(
        &mut self,
        node: u8,
        object: (u16, u8),
        value: &[u8],
        timeout: Duration,
    ) -> Result<(), String> {
        self.send(&cia402::sdo_write(node, object, value))
            .map_err(|e| e.to_string())?;
        match self.sdo_wait(node, object, timeout)? {
            SdoAnswer::Written { object: o } if o == object => Ok(()),
            other => Err(format!("node {node}: unexpected SDO answer {other:?}")),
        }
    }

    fn sdo_read(
        &mut self,
        node: u8,
        object: (u16, u8),
        timeout: Duration,
    ) -> Result<[u8; 4], String> {
        self.send(&cia402::sdo_read(node, object))
            .map_err(|e| e.to_string())?;
        match self.sdo_wait(node, object, timeout)? {
            SdoAnswer::Read {
                object: o, data, ..
            } if o == object => Ok(data),
            other => Err(format!("node {node}: unexpected SDO answer {other:?}")),
        }
    }

    /// The interpolation period as CiA 402 0x60C2 wants it: value ·
    /// 10^index s, value a byte.
    fn interpolation_period(period: f64) -> Option<(u8, i8)> {
        (-6..=-3).rev().find_map(|index: i8| {
            let v = period / 10f64.powi(index as i32);
            (v.round() >= 1.0 && v.round() <= 255.0 && (v - v.round()).abs() < 1e-6)
                .then_some((v.round() as u8, index))
        })
    }

    /// Take in every frame waiting on the bus.
    fn drain(&mut self, now: u64) -> Result<(), HalFault> {
        while let Some(f) = self.bus.try_recv().map_err(|_| HalFault::Link {
            reason: "the CAN interface failed (bus off or link down)",
        })? {
            let (base, node) = (f.id & !0x7F, (f.id & 0x7F) as u8);
            let Some(j) = self.drives.iter().position(|d| d.node == node) else {
                continue;
            };
            let d = &mut self.drives[j];
            match base {
                cia402::TPDO1_BASE if f.len == 6 => {
                    d.statusword = u16::from_le_bytes([f.data[0], f.data[1]]);
                    d.actual =
                        i32::from_le_bytes([f.data[2], f.data[3], f.data[4], f.data[5]]) as i64;
                    d.missed_tpdo = 0;
                }
                cia402::HEARTBEAT_BASE if f.len == 1 => {
                    d.heartbeat_ns = now;
                    if f.data[0] != cia402::STATE_OPERATIONAL {
                        return Err(fault(j, "the drive left the NMT operational state"));
                    }
                }
                cia402::EMCY_BASE if f.len == 8 && (f.data[0] != 0 || f.data[1] != 0) => {
                    return Err(fault(j, "the drive sent an emergency (EMCY) message"));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// One servo cycle.
    pub fn cycle(&mut self, msg: &TickMsg) -> Result<(), HalFault> {
        let now = self.clock.now_ns();
        if !self.period_set {
            // The servo period is known only now; tell the drives (CSP and
            // CSV interpolate over it).
            let (value, index) = Self::interpolation_period(msg.period).ok_or(HalFault::Link {
                reason: "the servo period cannot be expressed as a CiA 402 interpolation period",
            })?;
            let t = Duration::from_millis(500);
            for j in 0..self.drives.len() {
                let node = self.drives[j].node;
                self.sdo_write(node, obj::INTERPOLATION_PERIOD, &[value], t)
                    .and_then(|()| {
                        self.sdo_write(node, obj::INTERPOLATION_INDEX, &[index as u8], t)
                    })
                    .map_err(|_| fault(j, "the drive refused the interpolation period (0x60C2)"))?;
            }
            self.period_set = true;
        }
        self.drain(now)?;
        let reset = self.shared.reset.swap(false, Ordering::AcqRel);
        for (j, d) in self.drives.iter_mut().enumerate() {
            if now.saturating_sub(d.heartbeat_ns) > self.heartbeat_timeout_ns {
                return Err(fault(
                    j,
                    "heartbeat lost (no heartbeat within heartbeat_timeout_ms)",
                ));
            }
            d.missed_tpdo += 1;
            if d.missed_tpdo > MAX_MISSED_TPDO {
                return Err(fault(j, "no process data (TPDO) from the drive"));
            }
            if reset && DriveState::from_statusword(d.statusword) == DriveState::Fault {
                d.resetting = Some(0);
            }
        }
        let period = msg.period;
        for j in 0..self.drives.len() {
            let state = DriveState::from_statusword(self.drives[j].statusword);
            let d = &mut self.drives[j];
            let actual_mm = d.initial + (d.actual - d.count0) as f64 / d.counts_per_mm;
            let controlword = match (state, d.resetting) {
                (DriveState::Fault, None) => {
                    return Err(fault(j, "the drive reports a fault (statusword)"));
                }
                (DriveState::Fault, Some(n)) if n >= MAX_RESET_CYCLES => {
                    return Err(fault(j, "the drive stays in fault after a fault reset"));
                }
                (DriveState::Fault, Some(n)) => {
                    // Fault reset acts on a rising edge of bit 7: low, high, low...
                    d.resetting = Some(n + 1);
                    if n % 2 == 0 {
                        cw::DISABLE_VOLTAGE
                    } else {
                        cw::FAULT_RESET
                    }
                }
                (s, _) => {
                    d.resetting = None;
                    if msg.enable {
                        s.towards_enabled()
                    } else {
                        cw::SHUTDOWN
                    }
                }
            };
            let enabled = state == DriveState::OperationEnabled && msg.enable;
            let target: i32 = match self.mode {
                Mode::Csp => {
                    let mm = if enabled { msg.position[j] } else { actual_mm };
                    (d.count0 as f64 + (mm - d.initial) * d.counts_per_mm).round() as i32
                }
                Mode::Csv => {
                    let v = if enabled {
                        // Position at this SYNC: last measured plus the
                        // velocity commanded since (the TPDO is one cycle old).
                        let predicted = actual_mm + d.velocity * period;
                        let start = d.previous.unwrap_or(msg.position[j]);
                        let error = start - predicted;
                        let feedforward = (msg.position[j] - start) / period;
                        let v = feedforward
                            + self.kp * error
                            + self.kd * (error - d.previous_error) / period;
                        d.previous_error = error;
                        v
                    } else {
                        d.previous_error = 0.0;
                        0.0
                    };
                    d.velocity = v;
                    d.previous = Some(msg.position[j]);
                    (v * d.counts_per_mm).round() as i32
                }
            };
            let mut data = [0u8; 6];
            data[..2].copy_from_slice(&controlword.to_le_bytes());
            data[2..].copy_from_slice(&target.to_le_bytes());
            let f = Frame::new(cia402::RPDO1_BASE + d.node as u16, &data);
            self.bus.send(&f).map_err(|_| HalFault::Link {
                reason: "the CAN interface failed (bus off or link down)",
            })?;
        }
        self.bus
            .send(&Frame::new(cia402::SYNC, &[]))
            .map_err(|_| HalFault::Link {
                reason: "the CAN interface failed (bus off or link down)",
            })?;
        self.publish();
        Ok(())
    }

    fn publish(&self) {
        for (j, d) in self.drives.iter().enumerate() {
            let mm = d.initial + (d.actual - d.count0) as f64 / d.counts_per_mm;
            self.shared.position[j].store(mm.to_bits(), Ordering::Relaxed);
            self.shared.statusword[j].store(d.statusword, Ordering::Relaxed);
        }
    }

    /// On a fault: switch every drive's power off (best effort), and keep
    /// reading the bus so the feedback stays current.
    pub fn shutdown(&mut self) {
        let now = self.clock.now_ns();
        let _ = self.drain(now);
        self.publish();
        for d in &self.drives {
            let mut data = [0u8; 6];
            data[..2].copy_from_slice(&cw::SHUTDOWN.to_le_bytes());
            data[2..].copy_from_slice(&((d.actual) as i32).to_le_bytes());
            let _ = self
                .bus
                .send(&Frame::new(cia402::RPDO1_BASE + d.node as u16, &data));
        }
        let _ = self.bus.send(&Frame::new(cia402::SYNC, &[]));
    }
}

/// The CAN thread: a cycle per queued tick; between ticks it parks (the
/// tick unparks it).
pub(crate) fn run(mut master: Master, mut ticks: rtrb::Consumer<TickMsg>) {
    let shared = master.shared.clone();
    while !shared.stop.load(Ordering::Relaxed) {
        let Ok(msg) = ticks.pop() else {
            std::thread::park_timeout(Duration::from_millis(5));
            continue;
        };
        if shared.fault.get().is_some() && !shared.reset.load(Ordering::Acquire) {
            // Faulted: keep the drives off until the operator resets.
            master.shutdown();
        } else if let Err(f) = master.cycle(&msg) {
            shared.fault.raise(f);
            master.shutdown();
        }
        shared.processed.fetch_add(1, Ordering::Release);
    }
}
