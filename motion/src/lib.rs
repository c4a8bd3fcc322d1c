//! kerf-motion: from canon to a trajectory sampled once per servo period.
//!
//! * [`kinematics`]: the [`Kinematics`] trait every machine implements
//!   (tool pose ↔ joint positions, plus limits).
//! * [`plan`]: the planner, which turns [`kerf_interp::Canon`] into
//!   [`Segment`]s with velocity profiles. It runs ahead of the machine and may
//!   allocate.
//! * [`exec`]: the [`Executor`], which advances along planned segments one
//!   servo period at a time. It is real-time safe: no allocation, no locks,
//!   no I/O.

pub mod exec;
pub mod kinematics;
pub mod plan;
pub mod profile;

pub use exec::{Executor, Sample};
pub use kinematics::{AxisSpec, JointSpec, Kinematics, KinematicsError, Limits, MAX_JOINTS};
pub use plan::{PlanError, Planner, Segment, SegmentKind};
pub use profile::Trapezoid;
