//! The planner: canon commands into [`Segment`]s the executor can follow.
//!
//! For each move the planner builds its shape (line, arc or helix), blends
//! line–line corners with G2-continuous curves inside the path tolerance,
//! and works out the limits the executor must respect along the segment:
//! path speed, acceleration and jerk such that every axis — and every joint,
//! through the machine's kinematics — stays within its own limits. It also
//! caps the speed at each junction. It does not build the velocity profile:
//! the executor does that online, looking ahead over the whole queue, so
//! overrides and feed hold act within one servo period.

use std::collections::VecDeque;

use kerf_interp::{Axis, Canon, CanonCmd, Position, Source};

use crate::kinematics::{Kinematics, Limits, MAX_JOINTS};
use crate::path::{norm, Arc, Blend, Line, Shape, Vec9};

/// What a segment does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SegmentKind {
    /// G0: as fast as the machine allows (times the rapid override).
    Rapid,
    /// G1/G2/G3: at the programmed feed (times the feed override).
    Feed,
    /// G4: stand still for `seconds`.
    Dwell { seconds: f64 },
    /// Come to rest here and report `tag` (program end, end of an MDI block).
    Stop { tag: u32 },
}

/// A planned piece of motion. `Copy` and allocation-free, so the servo
/// thread can take and drop it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub kind: SegmentKind,
    /// Source line of the canon command that made this segment.
    pub line: u32,
    pub shape: Shape,
    /// Path length, mm (degrees for pure rotary moves).
    pub length: f64,
    /// Programmed path speed, mm/s; infinite for rapids.
    pub feed: f64,
    /// Highest path speed the machine allows along the segment, mm/s.
    pub max_velocity: f64,
    /// Highest path acceleration, mm/s².
    pub max_acceleration: f64,
    /// Highest path jerk, mm/s³.
    pub max_jerk: f64,
    /// Highest speed at the junction with the next segment, mm/s.
    pub exit_velocity: f64,
}

impl Segment {
    /// A zero-length segment at `at` of the given kind.
    pub fn marker(kind: SegmentKind, line: u32, at: Position) -> Segment {
        let p = at.to_array();
        Segment {
            kind,
            line,
            shape: Shape::Line(Line { start: p, end: p }),
            length: 0.0,
            feed: 0.0,
            max_velocity: 0.0,
            max_acceleration: f64::INFINITY,
            max_jerk: f64::INFINITY,
            exit_velocity: 0.0,
        }
    }

    /// True for segments that move the tool.
    pub fn is_motion(&self) -> bool {
        matches!(self.kind, SegmentKind::Rapid | SegmentKind::Feed)
    }

    /// Tool position `s` along the segment.
    pub fn position_at(&self, s: f64) -> Position {
        Position::from_array(self.shape.point(s))
    }

    /// Start point.
    pub fn start(&self) -> Position {
        Position::from_array(self.shape.start())
    }

    /// End point.
    pub fn end(&self) -> Position {
        Position::from_array(self.shape.end())
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

/// Path control mode (G61, G61.1, G64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PathMode {
    /// G61.1: stop at the end of every move.
    ExactStop,
    /// G61: follow the path exactly; stop only where it has a corner.
    ExactPath,
    /// G64 P: blend corners, staying within `tolerance` mm of the
    /// programmed corner (infinite: as fast as segment lengths allow).
    Blend { tolerance: f64 },
}

/// Planner settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannerConfig {
    /// Servo period, s. A curvature jump at a junction changes the
    /// acceleration within one period; the junction speed is capped so
    /// that change stays within the jerk limit.
    pub period: f64,
    /// Path mode at program start.
    pub mode: PathMode,
    /// Jerk-limited (S-curve) profiles, or acceleration-limited
    /// (trapezoidal) ones for comparison.
    pub jerk_limited: bool,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            period: 0.001,
            mode: PathMode::Blend { tolerance: 0.01 },
            jerk_limited: true,
        }
    }
}

/// A line waiting for its successor, which decides its end blend.
#[derive(Clone, Copy, Debug)]
struct Held {
    segment: Segment,
    /// The segment's line, when it is one (lines can be trimmed for blends).
    line: Option<Line>,
    /// Length before any trimming: blends take at most half of it at each end.
    full_length: f64,
}

/// Turns canon into segments for one machine.
pub struct Planner<'k> {
    kins: &'k dyn Kinematics,
    config: PlannerConfig,
    /// Axis limits with the limits of joints that move exactly with an axis folded in.
    limits: [Option<Limits>; 9],
    /// Joints that need sampling through the kinematics (false: all joints are axes).
    sample_joints: bool,
    mode: PathMode,
    /// Programmed feed, mm/s.
    feed: f64,
    position: Position,
    held: Option<Held>,
    ready: VecDeque<Segment>,
}

/// Directions closer than this (|u1 − u2|) are one straight line.
const STRAIGHT: f64 = 1e-9;

impl<'k> Planner<'k> {
    /// A planner for the machine `kins`, starting at `start`.
    pub fn new(kins: &'k dyn Kinematics, start: Position, config: PlannerConfig) -> Self {
        let mut limits = [None; 9];
        for spec in kins.axes() {
            limits[spec.axis.index()] = Some(spec.limits);
        }
        let mut sample_joints = false;
        for (j, spec) in kins.joints().iter().enumerate() {
            match kins
                .joint_axis(j)
                .and_then(|a| limits[a.index()].as_mut().map(|l| (a, l)))
            {
                Some((_, l)) => {
                    l.max_velocity = l.max_velocity.min(spec.limits.max_velocity);
                    l.max_acceleration = l.max_acceleration.min(spec.limits.max_acceleration);
                    l.max_jerk = l.max_jerk.min(spec.limits.max_jerk);
                }
                None => sample_joints = true,
            }
        }
        if !config.jerk_limited {
            for l in limits.iter_mut().flatten() {
                l.max_jerk = f64::INFINITY;
            }
        }
        Planner {
            kins,
            config,
            limits,
            sample_joints,
            mode: config.mode,
            feed: 0.0,
            position: start,
            held: None,
            ready: VecDeque::new(),
        }
    }

    /// Where the tool is after everything planned so far.
    pub fn position(&self) -> Position {
        self.position
    }

    /// Set the path control mode for the following moves.
    pub fn set_mode(&mut self, mode: PathMode) {
        self.mode = mode;
    }

    /// The next segment whose successor is known, if any.
    pub fn next_segment(&mut self) -> Option<Segment> {
        self.ready.pop_front()
    }

    /// Release the last held move, ending at rest (program end).
    pub fn finish(&mut self) {
        self.release_held(0.0);
    }

    /// Plan one canon command. Segments become available from
    /// [`next_segment`](Self::next_segment) once their successor is known.
    ///
    /// Errors, naming the source line, if the move leaves the machine's
    /// travel, reach or joint strokes, or moves an axis the machine lacks.
    pub fn plan(&mut self, canon: &Canon) -> Result<(), PlanError> {
        let line = canon.source.line;
        match &canon.cmd {
            CanonCmd::SetFeedRate { mm_per_min } => self.feed = mm_per_min / 60.0,
            CanonCmd::Dwell { seconds } => {
                self.finish();
                self.ready.push_back(Segment::marker(
                    SegmentKind::Dwell { seconds: *seconds },
                    line,
                    self.position,
                ));
            }
            CanonCmd::StraightTraverse { end } => self.line(canon, SegmentKind::Rapid, *end)?,
            CanonCmd::StraightFeed { end } => self.line(canon, SegmentKind::Feed, *end)?,
            CanonCmd::ProgramEnd => self.finish(),
            CanonCmd::UseLengthUnits(_) | CanonCmd::Comment(_) | CanonCmd::Message(_) => {}
        }
        Ok(())
    }

    fn error(&self, canon: &Canon, message: String) -> PlanError {
        PlanError {
            at: canon.source.clone(),
            message,
        }
    }

    /// Check every axis that moves exists, and the path stays in reach.
    fn check_shape(&self, canon: &Canon, shape: &Shape) -> Result<(), PlanError> {
        let (a, b) = (shape.start(), shape.end());
        for i in 0..9 {
            if a[i] != b[i] && self.limits[i].is_none() {
                return Err(self.error(
                    canon,
                    format!(
                        "axis {} is not on this machine ({})",
                        Axis::ALL[i],
                        self.kins.name()
                    ),
                ));
            }
        }
        let check = |p: Vec9| {
            self.kins.check_pose(&Position::from_array(p)).map_err(|e| {
                self.error(
                    canon,
                    format!(
                        "move leaves the machine's limits: {}",
                        e.describe(self.kins)
                    ),
                )
            })
        };
        check(b)?;
        if self.sample_joints {
            // Nonlinear kinematics: the joints can leave their strokes
            // between end points. Sample at 1 mm or finer.
            let len = shape.length();
            let n = ((len / 1.0).ceil() as usize).clamp(4, 256);
            for k in 1..n {
                check(shape.point(len * k as f64 / n as f64))?;
            }
        } else if let Shape::Arc(arc) = shape {
            // The axis box is convex, so a line inside at both ends stays
            // inside; an arc can bulge out at its quadrant points.
            let len = shape.length();
            for q in 0..8 {
                let angle = q as f64 * std::f64::consts::FRAC_PI_2 - 4.0 * std::f64::consts::PI;
                let f = (angle - arc.start_angle) / arc.sweep;
                if f > 0.0 && f < 1.0 {
                    check(shape.point(len * f))?;
                }
            }
        }
        Ok(())
    }

    fn line(&mut self, canon: &Canon, kind: SegmentKind, end: Position) -> Result<(), PlanError> {
        let line = Line {
            start: self.position.to_array(),
            end: end.to_array(),
        };
        let shape = Shape::Line(line);
        self.check_shape(canon, &shape)?;
        self.position = end;
        let length = line.length();
        if length == 0.0 {
            return Ok(());
        }
        if kind == SegmentKind::Feed && self.feed <= 0.0 {
            return Err(self.error(canon, "feed move with a zero feed rate".into()));
        }
        let segment = self.segment(kind, canon.source.line, shape);
        let incoming = Held {
            segment,
            line: Some(line),
            full_length: length,
        };
        match self.held.take() {
            Some(prev) if prev.line.is_some() => self.join_lines(prev, incoming),
            prev => {
                self.held = prev;
                self.join(incoming);
            }
        }
        Ok(())
    }

    /// Join two consecutive lines: straight through, blended, or a stop.
    fn join_lines(&mut self, prev: Held, next: Held) {
        let (Some(prev_line), Some(next_line)) = (prev.line, next.line) else {
            self.held = Some(prev);
            return self.join(next);
        };
        if self.mode == PathMode::ExactStop {
            self.held = Some(prev);
            self.release_held(0.0);
            self.held = Some(next);
            return;
        }
        let (u1, u2) = (prev_line.direction(), next_line.direction());
        let turn: Vec9 = std::array::from_fn(|i| u2[i] - u1[i]);
        let bend = norm(&turn);
        let xyz_only = |l: &Line| (3..9).all(|i| l.start[i] == l.end[i]);
        let mut prev = prev;
        let mut next = next;
        if bend < STRAIGHT {
            self.held = Some(prev);
            self.release_held(f64::INFINITY);
            self.held = Some(next);
            return;
        }
        let tolerance = match self.mode {
            PathMode::Blend { tolerance }
                if xyz_only(&prev_line) && xyz_only(&next_line) && bend < 2.0 - 1e-9 =>
            {
                tolerance
            }
            _ => {
                // A corner on an exact path, or one we do not blend: stop there.
                self.held = Some(prev);
                self.release_held(0.0);
                self.held = Some(next);
                return;
            }
        };
        let prev_len = prev_line.length();
        let leg = (tolerance * 32.0 / (6.0 * bend))
            .min(prev_len)
            .min(prev.full_length / 2.0)
            .min(next.full_length / 2.0);
        if leg < 1e-9 {
            self.held = Some(prev);
            self.release_held(0.0);
            self.held = Some(next);
            return;
        }
        let corner = prev_line.end;
        let mut prev_line = prev_line;
        let mut next_line = next_line;
        prev_line.end = std::array::from_fn(|i| corner[i] - leg * u1[i]);
        next_line.start = std::array::from_fn(|i| corner[i] + leg * u2[i]);
        prev.line = Some(prev_line);
        next.line = Some(next_line);
        let blend_kind =
            if prev.segment.kind == SegmentKind::Rapid && next.segment.kind == SegmentKind::Rapid {
                SegmentKind::Rapid
            } else {
                SegmentKind::Feed
            };
        let mut blend = self.segment(
            blend_kind,
            next.segment.line,
            Shape::Blend(Blend::corner(&corner, &u1, &u2, leg)),
        );
        blend.feed = prev.segment.feed.min(next.segment.feed);
        prev.segment.shape = Shape::Line(prev_line);
        prev.segment.length = prev_line.length();
        next.segment.shape = Shape::Line(next_line);
        next.segment.length = next_line.length();
        // Lines and blend meet with equal tangents and zero curvature on
        // both sides, so the junction needs no extra cap.
        self.held = Some(prev);
        self.release_held(f64::INFINITY);
        blend.exit_velocity = blend.max_velocity.min(next.segment.max_velocity);
        self.ready.push_back(blend);
        self.held = Some(next);
    }

    /// Emit the held line with a junction cap of `exit` mm/s.
    fn release_held(&mut self, exit: f64) {
        if let Some(mut h) = self.held.take() {
            if h.segment.length > 0.0 {
                h.segment.exit_velocity = h.segment.max_velocity.min(exit);
                self.ready.push_back(h.segment);
            }
        }
    }

    /// A segment of `shape` with its path limits.
    fn segment(&self, kind: SegmentKind, line: u32, shape: Shape) -> Segment {
        let length = shape.length();
        let feed = match kind {
            SegmentKind::Feed => self.feed,
            _ => f64::INFINITY,
        };
        let (v, a, j) = self.path_limits(&shape, length);
        Segment {
            kind,
            line,
            shape,
            length,
            feed,
            max_velocity: v,
            max_acceleration: a,
            max_jerk: j,
            exit_velocity: 0.0,
        }
    }

    /// Path speed, acceleration and jerk limits along `shape` such that
    /// every axis and joint stays within its limits.
    ///
    /// Along a line, axis i moves at t_i times the path motion, so each limit
    /// divides by |t_i|. On a curve, axis acceleration is a·t_i + v²·κ_i and
    /// axis jerk is j·t_i + 3·a·v·κ_i + v³·κ'_i; the budget is split, half
    /// and half for acceleration and in thirds for jerk, which bounds the
    /// sum by the limit.
    fn path_limits(&self, shape: &Shape, length: f64) -> (f64, f64, f64) {
        let (mut v, mut a, mut j) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let samples: usize = match shape {
            Shape::Line(_) => 1,
            Shape::Arc(_) => 3,
            Shape::Blend(_) => 9,
        };
        // Largest |t_i|, |κ_i| and |dκ_i/ds| over the shape.
        let mut t_max = [0.0f64; 9];
        let mut k_max = [0.0f64; 9];
        let mut dk_max = [0.0f64; 9];
        for k in 0..samples {
            let s = if samples == 1 {
                0.0
            } else {
                length * k as f64 / (samples - 1) as f64
            };
            let f = shape.frame(s);
            let h = (length * 1e-4).max(1e-9);
            let (fa, fb) = (
                shape.frame((s - h).max(0.0)),
                shape.frame((s + h).min(length)),
            );
            let span = (s + h).min(length) - (s - h).max(0.0);
            for i in 0..9 {
                t_max[i] = t_max[i].max(f.tangent[i].abs());
                k_max[i] = k_max[i].max(f.curvature[i].abs());
                if span > 0.0 && !matches!(shape, Shape::Line(_)) {
                    dk_max[i] = dk_max[i].max(((fb.curvature[i] - fa.curvature[i]) / span).abs());
                }
            }
        }
        let curved = !matches!(shape, Shape::Line(_));
        for i in 0..9 {
            let Some(l) = self.limits[i] else { continue };
            if t_max[i] > 0.0 {
                v = v.min(l.max_velocity / t_max[i]);
                let share = if curved { 0.5 } else { 1.0 };
                a = a.min(share * l.max_acceleration / t_max[i]);
                let jshare = if curved { 1.0 / 3.0 } else { 1.0 };
                j = j.min(jshare * l.max_jerk / t_max[i]);
            }
            if k_max[i] > 0.0 {
                v = v.min((0.5 * l.max_acceleration / k_max[i]).sqrt());
            }
            if dk_max[i] > 0.0 && l.max_jerk.is_finite() {
                v = v.min((l.max_jerk / 3.0 / dk_max[i]).cbrt());
            }
        }
        // The 3·a·v·κ_i jerk term, given the speed limit just found.
        for i in 0..9 {
            let Some(l) = self.limits[i] else { continue };
            if k_max[i] > 0.0 && l.max_jerk.is_finite() && v.is_finite() && v > 0.0 {
                a = a.min(l.max_jerk / 3.0 / (3.0 * v * k_max[i]));
            }
        }
        if self.sample_joints {
            let (jv, ja) = self.joint_limits(shape, length);
            v = v.min(jv);
            a = a.min(ja.0);
            v = v.min(ja.1);
        }
        (v, a, j)
    }

    /// Joint velocity and acceleration limits on path speed and
    /// acceleration, from dq/ds and d²q/ds² sampled through the
    /// kinematics. Returns (v_max, (a_max, v_max from curvature)).
    fn joint_limits(&self, shape: &Shape, length: f64) -> (f64, (f64, f64)) {
        let joints = self.kins.joints();
        let n = joints.len();
        let samples = ((length / 2.0).ceil() as usize).clamp(3, 64);
        let h = (length / samples as f64 / 4.0).clamp(1e-6, 0.5);
        let mut v = f64::INFINITY;
        let mut a = f64::INFINITY;
        let mut v_curv = f64::INFINITY;
        let mut seed = Position::from_array(shape.start());
        for k in 0..=samples {
            let s = length * k as f64 / samples as f64;
            let (s0, s1) = ((s - h).max(0.0), (s + h).min(length));
            let mut q = [[0.0; MAX_JOINTS]; 3];
            let ok = [s0, s, s1].iter().enumerate().all(|(m, &si)| {
                let p = Position::from_array(shape.point(si));
                seed = p;
                self.kins.inverse(&p, &mut q[m][..n]).is_ok()
            });
            if !ok || s1 - s0 <= 0.0 {
                continue;
            }
            let hh = (s1 - s0) / 2.0;
            for (jn, spec) in joints.iter().enumerate() {
                let d1 = (q[2][jn] - q[0][jn]) / (s1 - s0);
                let d2 = (q[2][jn] - 2.0 * q[1][jn] + q[0][jn]) / (hh * hh);
                let l = spec.limits;
                if d1.abs() > 0.0 {
                    v = v.min(l.max_velocity / d1.abs());
                    a = a.min(0.5 * l.max_acceleration / d1.abs());
                }
                if d2.abs() > 1e-12 {
                    v_curv = v_curv.min((0.5 * l.max_acceleration / d2.abs()).sqrt());
                }
            }
        }
        let _ = seed;
        (v, (a, v_curv))
    }

    /// Plan an arc (used once the interpreter produces arcs).
    pub fn arc(&mut self, canon: &Canon, arc: Arc) -> Result<(), PlanError> {
        let shape = Shape::Arc(arc);
        self.check_shape(canon, &shape)?;
        if self.feed <= 0.0 {
            return Err(self.error(canon, "arc with a zero feed rate".into()));
        }
        let segment = self.segment(SegmentKind::Feed, canon.source.line, shape);
        self.position = Position::from_array(shape.end());
        let full_length = segment.length;
        self.join(Held {
            segment,
            line: None,
            full_length,
        });
        Ok(())
    }

    /// Join `next` after whatever is held when no blend applies: straight
    /// through a tangent junction at a speed that keeps the curvature jump
    /// within the jerk limit over one period, or a stop at a corner.
    fn join(&mut self, next: Held) {
        let exit = match self.held.as_ref() {
            None => 0.0,
            Some(_) if self.mode == PathMode::ExactStop => 0.0,
            Some(prev) => {
                let end = prev.segment.shape.frame(prev.segment.length);
                let start = next.segment.shape.frame(0.0);
                let bend: Vec9 = std::array::from_fn(|i| start.tangent[i] - end.tangent[i]);
                if norm(&bend) > 1e-6 {
                    0.0
                } else {
                    let jump: Vec9 = std::array::from_fn(|i| start.curvature[i] - end.curvature[i]);
                    self.curvature_jump_cap(&jump)
                }
            }
        };
        self.release_held(exit);
        self.held = Some(next);
    }

    fn curvature_jump_cap(&self, jump: &Vec9) -> f64 {
        let mut v = f64::INFINITY;
        for i in 0..9 {
            if let (Some(l), true) = (self.limits[i], jump[i] != 0.0) {
                v = v.min((l.max_jerk * self.config.period / jump[i].abs()).sqrt());
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit::xyz;
    use kerf_interp::Interpreter;

    fn plan(kins: &dyn Kinematics, config: PlannerConfig, text: &str) -> Vec<Segment> {
        let mut p = Planner::new(kins, Position::ZERO, config);
        for c in Interpreter::new(text.as_bytes(), "t.ngc", Position::ZERO) {
            p.plan(&c.unwrap()).unwrap();
        }
        p.finish();
        std::iter::from_fn(|| p.next_segment()).collect()
    }

    #[test]
    fn line_limits_divide_by_the_direction_cosines() {
        let k = xyz(100.0, 1000.0, 1e5);
        let segs = plan(&k, PlannerConfig::default(), "G1 X30 Y40 F6000\nM2\n");
        assert_eq!(segs.len(), 1);
        // Direction (0.6, 0.8): Y binds, 100/0.8 = 125 mm/s, 1000/0.8, 1e5/0.8.
        let s = &segs[0];
        assert!((s.max_velocity - 125.0).abs() < 1e-9);
        assert!((s.max_acceleration - 1250.0).abs() < 1e-9);
        assert!((s.max_jerk - 1.25e5).abs() < 1e-6);
        assert_eq!(s.feed, 100.0);
        assert_eq!(s.exit_velocity, 0.0);
    }

    #[test]
    fn corner_blend_stays_within_tolerance_and_keeps_end_points() {
        let k = xyz(100.0, 1000.0, 1e5);
        let config = PlannerConfig {
            mode: PathMode::Blend { tolerance: 0.05 },
            ..Default::default()
        };
        let segs = plan(&k, config, "G1 X10 F600\nY10\nM2\n");
        assert_eq!(segs.len(), 3, "{segs:#?}");
        assert!(matches!(segs[1].shape, Shape::Blend(_)));
        // Continuity of the chain and exact end point.
        for w in segs.windows(2) {
            let (a, b) = (w[0].end(), w[1].start());
            assert!((a.x - b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12);
        }
        assert_eq!(segs[2].end(), Position::xyz(10.0, 10.0, 0.0));
        // Measured deviation from the corner (10, 0): sample the blend.
        let b = &segs[1];
        let mut worst: f64 = 0.0;
        for i in 0..=200 {
            let p = b.position_at(b.length * i as f64 / 200.0);
            // distance to the polyline (0,0)-(10,0)-(10,10)
            let d1 = if p.x <= 10.0 {
                p.y.abs()
            } else {
                ((p.x - 10.0).powi(2) + p.y.powi(2)).sqrt()
            };
            let d2 = if p.y >= 0.0 {
                (p.x - 10.0).abs()
            } else {
                ((p.x - 10.0).powi(2) + p.y.powi(2)).sqrt()
            };
            worst = worst.max(d1.min(d2));
        }
        assert!(worst <= 0.05 + 1e-12, "deviation {worst}");
        assert!(
            worst > 0.01,
            "the blend should use its tolerance, deviation {worst}"
        );
        assert!(segs[0].exit_velocity > 0.0 && segs[1].exit_velocity > 0.0);
    }

    #[test]
    fn exact_stop_and_reversal_stop_at_the_corner() {
        let k = xyz(100.0, 1000.0, 1e5);
        let stop = PlannerConfig {
            mode: PathMode::ExactStop,
            ..Default::default()
        };
        let segs = plan(&k, stop, "G1 X10 F600\nY10\nM2\n");
        assert_eq!(segs.len(), 2);
        assert_eq!(segs[0].exit_velocity, 0.0);
        let segs = plan(&k, PlannerConfig::default(), "G1 X10 F600\nX0\nM2\n");
        assert_eq!(segs.len(), 2);
        assert_eq!(segs[0].exit_velocity, 0.0);
        // Collinear moves run straight through at full speed.
        let segs = plan(&k, PlannerConfig::default(), "G1 X10 F600\nX20\nM2\n");
        assert_eq!(segs[0].exit_velocity, 100.0);
    }

    #[test]
    fn arc_limits_respect_centripetal_acceleration_and_jerk() {
        let k = xyz(1000.0, 1000.0, 1e5);
        let mut p = Planner::new(&k, Position::xyz(10.0, 0.0, 0.0), PlannerConfig::default());
        let canon = Canon {
            source: Source {
                file: "t".into(),
                line: 1,
            },
            cmd: CanonCmd::SetFeedRate {
                mm_per_min: 60000.0,
            },
        };
        p.plan(&canon).unwrap();
        let arc = Arc {
            plane: (0, 1),
            center: (0.0, 0.0),
            radius: 10.0,
            start_angle: 0.0,
            sweep: std::f64::consts::PI,
            start: [10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            end: [-10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        };
        p.arc(&canon, arc).unwrap();
        p.finish();
        let s = p.next_segment().unwrap();
        // v²/r ≤ A/2 → v ≤ sqrt(500·10) ≈ 70.7; v³·κ' ≤ J/3 with
        // |dκ_i/ds| ≤ 1/r² = 0.01 → v ≤ (1e5/3/0.01)^(1/3) ≈ 149.4.
        assert!(
            (s.max_velocity - (500.0f64 * 10.0).sqrt()).abs() < 1e-6,
            "{}",
            s.max_velocity
        );
        assert!(s.max_acceleration <= 500.0 + 1e-9);
    }
}
