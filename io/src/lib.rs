//! kerf-io: the hardware abstraction layer.
//!
//! A [`Hal`] backend is called once per servo tick: it takes the joint
//! [`Setpoints`] for this period and fills in the [`Feedback`] measured by the
//! hardware. Backends must be real-time safe in [`Hal::exchange`]: no
//! allocation, no locks, no blocking I/O (hardware that needs I/O buffers it
//! and talks to its device from its own thread, reached through lock-free
//! queues and atomics).
//!
//! Backends: [`sim`] (simulated drives), [`stepdir`] (step/dir through a
//! microcontroller on a serial line), [`can`] (CiA 402 drives over CAN).
//! The machine description wires each joint to one of them; [`build`]
//! returns one [`Hal`] that routes every joint to its backend. [`pins`]
//! holds the I/O pins M62–M68 act on; [`shm`] exports status and pins to
//! other processes over iceoryx2 shared memory.
//!
//! This crate depends on none of kerf's other crates: it deals only in joint
//! numbers, in the joint's own units (mm for linear drives).

pub mod can;
pub mod clock;
pub mod config;
pub mod pins;
pub mod shm;
pub mod sim;
pub mod stepdir;

mod fault;
mod route;

pub use config::{HalConfig, HalConfigError, ShmConfig};
pub use pins::{PinBank, PinConfig};
pub use sim::SimHal;

/// Largest number of joints a backend serves (equals kerf-motion's MAX_JOINTS).
pub const MAX_JOINTS: usize = 9;

/// What the controller asks of one joint for one servo period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointCommand {
    /// Commanded position at the end of the period, mm.
    pub position: f64,
    /// Commanded velocity, mm/s (feedforward for drives that take it).
    pub velocity: f64,
    /// Control effort from the host-side loop, in the drive's input units
    /// (e.g. volts for an analogue velocity drive). Backends that close the
    /// position loop themselves ignore it.
    pub effort: f64,
}

/// Setpoints for every joint for one period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoints {
    /// Per-joint commands; the first `joint_count` are used.
    pub joints: [JointCommand; MAX_JOINTS],
    /// Drives enabled (false: outputs off, motors free or braked).
    pub enable: bool,
    /// Commanded spindle speed, rpm (0: stopped).
    pub spindle_speed: f64,
}

impl Default for Setpoints {
    fn default() -> Self {
        Setpoints {
            joints: [JointCommand::default(); MAX_JOINTS],
            enable: false,
            spindle_speed: 0.0,
        }
    }
}

/// What the hardware measured for one joint.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointFeedback {
    /// Measured position, mm.
    pub position: f64,
    /// Measured velocity, mm/s.
    pub velocity: f64,
}

/// Feedback from the hardware for one period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Feedback {
    /// Per-joint feedback; the first `joint_count` are filled in.
    pub joints: [JointFeedback; MAX_JOINTS],
    /// Spindle motor current, A (0 where not measured).
    pub spindle_current: f64,
    /// Largest cutting force at the tool over the period, N, where a force
    /// sensor (a dynamometer, or the simulator) measures it; 0 otherwise.
    pub cutting_force: f64,
}

/// A hardware fault: motion must stop and the reason reach the operator.
/// Does not allocate.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum HalFault {
    /// The link to the hardware is lost (no answer, port gone, CRC errors).
    #[error("link lost: {reason}")]
    Link { reason: &'static str },
    /// A drive reports a fault.
    #[error("joint {joint} drive fault: {reason}")]
    Drive { joint: usize, reason: &'static str },
}

/// A hardware backend, exchanged with once per servo tick.
pub trait Hal: Send {
    /// Backend name, e.g. `sim`.
    fn name(&self) -> &str;

    /// Number of joints this backend drives.
    fn joint_count(&self) -> usize;

    /// Send this period's setpoints and read feedback. `period` is the servo
    /// period in seconds. Must not allocate, lock or block.
    ///
    /// Once a backend has returned a fault it keeps returning it, and moves
    /// nothing, until [`Hal::clear_fault`] (the operator's reset).
    fn exchange(
        &mut self,
        period: f64,
        out: &Setpoints,
        feedback: &mut Feedback,
    ) -> Result<(), HalFault>;

    /// The operator's fault reset: try to bring the hardware back after a
    /// fault. Returns the fault that still stands if the hardware cannot be
    /// brought back (e.g. the serial port is gone). The default, for
    /// backends that cannot fault, does nothing. Not real-time: may block
    /// while the hardware is re-initialised; call it with motion stopped.
    fn clear_fault(&mut self) -> Result<(), HalFault> {
        Ok(())
    }
}

/// Build the HAL a configuration describes for `initial.len()` joints
/// starting at `initial` positions (mm): each joint goes to the backend the
/// configuration wires it to (see [`HalConfig`]).
pub fn build(config: &HalConfig, initial: &[f64]) -> Result<Box<dyn Hal>, HalConfigError> {
    route::build(config, initial)
}
