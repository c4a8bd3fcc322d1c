//! rfmt5: the reconfigurable five-axis machine tool of Cheng and Lin
//! (Sensors and Materials 32(11), 2020): a three-column parallel head that
//! sets the height and tilt of the spindle, over an X–Y table, with
//! tool-centre-point control done here in real time.
//!
//! # Frame
//!
//! Machine coordinates are right-handed with Z up and Z = 0 on the table
//! top. The paper measures z downward from the base plate; its frame is
//! ours turned half a turn about X, so its y is our −Y, its depth is
//! `base_height − Z`, its α is our A and its β is our −B. The columns stand
//! at radius `base_radius` at angles ψ = 0°, −120°, +120° (the paper's
//! θ = 0°, 120°, 240° seen from our side) for joints l1, l2, l3.
//!
//! # Equations as implemented
//!
//! Program pose: tool tip X Y Z (mm, relative to the table), tool tilt A B
//! (degrees). With a = A, b = B in radians and R = R_y(b)·R_x(a) (eq. 6 in
//! our frame), the spindle axis is k = R·ẑ = (cos a sin b, −sin a, cos a cos b)
//! and the tool tip sits `tool_length` (TL) below the platform centre C
//! along k (eqs. 13–17):
//!
//! * platform centre height  Zc = Z + TL·cos a·cos b                (eq. 20)
//! * table joints  x = X + TL·cos a·sin b,  y = Y − TL·sin a       (eqs. 18–19)
//!
//! The table moves the work so that the tip, displaced by −TL·k from the
//! platform centre, still lands on X Y: that is the tool-centre-point
//! compensation the paper did in a post-processor.
//!
//! Platform joint i is Uᵢ = (0, 0, Zc) + R·r·(cos ψᵢ, sin ψᵢ, 0) (eq. 7); its
//! slider at (R_b cos ψᵢ, R_b sin ψᵢ, base_height − lᵢ) hangs rod D above it
//! (eqs. 10–12), so the slider's extension below the base plate is
//!
//! * lᵢ = base_height − Uᵢz − √(D² − (Uᵢx − R_b cos ψᵢ)² − (Uᵢy − R_b sin ψᵢ)²)
//!
//! The platform centre stays on the machine's vertical axis without turning
//! about it, as the paper models it. Joints are [x, y, l1, l2, l3].
//!
//! Forward kinematics solve the three leg equations for (Zc, a, b) by Newton
//! iteration from the seed pose, with an analytic Jacobian.

use kerf_interp::{Axis, Position};
use kerf_motion::kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError};
use nalgebra::{Matrix3, Vector3};

use crate::description::{Description, MachineError};
use crate::{check_joint_input, check_pose_input};

/// Dimensions of the rfmt5 head, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dimensions {
    /// Radius of the circle the three columns stand on (the paper's R), mm.
    pub base_radius: f64,
    /// Radius of the circle of platform joints (the paper's r), mm.
    pub platform_radius: f64,
    /// Length of each rod (the paper's D), mm.
    pub rod_length: f64,
    /// Platform centre to tool tip (the paper's TL), mm.
    pub tool_length: f64,
    /// Height of the base plate (slider zero) above the table top, mm.
    pub base_height: f64,
}

/// The dimension keys of `[dimensions]` for rfmt5 machines.
pub const DIMENSION_KEYS: [&str; 5] = [
    "base_radius",
    "platform_radius",
    "rod_length",
    "tool_length",
    "base_height",
];

/// Column angles ψᵢ of joints l1, l2, l3 in the machine frame, degrees.
pub const COLUMN_ANGLES_DEG: [f64; 3] = [0.0, -120.0, 120.0];

/// A rod whose vertical extent falls below this fraction of its length is
/// horizontal enough to call singular: its slider would have to move
/// 1/`SINGULAR_FRACTION` times faster than the platform.
pub const SINGULAR_FRACTION: f64 = 1e-6;

/// Forward kinematics accept a solution whose legs match the joints within
/// this many mm. It is ten times below the 1e-9 mm the controller promises
/// for a joint round trip, and a hundred times above the rounding noise of
/// a leg length near 500 mm (≈ 1e-13 mm).
pub const FORWARD_TOLERANCE: f64 = 1e-10;

/// Newton iterations before forward kinematics give up. From the last
/// servo pose two suffice; from a level-platform guess about six.
pub const FORWARD_MAX_ITERATIONS: u32 = 30;

const ROD_TOO_SHORT: [&str; 3] = [
    "rod of l1 cannot reach its column",
    "rod of l2 cannot reach its column",
    "rod of l3 cannot reach its column",
];
const ROD_HORIZONTAL: [&str; 3] = [
    "rod of l1 is horizontal",
    "rod of l2 is horizontal",
    "rod of l3 is horizontal",
];

/// rfmt5 kinematics. Joints [x, y, l1, l2, l3]; pose X Y Z A B.
#[derive(Clone, Debug)]
pub struct Rfmt5 {
    dims: Dimensions,
    /// Column i's foot (x, y), mm.
    columns: [[f64; 2]; 3],
    /// Platform joint i in the platform frame, mm.
    platform: [Vector3<f64>; 3],
    axes: Vec<AxisSpec>,
    joints: Vec<JointSpec>,
}

/// R_y(b)·R_x(a), as sines and cosines of a and b.
fn rotation(sa: f64, ca: f64, sb: f64, cb: f64) -> Matrix3<f64> {
    #[rustfmt::skip]
    let r = Matrix3::new(
        cb,  sb * sa, sb * ca,
        0.0, ca,      -sa,
        -sb, cb * sa, cb * ca,
    );
    r
}

/// ∂R/∂a and ∂R/∂b of [`rotation`].
fn rotation_derivatives(sa: f64, ca: f64, sb: f64, cb: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    #[rustfmt::skip]
    let dr_da = Matrix3::new(
        0.0, sb * ca,  -sb * sa,
        0.0, -sa,      -ca,
        0.0, cb * ca,  -cb * sa,
    );
    #[rustfmt::skip]
    let dr_db = Matrix3::new(
        -sb, cb * sa,  cb * ca,
        0.0, 0.0,      0.0,
        -cb, -sb * sa, -sb * ca,
    );
    (dr_da, dr_db)
}

impl Rfmt5 {
    /// Build from a description: axes x y z a b, joints [x, y, l1, l2, l3],
    /// and the dimensions of [`DIMENSION_KEYS`] (all > 0).
    pub fn from_description(desc: &Description, origin: &str) -> Result<Rfmt5, MachineError> {
        desc.expect_layout(
            origin,
            "rfmt5",
            &[Axis::X, Axis::Y, Axis::Z, Axis::A, Axis::B],
            5,
            &DIMENSION_KEYS,
        )?;
        let dims = Dimensions {
            base_radius: desc.positive_dimension(origin, "base_radius")?,
            platform_radius: desc.positive_dimension(origin, "platform_radius")?,
            rod_length: desc.positive_dimension(origin, "rod_length")?,
            tool_length: desc.positive_dimension(origin, "tool_length")?,
            base_height: desc.positive_dimension(origin, "base_height")?,
        };
        Ok(Rfmt5::new(dims, desc.axis_specs(), desc.joint_specs()))
    }

    /// A machine with these dimensions and limits.
    pub fn new(dims: Dimensions, axes: Vec<AxisSpec>, joints: Vec<JointSpec>) -> Rfmt5 {
        let at = |i: usize, radius: f64| {
            let (s, c) = COLUMN_ANGLES_DEG[i].to_radians().sin_cos();
            [radius * c, radius * s]
        };
        let columns = [0, 1, 2].map(|i| at(i, dims.base_radius));
        let platform = [0, 1, 2].map(|i| {
            let [x, y] = at(i, dims.platform_radius);
            Vector3::new(x, y, 0.0)
        });
        Rfmt5 {
            dims,
            columns,
            platform,
            axes,
            joints,
        }
    }

    /// The head's dimensions.
    pub fn dimensions(&self) -> Dimensions {
        self.dims
    }

    /// Slider extensions l1..l3 for the platform v = (centre height Zc mm,
    /// tilt a, b radians); with `jacobian`, also ∂l/∂(Zc, a, b) row by row
    /// (forward kinematics need it, inverse kinematics do not).
    fn legs(
        &self,
        v: &Vector3<f64>,
        jacobian: Option<&mut Matrix3<f64>>,
    ) -> Result<Vector3<f64>, KinematicsError> {
        let (zc, a, b) = (v[0], v[1], v[2]);
        let (sa, ca) = a.sin_cos();
        let (sb, cb) = b.sin_cos();
        let r = rotation(sa, ca, sb, cb);
        let derivatives = jacobian
            .is_some()
            .then(|| rotation_derivatives(sa, ca, sb, cb));
        let rod = self.dims.rod_length;
        let mut legs = Vector3::zeros();
        let mut jac = Matrix3::zeros();
        for i in 0..3 {
            let p = &self.platform[i];
            let u = r * p;
            let dx = u.x - self.columns[i][0];
            let dy = u.y - self.columns[i][1];
            let w_sq = rod * rod - dx * dx - dy * dy;
            if w_sq < 0.0 {
                return Err(KinematicsError::Unreachable {
                    reason: ROD_TOO_SHORT[i],
                });
            }
            let w = w_sq.sqrt();
            if w < SINGULAR_FRACTION * rod {
                return Err(KinematicsError::Singular {
                    reason: ROD_HORIZONTAL[i],
                });
            }
            legs[i] = self.dims.base_height - (zc + u.z) - w;
            if let Some((dr_da, dr_db)) = &derivatives {
                // ∂l/∂q = −∂Uz/∂q + (dx ∂Ux/∂q + dy ∂Uy/∂q) / w
                let du_da = dr_da * p;
                let du_db = dr_db * p;
                jac[(i, 0)] = -1.0;
                jac[(i, 1)] = -du_da.z + (dx * du_da.x + dy * du_da.y) / w;
                jac[(i, 2)] = -du_db.z + (dx * du_db.x + dy * du_db.y) / w;
            }
        }
        if let Some(out) = jacobian {
            *out = jac;
        }
        Ok(legs)
    }

    /// Platform centre height and tilt (radians) for a program pose.
    fn platform_of(&self, pose: &Position) -> Vector3<f64> {
        let (a, b) = (pose.a.to_radians(), pose.b.to_radians());
        Vector3::new(pose.z + self.dims.tool_length * a.cos() * b.cos(), a, b)
    }

    /// A level platform at the mean slider extension: the starting guess
    /// when the seed pose is no use.
    fn level_guess(&self, legs: &Vector3<f64>) -> Vector3<f64> {
        let reach = self.dims.base_radius - self.dims.platform_radius;
        let drop = (self.dims.rod_length.powi(2) - reach * reach)
            .max(0.0)
            .sqrt();
        Vector3::new(self.dims.base_height - legs.mean() - drop, 0.0, 0.0)
    }

    /// Newton iteration for the platform that gives slider extensions
    /// `target`, starting at `start` = (Zc, a, b).
    fn solve_platform(
        &self,
        target: &Vector3<f64>,
        start: Vector3<f64>,
    ) -> Result<Vector3<f64>, KinematicsError> {
        let mut v = start;
        let mut jac = Matrix3::zeros();
        let legs = self.legs(&v, Some(&mut jac))?;
        let mut residual = legs - target;
        let mut norm = residual.amax();
        let scale = self.dims.platform_radius * self.dims.platform_radius;
        for iteration in 1..=FORWARD_MAX_ITERATIONS {
            if norm == 0.0 {
                return Ok(v);
            }
            // The Jacobian's columns are mm/mm, mm/rad, mm/rad; its
            // determinant scales with r², so compare against that.
            if jac.determinant().abs() < SINGULAR_FRACTION * scale {
                return Err(KinematicsError::Singular {
                    reason: "the platform Jacobian is singular",
                });
            }
            let step = jac
                .lu()
                .solve(&-residual)
                .ok_or(KinematicsError::Singular {
                    reason: "the platform Jacobian is singular",
                })?;
            // Backtrack along the Newton step until the residual drops; at
            // the rounding floor it cannot, and the solution is as good as
            // f64 gets.
            let mut fraction = 1.0;
            loop {
                let candidate = v + step * fraction;
                let mut j = Matrix3::zeros();
                if let Ok(legs) = self.legs(&candidate, Some(&mut j)) {
                    let r = legs - target;
                    if r.amax() < norm {
                        v = candidate;
                        residual = r;
                        norm = r.amax();
                        jac = j;
                        break;
                    }
                }
                if norm <= FORWARD_TOLERANCE {
                    return Ok(v);
                }
                fraction *= 0.5;
                if fraction < 1e-4 {
                    return Err(KinematicsError::NoConvergence {
                        iterations: iteration,
                        residual: norm,
                    });
                }
            }
        }
        if norm <= FORWARD_TOLERANCE {
            Ok(v)
        } else {
            Err(KinematicsError::NoConvergence {
                iterations: FORWARD_MAX_ITERATIONS,
                residual: norm,
            })
        }
    }
}

impl Kinematics for Rfmt5 {
    fn name(&self) -> &str {
        "rfmt5"
    }

    fn axes(&self) -> &[AxisSpec] {
        &self.axes
    }

    fn joints(&self) -> &[JointSpec] {
        &self.joints
    }

    fn inverse(&self, pose: &Position, joints: &mut [f64]) -> Result<(), KinematicsError> {
        check_pose_input(pose, &self.axes, joints.len(), 5)?;
        let v = self.platform_of(pose);
        let legs = self.legs(&v, None)?;
        let (sa, ca) = v[1].sin_cos();
        let sb = v[2].sin();
        let tl = self.dims.tool_length;
        joints[0] = pose.x + tl * ca * sb;
        joints[1] = pose.y - tl * sa;
        joints[2] = legs[0];
        joints[3] = legs[1];
        joints[4] = legs[2];
        Ok(())
    }

    fn forward(&self, joints: &[f64], seed: &Position) -> Result<Position, KinematicsError> {
        check_joint_input(joints, 5)?;
        let target = Vector3::new(joints[2], joints[3], joints[4]);
        let from_seed = self.platform_of(seed);
        let solved = if from_seed.iter().all(|c| c.is_finite()) {
            self.solve_platform(&target, from_seed)
                .or_else(|_| self.solve_platform(&target, self.level_guess(&target)))
        } else {
            self.solve_platform(&target, self.level_guess(&target))
        }?;
        let (zc, a, b) = (solved[0], solved[1], solved[2]);
        let (sa, ca) = a.sin_cos();
        let (sb, cb) = b.sin_cos();
        let tl = self.dims.tool_length;
        Ok(Position {
            x: joints[0] - tl * ca * sb,
            y: joints[1] + tl * sa,
            z: zc - tl * ca * cb,
            a: a.to_degrees(),
            b: b.to_degrees(),
            ..Position::ZERO
        })
    }
}
