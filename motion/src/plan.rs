//! The planner: canon commands into [`Segment`]s with velocity profiles.
//!
//! This first planner is deliberately simple: every move is an exact stop
//! (rest to rest) with a trapezoidal profile whose speed and acceleration are
//! the largest that keep every moving axis within its limits. Lookahead,
//! blending and jerk limits replace it without changing the [`Segment`] seam.

use kerf_interp::{Axis, Canon, CanonCmd, Position, Source};

use crate::kinematics::{Kinematics, Limits};
use crate::profile::Trapezoid;

/// What a segment does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentKind {
    /// G0: as fast as the axes allow.
    Rapid,
    /// G1: at the programmed feed rate or slower.
    Feed,
    /// G4: stand still.
    Dwell,
}

/// A planned piece of motion: a straight line from `start` to `end` (or a
/// dwell at `start`) along which `profile` gives the distance at each time.
///
/// `Copy` and allocation-free, so the servo thread can take and drop it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub kind: SegmentKind,
    /// Source line of the canon command that made this segment.
    pub line: u32,
    pub start: Position,
    pub end: Position,
    pub profile: Trapezoid,
}

impl Segment {
    /// Duration in seconds.
    pub fn duration(&self) -> f64 {
        self.profile.duration()
    }

    /// Tool position `t` seconds into the segment.
    pub fn position_at(&self, t: f64) -> Position {
        let length = self.profile.length;
        if length == 0.0 {
            return if t >= self.duration() {
                self.end
            } else {
                self.start
            };
        }
        let f = self.profile.distance_at(t) / length;
        if f >= 1.0 {
            return self.end;
        }
        let (a, b) = (self.start.to_array(), self.end.to_array());
        let mut p = [0.0; 9];
        for i in 0..9 {
            p[i] = a[i] + (b[i] - a[i]) * f;
        }
        Position::from_array(p)
    }
}

/// A move the planner refuses, with the source line that asked for it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{at}: {message}")]
pub struct PlanError {
    /// The program line that asked for the move.
    pub at: Source,
    pub message: String,
}

/// Turns canon into segments for one machine.
pub struct Planner<'k> {
    kins: &'k dyn Kinematics,
    limits: [Option<Limits>; 9],
    /// Programmed feed in mm/s.
    feed: f64,
    position: Position,
}

impl<'k> Planner<'k> {
    /// A planner for the machine `kins`, starting at `start`.
    pub fn new(kins: &'k dyn Kinematics, start: Position) -> Self {
        let mut limits = [None; 9];
        for spec in kins.axes() {
            limits[spec.axis.index()] = Some(spec.limits);
        }
        Planner {
            kins,
            limits,
            feed: 0.0,
            position: start,
        }
    }

    /// Where the tool is after everything planned so far.
    pub fn position(&self) -> Position {
        self.position
    }

    /// Plan one canon command. Returns the segment it makes, if any.
    ///
    /// Errors, naming the source line, if the move leaves the machine's
    /// travel or joint strokes, or moves an axis the machine does not have.
    pub fn plan(&mut self, canon: &Canon) -> Result<Option<Segment>, PlanError> {
        let err = |message: String| PlanError {
            at: canon.source.clone(),
            message,
        };
        let (kind, end) = match &canon.cmd {
            CanonCmd::SetFeedRate { mm_per_min } => {
                self.feed = mm_per_min / 60.0;
                return Ok(None);
            }
            CanonCmd::Dwell { seconds } => {
                return Ok(Some(Segment {
                    kind: SegmentKind::Dwell,
                    line: canon.source.line,
                    start: self.position,
                    end: self.position,
                    profile: Trapezoid::rest(*seconds),
                }));
            }
            CanonCmd::StraightTraverse { end } => (SegmentKind::Rapid, *end),
            CanonCmd::StraightFeed { end } => (SegmentKind::Feed, *end),
            CanonCmd::UseLengthUnits(_)
            | CanonCmd::Comment(_)
            | CanonCmd::Message(_)
            | CanonCmd::ProgramEnd => return Ok(None),
            // Offsets and modes the interpreter has already applied to
            // every position, and commands for other parts of the machine.
            CanonCmd::SetG5xOffset { .. }
            | CanonCmd::SetG92Offset { .. }
            | CanonCmd::SetXYRotation { .. }
            | CanonCmd::UseToolLengthOffset { .. }
            | CanonCmd::SelectPlane(_)
            | CanonCmd::SetFeedMode { .. }
            | CanonCmd::SetMotionControlMode(_)
            | CanonCmd::SetNaivecamTolerance { .. }
            | CanonCmd::SetPlannerMode { .. }
            | CanonCmd::SetSpindleSpeed { .. }
            | CanonCmd::StartSpindleClockwise { .. }
            | CanonCmd::StartSpindleCounterclockwise { .. }
            | CanonCmd::StopSpindleTurning { .. }
            | CanonCmd::SetSpindleMode { .. }
            | CanonCmd::OrientSpindle { .. }
            | CanonCmd::WaitSpindleOrientComplete { .. }
            | CanonCmd::SelectTool { .. }
            | CanonCmd::StartChange
            | CanonCmd::ChangeTool { .. }
            | CanonCmd::ChangeToolNumber { .. }
            | CanonCmd::SetToolTableEntry { .. }
            | CanonCmd::MistOn
            | CanonCmd::MistOff
            | CanonCmd::FloodOn
            | CanonCmd::FloodOff
            | CanonCmd::EnableFeedOverride
            | CanonCmd::DisableFeedOverride
            | CanonCmd::EnableSpeedOverride { .. }
            | CanonCmd::DisableSpeedOverride { .. }
            | CanonCmd::EnableAdaptiveFeed
            | CanonCmd::DisableAdaptiveFeed
            | CanonCmd::EnableFeedHold
            | CanonCmd::DisableFeedHold
            | CanonCmd::SetMotionOutputBit { .. }
            | CanonCmd::ClearMotionOutputBit { .. }
            | CanonCmd::SetMotionOutputValue { .. }
            | CanonCmd::SetAuxOutputBit { .. }
            | CanonCmd::ClearAuxOutputBit { .. }
            | CanonCmd::SetAuxOutputValue { .. }
            | CanonCmd::WaitInput { .. }
            | CanonCmd::UserMCode { .. }
            | CanonCmd::Log(_)
            | CanonCmd::LogOpen(_)
            | CanonCmd::LogAppend(_)
            | CanonCmd::LogClose
            | CanonCmd::Print(_)
            | CanonCmd::ProgramStop
            | CanonCmd::OptionalProgramStop
            | CanonCmd::PalletShuttle
            | CanonCmd::Finish => return Ok(None),
            CanonCmd::ArcFeed { .. } => {
                return Err(err(
                    "arc move (G2/G3) is not supported by the planner yet".into()
                ))
            }
            CanonCmd::StraightProbe { .. } => {
                return Err(err(
                    "probe move (G38.x) is not supported by the planner yet".into(),
                ))
            }
            CanonCmd::RigidTap { .. } => {
                return Err(err(
                    "rigid tapping (G33.1) is not supported by the planner yet".into(),
                ))
            }
            CanonCmd::StartSpeedFeedSync { .. } | CanonCmd::StopSpeedFeedSync => {
                return Err(err(
                    "spindle-synchronised motion (G33, G76) is not supported by the planner yet"
                        .into(),
                ))
            }
        };

        let start = self.position.to_array();
        let stop = end.to_array();
        let mut delta = [0.0; 9];
        for i in 0..9 {
            delta[i] = stop[i] - start[i];
            if delta[i] != 0.0 && self.limits[i].is_none() {
                return Err(err(format!(
                    "axis {} is not on this machine ({})",
                    Axis::ALL[i],
                    self.kins.name()
                )));
            }
        }
        self.kins.check_pose(&end).map_err(|e| {
            err(format!(
                "move leaves the machine's limits: {}",
                e.describe(self.kins)
            ))
        })?;

        // LinuxCNC's rule for the path length: XYZ if they move, else ABC, else UVW.
        let norm = |r: std::ops::Range<usize>| delta[r].iter().map(|d| d * d).sum::<f64>().sqrt();
        let length = [norm(0..3), norm(3..6), norm(6..9)]
            .into_iter()
            .find(|&l| l > 0.0)
            .unwrap_or(0.0);

        let mut max_v = f64::INFINITY;
        let mut max_a = f64::INFINITY;
        if length > 0.0 {
            for (limit, d) in self.limits.iter().zip(delta) {
                if let (Some(lim), true) = (limit, d != 0.0) {
                    let share = d.abs() / length;
                    max_v = max_v.min(lim.max_velocity / share);
                    max_a = max_a.min(lim.max_acceleration / share);
                }
            }
        }
        if kind == SegmentKind::Feed {
            if self.feed <= 0.0 {
                return Err(err("feed move with a zero feed rate".into()));
            }
            max_v = max_v.min(self.feed);
        }
        let profile = if length > 0.0 {
            Trapezoid::new(length, max_v, max_a)
        } else {
            Trapezoid::rest(0.0)
        };
        let segment = Segment {
            kind,
            line: canon.source.line,
            start: self.position,
            end,
            profile,
        };
        self.position = end;
        Ok(Some(segment))
    }
}
