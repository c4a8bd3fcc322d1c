//! Trivial kinematics: each joint drives one Cartesian axis directly.
//!
//! Any axis-to-joint mapping is allowed, including a gantry where two joints
//! drive the same axis. Forward kinematics reads each axis from the first
//! joint that drives it.

use kerf_interp::{Axis, Position};
use kerf_motion::kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError};

use crate::description::{Description, MachineError};
use crate::{check_joint_input, check_pose_input};

/// Joint i = axis `map[i]`.
#[derive(Clone, Debug)]
pub struct Trivial {
    axes: Vec<AxisSpec>,
    joints: Vec<JointSpec>,
    map: Vec<Axis>,
}

impl Trivial {
    /// Build from a machine description: every joint names its `axis`, and
    /// every axis is driven by at least one joint.
    pub fn from_description(d: &Description, origin: &str) -> Result<Trivial, MachineError> {
        let key_err = |key: String, reason: String| MachineError::Key {
            origin: origin.to_string(),
            key,
            reason,
        };
        let axes: Vec<AxisSpec> = d
            .axis_limits()
            .into_iter()
            .map(|(axis, limits)| AxisSpec { axis, limits })
            .collect();
        let mut map = Vec::new();
        for (i, j) in d.joints.iter().enumerate() {
            let name = j.axis.as_deref().ok_or_else(|| {
                key_err(
                    format!("joints[{i}].axis"),
                    "trivial kinematics needs the axis each joint drives".into(),
                )
            })?;
            let axis = name
                .chars()
                .next()
                .filter(|_| name.len() == 1)
                .and_then(Axis::from_letter)
                .filter(|a| axes.iter().any(|s| s.axis == *a))
                .ok_or_else(|| {
                    key_err(
                        format!("joints[{i}].axis"),
                        format!("{name:?} is not one of this machine's [axes]"),
                    )
                })?;
            map.push(axis);
        }
        for spec in &axes {
            if !map.contains(&spec.axis) {
                return Err(key_err(
                    format!("axes.{}", spec.axis.letter().to_ascii_lowercase()),
                    "no joint drives this axis".into(),
                ));
            }
        }
        let joints = d
            .joints
            .iter()
            .map(|j| JointSpec {
                name: j.name.clone(),
                limits: j.limits(),
            })
            .collect();
        Ok(Trivial { axes, joints, map })
    }
}

impl Kinematics for Trivial {
    fn name(&self) -> &str {
        "trivial"
    }

    fn axes(&self) -> &[AxisSpec] {
        &self.axes
    }

    fn joints(&self) -> &[JointSpec] {
        &self.joints
    }

    fn joint_axis(&self, joint: usize) -> Option<Axis> {
        self.map.get(joint).copied()
    }

    fn inverse(&self, pose: &Position, joints: &mut [f64]) -> Result<(), KinematicsError> {
        check_pose_input(pose, &self.axes, joints.len(), self.map.len())?;
        for (q, axis) in joints.iter_mut().zip(&self.map) {
            *q = pose.get(*axis);
        }
        Ok(())
    }

    fn forward(&self, joints: &[f64], _seed: &Position) -> Result<Position, KinematicsError> {
        check_joint_input(joints, self.map.len())?;
        let mut p = [0.0; 9];
        // Reverse order so the first joint on an axis wins.
        for (q, axis) in joints.iter().zip(&self.map).rev() {
            p[axis.index()] = *q;
        }
        Ok(Position::from_array(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gantry_drives_both_joints_and_reads_back() {
        let text = crate::EMBEDDED[0].1.replacen(
            "[[joints]]\nname = \"y\"",
            "[[joints]]\nname = \"y2\"\naxis = \"y\"\nmin = 0.0\nmax = 200.0\nmax_velocity = 1.0\nmax_acceleration = 1.0\n\n[[joints]]\nname = \"y\"",
            1,
        );
        let m = crate::from_toml(&text, "gantry").unwrap();
        let k = &m.kinematics;
        assert_eq!(k.joints().len(), 4);
        let pose = Position::xyz(12.0, 34.0, -5.0);
        let mut q = [0.0; 4];
        k.inverse(&pose, &mut q).unwrap();
        assert_eq!(q, [12.0, 34.0, 34.0, -5.0]);
        assert_eq!(k.forward(&q, &Position::ZERO).unwrap(), pose);
    }

    #[test]
    fn check_pose_names_the_axis() {
        let m = crate::load("mill3").unwrap();
        let e = m
            .kinematics
            .check_pose(&Position::xyz(10.0, 10.0, 5.0))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "axis Z at 5.0000 is outside its travel -100.0000 .. 0.0000"
        );
        let e = m
            .kinematics
            .inverse(&Position::ZERO, &mut [0.0; 2])
            .unwrap_err();
        assert!(matches!(
            e,
            KinematicsError::JointCount {
                expected: 3,
                got: 2
            }
        ));
    }
}
