//! The `[hal]` table of a machine description: which backend drives which
//! joint, and each backend's settings.
//!
//! ```toml
//! [hal]
//! backend = "sim"            # joints that no backend section claims
//!
//! [hal.stepdir]              # joints 0-2: steppers through a serial MCU
//! port = "/dev/ttyACM0"
//! [[hal.stepdir.joints]]
//! joint = 0
//! steps_per_mm = 800.0
//!
//! [hal.can]                  # joint 3: a CiA 402 drive on can0
//! interface = "can0"
//! [[hal.can.drives]]
//! joint = 3
//! node = 1
//! counts_per_mm = 10000.0
//! ```
//!
//! A joint is claimed by at most one backend section; the rest go to
//! `backend`, which today can only be `sim` (the other backends need
//! per-joint settings). `backend = "sim"` alone keeps every joint simulated.

use serde::Deserialize;

use crate::can::CanConfig;
use crate::pins::PinConfig;
use crate::sim::SimConfig;
use crate::stepdir::StepDirConfig;

/// Errors building a backend from its configuration. Each names the key
/// under `[hal]` and the reason.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HalConfigError {
    /// `backend` names no known backend.
    #[error("unknown HAL backend {0:?}; known backends: sim, stepdir, can")]
    UnknownBackend(String),
    /// A key has a bad value, or the wiring is inconsistent.
    #[error("key `hal.{key}`: {reason}")]
    Key {
        /// Dotted path below `hal`, e.g. `stepdir.joints[0].steps_per_mm`.
        key: String,
        /// Why the value is refused.
        reason: String,
    },
    /// The backend's device could not be opened or set up.
    #[error("`hal.{backend}`: cannot start the hardware: {reason}")]
    Device {
        /// Backend table, e.g. `stepdir`.
        backend: &'static str,
        /// What failed, with the OS error or the device's answer.
        reason: String,
    },
}

impl HalConfigError {
    /// A [`HalConfigError::Key`] error.
    pub fn key(key: impl Into<String>, reason: impl Into<String>) -> HalConfigError {
        HalConfigError::Key {
            key: key.into(),
            reason: reason.into(),
        }
    }
}

/// The `[hal]` table of a machine description.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HalConfig {
    /// Backend for every joint no backend section claims: `sim`. May be
    /// left out when every joint is claimed.
    #[serde(default)]
    pub backend: Option<String>,
    /// `[hal.sim]`: settings of the simulated joints.
    #[serde(default)]
    pub sim: SimConfig,
    /// `[hal.stepdir]`: step/dir joints driven through a serial MCU.
    #[serde(default)]
    pub stepdir: Option<StepDirConfig>,
    /// `[hal.can]`: CiA 402 drives on a CAN bus.
    #[serde(default)]
    pub can: Option<CanConfig>,
    /// `[hal.pins]`: names of the digital and analog I/O pins.
    #[serde(default)]
    pub pins: PinConfig,
    /// `[hal.shm]`: export status and pins over shared memory.
    #[serde(default)]
    pub shm: Option<ShmConfig>,
}

/// `[hal.shm]`: present to publish status and pins over iceoryx2.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ShmConfig {
    /// Instance name in the service names (`kerf/INSTANCE/...`); default:
    /// the machine's name.
    #[serde(default)]
    pub instance: Option<String>,
}

/// Which backend drives a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wire {
    /// The simulator.
    Sim,
    /// Entry `index` of `hal.stepdir.joints`.
    StepDir(usize),
    /// Entry `index` of `hal.can.drives`.
    Can(usize),
}

impl HalConfig {
    /// Which backend drives each of `joints` joints, checking that no joint
    /// is claimed twice or out of range and that unclaimed joints have a
    /// default backend.
    pub fn wiring(&self, joints: usize) -> Result<Vec<Wire>, HalConfigError> {
        let mut wires: Vec<Option<(Wire, String)>> = vec![None; joints];
        let mut claim = |joint: usize, wire: Wire, key: String| {
            if joint >= joints {
                return Err(HalConfigError::key(
                    key,
                    format!(
                        "joint {joint} does not exist: the machine has joints 0 to {}",
                        joints - 1
                    ),
                ));
            }
            if let Some((_, other)) = &wires[joint] {
                return Err(HalConfigError::key(
                    key,
                    format!("joint {joint} is already wired by `hal.{other}`"),
                ));
            }
            wires[joint] = Some((wire, key));
            Ok(())
        };
        if let Some(sd) = &self.stepdir {
            for (i, j) in sd.joints.iter().enumerate() {
                claim(
                    j.joint,
                    Wire::StepDir(i),
                    format!("stepdir.joints[{i}].joint"),
                )?;
            }
        }
        if let Some(can) = &self.can {
            for (i, d) in can.drives.iter().enumerate() {
                claim(d.joint, Wire::Can(i), format!("can.drives[{i}].joint"))?;
            }
        }
        let default = match self.backend.as_deref() {
            None => None,
            Some("sim") => Some(Wire::Sim),
            Some(b @ ("stepdir" | "can")) => {
                return Err(HalConfigError::key(
                    "backend",
                    format!(
                        "`{b}` needs per-joint settings: list its joints in `[[hal.{}]]` \
                         and leave `backend` for the remaining joints (\"sim\") or out",
                        if b == "can" {
                            "can.drives"
                        } else {
                            "stepdir.joints"
                        }
                    ),
                ))
            }
            Some(other) => return Err(HalConfigError::UnknownBackend(other.to_string())),
        };
        wires
            .into_iter()
            .enumerate()
            .map(|(j, w)| match (w, default) {
                (Some((w, _)), _) => Ok(w),
                (None, Some(d)) => Ok(d),
                (None, None) => Err(HalConfigError::key(
                    "backend",
                    format!("joint {j} is wired to no backend: claim it in a backend section or set `backend = \"sim\"`"),
                )),
            })
            .collect()
    }
}
