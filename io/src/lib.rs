//! kerf-io: the hardware abstraction layer.
//!
//! A [`Hal`] backend is called once per servo tick: it takes the joint
//! [`Setpoints`] for this period and fills in the [`Feedback`] measured by the
//! hardware. Backends must be real-time safe in [`Hal::exchange`]: no
//! allocation, no locks, no blocking I/O (hardware that needs I/O buffers it
//! and talks to its device from its own thread).
//!
//! This crate depends on none of kerf's other crates: it deals only in joint
//! numbers, in the joint's own units (mm for linear drives).

pub mod sim;

use serde::Deserialize;

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
    pub joints: [JointCommand; MAX_JOINTS],
    /// Drives enabled (false: outputs off, motors free or braked).
    pub enable: bool,
}

impl Default for Setpoints {
    fn default() -> Self {
        Setpoints {
            joints: [JointCommand::default(); MAX_JOINTS],
            enable: false,
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
    pub joints: [JointFeedback; MAX_JOINTS],
    /// Spindle motor current, A (0 where not measured).
    pub spindle_current: f64,
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
    fn exchange(
        &mut self,
        period: f64,
        out: &Setpoints,
        feedback: &mut Feedback,
    ) -> Result<(), HalFault>;
}

/// Errors building a backend from its configuration.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HalConfigError {
    #[error("unknown HAL backend {0:?}; known backends: sim")]
    UnknownBackend(String),
    #[error("key `hal.{key}`: {reason}")]
    Key { key: String, reason: String },
}

/// The `[hal]` table of a machine description.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HalConfig {
    /// Backend name: `sim`.
    pub backend: String,
    /// Settings for the `sim` backend.
    #[serde(default)]
    pub sim: sim::SimConfig,
}

/// Build the backend a configuration names, for `joints` joints starting at
/// `initial` positions (mm).
pub fn build(config: &HalConfig, initial: &[f64]) -> Result<Box<dyn Hal>, HalConfigError> {
    match config.backend.as_str() {
        "sim" => Ok(Box::new(SimHal::new(&config.sim, initial)?)),
        other => Err(HalConfigError::UnknownBackend(other.to_string())),
    }
}
