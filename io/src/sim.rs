//! The simulated machine.
//!
//! `plant = "ideal"`: each joint is an ideal position drive, like a stepper
//! that never loses a step: at the end of every period it is exactly where it
//! was commanded, and its velocity is the finite difference over the period.

use serde::Deserialize;

use crate::{Feedback, Hal, HalConfigError, HalFault, Setpoints, MAX_JOINTS};

/// Plant model of the simulated joints.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Plant {
    /// Position follows the command exactly.
    #[default]
    Ideal,
}

/// `[hal.sim]` settings.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    #[serde(default)]
    pub plant: Plant,
}

/// The simulated hardware backend.
#[derive(Clone, Debug)]
pub struct SimHal {
    joints: usize,
    position: [f64; MAX_JOINTS],
}

impl SimHal {
    /// A simulated machine with its joints at `initial` (mm).
    pub fn new(config: &SimConfig, initial: &[f64]) -> Result<SimHal, HalConfigError> {
        if initial.is_empty() || initial.len() > MAX_JOINTS {
            return Err(HalConfigError::Key {
                key: "sim".into(),
                reason: format!(
                    "the simulator drives 1 to {MAX_JOINTS} joints, asked for {}",
                    initial.len()
                ),
            });
        }
        let Plant::Ideal = config.plant;
        let mut position = [0.0; MAX_JOINTS];
        position[..initial.len()].copy_from_slice(initial);
        Ok(SimHal {
            joints: initial.len(),
            position,
        })
    }
}

impl Hal for SimHal {
    fn name(&self) -> &str {
        "sim"
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
        for i in 0..self.joints {
            let target = if out.enable {
                out.joints[i].position
            } else {
                self.position[i]
            };
            feedback.joints[i].velocity = (target - self.position[i]) / period;
            feedback.joints[i].position = target;
            self.position[i] = target;
        }
        feedback.spindle_current = 0.0;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build, HalConfig, JointCommand};

    #[test]
    fn ideal_joints_follow_when_enabled_and_hold_when_disabled() {
        let cfg: HalConfig = toml::from_str("backend = \"sim\"").unwrap();
        let mut hal = build(&cfg, &[1.0, 2.0]).unwrap();
        let mut out = Setpoints::default();
        let mut fb = Feedback::default();
        out.joints[0] = JointCommand {
            position: 1.5,
            ..Default::default()
        };
        out.joints[1] = JointCommand {
            position: 2.0,
            ..Default::default()
        };

        // Disabled drives stay where they are whatever is commanded.
        hal.exchange(0.001, &out, &mut fb).unwrap();
        assert_eq!((fb.joints[0].position, fb.joints[0].velocity), (1.0, 0.0));

        out.enable = true;
        hal.exchange(0.001, &out, &mut fb).unwrap();
        assert_eq!(fb.joints[0].position, 1.5);
        assert!((fb.joints[0].velocity - 500.0).abs() < 1e-9);
        assert_eq!(fb.joints[1].position, 2.0);
    }

    #[test]
    fn unknown_backend_and_keys_are_errors() {
        let cfg: HalConfig = toml::from_str("backend = \"ethercat\"").unwrap();
        assert!(build(&cfg, &[0.0]).is_err());
        let e = toml::from_str::<HalConfig>("backend = \"sim\"\n[sim]\nplant = \"quantum\"")
            .unwrap_err();
        assert!(e.to_string().contains("quantum"), "{e}");
    }
}
