//! Offline runs: a program through the planner and the executor on a
//! virtual clock, with the figures a person checks a plan by.
//!
//! The figures are measured on the sampled trajectory itself, not taken
//! from the planner's bookkeeping: deviation is the distance of each
//! commanded point from the programmed moves, and limit use comes from
//! finite differences of the commanded axis and joint positions.

use std::collections::VecDeque;

use kerf_interp::{Canon, CanonCmd, InterpError, Position};

use crate::exec::{Executor, Intervals};
use crate::kinematics::{Kinematics, Limits, MAX_JOINTS};
use crate::path::{distance_to_segment, Arc, Shape, Vec9};
use crate::plan::{PathMode, PlanError, Planner, PlannerConfig, Segment, SourceMoves};
use crate::schedule::{Interval, RateLimits, ScheduleConfig, ScheduleStream, Window};

/// Why an offline run stopped early.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RunError {
    #[error("{0}")]
    Interp(#[from] InterpError),
    #[error("{0}")]
    Plan(#[from] PlanError),
    #[error("kinematics failed at t = {time:.3} s: {message}")]
    Kinematics { time: f64, message: String },
    #[error("cannot follow a schedule: {0}")]
    Schedule(#[from] crate::schedule::ScheduleError),
}

/// Largest use of one kind of limit, as a fraction of the limit, and where.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Use {
    pub ratio: f64,
    /// Time of the worst sample, s.
    pub time: f64,
    /// Source line executing then.
    pub line: u32,
}

impl Use {
    fn see(&mut self, ratio: f64, time: f64, line: u32) {
        if ratio > self.ratio {
            *self = Use { ratio, time, line };
        }
    }
}

/// Limit use of one axis or joint.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LimitUse {
    pub name: String,
    pub velocity: Use,
    pub acceleration: Use,
    pub jerk: Use,
}

impl LimitUse {
    /// Take in one sample's (velocity, acceleration, jerk) by finite
    /// differences against `limits` (jerk only for jerk-limited plans).
    fn see(&mut self, d: [Option<f64>; 3], limits: &Limits, jerk: bool, time: f64, line: u32) {
        if let Some(v) = d[0] {
            self.velocity.see(v.abs() / limits.max_velocity, time, line);
        }
        if let Some(a) = d[1] {
            self.acceleration
                .see(a.abs() / limits.max_acceleration, time, line);
        }
        if let (Some(j), true) = (d[2], jerk) {
            self.jerk.see(j.abs() / limits.max_jerk, time, line);
        }
    }

    /// The largest of velocity, acceleration and jerk use.
    pub fn worst(&self) -> f64 {
        self.velocity
            .ratio
            .max(self.acceleration.ratio)
            .max(self.jerk.ratio)
    }
}

/// One recorded point of the trajectory (for plots).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub time: f64,
    pub position: Position,
    pub joints: [f64; MAX_JOINTS],
    /// Path speed, mm/s.
    pub velocity: f64,
}

/// The result of an offline run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    /// Time from start to the end of the last move, s.
    pub cycle_time: f64,
    /// Segments planned (moves, blends, dwells).
    pub segments: usize,
    /// Largest distance of the commanded tool point from the programmed
    /// moves, mm.
    pub max_deviation: f64,
    /// Where it was: time (s) and source line.
    pub max_deviation_at: (f64, u32),
    /// What the program allowed there, mm: its G64 P (the planner's default
    /// tolerance for G64 without P, 0 under G61 and G61.1) plus its G64 Q,
    /// the largest over the moves the segment spans.
    pub max_deviation_allowed: f64,
    /// The most the deviation went beyond what the program allowed where
    /// it happened, by more than the measure's precision (0.1 µm on
    /// helices, kept as chords), mm (0: within it everywhere), and where:
    /// time (s) and source line.
    pub over_tolerance: f64,
    pub over_tolerance_at: (f64, u32),
    pub axes: Vec<LimitUse>,
    pub joints: Vec<LimitUse>,
    /// Up to `record` evenly spaced points of the trajectory.
    pub points: Vec<Point>,
    /// The programmed path as polylines of XYZ points (for plots).
    pub programmed: Vec<[f64; 3]>,
    /// Servo periods in which the executor followed its guard because the
    /// state its search chose had no checked way to rest
    /// ([`Executor::guard_takeovers`]).
    pub guard_takeovers: u64,
    /// With [`RunConfig::follow`]: stretches of the schedule the executor
    /// followed, and of those the schedule solved, how many (none where
    /// an override above 100 % or a stretch left standing kept the
    /// executor on its own profiles).
    pub stretches_followed: u64,
}

impl Report {
    /// The largest limit use of any axis or joint.
    pub fn max_limit_ratio(&self) -> f64 {
        self.axes
            .iter()
            .chain(&self.joints)
            .map(LimitUse::worst)
            .fold(0.0, f64::max)
    }
}

/// Settings of an offline run.
#[derive(Clone, Copy, Debug)]
pub struct RunConfig {
    pub planner: PlannerConfig,
    /// Points to keep for plots (0: none).
    pub record: usize,
    /// Follow a jerk-limited schedule solved alongside the planner where
    /// one is ready ([`Executor::tick_following`]); `None`: the executor's
    /// own profiles throughout.
    pub follow: Option<FollowConfig>,
}

/// How an offline run solves the schedule its executor follows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FollowConfig {
    /// The schedule's settings; its `reserve` sets how fast the override
    /// may change on it ([`RateLimits::for_machine`]), its `period` is
    /// taken from the planner's.
    pub schedule: ScheduleConfig,
    /// The windows it is solved in, ahead of the motion.
    pub window: Window,
}

impl Default for FollowConfig {
    /// Nodes eight a servo period apart at each segment's top speed but
    /// at least 0.01 mm apart, six passes, windows of 2000 nodes keeping
    /// 500, a tenth of each acceleration and jerk limit kept for override
    /// (a hold from 100 % takes about 1.1 s on mill3). On stellabee1.ngc's
    /// first 2000 lines the nodes every 0.01 mm make the motion 1.1 %
    /// quicker (57.812 s against 58.450 s) but solve 4.7 times slower
    /// (157 s against 33.6 s with the run, on this project's VM).
    fn default() -> Self {
        FollowConfig {
            schedule: ScheduleConfig {
                reserve: 0.1,
                nodes_per_period: Some(8.0),
                ..ScheduleConfig::default()
            },
            window: Window {
                horizon: 2000,
                commit: 500,
            },
        }
    }
}

/// A programmed move (or a chord of a programmed helix), kept while the
/// machine may still be near it.
#[derive(Clone, Copy, Debug)]
struct Programmed {
    /// The canon command's number ([`SourceMoves`]).
    number: u64,
    piece: Piece,
    /// The deviation the program allows along it: G64 P plus Q, mm.
    allowed: f64,
}

/// The geometry of a [`Programmed`] move.
#[derive(Clone, Copy, Debug)]
enum Piece {
    /// A line, or a chord of a helix, which lies within `sag` mm of it.
    Line { start: Vec9, end: Vec9, sag: f64 },
    /// An arc (or the spiral a hair off one that programs' rounded end
    /// points make) in a plane of X Y Z whose third axis stays put:
    /// measured exactly ([`flat_arc_distance`]).
    FlatArc(Arc),
}

impl Piece {
    /// XYZ distance from `p`, and how far the programmed path may lie
    /// from what was measured, mm.
    fn distance(&self, p: &Vec9) -> (f64, f64) {
        match self {
            Piece::Line { start, end, sag } => (distance_to_segment(p, start, end), *sag),
            Piece::FlatArc(arc) => (flat_arc_distance(p, arc), 0.0),
        }
    }

    /// XYZ length, mm.
    fn length(&self) -> f64 {
        match self {
            Piece::Line { start, end, .. } => (0..3)
                .map(|i| (end[i] - start[i]).powi(2))
                .sum::<f64>()
                .sqrt(),
            Piece::FlatArc(arc) => Shape::Arc(*arc).length(),
        }
    }
}

/// Whether `arc` lies in a plane of X Y Z and does not move the third of
/// them (no helix), so that [`flat_arc_distance`] applies.
fn is_flat(arc: &Arc) -> bool {
    let (i, j) = arc.plane;
    i <= 2 && j <= 2 && arc.sweep != 0.0 && arc.start[3 - i - j] == arc.end[3 - i - j]
}

/// XYZ distance from `p` to a flat arc ([`is_flat`]): to its point at `p`'s
/// angle about the centre, on every turn the sweep makes there, or to an
/// end. On a circle that is the exact distance. On the logarithmic spiral
/// a rounded end point makes (radius r·e^(g·θ), g a millionth or so) it is
/// the distance to a point of the path, above the exact one by about
/// g²·r·D/(2ρ) for a point D from the path and ρ from the centre: for a
/// point near the path, g²·D/2, a trillionth of D.
fn flat_arc_distance(p: &Vec9, arc: &Arc) -> f64 {
    let d =
        |q: &Vec9| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
    let (i, j) = arc.plane;
    let phi = (p[j] - arc.center.1).atan2(p[i] - arc.center.0);
    let sweep = arc.sweep.abs();
    // The angle from the start in the sweep's direction, on the first turn.
    let mut along =
        ((phi - arc.start_angle) * arc.sweep.signum()).rem_euclid(std::f64::consts::TAU);
    let mut best = d(&arc.start).min(d(&arc.end));
    while along <= sweep {
        best = best.min(d(&arc.point_at_fraction(along / sweep)));
        along += std::f64::consts::TAU;
    }
    best
}

/// Sag of the chords a helix is kept as, and of the points plots get for
/// any arc, mm (at most 100,000 of them).
const CHORD_SAG: f64 = 1e-4;

/// How far a point is from the programmed path ([`PathWindow::distance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Deviation {
    /// Distance from the nearest programmed move (helices as chords), mm.
    pub distance: f64,
    /// What the program allows along the moves spanned: G64 P plus Q, mm.
    pub allowed: f64,
    /// How precise `distance` is, mm: the sag of the chord of a helix it
    /// was measured to (0 on lines and arcs).
    pub precision: f64,
}

impl Deviation {
    /// How far beyond what the program allows the point surely is, mm
    /// (negative: within it, as far as the measure can tell).
    pub fn over(&self) -> f64 {
        self.distance - self.precision - self.allowed
    }
}

/// The programmed moves (helices as fine chords) near where the machine is,
/// to measure how far a point is from the path.
///
/// Every canon command given to the planner must be given to
/// [`push`](Self::push) too, in the same order: both number them the same
/// way, and a point is measured against the moves its segment spans
/// ([`SourceMoves`], from [`Sample::moves`](crate::Sample::moves)), not
/// against whatever moves happen to be near. Moves before those are
/// dropped, but `keep_back` mm of path before them is kept, for points
/// that lag behind the commanded one (the machine's actual position).
#[derive(Clone, Debug)]
pub struct PathWindow {
    moves: VecDeque<Programmed>,
    last_end: Vec9,
    keep_back: f64,
    /// Canon commands pushed so far.
    received: u64,
    /// G64 P in force, mm (0 under G61 and G61.1), as the planner reads it.
    tolerance: f64,
    /// The planner's tolerance for G64 without P, mm.
    default_tolerance: f64,
    /// G64 Q in force, mm.
    merge: f64,
}

impl PathWindow {
    /// An empty path starting at `start`, keeping `keep_back` mm of moves
    /// behind the executing segment's, for a planner set up with `planner`
    /// (its starting path mode and default tolerance).
    pub fn new(start: Position, keep_back: f64, planner: &PlannerConfig) -> PathWindow {
        PathWindow {
            moves: VecDeque::new(),
            last_end: start.to_array(),
            keep_back,
            received: 0,
            tolerance: planner.mode.tolerance(),
            default_tolerance: planner.default_tolerance,
            merge: 0.0,
        }
    }

    /// Record `canon` (numbering it as the planner does) and its move, if
    /// it is one; returns the XYZ points it adds to the path (for plots).
    /// Arcs in a plane of X Y Z are kept whole and measured exactly;
    /// helices as chords whose sag is under 0.1 µm, so distances to them
    /// are distances to the helix to that precision. A move that goes
    /// nowhere (an F word alone on a G1 line) is no geometry.
    pub fn push(&mut self, canon: &Canon) -> Vec<[f64; 3]> {
        self.received += 1;
        let number = self.received;
        let allowed = self.tolerance + self.merge;
        let mut added = Vec::new();
        match &canon.cmd {
            CanonCmd::SetMotionControlMode(mode) => {
                self.tolerance = PathMode::from_program(*mode, self.default_tolerance).tolerance()
            }
            CanonCmd::SetNaivecamTolerance { tolerance } => self.merge = tolerance.max(0.0),
            CanonCmd::StraightTraverse { end } | CanonCmd::StraightFeed { end }
                if end.to_array() != self.last_end =>
            {
                let end = end.to_array();
                self.moves.push_back(Programmed {
                    number,
                    piece: Piece::Line {
                        start: self.last_end,
                        end,
                        sag: 0.0,
                    },
                    allowed,
                });
                self.last_end = end;
                added.push([end[0], end[1], end[2]]);
            }
            CanonCmd::ArcFeed {
                end,
                center,
                plane,
                turns,
            } => {
                let [first, second, _] = plane.axes();
                let arc = Arc::from_program(
                    &self.last_end,
                    &end.to_array(),
                    (first.index(), second.index()),
                    (center[0], center[1]),
                    *turns,
                );
                let shape = Shape::Arc(arc);
                let radius = arc.radius.max(arc.end_radius).max(1e-9);
                let step = 2.0 * (1.0 - CHORD_SAG / radius).clamp(-1.0, 1.0).acos();
                let n = ((arc.sweep.abs() / step.max(1e-6)).ceil() as usize).clamp(1, 100_000);
                // CHORD_SAG, or more on an arc too long for 100,000 chords.
                let sag = radius * (1.0 - (arc.sweep.abs() / (2.0 * n as f64)).cos());
                let len = shape.length();
                let flat = is_flat(&arc);
                if flat {
                    self.moves.push_back(Programmed {
                        number,
                        piece: Piece::FlatArc(arc),
                        allowed,
                    });
                }
                let mut from = self.last_end;
                for k in 1..=n {
                    let to = shape.point(len * k as f64 / n as f64);
                    if !flat {
                        self.moves.push_back(Programmed {
                            number,
                            piece: Piece::Line {
                                start: from,
                                end: to,
                                sag,
                            },
                            allowed,
                        });
                    }
                    added.push([to[0], to[1], to[2]]);
                    from = to;
                }
                self.last_end = end.to_array();
            }
            _ => {}
        }
        added
    }

    /// XYZ distance of `p` from the nearest of the programmed moves
    /// `moves` (and of those kept behind them), and the largest deviation
    /// the program allows along those moves (G64 P plus Q, mm); `None` if
    /// none of them is geometry (before any move).
    pub fn distance(&mut self, p: &Position, moves: SourceMoves) -> Option<Deviation> {
        // Drop what lies wholly more than keep_back behind the first move
        // spanned: segments run in order, and their spans never go back.
        let before = self.moves.partition_point(|m| m.number < moves.first);
        let mut behind = 0.0;
        let mut keep = 0;
        while keep < before && behind < self.keep_back {
            behind += self.moves[before - 1 - keep].piece.length();
            keep += 1;
        }
        self.moves.drain(..before - keep);
        let p = p.to_array();
        let mut found = Deviation {
            distance: f64::INFINITY,
            allowed: 0.0,
            precision: 0.0,
        };
        for m in self.moves.iter().take_while(|m| m.number <= moves.last) {
            let (d, precision) = m.piece.distance(&p);
            if d < found.distance {
                found.distance = d;
                found.precision = precision;
            }
            if m.number >= moves.first {
                found.allowed = found.allowed.max(m.allowed);
            }
        }
        found.distance.is_finite().then_some(found)
    }
}

/// Finite-difference limit tracker for one coordinate.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Differences {
    last: [f64; 3],
    seen: usize,
}

impl Differences {
    /// A coordinate that has stood at `x` for three samples: the next
    /// sample's velocity, acceleration and jerk are defined.
    pub(crate) fn at_rest(x: f64) -> Differences {
        Differences {
            last: [x; 3],
            seen: 3,
        }
    }

    /// Push a sample; returns (velocity, acceleration, jerk) once defined.
    pub(crate) fn push(&mut self, x: f64, dt: f64) -> [Option<f64>; 3] {
        let [p1, p2, p3] = self.last;
        let out = [
            (self.seen >= 1).then(|| (x - p1) / dt),
            (self.seen >= 2).then(|| (x - 2.0 * p1 + p2) / (dt * dt)),
            (self.seen >= 3).then(|| (x - 3.0 * p1 + 3.0 * p2 - p3) / (dt * dt * dt)),
        ];
        self.last = [x, p1, p2];
        self.seen += 1;
        out
    }
}

/// Plan a whole program at once: its segments in order, then a
/// [`SegmentKind::Stop`] marker tagged `tag` where it ends. For tests and
/// tools that queue a short program in one go.
pub fn plan_program(
    program: impl IntoIterator<Item = Result<Canon, InterpError>>,
    kins: &dyn Kinematics,
    start: Position,
    config: PlannerConfig,
    tag: u32,
) -> Result<Vec<Segment>, RunError> {
    let mut planner = Planner::new(kins, start, config);
    let mut out = Vec::new();
    for canon in program {
        planner.plan(&canon?)?;
        out.extend(std::iter::from_fn(|| planner.next_segment()));
    }
    planner.finish();
    out.extend(std::iter::from_fn(|| planner.next_segment()));
    out.push(planner.end_marker(tag));
    Ok(out)
}

/// Run `program` (canon, in order) on `kins` from `start` with servo period
/// `config.planner.period`, and measure it.
pub fn run(
    program: impl IntoIterator<Item = Result<Canon, InterpError>>,
    kins: &dyn Kinematics,
    start: Position,
    config: RunConfig,
) -> Result<Report, RunError> {
    run_operated(program, kins, start, config, |_, _| {})
}

/// [`run`] with an operator: `operate` acts on the executor (feed hold,
/// overrides, single block) before every servo period, given the time
/// into the run, s. The operator must release what it holds for the run
/// to end.
pub fn run_operated(
    program: impl IntoIterator<Item = Result<Canon, InterpError>>,
    kins: &dyn Kinematics,
    start: Position,
    config: RunConfig,
    mut operate: impl FnMut(&mut Executor, f64),
) -> Result<Report, RunError> {
    let dt = config.planner.period;
    let mut planner = Planner::new(kins, start, config.planner);
    let mut queue: VecDeque<Segment> = VecDeque::new();
    let mut executor = Executor::new(start);
    let mut stream = match config.follow {
        Some(follow) => {
            let schedule = ScheduleConfig {
                period: dt,
                ..follow.schedule
            };
            let limits = RateLimits::for_machine(kins, schedule.reserve)?;
            executor.follow_schedules(limits);
            Some(ScheduleStream::new(kins, schedule, follow.window)?)
        }
        None => None,
    };
    let mut intervals: VecDeque<Interval> = VecDeque::new();
    let mut report = Report::default();
    let mut programmed = PathWindow::new(start, 0.0, &config.planner);
    let njoints = kins.joints().len();

    let axis_specs = kins.axes().to_vec();
    report.axes = axis_specs
        .iter()
        .map(|a| LimitUse {
            name: a.axis.to_string(),
            ..Default::default()
        })
        .collect();
    report.joints = kins
        .joints()
        .iter()
        .map(|j| LimitUse {
            name: j.name.clone(),
            ..Default::default()
        })
        .collect();
    let mut axis_diff = vec![Differences::default(); axis_specs.len()];
    let mut joint_diff = vec![Differences::default(); njoints];
    let mut all_points = Vec::new();
    let mut ticks: u64 = 0;
    let mut program = program.into_iter();
    let mut program_done = false;
    // Keep the queue this deep so the executor's look ahead is not starved.
    const DEPTH: usize = 4096;

    loop {
        while !program_done && queue.len() < DEPTH {
            match program.next() {
                None => {
                    planner.finish();
                    program_done = true;
                }
                Some(canon) => {
                    let canon = canon?;
                    report.programmed.extend(programmed.push(&canon));
                    planner.plan(&canon)?;
                }
            }
            while let Some(seg) = planner.next_segment() {
                report.segments += 1;
                if let Some(stream) = &mut stream {
                    stream.push(&seg, &mut |i| intervals.push_back(i));
                }
                queue.push_back(seg);
            }
            if program_done {
                let end = planner.end_marker(1);
                if let Some(stream) = &mut stream {
                    stream.push(&end, &mut |i| intervals.push_back(i));
                    stream.finish(&mut |i| intervals.push_back(i));
                }
                queue.push_back(end);
            }
        }
        let (a, b) = queue.as_slices();
        // Offline, an M66 reads its input at once (the interpreter's
        // offline environment answers it), so a wait never holds.
        executor.release_input();
        // Nobody is there to resume a program stop (M0, M1): it passes,
        // and the cycle time leaves out the operator's part.
        executor.release_stop();
        operate(&mut executor, ticks as f64 * dt);
        let sample = if stream.is_some() {
            let (head, tail) = intervals.as_slices();
            executor.tick_following(dt, a, b, Intervals { head, tail })
        } else {
            executor.tick(dt, a, b)
        };
        queue.drain(..sample.consumed);
        intervals.drain(..sample.intervals_consumed);
        ticks += 1;
        let time = ticks as f64 * dt;
        let p = sample.position.to_array();
        // Deviation: distance to the nearest of the programmed moves the
        // executing segment runs along (a blend sits between two, a line
        // merged under G64 Q stands for many).
        if let Some(d) = programmed.distance(&sample.position, sample.moves) {
            if d.over() > report.over_tolerance {
                report.over_tolerance = d.over();
                report.over_tolerance_at = (time, sample.line);
            }
            if d.distance > report.max_deviation {
                report.max_deviation = d.distance;
                report.max_deviation_allowed = d.allowed;
                report.max_deviation_at = (time, sample.line);
            }
        }

        let jerk = config.planner.jerk_limited;
        for (k, spec) in axis_specs.iter().enumerate() {
            let d = axis_diff[k].push(p[spec.axis.index()], dt);
            report.axes[k].see(d, &spec.limits, jerk, time, sample.line);
        }
        let mut q = [0.0; MAX_JOINTS];
        kins.inverse(&sample.position, &mut q[..njoints])
            .map_err(|e| RunError::Kinematics {
                time,
                message: e.describe(kins),
            })?;
        for (k, spec) in kins.joints().iter().enumerate() {
            let d = joint_diff[k].push(q[k], dt);
            report.joints[k].see(d, &spec.limits, jerk, time, sample.line);
        }
        if config.record > 0 {
            all_points.push(Point {
                time,
                position: sample.position,
                joints: q,
                velocity: sample.velocity,
            });
        }
        if sample.stopped_at == Some(1) {
            report.cycle_time = time;
            break;
        }
    }
    report.guard_takeovers = executor.guard_takeovers();
    report.stretches_followed = executor.stretches_followed();
    if config.record > 0 && !all_points.is_empty() {
        let step = (all_points.len() / config.record).max(1);
        report.points = all_points.iter().step_by(step).copied().collect();
        if let Some(last) = all_points.last() {
            report.points.push(*last);
        }
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distance to a flat arc against the least distance to 50,000
    /// points along it, on circles and the spirals rounded end points make
    /// (end radius a little off), either way round, in every plane of
    /// X Y Z, with the far axis off the plane, sweeps up to three turns, and
    /// points near the path, at the centre and far away.
    #[test]
    fn a_flat_arc_is_measured_as_closely_as_its_points() {
        let mut rng = crate::testkit::uniform(11);
        for case in 0..30 {
            let plane = [(0, 1), (2, 0), (1, 2)][case % 3];
            let k = 3 - plane.0 - plane.1;
            let r = 0.5 + 50.0 * rng();
            let a0 = std::f64::consts::TAU * rng();
            let turns = 1 + (case / 10) as i32;
            let sweep = (0.05 + rng() * (std::f64::consts::TAU - 0.1))
                * if rng() < 0.5 { -1.0 } else { 1.0 };
            let end_angle = a0 + sweep;
            let off = 1.0 + (rng() - 0.5) * 2e-4;
            let mut start = [0.0; 9];
            start[plane.0] = 10.0 + r * a0.cos();
            start[plane.1] = -5.0 + r * a0.sin();
            start[k] = 3.0;
            let mut end = start;
            end[plane.0] = 10.0 + r * off * end_angle.cos();
            end[plane.1] = -5.0 + r * off * end_angle.sin();
            let dir = if sweep > 0.0 { turns } else { -turns };
            let arc = Arc::from_program(&start, &end, plane, (10.0, -5.0), dir);
            assert!(is_flat(&arc), "case {case}");
            let shape = Shape::Arc(arc);
            let len = shape.length();
            let points: Vec<Vec9> = (0..=50_000)
                .map(|n| shape.point(len * n as f64 / 50_000.0))
                .collect();
            for _ in 0..5 {
                let mut p = shape.point(len * rng());
                let scale = [1e-3, 0.05, 2.0 * r][(rng() * 3.0) as usize];
                for q in p.iter_mut().take(3) {
                    *q += (rng() - 0.5) * scale;
                }
                if rng() < 0.05 {
                    p[plane.0] = 10.0;
                    p[plane.1] = -5.0;
                }
                let d = |q: &Vec9| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt();
                let sampled = points.iter().map(d).fold(f64::INFINITY, f64::min);
                let exact = flat_arc_distance(&p, &arc);
                // Points 2π·r·turns / 50,000 apart miss the nearest by at
                // most half that along the path, which costs its square
                // over twice the distance (and at most that much).
                let step = len / 50_000.0;
                let slack = (step * step / (2.0 * sampled.max(1e-9))).min(step) + 1e-9;
                // On a spiral the point at p's angle is off the nearest
                // (see flat_arc_distance), by at most the spiral's change
                // of radius.
                let growth = (arc.end_radius / arc.radius).ln().abs() / arc.sweep.abs();
                let rho = (p[plane.0] - 10.0).hypot(p[plane.1] + 5.0);
                let over = (growth * growth * r * sampled / (2.0 * rho))
                    .min(growth * arc.sweep.abs() * r * 1.01)
                    + 1e-9;
                assert!(
                    exact <= sampled + over && exact >= sampled - slack,
                    "case {case}: exact {exact}, sampled {sampled}"
                );
            }
        }
    }
}
