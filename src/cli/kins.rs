//! `kerf kins`: a machine's kinematics by hand — joints for a pose, or the
//! pose for joints — offline, without kerfd.

use kerf_interp::{Axis, Position};
use kerf_machines::Machine;
use kerf_motion::kinematics::{check_joints, MAX_JOINTS};
use serde_json::{json, Map, Value};

use super::Failure;

/// Which way to run the kinematics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Pose (X Y Z, then the machine's other axes) → joints.
    Inverse,
    /// Joints in joint order → pose.
    Forward,
}

/// What `kerf kins` is asked.
#[derive(Clone, Debug)]
pub struct Request {
    /// Embedded machine name or TOML path.
    pub machine: String,
    /// Inverse or forward.
    pub direction: Direction,
    /// The numbers as typed: pose coordinates (mm, degrees) or joints.
    pub values: Vec<String>,
    /// Print JSON instead of a table.
    pub json: bool,
    /// Skip the travel and stroke checks (reach and singularity still apply).
    pub no_limits: bool,
}

/// A solved request: named values in order.
enum Outcome {
    /// Joint name → position, in joint order.
    Joints(Vec<(String, f64)>),
    /// Axis → coordinate, in canonical axis order.
    Pose(Vec<(Axis, f64)>),
}

impl Outcome {
    fn to_json(&self) -> Value {
        match self {
            Outcome::Joints(joints) => {
                json!({ "joints": joints.iter().map(|(_, v)| *v).collect::<Vec<f64>>() })
            }
            Outcome::Pose(pose) => {
                let map: Map<String, Value> = pose
                    .iter()
                    .map(|(a, v)| (a.letter().to_ascii_lowercase().to_string(), json!(v)))
                    .collect();
                json!({ "pose": map })
            }
        }
    }

    fn print_table(&self) {
        let rows: Vec<(String, f64)> = match self {
            Outcome::Joints(joints) => joints.clone(),
            Outcome::Pose(pose) => pose.iter().map(|(a, v)| (a.to_string(), *v)).collect(),
        };
        for (name, v) in rows {
            println!("{name:<4} {v:>14.6}");
        }
    }
}

/// Run `kerf kins`: print the joints for a pose or the pose for joints.
///
/// Inverse takes X Y Z and then the machine's other axes in canonical order
/// (A B for rfmt5); axes left out are 0. Forward takes one value per joint
/// and starts iterative solvers from the machine's home pose. Unless
/// `no_limits`, the pose must lie in the travel and the joints in their
/// strokes. With `json`, errors are printed as `{"error": "..."}` on stdout.
pub fn kins(request: &Request) -> Result<(), Failure> {
    match solve(request) {
        Ok(outcome) if request.json => {
            println!("{}", outcome.to_json());
            Ok(())
        }
        Ok(outcome) => {
            outcome.print_table();
            Ok(())
        }
        Err(message) if request.json => {
            println!("{}", json!({ "error": message }));
            Err(Failure::new(String::new()))
        }
        Err(message) => Err(Failure::new(message)),
    }
}

/// Parse the typed numbers, naming the one that is not a finite number.
fn numbers(values: &[String]) -> Result<Vec<f64>, String> {
    values
        .iter()
        .enumerate()
        .map(|(i, text)| match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("value {} ({text:?}) is not a finite number", i + 1)),
        })
        .collect()
}

fn solve(request: &Request) -> Result<Outcome, String> {
    let machine: Machine = kerf_machines::load(&request.machine).map_err(|e| e.to_string())?;
    let kins = &*machine.kinematics;
    let values = numbers(&request.values)?;
    let axes: Vec<Axis> = kins.axes().iter().map(|a| a.axis).collect();
    let n = kins.joints().len();
    let describe = |e: kerf_motion::KinematicsError| e.describe(kins);
    match request.direction {
        Direction::Inverse => {
            let fewest = axes.len().min(3);
            if values.len() < fewest || values.len() > axes.len() {
                let letters: Vec<String> = axes.iter().map(|a| a.to_string()).collect();
                let count = if fewest == axes.len() {
                    fewest.to_string()
                } else {
                    format!("{fewest} to {}", axes.len())
                };
                return Err(format!(
                    "inverse takes {count} values ({}), got {}",
                    letters.join(" "),
                    values.len()
                ));
            }
            let mut pose = Position::ZERO;
            for (axis, v) in axes.iter().zip(&values) {
                pose.set(*axis, *v);
            }
            let mut q = [0.0; MAX_JOINTS];
            kins.inverse(&pose, &mut q[..n]).map_err(describe)?;
            if !request.no_limits {
                kins.check_pose(&pose).map_err(describe)?;
            }
            Ok(Outcome::Joints(
                kins.joints()
                    .iter()
                    .zip(&q[..n])
                    .map(|(j, v)| (j.name.clone(), *v))
                    .collect(),
            ))
        }
        Direction::Forward => {
            if values.len() != n {
                let names: Vec<&str> = kins.joints().iter().map(|j| j.name.as_str()).collect();
                return Err(format!(
                    "forward takes {n} joint values ({}), got {}",
                    names.join(" "),
                    values.len()
                ));
            }
            if !request.no_limits {
                check_joints(kins.joints(), &values).map_err(describe)?;
            }
            let pose = kins.forward(&values, &machine.home()).map_err(describe)?;
            if !request.no_limits {
                kins.check_pose(&pose).map_err(describe)?;
            }
            Ok(Outcome::Pose(
                axes.iter().map(|a| (*a, pose.get(*a))).collect(),
            ))
        }
    }
}
