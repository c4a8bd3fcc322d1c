//! A lower bound on cycle time for benchmarks and tests: time-optimal path
//! parameterisation (TOPP) of the planned path under velocity and
//! acceleration limits and a necessary condition of the jerk limits.
//!
//! Not used by the controller. The planner decides the path (lines, arcs,
//! corner blends); the executor decides, online, how fast to go along it.
//! This module answers: how fast could *any* trajectory go along that same
//! path if it only had to respect the programmed feed, each axis's (and
//! joint's) velocity and acceleration limit, and the part of each axis's
//! jerk limit that the path's geometry alone imposes? It shares nothing
//! with the executor's velocity profile, so a planned cycle time divided by
//! this bound measures how much time the executor's profile gives away.
//!
//! Why it is a lower bound: it solves a relaxation of the executor's
//! problem. The path is the same, the velocity and acceleration limits are
//! the same, and of the jerk limits only necessary conditions are kept
//! (below). The stops are the same: the planner's own stops (exit speed 0 —
//! exact stop, unblended corners, program end) and the markers that stand
//! still (dwell, immediate output, input wait); dwell times are added. Any
//! trajectory the executor could follow is feasible here, so none is faster
//! than the optimum found here.
//!
//! Method (Bobrow / TOPP-RA style): with x = v² and u = dv/dt = ½ dx/ds, a
//! coordinate c with tangent t_c = dc/ds and curvature κ_c = d²c/ds² moves
//! at v·t_c and accelerates at u·t_c + x·κ_c. Its limits
//!
//! * |v·t_c| ≤ V_c, v ≤ programmed feed (rapids: no feed cap),
//! * |u·t_c + x·κ_c| ≤ A_c,
//!
//! are linear in (x, u), so at each point of the path the feasible u for a
//! given x is an interval, and the largest x at which that interval is not
//! empty (the maximum-velocity curve) has a closed form: every pair of
//! coordinates c, d needs x·|κ_c·t_d − κ_d·t_c| ≤ A_c·|t_d| + A_d·|t_c|.
//! The path is sampled every `ds` on curves, at least 16 steps each (lines
//! have constant limits and are one exact step each); a forward pass
//! accelerates as hard as the interval allows, a backward pass decelerates
//! as hard as it allows (both integrating dx/ds = 2u by Heun's method), and
//! the time is Σ 2·ds / (v_k + v_{k+1}) (exact trapezoids on lines).
//! Each of the three (maximum-velocity curve, forward, backward) is an
//! upper bound on x of every feasible trajectory, so their minimum is too.
//!
//! Jerk on curves. The axis jerk along p(s) is p‴ = p′·s⃛ + 3·p″·v·u +
//! p‴(s)·v³ (p‴(s) = d³p/ds³, κ′ on an arc-length parameter). On the unit
//! normal n (the part of p″ orthogonal to p′, where there is one) the
//! unknown s⃛ drops out: j·n = 3·(κ·n)·v·u + (p‴·n)·v³, and with every axis
//! within |j_i| ≤ J_i, |j·n| ≤ Σ_i J_i·|n_i| =: J_n. So every trajectory
//! whose axis jerk stays within its limits at every instant has
//!
//! * |3·(κ·n)·v·u + (p‴·n)·v³| ≤ J_n,
//!
//! for given x an interval of u, intersected with the acceleration
//! interval in both passes. p‴·n is analytic: on arcs from θ and r linear
//! in s (0 on circles and helices, where p‴ = −w²·p′ in the plane, so a
//! circle's cruise speed is unchanged and only the ramps slow down), on
//! blends d|κ|/ds from the quintic's third derivative. In the
//! maximum-velocity curve the condition enters relaxed, to keep a closed
//! form: with U bounding the |u| that could offset p‴·n·v³ anywhere in the
//! acceleration-feasible range of x, |p‴·n|·v³ ≤ J_n + 3·(κ·n)·U·v (a
//! cubic with one positive root, found by Newton from above). Lines have
//! no normal and no such condition.
//!
//! Tangential jerk: speeding up from rest and slowing down to it. On the
//! tangent, s⃛ itself is bounded: on a line each axis's jerk is t_i·s⃛, so
//! |s⃛| ≤ min_i J_i/|t_i|; on a curve, projecting the axis jerk on t
//! (with t·t = 1, κ·t = 0 and p‴·t = −|κ|² on an arc-length parameter;
//! the general terms are kept for arcs) gives s⃛ = j·t + |κ|²·v³, so
//! |s⃛| ≤ Σ_i J_i·|t_i| + |κ|²·v³ =: Ĵ, with v from the first round of
//! passes (which already bounds every trajectory's speed). A trajectory
//! with u > 0 at some instant built that u up from below at a rate of at
//! most Ĵ, so over the last u/Ĵ seconds u stayed positive and the speed
//! rose by at least u²/(2Ĵ) from a speed ≥ 0:
//!
//! * u ≤ √(2·Ĵ·v), and likewise −u ≤ √(2·Ĵ·v) looking ahead (u < 0 must
//!   return to 0 before the speed reaches 0),
//!
//! with Ĵ the largest over the stretch of path those u/Ĵ seconds can cover
//! (at most v·U/Ĵ long, U bounding |u|; a node at rest ends it). This is
//! the S-curve's slow start, which a second-order bound lacks: from rest,
//! v^{3/2} grows by 1.5·√(2Ĵ)·ds while √(2Ĵ·v) < the acceleration bound.
//! A second round of passes applies it, and lines take their time from
//! the same two ramps in closed form. It is a relaxation, not the S-curve:
//! it lets u switch from +√(2Ĵv) to −√(2Ĵv) at once, so on a short line
//! from rest to rest it is 2·(3L/J)^{1/3} against the S-curve's
//! 4·(L/2J)^{1/3}, 9 % less. Joints of non-trivial kinematics get none of
//! the jerk conditions (they would only add conditions).
//!
//! Tangential jerk at the speed's crests. Where the speed rises and then
//! falls (a crest between two corners, or the turn from speeding up into
//! a cruise), u turns from positive to negative, no faster than s⃛ ≥ −Ĵ⁻
//! allows, Ĵ⁻ = `base` + `coupling`·v·U + `lift`·v³ (on a line min_i
//! J_i/|t_i|, on an arc-length curve Σ_i J_i·|t_i|). Along the path, f =
//! v³ has f′ = 3·v·u and
//!
//! * f″ = 3·s⃛ + 3·u²/v ≥ −3·Ĵ⁻,
//!
//! so f + Φ is convex where Φ″ = 3·Ĵ⁻ (Φ = Φ′ = 0 at a piece's start).
//! The passes' x is above every trajectory's v² at every point, so every
//! trajectory's f + Φ is below x^{3/2} + Φ and, being convex, below that
//! function's lower convex hull: the bound takes the hull less Φ as its
//! v³ (`round_crests`), on points every `ds` (lines at least 64, along
//! their closed-form ramps), and adds the time this costs by trapezoids.
//! The hull keeps the acceleration limits (a bridge of the hull is
//! concave in f with its slope between its ends', and f′ = 3·v·u). The
//! pieces end at rest and where nothing bounds s⃛; junctions do not end
//! them: a curvature jump steps the acceleration across the path (v²·Δκ),
//! not along it. The valleys, where u turns from negative to positive (into
//! and out of a slow corner), have no such convex form (there f″ is
//! bounded above only through 1/v, which a slower trajectory raises), and
//! the bound still lets u switch at once there. On a short line from rest
//! to rest rounding the crest brings the bound from 0.909 to 0.980 of the
//! S-curve (f = 4.5·J·s² from each end, bridged by P − 1.5·J·(s − L/2)²
//! tangent at L/8). `BoundConfig::crests = false` leaves it out.
//!
//! `BoundConfig::jerk = false` drops all of this, for a planner run with
//! `jerk_limited: false`.
//!
//! What "within its limits" means here: at every instant, as the planner's
//! per-segment limits guarantee for the executor (its path limits keep
//! j·t_i + 3·a·v·κ_i + v³·κ′_i ≤ J_i pointwise). A sampled trajectory
//! judged only by 1 ms finite differences could pass a feature shorter
//! than v·T faster, since the differences average the jerk over 3 ms; the
//! bound does not allow for that.
//!
//! Junctions where the curvature jumps (line to arc, arc to arc) step the
//! axis acceleration by v²·Δκ_i, an unbounded jerk in continuous time. The
//! planner passes them at v²·|Δκ_i| ≤ J_i·T (one servo period T). Sampled
//! every T, a step Δa shows a third difference of Δa/(2T) at the least
//! (when it falls on a sample; 3Δa/(4T) midway), and the rest of the
//! motion's jerk, within J_i, could offset at most J_i of it; so a
//! trajectory measured within J_i at the servo period has v²·|Δκ_i| ≤
//! 4·J_i·T, and the bound caps the junction speed there
//! (`JUNCTION_SLACK` = 4, twice the planner's speed): looser than the
//! planner, so the bound stays below it.
//!
//! Junctions the planner passes through at speed may still bend the tangent
//! by rounding (up to 1e-6). In continuous time that would force a stop; the
//! executor samples every servo period T and the measured axis acceleration
//! across such a kink is v·|Δt_c| / T, so the bound caps the speed there at
//! A_c·T / |Δt_c|, no tighter than the executor's own measure.
//!
//! Discretisation error. Against ds = 0.000625 mm, ds = 0.01 mm gives the
//! circle of chords +0.001 %, the zig-zag pocket −0.012 %, the 0.02 mm
//! spiral +0.012 % and the first 20,000 lines of stellabee1.ngc −0.45 %
//! (`cargo test --release --test time_bound -- --ignored --nocapture
//! discretisation`): low, which keeps it a bound, except the spiral's
//! 0.012 % (2 ms of 16.8 s), far inside its ratio. Steps from rest onto a
//! curve, where the jerk's u ≤ J_n/(3·κ·v) is unbounded as v → 0, are held
//! by the acceleration interval and err fast, the safe side. (Without the
//! jerk conditions the pocket was −0.002 %; Euler steps were +0.15 % and
//! +2.6 %, too high for a bound.)

use kerf_interp::Position;

use crate::kinematics::{Kinematics, MAX_JOINTS};
use crate::path::{Arc, Frame, Shape, Vec9};
use crate::plan::{PlannerConfig, Segment, SegmentKind};

/// Fewest steps on a curved segment, however short: short arcs and blends
/// bend their limits fastest.
const MIN_STEPS: usize = 16;

/// Fewest points on a line where the crests are rounded (the rounding's
/// time is summed by trapezoids between them): 16 read the crest of a
/// short line 0.16 % above its closed form, 64 within 0.01 %.
const LINE_CREST_POINTS: usize = 64;

/// A curvature jump at a junction passed at speed v steps axis i's
/// acceleration by v²·Δκ_i within one servo period. The planner caps that
/// at J_i·T; the bound allows `JUNCTION_SLACK` times as much (see the
/// module documentation).
const JUNCTION_SLACK: f64 = 4.0;

/// Settings of the bound.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundConfig {
    /// Sample spacing on curved segments (arcs, blends), mm.
    pub ds: f64,
    /// Servo period, s (for rounding kinks and curvature jumps, see the
    /// module documentation).
    pub period: f64,
    /// Apply the axes' jerk limits (as the planner does when
    /// `PlannerConfig::jerk_limited`).
    pub jerk: bool,
    /// With `jerk`, also round the speed's crests: v³ may bend down along
    /// the path no faster than the tangential jerk allows (see the module
    /// documentation). `false` gives the bound without it, for comparison.
    pub crests: bool,
}

impl BoundConfig {
    /// The bound for segments `planner` planned: its servo period at kinks
    /// and curvature jumps, the jerk limits if its profiles are
    /// jerk-limited, and the default sample spacing.
    pub fn for_planner(planner: &PlannerConfig) -> BoundConfig {
        BoundConfig {
            period: planner.period,
            jerk: planner.jerk_limited,
            ..BoundConfig::default()
        }
    }
}

impl Default for BoundConfig {
    fn default() -> Self {
        BoundConfig {
            ds: 0.01,
            period: 0.001,
            jerk: true,
            crests: true,
        }
    }
}

/// One limited coordinate: an axis, or a joint sampled through the
/// kinematics.
#[derive(Clone, Copy, Debug)]
enum Coordinate {
    Axis {
        index: usize,
        v: f64,
        a: f64,
        j: f64,
    },
    Joint {
        index: usize,
        v: f64,
        a: f64,
    },
}

impl Coordinate {
    fn limits(&self) -> (f64, f64) {
        match *self {
            Coordinate::Axis { v, a, .. } | Coordinate::Joint { v, a, .. } => (v, a),
        }
    }
}

/// The jerk constraint at a node, projected on the path's unit normal n:
/// |k3·v·u + d·v³| ≤ jn (see the module documentation). `k3` is 0 where
/// there is none (lines, straight points, no jerk limits).
#[derive(Clone, Copy, Debug, Default)]
struct Jerk {
    /// 3·(κ·n) = 3·|κ⊥|, 1/mm.
    k3: f64,
    /// p‴·n, 1/mm² (d|κ|/ds on an arc-length parameter).
    d: f64,
    /// Σ over axes of J_i·|n_i|, mm/s³.
    jn: f64,
}

/// What bounds the path's third derivative s⃛ from above at a node, as
/// s⃛ ≤ `base` + `coupling`·v·U + `bend`·v³ (U bounding |dv/dt|): on
/// lines the axes' jerk limits over the tangent, on curves the projection
/// of the axis jerk on the tangent (see the module documentation).
#[derive(Clone, Copy, Debug)]
struct Tangential {
    /// mm/s³; infinite where nothing bounds s⃛ (no jerk limits).
    base: f64,
    /// 3·|κ·t|/|t|², 1/mm.
    coupling: f64,
    /// max(0, −p‴·t)/|t|², 1/mm² (|κ|² on an arc-length parameter).
    bend: f64,
    /// max(0, p‴·t)/|t|², 1/mm²: what bounds −s⃛ beyond `base` and
    /// `coupling` (0 on an arc-length parameter).
    lift: f64,
}

impl Tangential {
    const FREE: Tangential = Tangential {
        base: f64::INFINITY,
        coupling: 0.0,
        bend: 0.0,
        lift: 0.0,
    };

    /// Ĵ⁺ ≥ s⃛ at speed `v` with |dv/dt| ≤ `u`, mm/s³ (infinite where
    /// nothing bounds it).
    fn above(&self, v: f64, u: f64) -> f64 {
        finite_or_infinite(self.base + self.coupling * v * u + self.bend * v * v * v)
    }

    /// Ĵ⁻ ≥ −s⃛ at speed `v` with |dv/dt| ≤ `u`, mm/s³ (infinite where
    /// nothing bounds it).
    fn below(&self, v: f64, u: f64) -> f64 {
        finite_or_infinite(self.base + self.coupling * v * u + self.lift * v * v * v)
    }
}

/// `j`, or infinity where it is not finite (NaN from infinite terms).
fn finite_or_infinite(j: f64) -> f64 {
    if j.is_finite() {
        j
    } else {
        f64::INFINITY
    }
}

/// A sampled point of the path.
#[derive(Clone, Copy, Debug)]
struct Node {
    /// Largest x = v² allowed here.
    xmax: f64,
    /// Largest x = v² the segment itself allows (before stops and caps).
    own: f64,
    /// Path length to the next node.
    ds: f64,
    /// The step to the next node is a line: constant limits, exact time.
    line: bool,
}

/// The result: the optimal speed profile and its time (dwells included).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Profile {
    /// Cycle time of the optimal profile, s.
    pub time: f64,
    /// Path position of each node, mm.
    pub s: Vec<f64>,
    /// Optimal path speed at each node, mm/s.
    pub v: Vec<f64>,
    /// Time from each node to the next, s (0 after the last), by the
    /// same rules as `time`: where along the path the optimum spends it,
    /// to set beside where a planned run does. Dwells are not in it.
    pub step: Vec<f64>,
}

/// Collects planned segments and computes the time-optimal profile along
/// them. Feed it every segment in order (markers included), then call
/// [`solve`](Self::solve).
pub struct TimeBound<'k> {
    kins: &'k dyn Kinematics,
    config: BoundConfig,
    coords: Vec<Coordinate>,
    nodes: Vec<Node>,
    /// Per node, (t_c, κ_c) for every coordinate, flat.
    geometry: Vec<f64>,
    /// Per node, the normal jerk constraint.
    jerks: Vec<Jerk>,
    /// Per node, what bounds s⃛ from above.
    tangential: Vec<Tangential>,
    /// Jerk limit of each axis (joints moving with it folded in), infinite
    /// for axes the machine lacks or when jerk is not limited.
    axis_jerk: [f64; 9],
    /// Tangent (per coordinate) at the end of the last segment, for the
    /// kink cap at the next junction.
    last_tangent: Vec<f64>,
    /// Curvature (per coordinate) there, for the curvature-jump cap.
    last_curvature: Vec<f64>,
    /// Whether the last node must be at rest.
    rest: bool,
    /// Dwells (G4), s: standing still is part of the cycle.
    dwell: f64,
}

impl<'k> TimeBound<'k> {
    /// An empty path on machine `kins`, starting at rest.
    pub fn new(kins: &'k dyn Kinematics, config: BoundConfig) -> TimeBound<'k> {
        let mut axis_limits: [Option<(f64, f64, f64)>; 9] = [None; 9];
        for spec in kins.axes() {
            let l = &spec.limits;
            axis_limits[spec.axis.index()] = Some((l.max_velocity, l.max_acceleration, l.max_jerk));
        }
        let mut coords = Vec::new();
        let mut joints = Vec::new();
        for (j, spec) in kins.joints().iter().enumerate() {
            let l = &spec.limits;
            let (v, a) = (l.max_velocity, l.max_acceleration);
            match kins
                .joint_axis(j)
                .and_then(|ax| axis_limits[ax.index()].as_mut())
            {
                Some(al) => *al = (al.0.min(v), al.1.min(a), al.2.min(l.max_jerk)),
                None => joints.push(Coordinate::Joint { index: j, v, a }),
            }
        }
        let mut axis_jerk = [f64::INFINITY; 9];
        for (index, l) in axis_limits.iter().enumerate() {
            if let Some((v, a, j)) = *l {
                let j = if config.jerk { j } else { f64::INFINITY };
                axis_jerk[index] = j;
                coords.push(Coordinate::Axis { index, v, a, j });
            }
        }
        coords.extend(joints);
        TimeBound {
            kins,
            config,
            last_tangent: vec![0.0; coords.len()],
            last_curvature: vec![0.0; coords.len()],
            coords,
            nodes: Vec::new(),
            geometry: Vec::new(),
            jerks: Vec::new(),
            tangential: Vec::new(),
            axis_jerk,
            rest: true,
            dwell: 0.0,
        }
    }

    /// (t_c, κ_c) of every coordinate at `frame`.
    fn coordinates(&self, frame: &Frame, out: &mut Vec<f64>) {
        let n = self.kins.joints().len();
        let mut q = [[0.0; MAX_JOINTS]; 3];
        let mut joints_ok = None;
        for c in &self.coords {
            match *c {
                Coordinate::Axis { index, .. } => {
                    out.push(frame.tangent[index]);
                    out.push(frame.curvature[index]);
                }
                Coordinate::Joint { index, .. } => {
                    let ok = *joints_ok.get_or_insert_with(|| {
                        let h = 1e-3;
                        (0..3).all(|m| {
                            let e = (m as f64 - 1.0) * h;
                            let p: Vec9 = std::array::from_fn(|i| {
                                frame.point[i]
                                    + e * frame.tangent[i]
                                    + 0.5 * e * e * frame.curvature[i]
                            });
                            self.kins
                                .inverse(&Position::from_array(p), &mut q[m][..n])
                                .is_ok()
                        })
                    });
                    if ok {
                        let h = 1e-3;
                        out.push((q[2][index] - q[0][index]) / (2.0 * h));
                        out.push((q[2][index] - 2.0 * q[1][index] + q[0][index]) / (h * h));
                    } else {
                        out.push(0.0);
                        out.push(0.0);
                    }
                }
            }
        }
    }

    /// Largest x = v² at which the acceleration interval is not empty and
    /// every velocity limit holds, for geometry `g` (pairs t_c, κ_c).
    fn max_x(&self, g: &[f64], feed: f64) -> f64 {
        let mut x = feed * feed;
        let m = self.coords.len();
        for c in 0..m {
            let (vc, ac) = self.coords[c].limits();
            let (tc, kc) = (g[2 * c], g[2 * c + 1]);
            if tc != 0.0 {
                x = x.min(vc * vc / (tc * tc));
            } else if kc != 0.0 {
                x = x.min(ac / kc.abs());
            }
            for d in c + 1..m {
                let (_, ad) = self.coords[d].limits();
                let (td, kd) = (g[2 * d], g[2 * d + 1]);
                if tc == 0.0 && td == 0.0 {
                    continue;
                }
                let den = (kc * td - kd * tc).abs();
                if den > 0.0 {
                    x = x.min((ac * td.abs() + ad * tc.abs()) / den);
                }
            }
        }
        x
    }

    /// The interval of u = dv/dt allowed at x on geometry `g` with the
    /// normal jerk constraint `jerk`.
    fn u_range(&self, g: &[f64], jerk: &Jerk, x: f64) -> (f64, f64) {
        let (mut lo, mut hi) = self.accel_range(g, x);
        if jerk.k3 > 0.0 && x > 0.0 {
            // |k3·v·u + d·v³| ≤ jn.
            let v = x.sqrt();
            let (j, d) = (jerk.jn / v, jerk.d * x);
            lo = lo.max((-j - d) / jerk.k3);
            hi = hi.min((j - d) / jerk.k3);
        }
        (lo, hi)
    }

    /// The interval of u = dv/dt the acceleration limits allow at x.
    fn accel_range(&self, g: &[f64], x: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for (c, coord) in self.coords.iter().enumerate() {
            let (tc, kc) = (g[2 * c], g[2 * c + 1]);
            if tc == 0.0 {
                continue;
            }
            let (l, h) = accel_interval(coord.limits().1, tc, kc, x);
            lo = lo.max(l);
            hi = hi.min(h);
        }
        (lo, hi)
    }

    /// The normal jerk constraint at `frame`, given p‴·n by `third` (a
    /// function of the unit normal n). Where the curvature vanishes, n is
    /// the direction of p‴'s normal part, `straight` (if any): with κ = 0
    /// the condition is the speed cap |p‴·n|·v³ ≤ J_n.
    fn jerk_at(&self, frame: &Frame, third: impl Fn(&Vec9) -> f64, straight: Option<Vec9>) -> Jerk {
        let (t, k) = (&frame.tangent, &frame.curvature);
        let tt: f64 = t.iter().map(|x| x * x).sum();
        if tt == 0.0 {
            return Jerk::default();
        }
        let along = (0..9).map(|i| k[i] * t[i]).sum::<f64>() / tt;
        let perp: Vec9 = std::array::from_fn(|i| k[i] - along * t[i]);
        let kn = perp.iter().map(|x| x * x).sum::<f64>().sqrt();
        if !kn.is_finite() {
            return Jerk::default();
        }
        if kn == 0.0 {
            let Some(p3) = straight else {
                return Jerk::default();
            };
            let along = (0..9).map(|i| p3[i] * t[i]).sum::<f64>() / tt;
            let perp: Vec9 = std::array::from_fn(|i| p3[i] - along * t[i]);
            let d = perp.iter().map(|x| x * x).sum::<f64>().sqrt();
            if d == 0.0 || !d.is_finite() {
                return Jerk::default();
            }
            let jn: f64 = (0..9)
                .filter(|&i| perp[i] != 0.0)
                .map(|i| self.axis_jerk[i] * (perp[i] / d).abs())
                .sum();
            if !jn.is_finite() {
                return Jerk::default();
            }
            return Jerk { k3: 0.0, d, jn };
        }
        let n: Vec9 = std::array::from_fn(|i| perp[i] / kn);
        let jn: f64 = (0..9)
            .filter(|&i| n[i] != 0.0)
            .map(|i| self.axis_jerk[i] * n[i].abs())
            .sum();
        if !jn.is_finite() {
            return Jerk::default();
        }
        // κ·n = |κ⊥|: the tangential part of κ (parameters that are not
        // exactly arc length, spiral arcs) drops out with n·t = 0.
        Jerk {
            k3: 3.0 * kn,
            d: third(&n),
            jn,
        }
    }

    /// The largest x = v² at which a u in the acceleration interval meets
    /// the normal jerk constraint, relaxed to a form with a closed
    /// answer: with U ≥ 0 bounding the u that could cancel d·v³ over the
    /// whole acceleration-feasible range x ∈ [0, `xa`] (the acceleration
    /// interval's ends are linear pieces in x, so their extremes over the
    /// range are at its ends), |d|·v³ ≤ jn + k3·U·v. The cubic in v is
    /// convex and negative at 0, so the feasible speeds are [0, v*];
    /// Newton from above stays above v*, so stopping early keeps it a bound.
    fn jerk_max_x(&self, g: &[f64], jerk: &Jerk, xa: f64) -> f64 {
        if jerk.d == 0.0 || !jerk.jn.is_finite() || !xa.is_finite() || xa <= 0.0 {
            return xa;
        }
        let (mut hb, mut lb) = (f64::INFINITY, f64::NEG_INFINITY);
        for (c, coord) in self.coords.iter().enumerate() {
            let (tc, kc) = (g[2 * c], g[2 * c + 1]);
            if tc == 0.0 {
                continue;
            }
            let a = coord.limits().1;
            let (l0, h0) = accel_interval(a, tc, kc, 0.0);
            let (l1, h1) = accel_interval(a, tc, kc, xa);
            hb = hb.min(h0.max(h1));
            lb = lb.max(l0.min(l1));
        }
        // d > 0 needs u ≤ (jn − d·v³)/(k3·v), so u ≥ lb must allow it;
        // d < 0 needs u ≥ (|d|·v³ − jn)/(k3·v) below hb.
        let u = if jerk.k3 == 0.0 {
            0.0
        } else if jerk.d > 0.0 {
            -lb
        } else {
            hb
        }
        .max(0.0);
        if !u.is_finite() {
            return xa;
        }
        let (d, b, c) = (jerk.d.abs(), jerk.k3 * u, jerk.jn);
        let f = |y: f64| d * y * y * y - b * y - c;
        // f(y0) ≥ 0 (see the sum of halves: d·y0³ ≥ 2c and ≥ 2b·y0).
        let mut y = (2.0 * c / d).cbrt() + (2.0 * b / d).sqrt();
        for _ in 0..40 {
            let fy = f(y);
            let slope = 3.0 * d * y * y - b;
            if fy <= 0.0 || slope <= 0.0 {
                break;
            }
            let next = y - fy / slope;
            if next >= y * (1.0 - 1e-12) {
                break;
            }
            y = next;
        }
        xa.min(y * y)
    }

    /// What bounds s⃛ from above at `frame`, given p‴·t by `third_t`; on
    /// a line (`line`) p‴ vanishes, and axis i's jerk is t_i·s⃛ alone.
    fn tangential_at(&self, frame: &Frame, third_t: f64, line: bool) -> Tangential {
        if !self.config.jerk {
            return Tangential::FREE;
        }
        let (t, k) = (&frame.tangent, &frame.curvature);
        let tt: f64 = t.iter().map(|x| x * x).sum();
        if tt == 0.0 || !tt.is_finite() {
            return Tangential::FREE;
        }
        let moving = (0..9).filter(|&i| t[i] != 0.0);
        // Elsewhere — a blend's end has no curvature but a p‴ across the
        // tangent — the axis jerks are projected on the tangent.
        let base = if line {
            moving
                .map(|i| self.axis_jerk[i] / t[i].abs())
                .fold(f64::INFINITY, f64::min)
        } else {
            moving.map(|i| self.axis_jerk[i] * t[i].abs()).sum::<f64>() / tt
        };
        let kt: f64 = (0..9).map(|i| k[i] * t[i]).sum();
        if !base.is_finite() || !kt.is_finite() || !third_t.is_finite() {
            return Tangential::FREE;
        }
        Tangential {
            base,
            coupling: 3.0 * kt.abs() / tt,
            bend: (-third_t).max(0.0) / tt,
            lift: third_t.max(0.0) / tt,
        }
    }

    fn push_node(
        &mut self,
        frame: &Frame,
        jerk: Jerk,
        third_t: f64,
        feed: f64,
        ds: f64,
        line: bool,
    ) {
        let tangential = self.tangential_at(frame, third_t, line);
        self.tangential.push(tangential);
        let start = self.geometry.len();
        let mut g = std::mem::take(&mut self.geometry);
        self.coordinates(frame, &mut g);
        let xa = self.max_x(&g[start..], feed);
        let xmax = self.jerk_max_x(&g[start..], &jerk, xa);
        self.geometry = g;
        self.jerks.push(jerk);
        self.nodes.push(Node {
            xmax,
            own: xmax,
            ds,
            line,
        });
    }

    /// Add the next planned segment.
    pub fn push(&mut self, segment: &Segment) {
        if !segment.is_motion() {
            // Markers stand still (dwell, stop, output, input wait).
            if let SegmentKind::Dwell { seconds } = segment.kind {
                self.dwell += seconds.max(0.0);
            }
            if let Some(last) = self.nodes.last_mut() {
                last.xmax = 0.0;
            }
            self.rest = true;
            return;
        }
        if segment.length <= 0.0 {
            return;
        }
        let shape = &segment.shape;
        let feed = match segment.kind {
            SegmentKind::Feed => segment.feed,
            _ => f64::INFINITY,
        };
        let first = shape.frame(0.0);
        // The junction with the segment before: a zero-length step from
        // the end of the last segment to the start of this one.
        let mut start_cap = if self.rest { 0.0 } else { f64::INFINITY };
        if !self.rest {
            let mut g = Vec::with_capacity(2 * self.coords.len());
            self.coordinates(&first, &mut g);
            for (c, coord) in self.coords.iter().enumerate() {
                let jump = (g[2 * c] - self.last_tangent[c]).abs();
                if jump > 0.0 {
                    let v = coord.limits().1 * self.config.period / jump;
                    start_cap = start_cap.min(v * v);
                }
                // Curvature jumps: axes only (joints would only add caps).
                let bend = (g[2 * c + 1] - self.last_curvature[c]).abs();
                if let (Coordinate::Axis { j, .. }, true) = (*coord, bend > 0.0) {
                    start_cap = start_cap.min(JUNCTION_SLACK * j * self.config.period / bend);
                }
            }
            if let Some(last) = self.nodes.last_mut() {
                last.xmax = last.xmax.min(start_cap);
                last.ds = 0.0;
                last.line = false;
            }
        }
        let (line, n) = match shape {
            Shape::Line(_) => (true, 1),
            _ => (
                false,
                ((segment.length / self.config.ds).ceil() as usize).max(MIN_STEPS),
            ),
        };
        let at_start = self.nodes.len();
        match shape {
            Shape::Blend(b) => {
                // Uniform in the Bézier parameter; arc length from the table.
                let mut s0 = 0.0;
                for k in 0..=n {
                    let u = k as f64 / n as f64;
                    let s1 = if k < n {
                        b.length_to((k + 1) as f64 / n as f64)
                    } else {
                        s0
                    };
                    let frame = b.frame_at_parameter(u);
                    // p‴·n = d|κ|/ds on the arc-length parameter.
                    let jerk = self.jerk_at(
                        &frame,
                        |_| b.curvature_rate_at_parameter(u),
                        Some(b.third_normal_where_straight(u)),
                    );
                    // p‴·t = −|κ|² on an arc-length parameter (t·t = 1).
                    let bend: f64 = frame.curvature.iter().map(|c| c * c).sum();
                    self.push_node(&frame, jerk, -bend, feed, s1 - s0, false);
                    s0 = s1;
                }
            }
            _ => {
                let step = segment.length / n as f64;
                for k in 0..=n {
                    let s = segment.length * k as f64 / n as f64;
                    let frame = if k == 0 { first } else { shape.frame(s) };
                    let (jerk, third_t) = match shape {
                        Shape::Arc(a) => {
                            let p3 = arc_third(a, s, segment.length);
                            let on = |n: &Vec9| (0..9).map(|i| p3[i] * n[i]).sum::<f64>();
                            (self.jerk_at(&frame, on, None), on(&frame.tangent))
                        }
                        _ => (Jerk::default(), 0.0),
                    };
                    let ds = if k < n { step } else { 0.0 };
                    self.push_node(&frame, jerk, third_t, feed, ds, line);
                }
            }
        }
        self.nodes[at_start].xmax = self.nodes[at_start].xmax.min(start_cap);
        let last = self.nodes.len() - 1;
        self.nodes[last].line = false;
        let m = self.coords.len();
        for c in 0..m {
            self.last_tangent[c] = self.geometry[2 * (last * m + c)];
            self.last_curvature[c] = self.geometry[2 * (last * m + c) + 1];
        }
        // The planner's stops: exact stop, unblended corners, program end.
        self.rest = segment.exit_velocity == 0.0;
        if self.rest {
            self.nodes[last].xmax = 0.0;
        }
    }

    /// The time-optimal profile along everything pushed, from rest to rest.
    pub fn solve(&self) -> Profile {
        let nodes = &self.nodes;
        let n = nodes.len();
        if n == 0 {
            return Profile {
                time: self.dwell,
                ..Profile::default()
            };
        }
        let mut x: Vec<f64> = nodes.iter().map(|nd| nd.xmax).collect();
        x[0] = 0.0;
        x[n - 1] = 0.0;
        let free = vec![f64::INFINITY; n];
        self.passes(&mut x, &free, &free);
        // The tangential jerk condition needs an upper bound on the speed
        // (its curves' terms grow with v), which the first round gives.
        let (behind, ahead) = if self.config.jerk {
            let (behind, ahead) = self.ramp_rates(&x);
            self.passes(&mut x, &behind, &ahead);
            (behind, ahead)
        } else {
            (free.clone(), free)
        };
        let m = self.coords.len();
        let g = |k: usize| &self.geometry[2 * m * k..2 * m * (k + 1)];
        let v: Vec<f64> = x.iter().map(|x| x.max(0.0).sqrt()).collect();
        // Time of each step from node k to k + 1.
        let mut step = vec![0.0; n];
        for k in 0..n - 1 {
            let ds = nodes[k].ds;
            if ds == 0.0 {
                continue;
            }
            step[k] = if nodes[k].line {
                let (_, a) = self.accel_range(g(k), 0.0);
                let up = Ramp::new(a, behind[k].max(behind[k + 1]));
                let down = Ramp::new(a, ahead[k].max(ahead[k + 1]));
                line_time(v[k], v[k + 1], nodes[k].own, up, down, ds)
            } else if v[k] + v[k + 1] > 0.0 {
                // The chord; but from rest (v ∝ s^{2/3} on the ramp) no
                // less than the ramps' own time over the step.
                let up = ramp_time(v[k], behind[k].max(behind[k + 1]), ds);
                let down = ramp_time(v[k + 1], ahead[k].max(ahead[k + 1]), ds);
                (2.0 * ds / (v[k] + v[k + 1])).max(up).max(down)
            } else {
                f64::INFINITY
            };
        }
        let mut v = v;
        if self.config.jerk && self.config.crests {
            self.round_crests(&x, &behind, &ahead, &mut v, &mut step);
        }
        let mut time = self.dwell;
        let mut s = Vec::with_capacity(n);
        let mut at = 0.0;
        for k in 0..n {
            s.push(at);
            at += nodes[k].ds;
            time += step[k];
        }
        Profile { time, s, v, step }
    }

    /// One forward and one backward pass over `x` (lowering it only):
    /// as hard as the acceleration interval allows, dx/ds = 2·hi(s, x),
    /// integrated by Heun's method (second order in ds), and no faster
    /// than u ≤ C·v^½ with C = `behind[k]` lets it (see
    /// [`ramp_rates`](Self::ramp_rates)); then the same slowing down from
    /// the end with `ahead`.
    fn passes(&self, x: &mut [f64], behind: &[f64], ahead: &[f64]) {
        let nodes = &self.nodes;
        let n = nodes.len();
        let m = self.coords.len();
        let g = |k: usize| &self.geometry[2 * m * k..2 * m * (k + 1)];
        let jk = |k: usize| &self.jerks[k];
        for k in 0..n - 1 {
            let ds = nodes[k].ds;
            if ds == 0.0 {
                x[k + 1] = x[k + 1].min(x[k]);
                continue;
            }
            let (_, hi0) = self.u_range(g(k), jk(k), x[k]);
            let guess = (x[k] + 2.0 * ds * hi0).clamp(0.0, x[k + 1]);
            let (_, hi1) = self.u_range(g(k + 1), jk(k + 1), guess);
            let ramp = ramp_rise(x[k], behind[k].max(behind[k + 1]), ds);
            x[k + 1] = x[k + 1].min((x[k] + ds * (hi0 + hi1)).max(0.0)).min(ramp);
        }
        for k in (0..n - 1).rev() {
            let ds = nodes[k].ds;
            if ds == 0.0 {
                x[k] = x[k].min(x[k + 1]);
                continue;
            }
            let (lo1, _) = self.u_range(g(k + 1), jk(k + 1), x[k + 1]);
            let guess = (x[k + 1] - 2.0 * ds * lo1).clamp(0.0, x[k]);
            let (lo0, _) = self.u_range(g(k), jk(k), guess);
            let ramp = ramp_rise(x[k + 1], ahead[k].max(ahead[k + 1]), ds);
            x[k] = x[k].min((x[k + 1] - ds * (lo0 + lo1)).max(0.0)).min(ramp);
        }
    }

    /// The crest condition (module documentation): f = v³ has f″ = 3·s⃛ +
    /// 3·u²/v ≥ −3·Ĵ⁻ along the path, Ĵ⁻ bounding −s⃛, so f + Φ is
    /// convex where Φ″ = 3·Ĵ⁻. The passes' `x` bounds every trajectory's
    /// v² from above, so every trajectory's f + Φ lies below the lower
    /// convex hull of x^{3/2} + Φ, piece by piece between nodes at rest.
    /// Lowers `v` to the hull's speed at the nodes and adds to `step` the
    /// time that costs, step by step on points every `ds` (lines are
    /// sampled along their closed-form ramps for it).
    fn round_crests(
        &self,
        x: &[f64],
        behind: &[f64],
        ahead: &[f64],
        v: &mut [f64],
        step: &mut [f64],
    ) {
        let nodes = &self.nodes;
        let n = nodes.len();
        let m = self.coords.len();
        let g = |k: usize| &self.geometry[2 * m * k..2 * m * (k + 1)];
        // Ĵ⁻ at each node; infinite where nothing bounds s⃛.
        let floor: Vec<f64> = (0..n)
            .map(|k| self.tangential[k].below(v[k], self.u_bound(g(k), x[k])))
            .collect();
        let mut piece: Vec<CrestPoint> = Vec::new();
        let mut hull: Vec<usize> = Vec::new();
        // Round what the piece holds and start the next at node `k`.
        let mut restart =
            |piece: &mut Vec<CrestPoint>, k: usize, v: &mut [f64], step: &mut [f64]| {
                round_piece(piece, &mut hull, v, step);
                piece.clear();
                piece.push(CrestPoint {
                    s: 0.0,
                    f: v[k].powi(3),
                    phi: 0.0,
                    step: k,
                    nodes: Some((k, k)),
                });
            };
        restart(&mut piece, 0, v, step);
        let mut slope = 0.0;
        for k in 0..n - 1 {
            let ds = nodes[k].ds;
            if ds == 0.0 {
                // A junction: node k + 1 is the same point as node k.
                let p = piece.last_mut().expect("a piece has its first point");
                p.f = p.f.min(v[k + 1].powi(3));
                p.nodes = p.nodes.map(|(first, _)| (first, k + 1));
                continue;
            }
            let j = floor[k].max(floor[k + 1]);
            if !j.is_finite() {
                // Nothing bounds s⃛ on this step: the pieces either side
                // are rounded apart, the step left as it is.
                restart(&mut piece, k + 1, v, step);
                slope = 0.0;
                continue;
            }
            let c = 3.0 * j;
            let mut push = |piece: &mut Vec<CrestPoint>, h: f64, f: f64, node: Option<usize>| {
                let p = *piece.last().expect("a piece has its first point");
                let phi = p.phi + slope * h + 0.5 * c * h * h;
                slope += c * h;
                piece.push(CrestPoint {
                    s: p.s + h,
                    f,
                    phi,
                    step: k,
                    nodes: node.map(|i| (i, i)),
                });
            };
            if nodes[k].line {
                let (_, a) = self.accel_range(g(k), 0.0);
                let up = Ramp::new(a, behind[k].max(behind[k + 1]));
                let down = Ramp::new(a, ahead[k].max(ahead[k + 1]));
                let vm = nodes[k].own.sqrt();
                let (v0, v1) = (v[k].min(vm), v[k + 1].min(vm));
                let parts = ((ds / self.config.ds).ceil() as usize).max(LINE_CREST_POINTS);
                let h = ds / parts as f64;
                for i in 1..parts {
                    let at = ds * i as f64 / parts as f64;
                    let top = vm.min(up.reach(v0, at)).min(down.reach(v1, ds - at));
                    push(&mut piece, h, top.powi(3), None);
                }
                push(&mut piece, h, v[k + 1].powi(3), Some(k + 1));
            } else {
                push(&mut piece, ds, v[k + 1].powi(3), Some(k + 1));
            }
            if x[k + 1] <= 0.0 {
                // At rest f = 0 whatever came before: a new piece.
                restart(&mut piece, k + 1, v, step);
                slope = 0.0;
            }
        }
        round_piece(&mut piece, &mut hull, v, step);
    }

    /// Per node, the rates C (mm^½/s^{5/2}) of the tangential jerk
    /// condition |u| ≤ C·v^½, given `x` bounding v² from above: C =
    /// √(2·Ĵ) with Ĵ the largest bound on s⃛ over the stretch of path a
    /// trajectory covers while its acceleration builds up (`behind`, for
    /// u > 0) or dies away (`ahead`, u < 0). See the module documentation.
    fn ramp_rates(&self, x: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let nodes = &self.nodes;
        let n = nodes.len();
        let m = self.coords.len();
        let g = |k: usize| &self.geometry[2 * m * k..2 * m * (k + 1)];
        let mut at = Vec::with_capacity(n);
        let mut reach = Vec::with_capacity(n);
        let mut own = Vec::with_capacity(n);
        let mut pos = 0.0;
        for k in 0..n {
            at.push(pos);
            pos += nodes[k].ds;
            let v = x[k].max(0.0).sqrt();
            let u = self.u_bound(g(k), x[k]);
            let t = &self.tangential[k];
            own.push(t.above(v, u));
            reach.push(v * u);
        }
        // The window: u builds up from 0 (behind) or falls back to 0
        // (ahead) at |s⃛| ≤ Ĵ in |u|/Ĵ ≤ U/Ĵ seconds at speeds no more than
        // v, so over at most v·U/Ĵ of path; widen it until the largest Ĵ
        // in it says it is wide enough. A node at rest ends it (the
        // trajectory stands there).
        let window = |k: usize, step: &dyn Fn(usize) -> Option<usize>| {
            let mut j = own[k];
            let mut i = k;
            while j.is_finite() && x[i] > 0.0 {
                let Some(next) = step(i) else { break };
                if (at[next] - at[k]).abs() > reach[k] / j {
                    break;
                }
                i = next;
                j = j.max(own[i]);
            }
            (2.0 * j).sqrt()
        };
        let behind = (0..n).map(|k| window(k, &|i| i.checked_sub(1))).collect();
        let ahead = (0..n)
            .map(|k| window(k, &|i| (i + 1 < n).then_some(i + 1)))
            .collect();
        (behind, ahead)
    }

    /// A bound on |u| = |dv/dt| at x = v²: each coordinate's acceleration
    /// |u·t_c + x·κ_c| ≤ A_c.
    fn u_bound(&self, g: &[f64], x: f64) -> f64 {
        let mut u = f64::INFINITY;
        for (c, coord) in self.coords.iter().enumerate() {
            let (tc, kc) = (g[2 * c], g[2 * c + 1]);
            if tc != 0.0 {
                u = u.min((coord.limits().1 + x * kc.abs()) / tc.abs());
            }
        }
        u
    }
}

/// d³p/ds³ on arc `a` of length `len` at `s`. On a circle or helix
/// (θ = θ0 + w·s) it is −w²·p′ in the plane, orthogonal to the normal.
/// On a spiral (`Shape::frame`: r = r0 + D·s/len, r·θ′ = c constant)
/// the curvature is w·((D/len)·n1 − c·n2) with w = c/r, n1 = (−sin θ,
/// cos θ), n2 = (cos θ, sin θ), and its derivative
/// w′·((D/len)·n1 − c·n2) − w²·((D/len)·n2 + c·n1), w′ = −w·D/(len·r).
/// (The axial part moves linearly: no third derivative.)
pub(crate) fn arc_third(a: &Arc, s: f64, len: f64) -> Vec9 {
    let mut p3 = [0.0; 9];
    if len <= 0.0 {
        return p3;
    }
    let q = (s / len).clamp(0.0, 1.0);
    let d = a.end_radius - a.radius;
    if !a.is_logarithmic() {
        // θ = θ0 + w·s, r = r0 + r′·s (a circle, or a spiral from or to
        // its centre).
        let (sin, cos) = (a.start_angle + a.sweep * q).sin_cos();
        let r = a.radius + d * q;
        let w = a.sweep / len;
        let dr = d / len;
        p3[a.plane.0] = -3.0 * dr * w * w * cos + r * w * w * w * sin;
        p3[a.plane.1] = -3.0 * dr * w * w * sin - r * w * w * w * cos;
        return p3;
    }
    let (sin, cos) = (a.start_angle + a.sweep * a.sweep_fraction(q)).sin_cos();
    let (_, h) = a.growth();
    let r = a.radius + d * q;
    let c = a.sweep * h / len;
    let w = c / r;
    let dr = d / len;
    let w1 = -w * dr / r;
    let (n1, n2) = ([-sin, cos], [cos, sin]);
    for k in 0..2 {
        let axis = if k == 0 { a.plane.0 } else { a.plane.1 };
        p3[axis] = w1 * (dr * n1[k] - c * n2[k]) - w * w * (dr * n2[k] + c * n1[k]);
    }
    p3
}

/// How fast the path speed can change from rest or toward it: |u| ≤ `a`
/// and |u| ≤ `c`·v^½ (the tangential jerk condition).
#[derive(Clone, Copy, Debug)]
struct Ramp {
    a: f64,
    c: f64,
    /// The speed where the two meet, (a/c)².
    knee: f64,
}

impl Ramp {
    fn new(a: f64, c: f64) -> Ramp {
        let knee = if c.is_finite() { (a / c).powi(2) } else { 0.0 };
        Ramp { a, c, knee }
    }

    /// Path length to change speed from `v0` to `v` ≥ `v0` as fast as
    /// allowed.
    fn length(&self, v0: f64, v: f64) -> f64 {
        let mut len = 0.0;
        if v0 < self.knee {
            let top = v.min(self.knee);
            len += 2.0 / (3.0 * self.c) * (top.powf(1.5) - v0.powf(1.5));
        }
        let from = v0.max(self.knee);
        if v > from {
            len += (v * v - from * from) / (2.0 * self.a);
        }
        len
    }

    /// The speed reached from `v0` after `len` of path, changing speed as
    /// fast as allowed (the inverse of [`length`](Self::length)).
    fn reach(&self, v0: f64, len: f64) -> f64 {
        if !self.a.is_finite() {
            return f64::INFINITY;
        }
        let mut v = v0;
        let mut left = len;
        if v0 < self.knee {
            let to_knee = self.length(v0, self.knee);
            if left <= to_knee {
                return (v0.powf(1.5) + 1.5 * self.c * left).powf(2.0 / 3.0);
            }
            left -= to_knee;
            v = self.knee;
        }
        (v * v + 2.0 * self.a * left).sqrt()
    }

    /// Time to change speed from `v0` to `v` ≥ `v0` as fast as allowed.
    fn time(&self, v0: f64, v: f64) -> f64 {
        let mut t = 0.0;
        if v0 < self.knee {
            let top = v.min(self.knee);
            t += 2.0 / self.c * (top.sqrt() - v0.sqrt());
        }
        let from = v0.max(self.knee);
        if v > from {
            t += (v - from) / self.a;
        }
        t
    }
}

/// x = v² after `ds` of speeding up from x0 as fast as u ≤ c·v^½ lets
/// it: v^{3/2} grows by 1.5·c·ds.
fn ramp_rise(x0: f64, c: f64, ds: f64) -> f64 {
    if !c.is_finite() {
        return f64::INFINITY;
    }
    (x0.max(0.0).powf(0.75) + 1.5 * c * ds).powf(4.0 / 3.0)
}

/// Time to cover `ds` speeding up from `v0` as fast as u ≤ c·v^½ lets it,
/// (2/c)·(√v(ds) − √v0): every trajectory under that condition takes at
/// least this long.
fn ramp_time(v0: f64, c: f64, ds: f64) -> f64 {
    if !c.is_finite() {
        return 0.0;
    }
    let end = ramp_rise(v0 * v0, c, ds).sqrt();
    Ramp::new(f64::INFINITY, c).time(v0, end)
}

/// Time along a line of length `len` from speed `v0` to `v1`, speeding up
/// as `up` allows, slowing down as `down` allows, at most sqrt(`xmax`):
/// speed up, cruise if there is room, slow down.
fn line_time(v0: f64, v1: f64, xmax: f64, up: Ramp, down: Ramp, len: f64) -> f64 {
    if !up.a.is_finite() {
        return len / xmax.sqrt();
    }
    let vm = xmax.sqrt();
    let (v0, v1) = (v0.min(vm), v1.min(vm));
    let span = |v: f64| up.length(v0, v) + down.length(v1, v);
    let time = |v: f64| up.time(v0, v) + down.time(v1, v);
    let cruise = len - span(vm);
    if cruise >= 0.0 {
        return time(vm) + cruise / vm;
    }
    // The peak speed: where the two ramps meet (span grows with v).
    let (mut lo, mut hi) = (v0.max(v1), vm);
    if span(lo) >= len {
        return time(lo);
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if span(mid) < len {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    time(lo)
}

/// The u = dv/dt for which a coordinate with tangent `tc` (non-zero) and
/// curvature `kc` keeps |u·tc + x·kc| within its acceleration limit `a`.
fn accel_interval(a: f64, tc: f64, kc: f64, x: f64) -> (f64, f64) {
    let (p, q) = ((a - x * kc) / tc, (-a - x * kc) / tc);
    (p.min(q), p.max(q))
}

/// A point of a piece of path for [`TimeBound::round_crests`].
#[derive(Clone, Copy, Debug)]
struct CrestPoint {
    /// Path position from the piece's start, mm.
    s: f64,
    /// Upper bound on v³ here, mm³/s³.
    f: f64,
    /// Φ here (Φ″ = 3·Ĵ⁻, Φ = Φ′ = 0 at the piece's start), mm³/s³.
    phi: f64,
    /// The step whose time the way into this point belongs to.
    step: usize,
    /// The nodes at this point (first, last; more than one at a
    /// junction), none for a point inside a line.
    nodes: Option<(usize, usize)>,
}

/// Lower the points of `piece` to the lower convex hull of f + Φ, write
/// the nodes' new speeds into `v` and add the time this costs to `step`
/// (trapezoids in v, against the same on the speeds before).
fn round_piece(piece: &mut [CrestPoint], hull: &mut Vec<usize>, v: &mut [f64], step: &mut [f64]) {
    if piece.len() < 3 {
        return;
    }
    let g = |p: &CrestPoint| p.f + p.phi;
    hull.clear();
    for i in 0..piece.len() {
        while hull.len() >= 2 {
            let (a, b) = (&piece[hull[hull.len() - 2]], &piece[hull[hull.len() - 1]]);
            let c = &piece[i];
            // Drop b if it lies on or above the chord from a to c.
            let cross = (b.s - a.s) * (g(c) - g(a)) - (g(b) - g(a)) * (c.s - a.s);
            if cross <= 0.0 {
                hull.pop();
            } else {
                break;
            }
        }
        hull.push(i);
    }
    let mut before = piece[0].f.cbrt();
    let mut edge = 0;
    for i in 0..piece.len() {
        while edge + 1 < hull.len() - 1 && hull[edge + 1] <= i {
            edge += 1;
        }
        let (a, b) = (
            &piece[hull[edge]],
            &piece[hull[(edge + 1).min(hull.len() - 1)]],
        );
        let on = if b.s > a.s {
            g(a) + (g(b) - g(a)) * (piece[i].s - a.s) / (b.s - a.s)
        } else {
            g(a)
        };
        let f = (on - piece[i].phi).clamp(0.0, piece[i].f);
        let old = piece[i].f.cbrt();
        piece[i].f = f;
        if i > 0 {
            let (p, q) = (&piece[i - 1], &piece[i]);
            let h = q.s - p.s;
            let now = p.f.cbrt() + q.f.cbrt();
            let was = before + old;
            if was > 0.0 {
                step[q.step] += 2.0 * h / now - 2.0 * h / was;
            }
        }
        before = old;
        if let Some((first, last)) = piece[i].nodes {
            for speed in &mut v[first..=last] {
                *speed = speed.min(f.cbrt());
            }
        }
    }
}

/// The bound for a list of planned segments (markers included) on `kins`.
pub fn lower_bound<'a>(
    segments: impl IntoIterator<Item = &'a Segment>,
    kins: &dyn Kinematics,
    config: BoundConfig,
) -> Profile {
    let mut bound = TimeBound::new(kins, config);
    for s in segments {
        bound.push(s);
    }
    bound.solve()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::norm;

    fn v(x: f64, y: f64, z: f64) -> Vec9 {
        [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    }

    #[test]
    fn arc_third_derivative_matches_the_curvature_and_vanishes_on_the_normal_of_a_helix() {
        // A spiral helix: the end 0.3 mm off the start circle, Z moving.
        let spiral = Arc::from_program(
            &v(15.0, 0.0, 0.0),
            &v(0.0, 5.3, -2.0),
            (0, 1),
            (0.0, 0.0),
            1,
        );
        let helix = Arc::from_program(&v(5.0, 0.0, 0.0), &v(0.0, 5.0, -2.0), (0, 1), (0.0, 0.0), 1);
        let spiral = Arc {
            start: v(5.0, 0.0, 0.0),
            radius: 5.0,
            ..spiral
        };
        for (arc, spirals) in [(spiral, true), (helix, false)] {
            let shape = Shape::Arc(arc);
            let len = shape.length();
            let h = 1e-5;
            for k in 1..10 {
                let s = len * k as f64 / 10.0;
                let (a, b) = (shape.frame(s - h), shape.frame(s + h));
                let p3 = arc_third(&arc, s, len);
                for i in 0..3 {
                    let want = (b.curvature[i] - a.curvature[i]) / (2.0 * h);
                    assert!((p3[i] - want).abs() < 1e-6, "{i}: {} vs {want}", p3[i]);
                }
                let f = shape.frame(s);
                let kn = norm(&f.curvature);
                let along: f64 = (0..9).map(|i| p3[i] * f.curvature[i] / kn).sum();
                assert_eq!(along.abs() > 1e-6, spirals, "{along}");
            }
        }
    }
}
