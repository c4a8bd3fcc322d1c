//! Simulated CiA 402 drives on an in-process bus.
//!
//! [`SimDrive`] is a CANopen node with the objects the master uses: an SDO
//! server (expedited transfers), NMT states, heartbeat producer, one RPDO
//! and one TPDO with configurable mapping (checked as a real drive would:
//! mapping only while the PDO is disabled, only mappable objects), the
//! CiA 402 state machine driven by the controlword, and an ideal motor: in
//! CSP it is at the target at each SYNC, in CSV it moves at the target
//! velocity (times a gain error, to test the host's loop) between SYNCs.
//!
//! [`SimBus`] delivers each frame the master sends to every drive at once
//! and queues their answers, so a run is deterministic; heartbeats follow
//! the clock it is given.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::bus::{Bus, BusError, Frame};
use super::cia402::{self, obj, DriveState};
use crate::clock::Clock;

/// A simulated drive.
#[derive(Clone, Debug)]
pub struct SimDrive {
    node: u8,
    nmt: u8,
    state: DriveState,
    controlword: u16,
    heartbeat_ms: u16,
    next_heartbeat_ns: Option<u64>,
    mode: i8,
    period: (u8, i8),
    rpdo_cob: u32,
    rpdo_map: Vec<u32>,
    tpdo_cob: u32,
    tpdo_map: Vec<u32>,
    pending_rpdo: Option<Frame>,
    target_position: i32,
    target_velocity: i32,
    /// Position actual, increments (fractional for CSV integration).
    position: f64,
    syncs: u64,
    /// Real velocity / commanded velocity in CSV.
    pub velocity_gain: f64,
    /// Go to Fault (and send EMCY 0x2310, overcurrent) at this SYNC.
    pub fault_at_sync: Option<u64>,
    /// Stop sending anything from this SYNC on (cable pulled).
    pub silent_from_sync: Option<u64>,
    /// Stop only the heartbeat from this SYNC on.
    pub heartbeat_stops_at_sync: Option<u64>,
}

impl SimDrive {
    /// A drive with node id `node`, at position 0, in switch on disabled.
    pub fn new(node: u8) -> SimDrive {
        SimDrive {
            node,
            nmt: cia402::STATE_PRE_OPERATIONAL,
            state: DriveState::SwitchOnDisabled,
            controlword: 0,
            heartbeat_ms: 0,
            next_heartbeat_ns: None,
            mode: 0,
            period: (1, -3),
            rpdo_cob: cia402::PDO_DISABLED,
            rpdo_map: Vec::new(),
            tpdo_cob: cia402::PDO_DISABLED,
            tpdo_map: Vec::new(),
            pending_rpdo: None,
            target_position: 0,
            target_velocity: 0,
            position: 0.0,
            syncs: 0,
            velocity_gain: 1.0,
            fault_at_sync: None,
            silent_from_sync: None,
            heartbeat_stops_at_sync: None,
        }
    }

    /// Start at `counts` increments (an absolute encoder's reading).
    pub fn at(mut self, counts: i32) -> SimDrive {
        self.position = counts as f64;
        self.target_position = counts;
        self
    }

    /// The CiA 402 state.
    pub fn state(&self) -> DriveState {
        self.state
    }

    /// Position actual, increments.
    pub fn position(&self) -> i32 {
        self.position.round() as i32
    }

    fn silent(&self) -> bool {
        self.silent_from_sync.is_some_and(|s| self.syncs >= s)
    }

    fn statusword(&self) -> u16 {
        // Bit 9 remote; bit 4 voltage enabled when powered.
        let powered = matches!(
            self.state,
            DriveState::SwitchedOn | DriveState::OperationEnabled | DriveState::QuickStopActive
        );
        self.state.statusword() | 0x0200 | if powered { 0x10 } else { 0 }
    }

    fn abort(&self, index: u16, sub: u8, code: u32, out: &mut Vec<Frame>) {
        let mut d = [0u8; 8];
        d[0] = 0x80;
        d[1..3].copy_from_slice(&index.to_le_bytes());
        d[3] = sub;
        d[4..].copy_from_slice(&code.to_le_bytes());
        out.push(Frame::new(cia402::SDO_TX_BASE + self.node as u16, &d));
    }

    fn sdo(&mut self, f: &Frame, out: &mut Vec<Frame>) {
        let d = f.bytes();
        if d.len() != 8 {
            return;
        }
        let (index, sub) = (u16::from_le_bytes([d[1], d[2]]), d[3]);
        let value = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
        let reply_to = cia402::SDO_TX_BASE + self.node as u16;
        if d[0] == 0x40 {
            let (v, n): (u32, u8) = match (index, sub) {
                (obj::STATUSWORD, 0) => (self.statusword() as u32, 2),
                (obj::POSITION_ACTUAL, 0) => (self.position() as u32, 4),
                (0x6060, 0) => (self.mode as u8 as u32, 1),
                _ => return self.abort(index, sub, cia402::ABORT_NO_OBJECT, out),
            };
            let mut r = [0u8; 8];
            r[0] = 0x43 | ((4 - n) << 2);
            r[1..4].copy_from_slice(&d[1..4]);
            r[4..].copy_from_slice(&v.to_le_bytes());
            out.push(Frame::new(reply_to, &r));
            return;
        }
        if d[0] & 0xE3 != 0x23 {
            return self.abort(index, sub, 0x0504_0001, out);
        }
        let mappable_rx = [obj::CONTROLWORD, obj::TARGET_POSITION, obj::TARGET_VELOCITY];
        let mappable_tx = [obj::STATUSWORD, obj::POSITION_ACTUAL];
        let pdo_map = |cob: u32, map: &mut Vec<u32>, mappable: &[u16]| -> Result<(), u32> {
            if cob & cia402::PDO_DISABLED == 0 {
                // CiA 301: the mapping of an enabled PDO cannot change.
                return Err(0x0800_0022);
            }
            if sub == 0 {
                if value as usize > map.len() || value > 8 {
                    return Err(cia402::ABORT_RANGE);
                }
                map.truncate(value as usize);
            } else {
                if !mappable.contains(&((value >> 16) as u16)) {
                    return Err(cia402::ABORT_NOT_MAPPABLE);
                }
                // The objects mapped here are 16 or 32 bits, and a PDO
                // holds 64 bits at most.
                let bits = |e: &u32| e & 0xFF;
                let others: u32 = map
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != sub as usize - 1)
                    .map(|(_, e)| bits(e))
                    .sum();
                if !matches!(bits(&value), 16 | 32) || others + bits(&value) > 64 {
                    return Err(0x0604_0042);
                }
                let i = sub as usize - 1;
                if i > map.len() {
                    return Err(cia402::ABORT_RANGE);
                }
                if i == map.len() {
                    map.push(value);
                } else {
                    map[i] = value;
                }
            }
            Ok(())
        };
        let result = match (index, sub) {
            (0x1017, 0) => {
                self.heartbeat_ms = value as u16;
                self.next_heartbeat_ns = None;
                Ok(())
            }
            (0x6060, 0) => match value as i8 {
                cia402::MODE_CSP | cia402::MODE_CSV => {
                    self.mode = value as i8;
                    Ok(())
                }
                _ => Err(cia402::ABORT_RANGE),
            },
            (0x60C2, 1) => {
                self.period.0 = value as u8;
                Ok(())
            }
            (0x60C2, 2) => {
                self.period.1 = value as u8 as i8;
                Ok(())
            }
            (0x1400, 1) => {
                self.rpdo_cob = value;
                Ok(())
            }
            (0x1800, 1) => {
                self.tpdo_cob = value;
                Ok(())
            }
            (0x1400, 2) | (0x1800, 2) if value == 1 => Ok(()),
            (0x1400, 2) | (0x1800, 2) => Err(cia402::ABORT_RANGE),
            (0x1600, _) => pdo_map(self.rpdo_cob, &mut self.rpdo_map, &mappable_rx),
            (0x1A00, _) => pdo_map(self.tpdo_cob, &mut self.tpdo_map, &mappable_tx),
            _ => Err(cia402::ABORT_NO_OBJECT),
        };
        match result {
            Ok(()) => {
                let mut r = [0u8; 8];
                r[0] = 0x60;
                r[1..4].copy_from_slice(&d[1..4]);
                out.push(Frame::new(reply_to, &r));
            }
            Err(code) => self.abort(index, sub, code, out),
        }
    }

    fn apply_controlword(&mut self) {
        use DriveState::*;
        let c = self.controlword;
        let fault_reset_edge = c & 0x80 != 0;
        self.state = match self.state {
            Fault if fault_reset_edge => SwitchOnDisabled,
            Fault | FaultReactionActive => Fault,
            _ if c & 0x02 == 0 => SwitchOnDisabled,
            _ if c & 0x87 == 0x06 => ReadyToSwitchOn,
            ReadyToSwitchOn | SwitchedOn | OperationEnabled if c & 0x8F == 0x07 => SwitchedOn,
            SwitchedOn | OperationEnabled if c & 0x8F == 0x0F => OperationEnabled,
            ReadyToSwitchOn if c & 0x8F == 0x0F => SwitchedOn,
            s => s,
        };
    }

    fn on_sync(&mut self, out: &mut Vec<Frame>) {
        self.syncs += 1;
        if self.silent() {
            return;
        }
        let period = self.period.0 as f64 * 10f64.powi(self.period.1 as i32);
        if self.state == DriveState::OperationEnabled && self.mode == cia402::MODE_CSV {
            // The velocity latched at the previous SYNC acted until now.
            self.position += self.target_velocity as f64 * self.velocity_gain * period;
        }
        if let Some(f) = self.pending_rpdo.take() {
            let mut at = 0;
            for &entry in &self.rpdo_map {
                let bytes = ((entry & 0xFF) / 8) as usize;
                if at + bytes > f.len as usize {
                    // A PDO shorter than its mapping is ignored (CiA 301
                    // would raise an EMCY "PDO length error").
                    break;
                }
                let mut v = [0u8; 4];
                v[..bytes].copy_from_slice(&f.data[at..at + bytes]);
                let value = u32::from_le_bytes(v);
                match (entry >> 16) as u16 {
                    obj::CONTROLWORD => self.controlword = value as u16,
                    obj::TARGET_POSITION => self.target_position = value as i32,
                    obj::TARGET_VELOCITY => self.target_velocity = value as i32,
                    _ => {}
                }
                at += bytes;
            }
            self.apply_controlword();
        }
        if self.fault_at_sync == Some(self.syncs) {
            self.state = DriveState::Fault;
            // EMCY: error code 0x2310 (continuous overcurrent), error register bit 1.
            out.push(Frame::new(
                cia402::EMCY_BASE + self.node as u16,
                &[0x10, 0x23, 0x02, 0, 0, 0, 0, 0],
            ));
        }
        if self.state != DriveState::OperationEnabled {
            self.target_velocity = 0;
        } else if self.mode == cia402::MODE_CSP {
            // An ideal position loop: at the target by this SYNC.
            self.position = self.target_position as f64;
        }
        if self.tpdo_cob & cia402::PDO_DISABLED == 0 {
            let mut data = Vec::new();
            for &entry in &self.tpdo_map {
                let bytes = ((entry & 0xFF) / 8) as usize;
                let v: u32 = match (entry >> 16) as u16 {
                    obj::STATUSWORD => self.statusword() as u32,
                    obj::POSITION_ACTUAL => self.position() as u32,
                    _ => 0,
                };
                data.extend_from_slice(&v.to_le_bytes()[..bytes]);
            }
            out.push(Frame::new((self.tpdo_cob & 0x7FF) as u16, &data));
        }
    }

    /// Take a frame off the bus; answers go to `out`.
    pub fn receive(&mut self, f: &Frame, out: &mut Vec<Frame>) {
        let node = self.node as u16;
        if f.id == cia402::NMT && f.len == 2 && (f.data[1] == 0 || f.data[1] == self.node) {
            self.nmt = match f.data[0] {
                cia402::NMT_START => cia402::STATE_OPERATIONAL,
                cia402::NMT_PRE_OPERATIONAL => cia402::STATE_PRE_OPERATIONAL,
                _ => self.nmt,
            };
        } else if f.id == cia402::SDO_RX_BASE + node {
            if !self.silent() {
                self.sdo(f, out);
            }
        } else if self.nmt == cia402::STATE_OPERATIONAL {
            if f.id == cia402::SYNC {
                self.on_sync(out);
            } else if self.rpdo_cob & cia402::PDO_DISABLED == 0 && f.id as u32 == self.rpdo_cob {
                self.pending_rpdo = Some(*f);
            }
        }
    }

    /// Heartbeats due by host time `now_ns`.
    pub fn heartbeats(&mut self, now_ns: u64, out: &mut Vec<Frame>) {
        let stopped = self
            .heartbeat_stops_at_sync
            .is_some_and(|s| self.syncs >= s);
        if self.heartbeat_ms == 0 || self.silent() || stopped {
            return;
        }
        let step = self.heartbeat_ms as u64 * 1_000_000;
        let next = self.next_heartbeat_ns.get_or_insert(now_ns);
        while *next <= now_ns {
            out.push(Frame::new(
                cia402::HEARTBEAT_BASE + self.node as u16,
                &[self.nmt],
            ));
            *next += step;
        }
    }
}

/// An in-process bus with simulated drives on it.
pub struct SimBus {
    drives: Arc<Mutex<Vec<SimDrive>>>,
    clock: Arc<dyn Clock>,
    rx: VecDeque<Frame>,
    log: Arc<Mutex<Vec<Frame>>>,
}

impl SimBus {
    /// A bus with `drives`, heartbeats timed by `clock`.
    pub fn new(drives: Vec<SimDrive>, clock: Arc<dyn Clock>) -> SimBus {
        SimBus {
            drives: Arc::new(Mutex::new(drives)),
            clock,
            rx: VecDeque::new(),
            log: Arc::new(Mutex::new(Vec::new())),
        }
    }

    /// Every frame the master has sent, in order (for tests).
    pub fn log(&self) -> Arc<Mutex<Vec<Frame>>> {
        self.log.clone()
    }

    /// The drives (for tests to inspect and to inject faults).
    pub fn drives(&self) -> Arc<Mutex<Vec<SimDrive>>> {
        self.drives.clone()
    }

    fn heartbeats(&mut self) {
        let now = self.clock.now_ns();
        let mut out = Vec::new();
        for d in self.drives.lock().expect("sim drives").iter_mut() {
            d.heartbeats(now, &mut out);
        }
        self.rx.extend(out);
    }
}

impl Bus for SimBus {
    fn send(&mut self, frame: &Frame) -> Result<(), BusError> {
        self.log.lock().expect("sim bus log").push(*frame);
        let mut out = Vec::new();
        for d in self.drives.lock().expect("sim drives").iter_mut() {
            d.receive(frame, &mut out);
        }
        self.rx.extend(out);
        Ok(())
    }

    fn try_recv(&mut self) -> Result<Option<Frame>, BusError> {
        self.heartbeats();
        Ok(self.rx.pop_front())
    }

    fn recv_timeout(&mut self, _timeout: Duration) -> Result<Option<Frame>, BusError> {
        // Answers are queued when the request is sent: nothing comes later.
        self.try_recv()
    }
}
