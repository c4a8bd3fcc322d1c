//! The machine description file (`machines/*.toml`).

use std::collections::BTreeMap;

use kerf_interp::{Axis, Position};
use kerf_motion::control::LoopGains;
use kerf_motion::fuzzy::{CurrentSensor, FuzzyConfig};
use kerf_motion::kinematics::{AxisSpec, JointSpec};
use kerf_motion::Limits;
use serde::Deserialize;

/// An error in a machine description: which file, which key, and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MachineError {
    #[error("cannot read machine file {path}: {reason}")]
    Read { path: String, reason: String },
    #[error("{origin}: {message}")]
    Syntax { origin: String, message: String },
    #[error("{origin}: key `{key}`: {reason}")]
    Key {
        origin: String,
        key: String,
        reason: String,
    },
    #[error("unknown machine {name:?}: give an embedded name ({known}) or a path to a .toml file")]
    UnknownMachine { name: String, known: String },
}

/// Travel and dynamics as written in TOML.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LimitsToml {
    pub min: f64,
    pub max: f64,
    pub max_velocity: f64,
    pub max_acceleration: f64,
    /// mm/s³; defaults to [`Limits::default_jerk`].
    pub max_jerk: Option<f64>,
}

/// One `[[joints]]` entry.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct JointToml {
    pub name: String,
    /// For trivial kinematics: the axis this joint drives.
    pub axis: Option<String>,
    pub min: f64,
    pub max: f64,
    pub max_velocity: f64,
    pub max_acceleration: f64,
    /// mm/s³; defaults to [`Limits::default_jerk`].
    pub max_jerk: Option<f64>,
    /// Joint position of the home pose, joint units; defaults to the joint's
    /// position at the machine origin.
    pub home: Option<f64>,
    /// Largest distance between commanded and measured joint position
    /// before the servo faults, joint units; unchecked when absent.
    pub following_error: Option<f64>,
    /// Position loop, proportional gain, drive units (V) per mm.
    pub kp: Option<f64>,
    /// Position loop, integral gain, V per mm·s.
    pub ki: Option<f64>,
    /// Position loop, derivative gain, V per mm/s.
    pub kd: Option<f64>,
    /// Velocity feedforward, V per mm/s.
    pub kvff: Option<f64>,
    /// Acceleration feedforward, V per mm/s².
    pub kaff: Option<f64>,
    /// Largest drive input either way, V.
    pub max_output: Option<f64>,
}

impl JointToml {
    /// The joint's position-loop gains: each key given, the seed's
    /// ([`LoopGains::SEED`]) for the rest.
    pub fn loop_gains(&self) -> LoopGains {
        let d = LoopGains::SEED;
        LoopGains {
            kp: self.kp.unwrap_or(d.kp),
            ki: self.ki.unwrap_or(d.ki),
            kd: self.kd.unwrap_or(d.kd),
            kvff: self.kvff.unwrap_or(d.kvff),
            kaff: self.kaff.unwrap_or(d.kaff),
            max_output: self.max_output.unwrap_or(d.max_output),
        }
    }

    /// The joint's limits.
    pub fn limits(&self) -> Limits {
        Limits {
            min: self.min,
            max: self.max,
            max_velocity: self.max_velocity,
            max_acceleration: self.max_acceleration,
            max_jerk: self
                .max_jerk
                .unwrap_or_else(|| Limits::default_jerk(self.max_acceleration)),
        }
    }
}

/// A parsed machine description.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Description {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Kinematics module name, e.g. `trivial`.
    pub kinematics: String,
    /// Kinematics dimensions (module-specific keys).
    #[serde(default)]
    pub dimensions: BTreeMap<String, f64>,
    /// Axis travel, keyed by lower-case axis letter.
    pub axes: BTreeMap<String, LimitsToml>,
    pub joints: Vec<JointToml>,
    /// Where the machine rests when it starts: axis letter → coordinate
    /// (mm, degrees for rotary axes). Axes not named are at 0.
    #[serde(default)]
    pub home: BTreeMap<String, f64>,
    /// HAL wiring, interpreted by the io crate.
    #[serde(default)]
    pub hal: toml::Table,
    /// `[spindle]`: its speed and the current-to-force calibration.
    #[serde(default)]
    pub spindle: Option<SpindleToml>,
    /// `[force_control]`: the fuzzy cutting-force feed override.
    #[serde(default)]
    pub force_control: Option<ForceControlToml>,
}

/// `[spindle]`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SpindleToml {
    /// Spindle speed while the machine runs, rpm (until programs can set
    /// it with S words).
    pub rpm: f64,
    /// Motor current turning without cutting, I0, A.
    #[serde(default = "default_idle_current")]
    pub idle_current: f64,
    /// Motor current per newton of cutting force, k, A/N.
    #[serde(default = "default_current_per_newton")]
    pub current_per_newton: f64,
}

fn default_idle_current() -> f64 {
    2.0
}

fn default_current_per_newton() -> f64 {
    0.01
}

impl SpindleToml {
    /// The current-to-force conversion.
    pub fn sensor(&self) -> CurrentSensor {
        CurrentSensor {
            idle_current: self.idle_current,
            current_per_newton: self.current_per_newton,
        }
    }
}

/// `[force_control]`; every key defaults to [`FuzzyConfig::default`].
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ForceControlToml {
    /// Target force F_d at start-up, N; off at start-up when absent.
    pub target: Option<f64>,
    /// [`FuzzyConfig::gain_e`].
    pub gain_e: Option<f64>,
    /// [`FuzzyConfig::gain_ce`].
    pub gain_ce: Option<f64>,
    /// [`FuzzyConfig::gain_out`].
    pub gain_out: Option<f64>,
    /// [`FuzzyConfig::min_override`].
    pub min_override: Option<f64>,
    /// [`FuzzyConfig::max_override`].
    pub max_override: Option<f64>,
    /// [`FuzzyConfig::engage`].
    pub engage: Option<f64>,
}

impl ForceControlToml {
    /// The controller settings.
    pub fn config(&self) -> FuzzyConfig {
        let d = FuzzyConfig::default();
        FuzzyConfig {
            gain_e: self.gain_e.unwrap_or(d.gain_e),
            gain_ce: self.gain_ce.unwrap_or(d.gain_ce),
            gain_out: self.gain_out.unwrap_or(d.gain_out),
            min_override: self.min_override.unwrap_or(d.min_override),
            max_override: self.max_override.unwrap_or(d.max_override),
            engage: self.engage.unwrap_or(d.engage),
        }
    }
}

impl Description {
    /// Parse and validate description text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Description, MachineError> {
        let d: Description = toml::from_str(text).map_err(|e| MachineError::Syntax {
            origin: origin.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let key_err = |key: String, reason: String| MachineError::Key {
            origin: origin.to_string(),
            key,
            reason,
        };
        for (name, l) in &d.axes {
            if name.len() != 1 || Axis::from_letter(name.chars().next().unwrap()).is_none() {
                return Err(key_err(
                    format!("axes.{name}"),
                    "not an axis letter (x y z a b c u v w)".into(),
                ));
            }
            check_limits(
                &format!("axes.{name}"),
                l.min,
                l.max,
                l.max_velocity,
                l.max_acceleration,
                l.max_jerk,
            )
            .map_err(|(k, r)| key_err(k, r))?;
        }
        if d.joints.is_empty() || d.joints.len() > kerf_motion::MAX_JOINTS {
            return Err(key_err(
                "joints".into(),
                format!(
                    "a machine has 1 to {} joints, found {}",
                    kerf_motion::MAX_JOINTS,
                    d.joints.len()
                ),
            ));
        }
        for (i, j) in d.joints.iter().enumerate() {
            check_limits(
                &format!("joints[{i}]"),
                j.min,
                j.max,
                j.max_velocity,
                j.max_acceleration,
                j.max_jerk,
            )
            .map_err(|(k, r)| key_err(k, r))?;
            if let Some(f) = j.following_error.filter(|f| !(f.is_finite() && *f > 0.0)) {
                return Err(key_err(
                    format!("joints[{i}].following_error"),
                    format!("must be a positive number, got {f}"),
                ));
            }
            if let Some(h) = j
                .home
                .filter(|h| !(h.is_finite() && *h >= j.min && *h <= j.max))
            {
                return Err(key_err(
                    format!("joints[{i}].home"),
                    format!("{h} is outside the joint's stroke {} .. {}", j.min, j.max),
                ));
            }
            if let Some((k, v)) = j.loop_gains().invalid() {
                return Err(key_err(
                    format!("joints[{i}].{k}"),
                    format!("must be a number ≥ 0, got {v}"),
                ));
            }
        }
        if let Some(s) = &d.spindle {
            if !(s.rpm.is_finite() && s.rpm > 0.0) {
                return Err(key_err(
                    "spindle.rpm".into(),
                    format!("must be a positive number, got {}", s.rpm),
                ));
            }
            if !(s.current_per_newton.is_finite() && s.current_per_newton > 0.0) {
                return Err(key_err(
                    "spindle.current_per_newton".into(),
                    format!("must be a positive number, got {}", s.current_per_newton),
                ));
            }
            if !s.idle_current.is_finite() {
                return Err(key_err(
                    "spindle.idle_current".into(),
                    format!("must be a number, got {}", s.idle_current),
                ));
            }
        }
        if let Some(f) = &d.force_control {
            if d.spindle.is_none() {
                return Err(key_err(
                    "force_control".into(),
                    "needs a [spindle] table: the spindle speed sets the controller's \
                     period and its current is the force sensor"
                        .into(),
                ));
            }
            if let Some(t) = f.target.filter(|t| !(t.is_finite() && *t > 0.0)) {
                return Err(key_err(
                    "force_control.target".into(),
                    format!("must be a positive force in N, got {t}"),
                ));
            }
            if let Some((k, reason)) = f.config().invalid() {
                return Err(key_err(format!("force_control.{k}"), reason));
            }
        }
        for (name, value) in &d.home {
            if !d.axes.contains_key(name) {
                return Err(key_err(
                    format!("home.{name}"),
                    "not one of this machine's [axes]".into(),
                ));
            }
            if !value.is_finite() {
                return Err(key_err(
                    format!("home.{name}"),
                    format!("must be a finite number, got {value}"),
                ));
            }
        }
        for (name, value) in &d.dimensions {
            if !value.is_finite() {
                return Err(key_err(
                    format!("dimensions.{name}"),
                    format!("must be a finite number, got {value}"),
                ));
            }
        }
        Ok(d)
    }

    /// The pose the machine starts at: the `[home]` table, other axes at 0.
    pub fn home(&self) -> Position {
        let mut p = Position::ZERO;
        for (name, value) in &self.home {
            if let Some(axis) = name.chars().next().and_then(Axis::from_letter) {
                p.set(axis, *value);
            }
        }
        p
    }

    /// The axes as kinematics specs, in canonical order.
    pub fn axis_specs(&self) -> Vec<AxisSpec> {
        self.axis_limits()
            .into_iter()
            .map(|(axis, limits)| AxisSpec { axis, limits })
            .collect()
    }

    /// The joints as kinematics specs, in joint order.
    pub fn joint_specs(&self) -> Vec<JointSpec> {
        self.joints
            .iter()
            .map(|j| JointSpec {
                name: j.name.clone(),
                limits: j.limits(),
            })
            .collect()
    }

    /// The axes in canonical order with their limits.
    pub fn axis_limits(&self) -> Vec<(Axis, Limits)> {
        let mut v: Vec<(Axis, Limits)> = self
            .axes
            .iter()
            .map(|(name, l)| {
                (
                    Axis::from_letter(name.chars().next().unwrap()).expect("validated in parse"),
                    Limits {
                        min: l.min,
                        max: l.max,
                        max_velocity: l.max_velocity,
                        max_acceleration: l.max_acceleration,
                        max_jerk: l
                            .max_jerk
                            .unwrap_or_else(|| Limits::default_jerk(l.max_acceleration)),
                    },
                )
            })
            .collect();
        v.sort_by_key(|(a, _)| *a);
        v
    }
}

impl Description {
    /// Check that this machine fits a kinematics module: exactly the axes
    /// `axes`, `joints` joints, and no dimension key outside `dimensions`.
    /// `kinematics` names the module in the messages.
    pub fn expect_layout(
        &self,
        origin: &str,
        kinematics: &str,
        axes: &[Axis],
        joints: usize,
        dimensions: &[&str],
    ) -> Result<(), MachineError> {
        let key_err = |key: String, reason: String| MachineError::Key {
            origin: origin.to_string(),
            key,
            reason,
        };
        let letters = |list: &mut dyn Iterator<Item = Axis>| {
            list.map(|a| a.letter().to_ascii_lowercase().to_string())
                .collect::<Vec<_>>()
                .join(" ")
        };
        let have: Vec<Axis> = self.axis_limits().iter().map(|(a, _)| *a).collect();
        if have != axes {
            return Err(key_err(
                "axes".into(),
                format!(
                    "{kinematics} kinematics needs exactly the axes {}, found {}",
                    letters(&mut axes.iter().copied()),
                    letters(&mut have.into_iter())
                ),
            ));
        }
        if self.joints.len() != joints {
            return Err(key_err(
                "joints".into(),
                format!(
                    "{kinematics} kinematics has {joints} joints, found {}",
                    self.joints.len()
                ),
            ));
        }
        if let Some(name) = self
            .dimensions
            .keys()
            .find(|k| !dimensions.contains(&k.as_str()))
        {
            return Err(key_err(
                format!("dimensions.{name}"),
                format!(
                    "not a dimension of {kinematics} kinematics (it has {})",
                    dimensions.join(", ")
                ),
            ));
        }
        Ok(())
    }

    /// The dimension `key`, which must be given and be greater than zero.
    pub fn positive_dimension(&self, origin: &str, key: &str) -> Result<f64, MachineError> {
        let value = self.dimension(origin, key)?;
        if value > 0.0 {
            Ok(value)
        } else {
            Err(MachineError::Key {
                origin: origin.to_string(),
                key: format!("dimensions.{key}"),
                reason: format!("must be greater than zero, got {value}"),
            })
        }
    }

    /// The dimension `key`, which must be given.
    pub fn dimension(&self, origin: &str, key: &str) -> Result<f64, MachineError> {
        self.dimensions
            .get(key)
            .copied()
            .ok_or_else(|| MachineError::Key {
                origin: origin.to_string(),
                key: format!("dimensions.{key}"),
                reason: format!("missing: {} kinematics needs it", self.kinematics),
            })
    }
}

fn check_limits(
    key: &str,
    min: f64,
    max: f64,
    vel: f64,
    acc: f64,
    jerk: Option<f64>,
) -> Result<(), (String, String)> {
    if let Some(j) = jerk.filter(|j| !(j.is_finite() && *j > 0.0)) {
        return Err((
            format!("{key}.max_jerk"),
            format!("must be a positive number, got {j}"),
        ));
    }
    if !(min.is_finite() && max.is_finite() && min < max) {
        return Err((
            format!("{key}.min"),
            format!("min ({min}) must be below max ({max})"),
        ));
    }
    if !(vel.is_finite() && vel > 0.0) {
        return Err((
            format!("{key}.max_velocity"),
            format!("must be a positive number, got {vel}"),
        ));
    }
    if !(acc.is_finite() && acc > 0.0) {
        return Err((
            format!("{key}.max_acceleration"),
            format!("must be a positive number, got {acc}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "m"
kinematics = "trivial"
[axes.x]
min = 0.0
max = 10.0
max_velocity = 1.0
max_acceleration = 1.0
[[joints]]
name = "x"
axis = "x"
min = 0.0
max = 10.0
max_velocity = 1.0
max_acceleration = 1.0
"#;

    #[test]
    fn parses_a_minimal_machine() {
        let d = Description::parse(GOOD, "m.toml").unwrap();
        assert_eq!(d.axis_limits()[0].0, Axis::X);
    }

    #[test]
    fn bad_values_name_the_key() {
        let bad = GOOD.replacen("max_velocity = 1.0", "max_velocity = -1.0", 1);
        let e = Description::parse(&bad, "m.toml").unwrap_err().to_string();
        assert_eq!(
            e,
            "m.toml: key `axes.x.max_velocity`: must be a positive number, got -1"
        );
    }

    #[test]
    fn servo_keys_are_checked() {
        let with = |extra: &str| format!("{GOOD}{extra}\n");
        let d = Description::parse(&with("following_error = 0.5\nkp = 2.0"), "m.toml").unwrap();
        assert_eq!(d.joints[0].following_error, Some(0.5));
        let g = d.joints[0].loop_gains();
        assert_eq!((g.kp, g.kd), (2.0, LoopGains::SEED.kd));
        let e = Description::parse(&with("following_error = 0.0"), "m.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m.toml: key `joints[0].following_error`: must be a positive number, got 0"
        );
        let e = Description::parse(&with("kaff = -1.0"), "m.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m.toml: key `joints[0].kaff`: must be a number ≥ 0, got -1"
        );
        let e = Description::parse(&format!("{GOOD}[force_control]\n"), "m.toml").unwrap_err();
        assert!(
            e.to_string()
                .contains("key `force_control`: needs a [spindle]"),
            "{e}"
        );
        let spindle = "[spindle]\nrpm = 1000.0\n";
        let e = Description::parse(
            &format!("{GOOD}{spindle}[force_control]\nmax_override = 3.0\n"),
            "m.toml",
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("key `force_control.max_override`"),
            "{e}"
        );
        let d = Description::parse(
            &format!("{GOOD}{spindle}[force_control]\ntarget = 250.0\n"),
            "m.toml",
        )
        .unwrap();
        assert_eq!(d.force_control.unwrap().target, Some(250.0));
        let e = Description::parse(&format!("{GOOD}[spindle]\nrpm = 0.0\n"), "m.toml").unwrap_err();
        assert!(e.to_string().contains("key `spindle.rpm`"), "{e}");
    }

    #[test]
    fn unknown_keys_and_syntax_errors_name_the_line() {
        let bad = GOOD.replacen("name = \"m\"", "name = \"m\"\nspeed = 3", 1);
        let e = Description::parse(&bad, "m.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("m.toml: ") && e.contains("speed") && e.contains("line 3"),
            "{e}"
        );
    }

    #[test]
    fn home_and_following_error_are_checked() {
        let with = |extra: &str| format!("{GOOD}{extra}\n");
        let d = Description::parse(&with("home = 4.0\nfollowing_error = 0.5"), "m.toml").unwrap();
        assert_eq!(
            (d.joints[0].home, d.joints[0].following_error),
            (Some(4.0), Some(0.5))
        );
        let e = Description::parse(&with("home = 11.0"), "m.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m.toml: key `joints[0].home`: 11 is outside the joint's stroke 0 .. 10"
        );
        let e = Description::parse(&with("following_error = 0.0"), "m.toml").unwrap_err();
        assert_eq!(
            e.to_string(),
            "m.toml: key `joints[0].following_error`: must be a positive number, got 0"
        );
    }
}
