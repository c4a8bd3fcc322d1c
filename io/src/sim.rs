//! The simulated machine.
//!
//! `plant = "ideal"` (the default): each joint is an ideal position drive,
//! like a stepper that never loses a step: at the end of every period it
//! is exactly where it was commanded, and its velocity is the finite
//! difference over the period. The control effort is ignored.
//!
//! `plant = "identified"`: each joint is the velocity drive and axis the
//! seed paper identified (eq. 2; see [`plant`]), driven by the effort of
//! the host's position loop; the commanded position is ignored. Disabled
//! drives get no input and coast to rest.
//!
//! Either plant can read its positions through a quantising encoder with
//! seeded noise, and can cut: `[hal.sim.cutting]` (see [`cutting`]).

pub mod cutting;
pub mod noise;
pub mod plant;

use serde::Deserialize;

use crate::{Feedback, Hal, HalConfigError, HalFault, Setpoints, MAX_JOINTS};
use cutting::{Cutting, CuttingConfig};
use noise::Noise;
use plant::DriveModel;

/// Plant model of the simulated joints.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Plant {
    /// Position follows the command exactly.
    #[default]
    Ideal,
    /// The identified feed drive of seed eq. (2), driven by the effort.
    Identified,
}

/// `[hal.sim]` settings.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Plant model of every simulated joint.
    #[serde(default)]
    pub plant: Plant,
    /// Identified plant: settled speed per unit of effort, mm/s per volt
    /// (default: the seed's 27.67).
    #[serde(default)]
    pub gain: Option<f64>,
    /// Identified plant: time constant of the speed response, s (default:
    /// the seed's 0.005039).
    #[serde(default)]
    pub time_constant: Option<f64>,
    /// Encoder resolution, mm: measured positions are rounded to it (0 or
    /// absent: exact).
    #[serde(default)]
    pub encoder_resolution: f64,
    /// Standard deviation of white noise on the measured positions, mm.
    #[serde(default)]
    pub position_noise: f64,
    /// Seed of the position noise.
    #[serde(default)]
    pub seed: u64,
    /// The cutting process and spindle current, if simulated.
    #[serde(default)]
    pub cutting: Option<CuttingConfig>,
    /// Fault injection for tests and demonstrations: a simulated crash.
    #[serde(default)]
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

impl SimConfig {
    /// The drive model of the identified plant, checked.
    fn drive(&self) -> Result<DriveModel, HalConfigError> {
        let mut model = DriveModel::SEED;
        for (key, value, slot) in [
            ("gain", self.gain, &mut model.gain),
            (
                "time_constant",
                self.time_constant,
                &mut model.time_constant,
            ),
        ] {
            if let Some(v) = value {
                if self.plant != Plant::Identified {
                    return Err(HalConfigError::key(
                        format!("sim.{key}"),
                        "only applies to plant = \"identified\"",
                    ));
                }
                if !(v.is_finite() && v > 0.0) {
                    return Err(HalConfigError::key(
                        format!("sim.{key}"),
                        format!("must be a positive number, got {v}"),
                    ));
                }
                *slot = v;
            }
        }
        for (key, v) in [
            ("encoder_resolution", self.encoder_resolution),
            ("position_noise", self.position_noise),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(HalConfigError::key(
                    format!("sim.{key}"),
                    format!("must be a number ≥ 0 (mm), got {v}"),
                ));
            }
        }
        Ok(model)
    }
}

/// The simulated hardware backend.
#[derive(Clone, Debug)]
pub struct SimHal {
    joints: usize,
    plant: Plant,
    drive: DriveModel,
    /// True joint positions, mm.
    position: [f64; MAX_JOINTS],
    /// True joint velocities, mm/s.
    velocity: [f64; MAX_JOINTS],
    /// Last measured positions, mm.
    measured: [f64; MAX_JOINTS],
    encoder_resolution: f64,
    position_noise: f64,
    noise: Noise,
    cutting: Option<Cutting>,
    jam: Option<Jam>,
    jammed: bool,
}

impl SimHal {
    /// A simulated machine with its joints at rest at `initial` (mm).
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
        let drive = config.drive()?;
        if let Some(c) = &config.cutting {
            c.validate(initial.len())?;
        }
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
            plant: config.plant,
            drive,
            position,
            velocity: [0.0; MAX_JOINTS],
            measured: position,
            encoder_resolution: config.encoder_resolution,
            position_noise: config.position_noise,
            noise: Noise::new(config.seed),
            cutting: config.cutting.clone().map(Cutting::new),
            jam: config.jam,
            jammed: false,
        })
    }

    /// What the encoder reads for true position `x`.
    fn measure(&mut self, x: f64) -> f64 {
        let noisy = if self.position_noise > 0.0 {
            x + self.position_noise * self.noise.normal()
        } else {
            x
        };
        if self.encoder_resolution > 0.0 {
            (noisy / self.encoder_resolution).round() * self.encoder_resolution
        } else {
            noisy
        }
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
            let before = self.position[i];
            match self.plant {
                Plant::Ideal => {
                    let target = if out.enable {
                        out.joints[i].position
                    } else {
                        self.position[i]
                    };
                    self.velocity[i] = (target - self.position[i]) / period;
                    self.position[i] = target;
                }
                Plant::Identified => {
                    let u = if out.enable {
                        out.joints[i].effort
                    } else {
                        0.0
                    };
                    (self.position[i], self.velocity[i]) =
                        self.drive
                            .step(self.position[i], self.velocity[i], u, period);
                }
            }
            // A jammed joint seizes where it first passes `at` and stays
            // there, whatever the plant or the command does.
            if let Some(jam) = self.jam.filter(|j| j.joint == i) {
                let now = self.position[i];
                let (lo, hi) = if now < before {
                    (now, before)
                } else {
                    (before, now)
                };
                if !self.jammed && lo <= jam.at && jam.at <= hi && now != before {
                    self.jammed = true;
                }
                if self.jammed {
                    self.position[i] = jam.at;
                    self.velocity[i] = 0.0;
                }
            }
            let reading = self.measure(self.position[i]);
            feedback.joints[i].velocity = (reading - self.measured[i]) / period;
            feedback.joints[i].position = reading;
            self.measured[i] = reading;
        }
        let (force, current) = match &mut self.cutting {
            Some(cut) => {
                let [x, y, z] = cut.config().joints;
                let tip = [self.position[x], self.position[y], self.position[z]];
                let v = [self.velocity[x], self.velocity[y], self.velocity[z]];
                let c = cut.step(tip, v, out.spindle_speed, period);
                (c.force, c.current)
            }
            None => (0.0, 0.0),
        };
        feedback.cutting_force = force;
        feedback.spindle_current = current;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{build, HalConfig, JointCommand};
    use plant::DriveModel;

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

    fn identified(extra: &str) -> Box<dyn Hal> {
        let cfg: HalConfig = toml::from_str(&format!(
            "backend = \"sim\"\n[sim]\nplant = \"identified\"\n{extra}"
        ))
        .unwrap();
        build(&cfg, &[5.0]).unwrap()
    }

    #[test]
    fn identified_plant_integrates_the_effort() {
        // 2 V for 50 ms from rest at 5 mm: y = 5 + 2K (t − τ(1 − e^(−t/τ))).
        let mut hal = identified("");
        let mut out = Setpoints {
            enable: true,
            ..Default::default()
        };
        out.joints[0] = JointCommand {
            position: 1000.0, // ignored by this plant
            effort: 2.0,
            ..Default::default()
        };
        let mut fb = Feedback::default();
        for _ in 0..50 {
            hal.exchange(0.001, &out, &mut fb).unwrap();
        }
        let m = DriveModel::SEED;
        let t: f64 = 0.05;
        let want =
            5.0 + 2.0 * m.gain * (t - m.time_constant * (1.0 - (-t / m.time_constant).exp()));
        assert!(
            (fb.joints[0].position - want).abs() < 1e-9,
            "{}",
            fb.joints[0].position
        );
        // Disabled: no input, the axis coasts to rest (speed decays with τ).
        out.enable = false;
        for _ in 0..200 {
            hal.exchange(0.001, &out, &mut fb).unwrap();
        }
        assert!(fb.joints[0].velocity.abs() < 1e-9);
    }

    #[test]
    fn encoder_quantises_and_noise_is_seeded() {
        let mut out = Setpoints {
            enable: true,
            ..Default::default()
        };
        out.joints[0].effort = 0.1;
        let run = |extra: &str| {
            let mut hal = identified(extra);
            let mut fb = Feedback::default();
            let mut out = out;
            (0..100)
                .map(|k| {
                    out.joints[0].effort = 0.1 * (k as f64 * 0.1).sin();
                    hal.exchange(0.001, &out, &mut fb).unwrap();
                    fb.joints[0].position
                })
                .collect::<Vec<_>>()
        };
        let exact = run("");
        let coarse = run("encoder_resolution = 0.001");
        for (e, c) in exact.iter().zip(&coarse) {
            assert!((e - c).abs() <= 0.0005 + 1e-12);
            assert!(((c / 0.001).round() * 0.001 - c).abs() < 1e-12);
        }
        let a = run("position_noise = 0.002\nseed = 3");
        assert_eq!(a, run("position_noise = 0.002\nseed = 3"));
        assert_ne!(a, run("position_noise = 0.002\nseed = 4"));
        let rms = (a
            .iter()
            .zip(&exact)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            / 100.0)
            .sqrt();
        assert!(rms > 0.001 && rms < 0.003, "noise rms {rms}");
    }

    #[test]
    fn plant_settings_are_checked() {
        let bad = |text: &str| {
            let cfg: HalConfig = toml::from_str(text).unwrap();
            build(&cfg, &[0.0]).err().unwrap().to_string()
        };
        let e = bad("backend = \"sim\"\n[sim]\ngain = 3.0");
        assert!(
            e.contains("hal.sim.gain") && e.contains("identified"),
            "{e}"
        );
        let e = bad("backend = \"sim\"\n[sim]\nplant = \"identified\"\ntime_constant = -1.0");
        assert!(e.contains("hal.sim.time_constant"), "{e}");
        let e = bad("backend = \"sim\"\n[sim]\nencoder_resolution = -0.001");
        assert!(e.contains("hal.sim.encoder_resolution"), "{e}");
    }

    #[test]
    fn cutting_reports_force_and_current_through_the_hal() {
        let cfg: HalConfig = toml::from_str(
            "backend = \"sim\"\n[sim.cutting]\nstock_top = 0.0\ncurrent_noise = 0.0",
        )
        .unwrap();
        let mut hal = build(&cfg, &[0.0, 0.0, -2.0]).unwrap();
        let mut out = Setpoints {
            enable: true,
            spindle_speed: 1000.0,
            ..Default::default()
        };
        out.joints[2].position = -2.0;
        let mut fb = Feedback::default();
        let mut largest: f64 = 0.0;
        for k in 1..=120 {
            out.joints[0].position = k as f64 * 0.004; // 240 mm/min
            hal.exchange(0.001, &out, &mut fb).unwrap();
            largest = largest.max(fb.cutting_force);
        }
        let c: cutting::CuttingConfig = toml::from_str("stock_top = 0.0").unwrap();
        let peak = c.force(0.12, 2.0, 1.0);
        assert!((largest - peak).abs() < 1e-6, "{largest} vs {peak}");
        assert!((fb.spindle_current - (2.0 + 0.01 * peak)).abs() < 1e-6);
        // A cutting process needs every joint in the simulator.
        let mixed: HalConfig = toml::from_str(
            "backend = \"sim\"\n[sim.cutting]\nstock_top = 0.0\n[can]\nbus = \"sim\"\n[[can.drives]]\njoint = 1\nnode = 2\ncounts_per_mm = 100.0",
        )
        .unwrap();
        let e = build(&mixed, &[0.0, 0.0, 0.0]).err().unwrap().to_string();
        assert!(e.contains("hal.sim.cutting"), "{e}");
    }
}
