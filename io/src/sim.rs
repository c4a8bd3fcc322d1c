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
    /// Fault injection for tests and demonstrations: a simulated crash.
    pub jam: Option<Jam>,
}

/// `[hal.sim.jam]`: joint `joint` seizes when its command first reaches
/// `at` (joint units) and moves no more, whatever it is commanded. The
/// controller sees the command run away from the feedback: a following
/// error.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Jam {
    /// Joint number, from 0.
    pub joint: usize,
    /// Joint position where it seizes, joint units (mm).
    pub at: f64,
}

/// The simulated hardware backend.
#[derive(Clone, Debug)]
pub struct SimHal {
    joints: usize,
    position: [f64; MAX_JOINTS],
    jam: Option<Jam>,
    jammed: bool,
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
        if let Some(jam) = config
            .jam
            .filter(|j| j.joint >= initial.len() || !j.at.is_finite())
        {
            return Err(HalConfigError::Key {
                key: "sim.jam".into(),
                reason: format!(
                    "joint {} at {}: the machine has joints 0 to {} and `at` must be a number",
                    jam.joint,
                    jam.at,
                    initial.len() - 1
                ),
            });
        }
        let mut position = [0.0; MAX_JOINTS];
        position[..initial.len()].copy_from_slice(initial);
        Ok(SimHal {
            joints: initial.len(),
            position,
            jam: config.jam,
            jammed: false,
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
            let mut target = if out.enable {
                out.joints[i].position
            } else {
                self.position[i]
            };
            if let Some(jam) = self.jam.filter(|j| j.joint == i) {
                let (lo, hi) = if target < self.position[i] {
                    (target, self.position[i])
                } else {
                    (self.position[i], target)
                };
                if !self.jammed && lo <= jam.at && jam.at <= hi && target != self.position[i] {
                    self.jammed = true;
                    self.position[i] = jam.at;
                }
                if self.jammed {
                    target = self.position[i];
                }
            }
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

    #[test]
    fn a_jammed_joint_stops_where_it_seizes() {
        let cfg: HalConfig =
            toml::from_str("backend = \"sim\"\n[sim.jam]\njoint = 0\nat = 2.0").unwrap();
        let mut hal = build(&cfg, &[0.0, 0.0]).unwrap();
        let mut out = Setpoints {
            enable: true,
            ..Default::default()
        };
        let mut fb = Feedback::default();
        for step in 1..=5 {
            out.joints[0].position = step as f64;
            out.joints[1].position = step as f64;
            hal.exchange(0.001, &out, &mut fb).unwrap();
        }
        // Joint 0 passed 2.0 on its way to 5.0 and stayed there; joint 1 is free.
        assert_eq!(fb.joints[0].position, 2.0);
        assert_eq!(fb.joints[0].velocity, 0.0);
        assert_eq!(fb.joints[1].position, 5.0);

        let bad: HalConfig =
            toml::from_str("backend = \"sim\"\n[sim.jam]\njoint = 3\nat = 2.0").unwrap();
        let e = build(&bad, &[0.0, 0.0]).err().unwrap().to_string();
        assert!(e.contains("hal.sim.jam") && e.contains("joint 3"), "{e}");
    }
}
