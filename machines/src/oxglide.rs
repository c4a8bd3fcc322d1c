//! O-X glide: a planar parallel mechanism in the XZ plane on a serial Y
//! slider (Živanović et al., Machine Design 8(4), 2016).
//!
//! Frame of the paper: slider s1 runs along z = −d, slider s2 along z = +d,
//! both from x = 0; the tool point P(x, z) hangs below them. Rod l1 joins
//! slider 1 to the platform joint at P − (p1, 0), rod l2 joins slider 2 to
//! P + (p2, 0). The serial slider s3 carries the whole mechanism, so y = s3.
//!
//! With w1 = √(l1² − (z + d)²) and w2 = √(l2² − (z − d)²) (the rods'
//! horizontal extents), the inverse is
//!
//! * crossed form (eqs. 7–8):  s1 = x − p1 + w1,  s2 = x + p2 − w2
//! * extended form (eqs. 9–10): s1 = x − p1 − w1,  s2 = x + p2 + w2
//!
//! The direct kinematics are eqs. (12)–(15) with the scans' typos fixed:
//! subtracting the two rod equations gives the line x = m3 + m4·z, and
//! putting that into the rod-1 equation (5) gives m5·z² + m6·z + m7 = 0 with
//! m5 = 1 + m4². Its two roots are the two places where the rod circles
//! around (s1 + p1, −d) and (s2 − p2, d) meet, mirror images across the line
//! through those centres. Both forms work with P below that line, which is
//! the lower root; the paper's choice of sign in eq. (15) holds for both.
//! Poses above the line belong to the other assembly mode and are refused,
//! so that forward and inverse stay each other's inverse.

use kerf_interp::{Axis, Position};
use kerf_motion::kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError};

use crate::description::{Description, MachineError};
use crate::{check_joint_input, check_pose_input};

/// Which way the two rods are assembled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// X form: each slider lies beyond the other rod's platform joint, so
    /// the rods cross (eqs. 7–8).
    Crossed,
    /// O form: each slider lies on its own side, the rods splay (eqs. 9–10).
    Extended,
}

impl Form {
    /// Signs of the rods' horizontal extents (slider x minus platform joint
    /// x, as a multiple of w1 and w2).
    fn signs(self) -> (f64, f64) {
        match self {
            Form::Crossed => (1.0, -1.0),
            Form::Extended => (-1.0, 1.0),
        }
    }
}

/// Dimensions of the O-X glide mechanism, mm (the paper's names).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dimensions {
    /// Rod from slider 1 (on z = −d), mm.
    pub l1: f64,
    /// Rod from slider 2 (on z = +d), mm.
    pub l2: f64,
    /// Platform joint 1 lies `p1` to the left of P, mm.
    pub p1: f64,
    /// Platform joint 2 lies `p2` to the right of P, mm.
    pub p2: f64,
    /// Half the vertical distance between the two slider guides, mm.
    pub d: f64,
}

/// The dimension keys of `[dimensions]` for O-X glide machines.
pub const DIMENSION_KEYS: [&str; 5] = ["l1", "l2", "p1", "p2", "d"];

/// A rod closer than this fraction of its length to vertical (horizontal
/// extent w below `SINGULAR_FRACTION · l`) is treated as singular: there the
/// two forms meet, and a slider moves ≥ 1/`SINGULAR_FRACTION` times faster
/// than the tool in z. The same bound on the sine of the angle between the
/// rods guards the direct singularity where the rods line up.
pub const SINGULAR_FRACTION: f64 = 1e-6;

/// O-X glide kinematics in one form. Joints [s1, s2, s3], pose (x, y, z).
#[derive(Clone, Debug)]
pub struct OxGlide {
    form: Form,
    dims: Dimensions,
    axes: Vec<AxisSpec>,
    joints: Vec<JointSpec>,
}

/// The rods' horizontal extents w1, w2 at height `z`, after checking reach,
/// the vertical-rod singularity and the assembly mode.
fn rod_extents(dims: &Dimensions, z: f64) -> Result<(f64, f64), KinematicsError> {
    let w1_sq = dims.l1 * dims.l1 - (z + dims.d) * (z + dims.d);
    let w2_sq = dims.l2 * dims.l2 - (z - dims.d) * (z - dims.d);
    if w1_sq < 0.0 {
        return Err(KinematicsError::Unreachable {
            reason: "rod l1 is too short: |z + d| > l1",
        });
    }
    if w2_sq < 0.0 {
        return Err(KinematicsError::Unreachable {
            reason: "rod l2 is too short: |z - d| > l2",
        });
    }
    let (w1, w2) = (w1_sq.sqrt(), w2_sq.sqrt());
    if w1 < SINGULAR_FRACTION * dims.l1 {
        return Err(KinematicsError::Singular {
            reason: "rod l1 is vertical, where the crossed and extended forms meet",
        });
    }
    if w2 < SINGULAR_FRACTION * dims.l2 {
        return Err(KinematicsError::Singular {
            reason: "rod l2 is vertical, where the crossed and extended forms meet",
        });
    }
    // Twice the signed area spanned by the rods, seen from P: positive when
    // P lies below the line through the slider-side pivots. It is the same
    // expression for both forms (the signs of w1 and w2 cancel).
    let spread = w1 * (dims.d - z) - w2 * (z + dims.d);
    if spread < -SINGULAR_FRACTION * dims.l1 * dims.l2 {
        return Err(KinematicsError::Unreachable {
            reason: "the platform would be above the line through the rod pivots \
                     (the other assembly mode)",
        });
    }
    if spread < SINGULAR_FRACTION * dims.l1 * dims.l2 {
        return Err(KinematicsError::Singular {
            reason: "rods l1 and l2 are in line (direct singularity)",
        });
    }
    Ok((w1, w2))
}

impl OxGlide {
    /// Build from a description: axes x y z, joints [s1, s2, s3], and the
    /// dimensions l1 l2 p1 p2 d (all > 0).
    pub fn from_description(
        form: Form,
        desc: &Description,
        origin: &str,
    ) -> Result<OxGlide, MachineError> {
        let name = match form {
            Form::Crossed => "oxglide-x",
            Form::Extended => "oxglide-o",
        };
        desc.expect_layout(
            origin,
            name,
            &[Axis::X, Axis::Y, Axis::Z],
            3,
            &DIMENSION_KEYS,
        )?;
        let dims = Dimensions {
            l1: desc.positive_dimension(origin, "l1")?,
            l2: desc.positive_dimension(origin, "l2")?,
            p1: desc.positive_dimension(origin, "p1")?,
            p2: desc.positive_dimension(origin, "p2")?,
            d: desc.positive_dimension(origin, "d")?,
        };
        Ok(OxGlide {
            form,
            dims,
            axes: desc.axis_specs(),
            joints: desc.joint_specs(),
        })
    }

    /// The form this machine is assembled in.
    pub fn form(&self) -> Form {
        self.form
    }

    /// The mechanism's dimensions.
    pub fn dimensions(&self) -> Dimensions {
        self.dims
    }
}

impl Kinematics for OxGlide {
    fn name(&self) -> &str {
        match self.form {
            Form::Crossed => "oxglide-x",
            Form::Extended => "oxglide-o",
        }
    }

    fn axes(&self) -> &[AxisSpec] {
        &self.axes
    }

    fn joints(&self) -> &[JointSpec] {
        &self.joints
    }

    fn inverse(&self, pose: &Position, joints: &mut [f64]) -> Result<(), KinematicsError> {
        check_pose_input(pose, &self.axes, joints.len(), 3)?;
        let Dimensions { p1, p2, .. } = self.dims;
        let (w1, w2) = rod_extents(&self.dims, pose.z)?;
        let (sign1, sign2) = self.form.signs();
        joints[0] = pose.x - p1 + sign1 * w1;
        joints[1] = pose.x + p2 + sign2 * w2;
        joints[2] = pose.y;
        Ok(())
    }

    fn forward(&self, joints: &[f64], _seed: &Position) -> Result<Position, KinematicsError> {
        check_joint_input(joints, 3)?;
        let Dimensions { l1, l2, p1, p2, d } = self.dims;
        let (s1, s2) = (joints[0], joints[1]);
        // Eq. (12): the rod equations (5) minus (6) give a line in x and z.
        let m1 = s2 - s1 - p1 - p2;
        let m2 = (s1 + p1) * (s1 + p1) - (s2 - p2) * (s2 - p2) - l1 * l1 + l2 * l2;
        // m1 = −(w1 + w2) in the crossed form and +(w1 + w2) in the extended
        // one, so its sign tells which form these joints can belong to.
        let (sign1, sign2) = self.form.signs();
        if m1 * sign1 >= 0.0 {
            return Err(KinematicsError::Unreachable {
                reason: "sliders s1 and s2 are in the wrong order for this form",
            });
        }
        // Eq. (13).
        let m3 = -m2 / (2.0 * m1);
        let m4 = -2.0 * d / m1;
        // Eq. (14), from x = m3 + m4·z put into eq. (5).
        let c = s1 + p1 - m3;
        let m5 = 1.0 + m4 * m4;
        let m6 = 2.0 * d - 2.0 * m4 * c;
        let m7 = c * c + d * d - l1 * l1;
        let disc = m6 * m6 - 4.0 * m5 * m7;
        if disc < 0.0 {
            return Err(KinematicsError::Unreachable {
                reason: "the rods cannot meet: sliders s1 and s2 are too far apart",
            });
        }
        // Eq. (15), lower root, in the form that does not cancel digits.
        let q = -0.5 * (m6 + m6.signum() * disc.sqrt());
        let z = if q == 0.0 { 0.0 } else { (q / m5).min(m7 / q) };
        let x = m3 + m4 * z;
        rod_extents(&self.dims, z)?;
        // The root is only this form's if each slider is on its side.
        if (s1 + p1 - x) * sign1 <= 0.0 || (s2 - p2 - x) * sign2 <= 0.0 {
            return Err(KinematicsError::Unreachable {
                reason: "these slider positions assemble the mechanism in the other form",
            });
        }
        Ok(Position {
            x,
            y: joints[2],
            z,
            ..Position::ZERO
        })
    }
}
