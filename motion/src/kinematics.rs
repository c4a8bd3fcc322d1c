//! The machine kinematics seam: tool pose ↔ joint positions, with limits.
//!
//! A pose is a [`Position`] in machine coordinates (mm, and degrees for
//! rotary axes, as in the canon stream); implementations convert degrees to
//! radians internally. Joint positions are in the joint's own units (mm for
//! linear drives, degrees for rotary ones).
//!
//! Both directions write into caller-provided storage and return errors that
//! do not allocate, so the servo tick can call them.

use kerf_interp::{Axis, Position};

/// Largest number of joints a machine may have.
pub const MAX_JOINTS: usize = 9;

/// Travel and dynamic limits of one axis or joint.
///
/// Units: mm, mm/s, mm/s², mm/s³ (degrees, deg/s, deg/s², deg/s³ for
/// rotary ones).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    pub min: f64,
    pub max: f64,
    pub max_velocity: f64,
    pub max_acceleration: f64,
    /// Largest rate of change of acceleration.
    pub max_jerk: f64,
}

impl Limits {
    /// Jerk limit used when a machine description gives none: full
    /// acceleration is reached in 20 ms.
    pub fn default_jerk(max_acceleration: f64) -> f64 {
        50.0 * max_acceleration
    }

    /// True if `value` lies within `min..=max`, allowing `slack` either side.
    pub fn contains(&self, value: f64, slack: f64) -> bool {
        value >= self.min - slack && value <= self.max + slack
    }
}

/// One Cartesian axis of the machine with its travel and dynamics.
#[derive(Clone, Debug, PartialEq)]
pub struct AxisSpec {
    pub axis: Axis,
    pub limits: Limits,
}

/// One joint (drive) of the machine, in joint order.
#[derive(Clone, Debug, PartialEq)]
pub struct JointSpec {
    /// Short name used in messages and status, e.g. `x`, `s1`.
    pub name: String,
    pub limits: Limits,
}

/// Why a pose or joint vector is not acceptable. Does not allocate.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum KinematicsError {
    /// A joint position lies outside its stroke.
    #[error("joint {joint} at {value:.4} is outside its stroke {min:.4} .. {max:.4}")]
    JointOutOfRange {
        joint: usize,
        value: f64,
        min: f64,
        max: f64,
    },
    /// A pose coordinate lies outside the axis travel.
    #[error("axis {axis} at {value:.4} is outside its travel {min:.4} .. {max:.4}")]
    AxisOutOfRange {
        axis: Axis,
        value: f64,
        min: f64,
        max: f64,
    },
    /// The mechanism cannot reach the pose at all (e.g. a rod too short).
    #[error("pose unreachable: {reason}")]
    Unreachable { reason: &'static str },
    /// The pose or joint vector is at or too near a singular configuration.
    #[error("singular configuration: {reason}")]
    Singular { reason: &'static str },
    /// An iterative forward solution did not converge.
    #[error(
        "forward kinematics did not converge in {iterations} iterations (residual {residual:.3e})"
    )]
    NoConvergence { iterations: u32, residual: f64 },
    /// The caller passed a joint slice of the wrong length.
    #[error("expected {expected} joint values, got {got}")]
    JointCount { expected: usize, got: usize },
}

impl KinematicsError {
    /// A message naming the joint by its name on `kins` where it names one.
    pub fn describe(&self, kins: &dyn Kinematics) -> String {
        match *self {
            KinematicsError::JointOutOfRange {
                joint,
                value,
                min,
                max,
            } => {
                let name = kins
                    .joints()
                    .get(joint)
                    .map(|j| j.name.as_str())
                    .unwrap_or("?");
                format!("joint {name} at {value:.4} is outside its stroke {min:.4} .. {max:.4}")
            }
            other => other.to_string(),
        }
    }
}

/// A machine's kinematics: the mapping between tool pose and joints, and
/// the limits on both.
///
/// Implementations are pure functions of their dimensions: no I/O, no
/// allocation in [`inverse`](Kinematics::inverse) or
/// [`forward`](Kinematics::forward), so they can run in the servo tick.
pub trait Kinematics: Send + Sync {
    /// The kinematics' name, e.g. `trivial`, `oxglide-x`.
    fn name(&self) -> &str;

    /// The Cartesian axes this machine has, with their travel.
    fn axes(&self) -> &[AxisSpec];

    /// The joints in joint order, with their strokes and dynamics.
    fn joints(&self) -> &[JointSpec];

    /// Joint positions that put the tool at `pose`.
    ///
    /// `joints` must have exactly `self.joints().len()` elements. Errors if
    /// the pose is unreachable or singular; stroke limits are checked by
    /// [`check_pose`](Kinematics::check_pose), not here.
    fn inverse(&self, pose: &Position, joints: &mut [f64]) -> Result<(), KinematicsError>;

    /// The tool pose for joint positions `joints`. `seed` is a nearby pose
    /// (usually the last one) for kinematics that solve iteratively.
    fn forward(&self, joints: &[f64], seed: &Position) -> Result<Position, KinematicsError>;

    /// `Some(axis)` when joint `joint` moves exactly with one axis (joint
    /// position = axis position), as in trivial kinematics. The planner then
    /// applies that joint's limits to the axis directly instead of sampling
    /// the path through [`inverse`](Kinematics::inverse). When every joint
    /// does, it takes the reach to be the box of axis travel and joint
    /// strokes (corner blends are proven inside it), so such a machine's
    /// [`check_pose`](Kinematics::check_pose) must not refuse anything else.
    fn joint_axis(&self, _joint: usize) -> Option<Axis> {
        None
    }

    /// Check that `pose` is inside the axis travel, reachable, and that the
    /// joints it needs are inside their strokes.
    fn check_pose(&self, pose: &Position) -> Result<(), KinematicsError> {
        for spec in self.axes() {
            let value = pose.get(spec.axis);
            if !spec.limits.contains(value, LIMIT_SLACK) {
                return Err(KinematicsError::AxisOutOfRange {
                    axis: spec.axis,
                    value,
                    min: spec.limits.min,
                    max: spec.limits.max,
                });
            }
        }
        let n = self.joints().len();
        let mut q = [0.0; MAX_JOINTS];
        self.inverse(pose, &mut q[..n])?;
        check_joints(self.joints(), &q[..n])
    }
}

/// Rounding slack on limit checks, mm or degrees: positions that come from
/// inch conversion or incremental sums may land a few ulps past a limit.
pub const LIMIT_SLACK: f64 = 1e-9;

/// Check joint positions against their strokes.
pub fn check_joints(specs: &[JointSpec], joints: &[f64]) -> Result<(), KinematicsError> {
    for (i, (spec, &value)) in specs.iter().zip(joints).enumerate() {
        if !spec.limits.contains(value, LIMIT_SLACK) {
            return Err(KinematicsError::JointOutOfRange {
                joint: i,
                value,
                min: spec.limits.min,
                max: spec.limits.max,
            });
        }
    }
    Ok(())
}
