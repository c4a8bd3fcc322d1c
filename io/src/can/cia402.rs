//! CANopen (CiA 301) and drive profile (CiA 402) definitions the master
//! and the simulated drive share: COB-IDs, SDO frames, object indices,
//! the statusword decoding and the controlword commands.

use super::bus::Frame;

/// NMT command COB-ID (from the master to all nodes).
pub const NMT: u16 = 0x000;
/// SYNC COB-ID.
pub const SYNC: u16 = 0x080;
/// Emergency messages: 0x080 + node.
pub const EMCY_BASE: u16 = 0x080;
/// First transmit PDO of a node: 0x180 + node.
pub const TPDO1_BASE: u16 = 0x180;
/// First receive PDO of a node: 0x200 + node.
pub const RPDO1_BASE: u16 = 0x200;
/// SDO server → client: 0x580 + node.
pub const SDO_TX_BASE: u16 = 0x580;
/// SDO client → server: 0x600 + node.
pub const SDO_RX_BASE: u16 = 0x600;
/// Heartbeat: 0x700 + node.
pub const HEARTBEAT_BASE: u16 = 0x700;

/// NMT command: start remote node (→ operational).
pub const NMT_START: u8 = 0x01;
/// NMT command: enter pre-operational.
pub const NMT_PRE_OPERATIONAL: u8 = 0x80;
/// Heartbeat state byte: operational.
pub const STATE_OPERATIONAL: u8 = 0x05;
/// Heartbeat state byte: pre-operational.
pub const STATE_PRE_OPERATIONAL: u8 = 0x7F;

/// Objects the master writes or maps (index, sub-index).
pub mod obj {
    /// Producer heartbeat time, ms (u16).
    pub const HEARTBEAT_TIME: (u16, u8) = (0x1017, 0);
    /// RPDO1 communication parameter: COB-ID (u32).
    pub const RPDO1_COB_ID: (u16, u8) = (0x1400, 1);
    /// RPDO1 transmission type (u8).
    pub const RPDO1_TYPE: (u16, u8) = (0x1400, 2);
    /// RPDO1 mapping (0x1600:0 count, :1.. entries).
    pub const RPDO1_MAP: u16 = 0x1600;
    /// TPDO1 communication parameter: COB-ID (u32).
    pub const TPDO1_COB_ID: (u16, u8) = (0x1800, 1);
    /// TPDO1 transmission type (u8; 1 = on every SYNC).
    pub const TPDO1_TYPE: (u16, u8) = (0x1800, 2);
    /// TPDO1 mapping.
    pub const TPDO1_MAP: u16 = 0x1A00;
    /// Controlword (u16).
    pub const CONTROLWORD: u16 = 0x6040;
    /// Statusword (u16).
    pub const STATUSWORD: u16 = 0x6041;
    /// Modes of operation (i8): 8 = CSP, 9 = CSV.
    pub const MODES_OF_OPERATION: (u16, u8) = (0x6060, 0);
    /// Position actual value (i32, increments).
    pub const POSITION_ACTUAL: u16 = 0x6064;
    /// Target position (i32, increments).
    pub const TARGET_POSITION: u16 = 0x607A;
    /// Target velocity (i32, increments/s).
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Interpolation time period: value (u8).
    pub const INTERPOLATION_PERIOD: (u16, u8) = (0x60C2, 1);
    /// Interpolation time period: index (i8, power of ten of seconds).
    pub const INTERPOLATION_INDEX: (u16, u8) = (0x60C2, 2);
}

/// A PDO mapping entry: object index, sub-index and bit length.
pub fn map_entry(index: u16, sub: u8, bits: u8) -> u32 {
    (index as u32) << 16 | (sub as u32) << 8 | bits as u32
}

/// Bit 31 of a PDO COB-ID: the PDO is disabled.
pub const PDO_DISABLED: u32 = 1 << 31;

/// Mode of operation 8: cyclic synchronous position.
pub const MODE_CSP: i8 = 8;
/// Mode of operation 9: cyclic synchronous velocity.
pub const MODE_CSV: i8 = 9;

/// Controlword commands (CiA 402 device control).
pub mod cw {
    /// Shutdown: → ready to switch on.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on: → switched on.
    pub const SWITCH_ON: u16 = 0x0007;
    /// Enable operation: → operation enabled.
    pub const ENABLE_OPERATION: u16 = 0x000F;
    /// Disable voltage: → switch on disabled.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Fault reset (on the rising edge of bit 7).
    pub const FAULT_RESET: u16 = 0x0080;
}

/// The CiA 402 drive state, decoded from the statusword.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveState {
    /// Not ready to switch on (initialising).
    NotReady,
    /// Switch on disabled.
    SwitchOnDisabled,
    /// Ready to switch on.
    ReadyToSwitchOn,
    /// Switched on.
    SwitchedOn,
    /// Operation enabled: the drive follows its targets.
    OperationEnabled,
    /// Quick stop active.
    QuickStopActive,
    /// Fault reaction active.
    FaultReactionActive,
    /// Fault.
    Fault,
}

impl DriveState {
    /// Decode a statusword (bits 0-3, 5 and 6).
    pub fn from_statusword(sw: u16) -> DriveState {
        match (sw & 0x4F, sw & 0x6F) {
            (0x00, _) => DriveState::NotReady,
            (0x40, _) => DriveState::SwitchOnDisabled,
            (0x0F, _) => DriveState::FaultReactionActive,
            (0x08, _) => DriveState::Fault,
            (_, 0x21) => DriveState::ReadyToSwitchOn,
            (_, 0x23) => DriveState::SwitchedOn,
            (_, 0x27) => DriveState::OperationEnabled,
            (_, 0x07) => DriveState::QuickStopActive,
            _ => DriveState::NotReady,
        }
    }

    /// The statusword bits of this state (other bits clear).
    pub fn statusword(self) -> u16 {
        match self {
            DriveState::NotReady => 0x00,
            DriveState::SwitchOnDisabled => 0x40,
            DriveState::ReadyToSwitchOn => 0x21,
            DriveState::SwitchedOn => 0x23,
            DriveState::OperationEnabled => 0x27,
            DriveState::QuickStopActive => 0x07,
            DriveState::FaultReactionActive => 0x0F,
            DriveState::Fault => 0x08,
        }
    }

    /// The controlword that moves a drive in this state one step towards
    /// operation enabled (or keeps it there).
    pub fn towards_enabled(self) -> u16 {
        match self {
            DriveState::SwitchOnDisabled | DriveState::NotReady => cw::SHUTDOWN,
            DriveState::ReadyToSwitchOn => cw::SWITCH_ON,
            DriveState::SwitchedOn | DriveState::OperationEnabled => cw::ENABLE_OPERATION,
            // Leave quick stop and fault through switch on disabled.
            DriveState::QuickStopActive => cw::DISABLE_VOLTAGE,
            DriveState::FaultReactionActive | DriveState::Fault => cw::DISABLE_VOLTAGE,
        }
    }
}

/// An expedited SDO download (write) request of `value` (1 to 4 bytes,
/// little-endian).
pub fn sdo_write(node: u8, (index, sub): (u16, u8), value: &[u8]) -> Frame {
    debug_assert!((1..=4).contains(&value.len()));
    // ccs = 1, e = 1, s = 1, n = 4 − size.
    let cmd = 0x23 | (((4 - value.len()) as u8) << 2);
    let mut data = [0u8; 8];
    data[0] = cmd;
    data[1..3].copy_from_slice(&index.to_le_bytes());
    data[3] = sub;
    data[4..4 + value.len()].copy_from_slice(value);
    Frame::new(SDO_RX_BASE + node as u16, &data)
}

/// An SDO upload (read) request.
pub fn sdo_read(node: u8, (index, sub): (u16, u8)) -> Frame {
    let mut data = [0u8; 8];
    data[0] = 0x40;
    data[1..3].copy_from_slice(&index.to_le_bytes());
    data[3] = sub;
    Frame::new(SDO_RX_BASE + node as u16, &data)
}

/// An SDO server's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SdoAnswer {
    /// Download (write) confirmed.
    Written {
        /// Object.
        object: (u16, u8),
    },
    /// Upload (read) data, little-endian, `len` bytes.
    Read {
        /// Object.
        object: (u16, u8),
        /// Value bytes.
        data: [u8; 4],
        /// Number of bytes.
        len: u8,
    },
    /// Transfer aborted with a CiA 301 abort code.
    Abort {
        /// Object.
        object: (u16, u8),
        /// Abort code (e.g. 0x06020000: object does not exist).
        code: u32,
    },
}

/// Decode an SDO server → client frame.
pub fn sdo_answer(frame: &Frame) -> Option<SdoAnswer> {
    let d = frame.bytes();
    if d.len() != 8 {
        return None;
    }
    let object = (u16::from_le_bytes([d[1], d[2]]), d[3]);
    let value = [d[4], d[5], d[6], d[7]];
    match d[0] {
        0x60 => Some(SdoAnswer::Written { object }),
        0x80 => Some(SdoAnswer::Abort {
            object,
            code: u32::from_le_bytes(value),
        }),
        c if c & 0xF3 == 0x43 => Some(SdoAnswer::Read {
            object,
            data: value,
            len: 4 - ((c >> 2) & 3),
        }),
        _ => None,
    }
}

/// SDO abort: object does not exist.
pub const ABORT_NO_OBJECT: u32 = 0x0602_0000;
/// SDO abort: value out of range.
pub const ABORT_RANGE: u32 = 0x0609_0030;
/// SDO abort: cannot map the object to a PDO.
pub const ABORT_NOT_MAPPABLE: u32 = 0x0604_0041;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statusword_states_round_trip_and_ignore_other_bits() {
        for s in [
            DriveState::NotReady,
            DriveState::SwitchOnDisabled,
            DriveState::ReadyToSwitchOn,
            DriveState::SwitchedOn,
            DriveState::OperationEnabled,
            DriveState::QuickStopActive,
            DriveState::FaultReactionActive,
            DriveState::Fault,
        ] {
            // Bit 4 (voltage enabled), bit 9 (remote), bit 10 (target
            // reached) do not change the state.
            assert_eq!(DriveState::from_statusword(s.statusword() | 0x0610), s);
        }
        // A typical enabled drive's statusword from a manual: 0x1237.
        assert_eq!(
            DriveState::from_statusword(0x1237),
            DriveState::OperationEnabled
        );
    }

    #[test]
    fn sdo_frames_have_the_cia301_layout() {
        // Writing 0x08 to 0x6060:00 of node 5: 2F 60 60 00 08 00 00 00 on 0x605.
        let f = sdo_write(5, (0x6060, 0), &[8]);
        assert_eq!(f.id, 0x605);
        assert_eq!(f.bytes(), &[0x2F, 0x60, 0x60, 0x00, 0x08, 0, 0, 0]);
        let f = sdo_write(1, (0x1017, 0), &100u16.to_le_bytes());
        assert_eq!(f.bytes()[0], 0x2B);
        let f = sdo_write(1, (0x1400, 1), &0x201u32.to_le_bytes());
        assert_eq!(f.bytes()[0], 0x23);
        let a = Frame::new(0x585, &[0x4B, 0x41, 0x60, 0, 0x37, 0x12, 0, 0]);
        assert_eq!(
            sdo_answer(&a),
            Some(SdoAnswer::Read {
                object: (0x6041, 0),
                data: [0x37, 0x12, 0, 0],
                len: 2
            })
        );
    }
}
