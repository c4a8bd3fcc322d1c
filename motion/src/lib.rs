//! kerf-motion: from canon to a trajectory sampled once per servo period.
//!
//! * [`kinematics`]: the [`Kinematics`] trait every machine implements
//!   (tool pose ↔ joint positions, plus limits).
//! * [`path`]: segment shapes (lines, arcs, corner blends) parametrised by
//!   arc length.
//! * [`plan`]: the planner, which turns [`kerf_interp::Canon`] into
//!   [`Segment`]s with their limits. It runs ahead of the machine and may
//!   allocate. In front of its line handling, [`merge`] joins runs of
//!   nearly collinear straight feeds into one line (G64 Q).
//! * [`exec`]: the [`Executor`], which advances along planned segments one
//!   servo period at a time with jerk-limited path speed. It is real-time
//!   safe: no allocation, no locks, no I/O.
//! * [`bound`]: a time-optimal lower bound on cycle time along a planned
//!   path, for benchmarks and tests only (not used by the controller).
//! * [`control`]: the per-joint position loop (PD + feedforward) the servo
//!   runs on the host; [`fuzzy`]: the cutting-force feed-override
//!   controller. Plain state and arithmetic, real-time safe.

// Numerical code over the nine axes indexes several parallel arrays by axis;
// iterator chains over four zipped arrays would read worse.
#![allow(clippy::needless_range_loop)]

pub mod bound;
pub mod control;
pub mod exec;
pub mod fuzzy;
pub mod kinematics;
pub mod merge;
pub mod offline;
pub mod path;
pub mod plan;
pub mod schedule;
#[cfg(test)]
mod testkit;

pub use exec::{Executor, Sample};
pub use kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError, Limits, MAX_JOINTS};
pub use plan::{
    InputRequest, OutputChange, PathMode, PlanError, Planner, PlannerConfig, Segment, SegmentKind,
    SourceMoves, SyncOutputs, MAX_ANALOG_OUTPUTS, MAX_DIGITAL_OUTPUTS,
};
