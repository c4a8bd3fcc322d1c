//! A jerk-limited speed schedule along the planned path, near the
//! time-optimal one: the other side of the lower bound in [`crate::bound`].
//!
//! Not used by the controller. The bound answers "how fast could any
//! trajectory along this path go?" with a relaxation, so it may be lower
//! than anything a machine can follow. This module answers "how fast does
//! one trajectory go that keeps every axis's velocity, acceleration and
//! jerk limit?" by finding one. The optimum lies between the two, so
//! together they tell how much of the executor's gap to the bound
//! third-order planning could close, and how much is the bound's
//! looseness.
//!
//! Method: time-optimal path parameterisation with jerk limits by
//! sequential linear programming (as CNC feed-rate scheduling does). The
//! path is sampled every `ds` of arc length; at each node the unknown is
//! x = v². With u = ½·dx/ds (the path acceleration) and p′, p″, p‴ the
//! path's derivatives in arc length, axis i moves at v·p′_i, accelerates
//! at p′_i·u + p″_i·x and jerks at v·(p′_i·du/ds + 3·p″_i·u + p‴_i·x). The
//! velocity limit is linear in x. Between the nodes the speed is the one
//! [`Interpolant::SpeedInLength`] follows: x piecewise quadratic, u
//! continuous and linear on each half interval, each node's u made of
//! its neighbours' x, so that x, u and u′ anywhere are linear in the
//! nodes' x (within a node, its neighbours and the node after next). The
//! acceleration and jerk are judged where that motion has them, at each
//! interval's ends and middle, which holds the speed between nodes to the
//! limits too: judged at the nodes alone, by finite differences, the
//! solutions zig-zagged from node to node and no motion through them kept
//! the jerk limit (up to 3.7 times it at 1 ms samples). Where the
//! speed crests inside a half interval (u falls through zero), the jerk
//! and the velocity are judged at the crest too, where the linear
//! program's guess has it: with nodes several servo periods apart, the
//! crests between the judged points read 1.009 of the jerk limit. Where
//! the speed dips inside a half, it is kept above half of the slower
//! node's (a deeper dip the motion between nodes is not made to follow:
//! see `interval_piece`). The jerk limit
//! reads |p′_i·u′ + 3·p″_i·u + p‴_i·x| ≤ J_i/√x; 1/√x is convex, so its tangent at any x̄ lies below
//! it, and with the tangent in its place the constraint is linear and
//! stricter than the true one. Every solution of the linear program is
//! therefore within the jerk limits (at those points), whatever x̄ was;
//! solving again with x̄ the last solution moves the tangents to where
//! the schedule is and lets it speed up. The objective is the first-order
//! change of the cycle time about x̄ (weights ds/x̄^{3/2}), so that the
//! program spends its freedom where the schedule is slow.
//!
//! Away from the stops x stays above [`MOVING_X`] at nodes and midpoints:
//! otherwise a node dropped to rest frees its own jerk constraint (√x
//! times anything is 0), a gap in the discretisation that no real motion
//! has. (Before the motion between nodes was judged, the tangent was also
//! taken at each node's neighbours to the same end.) Where the path's jerk
//! holds a stretch below that speed, no program of it has a solution; it
//! is then solved with [`LOWER_FLOOR`] of it, and then with none.
//!
//! Stops split the path into stretches solved one by one: exact stops,
//! unblended corners, markers that stand still, program end. At junctions
//! where the tangent or the curvature jumps the jerk is unbounded in
//! continuous time; the schedule passes them at the planner's own caps,
//! v·|Δt_i| ≤ A_i·T and v²·|Δκ_i| ≤ J_i·T (T the servo period).
//!
//! What the result is worth. The limits hold at the judged points under
//! the discretisation above, to the solver's tolerance (up to about 1e-5
//! where it reports reduced accuracy): [`Schedule::limit_use`] measures
//! them there with the exact √x, and [`Schedule::scaled_time`] slows the
//! whole schedule by the factor that brings it within every limit
//! (velocity scales as 1/λ, acceleration 1/λ², jerk 1/λ³). Followed in
//! time by [`Interpolant::SpeedInLength`] and sampled at the servo period
//! ([`Schedule::sampled`]), as `kerf plan` judges the executor, the
//! motion keeps the limits on the samples too (`cargo bench --bench
//! schedule`). Each linear program finds a local optimum of a non-convex
//! problem, so the scaled time is an upper estimate of the optimum, not
//! the optimum itself.
//!
//! Cost: each linear program is solved by an interior-point method whose
//! Newton systems are banded (`banded`), in time linear in the nodes:
//! 2,200–6,700 nodes a second at six passes on this project's 2-core VM
//! (`cargo bench --bench schedule`; fewest on one long stretch, as the
//! circle's), about three times as fast as stellabee1.ngc runs on mill3. (Rows
//! at the nodes alone gave 4,400–15,000; with `clarabel`, a general sparse
//! solver, until 2026-11-27 it was 380–2100, as slow as the motion.)
//!
//! Axes only: joints of non-trivial kinematics are not modelled, and
//! [`schedule`] refuses machines that have them.

mod banded;
mod follow;

use banded::{BandedLp, Failure};
pub use follow::{Follower, Interval, RateLimits, Sample};

use crate::bound::arc_third;
use crate::kinematics::Kinematics;
use crate::offline::Differences;
use crate::path::{Shape, Vec9};
use crate::plan::{Segment, SegmentKind};

/// Nodes next to a stop whose speed is capped by the ramp out of rest
/// (see `linear_program`): the geometry there is taken as the stop's.
const REST_NODES: usize = 8;

/// Least x = v² (mm²/s²) the schedule keeps at nodes and midpoints more
/// than [`REST_NODES`] from a stop, where the caps allow it.
const MOVING_X: f64 = 1.0;

/// Where no linear program of a stretch can be solved with
/// [`MOVING_X`], it is tried with this share of it, then with none.
const LOWER_FLOOR: f64 = 0.01;

/// Share of its bound by which a row across a window's seam may exceed
/// it (see `Rows::push`): the issue's tolerance on limit use, 1e-6.
const SEAM_ROOM: f64 = 1e-8;

/// Each half interval's motion is judged at its ends and at this many
/// minus one evenly spaced points inside: x and u change slowly along an
/// interval, but the geometry of a dense-curve blend can turn its
/// curvature within a few micrometres, and the jerk between judged
/// points then exceeds what the points show (judged at the ends and
/// middle alone, 1.06 of the limit on 1 ms samples of stellabee1.ngc).
const JUDGED_PER_HALF: usize = 4;

/// How far the geometry between judged points may stray from the straight
/// line between them, as a share of each quantity's largest size over the
/// interval, for those points to be judged alone ([`stride`]). The jerk
/// is a sum of terms that partly cancel, so the share must be small: at
/// 0.02, stellabee1.ngc's first 2000 lines read 1.004 of the jerk limit
/// on their 1 ms samples; at 0.005 and below, within it, and at 0.0025
/// the motion between samples reads what every interval judged at every
/// point does (1.004, `Schedule::continuous_jerk`).
const GEOMETRY_STRAY: f64 = 0.0025;

/// Of an interval's possible judged points (geometry `start`, `inner`,
/// `end`), every how many to judge: the coarsest stride (a power of two
/// up to [`JUDGED_PER_HALF`]) at which every point left out has its
/// tangent, curvature and third derivative within [`GEOMETRY_STRAY`] of
/// the straight line between the judged points beside it. Lines and arcs
/// take the coarsest; blends whose curvature turns inside an interval,
/// finer ones.
fn stride(start: &Geometry, inner: &[Geometry; INNER], end: &Geometry) -> usize {
    let at = |j: usize| match j {
        0 => start,
        _ if j == INNER + 1 => end,
        _ => &inner[j - 1],
    };
    let parts = |g: &Geometry| [g.t, g.c, g.d];
    // Each quantity's largest size per axis over the interval.
    let mut size = [[0.0f64; 9]; 3];
    for j in 0..=INNER + 1 {
        for (q, part) in parts(at(j)).iter().enumerate() {
            for i in 0..9 {
                size[q][i] = size[q][i].max(part[i].abs());
            }
        }
    }
    let mut stride = JUDGED_PER_HALF;
    while stride > 1 {
        let straight = (0..=INNER + 1)
            .filter(|j| !j.is_multiple_of(stride))
            .all(|j| {
                let a = j / stride * stride;
                let w = (j - a) as f64 / stride as f64;
                let (pa, pb, pj) = (parts(at(a)), parts(at(a + stride)), parts(at(j)));
                (0..3).all(|q| {
                    (0..9).all(|i| {
                        let line = (1.0 - w) * pa[q][i] + w * pb[q][i];
                        (pj[q][i] - line).abs() <= GEOMETRY_STRAY * size[q][i]
                    })
                })
            });
        if straight {
            break;
        }
        stride /= 2;
    }
    stride
}

/// A crest whose x rises by less than this share above the half's
/// start is not judged: the jerk there, √x·(…), exceeds the start's by
/// half that share at most, far inside the issue's 1e-6. (On a cruise
/// at the velocity limit the solver's last digits ripple the speed, and
/// every interval would have a crest and rows of its own.)
const CREST_RISE: f64 = 1e-7;

/// Points inside an interval where the geometry is kept.
const INNER: usize = 2 * JUDGED_PER_HALF - 1;

/// Points judged per interval: each half's ends and inside points (the
/// middle twice, once with each half's u′).
const JUDGED: usize = 2 * (JUDGED_PER_HALF + 1);

/// Lower first guesses tried when the solver gives up on the first pass.
const RETRIES: usize = 3;

/// Settings of the schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduleConfig {
    /// Node spacing along the path, mm (at least 4 intervals per segment).
    pub ds: f64,
    /// Servo period, s: the planner's caps at curvature jumps and kinks.
    pub period: f64,
    /// Linear programs per stretch (the first from a guess, each next one
    /// linearised about the last solution), or per window.
    pub passes: usize,
    /// Solve each stretch whole (`None`), or in windows that run ahead
    /// of the motion as an online planner's would.
    pub window: Option<Window>,
    /// Space a segment's nodes by its top speed instead: as far apart as
    /// that speed travels in `period / nodes_per_period`, but never
    /// closer than `ds` (`None`: every `ds`).
    pub nodes_per_period: Option<f64>,
    /// Share of every axis's acceleration and jerk limit the schedule
    /// leaves unused (0 ≤ reserve < 1), so that a [`Follower`] can change
    /// its feed override within the rest ([`RateLimits::for_machine`]).
    /// 0: the schedule uses the whole limits and a follower runs it at
    /// 100 % only. The velocity limits are used whole either way: an
    /// override at or below 100 % never raises a speed.
    pub reserve: f64,
}

/// Solving a stretch in windows, as a planner that runs ahead of the
/// motion must: each window's linear programs see only its own nodes,
/// start from the speed and acceleration the windows before committed,
/// and end at rest, so the schedule always has a way to rest within what
/// has been solved. Of each window's solution the first `commit` nodes
/// are kept; the next window starts three nodes before the first node not
/// kept (those three fix its speed, acceleration and the motion between
/// them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// Nodes per window (at 0.01 mm, 100 per millimetre of path).
    pub horizon: usize,
    /// Nodes kept of each window's solution: at least 4, less than
    /// `horizon` (clamped into that range).
    pub commit: usize,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        ScheduleConfig {
            ds: 0.01,
            period: 0.001,
            passes: 6,
            window: None,
            nodes_per_period: None,
            reserve: 0.0,
        }
    }
}

/// Why no schedule could be made.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum ScheduleError {
    /// A joint that is not an axis of its own: its limits would need the
    /// kinematics' Jacobian, which the schedule does not model.
    #[error(
        "joint {joint} does not drive one axis: schedules model trivial kinematics only; \
         use the lower bound (kerf_motion::bound) for this machine"
    )]
    NonTrivialKinematics { joint: String },
    /// A reserve outside 0 ≤ reserve < 1.
    #[error(
        "a schedule's reserve is the share of the acceleration and jerk limits kept back \
         for feed override, at least 0 and below 1; got {0}"
    )]
    Reserve(f64),
}

/// Path derivatives in arc length at a node, per axis.
#[derive(Clone, Copy, Debug, Default)]
struct Geometry {
    /// p′ (unit tangent).
    t: Vec9,
    /// p″ (curvature vector), 1/mm.
    c: Vec9,
    /// p‴, 1/mm².
    d: Vec9,
}

impl Geometry {
    /// Axis `i`'s jerk, mm/s³, moving at x = v² with path acceleration u
    /// = ½·dx/ds and its rate u′ = du/ds here: v·(p′·u′ + 3·p″·u + p‴·x).
    fn jerk(&self, i: usize, x: f64, u: f64, slope: f64) -> f64 {
        x.sqrt() * (self.t[i] * slope + 3.0 * self.c[i] * u + self.d[i] * x)
    }

    /// The path's derivatives `s` mm into `segment`.
    fn at(segment: &Segment, s: f64) -> Geometry {
        let shape = &segment.shape;
        let f = shape.frame(s);
        let d = match shape {
            Shape::Line(_) => [0.0; 9],
            Shape::Arc(a) => arc_third(a, s, segment.length),
            Shape::Blend(b) => {
                let d3 = b.third_at_parameter(b.parameter(s));
                std::array::from_fn(|i| if i < 3 { d3[i] } else { 0.0 })
            }
        };
        Geometry {
            t: f.tangent,
            c: f.curvature,
            d,
        }
    }
}

/// A sampled point of the path.
#[derive(Clone, Debug)]
struct Node {
    /// Geometry at the end of the interval before (differs from `right`
    /// only at junctions).
    left: Geometry,
    /// Geometry at the start of the interval after.
    right: Geometry,
    /// Geometry at the points inside the interval after where the motion
    /// is judged, j/(2·[`JUDGED_PER_HALF`]) along it for j = 1, 2, …
    /// (unused where it has no length).
    inner: [Geometry; INNER],
    /// Of the points a half interval could be judged at, every `stride`th
    /// is ([`stride`]).
    stride: usize,
    /// Largest x = v² here, mm²/s².
    xmax: f64,
    /// Arc length of the interval to the next node, mm (0 after the last
    /// node and across the zero-length step out of a stop).
    h: f64,
    /// The jerk constraint applies (no tangent or curvature jump here).
    smooth: bool,
    /// The segment the node lies on (its index in the schedule's input)
    /// and the arc length into it, mm.
    segment: usize,
    at: f64,
}

/// A speed schedule along planned segments.
#[derive(Clone, Debug)]
pub struct Schedule {
    /// Cycle time, s, dwells included, as solved (before any scaling).
    pub time: f64,
    /// Dwell time in `time`, s.
    pub dwell: f64,
    /// Path position of each node, mm.
    pub s: Vec<f64>,
    /// Path speed at each node, mm/s.
    pub v: Vec<f64>,
    /// Time from each node to the next, s (0 after the last and across
    /// the zero-length steps out of stops), summing to `time` less the
    /// dwells: where along the path the schedule spends its time.
    pub step: Vec<f64>,
    /// Stretches between stops.
    pub stretches: usize,
    /// Windows solved (0 when each stretch is solved whole).
    pub windows: usize,
    /// Windows with no solution from the state committed before them,
    /// where the schedule follows the window before to its rest instead
    /// (a stop no stretch solved whole would make).
    pub window_rests: usize,
    /// Linear programs solved, and those the solver gave up on (the
    /// stretch keeps its best earlier solution; a stretch with none
    /// stands still and makes `time` infinite).
    pub solves: usize,
    pub failed: usize,
    /// Stretches with no solution, which stand still: the segments (their
    /// indices in the schedule's input) of each one's first and last
    /// node, and its nodes.
    pub stranded: Vec<(usize, usize, usize)>,
    nodes: Vec<Node>,
    /// Servo period it was solved for, s: crests are judged on intervals
    /// that last longer.
    period: f64,
}

/// Largest use of each kind of limit over every axis, as fractions of the
/// limit (1 = at the limit).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScheduleUse {
    /// Axis speed over its velocity limit.
    pub velocity: f64,
    /// Axis acceleration over its acceleration limit.
    pub acceleration: f64,
    /// Axis jerk over its jerk limit.
    pub jerk: f64,
}

impl ScheduleUse {
    /// The factor λ ≥ 1 by which slowing the schedule down brings every
    /// use within 1: max(1, velocity, acceleration^½, jerk^⅓).
    pub fn slowdown(&self) -> f64 {
        1f64.max(self.velocity)
            .max(self.acceleration.sqrt())
            .max(self.jerk.cbrt())
    }
}

/// Axis limits folded from the machine: velocity, acceleration, jerk per
/// axis, infinite for axes it lacks.
#[derive(Clone, Copy, Debug)]
struct AxisLimits {
    v: Vec9,
    a: Vec9,
    j: Vec9,
}

fn axis_limits(kins: &dyn Kinematics) -> Result<AxisLimits, ScheduleError> {
    let mut l = AxisLimits {
        v: [f64::INFINITY; 9],
        a: [f64::INFINITY; 9],
        j: [f64::INFINITY; 9],
    };
    for spec in kins.axes() {
        let i = spec.axis.index();
        l.v[i] = spec.limits.max_velocity;
        l.a[i] = spec.limits.max_acceleration;
        l.j[i] = spec.limits.max_jerk;
    }
    for (k, spec) in kins.joints().iter().enumerate() {
        let Some(axis) = kins.joint_axis(k) else {
            return Err(ScheduleError::NonTrivialKinematics {
                joint: spec.name.clone(),
            });
        };
        let i = axis.index();
        l.v[i] = l.v[i].min(spec.limits.max_velocity);
        l.a[i] = l.a[i].min(spec.limits.max_acceleration);
        l.j[i] = l.j[i].min(spec.limits.max_jerk);
    }
    Ok(l)
}

/// The limits the schedule's linear programs keep: the machine's, less
/// `config.reserve` of each acceleration and jerk limit.
fn solving_limits(
    kins: &dyn Kinematics,
    config: &ScheduleConfig,
) -> Result<AxisLimits, ScheduleError> {
    let r = config.reserve;
    if !(0.0..1.0).contains(&r) {
        return Err(ScheduleError::Reserve(r));
    }
    let mut l = axis_limits(kins)?;
    for i in 0..9 {
        l.a[i] *= 1.0 - r;
        l.j[i] *= 1.0 - r;
    }
    Ok(l)
}

/// The schedule along `segments` (markers included, in order) on `kins`.
pub fn schedule(
    segments: &[Segment],
    kins: &dyn Kinematics,
    config: ScheduleConfig,
) -> Result<Schedule, ScheduleError> {
    let limits = solving_limits(kins, &config)?;
    let mut path = Sampler {
        limits,
        config,
        nodes: Vec::new(),
        rest: true,
        dwell: 0.0,
    };
    for (index, segment) in segments.iter().enumerate() {
        path.push(index, segment);
    }
    Ok(path.solve())
}

/// A schedule solved as the planned segments arrive, window by window
/// ([`Window`]), handing on each interval as soon as its speed is
/// committed: the planner-side half of third-order planning, feeding a
/// [`Follower`]. It hands on exactly the intervals
/// [`schedule`] with the same window would (`tests/schedule.rs`), but
/// runs only as far ahead as the segments it has been given: a window is
/// solved once the path reaches past its end, and a stretch ends at a stop
/// (or at [`ScheduleStream::finish`]). Dwells are left to the executor.
///
/// It holds the nodes it has not handed on and those its windows still
/// read (about 2 kB a node, 100 a millimetre at the default spacing), and
/// drops the rest: a window's worth, not the program's.
pub struct ScheduleStream {
    sampler: Sampler,
    window: Window,
    /// Segments pushed (the next one's index).
    segments: usize,
    /// x at every node, committed below `known`.
    x: Vec<f64>,
    known: usize,
    /// The first node of the stretch being solved, and its windows once
    /// it is known to need them.
    stretch: usize,
    windows: Option<Windows>,
    /// The next interval to hand on (its first node).
    next: usize,
    /// Counters, as [`Schedule`] keeps them.
    counts: Schedule,
}

/// What a [`ScheduleStream`]'s solves came to ([`ScheduleStream::counts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamCounts {
    /// Windows solved.
    pub windows: usize,
    /// Linear programs given up (their windows keeping an earlier pass).
    pub failed: usize,
    /// Windows that found nothing and followed the one before to rest.
    pub window_rests: usize,
    /// Stretches solved whole that found nothing and stand still.
    pub stranded: usize,
}

impl ScheduleStream {
    /// A stream for `kins` (its axes' limits) under `config`, solved in
    /// windows of `window`.
    pub fn new(
        kins: &dyn Kinematics,
        config: ScheduleConfig,
        window: Window,
    ) -> Result<ScheduleStream, ScheduleError> {
        let limits = solving_limits(kins, &config)?;
        Ok(ScheduleStream {
            sampler: Sampler {
                limits,
                config: ScheduleConfig {
                    window: Some(window),
                    ..config
                },
                nodes: Vec::new(),
                rest: true,
                dwell: 0.0,
            },
            window,
            segments: 0,
            x: Vec::new(),
            known: 0,
            stretch: 0,
            windows: None,
            next: 0,
            counts: Schedule::empty(0.0, config.period),
        })
    }

    /// Takes the next planned segment and hands `out` every interval this
    /// lets the stream commit.
    pub fn push(&mut self, segment: &Segment, out: &mut impl FnMut(Interval)) {
        self.sampler.push(self.segments, segment);
        self.segments += 1;
        self.advance(false, out);
    }

    /// The program has ended: the motion comes to rest at the last node,
    /// and `out` gets every interval still held.
    pub fn finish(&mut self, out: &mut impl FnMut(Interval)) {
        if let Some(last) = self.sampler.nodes.last_mut() {
            last.xmax = 0.0;
        }
        self.advance(true, out);
    }

    /// What the stream's solves came to so far, as [`Schedule`] counts
    /// them.
    pub fn counts(&self) -> StreamCounts {
        StreamCounts {
            windows: self.counts.windows,
            failed: self.counts.failed,
            window_rests: self.counts.window_rests,
            stranded: self.counts.stranded.len(),
        }
    }

    fn advance(&mut self, finished: bool, out: &mut impl FnMut(Interval)) {
        self.solve_what_it_can(finished, out);
        self.forget_handed_on();
    }

    /// Nodes held: those not yet handed on, those the windows still read,
    /// and up to [`FORGET_AT`] more.
    pub fn held_nodes(&self) -> usize {
        self.sampler.nodes.len()
    }

    /// Drops the nodes nothing will read again, once there are
    /// [`FORGET_AT`] of them (one move of the rest for so many).
    fn forget_handed_on(&mut self) {
        // The next interval's u reads the node before it; the stretch
        // being solved, from its first node or its windows' first.
        let by_stretch = match &self.windows {
            Some(windows) => self.stretch + windows.first_needed(),
            None => self.stretch,
        };
        let cut = self.next.saturating_sub(1).min(by_stretch);
        if cut < FORGET_AT {
            return;
        }
        self.sampler.nodes.drain(..cut);
        self.x.drain(..cut);
        self.known -= cut;
        self.next -= cut;
        if cut > self.stretch {
            let windows = self
                .windows
                .as_mut()
                .expect("only windows read past the stretch's start");
            windows.shift(cut - self.stretch);
            self.stretch = 0;
        } else {
            self.stretch -= cut;
        }
    }

    fn solve_what_it_can(&mut self, finished: bool, out: &mut impl FnMut(Interval)) {
        let n = self.sampler.nodes.len();
        // The last node changes with the next segment (its junction caps,
        // or a stop); the others are final.
        let settled = if finished { n } else { n.saturating_sub(1) };
        if self.x.len() < n {
            self.x.resize(n, 0.0);
        }
        while self.stretch + 1 < settled {
            let nodes = &self.sampler.nodes;
            let start = self.stretch;
            let stop = (start + 1..settled).find(|&k| nodes[k].xmax == 0.0);
            let (span, complete) = match stop {
                Some(stop) => (&nodes[start..=stop], true),
                None => (&nodes[start..settled], false),
            };
            let m = span.len();
            if self.windows.is_none() {
                if complete && m <= self.window.horizon + 1 {
                    // Short enough to solve whole, as `schedule` does.
                    if span.iter().any(|node| node.xmax > 0.0) {
                        self.counts.stretches += 1;
                        let x = self.sampler.whole(span, &mut self.counts);
                        for (k, &x) in x.iter().enumerate() {
                            self.x[start + k] = as_speed_squared(x);
                        }
                    }
                    self.known = start + m;
                    self.stretch = start + m - 1;
                    self.hand_on(out);
                    continue;
                }
                if !complete && m <= self.window.horizon + 1 {
                    // Whole or in windows: not known yet.
                    return;
                }
                self.counts.stretches += 1;
                self.windows = Some(Windows::new(m));
            }
            let windows = self.windows.as_mut().expect("set above");
            let step = windows.next(&self.sampler, span, complete, self.window, &mut self.counts);
            // Only what this window committed: the nodes before `known`
            // are final and already copied.
            let from = self.known.saturating_sub(start).min(windows.committed);
            for (k, &x) in windows.x[..windows.committed].iter().enumerate().skip(from) {
                self.x[start + k] = as_speed_squared(x);
            }
            self.known = start + windows.committed;
            match step {
                WindowStep::Committed => self.hand_on(out),
                WindowStep::Done => {
                    self.windows = None;
                    self.stretch = start + m - 1;
                    self.hand_on(out);
                }
                WindowStep::NeedMore => return,
            }
        }
        if finished {
            self.known = n;
            self.hand_on(out);
        }
    }

    /// Hands on every interval whose speed is now known: both its nodes'
    /// x and the x its nodes' u is taken from.
    fn hand_on(&mut self, out: &mut impl FnMut(Interval)) {
        let nodes = &self.sampler.nodes;
        while self.next + 1 < self.known {
            let k = self.next;
            let ready = k + 2 < self.known || self.x[k + 1] == 0.0;
            if !ready {
                return;
            }
            if nodes[k].h > 0.0 {
                out(interval(nodes, &self.x, k));
            }
            self.next += 1;
        }
    }
}

/// Nodes a [`ScheduleStream`] lets pile up before it drops those it no
/// longer reads.
const FORGET_AT: usize = 1024;

/// A solved x as the schedule keeps it, through its speed v = √x (so that
/// a stream's intervals are a whole schedule's to the bit).
fn as_speed_squared(x: f64) -> f64 {
    let v = x.max(0.0).sqrt();
    v * v
}

/// Builds the nodes, then solves.
struct Sampler {
    limits: AxisLimits,
    config: ScheduleConfig,
    nodes: Vec<Node>,
    /// The last node must be at rest.
    rest: bool,
    dwell: f64,
}

impl Sampler {
    /// Largest x the axes' velocity limits and the feed allow at `g`.
    fn velocity_cap(&self, g: &Geometry, feed: f64) -> f64 {
        let mut x = feed * feed;
        for i in 0..9 {
            if g.t[i] != 0.0 {
                x = x.min((self.limits.v[i] / g.t[i]).powi(2));
            }
        }
        x
    }

    fn push(&mut self, index: usize, segment: &Segment) {
        if !segment.is_motion() {
            if let SegmentKind::Dwell { seconds } = segment.kind {
                self.dwell += seconds.max(0.0);
            }
            self.rest = true;
            if let Some(last) = self.nodes.last_mut() {
                last.xmax = 0.0;
            }
            return;
        }
        if segment.length <= 0.0 {
            return;
        }
        let feed = match segment.kind {
            SegmentKind::Feed => segment.feed,
            _ => f64::INFINITY,
        };
        let len = segment.length;
        let ds = match self.config.nodes_per_period {
            Some(per) => {
                let top = feed.min(segment.max_velocity);
                if top.is_finite() {
                    self.config.ds.max(top * self.config.period / per)
                } else {
                    self.config.ds
                }
            }
            None => self.config.ds,
        };
        let n = ((len / ds).ceil() as usize).max(4);
        let at = |k: usize| len * k as f64 / n as f64;
        let geometry = |s: f64| Geometry::at(segment, s);
        let first = geometry(0.0);
        let start_cap = self.velocity_cap(&first, feed);
        match self.nodes.last_mut() {
            Some(last) if !self.rest => {
                // A junction at speed: the planner's caps where the
                // tangent or the curvature jumps.
                let before = last.left;
                let (period, a, j) = (self.config.period, self.limits.a, self.limits.j);
                let mut x = last.xmax.min(start_cap);
                let mut smooth = true;
                for i in 0..9 {
                    let kink = (first.t[i] - before.t[i]).abs();
                    if kink > 1e-9 {
                        x = x.min((a[i] * period / kink).powi(2));
                        smooth = false;
                    }
                    let bend = (first.c[i] - before.c[i]).abs();
                    if bend > 1e-6 * (1.0 + first.c[i].abs()) {
                        x = x.min(j[i] * period / bend);
                        smooth = false;
                    }
                }
                last.right = first;
                last.xmax = x;
                last.smooth = smooth;
            }
            _ => {
                // From rest: a node of its own (the step to it from the
                // last node, if any, has zero length).
                self.nodes.push(Node {
                    left: first,
                    right: first,
                    inner: [first; INNER],
                    stride: JUDGED_PER_HALF,
                    xmax: 0.0,
                    h: 0.0,
                    smooth: false,
                    segment: index,
                    at: 0.0,
                });
            }
        }
        for k in 1..=n {
            let last = self.nodes.last_mut().expect("a node was pushed above");
            last.h = at(k) - at(k - 1);
            let (from, h) = (at(k - 1), at(k) - at(k - 1));
            last.inner = std::array::from_fn(|j| {
                geometry(from + (j + 1) as f64 * h / (2 * JUDGED_PER_HALF) as f64)
            });
            let g = geometry(at(k));
            last.stride = stride(&last.right, &last.inner, &g);
            let xmax = self.velocity_cap(&g, feed);
            self.nodes.push(Node {
                left: g,
                right: g,
                inner: [g; INNER],
                stride: JUDGED_PER_HALF,
                xmax,
                h: 0.0,
                smooth: true,
                segment: index,
                at: at(k),
            });
        }
        self.rest = segment.exit_velocity == 0.0;
        if self.rest {
            self.nodes.last_mut().expect("pushed above").xmax = 0.0;
        }
    }

    fn solve(mut self) -> Schedule {
        let n = self.nodes.len();
        let mut out = Schedule::empty(self.dwell, self.config.period);
        out.s.reserve(n);
        out.v = vec![0.0; n];
        out.step = vec![0.0; n];
        if n == 0 {
            return out;
        }
        self.nodes[0].xmax = 0.0;
        self.nodes[n - 1].xmax = 0.0;
        let mut start = 0;
        for k in 1..n {
            if self.nodes[k].xmax > 0.0 {
                continue;
            }
            let stretch = &self.nodes[start..=k];
            if stretch.iter().any(|node| node.xmax > 0.0) {
                out.stretches += 1;
                let x = self.stretch(stretch, &mut out);
                for (m, &x) in x.iter().enumerate() {
                    out.v[start + m] = x.max(0.0).sqrt();
                }
            }
            start = k;
        }
        let mut s = 0.0;
        for k in 0..n {
            out.s.push(s);
            s += self.nodes[k].h;
            if self.nodes[k].h > 0.0 {
                out.step[k] = interval_time(self.nodes[k].h, out.v[k], out.v[k + 1]);
                out.time += out.step[k];
            }
        }
        out.nodes = self.nodes;
        out
    }

    /// x at every node of one stretch (from rest to rest).
    fn stretch(&self, nodes: &[Node], out: &mut Schedule) -> Vec<f64> {
        match self.config.window {
            Some(window) if nodes.len() > window.horizon + 1 => self.windowed(nodes, window, out),
            _ => self.whole(nodes, out),
        }
    }

    /// x at every node of one stretch (from rest to rest) solved whole; a
    /// stretch with no solution stands still, and `out.stranded` lists it.
    fn whole(&self, nodes: &[Node], out: &mut Schedule) -> Vec<f64> {
        let guess = self.first_guess(nodes, Start::Rest, None);
        self.passes(nodes, Start::Rest, guess, out)
            .unwrap_or_else(|| {
                let m = nodes.len();
                out.stranded
                    .push((nodes[0].segment, nodes[m - 1].segment, m));
                vec![0.0; m]
            })
    }

    /// One stretch window by window (see [`Window`]).
    fn windowed(&self, nodes: &[Node], window: Window, out: &mut Schedule) -> Vec<f64> {
        let mut windows = Windows::new(nodes.len());
        while windows.next(self, nodes, true, window, out) != WindowStep::Done {}
        windows.x
    }

    /// The first linearisation point: half of what the acceleration
    /// limits alone allow (the jerk-limited schedule is slower; a guess
    /// above it puts the first tangents where they bind hardest), or
    /// where the window before solved these nodes, the solution it found.
    /// Over that solution's last descent to rest, which only that
    /// window's end asked for, the higher of the two: a pass can raise x
    /// at most threefold over its guess (the tangent of 1/√x at x̄ reaches
    /// zero at 3x̄), so from the descent it would take many passes to
    /// climb back. Elsewhere the solution itself, whose tangents are the
    /// loosest there and keep the committed state's continuation
    /// feasible. With the higher guess everywhere the solver gave up 212
    /// times in the 175 windows of stellabee1.ngc's first 20,000 lines
    /// (3 times this way), and the schedule was 0.6 % slower.
    fn first_guess(&self, nodes: &[Node], from: Start, before: Option<&[f64]>) -> Vec<f64> {
        let mut guess = self.second_order(nodes, from);
        for x in guess.iter_mut() {
            *x *= 0.5;
        }
        if let Some(before) = before {
            // Where that solution's last descent to rest begins.
            let mut descent = before.len() - 1;
            while descent > 0 && before[descent - 1] >= before[descent] {
                descent -= 1;
            }
            for (k, (guess, &before)) in guess.iter_mut().zip(before).enumerate() {
                *guess = if k < descent {
                    before
                } else {
                    guess.max(before)
                };
            }
        }
        if let Start::Moving(fixed) = from {
            guess[..3].copy_from_slice(&fixed);
        }
        guess
    }

    /// x at every node of `nodes` (ending at rest, starting at `from`):
    /// the best by time of the passes from `guess`, or `None` when the
    /// solver gave up on every one.
    fn passes(
        &self,
        nodes: &[Node],
        from: Start,
        mut guess: Vec<f64>,
        out: &mut Schedule,
    ) -> Option<Vec<f64>> {
        let m = nodes.len();
        let time = |x: &[f64]| -> f64 {
            (0..m - 1)
                .filter(|&k| nodes[k].h > 0.0)
                .map(|k| interval_time(nodes[k].h, x[k].max(0.0).sqrt(), x[k + 1].max(0.0).sqrt()))
                .sum()
        };
        let mut best: Option<(Vec<f64>, f64)> = None;
        let mut retries = 0;
        let mut pass = 0;
        let first = guess.clone();
        let mut moving = MOVING_X;
        while pass < self.config.passes {
            out.solves += 1;
            // Crests where the guess has them once it is a solution: the
            // first guess's, of a profile under the acceleration limits
            // alone, are nowhere near the solution's, and with them a
            // window of a plain line found no solution from any guess.
            let turns = pass > 0;
            let Some(x) = self.linear_program(nodes, &guess, from, moving, turns) else {
                out.failed += 1;
                // The solver gave up (numerically): from a lower guess,
                // whose tangents are steeper, while nothing was found;
                // else keep the best found.
                if best.is_some() {
                    break;
                }
                if retries == RETRIES {
                    // Nothing from any guess. The speed kept away from
                    // the stops may be more than the path allows there:
                    // stellabee1.ngc has some 300 stretches whose tight
                    // blends the jerk holds below 1 mm/s. Lower it, down
                    // to none.
                    if moving == 0.0 {
                        break;
                    }
                    moving = if moving > MOVING_X * LOWER_FLOOR {
                        MOVING_X * LOWER_FLOOR
                    } else {
                        0.0
                    };
                    retries = 0;
                    guess.copy_from_slice(&first);
                    continue;
                }
                retries += 1;
                for x in guess.iter_mut() {
                    *x *= 0.25;
                }
                if let Start::Moving(fixed) = from {
                    guess[..3].copy_from_slice(&fixed);
                }
                continue;
            };
            pass += 1;
            let t = time(&x);
            if best.as_ref().is_none_or(|(_, best)| t < *best) {
                best = Some((x.clone(), t));
            }
            guess = x;
        }
        best.map(|(x, _)| x)
    }

    /// Forward and backward passes under the acceleration limits alone,
    /// from `from`.
    fn second_order(&self, nodes: &[Node], from: Start) -> Vec<f64> {
        let mut x: Vec<f64> = nodes.iter().map(|n| n.xmax).collect();
        let most = |g: &Geometry, x: f64| {
            let mut u = f64::INFINITY;
            for i in 0..9 {
                if g.t[i] != 0.0 {
                    u = u.min((self.limits.a[i] - (g.c[i] * x).abs()) / g.t[i].abs());
                }
            }
            u.max(0.0)
        };
        let m = nodes.len();
        match from {
            Start::Rest => x[0] = 0.0,
            Start::Moving(fixed) => x[..3].copy_from_slice(&fixed),
        }
        x[m - 1] = 0.0;
        for k in 0..m - 1 {
            let u = most(&nodes[k].right, x[k]);
            x[k + 1] = x[k + 1].min(x[k] + 2.0 * u * nodes[k].h);
        }
        for k in (0..m - 1).rev() {
            let u = most(&nodes[k + 1].left, x[k + 1]);
            x[k] = x[k].min(x[k + 1] + 2.0 * u * nodes[k].h);
        }
        x
    }

    /// One linear program: the velocity, acceleration and (linearised
    /// about `guess`) jerk limits, the cycle time's first-order change
    /// about `guess` as objective. `None` when the solver gives up.
    fn linear_program(
        &self,
        nodes: &[Node],
        guess: &[f64],
        from: Start,
        moving: f64,
        turns: bool,
    ) -> Option<Vec<f64>> {
        let m = nodes.len();
        let (a_max, j_max) = (&self.limits.a, &self.limits.j);
        // The stops are at rest: held at zero rather than bounded both
        // ways, which would leave the program no interior. A moving start
        // is held too, its values moved into the rows' bounds.
        let mut lp = BandedLp::new(m);
        lp.fix_zero(0);
        lp.fix_zero(m - 1);
        let fixed = match from {
            Start::Rest => None,
            Start::Moving(fixed) => {
                lp.fix_zero(1);
                lp.fix_zero(2);
                Some(fixed)
            }
        };
        let mut rows = Rows { lp, fixed };
        for (k, node) in nodes.iter().enumerate().take(m - 1).skip(1) {
            // An infinite cap is no row.
            rows.push(&[(k, 1.0)], node.xmax);
            rows.push(&[(k, -1.0)], 0.0);
        }
        // Out of rest and into it: the path's jerk s⃛ is at most
        // J_p = min J_i/|t_i| there (the other terms vanish with v), and
        // no motion from rest gets further in speed by a distance d than
        // the one at J_p throughout: v = (J_p/2)·(6d/J_p)^{2/3}, so x ≤
        // C·d^{4/3}. The jerk rows below cannot see this (the jerk is
        // v·(…) and v = 0 at the stop), so without it the discretised
        // schedule would start at full acceleration.
        let rest_cap = |g: &Geometry| {
            let jp = (0..9)
                .filter(|&i| g.t[i] != 0.0)
                .map(|i| j_max[i] / g.t[i].abs())
                .fold(f64::INFINITY, f64::min);
            jp.powf(2.0 / 3.0) * 6f64.powf(4.0 / 3.0) / 4.0
        };
        let c_start = match from {
            Start::Rest => rest_cap(&nodes[0].right),
            Start::Moving(_) => f64::INFINITY,
        };
        let c_end = rest_cap(&nodes[m - 1].left);
        let (mut from_start, mut from_end) = (0.0, 0.0);
        for k in 1..m - 1 {
            from_start += nodes[k - 1].h;
            if k > REST_NODES {
                break;
            }
            if c_start.is_finite() {
                rows.push(&[(k, 1.0)], c_start * from_start.powf(4.0 / 3.0));
            }
        }
        for k in (1..m - 1).rev() {
            from_end += nodes[k].h;
            if m - 1 - k > REST_NODES {
                break;
            }
            if c_end.is_finite() {
                rows.push(&[(k, 1.0)], c_end * from_end.powf(4.0 / 3.0));
            }
        }
        // Acceleration over the ramps out of rest and into it, judged at
        // both their ends: t·(x_{k+1} − x_k)/(2h) + c·x_end. (Every other
        // interval's is judged below, where the motion between nodes has
        // it.)
        for k in [0, m.saturating_sub(2)] {
            let h = nodes[k].h;
            if h == 0.0 {
                continue;
            }
            let w = 1.0 / (2.0 * h);
            for (end, g) in [(k, &nodes[k].right), (k + 1, &nodes[k + 1].left)] {
                for i in 0..9 {
                    if g.t[i] == 0.0 && g.c[i] == 0.0 {
                        continue;
                    }
                    for sign in [1.0, -1.0] {
                        rows.push(
                            &[
                                (k, -sign * g.t[i] * w),
                                (k + 1, sign * g.t[i] * w),
                                (end, sign * g.c[i]),
                            ],
                            a_max[i],
                        );
                    }
                }
            }
        }
        // Jerk as the motion between nodes has it (`Interpolant::
        // SpeedInLength`, which `JerkPoints` spells out), at both ends and
        // the middle of every interval that starts and ends in motion:
        // |t·u′ + 3c·u + d·x| ≤ J·L(x) with L the tangent of 1/√x at the
        // point's guess.
        let top = guess.iter().copied().fold(0.0, f64::max);
        if top <= 0.0 {
            return Some(vec![0.0; m]);
        }
        let floor = (top * 1e-4).max(1e-9);
        let rest_start = from == Start::Rest;
        // Interval 0 is the ramp out of rest, or, in a window that starts
        // moving, the window before's; the last is the ramp into rest.
        for k in 1..m.saturating_sub(2) {
            let points = JerkPoints::new(nodes, k, |i| (i == 0 && rest_start) || i + 1 == m);
            let base = k - 1;
            let value = |form: &[f64; 4]| apply(form, guess, base);
            // Away from the stops the motion keeps a little speed, at the
            // nodes and between them: where x all but vanishes its jerk
            // rows (√x times the rest) say nothing, and the solutions
            // then all but stopped and started again at full acceleration
            // between two nodes, which the motion between them cannot do.
            if moving > 0.0 && k > REST_NODES && k + 1 + REST_NODES < m {
                let least = moving.min(0.5 * nodes[k].xmax.min(nodes[k + 1].xmax));
                for form in points.start_and_middle() {
                    let terms: [(usize, f64); 4] = std::array::from_fn(|o| (base + o, -form[o]));
                    rows.push(&terms, -least);
                }
            }
            // The speed's crests inside a half where the guess has them,
            // held to the velocity limit there too (the nodes' caps
            // bound it only at the nodes). Not across a window's seam:
            // the window before judged those intervals, its crests where
            // its guess had them, and committed nodes that may break a
            // crest row put elsewhere, with nothing left free to mend it.
            // Only where an interval lasts longer than a servo period
            // at the guess's speed: the samples then see inside it, while
            // over shorter ones they average the crest away (and at 0.01
            // mm nodes the crests' rows made a windowed line's linear
            // program stall).
            let turns = turns && !(rows.fixed.is_some() && k < 3);
            let crests = if !turns || !outlasts_period(nodes, guess, k, self.config.period) {
                [None, None]
            } else {
                points.crests(guess, base)
            };
            for crest in crests.iter().flatten() {
                let cap = self
                    .velocity_cap(&crest.geometry, f64::INFINITY)
                    .min(nodes[k].xmax)
                    .min(nodes[k + 1].xmax);
                if cap.is_finite() {
                    let terms: [(usize, f64); 4] = std::array::from_fn(|o| (base + o, crest.x[o]));
                    rows.push(&terms, cap);
                }
            }
            // Nor may the speed dip towards rest between the nodes: the
            // follower would take the interval at constant path
            // acceleration instead (`interval_piece`), a step of
            // acceleration at either end, which broke the jerk limit
            // (1.157 of it next to a stop, with nodes two a servo period
            // apart). x at a valley of the guess stays above half of x
            // at the node where the guess is slower.
            if turns {
                let end = if guess[k] <= guess[k + 1] { 1 } else { 2 };
                for valley in points.valleys(guess, base).iter().flatten() {
                    let terms: [(usize, f64); 4] = std::array::from_fn(|o| {
                        let node = if o == end { 0.5 } else { 0.0 };
                        (base + o, node - valley.x[o])
                    });
                    rows.push(&terms, 0.0);
                }
            }
            for point in points.points().chain(crests.into_iter().flatten()) {
                for i in 0..9 {
                    let g = point.geometry;
                    if !j_max[i].is_finite() || (g.t[i] == 0.0 && g.c[i] == 0.0 && g.d[i] == 0.0) {
                        continue;
                    }
                    let expr: [f64; 4] = std::array::from_fn(|o| {
                        g.t[i] * point.slope[o] + 3.0 * g.c[i] * point.u[o] + g.d[i] * point.x[o]
                    });
                    let xb = value(&point.x).max(floor);
                    // L(x) = 3/(2√x̄) − x/(2·x̄^{3/2}).
                    let (l0, l1) = (1.5 / xb.sqrt(), 0.5 / (xb * xb.sqrt()));
                    for sign in [1.0, -1.0] {
                        let terms: [(usize, f64); 4] = std::array::from_fn(|o| {
                            (base + o, sign * expr[o] + j_max[i] * l1 * point.x[o])
                        });
                        rows.push(&terms, j_max[i] * l0);
                    }
                }
                // The axes' acceleration t·u + c·x there too. (The
                // middle's row comes twice, with each half's point: without
                // the copy, a window of a plain line in tests/schedule.rs
                // stalled at 1.6e-6 of the interior-point solver's
                // optimality, just past its acceptance of 1e-6, and
                // accepting 1e-5 instead let a junction of stellabee1.ngc
                // through at 1.003 of its jerk limit.)
                for i in 0..9 {
                    let g = point.geometry;
                    if g.t[i] == 0.0 && g.c[i] == 0.0 {
                        continue;
                    }
                    let expr: [f64; 4] =
                        std::array::from_fn(|o| g.t[i] * point.u[o] + g.c[i] * point.x[o]);
                    for sign in [1.0, -1.0] {
                        let terms: [(usize, f64); 4] =
                            std::array::from_fn(|o| (base + o, sign * expr[o]));
                        rows.push(&terms, a_max[i]);
                    }
                }
            }
        }
        // Objective: the cycle time's change, −Σ w_k·x_k/(2·x̄^{3/2}) with
        // w_k the node's share of length; scaled to the fastest node.
        let objective: Vec<f64> = (0..m)
            .map(|k| {
                let before = if k > 0 { nodes[k - 1].h } else { 0.0 };
                let share = (before + nodes[k].h) / 2.0;
                -share * (top / guess[k].max(top * 1e-3)).powf(1.5)
            })
            .collect();
        let mut x = match rows.solve(&objective, top) {
            Ok(x) => x,
            Err(_) => return None,
        };
        // The stops exactly at rest; anything the solver left a rounding
        // below zero, at zero.
        for x in x.iter_mut() {
            *x = x.max(0.0);
        }
        if let Some(fixed) = fixed {
            x[..3].copy_from_slice(&fixed);
        }
        x[m - 1] = 0.0;
        Some(x)
    }
}

/// Interval `k` lasts longer than `period` at `x` even at its faster
/// node's speed: the servo's samples see inside it, so the speed's
/// crests there are judged.
fn outlasts_period(nodes: &[Node], x: &[f64], k: usize, period: f64) -> bool {
    nodes[k].h > period * x[k].max(x[k + 1]).sqrt()
}

/// u = ½·dx/ds at node `j` as [`Interpolant::SpeedInLength`] takes it, as
/// coefficients of x at nodes j − 1, j, j + 1: the end slope of a ramp to
/// or from rest beside it, else the slopes of the intervals either side
/// interpolated from their midpoints to the node. `rest(i)`: node i is a
/// stop. ([`node_u`] applies it to the schedule's values.)
fn node_slope(nodes: &[Node], j: usize, rest: impl Fn(usize) -> bool) -> [f64; 3] {
    let m = nodes.len();
    let before = j >= 1 && nodes[j - 1].h > 0.0;
    let after = j + 1 < m && nodes[j].h > 0.0;
    let (h0, h1) = (
        if before { nodes[j - 1].h } else { 0.0 },
        if after { nodes[j].h } else { 0.0 },
    );
    let out_of_rest = before && rest(j - 1);
    let into_rest = after && rest(j + 1);
    match (out_of_rest, into_rest, before, after) {
        (true, true, _, _) => [0.0, (1.0 / h0 - 1.0 / h1) / 3.0, 0.0],
        (true, false, _, _) => [0.0, 2.0 / (3.0 * h0), 0.0],
        (false, true, _, _) => [0.0, -2.0 / (3.0 * h1), 0.0],
        (false, false, true, true) => {
            let sum = h0 + h1;
            [
                -h1 / (2.0 * h0 * sum),
                h1 / (2.0 * h0 * sum) - h0 / (2.0 * h1 * sum),
                h0 / (2.0 * h1 * sum),
            ]
        }
        (false, false, true, false) => [-0.5 / h0, 0.5 / h0, 0.0],
        (false, false, false, true) => [0.0, -0.5 / h1, 0.5 / h1],
        (false, false, false, false) => [0.0; 3],
    }
}

/// Σ form[o]·x[first + o]: a linear form over neighbouring nodes applied
/// to values (terms with a zero coefficient skipped, so a form may reach
/// past either end of `x` where it has none).
fn apply(form: &[f64], x: &[f64], first: usize) -> f64 {
    form.iter()
        .enumerate()
        .filter(|&(_, &c)| c != 0.0)
        .map(|(o, c)| c * x[first + o])
        .sum()
}

/// A point of an interval where the jerk and acceleration of
/// [`Interpolant::SpeedInLength`] are judged: its geometry, and x, u and
/// u′ there as coefficients of x at the nodes k − 1 … k + 2 of interval k.
#[derive(Clone, Copy)]
struct JerkPoint {
    geometry: Geometry,
    x: [f64; 4],
    u: [f64; 4],
    slope: [f64; 4],
}

/// The points of interval k (both its nodes in motion) where the motion
/// between nodes is judged: the ends of each half and
/// [`JUDGED_PER_HALF`] − 1 points inside it. On each half u is linear,
/// so u′ is constant, and x and u vary only slowly between these points;
/// the inside points catch the geometry of dense-curve blends, whose
/// curvature turns within an interval.
struct JerkPoints<'n> {
    nodes: &'n [Node],
    k: usize,
    /// x at the start of each half and its u there and at its end.
    starts: [[f64; 4]; 2],
    ends: [[[f64; 4]; 2]; 2],
    /// u′ on each half.
    halves: [[f64; 4]; 2],
    h: f64,
}

impl<'n> JerkPoints<'n> {
    /// Interval `k` (k ≥ 1) of `nodes`; `rest(i)`: node i is a stop.
    fn new(nodes: &'n [Node], k: usize, rest: impl Fn(usize) -> bool) -> JerkPoints<'n> {
        let h = nodes[k].h;
        let place = |form: [f64; 3], offset: usize| -> [f64; 4] {
            std::array::from_fn(|o| {
                if o >= offset && o < offset + 3 {
                    form[o - offset]
                } else {
                    0.0
                }
            })
        };
        let u0 = place(node_slope(nodes, k, &rest), 0);
        let u1 = place(node_slope(nodes, k + 1, rest), 1);
        let slope = [0.0, -0.5 / h, 0.5 / h, 0.0];
        // The middle's u chosen so that x meets the next node's.
        let um: [f64; 4] = std::array::from_fn(|o| 2.0 * slope[o] - 0.5 * (u0[o] + u1[o]));
        let x0 = [0.0, 1.0, 0.0, 0.0];
        // x = x0 + 2·∫u ds with u linear on each half.
        let xm = std::array::from_fn(|o| x0[o] + 0.5 * h * (u0[o] + um[o]));
        JerkPoints {
            nodes,
            k,
            starts: [x0, xm],
            ends: [[u0, um], [um, u1]],
            halves: [
                std::array::from_fn(|o| 2.0 * (um[o] - u0[o]) / h),
                std::array::from_fn(|o| 2.0 * (u1[o] - um[o]) / h),
            ],
            h,
        }
    }

    fn points(&self) -> impl Iterator<Item = JerkPoint> + '_ {
        let stride = self.nodes[self.k].stride;
        (0..JUDGED)
            .filter(move |p| (p % (JUDGED_PER_HALF + 1)).is_multiple_of(stride))
            .map(move |p| {
                let (half, q) = (p / (JUDGED_PER_HALF + 1), p % (JUDGED_PER_HALF + 1));
                self.point(half, q as f64 / JUDGED_PER_HALF as f64)
            })
    }

    /// Geometry `step`/(2·[`JUDGED_PER_HALF`]) along the interval.
    fn geometry(&self, step: usize) -> &'n Geometry {
        let (here, next) = (&self.nodes[self.k], &self.nodes[self.k + 1]);
        match step {
            0 => &here.right,
            _ if step == 2 * JUDGED_PER_HALF => &next.left,
            _ => &here.inner[step - 1],
        }
    }

    /// The point a share `f` (0 ≤ f ≤ 1) into half `half`. Its geometry
    /// is the judged points' between them, interpolated: [`stride`] keeps
    /// it within [`GEOMETRY_STRAY`] of the path's own where the points
    /// are thinned, and on lines it is exact.
    fn point(&self, half: usize, f: f64) -> JerkPoint {
        let along = (half as f64 + f) * JUDGED_PER_HALF as f64;
        let below = (along.floor() as usize).min(2 * JUDGED_PER_HALF);
        let w = along - below as f64;
        let geometry = if w <= 0.0 {
            *self.geometry(below)
        } else {
            let (a, b) = (self.geometry(below), self.geometry(below + 1));
            let mix = |p: &Vec9, q: &Vec9| std::array::from_fn(|i| (1.0 - w) * p[i] + w * q[i]);
            Geometry {
                t: mix(&a.t, &b.t),
                c: mix(&a.c, &b.c),
                d: mix(&a.d, &b.d),
            }
        };
        let [ua, ub] = self.ends[half];
        let x0 = self.starts[half];
        JerkPoint {
            geometry,
            // x = x0 + h·(ua·f + (ub − ua)·f²/2) at a share f of the
            // half; the ends exactly as the nodes and the middle have
            // them (the interval's end is node k + 1's x).
            x: match half {
                _ if f == 0.0 => x0,
                0 if f == 1.0 => self.starts[1],
                _ if f == 1.0 => [0.0, 0.0, 1.0, 0.0],
                _ => std::array::from_fn(|o| {
                    x0[o] + self.h * (ua[o] * f + 0.5 * (ub[o] - ua[o]) * f * f)
                }),
            },
            u: if f == 0.0 {
                ua
            } else if f == 1.0 {
                ub
            } else {
                std::array::from_fn(|o| ua[o] + f * (ub[o] - ua[o]))
            },
            slope: self.halves[half],
        }
    }

    /// Where x peaks inside a half at the nodes' values `x` (from node
    /// k − 1 on): u falls through zero there. Judged at the halves' ends
    /// and inside points alone, a crest between them goes unseen, and
    /// the jerk there (on a line √x·t·u′, largest where x is) exceeds
    /// what the points show: 1.007 of the limit on stellabee1.ngc's
    /// lines with nodes 0.05–0.08 mm apart. One point a half with a
    /// crest inside, between the judged points either side.
    fn crests(&self, x: &[f64], first: usize) -> [Option<JerkPoint>; 2] {
        let [ua, um, ub] = self.turning_slopes(x, first);
        let starts = self.starts.map(|form| apply(&form, x, first));
        [(0, ua, um), (1, um, ub)].map(|(half, ua, ub)| {
            let f = ua / (ua - ub);
            // x's rise from the half's start to the crest.
            let rise = 0.5 * self.h * ua * f;
            (ua > 0.0 && ub < 0.0 && rise > CREST_RISE * starts[half]).then(|| self.point(half, f))
        })
    }

    /// u at the interval's start, middle and end at the nodes' values `x`
    /// (from node k − 1 on).
    fn turning_slopes(&self, x: &[f64], first: usize) -> [f64; 3] {
        [self.ends[0][0], self.ends[0][1], self.ends[1][1]].map(|form| apply(&form, x, first))
    }

    /// Where x is lowest inside each half at the nodes' values `x` (from
    /// node k − 1 on): u rises through zero there.
    fn valleys(&self, x: &[f64], first: usize) -> [Option<JerkPoint>; 2] {
        let [ua, um, ub] = self.turning_slopes(x, first);
        [(0, ua, um), (1, um, ub)]
            .map(|(half, ua, ub)| (ua < 0.0 && ub > 0.0).then(|| self.point(half, ua / (ua - ub))))
    }

    /// x at the start of the interval and at its middle (the forms the
    /// floor on x away from the stops is put on).
    fn start_and_middle(&self) -> [[f64; 4]; 2] {
        self.starts
    }
}

/// Time over an interval of length `h` between speeds `v0` and `v1`:
/// 2h/(v0 + v1) at constant acceleration, and 3h/v out of rest or into it,
/// where the ramp at constant jerk has v ∝ s^{2/3}.
fn interval_time(h: f64, v0: f64, v1: f64) -> f64 {
    match (v0 > 0.0, v1 > 0.0) {
        (true, true) => 2.0 * h / (v0 + v1),
        (false, false) => f64::INFINITY,
        _ => 3.0 * h / (v0 + v1),
    }
}

/// A stretch solved window by window, one window a call, so that a
/// planner can solve each window as the segments it spans arrive
/// ([`ScheduleStream`]) or all of them in turn ([`Sampler::windowed`]).
struct Windows {
    /// x at the stretch's nodes, committed up to `committed`.
    x: Vec<f64>,
    committed: usize,
    /// The next window starts at node `begin`, in state `from`.
    begin: usize,
    from: Start,
    /// The last window solved: its first node and its solution, which
    /// ends at rest.
    last: Option<(usize, Vec<f64>)>,
    /// No window had a solution from rest: the stretch stands still.
    still: bool,
}

/// What one call of [`Windows::next`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum WindowStep {
    /// Committed x up to `Windows::committed`; more windows to come.
    Committed,
    /// The stretch is solved to its end.
    Done,
    /// The next window reaches past the nodes there are so far.
    NeedMore,
}

impl Windows {
    /// A stretch of `m` nodes (as far as known) from rest.
    fn new(m: usize) -> Windows {
        Windows {
            x: vec![0.0; m],
            committed: 0,
            begin: 0,
            from: Start::Rest,
            last: None,
            still: false,
        }
    }

    /// The first node (of the stretch) the windows still read: the next
    /// window's start, or the last window's solution's.
    fn first_needed(&self) -> usize {
        match &self.last {
            Some((at, _)) => self.begin.min(*at),
            None => self.begin,
        }
    }

    /// Forgets the stretch's first `by` nodes (at most
    /// [`Windows::first_needed`]): every index moves down by `by`.
    fn shift(&mut self, by: usize) {
        self.x.drain(..by);
        self.committed -= by;
        self.begin -= by;
        if let Some((at, _)) = &mut self.last {
            *at -= by;
        }
    }

    /// Solves the next window over `nodes` (the stretch's nodes so far;
    /// all of them when `complete`, its last then the stop it ends at).
    fn next(
        &mut self,
        sampler: &Sampler,
        nodes: &[Node],
        complete: bool,
        window: Window,
        out: &mut Schedule,
    ) -> WindowStep {
        let m = nodes.len();
        if self.x.len() < m {
            self.x.resize(m, 0.0);
        }
        if self.still {
            self.committed = m;
            return if complete {
                WindowStep::Done
            } else {
                WindowStep::NeedMore
            };
        }
        let commit = window.commit.clamp(4, window.horizon.max(5) - 1);
        let end = self.begin + window.horizon;
        let end = if complete {
            end.min(m - 1)
        } else if end < m {
            end
        } else {
            return WindowStep::NeedMore;
        };
        let begin = self.begin;
        let span = &nodes[begin..=end];
        out.windows += 1;
        let guess = sampler.first_guess(
            span,
            self.from,
            self.last.as_ref().map(|(at, sol)| &sol[begin - at..]),
        );
        let mut solved = sampler.passes(span, self.from, guess, out);
        if solved.is_none() {
            // The first guess can linearise the jerk limit more
            // tightly than the window before did, so tightly that the
            // committed state has no continuation. Linearised about
            // that window's own solution (at rest past its end), every
            // row that window had holds that solution again (each
            // jerk row's tangent now touches 1/√x there); only the
            // jerk rows at its end node are new, loose at the guess's
            // floor but not proven to hold.
            if let Some((at, sol)) = &self.last {
                let mut guess = vec![0.0; span.len()];
                let before = &sol[begin - at..];
                guess[..before.len()].copy_from_slice(before);
                solved = sampler.passes(span, self.from, guess, out);
            }
        }
        match solved {
            Some(sol) if complete && end == m - 1 => {
                self.x[begin..].copy_from_slice(&sol);
                self.committed = m;
                WindowStep::Done
            }
            Some(sol) => {
                let keep = begin + commit;
                self.x[begin..keep].copy_from_slice(&sol[..commit]);
                self.committed = keep;
                self.last = Some((begin, sol));
                self.begin = keep - 3;
                let b = self.begin;
                self.from = Start::Moving([self.x[b], self.x[b + 1], self.x[b + 2]]);
                WindowStep::Committed
            }
            None => {
                // Nothing within the limits from the committed state:
                // follow the last window's solution to its rest, as a
                // planner that runs ahead would, and start again from
                // there. With no such solution (the first window, or
                // one from rest), the stretch stands still, as a
                // stretch solved whole does.
                let Some((at, sol)) = self.last.take() else {
                    self.x[begin..].fill(0.0);
                    self.committed = m;
                    // Until the stretch ends: the rest of it is committed
                    // at rest as it arrives.
                    self.still = true;
                    return if complete {
                        WindowStep::Done
                    } else {
                        WindowStep::Committed
                    };
                };
                out.window_rests += 1;
                let rest = at + sol.len() - 1;
                self.x[begin..=rest].copy_from_slice(&sol[begin - at..]);
                self.committed = rest + 1;
                if complete && rest == m - 1 {
                    return WindowStep::Done;
                }
                self.begin = rest;
                self.from = Start::Rest;
                WindowStep::Committed
            }
        }
    }
}

/// Where a stretch or a window starts.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Start {
    /// At rest (x = 0 at the first node).
    Rest,
    /// Moving, with x at the first three nodes fixed by the window before.
    Moving([f64; 3]),
}

/// Constraint rows a·x ≤ b, built row by row, each within four
/// neighbouring nodes.
struct Rows {
    lp: BandedLp,
    /// x at columns 0, 1 and 2, when fixed by the window before: their terms
    /// move into the bound, and a row with nothing else, already kept by
    /// that window, is dropped.
    fixed: Option<[f64; 3]>,
}

impl Rows {
    fn push(&mut self, terms: &[(usize, f64)], bound: f64) {
        let banded = match self.fixed {
            None => self.lp.push(terms, bound),
            Some(fixed) => {
                let mut free = [(0, 0.0); 4];
                let (mut n, mut room) = (0, bound);
                for &(column, value) in terms {
                    if column < 3 {
                        room -= value * fixed[column];
                    } else {
                        free[n] = (column, value);
                        n += 1;
                    }
                }
                if n == 0 {
                    return;
                }
                if n < terms.len() {
                    // The window before committed these nodes at its own
                    // limits, so a row across the seam can leave the free
                    // nodes a single feasible value, and the interior-
                    // point method no interior to move in. SEAM_ROOM of
                    // the row's bound gives it one.
                    room += SEAM_ROOM * bound.abs();
                }
                self.lp.push(&free[..n], room)
            }
        };
        // Every row this module builds spans at most four neighbouring
        // nodes.
        debug_assert!(banded.is_ok(), "a row beyond four neighbouring nodes");
    }

    fn solve(&self, objective: &[f64], scale: f64) -> Result<Vec<f64>, Failure> {
        self.lp.solve(objective, scale)
    }
}

/// The schedule followed in time and sampled every servo period, as an
/// executor following it would move the axes: see [`Schedule::sampled`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sampled {
    /// Motion time, s (dwells left out): each interval lasts as
    /// [`interval_time`] counts it ([`Interpolant::QuinticInTime`]) or as
    /// long as its speed in arc length takes ([`Interpolant::SpeedInLength`],
    /// within a fraction of a per cent of the first).
    pub time: f64,
    /// Largest axis velocity, acceleration and jerk use, by finite
    /// differences of the sampled positions.
    pub limits: ScheduleUse,
    /// The largest jerk use at samples more than [`REST_NODES`] nodes
    /// from a stop, where the schedule's own jerk rows hold (next to a
    /// stop it caps the speed by the ramp out of rest instead).
    pub jerk_in_motion: f64,
    /// With [`Interpolant::SpeedInLength`]: intervals whose speed would
    /// have dipped towards rest between the nodes, followed with constant
    /// path acceleration instead (a step of acceleration at each end).
    pub flattened: usize,
    /// With [`Interpolant::SpeedInLength`]: servo periods the follower
    /// ran, until it reached the end (times the period, the motion time
    /// under the overrides of [`Schedule::followed`]).
    pub periods: u64,
}

/// The path position `t` into an interval of duration `d` from (speed
/// `v0`, path acceleration `a0`) to (`v1`, `a1`) over `h`: the quintic
/// that meets position, speed and acceleration at both ends (the
/// minimum-jerk interpolant), so that position, speed and acceleration
/// are continuous across nodes and the path jerk is finite.
fn quintic_position(h: f64, d: f64, [v0, a0]: [f64; 2], [v1, a1]: [f64; 2], t: f64) -> f64 {
    let (d2, d3) = (d * d, d * d * d);
    let c3 = (20.0 * h - (8.0 * v1 + 12.0 * v0) * d - (3.0 * a0 - a1) * d2) / (2.0 * d3);
    let c4 =
        (-30.0 * h + (14.0 * v1 + 16.0 * v0) * d + (3.0 * a0 - 2.0 * a1) * d2) / (2.0 * d3 * d);
    let c5 = (12.0 * h - 6.0 * (v1 + v0) * d - (a0 - a1) * d2) / (2.0 * d3 * d2);
    (t * (v0 + t * (0.5 * a0 + t * (c3 + t * (c4 + t * c5))))).clamp(0.0, h)
}

/// How a schedule's motion passes from node to node when it is followed
/// in time ([`Schedule::sampled`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolant {
    /// Each interval the quintic in time that meets both nodes' position,
    /// speed and path acceleration (the acceleration at a node the
    /// schedule's centred u, zero at rest), lasting as [`interval_time`]
    /// counts it: the motion passes every node at its time and speed.
    QuinticInTime,
    /// The speed as a function of arc length, the motion the schedule's
    /// rows judge: x = v² piecewise quadratic in s, its half-slope u =
    /// ½·dx/ds (the path acceleration) continuous and linear on each half
    /// interval, so that u′, which with u and x makes the jerk, is
    /// constant on each half; each node's u from the slopes of the
    /// intervals beside it; out of rest and into it the constant-jerk ramp
    /// x ∝ d^{4/3} that the nodes next to a stop are capped by. Each
    /// interval's x meets both nodes' x.
    SpeedInLength,
}

/// Abscissae and weights of 8-point Gauss–Legendre quadrature on [−1, 1]
/// (the positive half; the rule is symmetric).
const GAUSS8: [(f64, f64); 4] = [
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
];

/// One interval of [`Interpolant::SpeedInLength`].
#[derive(Clone, Copy, Debug, PartialEq)]
enum Piece {
    /// Out of rest: x = x1·(d/h)^{4/3}.
    Out { x1: f64 },
    /// Into rest: x = x0·((h − d)/h)^{4/3}.
    In { x0: f64 },
    /// Both ends in motion.
    Smooth(Halves),
    /// Both ends at rest: the stretch stands still.
    Still,
}

/// x over an interval of length `h` whose ends are both in motion: u
/// linear from `u0` at the start to `um` at the middle and on to `u1` at
/// the end, so x is a quadratic on each half, starting at `x0`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Halves {
    h: f64,
    x0: f64,
    u0: f64,
    um: f64,
    u1: f64,
}

impl Halves {
    /// x at `d` into the interval.
    fn x(&self, d: f64) -> f64 {
        let Halves { h, x0, u0, um, u1 } = *self;
        let half = 0.5 * h;
        if d <= half {
            x0 + 2.0 * (u0 * d + (um - u0) * d * d / h)
        } else {
            let e = d - half;
            let xm = x0 + half * (u0 + um);
            xm + 2.0 * (um * e + (u1 - um) * e * e / h)
        }
    }

    /// The least x over the interval: at an end, the middle, or where u
    /// crosses zero on a half.
    fn lowest(&self) -> f64 {
        let Halves { h, u0, um, u1, .. } = *self;
        let half = 0.5 * h;
        let mut least = self.x(0.0).min(self.x(half)).min(self.x(h));
        if (u0 > 0.0) != (um > 0.0) {
            least = least.min(self.x(half * u0 / (u0 - um)));
        }
        if (um > 0.0) != (u1 > 0.0) {
            least = least.min(self.x(half + half * um / (um - u1)));
        }
        least
    }

    /// Time from the start to `d` into the interval: ∫ ds/√x, by
    /// Gauss–Legendre on each half (x is a quadratic on each).
    fn time(&self, d: f64) -> f64 {
        let rule = |a: f64, b: f64| {
            let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
            let inv = |s: f64| 1.0 / self.x(s).max(f64::MIN_POSITIVE).sqrt();
            GAUSS8
                .iter()
                .map(|&(z, w)| w * (inv(mid - half * z) + inv(mid + half * z)))
                .sum::<f64>()
                * half
        };
        let half = 0.5 * self.h;
        if d <= half {
            rule(0.0, d)
        } else {
            rule(0.0, half) + rule(half, d)
        }
    }

    /// Where the interval is `t` into it, searched from `near` (an
    /// earlier position in it, or 0): Newton on time(d) = t, kept inside
    /// a bracket that bisection falls back on (time rises with d).
    fn position(&self, t: f64, near: f64) -> f64 {
        let h = self.h;
        let (mut low, mut high) = (near.clamp(0.0, h), h);
        if self.time(low) > t {
            low = 0.0;
        }
        let mut d = low;
        for _ in 0..60 {
            let miss = self.time(d) - t;
            if miss > 0.0 {
                high = d;
            } else {
                low = d;
            }
            let mut next = d - miss * self.x(d).max(0.0).sqrt();
            if !(next > low && next < high) {
                next = 0.5 * (low + high);
            }
            if (next - d).abs() <= 1e-15 * h.max(d) || high - low <= 1e-15 * h {
                return next;
            }
            d = next;
        }
        d
    }
}

/// u at node `k` in motion, by the rule the linear programs judge
/// ([`node_slope`]); 0 at rest. Reads x at nodes k − 1 … k + 1 (where
/// their coefficients are not zero).
fn node_u(nodes: &[Node], x: &[f64], k: usize) -> f64 {
    if x[k] == 0.0 {
        return 0.0;
    }
    let form = node_slope(nodes, k, |i| x[i] == 0.0);
    match k {
        // Node 0 has no node before it; its form has no term there.
        0 => apply(&form[1..], x, 0),
        _ => apply(&form, x, k - 1),
    }
}

/// The speed in arc length over interval `k` (from node k to k + 1),
/// and whether it was flattened: where x would dip below half its ends'
/// least value, taken linear in s instead (u constant, stepping at the
/// nodes). Reads x at nodes k − 1 … k + 2.
fn interval_piece(nodes: &[Node], x: &[f64], k: usize) -> (Piece, bool) {
    let h = nodes[k].h;
    let piece = match (x[k] > 0.0, x[k + 1] > 0.0) {
        _ if h == 0.0 => Piece::Still,
        (false, false) => Piece::Still,
        (false, true) => Piece::Out { x1: x[k + 1] },
        (true, false) => Piece::In { x0: x[k] },
        (true, true) => {
            let (u0, u1) = (node_u(nodes, x, k), node_u(nodes, x, k + 1));
            let slope = (x[k + 1] - x[k]) / (2.0 * h);
            // The middle chosen so that x meets the next node's.
            let um = 2.0 * slope - 0.5 * (u0 + u1);
            let halves = Halves {
                h,
                x0: x[k],
                u0,
                um,
                u1,
            };
            if halves.lowest() < 0.5 * x[k].min(x[k + 1]) {
                let flat = Halves {
                    u0: slope,
                    um: slope,
                    u1: slope,
                    ..halves
                };
                return (Piece::Smooth(flat), true);
            }
            Piece::Smooth(halves)
        }
    };
    (piece, false)
}

/// Interval `k` as a [`Follower`] runs it. Reads x at nodes k − 1 … k + 2.
fn interval(nodes: &[Node], x: &[f64], k: usize) -> Interval {
    interval_of(nodes, k, interval_piece(nodes, x, k).0)
}

/// Interval `k` (from node k to k + 1) run at `piece`.
fn interval_of(nodes: &[Node], k: usize, piece: Piece) -> Interval {
    let length = nodes[k].h;
    let end = &nodes[k + 1];
    Interval {
        segment: end.segment,
        from: end.at - length,
        length,
        duration: piece.duration(length),
        piece,
    }
}

/// The schedule's speed as a function of arc length, interval by
/// interval ([`Interpolant::SpeedInLength`]).
struct LengthProfile {
    pieces: Vec<Piece>,
    /// Intervals where x would have dipped below half its ends' least
    /// value, taken linear in s instead (u constant, stepping at the
    /// nodes).
    flattened: usize,
}

impl LengthProfile {
    fn new(nodes: &[Node], x: &[f64]) -> LengthProfile {
        let n = nodes.len();
        let mut flattened = 0;
        let pieces = (0..n.saturating_sub(1))
            .map(|k| {
                let (piece, flat) = interval_piece(nodes, x, k);
                flattened += usize::from(flat);
                piece
            })
            .collect();
        LengthProfile { pieces, flattened }
    }
}

impl Piece {
    /// How long an interval of length `h` with this speed lasts, s.
    fn duration(&self, h: f64) -> f64 {
        match *self {
            Piece::Out { x1 } => 3.0 * h / x1.sqrt(),
            Piece::In { x0 } => 3.0 * h / x0.sqrt(),
            Piece::Smooth(halves) => halves.time(h),
            Piece::Still => f64::INFINITY,
        }
    }

    /// Arc length into an interval of length `h` at time `t` into it,
    /// searched from `near` (an earlier sample's position in it, or 0).
    fn position(&self, h: f64, t: f64, near: f64) -> f64 {
        match *self {
            // t = 3·h^{2/3}·d^{1/3}/√x1.
            Piece::Out { x1 } => (h * (t * x1.sqrt() / (3.0 * h)).powi(3)).min(h),
            Piece::In { x0 } => {
                let left = (3.0 * h / x0.sqrt() - t).max(0.0);
                h - (h * (left * x0.sqrt() / (3.0 * h)).powi(3)).min(h)
            }
            Piece::Smooth(halves) => halves.position(t, near),
            Piece::Still => 0.0,
        }
    }
}

impl Schedule {
    /// No motion yet, `dwell` seconds of dwells.
    fn empty(dwell: f64, period: f64) -> Schedule {
        Schedule {
            period,
            time: dwell,
            dwell,
            s: Vec::new(),
            v: Vec::new(),
            step: Vec::new(),
            stretches: 0,
            windows: 0,
            window_rests: 0,
            solves: 0,
            failed: 0,
            stranded: Vec::new(),
            nodes: Vec::new(),
        }
    }

    /// The schedule as a [`Follower`] runs it: its speed in arc length
    /// ([`Interpolant::SpeedInLength`]) interval by interval, in order,
    /// the zero-length steps out of stops left out.
    pub fn intervals(&self) -> Vec<Interval> {
        let x: Vec<f64> = self.v.iter().map(|v| v * v).collect();
        (0..self.nodes.len().saturating_sub(1))
            .filter(|&k| self.nodes[k].h > 0.0)
            .map(|k| interval(&self.nodes, &x, k))
            .collect()
    }

    /// Motion time (without dwells), s.
    fn motion_time(&self) -> f64 {
        self.time - self.dwell
    }

    /// The cycle time slowed by `use_.slowdown()`: the schedule within
    /// every limit as measured by `use_`.
    pub fn scaled_time(&self, use_: &ScheduleUse) -> f64 {
        self.motion_time() * use_.slowdown() + self.dwell
    }

    /// The schedule followed in time, positions taken on `segments`
    /// (those it was made from) every `period`, s, and every axis's
    /// velocity, acceleration and jerk measured on them by finite
    /// differences against its limits, as `kerf plan` measures the
    /// executor. The machine is at rest before and after. `between` says
    /// how the motion passes from node to node ([`Interpolant`]).
    pub fn sampled(
        &self,
        segments: &[Segment],
        kins: &dyn Kinematics,
        period: f64,
        between: Interpolant,
    ) -> Result<Sampled, ScheduleError> {
        self.sample(
            segments,
            kins,
            period,
            between,
            Follower::new(period),
            &mut |_, _| {},
            u64::MAX,
        )
    }

    /// The schedule followed by length ([`Interpolant::SpeedInLength`])
    /// under a changing feed override, sampled and measured as
    /// [`Schedule::sampled`] does: before each period `operator` gets the
    /// period's number (from 0) and the follower, whose override it may
    /// set ([`Follower::set_override`]); the follower's rate moves within
    /// `limits`. Sampling ends at the schedule's end, or after
    /// `max_periods` (an operator that never releases a hold never ends
    /// the motion).
    pub fn followed(
        &self,
        segments: &[Segment],
        kins: &dyn Kinematics,
        period: f64,
        limits: RateLimits,
        operator: &mut dyn FnMut(u64, &mut Follower),
        max_periods: u64,
    ) -> Result<Sampled, ScheduleError> {
        let follower = Follower::with_override(period, limits);
        self.sample(
            segments,
            kins,
            period,
            Interpolant::SpeedInLength,
            follower,
            operator,
            max_periods,
        )
    }

    #[allow(clippy::too_many_arguments)]
    fn sample(
        &self,
        segments: &[Segment],
        kins: &dyn Kinematics,
        period: f64,
        between: Interpolant,
        mut follower: Follower,
        operator: &mut dyn FnMut(u64, &mut Follower),
        max_periods: u64,
    ) -> Result<Sampled, ScheduleError> {
        let limits = axis_limits(kins)?;
        let nodes = &self.nodes;
        let n = nodes.len();
        let mut out = Sampled::default();
        let Some(first) = nodes.first() else {
            return Ok(out);
        };
        let x: Vec<f64> = self.v.iter().map(|v| v * v).collect();
        let slope = |k: usize| (x[k + 1] - x[k]) / (2.0 * nodes[k].h);
        let accel: Vec<f64> = (0..n)
            .map(|k| {
                let before = (k > 0 && nodes[k - 1].h > 0.0).then(|| slope(k - 1));
                let after = (k + 1 < n && nodes[k].h > 0.0).then(|| slope(k));
                match (x[k] > 0.0, before, after) {
                    (false, _, _) => 0.0,
                    (true, Some(b), Some(a)) => 0.5 * (a + b),
                    (true, Some(u), None) | (true, None, Some(u)) => u,
                    (true, None, None) => 0.0,
                }
            })
            .collect();
        let profile = match between {
            Interpolant::QuinticInTime => None,
            Interpolant::SpeedInLength => Some(LengthProfile::new(nodes, &x)),
        };
        out.flattened = profile.as_ref().map_or(0, |p| p.flattened);
        // Nodes from the nearest stop, counted both ways.
        let mut from_rest = vec![usize::MAX; n];
        for order in [false, true] {
            let mut count = usize::MAX;
            for i in 0..n {
                let k = if order { n - 1 - i } else { i };
                count = if x[k] == 0.0 {
                    0
                } else {
                    count.saturating_add(1)
                };
                from_rest[k] = from_rest[k].min(count);
            }
        }
        // At rest before: every difference is defined from the first
        // sample on.
        let start = segments[first.segment].shape.point(first.at);
        let mut axes = start.map(Differences::at_rest);
        let mut see = |p: Vec9, in_motion: bool, out: &mut Sampled| {
            for i in 0..9 {
                // (All three are defined: the axes start at rest.)
                let [Some(v), Some(a), Some(j)] = axes[i].push(p[i], period) else {
                    continue;
                };
                let u = &mut out.limits;
                u.velocity = u.velocity.max(v.abs() / limits.v[i]);
                u.acceleration = u.acceleration.max(a.abs() / limits.a[i]);
                u.jerk = u.jerk.max(j.abs() / limits.j[i]);
                if in_motion {
                    out.jerk_in_motion = out.jerk_in_motion.max(j.abs() / limits.j[i]);
                }
            }
        };
        // Samples in a row taken in motion.
        let mut run = 0;
        if between == Interpolant::SpeedInLength {
            // Followed as the executor would: a `Follower` over the
            // intervals, as `intervals` lists them.
            let pieces = &profile.as_ref().expect("made by length").pieces;
            let intervals: Vec<Interval> = (0..n.saturating_sub(1))
                .filter(|&k| nodes[k].h > 0.0)
                .map(|k| interval_of(nodes, k, pieces[k]))
                .collect();
            if intervals.iter().any(|i| !i.duration.is_finite()) {
                // A stretch that stands still: no motion to sample.
                out.time = f64::INFINITY;
                return Ok(out);
            }
            let node_of: Vec<usize> = (0..n.saturating_sub(1))
                .filter(|&k| nodes[k].h > 0.0)
                .collect();
            debug_assert_eq!(node_of.len(), intervals.len());
            let mut queue = intervals.iter().copied();
            loop {
                if follower.periods() >= max_periods {
                    // Cut off in motion (or held): no rest at the end.
                    return Ok(Sampled {
                        time: follower.passed_time(),
                        periods: follower.periods(),
                        ..out
                    });
                }
                operator(follower.periods(), &mut follower);
                let Some(sample) = follower.tick(&mut queue) else {
                    break;
                };
                let k = node_of[sample.interval];
                let in_motion = from_rest[k].min(from_rest[k + 1]) > REST_NODES;
                run = if in_motion { run + 1 } else { 0 };
                // A sample's jerk spans it and the three before.
                see(
                    segments[sample.segment].shape.point(sample.at),
                    run >= 4,
                    &mut out,
                );
            }
            out.time = follower.passed_time();
            out.periods = follower.periods();
        } else {
            // Time at the start of the interval, and of the next sample.
            let (mut begun, mut samples) = (0.0, 1u64);
            for k in 0..n.saturating_sub(1) {
                let h = nodes[k].h;
                if h == 0.0 {
                    continue;
                }
                let (v0, v1) = (self.v[k], self.v[k + 1]);
                let lasts = interval_time(h, v0, v1);
                if !lasts.is_finite() {
                    out.time = f64::INFINITY;
                    return Ok(out);
                }
                let segment = &segments[nodes[k + 1].segment];
                let base = nodes[k + 1].at - h;
                let in_motion = from_rest[k].min(from_rest[k + 1]) > REST_NODES;
                while samples as f64 * period <= begun + lasts {
                    let t = samples as f64 * period - begun;
                    let ds = quintic_position(h, lasts, [v0, accel[k]], [v1, accel[k + 1]], t);
                    run = if in_motion { run + 1 } else { 0 };
                    see(segment.shape.point(base + ds), run >= 4, &mut out);
                    samples += 1;
                }
                begun += lasts;
            }
            out.time = begun;
        }
        // At rest at the end.
        let end = &nodes[n - 1];
        let end = segments[end.segment].shape.point(end.at);
        for _ in 0..3 {
            see(end, false, &mut out);
        }
        Ok(out)
    }

    /// The largest axis jerk use of the motion followed by length
    /// ([`Interpolant::SpeedInLength`]) anywhere between moving nodes,
    /// not only at the points the linear programs judge: the exact jerk
    /// v·(p′·u′ + 3·p″·u + p‴·x) at `per_half` + 1 evenly spaced points
    /// of each half interval, on the path's own geometry there. The
    /// 1 ms samples of [`Schedule::sampled`] average the jerk over three
    /// periods; this is the motion itself. Returns the use and where it
    /// is largest: the segment index and the arc length into it, mm.
    pub fn continuous_jerk(
        &self,
        segments: &[Segment],
        kins: &dyn Kinematics,
        per_half: usize,
    ) -> Result<(f64, usize, f64), ScheduleError> {
        let limits = axis_limits(kins)?;
        let nodes = &self.nodes;
        let x: Vec<f64> = self.v.iter().map(|v| v * v).collect();
        let profile = LengthProfile::new(nodes, &x);
        let per_half = per_half.max(1);
        let mut worst = (0.0, 0, 0.0);
        for (k, piece) in profile.pieces.iter().enumerate() {
            let Piece::Smooth(halves) = *piece else {
                continue;
            };
            let Halves { h, u0, um, u1, .. } = halves;
            let segment = nodes[k + 1].segment;
            let base = nodes[k + 1].at - h;
            for (half, (ua, ub)) in [(u0, um), (um, u1)].into_iter().enumerate() {
                let slope = 2.0 * (ub - ua) / h;
                for q in 0..=per_half {
                    let f = q as f64 / per_half as f64;
                    let d = 0.5 * h * (half as f64 + f);
                    let (u, xp) = (ua + f * (ub - ua), halves.x(d).max(0.0));
                    let g = Geometry::at(&segments[segment], base + d);
                    for i in 0..9 {
                        let j = g.jerk(i, xp, u, slope);
                        let use_ = j.abs() / limits.j[i];
                        if use_ > worst.0 {
                            worst = (use_, segment, base + d);
                        }
                    }
                }
            }
        }
        Ok(worst)
    }

    /// Largest axis velocity, acceleration and jerk use where the linear
    /// programs judge them: velocity at the nodes; acceleration and jerk
    /// at the judged points of every interval in motion at both ends, as
    /// [`Interpolant::SpeedInLength`] moves through it, with the exact
    /// speed √x where the linear programs used its tangent; all three at
    /// the speed's crests inside the intervals longer than a servo
    /// period, where this schedule has them. On the intervals out of a stop and into one, the
    /// constant-jerk ramp the rest cap bounds, the acceleration at both
    /// ends by the interval's slope, as the programs judge it.
    pub fn limit_use(&self, kins: &dyn Kinematics) -> Result<ScheduleUse, ScheduleError> {
        let limits = axis_limits(kins)?;
        let nodes = &self.nodes;
        let x: Vec<f64> = self.v.iter().map(|v| v * v).collect();
        let mut use_ = ScheduleUse::default();
        let slope = |k: usize| (x[k + 1] - x[k]) / (2.0 * nodes[k].h);
        for k in 0..nodes.len() {
            for g in [&nodes[k].left, &nodes[k].right] {
                for i in 0..9 {
                    use_.velocity = use_.velocity.max(self.v[k] * g.t[i].abs() / limits.v[i]);
                }
            }
            if k + 1 == nodes.len() || nodes[k].h == 0.0 {
                continue;
            }
            if k == 0 || x[k] == 0.0 || x[k + 1] == 0.0 {
                // A ramp out of rest or into it: its acceleration at both
                // ends by the interval's slope, as the programs judge it.
                let u = slope(k);
                for (end, g) in [(k, &nodes[k].right), (k + 1, &nodes[k + 1].left)] {
                    for i in 0..9 {
                        let a = g.t[i] * u + g.c[i] * x[end];
                        use_.acceleration = use_.acceleration.max(a.abs() / limits.a[i]);
                    }
                }
                continue;
            }
            // The jerk and acceleration between the nodes, where the motion
            // is under way at both.
            let points = JerkPoints::new(nodes, k, |i| x[i] == 0.0);
            let value = |form: &[f64; 4]| apply(form, &x, k - 1);
            // Crests where the linear programs judge them: on intervals
            // longer than a servo period (`continuous_jerk` and the
            // samples measure the motion everywhere).
            let crests = if outlasts_period(nodes, &x, k, self.period) {
                points.crests(&x, k - 1)
            } else {
                [None, None]
            };
            for crest in crests.iter().flatten() {
                let xp = value(&crest.x).max(0.0);
                for i in 0..9 {
                    let v = xp.sqrt() * crest.geometry.t[i].abs();
                    use_.velocity = use_.velocity.max(v / limits.v[i]);
                }
            }
            for point in points.points().chain(crests.into_iter().flatten()) {
                let g = &point.geometry;
                let (xp, u, slope) = (
                    value(&point.x).max(0.0),
                    value(&point.u),
                    value(&point.slope),
                );
                for i in 0..9 {
                    let j = g.jerk(i, xp, u, slope);
                    use_.jerk = use_.jerk.max(j.abs() / limits.j[i]);
                    let a = g.t[i] * u + g.c[i] * xp;
                    use_.acceleration = use_.acceleration.max(a.abs() / limits.a[i]);
                }
            }
        }
        Ok(use_)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(h: f64) -> Node {
        Node {
            left: Geometry::default(),
            right: Geometry::default(),
            inner: [Geometry::default(); INNER],
            stride: 1,
            xmax: f64::INFINITY,
            h,
            smooth: true,
            segment: 0,
            at: 0.0,
        }
    }

    /// The speed in arc length between two moving nodes meets both nodes'
    /// x, takes each node's u from the slopes of the intervals beside it
    /// (or from the ramp into a stop), keeps u continuous through the
    /// middle, takes as long as a fine sum of ds/v says, and its clock
    /// inverts.
    #[test]
    fn an_interval_followed_by_length_meets_its_nodes_and_its_clock_inverts() {
        let h = 0.01;
        let x = [20.0, 30.0, 42.0, 50.0, 0.0];
        let nodes: Vec<Node> = (0..x.len())
            .map(|k| node(if k + 1 < x.len() { h } else { 0.0 }))
            .collect();
        let profile = LengthProfile::new(&nodes, &x);
        assert_eq!(profile.flattened, 0);
        let Piece::Smooth(halves) = profile.pieces[1] else {
            panic!(
                "interval 1 is between moving nodes: {:?}",
                profile.pieces[1]
            );
        };
        // Equal intervals: a node's u is the mean of its two intervals'
        // slopes (x_{k+1} − x_k)/(2h); node 3 ends at the ramp into the
        // stop after it, x ∝ (h − d)^{4/3}, whose slope there is
        // −(4/3)·x_3/h, so u = −(2/3)·x_3/h.
        let mean = |k: usize| 0.25 * (x[k + 1] - x[k - 1]) / h;
        assert!((halves.u0 - mean(1)).abs() < 1e-9 * mean(1));
        assert!((halves.u1 - mean(2)).abs() < 1e-9 * mean(2));
        let Piece::Smooth(last) = profile.pieces[2] else {
            panic!("interval 2 is between moving nodes");
        };
        assert!((last.u1 + 2.0 / 3.0 * x[3] / h).abs() < 1e-9 * x[3] / h);
        // Both nodes' x met.
        assert_eq!(halves.x(0.0), x[1]);
        assert!((halves.x(h) - x[2]).abs() < 1e-12);
        // u (half the slope of x) the same either side of the middle.
        let e = 1e-6 * h;
        let left = (halves.x(0.5 * h) - halves.x(0.5 * h - e)) / (2.0 * e);
        let right = (halves.x(0.5 * h + e) - halves.x(0.5 * h)) / (2.0 * e);
        let um = halves.um;
        assert!(
            (left - um).abs() < 1e-3 * um.abs() && (right - um).abs() < 1e-3 * um.abs(),
            "{left} {right} {um}"
        );
        // The clock against a fine midpoint sum.
        let n = 100_000;
        let fine: f64 = (0..n)
            .map(|i| {
                let s = (i as f64 + 0.5) * h / n as f64;
                h / n as f64 / halves.x(s).sqrt()
            })
            .sum();
        let lasts = profile.pieces[1].duration(h);
        assert!((lasts - fine).abs() < 1e-9 * fine, "{lasts} against {fine}");
        for share in [0.1, 0.37, 0.5, 0.8, 0.999] {
            let d = profile.pieces[1].position(h, share * lasts, 0.0);
            let back = halves.time(d);
            assert!((back - share * lasts).abs() < 1e-12, "{share}: {back}");
        }
        // Into the stop at the end: the constant-jerk ramp, 3h/v long.
        let ramp = profile.pieces[3].duration(h);
        assert!((ramp - 3.0 * h / x[3].sqrt()).abs() < 1e-15);
        let d = profile.pieces[3].position(h, ramp, 0.0);
        assert!((d - h).abs() < 1e-15, "{d}");
    }

    /// The rows judge the motion at points of an interval through
    /// linear forms in the nodes' x; applied to a schedule they give the
    /// x, u = ½·dx/ds and u′ of the motion followed by length there
    /// (differentiated numerically), on intervals of unequal length.
    #[test]
    fn the_judged_points_see_the_motion_followed_by_length() {
        let lengths = [0.01, 0.013, 0.008, 0.011, 0.0];
        let x = [20.0, 31.0, 44.0, 47.0, 45.0];
        let nodes: Vec<Node> = lengths.iter().map(|&h| node(h)).collect();
        let profile = LengthProfile::new(&nodes, &x);
        let k = 2;
        let Piece::Smooth(halves) = profile.pieces[k] else {
            panic!("interval {k} is between moving nodes");
        };
        let h = lengths[k];
        let points = JerkPoints::new(&nodes, k, |_| false);
        let per = JUDGED_PER_HALF as f64;
        let places: Vec<f64> = (0..JUDGED)
            .map(|p| {
                let (half, q) = (p / (JUDGED_PER_HALF + 1), p % (JUDGED_PER_HALF + 1));
                0.5 * (half as f64 + q as f64 / per)
            })
            .collect();
        // x is a quadratic on each half, so one-sided differences within
        // the half are exact but for rounding, at any step inside it.
        let e = 0.2 * h / per;
        for (p, point) in points.points().enumerate() {
            let d = places[p] * h;
            let side = if p <= JUDGED_PER_HALF { -1.0 } else { 1.0 };
            let inside = if p == 0 || p + 1 == JUDGED {
                -side
            } else {
                side
            };
            let near = |n: f64| halves.x(d + inside * n * e);
            let u = 0.5 * inside * (-1.5 * near(0.0) + 2.0 * near(1.0) - 0.5 * near(2.0)) / e;
            let slope = 0.5 * (near(0.0) - 2.0 * near(1.0) + near(2.0)) / (e * e);
            let value = |form: &[f64; 4]| apply(form, &x, k - 1);
            assert!(
                (value(&point.x) - halves.x(d)).abs() < 1e-12,
                "x at point {p}"
            );
            assert!(
                (value(&point.u) - u).abs() < 1e-9 * u.abs().max(1.0),
                "u at point {p}: {} against {u}",
                value(&point.u)
            );
            assert!(
                (value(&point.slope) - slope).abs() < 1e-9 * slope.abs().max(1.0),
                "u′ at point {p}: {} against {slope}",
                value(&point.slope)
            );
        }
    }

    /// An interval's judged points thin out where its geometry runs
    /// straight between them: constant or linear geometry is judged at
    /// the halves' ends alone, a curvature with a kink at the quarters
    /// at the quarters too, and one with a kink at an eighth at every
    /// point.
    #[test]
    fn judged_points_thin_out_where_the_geometry_runs_straight() {
        let with = |curvature: &dyn Fn(usize) -> f64| {
            let g = |j: usize| {
                let mut g = Geometry::default();
                g.t[0] = 1.0;
                g.c[1] = curvature(j);
                g
            };
            let inner: [Geometry; INNER] = std::array::from_fn(|j| g(j + 1));
            stride(&g(0), &inner, &g(INNER + 1))
        };
        assert_eq!(with(&|_| 0.5), JUDGED_PER_HALF);
        assert_eq!(with(&|j| 0.5 + 0.1 * j as f64), JUDGED_PER_HALF);
        assert_eq!(with(&|j| (j as f64 - 2.0).abs()), 2);
        assert_eq!(with(&|j| (j as f64 - 3.0).abs()), 1);
        // A stray under the share is let through, one over it is not.
        let bump = |size: f64| move |j: usize| if j == 1 { size } else { 0.0 } + j as f64;
        let top = (INNER + 1) as f64;
        assert_eq!(with(&bump(0.5 * GEOMETRY_STRAY * top)), JUDGED_PER_HALF);
        assert_eq!(with(&bump(2.0 * GEOMETRY_STRAY * top)), 1);
    }
}
