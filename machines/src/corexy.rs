//! CoreXY: two motors drive one crossed belt that moves the head in X and
//! Y; Z is its own drive. Shown here as the smallest non-trivial mapping.
//!
//! Motor positions are the belt lengths paid out, in mm of belt:
//! a = x + y, b = x − y, and back x = (a + b) / 2, y = (a − b) / 2.
//! Joints `[a, b, z]`; pose (x, y, z). No dimensions.

use kerf_interp::{Axis, Position};
use kerf_motion::kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError};

use crate::description::{Description, MachineError};
use crate::{check_joint_input, check_pose_input};

/// CoreXY kinematics. Joints [a, b, z]; pose x y z.
#[derive(Clone, Debug)]
pub struct CoreXy {
    axes: Vec<AxisSpec>,
    joints: Vec<JointSpec>,
}

impl CoreXy {
    /// Build from a description: axes x y z, three joints, no dimensions.
    pub fn from_description(desc: &Description, origin: &str) -> Result<CoreXy, MachineError> {
        desc.expect_layout(origin, "corexy", &[Axis::X, Axis::Y, Axis::Z], 3, &[])?;
        Ok(CoreXy {
            axes: desc.axis_specs(),
            joints: desc.joint_specs(),
        })
    }
}

impl Kinematics for CoreXy {
    fn name(&self) -> &str {
        "corexy"
    }

    fn axes(&self) -> &[AxisSpec] {
        &self.axes
    }

    fn joints(&self) -> &[JointSpec] {
        &self.joints
    }

    fn inverse(&self, pose: &Position, joints: &mut [f64]) -> Result<(), KinematicsError> {
        check_pose_input(pose, &self.axes, joints.len(), 3)?;
        joints[0] = pose.x + pose.y;
        joints[1] = pose.x - pose.y;
        joints[2] = pose.z;
        Ok(())
    }

    fn forward(&self, joints: &[f64], _seed: &Position) -> Result<Position, KinematicsError> {
        check_joint_input(joints, 3)?;
        Ok(Position::xyz(
            0.5 * (joints[0] + joints[1]),
            0.5 * (joints[0] - joints[1]),
            joints[2],
        ))
    }
}
