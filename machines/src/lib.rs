//! kerf-machines: machine kinematics and machine description files.
//!
//! A machine is described by a TOML file (see `docs/machines.md`) that picks
//! a kinematics, gives its dimensions, the joint strokes and axis travel, and
//! the HAL wiring. Descriptions of the standard machines are embedded in the
//! binary; [`load`] takes an embedded name or a path to a TOML file.

pub mod corexy;
pub mod description;
pub mod oxglide;
pub mod rfmt5;
pub mod trivial;
pub mod workspace;

use std::path::Path;
use std::sync::Arc;

use kerf_interp::Position;
use kerf_motion::kinematics::{AxisSpec, KinematicsError};
use kerf_motion::Kinematics;

pub use description::{Description, MachineError};

/// Machine descriptions embedded in the binary, by name.
pub const EMBEDDED: &[(&str, &str)] = &[
    ("mill3", include_str!("../mill3.toml")),
    ("oxglide-x", include_str!("../oxglide-x.toml")),
    ("oxglide-o", include_str!("../oxglide-o.toml")),
    ("rfmt5", include_str!("../rfmt5.toml")),
    ("corexy", include_str!("../corexy.toml")),
];

/// The kinematics modules a description may name in `kinematics`.
pub const KINEMATICS: &[&str] = &["trivial", "oxglide-x", "oxglide-o", "rfmt5", "corexy"];

/// The name of the machine kerfd runs when no configuration names one.
pub const DEFAULT_MACHINE: &str = "mill3";

/// A machine ready to run: its description and its kinematics.
pub struct Machine {
    pub description: Description,
    pub kinematics: Arc<dyn Kinematics>,
    /// Where the description came from: `embedded:NAME` or a file path.
    pub origin: String,
}

impl Machine {
    /// The pose the machine starts at (the description's `[home]`), which
    /// [`from_toml`] has checked to be inside the travel and reachable.
    pub fn home(&self) -> kerf_interp::Position {
        self.description.home()
    }
}

impl std::fmt::Debug for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Machine")
            .field("name", &self.description.name)
            .field("kinematics", &self.kinematics.name())
            .field("origin", &self.origin)
            .finish()
    }
}

/// Refuse a joint slice of the wrong length or with a value that is not a
/// finite number: shared entry check of every module's `forward`.
pub(crate) fn check_joint_input(joints: &[f64], expected: usize) -> Result<(), KinematicsError> {
    if joints.len() != expected {
        return Err(KinematicsError::JointCount {
            expected,
            got: joints.len(),
        });
    }
    if joints.iter().all(|q| q.is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::Unreachable {
            reason: "a joint position is not a finite number",
        })
    }
}

/// Refuse a joint slice of the wrong length, or a pose with a coordinate on
/// one of `axes` that is not a finite number: shared entry check of every
/// module's `inverse`.
pub(crate) fn check_pose_input(
    pose: &Position,
    axes: &[AxisSpec],
    joints: usize,
    expected: usize,
) -> Result<(), KinematicsError> {
    if joints != expected {
        return Err(KinematicsError::JointCount {
            expected,
            got: joints,
        });
    }
    if axes.iter().all(|a| pose.get(a.axis).is_finite()) {
        Ok(())
    } else {
        Err(KinematicsError::Unreachable {
            reason: "a coordinate of the pose is not a finite number",
        })
    }
}

/// Load a machine by embedded name (e.g. `mill3`) or by TOML file path.
///
/// A spec containing `/` or ending in `.toml` is a path; anything else is an
/// embedded name.
pub fn load(spec: &str) -> Result<Machine, MachineError> {
    if spec.contains('/') || spec.ends_with(".toml") {
        let path = Path::new(spec);
        let text = std::fs::read_to_string(path).map_err(|e| MachineError::Read {
            path: spec.to_string(),
            reason: e.to_string(),
        })?;
        return from_toml(&text, spec);
    }
    match EMBEDDED.iter().find(|(name, _)| *name == spec) {
        Some((name, text)) => from_toml(text, &format!("embedded:{name}")),
        None => Err(MachineError::UnknownMachine {
            name: spec.to_string(),
            known: EMBEDDED
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

/// Build a machine from description text; `origin` names it in errors.
///
/// Besides the description's own checks, the home pose must lie inside the
/// travel and be reachable with every joint inside its stroke.
pub fn from_toml(text: &str, origin: &str) -> Result<Machine, MachineError> {
    let description = Description::parse(text, origin)?;
    let d = &description;
    let kinematics: Arc<dyn Kinematics> = match d.kinematics.as_str() {
        "trivial" => Arc::new(trivial::Trivial::from_description(d, origin)?),
        "oxglide-x" => Arc::new(oxglide::OxGlide::from_description(
            oxglide::Form::Crossed,
            d,
            origin,
        )?),
        "oxglide-o" => Arc::new(oxglide::OxGlide::from_description(
            oxglide::Form::Extended,
            d,
            origin,
        )?),
        "rfmt5" => Arc::new(rfmt5::Rfmt5::from_description(d, origin)?),
        "corexy" => Arc::new(corexy::CoreXy::from_description(d, origin)?),
        other => {
            return Err(MachineError::Key {
                origin: origin.to_string(),
                key: "kinematics".into(),
                reason: format!(
                    "unknown kinematics {other:?}; known: {}",
                    KINEMATICS.join(", ")
                ),
            })
        }
    };
    kinematics
        .check_pose(&d.home())
        .map_err(|e| MachineError::Key {
            origin: origin.to_string(),
            key: "home".into(),
            reason: format!(
                "the machine cannot start there: {}",
                e.describe(&*kinematics)
            ),
        })?;
    Ok(Machine {
        description,
        kinematics,
        origin: origin.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use kerf_interp::Axis;

    #[test]
    fn embedded_mill3_has_the_promised_travel() {
        let m = load("mill3").unwrap();
        let travel: Vec<(Axis, f64, f64)> = m
            .kinematics
            .axes()
            .iter()
            .map(|a| (a.axis, a.limits.min, a.limits.max))
            .collect();
        assert_eq!(
            travel,
            vec![
                (Axis::X, 0.0, 300.0),
                (Axis::Y, 0.0, 200.0),
                (Axis::Z, -100.0, 0.0)
            ]
        );
        assert_eq!(m.kinematics.joints().len(), 3);
        assert_eq!(
            m.description.hal.get("backend").and_then(|v| v.as_str()),
            Some("sim")
        );
    }

    #[test]
    fn unknown_name_lists_the_known_ones() {
        let e = load("nosuch").unwrap_err().to_string();
        assert!(e.contains("nosuch") && e.contains("mill3"), "{e}");
    }

    fn embedded(name: &str) -> &'static str {
        EMBEDDED.iter().find(|(n, _)| *n == name).unwrap().1
    }

    #[test]
    fn every_embedded_machine_loads_and_starts_at_home() {
        for (name, _) in EMBEDDED {
            let m = load(name).unwrap();
            assert_eq!(m.description.name, *name);
            m.kinematics.check_pose(&m.home()).unwrap();
        }
        assert_eq!(load("mill3").unwrap().home(), kerf_interp::Position::ZERO);
        let ox = load("oxglide-x").unwrap().home();
        assert_eq!((ox.x, ox.y, ox.z), (250.0, 0.0, -300.0));
    }

    #[test]
    fn dimension_errors_name_the_key() {
        let text = embedded("oxglide-x");
        let typo = text.replacen("l2 = 432.0", "l3 = 432.0", 1);
        assert_eq!(
            from_toml(&typo, "ox.toml").unwrap_err().to_string(),
            "ox.toml: key `dimensions.l3`: not a dimension of oxglide-x kinematics \
             (it has l1, l2, p1, p2, d)"
        );
        let missing = text.replacen("d = 74.0\n", "", 1);
        assert_eq!(
            from_toml(&missing, "ox.toml").unwrap_err().to_string(),
            "ox.toml: key `dimensions.d`: missing: oxglide-x kinematics needs it"
        );
        let negative = embedded("rfmt5").replacen("rod_length = 250.0", "rod_length = -250.0", 1);
        assert_eq!(
            from_toml(&negative, "r.toml").unwrap_err().to_string(),
            "r.toml: key `dimensions.rod_length`: must be greater than zero, got -250"
        );
    }

    #[test]
    fn layout_and_home_errors_name_the_key() {
        let text = embedded("oxglide-x");
        let two_joints = text.replacen("[[joints]]\nname = \"s3\"", "[extra]\nname = \"s3\"", 1);
        let e = from_toml(&two_joints, "ox.toml").unwrap_err().to_string();
        assert!(e.starts_with("ox.toml: "), "{e}");
        let unknown_kins = text.replacen("kinematics = \"oxglide-x\"", "kinematics = \"scara\"", 1);
        let e = from_toml(&unknown_kins, "ox.toml").unwrap_err().to_string();
        assert!(
            e.contains("`kinematics`") && e.contains("scara") && e.contains("rfmt5"),
            "{e}"
        );
        let no_a = embedded("rfmt5")
            .replacen("[axes.a]", "[axes.c]", 1)
            .replacen("a = 0.0\n", "", 1);
        let e = from_toml(&no_a, "r.toml").unwrap_err().to_string();
        assert_eq!(
            e,
            "r.toml: key `axes`: rfmt5 kinematics needs exactly the axes x y z a b, found x y z b c"
        );
        // The origin, where kerfd used to start every machine, is out of
        // the O-X glide's reach.
        let at_origin = text.replacen("z = -300.0", "z = 0.0", 1);
        let e = from_toml(&at_origin, "ox.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("ox.toml: key `home`: the machine cannot start there: "),
            "{e}"
        );
        let bad_axis = text.replacen("y = 0.0\nz = -300.0", "y = 0.0\nz = -300.0\na = 1.0", 1);
        let e = from_toml(&bad_axis, "ox.toml").unwrap_err().to_string();
        assert_eq!(e, "ox.toml: key `home.a`: not one of this machine's [axes]");
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = load("/nonexistent/m.toml").unwrap_err().to_string();
        assert!(e.contains("/nonexistent/m.toml"), "{e}");
    }
}
