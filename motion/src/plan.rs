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

mod ahead;
mod chords;

use ahead::{Fallback, Speculation, Worked};
use chords::{fit_side, Chord, Chords};

use kerf_interp::{Axis, Canon, CanonCmd, MotionMode, Position, Source};

use crate::kinematics::{Kinematics, Limits, LIMIT_SLACK, MAX_JOINTS};
use crate::merge::{CollinearMerge, MergeContext, Verdict};
use crate::path::{
    corner_spread, norm, norm3, Arc, Blend, BlendExtremes, Frame, Line, Near, Poly, Shape, Vec9,
};

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
    /// M64/M65/M68: set an output when the queue reaches this point, at
    /// rest. LinuxCNC's task also waits for motion to finish before an
    /// immediate output, so the change lands in program order.
    Output(OutputChange),
    /// M66: wait here, at rest, until the input answers or the wait times
    /// out. Whoever runs the executor polls the input and then calls
    /// [`Executor::release_input`](crate::Executor::release_input).
    WaitInput(InputRequest),
    /// M0, M60 (`optional: false`) and M1 (`optional: true`): come to rest
    /// here and wait until the operator resumes. M1 waits only while the
    /// optional-stop switch is on ([`Executor::set_optional_stop`]).
    ///
    /// [`Executor::set_optional_stop`]: crate::Executor::set_optional_stop
    ProgramStop { optional: bool },
}

/// What an M66 waits for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputRequest {
    /// Input number.
    pub index: u8,
    /// Digital (P word) or analog (E word).
    pub digital: bool,
    /// 0 now, 1 rise, 2 fall, 3 high, 4 low (L word).
    pub mode: u8,
    /// Longest wait, seconds (Q word).
    pub timeout: f64,
}

/// One output change of M64/M65 (digital) or M68 (analog).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OutputChange {
    /// Digital output `index` on or off.
    Digital { index: u8, on: bool },
    /// Analog output `index` to `value`.
    Analog { index: u8, value: f64 },
}

/// Most digital outputs a segment can change (bits of a `u64`).
pub const MAX_DIGITAL_OUTPUTS: usize = 64;
/// Most analog outputs a segment can change.
pub const MAX_ANALOG_OUTPUTS: usize = 16;

/// M62/M63/M67 changes that ride on a motion segment and take effect in
/// the servo period its motion starts. A fixed-size value, so segments stay
/// `Copy` and the servo applies it without allocating.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SyncOutputs {
    /// Digital outputs to change: bit `n` = output `n`.
    pub digital_mask: u64,
    /// Their new values, under `digital_mask`.
    pub digital_bits: u64,
    /// Analog outputs to change: bit `n` = output `n`.
    pub analog_mask: u16,
    /// Their new values, under `analog_mask`.
    pub analog: [f64; MAX_ANALOG_OUTPUTS],
}

impl SyncOutputs {
    /// Nothing to change.
    pub fn is_empty(&self) -> bool {
        self.digital_mask == 0 && self.analog_mask == 0
    }

    fn set_digital(&mut self, index: usize, on: bool) {
        self.digital_mask |= 1 << index;
        self.digital_bits = (self.digital_bits & !(1 << index)) | ((on as u64) << index);
    }

    fn set_analog(&mut self, index: usize, value: f64) {
        self.analog_mask |= 1 << index;
        self.analog[index] = value;
    }
}

/// The programmed moves a segment runs along, by number.
///
/// The planner numbers the canon commands it is given from 1, in order
/// ([`Planner::plan`]). A line or arc spans its own command; a line merged
/// under G64 Q spans the moves it stands for; a blend spans the move it
/// leaves to the move it enters. What measures a path against the program
/// (`offline`, `kerf sim`'s contour error) compares a point with the moves
/// its segment spans: source lines cannot say which those are, since loops
/// and subroutines run one line many times, and a merged line or a blend
/// reaches back past the line it is labelled with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SourceMoves {
    /// Number of the first canon command spanned.
    pub first: u64,
    /// Number of the last.
    pub last: u64,
}

impl SourceMoves {
    /// The one command numbered `n`.
    pub fn one(n: u64) -> SourceMoves {
        SourceMoves { first: n, last: n }
    }
}

/// A planned piece of motion. `Copy` and allocation-free, so the servo
/// thread can take and drop it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub kind: SegmentKind,
    /// Source line of the canon command that made this segment.
    pub line: u32,
    /// The programmed moves it runs along (none for markers).
    pub moves: SourceMoves,
    /// Which reading of its source line made it
    /// ([`Source::reading`](kerf_interp::Source::reading)): single block
    /// runs one reading per step, so each pass of a loop over one line is
    /// a step of its own.
    pub reading: u64,
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
    /// Cutting-force control along this segment, as the program asked
    /// ([`Planner::set_force_control`]): the target force, N, or `None`
    /// for off. The servo applies a change when the segment starts.
    pub force_control: Option<f64>,
    /// Outputs that change as this segment's motion starts (M62/M63/M67
    /// programmed before it).
    pub outputs: SyncOutputs,
}

impl Segment {
    /// A zero-length segment at `at` of the given kind.
    pub fn marker(kind: SegmentKind, line: u32, at: Position) -> Segment {
        let p = at.to_array();
        Segment {
            kind,
            line,
            moves: SourceMoves::default(),
            reading: 0,
            shape: Shape::Line(Line { start: p, end: p }),
            length: 0.0,
            feed: 0.0,
            max_velocity: 0.0,
            max_acceleration: f64::INFINITY,
            max_jerk: f64::INFINITY,
            exit_velocity: 0.0,
            force_control: None,
            outputs: SyncOutputs::default(),
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

impl PathMode {
    /// The mode a program's G61, G61.1 or G64 asks for, as the planner
    /// follows it. G64 without P lets LinuxCNC deviate as far as speed
    /// wants; kerf keeps to `default_tolerance` (mm) instead.
    pub fn from_program(mode: MotionMode, default_tolerance: f64) -> PathMode {
        match mode {
            MotionMode::ExactStop => PathMode::ExactStop,
            MotionMode::ExactPath => PathMode::ExactPath,
            MotionMode::Continuous { tolerance } if tolerance <= 0.0 => PathMode::Blend {
                tolerance: default_tolerance,
            },
            MotionMode::Continuous { tolerance } => PathMode::Blend { tolerance },
        }
    }

    /// How far the path may leave the programmed one at a corner, mm (0
    /// for the exact modes).
    pub fn tolerance(&self) -> f64 {
        match *self {
            PathMode::Blend { tolerance } => tolerance,
            PathMode::ExactStop | PathMode::ExactPath => 0.0,
        }
    }
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
    /// Most of each axis's acceleration the centripetal part may take on
    /// curves (0 to 1), which sets their speed limit; what is left at that
    /// speed is for speeding up and slowing down along them.
    pub centripetal_share: f64,
    /// Most of each axis's jerk the v³·κ′ term may take on curves (0 to
    /// 1), likewise; the tangential j·t and coupling 3·a·v·κ terms get half
    /// of what is left at the speed limit each.
    pub jerk_rate_share: f64,
    /// Path tolerance for G64 without P, mm (LinuxCNC: unlimited).
    pub default_tolerance: f64,
    /// Digital outputs the machine has (M62–M65 P must be below).
    pub digital_outputs: usize,
    /// Analog outputs the machine has (M67/M68 E must be below).
    pub analog_outputs: usize,
    /// Digital and analog inputs the machine has (M66 P and E must be
    /// below).
    pub digital_inputs: usize,
    pub analog_inputs: usize,
    /// Work out dense-curve blends ahead on a second thread (`plan/ahead.rs`).
    /// The plan is the same bit for bit either way; with a core to spare
    /// it comes faster. The planner then holds back a few hundred more
    /// lines before releasing segments (until the program ends or stops).
    pub blend_worker: bool,
    /// Under G64, stop at a corner between two lines instead of blending
    /// it where that is quicker (a sharp corner under a small tolerance,
    /// whose blend is passed at a few mm/s). The stop is on the
    /// programmed corner, within any tolerance. Off, every corner up to
    /// 150° that fits a blend is blended.
    pub stop_when_quicker: bool,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        PlannerConfig {
            period: 0.001,
            mode: PathMode::Blend { tolerance: 0.01 },
            jerk_limited: true,
            centripetal_share: 0.5,
            jerk_rate_share: 0.6,
            default_tolerance: 0.01,
            digital_outputs: MAX_DIGITAL_OUTPUTS,
            analog_outputs: MAX_ANALOG_OUTPUTS,
            digital_inputs: MAX_DIGITAL_OUTPUTS,
            analog_inputs: MAX_ANALOG_OUTPUTS,
            blend_worker: true,
            stop_when_quicker: true,
        }
    }
}

/// A blend the planner chose at the corner between the first two waiting
/// moves. Kept small (no control points, no 9-axis frame): it is passed
/// by value through the choice, and copies of a larger one showed in
/// profiles.
struct Chosen {
    /// Where it leaves the first move and joins the second, from their
    /// common vertex, mm.
    legs: (f64, f64),
    /// The blend with its arc-length table, and what its limits need.
    blend: (Blend, BlendExtremes),
    /// X Y Z of the point, unit tangent and curvature it ends with on the
    /// second move (the start of the next blend if that takes the rest).
    end: FrameXyz,
    /// Its path limits (speed, acceleration, jerk), once worked out
    /// ([`Planner::stops_sooner`] needs them first).
    limits: Option<(f64, f64, f64)>,
}

impl Chosen {
    /// The blend with control points `control`, ending with `end`.
    fn new(legs: (f64, f64), control: &[Vec9; 6], end: &Frame) -> Chosen {
        Chosen {
            legs,
            blend: Blend::sampled(*control),
            end: xyz_frame(end),
            limits: None,
        }
    }

    /// The blend the worker sampled, ending with `end`.
    fn worked(legs: (f64, f64), sampled: &(Blend, BlendExtremes), end: FrameXyz) -> Chosen {
        Chosen {
            legs,
            blend: *sampled,
            end,
            limits: None,
        }
    }
}

/// X Y Z of a frame's point, unit tangent and curvature: all a blend
/// needs of the frames it joins (blends move X Y Z only).
type FrameXyz = [[f64; 3]; 3];

/// The X Y Z part of `f`.
fn xyz_frame(f: &Frame) -> FrameXyz {
    [&f.point, &f.tangent, &f.curvature].map(|v| [v[0], v[1], v[2]])
}

/// The whole frame whose X Y Z part is `xyz`, on an X Y Z line whose
/// other six axes stand at `rest` and do not turn (as [`fitted_frame`]
/// makes them).
fn frame_on(xyz: &FrameXyz, rest: &[f64]) -> Frame {
    let full = |v: &[f64; 3], rest: &[f64]| -> Vec9 {
        std::array::from_fn(|i| if i < 3 { v[i] } else { rest[i - 3] })
    };
    Frame {
        point: full(&xyz[0], rest),
        tangent: full(&xyz[1], &[0.0; 6]),
        curvature: full(&xyz[2], &[0.0; 6]),
    }
}

/// A move waiting for its successors, which decide its end.
#[derive(Clone, Copy, Debug)]
struct Pending {
    segment: Segment,
    /// The move as programmed, before blends trimmed it.
    source: AsProgrammed,
    /// Path mode in force when the move was programmed.
    mode: PathMode,
    /// Length of the start taken by the blend before it.
    start_leg: f64,
    /// Where the blend that took this move's start ended, when blends
    /// take the whole line: the point, tangent and curvature the next
    /// blend starts from (on a dense curve, from the fitted curve).
    mid: FrameXyz,
}

/// A waiting move as programmed (one field, not two options: waiting
/// moves are copied often, and every byte shows).
#[derive(Clone, Copy, Debug)]
enum AsProgrammed {
    Line(Programmed),
    Arc(Arc),
}

impl Pending {
    fn is_line(&self) -> bool {
        matches!(self.source, AsProgrammed::Line(_))
    }

    /// The line as programmed, when it is one.
    fn programmed(&self) -> Option<&Programmed> {
        match &self.source {
            AsProgrammed::Line(p) => Some(p),
            AsProgrammed::Arc(_) => None,
        }
    }

    /// The arc as programmed, when it is one.
    fn arc(&self) -> Option<&Arc> {
        match &self.source {
            AsProgrammed::Arc(arc) => Some(arc),
            AsProgrammed::Line(_) => None,
        }
    }

    /// [`mid`](Self::mid) as a frame (the other axes where the line is).
    fn mid_frame(&self) -> Frame {
        frame_on(&self.mid, &self.segment.shape.start()[3..])
    }

    fn full_length(&self) -> f64 {
        match &self.source {
            AsProgrammed::Line(p) => p.length,
            AsProgrammed::Arc(arc) => arc.length(),
        }
    }

    /// Point, unit tangent and curvature (perpendicular to the tangent) of
    /// the move as programmed, `leg` mm from its start (`from_end`: from
    /// its end); `None` unless it is a line or arc that moves X Y Z only.
    fn frame_in(&self, leg: f64, from_end: bool) -> Option<Frame> {
        if let Some(p) = self.programmed().filter(|p| p.xyz_only) {
            return Some(p.frame_at(leg, from_end));
        }
        let arc = self.arc()?;
        let xyz = arc.plane.0 < 3 && arc.plane.1 < 3 && (3..9).all(|i| arc.start[i] == arc.end[i]);
        if !xyz {
            return None;
        }
        let full = arc.length();
        let f = if from_end {
            1.0 - leg / full
        } else {
            leg / full
        };
        // A spiral's frame is a hair off unit length and off square; the
        // blend takes the unit tangent and the curvature across it.
        let frame = Shape::Arc(*arc).frame(f * full);
        let n = norm(&frame.tangent);
        let t: Vec9 = std::array::from_fn(|i| frame.tangent[i] / n);
        let along: f64 = (0..9).map(|i| frame.curvature[i] * t[i]).sum();
        Some(Frame {
            point: arc.point_at_fraction(arc.sweep_fraction(f)),
            tangent: t,
            curvature: std::array::from_fn(|i| frame.curvature[i] - along * t[i]),
        })
    }

    /// The programmed path within `reach` mm of the move's end
    /// (`from_end`) or start, as lines, and how far they may stray from
    /// it: the line itself, or chords of the arc within `sag`.
    fn near(&self, reach: f64, from_end: bool, sag: f64) -> (Vec<Near>, f64) {
        match &self.source {
            AsProgrammed::Line(p) => (vec![Near::new(&p.line)], 0.0),
            AsProgrammed::Arc(arc) => {
                let q = (reach / arc.length()).min(1.0);
                let (f0, f1) = if from_end {
                    (arc.sweep_fraction(1.0 - q), 1.0)
                } else {
                    (0.0, arc.sweep_fraction(q))
                };
                let (chords, sag) = arc.chords(f0, f1, sag, 256);
                (chords.iter().map(Near::new).collect(), sag)
            }
        }
    }
}

/// A programmed line with what the blend decisions ask of it again and
/// again, worked out once.
#[derive(Clone, Copy, Debug)]
struct Programmed {
    line: Line,
    direction: Vec9,
    length: f64,
    /// Only X Y Z move (blends join such lines only).
    xyz_only: bool,
}

impl Programmed {
    fn new(line: Line) -> Programmed {
        Programmed {
            line,
            direction: line.direction(),
            length: line.length(),
            xyz_only: (3..9).all(|i| line.start[i] == line.end[i]),
        }
    }

    /// Point and tangent `leg` mm from the line's start (`from_end`: from
    /// its end), with no curvature.
    fn frame_at(&self, leg: f64, from_end: bool) -> Frame {
        let (corner, sign) = if from_end {
            (self.line.end, -1.0)
        } else {
            (self.line.start, 1.0)
        };
        Frame {
            point: std::array::from_fn(|i| corner[i] + sign * leg * self.direction[i]),
            tangent: self.direction,
            curvature: [0.0; 9],
        }
    }
}

/// In acceleration-limited (trapezoidal) planning, how many times a
/// servo period the jerk limit lets the acceleration swing over its range.
const TRAPEZOID_RAMPS: f64 = 16.0;

/// How many corner blend legs are tried ([`corner_legs`]).
const CORNER_TRIES: usize = 9;

/// Lines whose directions' dot product is below this turn by more than
/// 90°: a hairpin ([`hairpin`]).
const HAIRPIN_COS: f64 = 0.0;

/// Whether the corner from line `b` into line `c` is a hairpin, one a
/// blend passes at a crawl and a stop often passes quicker: the blend
/// into `b` then ends on `b` itself, with no curvature, not on the curve
/// fitted through `b`'s midpoint, so that [`Planner::stops_sooner`] may
/// still stop at the hairpin (a dense blend ends with the fit's
/// curvature, and the line after it, were the motion to stop at its end,
/// would start with a curvature jump). Both the planner and the blend
/// worker ask it, so that they make the same blends.
fn hairpin(b: &Programmed, c: &Programmed) -> bool {
    (0..3).map(|i| b.direction[i] * c.direction[i]).sum::<f64>() < HAIRPIN_COS
}

/// The legs a corner blend tries, in order, until one is within the
/// tolerance: `legs` (the tolerance's), then 0.7 times the one before.
/// The planner and the blend worker both follow it.
fn corner_legs(legs: (f64, f64)) -> impl Iterator<Item = (f64, f64)> {
    std::iter::successors(Some(legs), |l| Some((l.0 * 0.7, l.1 * 0.7))).take(CORNER_TRIES)
}

/// The blend legs at the vertex between lines `la` and `lb`, `lb`
/// programmed in `mode`: how much of `la`'s end and of `lb`'s start the
/// blend replaces (None: no blend). Each leg is the tolerance's leg or
/// half its line, whichever is less, so on dense paths blends meet at line
/// midpoints.
fn blend_legs(la: &Programmed, lb: &Programmed, mode: PathMode) -> Option<(f64, f64)> {
    let PathMode::Blend { tolerance } = mode else {
        return None;
    };
    let (u1, u2) = (&la.direction, &lb.direction);
    let bend = norm(&std::array::from_fn(|i| u2[i] - u1[i]));
    // Straight on between long lines needs no blend. Between chords of
    // a dense curve it is rounding (at 1e-4 mm on 0.02 mm chords most
    // neighbours that would bend by under 0.005 rad come out straight):
    // the curve goes on through it, and a blend carries its curvature.
    let chords = la.length <= FIT_REACH && lb.length <= FIT_REACH;
    if bend > SHARPEST || (bend < STRAIGHT && !chords) || !la.xyz_only || !lb.xyz_only {
        return None;
    }
    // Closed-form leg of a symmetric blend with zero end curvature: its
    // deviation is proportional to the leg.
    let leg = tolerance / Blend::deviation(1.0, u1, u2);
    let (a, b) = (leg.min(la.length / 2.0), leg.min(lb.length / 2.0));
    // Unequal legs let dense curves blend midpoint to midpoint though
    // neighbouring chords differ a little; a tolerance bounds how far
    // they stray. Without one (G64 with no P), bound the ratio instead,
    // so a long move cannot swing a wide blend into a short one.
    let legs = if tolerance.is_finite() {
        (a, b)
    } else {
        (a.min(2.0 * b), b.min(2.0 * a))
    };
    (legs.0.min(legs.1) >= 1e-9).then_some(legs)
}

/// The blend at the vertex of lines `pa` and `pb` from `start` (on `pa`)
/// to `end` (on `pb`), `legs` from the vertex: its control points, and
/// whether it is proven within `tolerance` of the two lines
/// ([`hull_bounds`], then [`sampled_within`]). Whether it stays where the
/// machine can go is the planner's to check.
fn blend_near(
    pa: &Programmed,
    pb: &Programmed,
    tolerance: f64,
    legs: (f64, f64),
    start: &Frame,
    end: &Frame,
) -> ([Vec9; 6], bool) {
    let (u1, u2) = (&pa.direction, &pb.direction);
    let bend = norm(&std::array::from_fn(|i| u2[i] - u1[i]));
    let scale = corner_spread(bend) * (legs.0 + legs.1);
    let control = Blend::hermite_control(
        &start.point,
        &start.tangent,
        &start.curvature,
        &end.point,
        &end.tangent,
        &end.curvature,
        scale,
    );
    // A well-shaped blend moves at about `scale` per unit parameter
    // everywhere; large end curvatures can fold it into a near-cusp,
    // where |B′| all but vanishes and arc length stops being usable.
    let min_speed = 0.3 * scale;
    let (na, nb) = (Near::new(&pa.line), Near::new(&pb.line));
    let proven = hull_bounds(&control, &na, &nb, tolerance, min_speed);
    let near = proven.all() || sampled_within(&control, &[na, nb], tolerance, min_speed, &proven);
    (control, near)
}

/// Shares of the curvature its two vertices give
/// ([`Planner::mid_curvature`]) that a line's midpoint frame takes where
/// no fitted frame serves, in the order tried. The whole where both
/// blends through the midpoint stay within the tolerance. On a polygon
/// whose chords' sag is about the tolerance (CAM output with its chord
/// tolerance equal to G64 P) they do not: less curvature at the midpoint
/// keeps the blends nearer the vertex, and the path stays
/// curvature-continuous. The last resort after these, zero curvature
/// (a corner blend at each vertex), slows such a polygon most: a circle
/// of R5 in 0.64 mm chords under G64 P0.01 had its blends limited to
/// 25 mm/s with zero curvature, 41 mm/s with three quarters.
const MID_SHARES: [f64; 4] = [1.0, 0.75, 0.5, 0.25];

/// On a run of lines `a`, `b`, `c` whose blends take `b`'s whole halves
/// (`legs` at a–b, `legs_bc` at b–c), the frame at `b`'s midpoint from its
/// vertices with the first of [`MID_SHARES`] of their curvature whose
/// blend from `start` (on `a`) and blend on to `c` are both within their
/// tolerances (`tol_b`, `tol_c`): the frame and the two blends' control
/// points. Planner and blend worker both take it, so they agree; the
/// machine's reach is the planner's to check.
#[allow(clippy::too_many_arguments)]
fn vertex_midpoint(
    a: &Programmed,
    b: &Programmed,
    c: &Programmed,
    legs: (f64, f64),
    legs_bc: (f64, f64),
    start: &Frame,
    tol_b: f64,
    tol_c: f64,
) -> Option<(Frame, [Vec9; 6], [Vec9; 6])> {
    let mut mid = b.frame_at(legs.1, false);
    let full = Planner::mid_curvature(a, b, c);
    let c_start = c.frame_at(legs_bc.1, false);
    for share in MID_SHARES {
        mid.curvature = full.map(|k| k * share);
        let (ab, near) = blend_near(a, b, tol_b, legs, start, &mid);
        if !near {
            continue;
        }
        let (bc, near) = blend_near(b, c, tol_c, legs_bc, &mid, &c_start);
        if near {
            return Some((mid, ab, bc));
        }
    }
    None
}

/// Turns canon into segments for one machine.
pub struct Planner<'k> {
    kins: &'k dyn Kinematics,
    config: PlannerConfig,
    /// Axis limits with the limits of joints that move exactly with an axis folded in.
    limits: [Option<Limits>; 9],
    /// Joints that need sampling through the kinematics (false: all joints are axes).
    sample_joints: bool,
    /// X Y Z travel, (min, max) mm, with the strokes of joints that move
    /// exactly with an axis folded in: where a blend may go when
    /// `sample_joints` is false.
    travel: [(f64, f64); 3],
    mode: PathMode,
    /// The F word, mm/min (mm/rev in feed-per-revolution mode).
    feed_word: f64,
    /// G95: feed per spindle revolution.
    per_revolution: bool,
    /// Programmed spindle speed, rev/min.
    spindle_rpm: f64,
    /// Programmed cutting-force control: target force, N.
    force_control: Option<f64>,
    /// M62/M63/M67 waiting for the next motion segment.
    sync_outputs: SyncOutputs,
    position: Position,
    /// Source line of the last command given to [`Planner::plan`].
    last_line: u32,
    /// Canon commands given to [`plan`](Self::plan) so far: the number of
    /// the last ([`SourceMoves`]).
    received: u64,
    /// The programmed moves of the command being planned.
    moves: SourceMoves,
    /// Its source's reading ([`Segment::reading`]).
    reading: u64,
    pending: VecDeque<Pending>,
    ready: VecDeque<Segment>,
    /// G64 Q: straight feeds held for merging (merge.rs).
    merge: CollinearMerge,
    /// The chords the curve fit sees: up to FIT_SIDE lines before the
    /// first waiting move, while they form one polyline with it (oldest
    /// first), then one per waiting move ([`Chord::BREAK`] for any but a
    /// line in X Y Z).
    chords: Chords,
    /// How many of `chords` come before the first waiting move.
    behind: usize,
    /// Waiting moves released so far (the first waiting move's index
    /// among all moves queued).
    released: u64,
    /// The blend worker, if there is one.
    ahead: Option<ahead::Ahead>,
    /// Fitted points the frames at the next midpoints reuse (in a cell:
    /// frames are fitted while the waiting moves are only read).
    fitted_points: std::cell::RefCell<FittedPoints>,
}

/// Largest step of the stencils that differentiate the joints along a
/// segment (`Planner::joint_limits`), mm. Their error grows with the
/// square of the step over the joint motion's length scale (an arc's
/// radius), and rounding in the third difference with its inverse cube:
/// at 0.02 mm a joint position of 500 mm rounds to 1e-7 mm⁻² in q‴.
const JOINT_STENCIL: f64 = 0.02;

/// Path limits the joints impose on one segment (see `Planner::joint_limits`).
#[derive(Clone, Copy, Debug)]
struct JointBounds {
    v: f64,
    a: f64,
    j: f64,
    /// Bound on a·v (mm²/s³) from the 3·q″·v·a jerk term.
    av: f64,
}

impl Default for JointBounds {
    fn default() -> Self {
        JointBounds {
            v: f64::INFINITY,
            a: f64::INFINITY,
            j: f64::INFINITY,
            av: f64::INFINITY,
        }
    }
}

/// Corners sharper than 150° (|u1 − u2| = 2·sin(θ/2) above this) are not
/// blended: a blend there is a hairpin with a near-cusp, and stopping is
/// faster anyway.
const SHARPEST: f64 = 1.931_851_652_578_136_6; // 2·sin(75°)

/// Directions closer than this (|u1 − u2|) are one straight line.
const STRAIGHT: f64 = 1e-9;

/// Where an arc meets another move, tangents closer than this (|u1 − u2|)
/// are one: rounding in the arc's end points bends them that much.
const KINK: f64 = 1e-6;

/// Lines on each side of a line whose midpoint the curve fit may use
/// ([`FitWindow::fit`]): enough to fill FIT_REACH with chords of 0.01 mm,
/// the shortest the planner is built for. (With 24, 0.01 mm chords
/// rounded to 1e-4 mm ran 1.45 times the exact curve's time.)
const FIT_SIDE: usize = 50;

/// Lines on each side the fit needs; with fewer, the midpoint's curvature
/// comes from its two vertices alone.
const FIT_MIN_SIDE: usize = 2;

/// Terms of the fitted polynomial (cubic).
const FIT_TERMS: usize = 4;

/// Path length the fit may span on each side of the centre midpoint, mm:
/// on longer chords the rounding of their ends no longer shows in the
/// curvature, and the fit would only flatten real features.
const FIT_REACH: f64 = 0.5;

/// Turn the fit may span on each side (|u − u_centre|, about radians):
/// the cubic's curvature drifts from a circle's with the square of the
/// turn it spans, and its midpoint with the fourth power.
const FIT_TURN: f64 = 0.4;

/// The fit spans no vertex bending more than this (|u1 − u2|, about 5.7°):
/// past it the lines are corners, not chords of one curve.
const FIT_BEND: f64 = 0.1;

/// The frame at the midpoint of `chords[at]`, the chord of line `p`, on
/// the curve fitted through it and its neighbours, when at least
/// [`FIT_MIN_SIDE`] chords on each side continue it without a corner.
/// Only chords before `end` are seen. `origin` is the index among all
/// moves queued of `chords[0]`; `points` keeps fitted points for the
/// frames on either side.
///
/// Where the neighbouring midpoints continue the curve, the frame is the
/// derivatives of the fitted points there ([`fitted_point`]) by finite
/// differences, so that the frames at neighbouring midpoints belong to
/// one curve. Each fit's own derivatives ([`FitWindow::fit`]) are the
/// derivatives of a different cubic: they differ from the fitted points'
/// slope by a fraction of the rounding noise, which across a 0.02 mm
/// blend is curvature rate, and v³·κ′ capped the speed. On a circle of
/// R5 in 0.02 mm chords rounded to 1e-3 mm on mill3, the blends' median
/// speed limit went from 14 to 46 mm/s with this, and the cycle time from
/// 2.85 to 1.29 times the exact circle's (at 1e-4 mm from 1.65 to 1.003;
/// `rounded_cam_chords_run_at_the_programmed_feed`). Elsewhere (ends of
/// a run, where a neighbour's fit has too few chords) the fit's own
/// derivatives stand.
fn fitted_frame(
    chords: &Chords,
    at: usize,
    end: usize,
    p: &Programmed,
    origin: u64,
    points: &mut FittedPoints,
) -> Option<Frame> {
    if let Some(mut frame) = differenced_frame(chords, at, end, origin, points) {
        frame.point[3..].copy_from_slice(&p.line.start[3..]);
        return Some(frame);
    }
    let (mut window, side) = FitWindow::walk(chords, at, end, FIT_SIDE);
    if side < FIT_MIN_SIDE {
        return None;
    }
    window.reach = 1.25 * window.extent();
    let mut frame = window.fit()?;
    let centre = chords.midpoint(at);
    for i in 0..3 {
        frame.point[i] += centre[i];
    }
    frame.point[3..].copy_from_slice(&p.line.start[3..]);
    Some(frame)
}

/// The frame at the midpoint of `chords[at]` from the fitted points at it
/// and at the two midpoints on either side, or the one where the run or
/// the fits stop sooner (X Y Z; the rest zero), when at least the nearest
/// neighbours continue the curve and fit.
fn differenced_frame(
    chords: &Chords,
    at: usize,
    end: usize,
    origin: u64,
    points: &mut FittedPoints,
) -> Option<Frame> {
    if at == 0 || at + 1 >= end || chords.corner(at) || chords.corner(at + 1) {
        return None;
    }
    let mut point = |k: usize| points.get(chords, k, end, origin);
    // Five points where the run goes on two midpoints each side: they
    // average more of what the fit leaves of the rounding (a circle of R5
    // in 0.02 mm chords rounded to 1e-3 mm: 1.02 times the exact circle's
    // time, 1.29 with three points). Else three.
    let wide = at >= 2 && at + 2 < end && !chords.corner(at - 1) && !chords.corner(at + 2);
    if wide {
        if let Some(frame) = differenced::<5>(chords, at - 2, &mut point) {
            return Some(frame);
        }
    }
    differenced::<3>(chords, at - 1, &mut point)
}

/// The frame at the middle of `N` (odd) neighbouring midpoints from
/// `chords[first]` on, from the fitted points there (`point`) by finite
/// differences on their uneven stations (the chords' midpoints along the
/// polyline, the fit's own parameter).
fn differenced<const N: usize>(
    chords: &Chords,
    first: usize,
    point: &mut impl FnMut(usize) -> Option<[f64; 3]>,
) -> Option<Frame> {
    let mut v = [[0.0; 3]; N];
    for (n, v) in v.iter_mut().enumerate() {
        *v = point(first + n)?;
    }
    let c = N / 2;
    let x: [f64; N] =
        std::array::from_fn(|n| chords.station(first + n) - chords.station(first + c));
    if x.windows(2)
        .any(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
    {
        return None;
    }
    let [_, w1, w2] = fornberg(&x);
    let along = |w: &[f64; N]| -> [f64; 3] {
        std::array::from_fn(|i| (0..N).map(|n| w[n] * (v[n][i] - v[c][i])).sum())
    };
    frame_from_derivatives(v[c], along(&w1), along(&w2))
}

/// Weights at 0 of the 0th, 1st and 2nd derivatives of a function from
/// its values at `x` (distinct): the derivatives of the polynomial through
/// them (Fornberg's recursion, "Generation of finite difference formulas
/// on arbitrarily spaced grids", 1988).
fn fornberg<const N: usize>(x: &[f64; N]) -> [[f64; N]; 3] {
    let mut c = [[[0.0f64; N]; N]; 3];
    c[0][0][0] = 1.0;
    let mut c1 = 1.0;
    for i in 1..N {
        let mut c2 = 1.0;
        for j in 0..i {
            let c3 = x[i] - x[j];
            c2 *= c3;
            for m in (0..=i.min(2)).rev() {
                let prev = if m > 0 { c[m - 1][i - 1][j] } else { 0.0 };
                c[m][i][j] = (x[i] * c[m][i - 1][j] - m as f64 * prev) / c3;
            }
        }
        for m in (0..=i.min(2)).rev() {
            let prev = if m > 0 { c[m - 1][i - 1][i - 1] } else { 0.0 };
            c[m][i][i] = c1 / c2 * (m as f64 * prev - x[i - 1] * c[m][i - 1][i - 1]);
        }
        c1 = c2;
    }
    [c[0][N - 1], c[1][N - 1], c[2][N - 1]]
}

/// The frame at `point` of a curve with first and second derivatives
/// `d1`, `d2` in any parameter (X Y Z; the rest zero).
fn frame_from_derivatives(point: [f64; 3], d1: [f64; 3], d2: [f64; 3]) -> Option<Frame> {
    let speed = norm3(&d1);
    if speed.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let t: [f64; 3] = std::array::from_fn(|i| d1[i] / speed);
    let along = d2[0] * t[0] + d2[1] * t[1] + d2[2] * t[2];
    let xyz = |f: &dyn Fn(usize) -> f64| -> Vec9 {
        std::array::from_fn(|i| if i < 3 { f(i) } else { 0.0 })
    };
    Some(Frame {
        point: xyz(&|i| point[i]),
        tangent: xyz(&|i| t[i]),
        curvature: xyz(&|i| (d2[i] - along * t[i]) / (speed * speed)),
    })
}

/// Chords on each side of a midpoint that its fitted point may use: two
/// fewer than [`FIT_SIDE`], so that the point two midpoints further on,
/// which a frame's differences take, sees no further than the frame's own
/// window (which the planner and the blend worker agree on).
const POINT_SIDE: usize = FIT_SIDE - 2;

/// The point at the midpoint of `chords[at]` on the curve fitted through
/// it and its neighbours ([`FitWindow::solve`]), seeing chords before
/// `end`.
fn fitted_point(chords: &Chords, at: usize, end: usize) -> Option<[f64; 3]> {
    let (mut window, side) = FitWindow::walk(chords, at, end, POINT_SIDE);
    if side < FIT_MIN_SIDE {
        return None;
    }
    // The weights should fall to zero where a chord leaves the window, so
    // that the points at neighbouring midpoints lie on one smooth curve,
    // and the reach should not move with every chord's rounding. Where
    // the window spans most of FIT_REACH, FIT_REACH itself; where short
    // chords fill POINT_SIDE well within it, half a chord past the
    // outermost midpoint; elsewhere (corners, turns) as the fit's own.
    let extent = window.extent();
    let snug = extent * (2 * side + 2) as f64 / (2 * side + 1) as f64;
    window.reach = if side == POINT_SIDE && snug < 0.8 * FIT_REACH {
        snug
    } else {
        (1.25 * extent).min(FIT_REACH)
    };
    let coef = window.solve()?;
    Some(std::array::from_fn(|i| coef[0][i] + window.midpoint[i]))
}

/// The last few fitted points ([`fitted_point`]), by the index among all
/// moves queued of the line at whose midpoint they are and by the end of
/// the window they saw: each is needed by the frames at its own midpoint
/// and at two neighbours on each side. Two fits with the same index and window end
/// see the same chords and give the same bits.
pub(super) struct FittedPoints {
    slots: [(u64, u64, Option<[f64; 3]>); 6],
    next: usize,
}

impl FittedPoints {
    pub(super) fn new() -> FittedPoints {
        FittedPoints {
            slots: [(u64::MAX, 0, None); 6],
            next: 0,
        }
    }

    /// [`fitted_point`] at `chords[at]`, `origin` being the index of
    /// `chords[0]`.
    fn get(&mut self, chords: &Chords, at: usize, end: usize, origin: u64) -> Option<[f64; 3]> {
        let index = origin + at as u64;
        // Nothing past POINT_SIDE chords after the centre changes the fit.
        let seen = (origin + end as u64).min(index + 1 + POINT_SIDE as u64);
        if let Some(&(_, _, point)) = self.slots.iter().find(|s| s.0 == index && s.1 == seen) {
            return point;
        }
        let point = fitted_point(chords, at, end);
        self.slots[self.next] = (index, seen, point);
        self.next = (self.next + 1) % self.slots.len();
        point
    }
}

/// Midpoints a curve fit sees around one line's midpoint, in path order,
/// as many before it as after it: `used` chords kept from storage slot
/// `first` of `chords` on. The fit takes their path length from the
/// centre's (`x`, mm, negative before it) and their offsets from the
/// centre's midpoint (`y`, mm) straight from the chords' fields, as
/// fractions of `reach`, mm, beyond which the weights are zero.
struct FitWindow<'c> {
    chords: &'c Chords,
    first: usize,
    used: usize,
    /// The centre chord's station and midpoint.
    station: f64,
    midpoint: [f64; 3],
    reach: f64,
}

/// Sums over a window's slots run in this many interleaved partial sums,
/// one per lane of a vector register; the order of additions is fixed, so
/// the plain and the AVX code give the same bits.
const FIT_LANES: usize = 4;

/// One value per lane of a fit's partial sums.
type Lanes = [f64; FIT_LANES];

/// The normal equations of a fit in partial sums, lane by lane: Σ w·u^p
/// (p = 0..6) and Σ w·u^p·y (p = 0..3, for X, Y and Z).
#[derive(Debug, PartialEq)]
struct FitSums {
    moments: [Lanes; 2 * FIT_TERMS - 1],
    rhs: [[Lanes; FIT_TERMS]; 3],
}

impl<'c> FitWindow<'c> {
    /// The window of a fit centred on chord `at`, seeing chords before
    /// `end`, with [`fit_side`]'s count of chords on each side (at most
    /// `most`), and that count. Reach unset.
    fn walk(chords: &'c Chords, at: usize, end: usize, most: usize) -> (FitWindow<'c>, usize) {
        let side = fit_side(chords, at, end, most);
        let centre = chords.slot(at);
        let window = FitWindow {
            chords,
            first: centre - side,
            used: 2 * side + 1,
            station: chords.station[centre],
            midpoint: chords.midpoint(at),
            reach: 0.0,
        };
        (window, side)
    }

    /// Slot `k`'s path length from the centre, mm.
    fn x(&self, k: usize) -> f64 {
        self.chords.station[self.first + k] - self.station
    }

    /// The fit's weighted sums over the window's `used` chords, with the
    /// path lengths scaled by `scale`, one lane of FIT_LANES chords after
    /// another (the last lane's chords past the window read whatever the
    /// chords' fields hold there, finite, and weigh +0). Weights fall
    /// smoothly to zero past the outermost midpoints (tricube): with equal
    /// weights, each step of the window along the chords would drop and
    /// add a point of large leverage, and the noise would come back as
    /// jumps between neighbouring fits.
    ///
    /// This is the plain version, and the reference for
    /// [`sums_avx`](Self::sums_avx), which does the same operations in the
    /// same order four chords per instruction: the compiler did not manage
    /// that on its own, and the sums were half the planner's time on dense
    /// chords.
    fn sums_lanes(&self, used: usize, scale: f64) -> FitSums {
        let mut s = FitSums {
            moments: [[0.0; FIT_LANES]; 2 * FIT_TERMS - 1],
            rhs: [[[0.0; FIT_LANES]; FIT_TERMS]; 3],
        };
        for c in 0..used.div_ceil(FIT_LANES) {
            for l in 0..FIT_LANES {
                let k = c * FIT_LANES + l;
                let u = self.x(k) * scale;
                let r = u.abs().min(1.0);
                let f = 1.0 - r * r * r;
                let mask = if k < used { 1.0 } else { 0.0 };
                let w = f * f * f * mask;
                let mut p = w;
                for (m, moment) in s.moments.iter_mut().enumerate() {
                    moment[l] += p;
                    if m + 1 < 2 * FIT_TERMS - 1 {
                        p *= u;
                    }
                }
                for i in 0..3 {
                    let y = self.chords.midpoint[i][self.first + k] - self.midpoint[i];
                    let mut p = w * y;
                    for (m, rhs) in s.rhs[i].iter_mut().enumerate() {
                        rhs[l] += p;
                        if m + 1 < FIT_TERMS {
                            p *= u;
                        }
                    }
                }
            }
        }
        s
    }

    /// [`sums_lanes`](Self::sums_lanes) in AVX instructions, four chords
    /// at once (mul and add, no FMA: every operation rounds as there).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn sums_avx(&self, used: usize, scale: f64) -> FitSums {
        use std::arch::x86_64::*;
        const _: () = assert!(FIT_LANES == 4);
        let chords = self.chords;
        let chunks = used.div_ceil(4);
        // The last group of four ends within the fields (checked once,
        // here, rather than at every load).
        let end = self.first + 4 * chunks;
        assert!(end <= chords.storage(), "a fit's window within its chords");
        let first = self.first;
        // Not closures: they would not inherit this function's AVX.
        macro_rules! load {
            ($a:expr, $c:expr) => {{
                // SAFETY: first + 4·c + 3 < end, within every field
                // (asserted above: `Chords::storage`).
                unsafe { _mm256_loadu_pd($a.as_ptr().add(first + $c * 4)) }
            }};
        }
        let mut out = FitSums {
            moments: [[0.0; 4]; 2 * FIT_TERMS - 1],
            rhs: [[[0.0; 4]; FIT_TERMS]; 3],
        };
        macro_rules! store {
            ($to:expr, $v:expr) => {
                // SAFETY: `$to` is four writable f64.
                unsafe { _mm256_storeu_pd($to.as_mut_ptr(), $v) }
            };
        }
        let zero = _mm256_setzero_pd();
        let one = _mm256_set1_pd(1.0);
        let sign = _mm256_set1_pd(-0.0);
        let scale = _mm256_set1_pd(scale);
        let station = _mm256_set1_pd(self.station);
        let midpoint = [
            _mm256_set1_pd(self.midpoint[0]),
            _mm256_set1_pd(self.midpoint[1]),
            _mm256_set1_pd(self.midpoint[2]),
        ];
        let first_slots = _mm256_set_pd(3.0, 2.0, 1.0, 0.0);
        let used_f = _mm256_set1_pd(used as f64);
        let mut moments = [zero; 2 * FIT_TERMS - 1];
        let mut rhs0 = [zero; FIT_TERMS];
        // The weight and u of chunk `c`'s lanes. Worked out again for the
        // second pass (X, Y and Z in one pass would need more registers
        // than there are): cheaper than an array that keeps them.
        macro_rules! weights {
            ($c:expr) => {{
                let c = $c;
                let x = _mm256_sub_pd(load!(chords.station, c), station);
                let u = _mm256_mul_pd(x, scale);
                let r = _mm256_min_pd(_mm256_andnot_pd(sign, u), one);
                let f = _mm256_sub_pd(one, _mm256_mul_pd(_mm256_mul_pd(r, r), r));
                // Chords past `used` weigh +0, as f³·0 does in the plain
                // sums (f ≥ 0): all bits kept where the lane's index is
                // below `used`, none elsewhere.
                let slot = _mm256_add_pd(first_slots, _mm256_set1_pd((c * 4) as f64));
                let mask = _mm256_cmp_pd::<_CMP_LT_OQ>(slot, used_f);
                (
                    _mm256_and_pd(_mm256_mul_pd(_mm256_mul_pd(f, f), f), mask),
                    u,
                )
            }};
        }
        macro_rules! offset {
            ($i:expr, $c:expr) => {
                _mm256_sub_pd(load!(chords.midpoint[$i], $c), midpoint[$i])
            };
        }
        for c in 0..chunks {
            let (w, u) = weights!(c);
            let mut p = w;
            for (m, moment) in moments.iter_mut().enumerate() {
                *moment = _mm256_add_pd(*moment, p);
                if m + 1 < 2 * FIT_TERMS - 1 {
                    p = _mm256_mul_pd(p, u);
                }
            }
            let mut p = _mm256_mul_pd(w, offset!(0, c));
            for (m, r) in rhs0.iter_mut().enumerate() {
                *r = _mm256_add_pd(*r, p);
                if m + 1 < FIT_TERMS {
                    p = _mm256_mul_pd(p, u);
                }
            }
        }
        let mut rhs12 = [[zero; FIT_TERMS]; 2];
        for c in 0..chunks {
            let (w, u) = weights!(c);
            for (i, rhs) in rhs12.iter_mut().enumerate() {
                let y = if i == 0 { offset!(1, c) } else { offset!(2, c) };
                let mut p = _mm256_mul_pd(w, y);
                for (m, r) in rhs.iter_mut().enumerate() {
                    *r = _mm256_add_pd(*r, p);
                    if m + 1 < FIT_TERMS {
                        p = _mm256_mul_pd(p, u);
                    }
                }
            }
        }
        for (to, v) in out.moments.iter_mut().zip(moments) {
            store!(to, v);
        }
        for (to, v) in out.rhs[0].iter_mut().zip(rhs0) {
            store!(to, v);
        }
        for (i, rhs) in rhs12.into_iter().enumerate() {
            for (to, v) in out.rhs[i + 1].iter_mut().zip(rhs) {
                store!(to, v);
            }
        }
        out
    }

    /// Path length from the centre to the farther outermost midpoint, mm.
    fn extent(&self) -> f64 {
        (-self.x(0)).max(self.x(self.used.max(1) - 1))
    }

    /// The curve that dense chords sample, near the centre midpoint: the
    /// coefficients of a weighted least-squares cubic through the window's
    /// midpoints in u = path length / reach (offsets from the centre
    /// midpoint; X Y Z in each), or None if the window is degenerate.
    ///
    /// CAM output rounds its points (to 1e-5 mm or worse), which on chords
    /// of 0.02 mm puts several per cent of noise on the curvature two
    /// vertices give, and far more on its rate, which caps the speed
    /// through v³·κ′. A fit over dozens of chords averages that away, and
    /// since neighbouring fits share most of their chords, the curvature
    /// changes little from one to the next. Midpoints, not vertices: on a
    /// polygon inscribed in a circle they lie on one circle themselves,
    /// with tangents along the chords, so the blends through them stay
    /// within the chords' sag.
    fn solve(&self) -> Option<[[f64; 3]; FIT_TERMS]> {
        let used = self.used;
        let reach = self.reach;
        if used == 0 || reach.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let scale = 1.0 / reach;
        // Weighted moments Σ w·u^p (p = 0..6) and Σ w·u^p·y (p = 0..3):
        // the normal equations of y = Σ c_p·u^p in u = x / reach (well
        // scaled). Cubic, not quadratic: a parabola takes the cubic term of
        // a curve whose curvature changes as a tilt of its tangent, the
        // same at every midpoint, which the blends between them would then
        // have to undo.
        #[cfg(target_arch = "x86_64")]
        let sums = if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the processor supports AVX, checked just above.
            unsafe { self.sums_avx(used, scale) }
        } else {
            self.sums_lanes(used, scale)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let sums = self.sums_lanes(used, scale);
        solve_sums(&sums)
    }

    /// The frame at the centre midpoint of the fitted cubic ([`solve`](Self::solve)),
    /// relative to the midpoint: the cubic's own derivatives there.
    fn fit(&self) -> Option<Frame> {
        let coef = self.solve()?;
        let reach = self.reach;
        // The frame at the centre midpoint (u = 0), relative to it.
        let c1: [f64; 3] = std::array::from_fn(|i| coef[1][i] / reach);
        let c2: [f64; 3] = std::array::from_fn(|i| 2.0 * coef[2][i] / (reach * reach));
        frame_from_derivatives(coef[0], c1, c2)
    }
}

/// The cubic's coefficients from its normal equations in partial sums
/// ([`FitWindow::solve`]).
fn solve_sums(sums: &FitSums) -> Option<[[f64; 3]; FIT_TERMS]> {
    let (moments, rhs) = (&sums.moments, &sums.rhs);
    let total = |a: &Lanes| (a[0] + a[1]) + (a[2] + a[3]);
    let mut m = [[0.0; FIT_TERMS + 3]; FIT_TERMS];
    for row in 0..FIT_TERMS {
        for col in 0..FIT_TERMS {
            m[row][col] = total(&moments[row + col]);
        }
        for i in 0..3 {
            m[row][FIT_TERMS + i] = total(&rhs[i][row]);
        }
    }
    // Gaussian elimination; the matrix is positive definite (at least
    // five distinct points), so no pivoting is needed.
    for p in 0..FIT_TERMS {
        // (NaN fails too.)
        if m[p][p].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        for row in p + 1..FIT_TERMS {
            let f = m[row][p] / m[p][p];
            for col in p..FIT_TERMS + 3 {
                m[row][col] -= f * m[p][col];
            }
        }
    }
    let mut coef = [[0.0f64; 3]; FIT_TERMS];
    for p in (0..FIT_TERMS).rev() {
        for i in 0..3 {
            let known: f64 = (p + 1..FIT_TERMS).map(|k| m[p][k] * coef[k][i]).sum();
            coef[p][i] = (m[p][FIT_TERMS + i] - known) / m[p][p];
        }
    }
    Some(coef)
}

/// Shortest time, s, over a line of `length` mm entered and left at speed
/// `at` mm/s with no acceleration, under top speed `top` mm/s,
/// acceleration `accel` mm/s² and jerk `jerk` mm/s³ (infinite for
/// trapezoidal profiles): the S-curve up by Δ and back down again, with Δ
/// the most the length allows, and a cruise at `top` if it is reached.
///
/// Up by Δ and down takes 2·τ(Δ) over (2·at + Δ)·τ(Δ), τ(Δ) = Δ/A + A/J
/// once the ramp reaches A (Δ ≥ A²/J), else 2·√(Δ/J); the length fixes Δ
/// through a quadratic or, below A, a cubic in √Δ with one real root.
fn line_time(length: f64, at: f64, top: f64, accel: f64, jerk: f64) -> f64 {
    let u = at.min(top).max(0.0);
    if length <= 0.0 {
        return 0.0;
    }
    // Speed change below which the ramp never reaches the acceleration
    // limit (0 for trapezoidal profiles).
    let knee = accel * accel / jerk;
    let ramp = |dv: f64| {
        if dv >= knee {
            dv / accel + accel / jerk
        } else {
            2.0 * (dv / jerk).sqrt()
        }
    };
    let most = top - u;
    let reach = (2.0 * u + most) * ramp(most);
    if reach <= length {
        return 2.0 * ramp(most) + (length - reach) / top;
    }
    let dv = if length <= (2.0 * u + knee) * ramp(knee) {
        // (2·u + x²)·2·x/√J = length with x = √Δ: x³ + p·x = c, p ≥ 0,
        // one real root. Both c^(1/3) and c/p lie above it, and within
        // 2^(1/3) of it at worst; the cubic is convex there, so Newton
        // steps from the lower of them fall onto it.
        let (p, c) = (2.0 * u, length * jerk.sqrt() / 2.0);
        // The cube root's exponent and leading bits from the float's
        // bits (within 4 %): one Newton step less than starting from
        // c/p alone, and no library cube root (slow, and planning runs
        // this at every sharp corner).
        let guess = f64::from_bits(c.to_bits() / 3 + 0x2A9F_7893_782D_A1CE);
        let mut x = if p > 0.0 { guess.min(c / p) } else { guess };
        for _ in 0..8 {
            let step = (x * (x * x + p) - c) / (3.0 * x * x + p);
            x -= step;
            if step.abs() <= 1e-12 * x {
                break;
            }
        }
        x * x
    } else {
        // (2·u + Δ)·(Δ/A + A/J) = length: Δ²/A + b·Δ + k = 0 with k < 0,
        // its positive root in the form that does not cancel.
        let b = accel / jerk + 2.0 * u / accel;
        let k = 2.0 * u * accel / jerk - length;
        -2.0 * k / (b + (b * b - 4.0 * k / accel).sqrt())
    };
    2.0 * ramp(dv.min(most))
}

/// Bounds on |dp_i/ds|, |d²p_i/ds²| and |d³p_i/ds³| of either plane axis
/// along an arc `length` mm long: a circle or helix, or a spiral whose
/// radius changes in the program's rounding (or up to the interpreter's
/// spiral tolerance, which on a small arc is more than the radius itself).
///
/// On a circle (sweep S, radius r, w = S/length) these are r·w, r·w² and
/// r·w³. A logarithmic spiral (`Shape::frame`) has a unit tangent whose in-plane
/// part is Lp/length (Lp its in-plane length), curvature w·Lp/length with
/// w = dθ/ds = S·h/(r·length) largest at the smaller radius, and
/// d(curvature)/ds of at most (|w′| + w²)·Lp/length with
/// w′ = −w·D/(r·length). Taking the start radius for all of the arc, as
/// circles do, understated them by up to the ratio of the radii (an arc of
/// 0.01 mm spiralling out to 0.03 mm ran at 1.13 times the jerk limit).
fn arc_extremes(arc: &Arc, length: f64) -> (f64, f64, f64) {
    if length <= 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let s = arc.sweep.abs();
    let d = (arc.end_radius - arc.radius).abs();
    if !arc.is_logarithmic() {
        // Angle θ0 + S·f and radius r0 + D·f at f = s / length: the
        // derivatives in f of a plane axis are sums of a sine and a cosine
        // (D·cos θ − r·S·sin θ, −2·D·S·sin θ − r·S²·cos θ,
        // −3·D·S²·cos θ + r·S³·sin θ), bounded at the larger radius.
        let rs = arc.radius.max(arc.end_radius) * s;
        return (
            (d * d + rs * rs).sqrt() / length,
            s * (4.0 * d * d + rs * rs).sqrt() / (length * length),
            s * s * (9.0 * d * d + rs * rs).sqrt() / (length * length * length),
        );
    }
    let (_, h) = arc.growth();
    let r_min = arc.radius.min(arc.end_radius);
    let along = arc.in_plane_length() / length;
    let w = s * h.abs() / (r_min * length);
    (along, w * along, (w * d / (r_min * length) + w * w) * along)
}

/// The control points of the two halves of a quintic Bézier, split at
/// u = ½ by de Casteljau: the left half's are the first points of each
/// level, the right half's the last ones.
fn halves(q: &[[f64; 3]; 6]) -> ([[f64; 3]; 6], [[f64; 3]; 6]) {
    let mut level = *q;
    let mut left = [[0.0; 3]; 6];
    let mut right = [[0.0; 3]; 6];
    for n in 0..6 {
        left[n] = level[0];
        right[5 - n] = level[5 - n];
        for k in 0..5 - n {
            for i in 0..3 {
                level[k][i] = 0.5 * (level[k][i] + level[k + 1][i]);
            }
        }
    }
    (left, right)
}

/// Halvings [`piece_near`] may make of a quarter before it gives up:
/// pieces of 1/256 of the blend's parameter, whose hulls hug the curve.
const SUBDIVISIONS: u32 = 6;

/// Whether the quintic piece `points` lies within √`limit2` of one of
/// `lines` everywhere: proven on its hull, or on the hulls of its halves,
/// down to [`SUBDIVISIONS`] levels; a piece that starts outside them all,
/// or cannot be proven at the last level, fails. A proof, not a sample:
/// sampling missed peaks narrower than the samples' spacing
/// (stellabee1.ngc measured 0.0103 mm under P0.01).
fn piece_near(points: &[[f64; 3]; 6], lines: &[Near], limit2: f64, depth: u32) -> bool {
    if lines.iter().any(|l| l.hull_within(points, limit2)) {
        return true;
    }
    // The piece's first control point is on the curve.
    if depth == 0 || !lines.iter().any(|l| l.distance2(&points[0]) <= limit2) {
        return false;
    }
    let (left, right) = halves(points);
    piece_near(&left, lines, limit2, depth - 1) && piece_near(&right, lines, limit2, depth - 1)
}

/// Whether the quintic piece `points` lies inside the box `travel`
/// (within [`LIMIT_SLACK`]): proven on its control points (the box is
/// convex), or on its halves', down to `depth` levels.
fn hull_in_box(points: &[[f64; 3]; 6], travel: &[(f64, f64); 3], depth: u32) -> bool {
    let inside = |p: &[f64; 3]| {
        (0..3).all(|i| p[i] >= travel[i].0 - LIMIT_SLACK && p[i] <= travel[i].1 + LIMIT_SLACK)
    };
    if points.iter().all(inside) {
        return true;
    }
    if depth == 0 || !inside(&points[0]) || !inside(&points[5]) {
        return false;
    }
    let (left, right) = halves(points);
    hull_in_box(&left, travel, depth - 1) && hull_in_box(&right, travel, depth - 1)
}

/// The blend with control points `q` within `tolerance` of one of `lines`
/// everywhere (proven by subdividing each quarter that `proven` does not
/// cover, see [`piece_near`]), and |B′| at least `min_speed` at 31
/// evenly spaced parameters. What `proven` (from [`hull_bounds`]) already
/// guarantees is not computed again.
fn sampled_within(
    q: &[Vec9; 6],
    lines: &[Near],
    tolerance: f64,
    min_speed: f64,
    proven: &Proven,
) -> bool {
    let limit = tolerance * (1.0 - 1e-9);
    let limit2 = limit * limit;
    let points: [[f64; 3]; 6] = std::array::from_fn(|k| [q[k][0], q[k][1], q[k][2]]);
    let (left, right) = halves(&points);
    let (q0, q1) = halves(&left);
    let (q2, q3) = halves(&right);
    let near = [q0, q1, q2, q3]
        .iter()
        .enumerate()
        .all(|(n, piece)| proven.quarters[n] || piece_near(piece, lines, limit2, SUBDIVISIONS));
    if !near {
        return false;
    }
    if proven.speed {
        return true;
    }
    let poly = Poly::new(q);
    (1..32).all(|k| poly.speed(k as f64 / 32.0) >= min_speed)
}

/// What [`hull_bounds`] proves of a blend for every parameter u, not only
/// the sampled ones.
#[derive(Clone, Copy, Debug, Default)]
struct Proven {
    /// Quarter `n` (u in n/4..=(n+1)/4) lies within the tolerance of a line.
    quarters: [bool; 4],
    /// |B′| is at least the least speed.
    speed: bool,
}

impl Proven {
    fn all(&self) -> bool {
        self.quarters.iter().all(|&q| q) && self.speed
    }
}

/// Sufficient conditions for [`sampled_within`] — every point within
/// `tolerance` of line `la` or `lb` and |B′| at least `min_speed` — that
/// cost a fraction of it. Most blends pass them all with room to spare;
/// for the rest the sampled test skips what they did prove.
///
/// Split at u = ½, each half is a quintic whose points lie in the convex hull
/// of its control points, and distance to a line segment is convex: so the
/// first half is within `tolerance` of `la` if its control points are, and
/// the second half of `lb` likewise; failing that, each quarter of either
/// line. The hodograph B′ is a quartic with control points 5·(Q[k+1] − Q[k]);
/// its component along any unit vector e is at least the least of theirs,
/// and |B′| ≥ B′·e. A margin of 1e-9 covers rounding (and squared distances
/// where the sampled test takes roots).
fn hull_bounds(q: &[Vec9; 6], la: &Near, lb: &Near, tolerance: f64, min_speed: f64) -> Proven {
    let limit = tolerance * (1.0 - 1e-9);
    let limit2 = limit * limit;
    let within = |points: &[[f64; 3]; 6], l: &Near| l.hull_within(points, limit2);
    let points: [[f64; 3]; 6] = std::array::from_fn(|k| [q[k][0], q[k][1], q[k][2]]);
    let (left, right) = halves(&points);
    let quarters = |half: &[[f64; 3]; 6], near: &Near| {
        if within(half, near) {
            return [true, true];
        }
        let (a, b) = halves(half);
        [
            within(&a, la) || within(&a, lb),
            within(&b, la) || within(&b, lb),
        ]
    };
    let ([q0, q1], [q2, q3]) = (quarters(&left, la), quarters(&right, lb));
    let chord: [f64; 3] = std::array::from_fn(|i| q[5][i] - q[0][i]);
    let length = (chord[0] * chord[0] + chord[1] * chord[1] + chord[2] * chord[2]).sqrt();
    let slowest = (0..5)
        .map(|k| {
            (0..3)
                .map(|i| 5.0 * (q[k + 1][i] - q[k][i]) * chord[i])
                .sum::<f64>()
        })
        .fold(f64::INFINITY, f64::min);
    Proven {
        quarters: [q0, q1, q2, q3],
        speed: length > 0.0 && slowest >= min_speed * length * (1.0 + 1e-9),
    }
}

impl<'k> Planner<'k> {
    /// A planner for the machine `kins`, starting at `start`.
    pub fn new(kins: &'k dyn Kinematics, start: Position, config: PlannerConfig) -> Self {
        let mut limits = [None; 9];
        let mut travel = [(f64::NEG_INFINITY, f64::INFINITY); 3];
        for spec in kins.axes() {
            limits[spec.axis.index()] = Some(spec.limits);
            if let Some(t) = travel.get_mut(spec.axis.index()) {
                *t = (spec.limits.min, spec.limits.max);
            }
        }
        let mut sample_joints = false;
        for (j, spec) in kins.joints().iter().enumerate() {
            let axis = kins.joint_axis(j);
            if let Some(t) = axis.and_then(|a| travel.get_mut(a.index())) {
                *t = (t.0.max(spec.limits.min), t.1.min(spec.limits.max));
            }
            match axis.and_then(|a| limits[a.index()].as_mut()) {
                Some(l) => {
                    l.max_velocity = l.max_velocity.min(spec.limits.max_velocity);
                    l.max_acceleration = l.max_acceleration.min(spec.limits.max_acceleration);
                    l.max_jerk = l.max_jerk.min(spec.limits.max_jerk);
                }
                None => sample_joints = true,
            }
        }
        if !config.jerk_limited {
            // Acceleration-limited profiles: the acceleration may swing
            // over its whole range within a sixteenth of a period, which
            // sampled every period is a step. (Not an infinite jerk: the
            // executor's profiles and guard take time to change the
            // acceleration, and divide by the jerk.)
            for l in limits.iter_mut().flatten() {
                l.max_jerk = TRAPEZOID_RAMPS * l.max_acceleration / config.period;
            }
        }
        Planner {
            kins,
            config,
            limits,
            sample_joints,
            travel,
            mode: config.mode,
            feed_word: 0.0,
            per_revolution: false,
            spindle_rpm: 0.0,
            force_control: None,
            sync_outputs: SyncOutputs::default(),
            position: start,
            last_line: 0,
            received: 0,
            moves: SourceMoves::default(),
            reading: 0,
            pending: VecDeque::new(),
            ready: VecDeque::new(),
            merge: CollinearMerge::new(),
            chords: Chords::new(),
            behind: 0,
            released: 0,
            ahead: config.blend_worker.then(ahead::Ahead::start).flatten(),
            fitted_points: std::cell::RefCell::new(FittedPoints::new()),
        }
    }

    /// Where the tool is after everything planned so far.
    pub fn position(&self) -> Position {
        self.position
    }

    /// The stop that ends a program (`SegmentKind::Stop { tag }`): where
    /// the tool is after everything planned, on the source line of the
    /// last command planned, so that whatever reads the line there (the
    /// status, the deviation measured against the program) sees the
    /// program's end, not line 0.
    pub fn end_marker(&self, tag: u32) -> Segment {
        Segment {
            reading: self.reading,
            ..Segment::marker(SegmentKind::Stop { tag }, self.last_line, self.position)
        }
    }

    /// Set the path control mode for the following moves.
    pub fn set_mode(&mut self, mode: PathMode) {
        self.release_merged();
        self.mode = mode;
    }

    /// Cutting-force control for the following moves: on with target
    /// force `newtons`, or off (`None`). This is what the program's
    /// force-control M-code (`docs/control.md`) is to call; it travels with
    /// the segments, so it takes effect in step with the motion.
    pub fn set_force_control(&mut self, newtons: Option<f64>) {
        self.release_merged();
        self.force_control = newtons;
    }

    /// The next segment whose successors are known, if any.
    pub fn next_segment(&mut self) -> Option<Segment> {
        self.ready.pop_front()
    }

    /// Release every waiting move, the last ending at rest (program end,
    /// dwell, or anything else that stops the machine).
    pub fn finish(&mut self) {
        self.release_merged();
        if let Some(ahead) = &mut self.ahead {
            ahead.flush();
        }
        self.drain(true);
    }

    /// Plan the moves held for a G64 Q merge. The merged line was checked
    /// against the machine each time the chain grew (`fits`,
    /// `merged_fits`), and the feed was above zero, so planning it cannot
    /// fail; the result is not needed.
    fn release_merged(&mut self) {
        self.merge.flush();
        while let Some((merged, moves)) = self.merge.take() {
            let planned = self.command(&merged, moves);
            debug_assert!(planned.is_ok(), "a checked merged line failed: {planned:?}");
        }
    }

    /// Plan one canon command. Segments become available from
    /// [`next_segment`](Self::next_segment) once their successors are known.
    ///
    /// Errors, naming the source line, if the move leaves the machine's
    /// travel, reach or joint strokes, or moves an axis the machine lacks.
    /// After an error the planner carries on from the move's end, so a
    /// check can report every violation of a program.
    pub fn plan(&mut self, canon: &Canon) -> Result<(), PlanError> {
        self.last_line = canon.source.line;
        self.received += 1;
        // G64 Q (merge.rs): runs of nearly collinear straight feeds are held
        // and planned as one line. A move that leaves the machine is not
        // held, so its error names its own line.
        let verdict = if self.merge.tolerance() > 0.0 && !self.fits(canon) {
            self.merge.flush();
            Verdict::Pass
        } else {
            // The merged line must fit too (on a machine whose reach is not
            // a box, a chord can leave it where the moves did not): if it
            // would not, what is held goes as it is and a new chain starts.
            if !self.merge.is_empty() && !self.merged_fits(canon) {
                self.merge.flush();
            }
            let ctx = MergeContext {
                at: self.position,
                continuous: matches!(self.mode, PathMode::Blend { .. }),
                feed_ok: self.feed() > 0.0,
                number: self.received,
            };
            self.merge.see(canon, &ctx)
        };
        let mut result = Ok(());
        while let Some((merged, moves)) = self.merge.take() {
            result = result.and(self.command(&merged, moves));
        }
        if verdict == Verdict::Pass {
            result = result.and(self.command(canon, SourceMoves::one(self.received)));
        }
        result
    }

    /// For a straight or arc feed, whether the straight move to its end
    /// from the last held or planned point passes the planner's checks.
    fn fits(&self, canon: &Canon) -> bool {
        let end = match &canon.cmd {
            CanonCmd::StraightFeed { end } | CanonCmd::ArcFeed { end, .. } => end,
            _ => return true,
        };
        let start = self.merge.last().unwrap_or(self.position);
        let line = Line {
            start: start.to_array(),
            end: end.to_array(),
        };
        self.check_shape(canon, &Shape::Line(line)).is_ok()
    }

    /// For a straight feed, whether the line from the start of the held
    /// chain to its end passes the planner's checks: the line it would
    /// merge into.
    fn merged_fits(&self, canon: &Canon) -> bool {
        let (CanonCmd::StraightFeed { end }, Some(start)) = (&canon.cmd, self.merge.first()) else {
            return true;
        };
        let line = Line {
            start: start.to_array(),
            end: end.to_array(),
        };
        self.check_shape(canon, &Shape::Line(line)).is_ok()
    }

    /// Plan `canon`, which runs along the programmed moves `moves`.
    fn command(&mut self, canon: &Canon, moves: SourceMoves) -> Result<(), PlanError> {
        self.moves = moves;
        self.reading = canon.source.reading;
        let line = canon.source.line;
        let unsupported = |what: &str| {
            Err(self.error(canon, format!("{what} is not supported by the planner yet")))
        };
        match &canon.cmd {
            CanonCmd::SetFeedRate { mm_per_min } => self.feed_word = *mm_per_min,
            CanonCmd::SetFeedMode { per_revolution, .. } => self.per_revolution = *per_revolution,
            CanonCmd::SetSpindleSpeed { rpm, .. } => self.spindle_rpm = *rpm,
            CanonCmd::ForceControl { target } => self.force_control = *target,
            CanonCmd::SetMotionControlMode(mode) => {
                self.mode = PathMode::from_program(*mode, self.config.default_tolerance)
            }
            CanonCmd::Dwell { seconds } => {
                self.marker_at_rest(line, SegmentKind::Dwell { seconds: *seconds })
            }
            CanonCmd::StraightTraverse { end } => self.line(canon, SegmentKind::Rapid, *end)?,
            CanonCmd::StraightFeed { end } => self.line(canon, SegmentKind::Feed, *end)?,
            CanonCmd::ArcFeed {
                end,
                center,
                plane,
                turns,
            } => {
                let [first, second, _] = plane.axes();
                let arc = Arc::from_program(
                    &self.position.to_array(),
                    &end.to_array(),
                    (first.index(), second.index()),
                    (center[0], center[1]),
                    *turns,
                );
                self.arc(canon, arc)?;
            }
            // The machine comes to rest at the program's end, and for a
            // pallet change (M30 and M60 ask for one; kerf drives no
            // shuttle, and M60's program stop follows it).
            CanonCmd::ProgramEnd | CanonCmd::Finish | CanonCmd::PalletShuttle => self.finish(),
            // And at a program stop, where it waits for the operator.
            CanonCmd::ProgramStop => {
                self.marker_at_rest(line, SegmentKind::ProgramStop { optional: false })
            }
            CanonCmd::OptionalProgramStop => {
                self.marker_at_rest(line, SegmentKind::ProgramStop { optional: true })
            }
            CanonCmd::StraightProbe { .. } => return unsupported("a probe move (G38.x)"),
            CanonCmd::RigidTap { .. } => return unsupported("rigid tapping (G33.1, G84 rigid)"),
            CanonCmd::StartSpeedFeedSync { .. } => {
                return unsupported("spindle-synchronised motion (G33, G76)")
            }
            CanonCmd::WaitInput {
                index,
                digital,
                mode,
                timeout,
            } => {
                let (count, kind, key) = if *digital {
                    (self.config.digital_inputs, "digital", "digital_in")
                } else {
                    (self.config.analog_inputs, "analog", "analog_in")
                };
                let index = match u8::try_from(*index) {
                    Ok(n) if (n as usize) < count => n,
                    _ => {
                        return Err(self.error(
                            canon,
                            format!(
                                "M66: no {kind} input {index}: the machine has {count} ([hal.pins] {key})"
                            ),
                        ))
                    }
                };
                let request = InputRequest {
                    index,
                    digital: *digital,
                    mode: *mode,
                    timeout: *timeout,
                };
                self.marker_at_rest(line, SegmentKind::WaitInput(request));
            }
            CanonCmd::SetMotionOutputBit { index } => {
                let n = self.digital_output(canon, *index)?;
                self.sync_outputs.set_digital(n, true);
            }
            CanonCmd::ClearMotionOutputBit { index } => {
                let n = self.digital_output(canon, *index)?;
                self.sync_outputs.set_digital(n, false);
            }
            CanonCmd::SetMotionOutputValue { index, value } => {
                let n = self.analog_output(canon, *index)?;
                self.sync_outputs.set_analog(n, *value);
            }
            CanonCmd::SetAuxOutputBit { index } | CanonCmd::ClearAuxOutputBit { index } => {
                let n = self.digital_output(canon, *index)?;
                let on = matches!(canon.cmd, CanonCmd::SetAuxOutputBit { .. });
                let change = OutputChange::Digital { index: n as u8, on };
                self.marker_at_rest(line, SegmentKind::Output(change));
            }
            CanonCmd::SetAuxOutputValue { index, value } => {
                let n = self.analog_output(canon, *index)?;
                let change = OutputChange::Analog {
                    index: n as u8,
                    value: *value,
                };
                self.marker_at_rest(line, SegmentKind::Output(change));
            }
            // Offsets and modes the interpreter has already applied to every
            // position, and commands for other parts of the machine.
            CanonCmd::UseLengthUnits(_)
            | CanonCmd::Comment(_)
            | CanonCmd::Message(_)
            | CanonCmd::SetG5xOffset { .. }
            | CanonCmd::SetG92Offset { .. }
            | CanonCmd::SetXYRotation { .. }
            | CanonCmd::UseToolLengthOffset { .. }
            | CanonCmd::SelectPlane(_)
            // G64 Q: the merge in front (merge.rs) has taken it.
            | CanonCmd::SetNaivecamTolerance { .. }
            | CanonCmd::SetPlannerMode { .. }
            | CanonCmd::StopSpeedFeedSync
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
            | CanonCmd::UserMCode { .. }
            | CanonCmd::Log(_)
            | CanonCmd::LogOpen(_)
            | CanonCmd::LogAppend(_)
            | CanonCmd::LogClose
            | CanonCmd::Print(_) => {}
        }
        Ok(())
    }

    /// `P` of M62–M65 as a digital output number of this machine.
    fn digital_output(&self, canon: &Canon, index: u32) -> Result<usize, PlanError> {
        let count = self.config.digital_outputs.min(MAX_DIGITAL_OUTPUTS);
        match index as usize {
            n if n < count => Ok(n),
            n => Err(self.error(
                canon,
                format!("no digital output {n}: the machine has {count} ([hal.pins] digital_out)"),
            )),
        }
    }

    /// `E` of M67/M68 as an analog output number of this machine.
    fn analog_output(&self, canon: &Canon, index: u32) -> Result<usize, PlanError> {
        let count = self.config.analog_outputs.min(MAX_ANALOG_OUTPUTS);
        match index as usize {
            n if n < count => Ok(n),
            n => Err(self.error(
                canon,
                format!("no analog output {n}: the machine has {count} ([hal.pins] analog_out)"),
            )),
        }
    }

    /// A marker that acts at rest (a dwell, an M66 wait, a program stop,
    /// an immediate output): everything before it runs to rest first.
    fn marker_at_rest(&mut self, line: u32, kind: SegmentKind) {
        // Finishing may plan held merged lines, which set their own reading.
        let reading = self.reading;
        self.finish();
        self.ready.push_back(Segment {
            reading,
            ..Segment::marker(kind, line, self.position)
        });
    }

    /// Hand the waiting M62/M63/M67 changes to the move about to be queued.
    fn take_sync_outputs(&mut self) -> SyncOutputs {
        std::mem::take(&mut self.sync_outputs)
    }

    /// The programmed path speed for feed moves, mm/s: the F word, or F
    /// times the spindle speed in feed-per-revolution mode (G95).
    fn feed(&self) -> f64 {
        if self.per_revolution {
            self.feed_word * self.spindle_rpm / 60.0
        } else {
            self.feed_word / 60.0
        }
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
        self.position = end;
        self.check_shape(canon, &shape)?;
        if line.length() == 0.0 {
            return Ok(());
        }
        if kind == SegmentKind::Feed && self.feed() <= 0.0 {
            let why = if self.per_revolution {
                "feed move in feed-per-revolution mode with the spindle speed at zero"
            } else {
                "feed move with a zero feed rate"
            };
            return Err(self.error(canon, why.into()));
        }
        // The limits wait until the line is emitted: on dense paths blends
        // consume most lines whole, and they never need them.
        let mut segment = self.segment_unlimited(kind, canon.source.line, shape);
        segment.outputs = self.take_sync_outputs();
        self.push_pending(Pending {
            segment,
            source: AsProgrammed::Line(Programmed::new(line)),
            mode: self.mode,
            start_leg: 0.0,
            mid: [[0.0; 3]; 3],
        });
        self.drain(false);
        Ok(())
    }

    /// Plan an arc or helix (from the interpreter's arc commands).
    pub fn arc(&mut self, canon: &Canon, arc: Arc) -> Result<(), PlanError> {
        let shape = Shape::Arc(arc);
        self.position = Position::from_array(shape.end());
        self.check_shape(canon, &shape)?;
        if self.feed() <= 0.0 {
            return Err(self.error(canon, "arc with a zero feed rate".into()));
        }
        let mut segment = self.segment(SegmentKind::Feed, canon.source.line, shape);
        segment.outputs = self.take_sync_outputs();
        self.push_pending(Pending {
            segment,
            source: AsProgrammed::Arc(arc),
            mode: self.mode,
            start_leg: 0.0,
            mid: [[0.0; 3]; 3],
        });
        self.drain(false);
        Ok(())
    }

    /// [`blend_legs`] between waiting moves `a` and `b` (None unless both
    /// are lines).
    fn legs(&self, a: &Pending, b: &Pending) -> Option<(f64, f64)> {
        blend_legs(a.programmed()?, b.programmed()?, b.mode)
    }

    /// Drop the first waiting move, keeping it for the curve fit if it is
    /// a line (an arc, or a line that moves more than X Y Z, ends the
    /// polyline the fit sees).
    fn pop_pending(&mut self) {
        if self.pending.pop_front().is_none() {
            return;
        }
        self.released += 1;
        if self.chords.is_break(self.behind) {
            self.chords.drain_front(self.behind + 1);
            self.behind = 0;
        } else if self.behind == FIT_SIDE {
            self.chords.pop_front();
        } else {
            self.behind += 1;
        }
        debug_assert_eq!(self.chords.len(), self.behind + self.pending.len());
    }

    /// Queue a waiting move, with its chord for the curve fit.
    fn push_pending(&mut self, pending: Pending) {
        let line = pending.programmed().filter(|p| p.xyz_only);
        let chord = line.map_or(Chord::BREAK, |p| Chord::of(p, self.chords.back().as_ref()));
        if let Some(ahead) = &mut self.ahead {
            ahead.push(match line {
                Some(&line) => ahead::Move::Line {
                    line,
                    mode: pending.mode,
                },
                None => ahead::Move::Other,
            });
        }
        self.pending.push_back(pending);
        self.chords.push_back(chord);
        debug_assert_eq!(self.chords.len(), self.behind + self.pending.len());
    }

    /// The frame at the midpoint of the second waiting move on the curve
    /// fitted through it and its neighbours ([`fitted_frame`]).
    ///
    /// At the junctions the planner keeps, the blend worker has usually
    /// fitted this already (the blend after starts there).
    fn fitted_mid(&self) -> Option<Frame> {
        let pb = self.pending.get(1)?.programmed().filter(|p| p.xyz_only)?;
        let (at, end) = (self.behind + 1, self.chords.len());
        if let Some(ahead) = &self.ahead {
            // Move indices among all moves queued: pending[1] is move
            // released + 1, and the chords end where the waiting moves do.
            let index = self.released + 1;
            let window = ahead::window_end(index, index + (end - at) as u64);
            if let Some(fit) = ahead.fit(index, window) {
                return fit.map(|xyz| frame_on(&xyz, &pb.line.start[3..]));
            }
        }
        // chords[at] is move released + 1.
        let origin = self.released + 1 - at as u64;
        fitted_frame(
            &self.chords,
            at,
            end,
            pb,
            origin,
            &mut self.fitted_points.borrow_mut(),
        )
    }

    /// Curvature the path should have at the midpoint of `b`, a line whose
    /// two blends meet there: the mean of the discrete curvatures at its two
    /// vertices (exactly 1/R on a polygon inscribed in a circle of radius R).
    fn mid_curvature(a: &Programmed, b: &Programmed, c: &Programmed) -> Vec9 {
        let (ta, tb, tc) = (&a.direction, &b.direction, &c.direction);
        let (la, lb, lc) = (a.length, b.length, c.length);
        let mut k: Vec9 = std::array::from_fn(|i| {
            ((tb[i] - ta[i]) / ((la + lb) / 2.0) + (tc[i] - tb[i]) / ((lb + lc) / 2.0)) / 2.0
        });
        let along: f64 = (0..9).map(|i| k[i] * tb[i]).sum();
        for i in 0..9 {
            k[i] -= along * tb[i];
        }
        k
    }

    /// The blend at the vertex of `a` and `b` from `start` (on `a`) to
    /// `end` (on `b`), `legs` from the vertex, if it is proven within
    /// `b`'s tolerance of the programmed lines ([`hull_bounds`], then
    /// [`sampled_within`]) and inside the machine's reach
    /// ([`Self::blend_in_reach`]).
    fn blend_within(
        &self,
        a: &Pending,
        b: &Pending,
        legs: (f64, f64),
        start: &Frame,
        end: &Frame,
    ) -> Option<[Vec9; 6]> {
        let (pa, pb) = (a.programmed()?, b.programmed()?);
        let PathMode::Blend { tolerance } = b.mode else {
            return None;
        };
        let (control, near) = blend_near(pa, pb, tolerance, legs, start, end);
        (near && self.control_in_reach(&control)).then_some(control)
    }

    /// Emit what the waiting moves decide. With `last`, everything goes and
    /// the final move ends at rest.
    fn drain(&mut self, last: bool) {
        loop {
            let n = self.pending.len();
            if n == 0 {
                return;
            }
            if n == 1 {
                if last {
                    self.release_front(0.0);
                }
                return;
            }
            let both_lines = self.pending[0].is_line() && self.pending[1].is_line();
            // The midpoint of pending[1] depends on the lines after it, up
            // to FIT_SIDE of them (fewer if something else comes first).
            // With a blend worker, LEAD more wait, so that it has them
            // before they are needed (the decisions are the same: nothing
            // looks further than FIT_SIDE lines ahead, nor past a move that
            // is not a line).
            let waiting = match self.ahead {
                Some(_) => n < 2 + FIT_SIDE + ahead::LEAD,
                None => n < 2 + FIT_SIDE && self.pending.iter().skip(2).all(Pending::is_line),
            };
            if both_lines && waiting && !last {
                return;
            }
            if !both_lines {
                if let Some((legs, control, end)) = self.choose_arc_blend() {
                    self.blend_corner(Chosen::new(legs, &control, &end));
                    continue;
                }
            }
            // Decided in place: a blend is a few hundred bytes, and its
            // copies showed in profiles.
            let mut chosen = self.choose_blend(both_lines);
            if let (Some(c), true) = (&mut chosen, self.config.stop_when_quicker) {
                let (stops, limits) = self.stops_sooner(c);
                c.limits = limits;
                if stops {
                    chosen = None;
                }
            }
            let Some(chosen) = chosen else {
                // No blend here, or none fits, or stopping is quicker: stop
                // (or go straight on) at the corner.
                let exit = self.junction(&self.pending[0], &self.pending[1]);
                self.release_front(exit);
                continue;
            };
            self.blend_corner(chosen);
        }
    }

    /// Whether stopping at the corner between the first two waiting lines
    /// is quicker than the blend `chosen` through it. On a dense curve (a
    /// blend taking half a line) only at a [`hairpin`], and only where the
    /// blend before, if it took the first line's other half, ended on that
    /// line with no curvature (the first line continues it). Judging every
    /// dense corner saved a little more (0.4 % on stellabee1.ngc) but cost
    /// a tenth of the planning throughput.
    ///
    /// Through a sharp corner under a small tolerance the blend's speed
    /// limit v is a few mm/s, and the ramps down to v and up from it take
    /// nearly as long as those to and from rest: a jerk-limited ramp ends
    /// in A/J of easing whatever speed it ends at.
    /// The comparison is [`line_time`] for both: each line taken as if
    /// the corner at its other end were alike (as on a zig-zag), half of
    /// its time charged to this corner. Also the blend's path limits,
    /// where it worked them out; the lines' limits stay on the waiting
    /// lines for [`release_front`](Self::release_front).
    fn stops_sooner(&mut self, chosen: &Chosen) -> (bool, Option<(f64, f64, f64)>) {
        let (Some(pa), Some(pb)) = (self.pending[0].programmed(), self.pending[1].programmed())
        else {
            return (false, None);
        };
        let (length_a, length_b) = (pa.length, pb.length);
        let (legs_a, legs_b) = chosen.legs;
        let a = &self.pending[0];
        let continues = a.start_leg < a.full_length() / 2.0 || a.mid[2] == [0.0; 3];
        let dense = legs_a >= 0.999 * length_a / 2.0 || legs_b >= 0.999 * length_b / 2.0;
        if !continues || (dense && !hairpin(pa, pb)) {
            return (false, None);
        }
        let length = chosen.blend.0.length();
        let limits = self.blend_limits(chosen);
        let feed = self.pending[0]
            .segment
            .feed
            .min(self.pending[1].segment.feed);
        let v = limits.0.min(feed);
        // A blend the motion cannot pass (v zero or NaN) is left to the
        // planner's other checks.
        let (Some(la), Some(lb), true) = (self.line_limits(0), self.line_limits(1), v > 0.0) else {
            return (false, Some(limits));
        };
        let line = |length: f64, l: (f64, f64, f64), at: f64| {
            let jerk = if self.config.jerk_limited {
                l.2
            } else {
                f64::INFINITY
            };
            line_time(length, at, l.0.min(feed), l.1, jerk)
        };
        let stop = (line(length_a, la, 0.0) + line(length_b, lb, 0.0)) / 2.0;
        let through = (line(length_a - 2.0 * legs_a, la, v) + line(length_b - 2.0 * legs_b, lb, v))
            / 2.0
            + length / v;
        // A blend must win by half a period: the executor works in whole
        // periods, and near a tie the model errs by that much.
        (through > stop - 0.5 * self.config.period, Some(limits))
    }

    /// The path limits of the blend `chosen`, from its sampled extremes.
    fn blend_limits(&self, chosen: &Chosen) -> (f64, f64, f64) {
        let (blend, extremes) = &chosen.blend;
        let shape = Shape::Blend(*blend);
        self.path_limits(&shape, shape.length(), Some(extremes))
    }

    /// The path limits of waiting line `k` as programmed, worked out once
    /// and kept on it (a trimmed line keeps them: they hold on the whole).
    fn line_limits(&mut self, k: usize) -> Option<(f64, f64, f64)> {
        let p = &self.pending[k];
        let programmed = p.programmed()?;
        if p.segment.max_velocity.is_nan() {
            let (v, a, j) =
                self.path_limits(&Shape::Line(programmed.line), programmed.length, None);
            let segment = &mut self.pending[k].segment;
            segment.max_velocity = v;
            segment.max_acceleration = a;
            segment.max_jerk = j;
        }
        let s = &self.pending[k].segment;
        Some((s.max_velocity, s.max_acceleration, s.max_jerk))
    }

    /// Trim the first two waiting moves (lines or arcs) by the chosen
    /// blend's legs, emit the first, and emit the blend that joins them;
    /// the second keeps waiting, with where the blend ends, for the blend
    /// after it if that one takes the rest of it.
    fn blend_corner(&mut self, chosen: Chosen) {
        let legs = chosen.legs;
        // Trim a and b in place: a waiting move is over a kilobyte, and
        // copies of them showed in profiles.
        let a = &mut self.pending[0];
        let full = a.full_length();
        if let (AsProgrammed::Line(p), Shape::Line(trimmed)) = (&a.source, &mut a.segment.shape) {
            trimmed.end = std::array::from_fn(|i| p.line.end[i] - legs.0 * p.direction[i]);
        } else if let Some(arc) = a.arc() {
            let f0 = arc.sweep_fraction(a.start_leg / full);
            let f1 = arc.sweep_fraction(1.0 - legs.0 / full).max(f0);
            a.segment.shape = Shape::Arc(arc.part(f0, f1));
        }
        a.segment.length = a.segment.shape.length();
        let a_kind = a.segment.kind;
        let a_feed = a.segment.feed;
        let a_first = a.segment.moves.first;
        // Equal tangents and curvatures meet at both ends of the blend;
        // a consumed move leaves nothing (or rounding) between blends.
        if a.segment.length > 1e-9 * full.max(1.0) {
            self.release_front(f64::INFINITY);
        } else {
            self.pop_pending();
        }
        let b = self.pending.front_mut().expect("b waits");
        let full = b.full_length();
        if let (AsProgrammed::Line(p), Shape::Line(trimmed)) = (&b.source, &mut b.segment.shape) {
            trimmed.start = std::array::from_fn(|i| p.line.start[i] + legs.1 * p.direction[i]);
        } else if let Some(arc) = b.arc() {
            b.segment.shape = Shape::Arc(arc.part(arc.sweep_fraction(legs.1 / full), 1.0));
        }
        b.segment.length = b.segment.shape.length();
        b.start_leg = legs.1;
        // X Y Z only: blends join lines that move nothing else.
        b.mid = chosen.end;
        let (b_kind, b_line_number, b_feed) = (b.segment.kind, b.segment.line, b.segment.feed);
        let b_reading = b.segment.reading;
        let moves = SourceMoves {
            first: a_first,
            last: b.segment.moves.last,
        };
        let b_force = b.segment.force_control;
        // Move b's motion now starts with the blend.
        let b_outputs = std::mem::take(&mut b.segment.outputs);
        let kind = if a_kind == SegmentKind::Rapid && b_kind == SegmentKind::Rapid {
            SegmentKind::Rapid
        } else {
            SegmentKind::Feed
        };
        let (v, a, j) = chosen.limits.unwrap_or_else(|| self.blend_limits(&chosen));
        let length = chosen.blend.0.length();
        // Built where it is queued, its exit speed capped by its own
        // limit only: a blend segment is half a kilobyte, and building it
        // in steps before queuing it copied it several times.
        if length > 0.0 {
            self.ready.push_back(Segment {
                kind,
                line: b_line_number,
                moves,
                reading: b_reading,
                shape: Shape::Blend(chosen.blend.0),
                length,
                feed: a_feed.min(b_feed),
                max_velocity: v,
                max_acceleration: a,
                max_jerk: j,
                exit_velocity: v.min(f64::INFINITY),
                // The blend starts move b, so it carries b's force
                // setting, not whatever the program has set since.
                force_control: b_force,
                outputs: b_outputs,
            });
        }
    }

    /// Whether the blend with control points `control` stays where the machine
    /// can go. The programmed moves are checked (`check_shape`), but a
    /// blend leaves them by up to the tolerance, and at a corner next to
    /// the edge of the travel or of the reach that can be outside.
    ///
    /// With every joint an axis the travel is a box, so it is proven on the
    /// control points' hull, halving the curve where a hull sticks out
    /// ([`hull_in_box`]). Otherwise the reach can be any shape, and the
    /// blend is sampled, as `check_shape` samples a move: at least 8
    /// points and one every 0.25 mm of its control polygon.
    fn control_in_reach(&self, control: &[Vec9; 6]) -> bool {
        self.blend_in_reach(&control.map(|q| [q[0], q[1], q[2]]), &control[0][3..])
    }

    /// [`control_in_reach`](Self::control_in_reach) for X Y Z control
    /// points `q`, the other six axes standing at `rest`.
    fn blend_in_reach(&self, q: &[[f64; 3]; 6], rest: &[f64]) -> bool {
        if !self.sample_joints {
            return hull_in_box(q, &self.travel, SUBDIVISIONS + 2);
        }
        let polygon: f64 = (0..5)
            .map(|k| norm3(&std::array::from_fn(|i| q[k + 1][i] - q[k][i])))
            .sum();
        let n = ((polygon / 0.25).ceil() as usize).clamp(8, 64);
        let poly = Poly::new(q);
        let mut p = [0.0; 9];
        p[3..].copy_from_slice(rest);
        (1..n).all(|k| {
            p[..3].copy_from_slice(&poly.point(k as f64 / n as f64));
            self.kins.check_pose(&Position::from_array(p)).is_ok()
        })
    }

    /// The blend at the corner between the first two waiting moves when
    /// either is an arc (lines and arcs that move X Y Z only, in G64 with
    /// a finite tolerance, turning more than [`KINK`] and at most
    /// [`SHARPEST`], or tangent where the curvature jump caps the speed
    /// below the arc's own limit): its legs, its control points and the
    /// frame it ends with on `b`, if one fits.
    ///
    /// Its ends take the point, tangent and curvature of the line or arc
    /// they join, so the path stays G2-continuous; each leg is at most half
    /// its move, so blends at both ends of a move never overlap. It must be
    /// proven within the tolerance of the programmed line, or of chords of
    /// the programmed arc less how far those chords stray from it (see
    /// [`piece_near`]); the legs shrink until it is.
    fn choose_arc_blend(&self) -> Option<((f64, f64), [Vec9; 6], Frame)> {
        let (a, b) = (&self.pending[0], &self.pending[1]);
        let PathMode::Blend { tolerance } = b.mode else {
            return None;
        };
        if (a.arc().is_none() && b.arc().is_none()) || !tolerance.is_finite() {
            return None;
        }
        let (end, start) = (a.frame_in(0.0, true)?, b.frame_in(0.0, false)?);
        let bend = norm(&std::array::from_fn(|i| start.tangent[i] - end.tangent[i]));
        let mut leg = if bend > KINK && bend <= SHARPEST {
            // The leg a line–line blend would take, then shorter ones.
            tolerance / Blend::deviation(1.0, &end.tangent, &start.tangent)
        } else if bend <= KINK {
            // Tangent, but the curvature jumps: worth a transition only
            // where the jump's speed cap is below what the arc allows.
            let jump: Vec9 = std::array::from_fn(|i| start.curvature[i] - end.curvature[i]);
            let arc_speed = [a, b]
                .iter()
                .filter(|p| p.arc().is_some())
                .map(|p| p.segment.max_velocity)
                .fold(f64::INFINITY, f64::min);
            if self.curvature_jump_cap(&jump) >= arc_speed {
                return None;
            }
            // A clothoid of length L from a line into a circle of
            // curvature κ shifts the circle by L²·κ/24: a leg of L/2
            // either side for the tolerance.
            (6.0 * tolerance / norm(&jump)).sqrt()
        } else {
            return None;
        };
        let (full_a, full_b) = (a.full_length(), b.full_length());
        let spread = corner_spread(bend);
        for _ in 0..12 {
            let legs = (leg.min(full_a / 2.0), leg.min(full_b / 2.0));
            leg *= 0.7;
            if legs.0.min(legs.1) < 1e-9 {
                return None;
            }
            let (p0, p1) = (a.frame_in(legs.0, true)?, b.frame_in(legs.1, false)?);
            let scale = spread * (legs.0 + legs.1);
            let control = Blend::hermite_control(
                &p0.point,
                &p0.tangent,
                &p0.curvature,
                &p1.point,
                &p1.tangent,
                &p1.curvature,
                scale,
            );
            // The blend is shorter than its control polygon, so it stays
            // within that much path of the corner on either side.
            let reach = legs.0 + legs.1 + tolerance;
            let (mut near, sag_a) = a.near(reach, true, 0.05 * tolerance);
            let (near_b, sag_b) = b.near(reach, false, 0.05 * tolerance);
            near.extend(near_b);
            let limit = tolerance - sag_a.max(sag_b);
            let nothing = Proven::default();
            if limit > 0.0
                && sampled_within(&control, &near, limit, 0.3 * scale, &nothing)
                && self.control_in_reach(&control)
            {
                return Some((legs, control, p1));
            }
        }
        None
    }

    /// The blend at the corner between the first two waiting moves, if they
    /// are lines (`both_lines`) to blend and one fits: its legs, control
    /// points and the curvature it ends with.
    fn choose_blend(&self, both_lines: bool) -> Option<Chosen> {
        let (a, b) = (&self.pending[0], &self.pending[1]);
        let legs = if both_lines {
            self.legs(a, b)?
        } else {
            return None;
        };
        let c = self.pending.get(2).filter(|c| c.is_line());
        let legs_bc = c.and_then(|c| self.legs(b, c));
        let half = |p: &Pending| p.full_length() / 2.0;
        // Where a blend meets a line at `leg` from its start or end, with
        // no curvature.
        let on_line = |p: &Pending, leg: f64, from_end: bool| p.frame_in(leg, from_end);
        // A line is consumed when blends take both its halves; the frame
        // chosen at its midpoint is shared by both blends.
        let a_consumed = a.start_leg == half(a) && legs.0 == half(a);
        let start = if a_consumed {
            a.mid_frame()
        } else {
            on_line(a, legs.0, true)?
        };
        let into_hairpin = match (b.programmed(), c.and_then(Pending::programmed)) {
            (Some(b), Some(c)) => hairpin(b, c),
            _ => false,
        };
        let b_consumed =
            legs.1 == half(b) && legs_bc.is_some_and(|l| l.0 == half(b)) && !into_hairpin;
        // The blend worker's, if it made it from this start: on a dense
        // curve, from a's fitted midpoint or from a corner's leg on a, or
        // at a corner from a leg on a (not from a's midpoint into a
        // corner, which it leaves). It leaves the reach to be checked.
        let worked = self
            .ahead
            .as_ref()
            .and_then(|ahead| ahead.take(self.released + 1, &xyz_frame(&start), legs, legs_bc));
        if let (true, Some(c), Some(legs_bc)) = (b_consumed, c, legs_bc) {
            let c_start = on_line(c, legs_bc.1, false)?;
            // The blend into `mid`, if both it and the one out of it fit.
            let through = |mid: Frame| {
                let bl = self.blend_within(a, b, legs, &start, &mid)?;
                self.blend_within(b, c, legs_bc, &mid, &c_start)?;
                #[cfg(test)]
                self.worked_here();
                Some(Chosen::new(legs, &bl, &mid))
            };
            // Else b's midpoint with (a share of) the curvature its two
            // vertices give, if in reach.
            let vertices = || {
                let (pa, pb, pc) = (a.programmed()?, b.programmed()?, c.programmed()?);
                let (PathMode::Blend { tolerance: tol_b }, PathMode::Blend { tolerance: tol_c }) =
                    (b.mode, c.mode)
                else {
                    return None;
                };
                let (mid, ab, bc) =
                    vertex_midpoint(pa, pb, pc, legs, legs_bc, &start, tol_b, tol_c)?;
                if !(self.control_in_reach(&ab) && self.control_in_reach(&bc)) {
                    return None;
                }
                #[cfg(test)]
                self.worked_here();
                Some(Chosen::new(legs, &ab, &mid))
            };
            let in_reach = |ab: &(Blend, BlendExtremes), bc: &[[f64; 3]; 6]| {
                self.blend_in_reach(&ab.0.control, &ab.0.rest)
                    && self.blend_in_reach(bc, &ab.0.rest)
            };
            let chosen = if let Some(Speculation {
                worked: Worked::Dense { fit, bc, fallback },
                sampled,
                ..
            }) = worked.as_deref()
            {
                match (fit, bc, fallback, sampled) {
                    (Some(mid), Some(bc), _, Some(ab)) if in_reach(ab, bc) => {
                        Some(Chosen::worked(legs, ab, *mid))
                    }
                    // The fit's blends are out of reach: the fallback is
                    // still to be tried.
                    (_, Some(_), _, _) => vertices(),
                    (_, None, Fallback::Within { mid, bc }, Some(ab)) => {
                        in_reach(ab, bc).then(|| Chosen::worked(legs, ab, *mid))
                    }
                    _ => None,
                }
            } else {
                self.fitted_mid().and_then(through).or_else(vertices)
            };
            if chosen.is_some() {
                return chosen;
            }
        }
        // Zero curvature at b's end. With the start fixed the legs are too
        // (a's midpoint is shared); otherwise shrink them until the blend
        // is within tolerance.
        let end = |legs: (f64, f64)| on_line(b, legs.1, false);
        if let Some(Speculation {
            worked:
                Worked::Corner {
                    chosen,
                    from_midpoint,
                },
            sampled,
            ..
        }) = worked.as_deref()
        {
            // Only if made for the tries this corner gets.
            match (chosen, sampled, *from_midpoint == a_consumed) {
                (_, _, false) => {}
                // The first legs whose blend is within the tolerance, if
                // in reach; else what comes after them is to be tried.
                (Some(legs), Some(s), true) if self.blend_in_reach(&s.0.control, &s.0.rest) => {
                    return Some(Chosen::worked(*legs, s, xyz_frame(&end(*legs)?)));
                }
                (Some(_), _, true) => {}
                // None of the legs gives a blend within the tolerance.
                (None, _, true) => return None,
            }
        }
        let tries = if a_consumed { 1 } else { CORNER_TRIES };
        for legs in corner_legs(legs).take(tries) {
            let from = if a_consumed {
                start
            } else {
                on_line(a, legs.0, true)?
            };
            let to = end(legs)?;
            if let Some(control) = self.blend_within(a, b, legs, &from, &to) {
                #[cfg(test)]
                self.worked_here();
                return Some(Chosen::new(legs, &control, &to));
            }
        }
        None
    }

    /// Tell the blend worker's tally that the planner worked out the blend
    /// at the first two waiting moves itself (tests only).
    #[cfg(test)]
    fn worked_here(&self) {
        if let Some(ahead) = &self.ahead {
            ahead.worked_here(self.released + 1);
        }
    }

    /// Speed cap where `a` meets `b` without a blend: straight or tangent
    /// junctions go through at the speed that keeps the curvature jump
    /// within the jerk limit over one period; corners stop.
    fn junction(&self, a: &Pending, b: &Pending) -> f64 {
        if b.mode == PathMode::ExactStop {
            return 0.0;
        }
        let end = a.segment.shape.frame(a.segment.length);
        let start = b.segment.shape.frame(0.0);
        let bend = norm(&std::array::from_fn(|i| start.tangent[i] - end.tangent[i]));
        let limit = if a.is_line() && b.is_line() {
            STRAIGHT
        } else {
            KINK
        };
        if bend > limit {
            return 0.0;
        }
        let jump: Vec9 = std::array::from_fn(|i| start.curvature[i] - end.curvature[i]);
        self.curvature_jump_cap(&jump)
    }

    /// A segment of `shape` with its path limits.
    fn segment(&self, kind: SegmentKind, line: u32, shape: Shape) -> Segment {
        self.segment_sampled(kind, line, shape, None)
    }

    /// A segment of `shape` whose path limits are still to be worked out
    /// (NaN) by [`release_front`](Self::release_front).
    fn segment_unlimited(&self, kind: SegmentKind, line: u32, shape: Shape) -> Segment {
        let feed = match kind {
            SegmentKind::Feed => self.feed(),
            _ => f64::INFINITY,
        };
        Segment {
            kind,
            line,
            moves: self.moves,
            reading: self.reading,
            shape,
            length: shape.length(),
            feed,
            max_velocity: f64::NAN,
            max_acceleration: f64::NAN,
            max_jerk: f64::NAN,
            exit_velocity: 0.0,
            force_control: self.force_control,
            outputs: SyncOutputs::default(),
        }
    }

    /// Emit the first waiting move with junction speed cap `exit`, with
    /// its limits if still due (lines: from the line as programmed, since
    /// trimming does not turn it). Copied once, straight into the ready
    /// queue, and finished there.
    fn release_front(&mut self, exit: f64) {
        if self.pending[0].segment.length > 0.0 {
            // A line's limits, worked out in place if still due.
            self.line_limits(0);
            self.ready.push_back(self.pending[0].segment);
            let segment = self.ready.back_mut().expect("just pushed");
            segment.exit_velocity = segment.max_velocity.min(exit);
        }
        self.pop_pending();
    }

    /// [`segment`](Self::segment) with a blend's extremes, if known.
    fn segment_sampled(
        &self,
        kind: SegmentKind,
        line: u32,
        shape: Shape,
        extremes: Option<&BlendExtremes>,
    ) -> Segment {
        let length = shape.length();
        let feed = match kind {
            SegmentKind::Feed => self.feed(),
            _ => f64::INFINITY,
        };
        let (v, a, j) = self.path_limits(&shape, length, extremes);
        Segment {
            kind,
            line,
            moves: self.moves,
            reading: self.reading,
            shape,
            length,
            feed,
            max_velocity: v,
            max_acceleration: a,
            max_jerk: j,
            exit_velocity: 0.0,
            force_control: self.force_control,
            outputs: SyncOutputs::default(),
        }
    }

    /// Path speed, acceleration and jerk limits along `shape` such that
    /// every axis and joint stays within its limits.
    ///
    /// Along a line, axis i moves at t_i times the path motion, so each limit
    /// divides by |t_i|. On a curve, axis acceleration is a·t_i + v²·κ_i and
    /// axis jerk is j·t_i + 3·a·v·κ_i + v³·κ'_i. The speed limit comes
    /// first, with the centripetal and rate terms taking up to
    /// [`PlannerConfig::centripetal_share`] and
    /// [`PlannerConfig::jerk_rate_share`] of each budget; the tangential
    /// terms get what that speed leaves, which bounds each sum by the limit.
    ///
    /// `extremes` are a blend's ([`Blend::sampled`]) when the caller has them.
    fn path_limits(
        &self,
        shape: &Shape,
        length: f64,
        extremes: Option<&BlendExtremes>,
    ) -> (f64, f64, f64) {
        let (mut v, mut a, mut j) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        // Largest |t_i|, |κ_i| and |dκ_i/ds| over the shape.
        let mut t_max = [0.0f64; 9];
        let mut k_max = [0.0f64; 9];
        let mut dk_max = [0.0f64; 9];
        match shape {
            Shape::Line(l) => {
                let t = l.direction();
                for i in 0..9 {
                    t_max[i] = t[i].abs();
                }
            }
            Shape::Arc(arc) => {
                // The other axes move in proportion to the path: their
                // tangent is constant.
                let f = shape.frame(0.0);
                let (in_plane, bend, rate) = arc_extremes(arc, length);
                for i in 0..9 {
                    if i == arc.plane.0 || i == arc.plane.1 {
                        t_max[i] = in_plane;
                        k_max[i] = bend;
                        dk_max[i] = rate;
                    } else {
                        t_max[i] = f.tangent[i].abs();
                    }
                }
            }
            Shape::Blend(b) => {
                // 32 samples for |t_i| and |κ_i|; |dκ_i/ds| exact at 65
                // with an allowance for crests between them (see
                // `BlendExtremes::curvature_rate`).
                let owned;
                let extremes = match extremes {
                    Some(extremes) => extremes,
                    None => {
                        owned = Blend::sampled(b.control_points()).1;
                        &owned
                    }
                };
                k_max[..3].copy_from_slice(&extremes.curvature);
                // A tangent component peaks between samples by at most
                // |dκ/ds|·(Δs/2)²/2 (its slope κ is zero at the peak); the
                // samples are at most about length/16 apart.
                let half_gap = length / 32.0;
                for i in 0..3 {
                    dk_max[i] = extremes.curvature_rate[i];
                    t_max[i] =
                        (extremes.tangent[i] + dk_max[i] * half_gap * half_gap / 2.0).min(1.0);
                }
            }
        }
        let curved = !matches!(shape, Shape::Line(_));
        // The speed limit first: the centripetal and curvature-rate terms
        // may take up to their shares of each axis's budget. Roots are
        // monotonic: one root of the least radicand over the axes gives the
        // least root (cube roots are slow).
        let (mut centripetal, mut rate) = (f64::INFINITY, f64::INFINITY);
        for i in 0..9 {
            let Some(l) = self.limits[i] else { continue };
            if t_max[i] > 0.0 {
                v = v.min(l.max_velocity / t_max[i]);
            }
            if k_max[i] > 0.0 {
                centripetal =
                    centripetal.min(self.config.centripetal_share * l.max_acceleration / k_max[i]);
            }
            if dk_max[i] > 0.0 && l.max_jerk.is_finite() {
                rate = rate.min(self.config.jerk_rate_share * l.max_jerk / dk_max[i]);
            }
        }
        if centripetal.is_finite() {
            v = v.min(centripetal.sqrt());
        }
        if rate.is_finite() {
            v = v.min(rate.cbrt());
        }
        // Then whatever the speed limit leaves of each budget, at that
        // speed, is for speeding up and slowing down along the path: the
        // tangential a·t_i gets the acceleration, and the tangential j·t_i
        // and the coupling 3·a·v·κ_i half the jerk each. Below the speed
        // limit the curve takes less, so the sums stay within the limits.
        for i in 0..9 {
            let Some(l) = self.limits[i] else { continue };
            let (a_left, j_left) = if !curved {
                (l.max_acceleration, l.max_jerk)
            } else if v.is_finite() {
                (
                    l.max_acceleration - v * v * k_max[i],
                    (l.max_jerk - v * v * v * dk_max[i]) / 2.0,
                )
            } else {
                (
                    (1.0 - self.config.centripetal_share) * l.max_acceleration,
                    (1.0 - self.config.jerk_rate_share) / 2.0 * l.max_jerk,
                )
            };
            let (a_left, j_left) = (a_left.max(0.0), j_left.max(0.0));
            if t_max[i] > 0.0 {
                a = a.min(a_left / t_max[i]);
                j = j.min(j_left / t_max[i]);
            }
            if k_max[i] > 0.0 && l.max_jerk.is_finite() && v.is_finite() && v > 0.0 {
                a = a.min(j_left / (3.0 * v * k_max[i]));
            }
        }
        if self.sample_joints {
            let b = self.joint_limits(shape, length);
            v = v.min(b.v);
            a = a.min(b.a);
            if self.config.jerk_limited {
                j = j.min(b.j);
                if v.is_finite() && v > 0.0 {
                    a = a.min(b.av / v);
                }
            }
        }
        (v, a, j)
    }

    /// Limits on path speed, acceleration and jerk from the joints, from
    /// q′ = dq/ds, q″ and q‴ sampled through the kinematics on 5-point
    /// stencils. Joint speed is q′·v, acceleration q′·a + q″·v², jerk
    /// q′·j + 3·q″·v·a + q‴·v³; the budgets are split (halves, thirds) so
    /// each sum stays within the joint's limit. Between samples a derivative
    /// can grow by the next one times half the sample spacing: the bounds
    /// add that rather than trust the samples.
    fn joint_limits(&self, shape: &Shape, length: f64) -> JointBounds {
        let joints = self.kins.joints();
        let n = joints.len();
        // A blend's curvature rate, which the joints' jerk follows, swings
        // within its length: at least 16 samples there.
        let fewest = if matches!(shape, Shape::Blend(_)) {
            16
        } else {
            3
        };
        let samples = ((length / 2.0).ceil() as usize).clamp(fewest, 64);
        let spacing = length / samples as f64;
        let h = (spacing / 4.0).clamp(1e-6, JOINT_STENCIL).min(length / 4.0);
        let mut b = JointBounds::default();
        for k in 0..=samples {
            // A symmetric stencil inside the segment: at its ends a clamped
            // stencil would mix up the differences.
            let s = (length * k as f64 / samples as f64)
                .clamp(2.0 * h, (length - 2.0 * h).max(2.0 * h));
            let mut q = [[0.0; MAX_JOINTS]; 5];
            let ok = (0..5).all(|m| {
                let at = (s + (m as f64 - 2.0) * h).clamp(0.0, length);
                self.kins
                    .inverse(&Position::from_array(shape.point(at)), &mut q[m][..n])
                    .is_ok()
            });
            if !ok || h <= 0.0 {
                continue;
            }
            for (jn, spec) in joints.iter().enumerate() {
                let d1 = (q[3][jn] - q[1][jn]) / (2.0 * h);
                let d2 = (q[3][jn] - 2.0 * q[2][jn] + q[1][jn]) / (h * h);
                let d3 =
                    (q[4][jn] - 2.0 * q[3][jn] + 2.0 * q[1][jn] - q[0][jn]) / (2.0 * h * h * h);
                let d4 = (q[4][jn] - 4.0 * q[3][jn] + 6.0 * q[2][jn] - 4.0 * q[1][jn] + q[0][jn])
                    / (h * h * h * h);
                // The central differences read low by q‴·h²/6 and q⁗·h²/12
                // (on an arc of radius r, by (h/r)²/6 of the speed: 0.1 %
                // at h = r/13, which let a joint run 1.0005 times its
                // limit); the next differences bound that.
                let d1 = d1.abs() + d3.abs() * h * h / 6.0 + d2.abs() * spacing / 2.0;
                let d2 = d2.abs() + d4.abs() * h * h / 12.0 + d3.abs() * spacing / 2.0;
                let d3 = d3.abs() + d4.abs() * spacing / 2.0;
                let l = spec.limits;
                if d1 > 0.0 {
                    b.v = b.v.min(l.max_velocity / d1);
                    b.a = b.a.min(0.5 * l.max_acceleration / d1);
                    b.j = b.j.min(l.max_jerk / 3.0 / d1);
                }
                if d2 > 1e-12 {
                    b.v = b.v.min((0.5 * l.max_acceleration / d2).sqrt());
                    b.av = b.av.min(l.max_jerk / 9.0 / d2);
                }
                if d3 > 1e-12 && l.max_jerk.is_finite() {
                    b.v = b.v.min((l.max_jerk / 3.0 / d3).cbrt());
                }
            }
        }
        b
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
    use crate::offline::{self, RunConfig};
    use crate::testkit::xyz;
    use kerf_interp::Interpreter;

    fn plan(kins: &dyn Kinematics, config: PlannerConfig, text: &str) -> Vec<Segment> {
        let mut p = Planner::new(kins, Position::ZERO, config);
        for c in Interpreter::from_text(text, "t.ngc", Position::ZERO) {
            p.plan(&c.unwrap()).unwrap();
        }
        p.finish();
        std::iter::from_fn(|| p.next_segment()).collect()
    }

    /// X Y Z that cannot reach within `hole` mm of X50 Y0 (a column on the
    /// table): a reach that is not convex, and joints the planner must
    /// sample through the inverse kinematics.
    struct Column {
        xyz: crate::testkit::Xyz,
        hole: f64,
    }

    impl Kinematics for Column {
        fn name(&self) -> &str {
            "column"
        }
        fn axes(&self) -> &[crate::kinematics::AxisSpec] {
            self.xyz.axes()
        }
        fn joints(&self) -> &[crate::kinematics::JointSpec] {
            self.xyz.joints()
        }
        fn inverse(&self, p: &Position, q: &mut [f64]) -> Result<(), crate::KinematicsError> {
            if (p.x - 50.0).hypot(p.y) < self.hole {
                return Err(crate::KinematicsError::Unreachable {
                    reason: "inside the column",
                });
            }
            self.xyz.inverse(p, q)
        }
        fn forward(&self, q: &[f64], seed: &Position) -> Result<Position, crate::KinematicsError> {
            self.xyz.forward(q, seed)
        }
    }

    #[test]
    fn a_collinear_merge_never_cuts_through_what_the_machine_cannot_reach() {
        // Moves of 0.05 mm along an arc 0.02 mm outside a column of radius
        // 10. Under Q0.05 chords over up to 0.2 rad would merge, but any
        // over 0.13 rad dips into the column, though every move is clear:
        // the merge must stop short of them, and planning must not fail.
        let kins = Column {
            xyz: xyz(100.0, 1000.0, 50_000.0),
            hole: 10.0,
        };
        let r = 10.02;
        let x = 50.0 + r;
        let mut text = format!("G21 G90 G64 P0.01 Q0.05\nG0 X{x} Y-30\nY0\nG1 F1000\n");
        let steps = 120;
        for k in 1..=steps {
            let a = k as f64 * 0.005;
            text += &format!("X{:.6} Y{:.6}\n", 50.0 + r * a.cos(), r * a.sin());
        }
        text += "M2\n";
        let segs = plan(&kins, PlannerConfig::default(), &text);
        let moves = segs.iter().filter(|s| s.is_motion()).count();
        assert!(
            moves < steps / 3,
            "merging happened: {moves} segments for {steps} moves"
        );
        assert_clear_of_column(&segs, "Q0.05");
    }

    /// Every planned segment, sampled 257 times, stays out of `Column`'s
    /// hole of radius 10.
    fn assert_clear_of_column(segs: &[Segment], what: &str) {
        for seg in segs.iter().filter(|s| s.is_motion()) {
            for k in 0..=256 {
                let p = seg.position_at(seg.length * k as f64 / 256.0);
                let from_axis = (p.x - 50.0).hypot(p.y);
                assert!(
                    from_axis >= 10.0 - 1e-9,
                    "{what}: line {} passes {from_axis:.5} mm from the column's axis",
                    seg.line
                );
            }
        }
    }

    /// Blends cut a corner by up to the tolerance, and only the programmed
    /// moves are checked against the machine's reach: at a corner 0.002 mm
    /// from the column, with the column on the side the blend cuts toward,
    /// the blend must come out smaller, not pass through the column.
    #[test]
    fn blends_never_cut_into_what_the_machine_cannot_reach() {
        let kins = Column {
            xyz: xyz(100.0, 1000.0, 50_000.0),
            hole: 10.0,
        };
        // The corner at (vx, 0) turns by 0.5°; the line in stays 10.0016
        // mm from the column's axis, the line out likewise and the arc out
        // 10.002 mm, all round the column.
        let vx = 50.0 - 10.002;
        let (sin, cos) = 0.5f64.to_radians().sin_cos();
        let into = format!(
            "G21 G90 G64 P0.01\nG0 X{:.6} Y{:.6}\nG1 F1000 X{vx} Y0\n",
            vx + 30.0 * sin,
            -30.0 * cos
        );
        let out = [
            format!("X{:.6} Y{:.6}", vx + 30.0 * sin, 30.0 * cos),
            "G2 X50 Y10.002 I10.002 J0".to_string(),
        ];
        for out in out {
            let text = format!("{into}{out}\nM2\n");
            let segs = plan(&kins, PlannerConfig::default(), &text);
            let at_corner = segs
                .iter()
                .filter(|s| {
                    matches!(s.shape, Shape::Blend(_))
                        && (s.start().x - vx).hypot(s.start().y) < 5.0
                })
                .count();
            assert_eq!(at_corner, 1, "{out}: the corner is blended, closer in");
            assert_clear_of_column(&segs, &out);
        }
    }

    /// On a machine whose joints are its axes the travel is a box. Lines
    /// that run into quarter arcs starting on the edge of the travel (at
    /// X1000, heading +Y): the blends' control polygons stick out past the
    /// edge there, the blends do not, and every corner still blends (the
    /// rapid's too: stopping there is quicker, but it is the shapes under
    /// test here).
    #[test]
    fn corners_on_the_edge_of_the_travel_still_blend_inside_it() {
        let k = xyz(100.0, 1000.0, 50_000.0);
        let config = PlannerConfig {
            stop_when_quicker: false,
            ..PlannerConfig::default()
        };
        let mut text = "G21 G90 G64 P0.05\nG0 X990 Y0\nG1 F3000\n".to_string();
        for n in 0..5 {
            let y = 20.0 * n as f64;
            text += &format!("X1000 Y{}\nG3 X990 Y{} I-10 J0\nG1\n", y + 10.0, y + 20.0);
        }
        text += "M2\n";
        let segs = plan(&k, config, &text);
        let blends = segs
            .iter()
            .filter(|s| matches!(s.shape, Shape::Blend(_)))
            .count();
        assert_eq!(blends, 10, "one blend per corner, the rapid's included");
        for seg in segs.iter().filter(|s| s.is_motion()) {
            for k in 0..=256 {
                let p = seg.position_at(seg.length * k as f64 / 256.0);
                assert!(p.x <= 1000.0 + 1e-9, "line {} reaches X{}", seg.line, p.x);
            }
        }
    }

    /// `hull_in_box` is a proof: on random quintics near the edge of a box
    /// it never accepts one that a dense sample finds outside, and it
    /// accepts most of those that stay clear of the edge.
    #[test]
    fn hull_in_box_never_accepts_a_curve_that_leaves_the_box() {
        let travel = [(0.0, 10.0), (0.0, 10.0), (-5.0, 5.0)];
        let mut rand = crate::testkit::uniform(0x5eed_b0c5);
        let (mut clear, mut proven) = (0, 0);
        for _ in 0..4000 {
            // Control points around the X = 10 face, up to 0.05 mm past it.
            let q: [Vec9; 6] = std::array::from_fn(|_| {
                let mut p = [0.0; 9];
                p[0] = 9.9 + 0.15 * rand();
                p[1] = 4.0 + 2.0 * rand();
                p[2] = -1.0 + 2.0 * rand();
                p
            });
            let points: [[f64; 3]; 6] = std::array::from_fn(|k| [q[k][0], q[k][1], q[k][2]]);
            let poly = Poly::new(&q);
            let most = (0..=2000)
                .map(|k| poly.point(k as f64 / 2000.0)[0])
                .fold(f64::NEG_INFINITY, f64::max);
            let accepted = hull_in_box(&points, &travel, SUBDIVISIONS + 2);
            assert!(
                !accepted || most <= 10.0 + LIMIT_SLACK,
                "accepted a curve reaching X{most}"
            );
            if most < 10.0 - 1e-4 {
                clear += 1;
                proven += accepted as usize;
            }
        }
        assert!(clear > 100, "{clear} clear curves");
        assert!(
            proven as f64 >= 0.95 * clear as f64,
            "proved {proven} of {clear} clear curves"
        );
    }

    #[test]
    fn hull_bounds_never_contradict_the_sampled_blend_test() {
        // Corners of every sharpness, unequal legs and end curvatures: the
        // fast test must never accept a blend the sampled test rejects, and
        // should accept the comfortable ones.
        let mut rand = crate::testkit::uniform(0x2545_f491_4f6c_dd1d);
        let xyz = |x: f64, y: f64, z: f64| [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (mut fast, mut sampled) = (0, 0);
        for _ in 0..50_000 {
            let (th, tilt) = (rand() * 2.6, rand() - 0.5);
            let n = (1.0 + tilt * tilt).sqrt();
            let corner = xyz(150.0, 100.0, -20.0);
            let u1 = xyz(1.0, 0.0, 0.0);
            let u2 = xyz(th.cos() / n, th.sin() / n, tilt / n);
            let (len_a, len_b) = (0.01 + rand() * 4.0, 0.01 + rand() * 4.0);
            let la = Line {
                start: std::array::from_fn(|i| corner[i] - len_a * u1[i]),
                end: corner,
            };
            let lb = Line {
                start: corner,
                end: std::array::from_fn(|i| corner[i] + len_b * u2[i]),
            };
            let legs = (rand() * len_a / 2.0, rand() * len_b / 2.0);
            let k = (rand() - 0.5) * 4.0;
            let control = Blend::hermite_control(
                &std::array::from_fn(|i| corner[i] - legs.0 * u1[i]),
                &u1,
                &xyz(0.0, k, 0.0),
                &std::array::from_fn(|i| corner[i] + legs.1 * u2[i]),
                &u2,
                &xyz(-k * u2[1], k * u2[0], 0.0),
                legs.0 + legs.1,
            );
            let tolerance = 0.001 + rand() * 0.05;
            let min_speed = 0.3 * (legs.0 + legs.1);
            let (la, lb) = (Near::new(&la), Near::new(&lb));
            let proven = hull_bounds(&control, &la, &lb, tolerance, min_speed);
            let sure = proven.all();
            let nothing = Proven::default();
            let ok = sampled_within(&control, &[la, lb], tolerance, min_speed, &nothing);
            assert!(
                ok || !sure,
                "fast test accepted a failing blend: {control:?}"
            );
            // What the bounds prove the samples would confirm: skipping it
            // changes no decision.
            let skipping = sampled_within(&control, &[la, lb], tolerance, min_speed, &proven);
            assert_eq!(ok, skipping, "{proven:?} {control:?}");
            fast += sure as usize;
            sampled += ok as usize;
        }
        // Random legs are mostly near their tolerance; real paths fare
        // better (nearly every blend on a dense curve).
        assert!(fast > sampled / 10, "fast {fast} of {sampled}");
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
            source: Source::new("t", 1),
            cmd: CanonCmd::SetFeedRate {
                mm_per_min: 60000.0,
            },
        };
        p.plan(&canon).unwrap();
        let arc = Arc {
            plane: (0, 1),
            center: (0.0, 0.0),
            radius: 10.0,
            end_radius: 10.0,
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

    /// `line_time` against a simulation: the speed taken up from `at` and
    /// back down again by integrating the jerk-limited ramp in steps of
    /// at most 10 µs (full jerk until the acceleration limit, easing off at
    /// full jerk from the step where what is left of the speed change
    /// equals a²/2J, found within its step), the peak found by bisection on
    /// the distance, a cruise at the top speed where the length leaves one.
    /// Short lines that never reach the acceleration limit, long ones that
    /// do, ones that cruise; from rest and from a blend's speed; and
    /// trapezoidal profiles (no jerk limit).
    #[test]
    fn line_time_matches_a_simulated_s_curve() {
        const STEP: f64 = 1e-5;
        // Time and distance to raise the speed by dv from `at`, starting
        // and ending with no acceleration.
        let ramp = |at: f64, dv: f64, accel: f64, jerk: f64| {
            if jerk.is_infinite() {
                return (dv / accel, (2.0 * at + dv) / 2.0 * dv / accel);
            }
            let (mut t, mut d, mut v, mut a) = (0.0, 0.0, at, 0.0f64);
            let mut easing = false;
            loop {
                let left = at + dv - v;
                let (j, h) = if easing {
                    (-jerk, STEP.min(a / jerk))
                } else {
                    // Where easing must start within the step: from a,
                    // left − a·h − ½·j·h² = (a + j·h)²/2J.
                    let (j, h, switch) = if a < accel {
                        let switch = ((a * a / 2.0 + jerk * left).sqrt() - a) / jerk;
                        (jerk, STEP.min((accel - a) / jerk), switch)
                    } else {
                        (0.0, STEP, (left - accel * accel / (2.0 * jerk)) / accel)
                    };
                    if switch <= h {
                        easing = true;
                        (j, switch.max(0.0))
                    } else {
                        (j, h)
                    }
                };
                if easing && h <= 0.0 && a <= 0.0 {
                    return (t, d);
                }
                d += v * h + a * h * h / 2.0 + j * h * h * h / 6.0;
                v += a * h + j * h * h / 2.0;
                a += j * h;
                t += h;
            }
        };
        let simulated = |length: f64, at: f64, top: f64, accel: f64, jerk: f64| {
            let (t, d) = ramp(at, top - at, accel, jerk);
            if 2.0 * d <= length {
                return 2.0 * t + (length - 2.0 * d) / top;
            }
            let (mut lo, mut hi) = (0.0, top - at);
            for _ in 0..40 {
                let mid = (lo + hi) / 2.0;
                if 2.0 * ramp(at, mid, accel, jerk).1 > length {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            2.0 * ramp(at, lo, accel, jerk).0
        };
        for jerk in [75_000.0, f64::INFINITY] {
            for at in [0.0, 7.7, 25.0] {
                for length in [0.05, 0.5, 3.0, 50.0] {
                    let (top, accel) = (50.0, 1500.0);
                    let want = simulated(length, at, top, accel, jerk);
                    let got = line_time(length, at, top, accel, jerk);
                    assert!(
                        (got - want).abs() <= 1e-6 * want,
                        "{length} mm from {at} mm/s, jerk {jerk}: {got} s, simulated {want} s"
                    );
                }
            }
        }
        assert_eq!(line_time(0.0, 10.0, 50.0, 1500.0, 75_000.0), 0.0);
    }

    /// `arc_extremes` bounds the first three derivatives of the plane
    /// axes in arc length, checked by finite differences of the points the
    /// executor follows (`Shape::point`) on spirals from nearly circles to
    /// radii that triple.
    #[test]
    fn arc_extremes_bound_the_derivatives_of_the_plane_axes() {
        let mut r = crate::testkit::uniform(7);
        for _ in 0..200 {
            let r0 = 0.01 + 20.0 * r();
            let r1 = r0
                * (1.0 + [0.0, 1e-5, 0.01, 0.5, 2.0][(5.0 * r()) as usize % 5] * (2.0 * r() - 1.0));
            let sweep = (0.1 + 6.0 * r()) * if r() < 0.5 { 1.0 } else { -1.0 };
            let arc = Arc {
                plane: (0, 1),
                center: (0.0, 0.0),
                radius: r0,
                end_radius: r1,
                start_angle: 6.0 * r(),
                sweep,
                start: [0.0; 9],
                end: [0.0; 9],
            };
            let length = arc.length();
            let (t, k, dk) = arc_extremes(&arc, length);
            // Derivatives in s at interior fractions, by central
            // differences of step h (in s).
            let h = length * 1e-3;
            let at = |s: f64| Shape::Arc(arc).point(s);
            for n in 1..100 {
                let s0 = length * n as f64 / 100.0;
                for i in 0..2 {
                    let p = |s: f64| at(s)[i];
                    let d1 = (p(s0 + h) - p(s0 - h)) / (2.0 * h);
                    let d2 = (p(s0 + h) - 2.0 * p(s0) + p(s0 - h)) / (h * h);
                    let d3 = (p(s0 + 2.0 * h) - 2.0 * p(s0 + h) + 2.0 * p(s0 - h)
                        - p(s0 - 2.0 * h))
                        / (2.0 * h * h * h);
                    assert!(
                        d1.abs() <= t * (1.0 + 1e-4),
                        "{r0} {r1} {sweep}: {d1} > {t}"
                    );
                    assert!(
                        d2.abs() <= k * (1.0 + 1e-3),
                        "{r0} {r1} {sweep}: {d2} > {k}"
                    );
                    assert!(
                        d3.abs() <= dk * (1.0 + 1e-2),
                        "{r0} {r1} {sweep}: {d3} > {dk}"
                    );
                }
            }
        }
    }

    /// Plans `text` and runs it offline on `k` under G64 P`tolerance`;
    /// returns the segments and the run's (largest deviation from the
    /// programmed path, largest limit use).
    fn planned_and_run(k: &dyn Kinematics, tolerance: f64, text: &str) -> (Vec<Segment>, f64, f64) {
        let config = PlannerConfig {
            mode: PathMode::Blend { tolerance },
            ..Default::default()
        };
        planned_and_run_with(k, config, text)
    }

    /// [`planned_and_run`] under `config`.
    fn planned_and_run_with(
        k: &dyn Kinematics,
        config: PlannerConfig,
        text: &str,
    ) -> (Vec<Segment>, f64, f64) {
        let segs = plan(k, config, text);
        let report = crate::offline::run(
            Interpreter::from_text(text, "t.ngc", Position::ZERO),
            k,
            Position::ZERO,
            crate::offline::RunConfig {
                planner: config,
                record: 0,
                follow: None,
            },
        )
        .unwrap();
        (segs, report.max_deviation, report.max_limit_ratio())
    }

    /// `text` planned under G61 (exact path).
    fn plan_exact_path(k: &dyn Kinematics, text: &str) -> Vec<Segment> {
        let config = PlannerConfig {
            mode: PathMode::ExactPath,
            ..Default::default()
        };
        plan(k, config, text)
    }

    /// Frames on both sides of each junction between motion segments:
    /// (largest tangent step, largest curvature step).
    fn junction_steps(segs: &[Segment]) -> (f64, f64) {
        segs.windows(2)
            .filter(|w| w[0].is_motion() && w[1].is_motion())
            .fold((0.0, 0.0), |(t, k), w| {
                let (a, b) = (w[0].shape.frame(w[0].length), w[1].shape.frame(0.0));
                let dt = norm(&std::array::from_fn(|i| b.tangent[i] - a.tangent[i]));
                let dk = norm(&std::array::from_fn(|i| b.curvature[i] - a.curvature[i]));
                (t.max(dt), k.max(dk))
            })
    }

    /// Six corners where arcs meet lines or arcs at 90°: line into arc and
    /// arc into line in XY, arc into arc, an arc in XZ (G18), a helix. Under
    /// G64 P each gets a blend that joins with the tangent and curvature
    /// of what it meets, so the tool does not stop until the end; the run
    /// stays within P of the programmed path (measured on the executed
    /// trajectory against the arcs as programmed) and within every limit.
    /// Under G61 the same corners stop.
    #[test]
    fn arc_corners_blend_g2_continuously_within_tolerance() {
        let k = xyz(200.0, 1000.0, 5e4);
        // (10,0) heading +X into a CW arc that starts heading +Y; it ends
        // at (20,0) heading −Y into a line heading +X; a CCW arc starting
        // heading −Y ends at (40,0) heading +Y into a CW arc starting
        // heading −X; it ends at (40,10) heading +X; an XZ arc starts
        // heading −Z... then a helix quarter turn and a line.
        let text = "G21 G17 G90 G1 X10 F3000\nG2 X20 R5\nG1 X30\nG3 X40 R5\nG2 Y10 R5\n\
                    G18 G2 X50 Z0 R5\nG17 G1 X55\nG3 X60 Y15 Z-2 R5\nG1 X50\nM2\n";
        for tolerance in [0.005, 0.05, 0.5] {
            let (segs, deviation, limits) = planned_and_run(&k, tolerance, text);
            let blends = segs
                .iter()
                .filter(|s| matches!(s.shape, Shape::Blend(_)))
                .count();
            assert_eq!(blends, 8, "P{tolerance}: one blend per corner");
            let motion: Vec<&Segment> = segs.iter().filter(|s| s.is_motion()).collect();
            let stops = motion[..motion.len() - 1]
                .iter()
                .filter(|s| s.exit_velocity == 0.0)
                .count();
            assert_eq!(stops, 0, "P{tolerance}: no stop before the end");
            let (dt, dk) = junction_steps(&segs);
            assert!(dt < 1e-9 && dk < 1e-6, "P{tolerance}: steps {dt} {dk}");
            assert!(
                deviation <= tolerance * (1.0 + 1e-9),
                "P{tolerance}: deviation {deviation}"
            );
            assert!(
                deviation > 0.3 * tolerance,
                "P{tolerance}: the blends should use the tolerance, deviation {deviation}"
            );
            assert!(limits <= 1.0 + 1e-6, "P{tolerance}: limit use {limits}");
            let end = motion.last().unwrap().end();
            assert!(
                (end.x - 50.0).abs() < 1e-12
                    && (end.y - 15.0).abs() < 1e-12
                    && (end.z + 2.0).abs() < 1e-12
            );
        }
        let exact = plan_exact_path(&k, text);
        let stops = exact
            .iter()
            .filter(|s| s.is_motion() && s.exit_velocity == 0.0)
            .count();
        assert_eq!(stops, 9, "G61: a stop at each of 8 corners and the end");
    }

    /// Five tangent junctions where the curvature jumps (line into arc,
    /// arc into line, and an S-bend where it reverses): under G61 each
    /// holds the speed to √(J·T/|Δκ|) (15.8 and 11.2 mm/s here); under
    /// G64 P a G2 transition replaces each, the tool passes at over 1.5
    /// times that, and the run stays within P and the limits.
    #[test]
    fn tangent_arc_junctions_get_transitions_instead_of_the_jump_cap() {
        let k = xyz(200.0, 1000.0, 5e4);
        let text = "G21 G17 G90 G1 X20 F6000\nG3 X25 Y5 I0 J5\nG1 Y15\nG2 X30 Y20 I5 J0\n\
                    G3 X35 Y25 I0 J5\nG1 Y35\nM2\n";
        let exact = plan_exact_path(&k, text);
        let caps: Vec<f64> = exact
            .iter()
            .filter(|s| s.is_motion())
            .map(|s| s.exit_velocity)
            .collect();
        let jump_cap = |dk: f64| (5e4 * 0.001 / dk).sqrt();
        let want = [
            jump_cap(0.2),
            jump_cap(0.2),
            jump_cap(0.2),
            jump_cap(0.4),
            jump_cap(0.2),
            0.0,
        ];
        assert_eq!(caps.len(), want.len(), "{caps:?}");
        for (got, want) in caps.iter().zip(want) {
            assert!((got - want).abs() <= 1e-9 * want.max(1.0), "{caps:?}");
        }
        let tolerance = 0.01;
        let (segs, deviation, limits) = planned_and_run(&k, tolerance, text);
        let blends = segs
            .iter()
            .filter(|s| matches!(s.shape, Shape::Blend(_)))
            .count();
        assert_eq!(blends, 5);
        let slowest = segs
            .iter()
            .filter(|s| s.is_motion())
            .map(|s| s.max_velocity)
            .fold(f64::INFINITY, f64::min);
        assert!(slowest > 1.5 * jump_cap(0.2), "slowest {slowest}");
        let (dt, dk) = junction_steps(&segs);
        assert!(dt < 1e-9 && dk < 1e-6, "steps {dt} {dk}");
        assert!(
            deviation <= tolerance * (1.0 + 1e-9),
            "deviation {deviation}"
        );
        assert!(limits <= 1.0 + 1e-6, "limit use {limits}");
    }

    /// Random chains of lines, arcs and helices (seeded; corners of every
    /// angle, radii from half the chord to three times it): the run stays
    /// within the tolerance of the programmed path and within the limits,
    /// and every junction the planner passes at speed is G2-continuous.
    #[test]
    fn random_line_and_arc_chains_blend_within_tolerance_and_limits() {
        let k = xyz(150.0, 1500.0, 7.5e4);
        let mut rng = crate::testkit::uniform(0x2545_f491_4f6c_dd1d);
        let mut blends = 0;
        for case in 0..24 {
            let mut text = String::from("G21 G17 G90 F6000\n");
            let (mut x, mut y, mut z) = (0.0f64, 0.0f64, 0.0f64);
            for _ in 0..16 {
                let len = if rng() < 0.3 {
                    0.05 + rng() * 0.5
                } else {
                    1.0 + rng() * 20.0
                };
                let angle = rng() * std::f64::consts::TAU;
                let round = |v: f64| (v * 1e4).round() / 1e4;
                x = round(x + len * angle.cos());
                y = round(y + len * angle.sin());
                if rng() < 0.2 {
                    z = round(-rng() * 5.0);
                }
                if rng() < 0.5 {
                    let code = if rng() < 0.5 { "G2" } else { "G3" };
                    let r = len / 2.0 * (1.0 + 2.0 * rng()) + 1e-3;
                    text += &format!("{code} X{x:.4} Y{y:.4} Z{z:.4} R{r:.4}\n");
                } else {
                    text += &format!("G1 X{x:.4} Y{y:.4} Z{z:.4}\n");
                }
            }
            text += "M2\n";
            let tolerance = [0.005, 0.05, 0.5][case % 3];
            // As planned, then blending every corner it can (no stops
            // where they are quicker), which the count below is about.
            let (planned, deviation, limits) = planned_and_run(&k, tolerance, &text);
            assert!(
                deviation <= tolerance * (1.0 + 1e-9) && limits <= 1.0 + 1e-6,
                "case {case} P{tolerance}: deviation {deviation}, limit use {limits}\n{text}"
            );
            let blending = PlannerConfig {
                mode: PathMode::Blend { tolerance },
                stop_when_quicker: false,
                ..Default::default()
            };
            let (segs, deviation, limits) = planned_and_run_with(&k, blending, &text);
            assert!(
                deviation <= tolerance * (1.0 + 1e-9) && limits <= 1.0 + 1e-6,
                "case {case} P{tolerance}, blending: deviation {deviation}, limit use {limits}\n{text}"
            );
            blends += segs
                .iter()
                .filter(|s| matches!(s.shape, Shape::Blend(_)))
                .count();
            for w in [&planned, &segs].into_iter().flat_map(|s| {
                s.windows(2)
                    .filter(|w| w[0].is_motion() && w[1].is_motion())
            }) {
                if w[0].exit_velocity > 0.0 && w[0].exit_velocity.is_finite() {
                    let (dt, _) = junction_steps(w);
                    assert!(
                        dt <= KINK,
                        "case {case}: a kink of {dt} passed at speed\n{text}"
                    );
                }
            }
        }
        // 24 × 15 corners, a sixth sharper than 150° (not blended), a few
        // with moves too short for any blend to fit the tolerance.
        assert!(blends >= 24 * 15 * 3 / 4, "{blends} blends");
    }
    /// The bits of a fit's partial sums, in order.
    fn sum_bits(s: &FitSums) -> Vec<u64> {
        let rhs = s.rhs.iter().flatten();
        s.moments
            .iter()
            .chain(rhs)
            .flatten()
            .map(|v| v.to_bits())
            .collect()
    }

    /// The window over the `used` chords from chord `from` on, centred
    /// on the middle one (reach unset).
    fn window_over(chords: &Chords, from: usize, used: usize) -> FitWindow<'_> {
        let centre = from + used / 2;
        FitWindow {
            chords,
            first: chords.slot(from),
            used,
            station: chords.station(centre),
            midpoint: chords.midpoint(centre),
            reach: 0.0,
        }
    }

    #[test]
    fn the_fits_avx_sums_are_its_plain_sums_bit_for_bit() {
        // Plans must not depend on the processor they were made on.
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            let mut rand = crate::testkit::uniform(7);
            let mut chords = Chords::new();
            // Some dropped first, so that the chords start past the
            // fields' first slot.
            for k in 0..140 {
                chords.push_back(Chord {
                    midpoint: [0.3 * rand() - 0.15, 0.3 * rand() - 0.15, rand()],
                    direction: [1.0, 0.0, 0.0],
                    length: 0.02,
                    station: k as f64 * 0.02 + 1e-3 * rand(),
                    corner: false,
                });
            }
            chords.drain_front(3);
            let n = chords.len();
            // Windows from the first chord on, from the next three (each
            // group of four starts elsewhere), and ending at the last
            // chord (the last group reads the zeros after it).
            for used in 1..=2 * FIT_SIDE + 1 {
                for from in [0, 1, 2, 3, n - used] {
                    let w = window_over(&chords, from, used);
                    let scale = 1.0 / (0.03 * used as f64);
                    let plain = w.sums_lanes(used, scale);
                    // SAFETY: the processor supports AVX, checked above.
                    let avx = unsafe { w.sums_avx(used, scale) };
                    assert_eq!(sum_bits(&plain), sum_bits(&avx), "{used} from {from}");
                    assert!(plain.moments[0].iter().sum::<f64>() > 0.0);
                }
            }
        }
    }

    /// The fit's partial sums as the window was gathered before it read
    /// the chords' fields: the offsets copied out, zeros after the last
    /// to the end of its group of four, summed in the same order. The
    /// reference the fit is held to.
    fn gathered_sums(w: &FitWindow, scale: f64) -> FitSums {
        let lanes = w.used.next_multiple_of(FIT_LANES);
        let x: Vec<f64> = (0..lanes)
            .map(|k| if k < w.used { w.x(k) } else { 0.0 })
            .collect();
        let y: Vec<[f64; 3]> = (0..lanes)
            .map(|k| {
                std::array::from_fn(|i| {
                    if k < w.used {
                        w.chords.midpoint[i][w.first + k] - w.midpoint[i]
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        let mut s = FitSums {
            moments: [[0.0; FIT_LANES]; 2 * FIT_TERMS - 1],
            rhs: [[[0.0; FIT_LANES]; FIT_TERMS]; 3],
        };
        for k in 0..lanes {
            let l = k % FIT_LANES;
            let u = x[k] * scale;
            let r = u.abs().min(1.0);
            let f = 1.0 - r * r * r;
            let weight = f * f * f * if k < w.used { 1.0 } else { 0.0 };
            let mut p = weight;
            for moment in s.moments.iter_mut() {
                moment[l] += p;
                p *= u;
            }
            for i in 0..3 {
                let mut p = weight * y[k][i];
                for rhs in s.rhs[i].iter_mut() {
                    rhs[l] += p;
                    p *= u;
                }
            }
        }
        s
    }

    #[test]
    fn a_walked_window_fits_as_a_gathered_one_to_the_bit() {
        // Chords of random lengths (some past FIT_REACH's share) turning
        // by random amounts (some past FIT_BEND, some past FIT_TURN in
        // all), with breaks: windows of every shape the walk can stop at.
        let chords = chords::tests::random_chords(11, 3000);
        let mut fitted = 0;
        for at in 1..chords.len() - 1 {
            if chords.is_break(at) {
                continue;
            }
            // Windows that see every chord after, and only a few; of
            // fitted points and of fitted frames.
            let ends = [chords.len(), (at + 3).min(chords.len())];
            for (end, most) in ends
                .into_iter()
                .flat_map(|e| [(e, POINT_SIDE), (e, FIT_SIDE)])
            {
                let (mut w, side) = FitWindow::walk(&chords, at, end, most);
                assert_eq!(w.used, 2 * side + 1);
                assert_eq!(w.x(side), 0.0, "at {at}: the centre");
                if side < FIT_MIN_SIDE {
                    continue;
                }
                w.reach = 1.25 * w.extent();
                let scale = 1.0 / w.reach;
                let gathered = gathered_sums(&w, scale);
                assert_eq!(
                    sum_bits(&w.sums_lanes(w.used, scale)),
                    sum_bits(&gathered),
                    "at {at}"
                );
                let bits = |c: Option<[[f64; 3]; FIT_TERMS]>| {
                    c.map(|c| {
                        c.as_flattened()
                            .iter()
                            .map(|v| v.to_bits())
                            .collect::<Vec<_>>()
                    })
                };
                assert_eq!(bits(w.solve()), bits(solve_sums(&gathered)), "at {at}");
                fitted += 1;
            }
        }
        assert!(fitted > 2000, "{fitted} windows fitted");
    }

    /// The midpoints of chords of `chord` mm inscribed in a circle of
    /// radius `r`, `side` on each side of the one at angle 0, and the
    /// radius of the circle they lie on.
    fn circle_chords(r: f64, chord: f64, side: usize) -> (Chords, f64) {
        let step = 2.0 * (chord / (2.0 * r)).asin();
        // Midpoints lie on a circle of radius r·cos(step/2), a path
        // length of `chord` apart along the polygon.
        let rm = r * (step / 2.0).cos();
        let mut chords = Chords::new();
        for n in -(side as i32)..=side as i32 {
            let angle = n as f64 * step;
            chords.push_back(Chord {
                midpoint: [rm * angle.cos(), rm * angle.sin(), 0.0],
                direction: [-angle.sin(), angle.cos(), 0.0],
                length: chord,
                station: n as f64 * chord,
                corner: false,
            });
        }
        (chords, rm)
    }

    #[test]
    fn the_fit_through_a_circles_chord_midpoints_gives_its_frame() {
        // Windows as the planner gathers them: at most FIT_REACH of path
        // and FIT_TURN of turn on each side.
        for (r, chord, side) in [
            (2.0, 0.02, 20),
            (1.0, 0.04, 10),
            (30.0, 0.02, 24),
            (1.25, 0.02, 24),
        ] {
            let (chords, rm) = circle_chords(r, chord, side);
            let mut w = window_over(&chords, 0, 2 * side + 1);
            w.reach = 1.25 * w.extent();
            let f = w.fit().expect("a fit");
            // The centre midpoint is at angle 0: (rm, 0) with tangent +Y
            // and curvature 1/rm toward the centre.
            // A cubic is not a circle: the fitted point sits a hair inside
            // it (a few 1e-6 mm at 0.2 rad either side), the same at every
            // midpoint of the circle, which is what keeps the blends
            // smooth; it has to stay far inside any path tolerance.
            let offset = f.point[0].hypot(f.point[1]);
            assert!(offset < 1e-4, "r {r}: point off by {offset}");
            assert!(
                (f.tangent[1] - 1.0).abs() < 1e-9,
                "r {r}: tangent {:?}",
                f.tangent
            );
            // The circle's fourth-order term (−s⁴/24R³ across it) biases
            // the cubic's curvature by a fraction that grows with the
            // square of the turn the window spans; the same fraction at
            // every midpoint of the circle.
            let k = -f.curvature[0];
            let turn = side as f64 * chord / r;
            assert!(
                (k * rm - 1.0).abs() < 0.1 * turn * turn,
                "r {r}: curvature {k} against 1/{rm}"
            );
            assert!(f.curvature[1].abs() < 1e-9 * k);
        }
    }

    /// The chords of the polyline through `vertices`, as the planner
    /// queues them for the curve fit ([`Chord::of`]).
    fn chords_through(vertices: &[[f64; 3]]) -> Chords {
        let mut chords = Chords::new();
        for w in vertices.windows(2) {
            let line = Programmed::new(Line {
                start: std::array::from_fn(|i| if i < 3 { w[0][i] } else { 0.0 }),
                end: std::array::from_fn(|i| if i < 3 { w[1][i] } else { 0.0 }),
            });
            let chord = Chord::of(&line, chords.back().as_ref());
            chords.push_back(chord);
        }
        chords
    }

    #[test]
    fn a_polygon_with_its_sag_at_the_tolerance_stays_curvature_continuous() {
        // CAM output whose chord tolerance is about G64 P: a circle of R5
        // in 49 chords of 0.641 mm sags 0.0103 mm, and arcs through the
        // chords' midpoints with the circle's curvature would pass the
        // vertices that far inside, just past the 0.01 mm tolerance. With
        // zero curvature at the midpoints (a corner blend at every vertex)
        // the circle ran 1.81 times as long as in 0.5 mm chords; with a
        // share of the vertices' curvature (MID_SHARES), 1.19 times.
        let (coarse, _, deviation, use_) = rounded_circle(9, 0.641);
        let (fine, _, _, _) = rounded_circle(9, 0.5);
        assert!(
            coarse < 1.3 * fine,
            "{coarse} s in 0.641 mm chords, {fine} s in 0.5 mm"
        );
        assert!(deviation <= 0.01 + 1e-9, "deviation {deviation}");
        assert!(use_ <= 1.0 + 1e-6, "limit use {use_}");
    }

    #[test]
    fn differenced_frames_give_the_curves_own_tangent_and_curvature() {
        // A helix of radius R and pitch 2πc has curvature R / (R² + c²)
        // everywhere; sampled at uneven steps (0.3, 1.0 and 1.7 times the
        // mean in turn, so the midpoints are 0.65, 1.35 and 1.0 apart), the
        // frame's differences must weigh their neighbours by the stations'
        // spacing: with the mean spacing for both, the tangent comes out
        // 7e-4 rad off (2.4e-7 in this cosine). The curvature keeps what
        // the chords' uneven sag leaves in the fitted points (under 2e-4
        // of it here with five points, 3e-4 with three).
        for (radius, pitch, chord) in [(5.0, 0.0, 0.02), (2.0, 1.0, 0.01), (30.0, 5.0, 0.02)] {
            let c = pitch / (2.0 * std::f64::consts::PI);
            let speed = (radius * radius + c * c).sqrt();
            let curvature = radius / (speed * speed);
            let mut theta = 0.0f64;
            let mut vertices = vec![];
            for k in 0..401 {
                vertices.push([radius * theta.cos(), radius * theta.sin(), c * theta]);
                theta += chord / speed * [0.3, 1.0, 1.7][k % 3];
            }
            let chords = chords_through(&vertices);
            for at in [200, 201, 202] {
                let frame =
                    differenced_frame(&chords, at, chords.len(), 0, &mut FittedPoints::new())
                        .expect("a frame in the middle of the run");
                // The helix at the parameter nearest the fitted point.
                let p = frame.point;
                let theta = p[1].atan2(p[0]);
                let tangent = [
                    -radius * theta.sin() / speed,
                    radius * theta.cos() / speed,
                    c / speed,
                ];
                let normal = [-theta.cos(), -theta.sin(), 0.0];
                let off = ((p[0].hypot(p[1]) - radius).powi(2) + (p[2] - c * theta).powi(2)).sqrt();
                assert!(off < 1e-4, "r {radius}: point {off} mm off the helix");
                let along: f64 = (0..3).map(|i| frame.tangent[i] * tangent[i]).sum();
                assert!(
                    along > 1.0 - 1e-9,
                    "r {radius}: tangent {:?} against {tangent:?}",
                    frame.tangent
                );
                let k: [f64; 3] = std::array::from_fn(|i| frame.curvature[i] / curvature);
                let err = norm3(&std::array::from_fn(|i| k[i] - normal[i]));
                assert!(
                    err < 1e-3,
                    "r {radius}: curvature {:?} against {curvature} along {normal:?}",
                    frame.curvature
                );
            }
        }
    }

    /// Cycle time, deviation and limit use of two turns of a circle of
    /// radius 5 mm in 0.02 mm chords at F3000, coordinates rounded to
    /// `decimals`, on a machine with mill3's limits.
    fn rounded_circle(decimals: usize, chord: f64) -> (f64, f64, f64, f64) {
        let r = 5.0;
        let n = (2.0 * std::f64::consts::PI * r / chord).round() as usize;
        // Centred on X−3 so that it starts where the machine is.
        // No G64 P: with P alone the collinear merge (Q = P) would take
        // the chords first. The default tolerance is 0.01 mm.
        let mut text = String::from("G21 G90\nG1 F3000\n");
        for k in 1..=2 * n {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            let (x, y) = (r * a.cos() - r, r * a.sin());
            text += &format!("X{x:.decimals$} Y{y:.decimals$}\n");
        }
        text += "M2\n";
        let kins = xyz(150.0, 1500.0, 75_000.0);
        let report = offline::run(
            Interpreter::from_text(&text, "circle.ngc", Position::ZERO),
            &kins,
            Position::ZERO,
            RunConfig {
                planner: PlannerConfig::default(),
                record: 0,
                follow: None,
            },
        )
        .unwrap();
        let length = 2.0 * n as f64 * chord;
        (
            report.cycle_time,
            length,
            report.max_deviation,
            report.max_limit_ratio(),
        )
    }

    #[test]
    fn rounded_cam_chords_run_at_the_programmed_feed() {
        // At 50 mm/s the centripetal acceleration is 500 mm/s², a third of
        // the limit: nothing but the feed caps the speed on the circle.
        // The exact circle takes its length at the feed and the ramps from
        // and to rest, each losing at most its duration: on a curve the
        // planner leaves the tangent half of A and a quarter of J (the
        // default shares), so v/a + a/j = 0.067 + 0.04 s.
        let (exact, length, _, _) = rounded_circle(9, 0.02);
        let feed_time = length / 50.0;
        let ramp = 50.0 / 750.0 + 750.0 / 18_750.0;
        assert!(
            exact < feed_time + 2.0 * ramp,
            "exact circle {exact} s for {feed_time} s at the feed"
        );
        // Without the fit, 1e-5 mm took 3.2 times as long as the exact
        // circle; with it, 1.3 times. At 1e-4 mm (0.5 % of a chord) most
        // neighbouring chords come out straight on; blended like the
        // others they took 2.4 times as long as the exact circle, left
        // straight (a stop of curvature at each) 8 times. With frames
        // that each fit's own derivatives gave, which disagree with the
        // neighbouring fits by a fraction of the noise, 1e-5, 1e-4 and
        // 1e-3 mm took 1.19, 2.16 and 4.5 times as long; with frames
        // differenced from the fitted points ([`differenced_frame`]),
        // 1.02, 1.03 and 1.59 times with three points, 1.02, 1.03 and
        // 1.064 with five.
        //
        // Chords of 0.01 mm: the fit takes up to 49 of them each side, to
        // its 0.5 mm reach. Rounded to 1e-5 and 1e-4 mm they run 1.015 and
        // 1.033 times the exact circle's time (with 23 lines each side,
        // well inside the reach, 1.19 and 2.37 times where the reach
        // followed the window's extent, and 1.007 and 1.45 where it sat
        // half a chord past it).
        let cases: [(f64, &[(usize, f64)]); 2] = [
            (0.02, &[(5, 1.05), (4, 1.08), (3, 1.15)]),
            (0.01, &[(5, 1.03), (4, 1.06)]),
        ];
        for (chord, roundings) in cases {
            let (exact, _, _, _) = rounded_circle(9, chord);
            for &(decimals, within) in roundings {
                let (time, _, deviation, use_) = rounded_circle(decimals, chord);
                assert!(
                    time < exact * within,
                    "{chord} mm chords, {decimals} decimals: {time} s against {exact} s exact"
                );
                assert!(deviation <= 0.01 + 1e-9, "deviation {deviation}");
                assert!(use_ <= 1.0 + 1e-6, "limit use {use_}");
            }
        }
    }
}
