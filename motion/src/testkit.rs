//! A Cartesian test machine for the planner and executor tests, written
//! here so motion's tests do not lean on kerf-machines.

use kerf_interp::{Axis, Position};

use crate::kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError, Limits};

/// A seeded xorshift generator of uniform numbers in [0, 1), so random
/// tests repeat.
pub(crate) fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// X Y Z with each joint equal to its axis and the same limits everywhere.
pub(crate) struct Xyz {
    axes: Vec<AxisSpec>,
    joints: Vec<JointSpec>,
}

/// An XYZ machine with ±1000 mm travel and the given dynamics.
pub(crate) fn xyz(max_velocity: f64, max_acceleration: f64, max_jerk: f64) -> Xyz {
    let limits = Limits {
        min: -1000.0,
        max: 1000.0,
        max_velocity,
        max_acceleration,
        max_jerk,
    };
    Xyz {
        axes: [Axis::X, Axis::Y, Axis::Z]
            .iter()
            .map(|&axis| AxisSpec { axis, limits })
            .collect(),
        joints: ["x", "y", "z"]
            .iter()
            .map(|n| JointSpec {
                name: n.to_string(),
                limits,
            })
            .collect(),
    }
}

impl Kinematics for Xyz {
    fn name(&self) -> &str {
        "xyz"
    }
    fn axes(&self) -> &[AxisSpec] {
        &self.axes
    }
    fn joints(&self) -> &[JointSpec] {
        &self.joints
    }
    fn joint_axis(&self, j: usize) -> Option<Axis> {
        Some(Axis::ALL[j])
    }
    fn inverse(&self, p: &Position, q: &mut [f64]) -> Result<(), KinematicsError> {
        q.copy_from_slice(&[p.x, p.y, p.z]);
        Ok(())
    }
    fn forward(&self, q: &[f64], _: &Position) -> Result<Position, KinematicsError> {
        Ok(Position::xyz(q[0], q[1], q[2]))
    }
}
