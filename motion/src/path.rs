//! Path geometry: the shapes a segment follows, parametrised by arc length.
//!
//! Every shape maps a distance `s` in `0..=length` (mm, or degrees for pure
//! rotary moves) to a point in the nine machine axes, and gives the unit
//! tangent and the curvature vector (second derivative by arc length) the
//! planner needs to respect acceleration and jerk limits.

/// A point or vector in the nine machine axes X Y Z A B C U V W.
pub type Vec9 = [f64; 9];

fn add(a: &Vec9, b: &Vec9, k: f64) -> Vec9 {
    let mut r = [0.0; 9];
    for i in 0..9 {
        r[i] = a[i] + b[i] * k;
    }
    r
}

/// Euclidean norm.
pub fn norm(v: &Vec9) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// X Y Z distance from `p` to the segment `a`–`b` (the other axes do not
/// count: path tolerances are in the tool's space).
pub fn distance_to_segment(p: &Vec9, a: &Vec9, b: &Vec9) -> f64 {
    Near::between(a, b).distance2(&[p[0], p[1], p[2]]).sqrt()
}

/// A segment (X Y Z) made ready for many distance tests, as the blend
/// proofs make: its start, its span and 1/|span|².
#[derive(Clone, Copy, Debug)]
pub(crate) struct Near {
    start: [f64; 3],
    span: [f64; 3],
    inv: f64,
}

impl Near {
    pub(crate) fn new(l: &Line) -> Near {
        Near::between(&l.start, &l.end)
    }

    fn between(a: &Vec9, b: &Vec9) -> Near {
        let span: [f64; 3] = std::array::from_fn(|i| b[i] - a[i]);
        let dd = span[0] * span[0] + span[1] * span[1] + span[2] * span[2];
        Near {
            start: [a[0], a[1], a[2]],
            span,
            inv: if dd > 0.0 { 1.0 / dd } else { 0.0 },
        }
    }

    /// Squared distance from `p` to the segment.
    pub(crate) fn distance2(&self, p: &[f64; 3]) -> f64 {
        let (d, w): (&[f64; 3], [f64; 3]) =
            (&self.span, std::array::from_fn(|i| p[i] - self.start[i]));
        let t = ((w[0] * d[0] + w[1] * d[1] + w[2] * d[2]) * self.inv).clamp(0.0, 1.0);
        let e: [f64; 3] = std::array::from_fn(|i| w[i] - t * d[i]);
        e[0] * e[0] + e[1] * e[1] + e[2] * e[2]
    }

    /// Whether every control point of `points` is within √`limit2` of the
    /// segment: then, by the convex hull property and the convexity of the
    /// distance to a segment, so is the whole curve piece they control.
    pub(crate) fn hull_within(&self, points: &[[f64; 3]; 6], limit2: f64) -> bool {
        // All six distances, then the test: without an early exit the
        // compiler evaluates several points per instruction, and the
        // answer is the same.
        let mut inside = [false; 6];
        for (inside, p) in inside.iter_mut().zip(points) {
            *inside = self.distance2(p) <= limit2;
        }
        inside.iter().all(|&x| x)
    }
}

/// A straight line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Line {
    pub start: Vec9,
    pub end: Vec9,
}

/// A circular arc in a plane, optionally a helix along the plane's normal
/// axis, with any other axes moving linearly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arc {
    /// Indices of the plane's first and second axes (e.g. X=0, Y=1 for G17).
    pub plane: (usize, usize),
    /// Centre in the plane's two coordinates.
    pub center: (f64, f64),
    pub radius: f64,
    /// Radius at the end: programs give end points a hair off the circle,
    /// and the arc then spirals to end exactly there: a logarithmic
    /// spiral, radius geometric in angle (and linear in arc length), so the
    /// tool moves at the path speed all along it, its tangent a unit
    /// vector at its ends as at lines and blends.
    pub end_radius: f64,
    /// Angle of the start point, radians, measured from the first axis.
    pub start_angle: f64,
    /// Signed sweep, radians: positive counter-clockwise (G3).
    pub sweep: f64,
    /// Start and end of every axis; the plane axes' entries are ignored,
    /// the others move linearly with the angle (helix, rotary axes).
    pub start: Vec9,
    pub end: Vec9,
}

/// Intervals of a blend's arc-length table (see [`Blend::sampled`] for how
/// it is integrated).
pub const TABLE: usize = 8;

/// How far along its lines a corner blend's inner control points reach:
/// the length of its end derivatives over the sum of its legs (σ; 1 spaces
/// the three control points on each line evenly), by turn angle in degrees,
/// linear in between.
///
/// Evenly spaced points suit gentle corners, but past 90° they pack the
/// turn into the middle of the blend: in a 150° corner the jerk from the
/// curvature rate then caps the speed so low that the blend takes 5.5 times
/// as long as one with σ = 0.475, for the same deviation. These values
/// minimise length / speed with the speed capped by v³·|d³p/ds³| ≤ J and
/// the legs sized to the tolerance (numerical optimum over σ at each
/// angle; the tests check the gain on 90° and 150° corners).
const SPREAD: [(f64, f64); 12] = [
    (60.0, 1.0),
    (70.0, 0.975),
    (80.0, 0.95),
    (90.0, 0.9),
    (100.0, 0.85),
    (110.0, 0.8),
    (120.0, 0.725),
    (130.0, 0.65),
    (140.0, 0.575),
    (150.0, 0.475),
    (160.0, 0.325),
    (170.0, 0.2),
];

/// σ of [`SPREAD`] for a corner with |u1 − u2| = `bend`: the planner's
/// corner blends have end derivatives σ·(sum of legs) long.
pub fn corner_spread(bend: f64) -> f64 {
    // Up to the first angle in the table (|u1 − u2| = 2·sin(θ/2) ≤ 1 up to
    // 60°, the dense curves) no arcsine is needed.
    if bend <= 1.0 {
        return SPREAD[0].1;
    }
    let degrees = 2.0 * (bend / 2.0).min(1.0).asin().to_degrees();
    // Past 60°, so at least one entry is at or below `degrees`.
    let k = SPREAD.partition_point(|&(angle, _)| angle <= degrees);
    if k == SPREAD.len() {
        return SPREAD[k - 1].1;
    }
    let ((a0, s0), (a1, s1)) = (SPREAD[k - 1], SPREAD[k]);
    s0 + (s1 - s0) * (degrees - a0) / (a1 - a0)
}

/// A G2-continuous corner blend: a quintic Bézier whose ends take the
/// point, tangent and curvature of what it joins ([`Blend::hermite`]);
/// between lines with zero end curvature ([`Blend::corner`]) its first
/// three and last three control points lie on the lines.
///
/// Only X Y Z move along a blend (the planner blends only moves of X Y Z),
/// so it keeps X Y Z control points and where the other axes stand: half
/// the size of nine-axis control points, in a segment that queues copy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    /// X Y Z control points, mm.
    pub control: [[f64; 3]; 6],
    /// A B C U V W, which stay where they are along the blend.
    pub rest: [f64; 6],
    /// Arc length from the start at parameter u = i/TABLE, i = 0..=TABLE.
    pub table: [f64; TABLE + 1],
}

/// The shape of a segment.
///
/// Kept inline rather than boxed: segments are `Copy` values in a
/// preallocated ring that the servo thread reads without allocating.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    Line(Line),
    Arc(Arc),
    Blend(Blend),
}

/// Where a point on a shape is, and how the shape bends there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub point: Vec9,
    /// Unit tangent, d point / ds.
    pub tangent: Vec9,
    /// Curvature vector, d² point / ds².
    pub curvature: Vec9,
}

impl Line {
    /// Length by LinuxCNC's rule: XYZ distance if XYZ move, else ABC, else UVW.
    pub fn length(&self) -> f64 {
        let d: Vec9 = std::array::from_fn(|i| self.end[i] - self.start[i]);
        let part = |r: std::ops::Range<usize>| d[r].iter().map(|x| x * x).sum::<f64>().sqrt();
        [part(0..3), part(3..6), part(6..9)]
            .into_iter()
            .find(|&l| l > 0.0)
            .unwrap_or(0.0)
    }

    /// d point / ds: the direction scaled so the path length is `length()`.
    pub fn direction(&self) -> Vec9 {
        let l = self.length();
        if l == 0.0 {
            return [0.0; 9];
        }
        std::array::from_fn(|i| (self.end[i] - self.start[i]) / l)
    }
}

impl Arc {
    /// The arc a program asks for: from `start` to `end` (machine
    /// coordinates) about `center` (coordinates on the plane's first and
    /// second axes, indices `plane`), turning `turns` as LinuxCNC counts it:
    /// positive counter-clockwise seen from the plane's normal, magnitude 1
    /// plus the number of extra full turns. Start equal to end in the plane
    /// is a full circle.
    pub fn from_program(
        start: &Vec9,
        end: &Vec9,
        plane: (usize, usize),
        center: (f64, f64),
        turns: i32,
    ) -> Arc {
        let (a, b) = plane;
        let a0 = (start[b] - center.1).atan2(start[a] - center.0);
        let a1 = (end[b] - center.1).atan2(end[a] - center.0);
        let tau = 2.0 * std::f64::consts::PI;
        let extra = (turns.unsigned_abs().max(1) - 1) as f64 * tau;
        let same = (start[a] - end[a]).abs() < 1e-12 && (start[b] - end[b]).abs() < 1e-12;
        let sweep = if turns >= 0 {
            let mut d = a1 - a0;
            while d <= 0.0 && !(same && d == 0.0) {
                d += tau;
            }
            if same {
                d = tau;
            }
            d + extra
        } else {
            let mut d = a1 - a0;
            while d >= 0.0 && !(same && d == 0.0) {
                d -= tau;
            }
            if same {
                d = -tau;
            }
            d - extra
        };
        let radius = ((start[a] - center.0).powi(2) + (start[b] - center.1).powi(2)).sqrt();
        let end_radius = ((end[a] - center.0).powi(2) + (end[b] - center.1).powi(2)).sqrt();
        Arc {
            plane,
            center,
            radius,
            end_radius,
            start_angle: a0,
            sweep,
            start: *start,
            end: *end,
        }
    }

    fn axial_delta(&self) -> Vec9 {
        let mut d: Vec9 = std::array::from_fn(|i| self.end[i] - self.start[i]);
        d[self.plane.0] = 0.0;
        d[self.plane.1] = 0.0;
        d
    }

    /// ln(end radius / radius), the spiral's growth over the sweep (0 on a
    /// circle), and h = (end radius − radius) / growth, which tends to the
    /// radius as the spiral tends to a circle: the in-plane length is
    /// √(D² + (h·sweep)²) for a radius change D.
    pub(crate) fn growth(&self) -> (f64, f64) {
        if !self.is_logarithmic() {
            return (0.0, self.radius);
        }
        let d = self.end_radius - self.radius;
        let growth = (d / self.radius).ln_1p();
        (growth, d / growth)
    }

    /// Whether the arc is a logarithmic spiral (see
    /// [`end_radius`](Self::end_radius)). Not a circle, and not one that
    /// starts or ends at (or within a thousandth of its larger radius of)
    /// its centre, which no such spiral reaches: those, only possible on
    /// arcs under the interpreter's spiral tolerance, keep the radius
    /// linear in angle, and their speed along the path varies with it.
    pub(crate) fn is_logarithmic(&self) -> bool {
        let (low, high) = (
            self.radius.min(self.end_radius),
            self.radius.max(self.end_radius),
        );
        // Radii a rounding apart have a ratio of 1 and no growth.
        low != high && low > 1e-3 * high && low / high < 1.0
    }

    /// Length of the in-plane part, mm.
    pub fn in_plane_length(&self) -> f64 {
        self.in_plane_length_with(self.growth())
    }

    /// [`in_plane_length`](Self::in_plane_length) given
    /// [`growth`](Self::growth).
    fn in_plane_length_with(&self, (growth, h): (f64, f64)) -> f64 {
        if growth == 0.0 {
            return (self.radius + self.end_radius) / 2.0 * self.sweep.abs();
        }
        let d = self.end_radius - self.radius;
        (d * d + (h * self.sweep).powi(2)).sqrt()
    }

    /// Helix length: the in-plane arc and the linear axes (XYZ part only
    /// when XYZ move, as for lines).
    pub fn length(&self) -> f64 {
        self.length_with(self.growth())
    }

    /// [`length`](Self::length) given [`growth`](Self::growth): the
    /// executor's frame on a spiral needs both, every servo period.
    fn length_with(&self, growth: (f64, f64)) -> f64 {
        let d = self.axial_delta();
        let xyz_axial: f64 = d[..3].iter().map(|x| x * x).sum();
        let in_plane = self.in_plane_length_with(growth);
        (in_plane * in_plane + xyz_axial).sqrt()
    }

    /// Radius at fraction `f` of the sweep: geometric in f (linear on
    /// the spirals that are not logarithmic).
    fn radius_at(&self, f: f64) -> f64 {
        let (growth, _) = self.growth();
        if growth == 0.0 {
            self.radius + (self.end_radius - self.radius) * f
        } else {
            self.radius * (growth * f).exp()
        }
    }

    /// Fraction of the length (and of the linear axes' travel) at fraction
    /// `f` of the sweep: the radius is linear in length.
    fn length_fraction(&self, f: f64) -> f64 {
        let (growth, _) = self.growth();
        if growth == 0.0 {
            f
        } else {
            // (r(f) − r0) / (r1 − r0), without the cancellation when the
            // radii differ only in rounding.
            (growth * f).exp_m1() / growth.exp_m1()
        }
    }

    /// Fraction of the sweep at fraction `q` of the arc's length: the
    /// inverse of [`length_fraction`](Self::length_fraction).
    pub fn sweep_fraction(&self, q: f64) -> f64 {
        self.sweep_fraction_with(q, self.growth().0)
    }

    /// [`sweep_fraction`](Self::sweep_fraction) given the spiral's growth.
    fn sweep_fraction_with(&self, q: f64, growth: f64) -> f64 {
        if growth == 0.0 {
            return q;
        }
        ((self.end_radius - self.radius) / self.radius * q).ln_1p() / growth
    }

    /// Point at fraction `f` (0 to 1) of the sweep, the linear axes in
    /// proportion to the length travelled: the ends exactly as programmed.
    pub fn point_at_fraction(&self, f: f64) -> Vec9 {
        if f <= 0.0 {
            return self.start;
        }
        if f >= 1.0 {
            return self.end;
        }
        let theta = self.start_angle + self.sweep * f;
        let r = self.radius_at(f);
        let q = self.length_fraction(f);
        let axial = self.axial_delta();
        let mut p: Vec9 = std::array::from_fn(|i| self.start[i] + axial[i] * q);
        p[self.plane.0] = self.center.0 + r * theta.cos();
        p[self.plane.1] = self.center.1 + r * theta.sin();
        p
    }

    /// The stretch of this arc from fraction `f0` to `f1` of its sweep
    /// (0 ≤ f0 ≤ f1 ≤ 1): the same circle, spiral or helix, so its points
    /// at any fraction are this arc's at the matching fraction.
    pub fn part(&self, f0: f64, f1: f64) -> Arc {
        Arc {
            plane: self.plane,
            center: self.center,
            radius: self.radius_at(f0),
            end_radius: self.radius_at(f1),
            start_angle: self.start_angle + self.sweep * f0,
            sweep: self.sweep * (f1 - f0),
            start: self.point_at_fraction(f0),
            end: self.point_at_fraction(f1),
        }
    }

    /// Chords of the stretch from fraction `f0` to `f1`, as lines, and how
    /// far any point of a chord can be from the arc, mm: at most `sag`,
    /// with no more than `most` chords (then the bound is what they give).
    ///
    /// Interpolating p(f) linearly over Δf strays at most Δf²/8·max|p″|.
    /// On a logarithmic spiral, in the plane p(f) is r0·e^((g + i·S)·f) as a complex number (growth
    /// g, sweep S), so |p″| = (g² + S²)·r ≤ (g² + S²)·r_max; the linear
    /// axes move in proportion to r − r0, which adds (travel / D)·g²·r_max.
    pub fn chords(&self, f0: f64, f1: f64, sag: f64, most: usize) -> (Vec<Line>, f64) {
        let (growth, _) = self.growth();
        let r_max = self.radius.max(self.end_radius);
        let d = self.end_radius - self.radius;
        let curl = if growth == 0.0 {
            // Radius linear in f: |p″| ≤ 2·|dr/df|·|dθ/df| + r_max·(dθ/df)²,
            // the linear axes in proportion to f.
            2.0 * d.abs() * self.sweep.abs() + r_max * self.sweep * self.sweep
        } else {
            let axial = norm(&self.axial_delta()) / d.abs() * growth * growth * r_max;
            (growth * growth + self.sweep * self.sweep) * r_max + axial
        };
        let span = (f1 - f0).max(0.0);
        let n = if sag > 0.0 {
            (span * (curl / (8.0 * sag)).sqrt()).ceil() as usize
        } else {
            most
        }
        .clamp(1, most.max(1));
        let step = span / n as f64;
        let lines = (0..n)
            .map(|k| Line {
                start: self.point_at_fraction(f0 + step * k as f64),
                end: self.point_at_fraction(if k + 1 == n {
                    f1
                } else {
                    f0 + step * (k + 1) as f64
                }),
            })
            .collect();
        (lines, step * step / 8.0 * curl)
    }
}

impl Blend {
    /// The blend of the corner at `corner` between incoming unit direction
    /// `u_in` and outgoing `u_out`, starting `leg` before the corner and
    /// ending `leg` after it, with zero curvature at both ends.
    ///
    /// Its greatest distance from the corner is [`Blend::deviation`].
    pub fn corner(corner: &Vec9, u_in: &Vec9, u_out: &Vec9, leg: f64) -> Blend {
        let zero = [0.0; 9];
        Blend::hermite(
            &add(corner, u_in, -leg),
            u_in,
            &zero,
            &add(corner, u_out, leg),
            u_out,
            &zero,
            2.0 * leg * corner_spread(norm(&add(u_out, u_in, -1.0))),
        )
    }

    /// The quintic from `p0` to `p1` with unit tangents `t0`, `t1` and
    /// curvature vectors `k0`, `k1` (perpendicular to the tangents) at its
    /// ends: G2 continuity with whatever it joins. `scale` is the length of
    /// the end derivatives, about the curve's length.
    pub fn hermite(
        p0: &Vec9,
        t0: &Vec9,
        k0: &Vec9,
        p1: &Vec9,
        t1: &Vec9,
        k1: &Vec9,
        scale: f64,
    ) -> Blend {
        Blend::from_control(Blend::hermite_control(p0, t0, k0, p1, t1, k1, scale))
    }

    /// The control points of [`hermite`](Self::hermite).
    pub fn hermite_control(
        p0: &Vec9,
        t0: &Vec9,
        k0: &Vec9,
        p1: &Vec9,
        t1: &Vec9,
        k1: &Vec9,
        scale: f64,
    ) -> [Vec9; 6] {
        // B′(0) = 5(Q1 − Q0), B″(0) = 20(Q2 − 2Q1 + Q0), and mirrored at 1:
        // with B′ = scale·t and B″ = scale²·k these give the control points.
        let l2 = scale * scale;
        // Axes whose tangent and curvature are zero at both ends stand at
        // the end points; past X Y Z that is every blend the planner
        // makes, so only X Y Z are worked out then (a third of the
        // arithmetic, which showed in planning dense curves).
        let still = |v: &Vec9| v[3..].iter().all(|&x| x == 0.0);
        let moving = if still(t0) && still(k0) && still(t1) && still(k1) {
            3
        } else {
            9
        };
        let mut q = [*p0, *p0, *p0, *p1, *p1, *p1];
        for i in 0..moving {
            q[1][i] = p0[i] + scale * t0[i] / 5.0;
            q[2][i] = p0[i] + 2.0 * scale * t0[i] / 5.0 + l2 * k0[i] / 20.0;
            q[3][i] = p1[i] - 2.0 * scale * t1[i] / 5.0 + l2 * k1[i] / 20.0;
            q[4][i] = p1[i] - scale * t1[i] / 5.0;
        }
        q
    }

    /// The blend with these control points, with its arc-length table.
    pub fn from_control(control: [Vec9; 6]) -> Blend {
        Blend::sampled(control).0
    }

    /// The blend with these control points, with its arc-length table, and
    /// the extremes of its tangent, curvature and curvature rate over
    /// [`SAMPLES`] + 1 evenly spaced parameters (9 on a smooth blend, a
    /// dense curve's: [`Sampling`]), which the planner needs for its
    /// limits: one pass of polynomial evaluations gives both.
    ///
    /// The arc lengths between samples (trapezoids with the end-derivative
    /// correction) only scale the interval means of the curvature rate;
    /// they agree with the table to about 1e-8 of the length.
    pub fn sampled(control: [Vec9; 6]) -> (Blend, BlendExtremes) {
        // The same code compiled for AVX where the processor has it: twice
        // the parameters per instruction. Without FMA every operation rounds
        // as in the baseline build, so the results are the same bit for bit.
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: the processor supports AVX, checked just above.
            return unsafe { Blend::sampled_avx(control) };
        }
        Blend::sampled_here(control)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn sampled_avx(control: [Vec9; 6]) -> (Blend, BlendExtremes) {
        Blend::sampled_here(control)
    }

    /// [`sampled`](Self::sampled) for whatever instruction set the caller
    /// is compiled for (inlined into it).
    #[inline(always)]
    fn sampled_here(control: [Vec9; 6]) -> (Blend, BlendExtremes) {
        let poly = Poly::new(&control);
        let out = match Sampling::of(&control) {
            Sampling::Smooth => extremes::<
                SMOOTH_SAMPLES,
                { SMOOTH_SAMPLES + 1 },
                { SMOOTH_SAMPLES + 2 },
            >(&poly, Sampling::Smooth),
            kind => extremes::<SAMPLES, { SAMPLES + 1 }, { SAMPLES + 2 }>(&poly, kind),
        };
        // The table by five-point Gauss–Legendre on each interval: the same
        // rule `parameter` integrates with inside an interval, so the
        // arc-length parametrisation is continuous across table entries.
        // All intervals' nodes in one array, as above.
        const G: usize = 5 * TABLE;
        const NODES: ([f64; G], [f64; G]) = {
            let half = 0.5 / TABLE as f64;
            let (mut node, mut weight) = ([0.0; G], [0.0; G]);
            let mut k = 0;
            while k < G {
                node[k] = (2 * (k / 5) + 1) as f64 * half + GAUSS_X[k % 5] * half;
                weight[k] = GAUSS_W[k % 5] * half;
                k += 1;
            }
            (node, weight)
        };
        let (node, weight) = (&NODES.0, &NODES.1);
        let mut v = [[0.0; G]; 3];
        for i in 0..3 {
            let c = &poly.d1[i];
            for k in 0..G {
                let u = node[k];
                v[i][k] = (((c[4] * u + c[3]) * u + c[2]) * u + c[1]) * u + c[0];
            }
        }
        let mut weighted = [0.0; G];
        for k in 0..G {
            let norm = (v[0][k] * v[0][k] + v[1][k] * v[1][k] + v[2][k] * v[2][k]).sqrt();
            weighted[k] = weight[k] * norm;
        }
        let mut b = Blend::untabled(control);
        for i in 0..TABLE {
            let w = &weighted[5 * i..5 * i + 5];
            b.table[i + 1] = b.table[i] + (w[0] + w[1] + w[2] + w[3] + w[4]);
        }
        (b, out)
    }

    /// The blend without its arc-length table: enough for
    /// [`point_at_parameter`](Self::point_at_parameter), e.g. to test a
    /// candidate shape before keeping it.
    pub fn untabled(control: [Vec9; 6]) -> Blend {
        let mut rest = [0.0; 6];
        rest.copy_from_slice(&control[0][3..]);
        Blend {
            control: control.map(|q| [q[0], q[1], q[2]]),
            rest,
            table: [0.0; TABLE + 1],
        }
    }

    /// The point with X Y Z `xyz` and the other axes where the blend
    /// holds them.
    fn with_rest(&self, xyz: [f64; 3]) -> Vec9 {
        let mut p = [0.0; 9];
        p[..3].copy_from_slice(&xyz);
        p[3..].copy_from_slice(&self.rest);
        p
    }

    /// Control point `k` (0..6) with every axis.
    pub fn control_point(&self, k: usize) -> Vec9 {
        self.with_rest(self.control[k])
    }

    /// All six control points with every axis, as [`sampled`](Self::sampled)
    /// takes them.
    pub fn control_points(&self) -> [Vec9; 6] {
        std::array::from_fn(|k| self.control_point(k))
    }

    /// |d B / du| (the hodograph's length), cheaper than computing all three derivatives.
    pub fn speed(&self, u: f64) -> f64 {
        Poly::new(&self.control).speed(u)
    }

    /// Point, unit tangent and curvature vector at Bézier parameter `u`.
    pub fn frame_at_parameter(&self, u: f64) -> Frame {
        let (p, d1, d2) = self.derivatives(u);
        let speed = norm(&d1);
        let t: Vec9 = std::array::from_fn(|i| d1[i] / speed);
        let along: f64 = (0..9).map(|i| d2[i] * t[i]).sum();
        Frame {
            point: p,
            tangent: t,
            curvature: std::array::from_fn(|i| (d2[i] - along * t[i]) / (speed * speed)),
        }
    }

    /// d|κ|/ds at Bézier parameter `u`: the rate of change of the
    /// curvature's magnitude along the arc length, which is κ′·n (κ′ =
    /// d³p/ds³, n the unit normal). With B′, B″, B‴ the derivatives in u
    /// and σ = |B′|: |κ| = |B′ × B″| / σ³, differentiated in u, over σ.
    /// Zero where the blend is straight (no normal).
    pub fn curvature_rate_at_parameter(&self, u: f64) -> f64 {
        let poly = Poly::new(&self.control);
        let (d1, d2, d3) = (poly.d1(u), poly.d2(u), poly.d3(u));
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let c = cross(d1, d2);
        let dc = cross(d1, d3);
        let (cn, sigma) = (dot(c, c).sqrt(), dot(d1, d1).sqrt());
        if cn == 0.0 || sigma == 0.0 {
            return 0.0;
        }
        let s3 = sigma * sigma * sigma;
        let dk_du = dot(c, dc) / (cn * s3) - 3.0 * cn * dot(d1, d2) / (s3 * sigma * sigma);
        dk_du / sigma
    }

    /// d³p/ds³ (the rate of change of the curvature vector along the arc
    /// length) of X Y Z at Bézier parameter `u`: with B′, B″, B‴ the
    /// derivatives in u, σ = |B′|, σ′ = B′·B″/σ and σ″ = (B″·B″ + B′·B‴)/σ
    /// − σ′²/σ, it is B‴/σ³ − 3σ′B″/σ⁴ + (3σ′² − σσ″)B′/σ⁵.
    pub fn third_at_parameter(&self, u: f64) -> [f64; 3] {
        let poly = Poly::new(&self.control);
        third(poly.d1(u), poly.d2(u), poly.d3(u))
    }

    /// The part of d³p/ds³ orthogonal to the tangent at Bézier parameter
    /// `u`, B‴⊥ / σ³ where the curvature vanishes (B″ parallel to B′, as at
    /// a blend's ends); elsewhere it also has terms in B″.
    pub fn third_normal_where_straight(&self, u: f64) -> Vec9 {
        let poly = Poly::new(&self.control);
        let (d1, d3) = (poly.d1(u), poly.d3(u));
        let sigma2 = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2];
        let mut out = [0.0; 9];
        if sigma2 == 0.0 {
            return out;
        }
        let along = (d3[0] * d1[0] + d3[1] * d1[1] + d3[2] * d1[2]) / sigma2;
        let s3 = sigma2 * sigma2.sqrt();
        for i in 0..3 {
            out[i] = (d3[i] - along * d1[i]) / s3;
        }
        out
    }

    /// Arc length from the start to parameter `u`.
    pub fn length_to(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let i = ((u * TABLE as f64) as usize).min(TABLE - 1);
        self.table[i] + Poly::new(&self.control).speed_integral(i as f64 / TABLE as f64, u)
    }

    /// Distance from the corner to the midpoint of [`Blend::corner`], which
    /// is its greatest distance from the corner: with σ =
    /// [`corner_spread`], (1 + 5·(1 − 0.4σ) + 10·(1 − 0.8σ))/32 · leg ·
    /// |u_out − u_in| = (16 − 10σ)/32 · leg · |u_out − u_in|.
    pub fn deviation(leg: f64, u_in: &Vec9, u_out: &Vec9) -> f64 {
        let bend = norm(&add(u_out, u_in, -1.0));
        (16.0 - 10.0 * corner_spread(bend)) / 32.0 * leg * bend
    }

    /// Point, first and second derivative in the Bézier parameter. Blends
    /// join XYZ-only lines, so only X Y Z vary; the other axes stay put.
    fn derivatives(&self, u: f64) -> (Vec9, Vec9, Vec9) {
        let poly = Poly::new(&self.control);
        let (p3, d13, d23) = (poly.point(u), poly.d1(u), poly.d2(u));
        let p = self.with_rest(p3);
        let mut d1 = [0.0; 9];
        let mut d2 = [0.0; 9];
        d1[..3].copy_from_slice(&d13);
        d2[..3].copy_from_slice(&d23);
        (p, d1, d2)
    }

    /// Point at Bézier parameter `u` (X Y Z vary, as in the derivatives).
    pub fn point_at_parameter(&self, u: f64) -> Vec9 {
        self.with_rest(Poly::new(&self.control).point(u))
    }

    /// Total arc length.
    pub fn length(&self) -> f64 {
        self.table[TABLE]
    }

    /// The Bézier parameter at arc length `s` (Newton from the table).
    pub(crate) fn parameter(&self, s: f64) -> f64 {
        if s <= 0.0 {
            return 0.0;
        }
        if s >= self.length() {
            return 1.0;
        }
        let poly = Poly::new(&self.control);
        let i = self.table.partition_point(|&t| t <= s).clamp(1, TABLE) - 1;
        let (s0, s1) = (self.table[i], self.table[i + 1]);
        let u0 = i as f64 / TABLE as f64;
        let mut u = u0
            + if s1 > s0 {
                (s - s0) / (s1 - s0) / TABLE as f64
            } else {
                0.0
            };
        for _ in 0..3 {
            let err = s0 + poly.speed_integral(u0, u) - s;
            let speed = poly.speed(u);
            if speed <= 0.0 {
                break;
            }
            u = (u - err / speed).clamp(0.0, 1.0);
        }
        u
    }
}

/// The largest |f| of a smooth function between its samples `x` (at
/// least three): between two neighbours, the larger plus `share` of the
/// larger second difference at either (the ends take their neighbour's),
/// for a crest between them. A parabola through three samples rises above
/// them by an eighth of their second difference; the callers take that
/// twice over, or more where the samples are spaced unevenly.
#[inline(always)]
fn crest_bound<const N: usize>(x: &[f64; N], share: f64) -> f64 {
    // Plain comparisons rather than f64::max (no NaN here), and the second
    // differences in an array first: this runs on every blend.
    let larger = |m: f64, v: f64| if v > m { v } else { m };
    let mut second = [0.0; N];
    for k in 1..N - 1 {
        second[k] = (x[k + 1] - 2.0 * x[k] + x[k - 1]).abs();
    }
    second[0] = second[1];
    second[N - 1] = second[N - 2];
    let mut bound = [0.0; N];
    for k in 0..N - 1 {
        let crest = larger(second[k], second[k + 1]);
        bound[k] = larger(x[k].abs(), x[k + 1].abs()) + share * crest;
    }
    largest(&bound)
}

/// The largest of `x` and zero (no NaN), in four running maxima a lane
/// of a vector register each: a maximum does not depend on the order it
/// is taken in, and one running maximum keeps the loop from vectorising.
#[inline(always)]
fn largest<const N: usize>(x: &[f64; N]) -> f64 {
    let larger = |m: f64, v: f64| if v > m { v } else { m };
    let mut lanes = [0.0; 4];
    let mut chunks = x.chunks_exact(4);
    for chunk in &mut chunks {
        for l in 0..4 {
            lanes[l] = larger(lanes[l], chunk[l]);
        }
    }
    for &v in chunks.remainder() {
        lanes[0] = larger(lanes[0], v);
    }
    larger(larger(lanes[0], lanes[1]), larger(lanes[2], lanes[3]))
}

/// d³p/ds³ from the first three derivatives in the Bézier parameter (see
/// [`Blend::third_at_parameter`]); zero where B′ vanishes.
fn third(d1: [f64; 3], d2: [f64; 3], d3: [f64; 3]) -> [f64; 3] {
    let (w1, w2, w3) = third_weights(d1, d2, d3);
    std::array::from_fn(|i| d3[i] * w3 + d2[i] * w2 + d1[i] * w1)
}

/// The weights (w1, w2, w3) with d³p/ds³ = w1·B′ + w2·B″ + w3·B‴, from
/// the derivatives in the Bézier parameter; all zero where B′ vanishes.
/// Written without branches so that loops over parameters vectorise.
#[inline(always)]
fn third_weights(d1: [f64; 3], d2: [f64; 3], d3: [f64; 3]) -> (f64, f64, f64) {
    let s2 = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2];
    let sigma = s2.sqrt();
    let inv = if s2 > 0.0 { 1.0 / sigma } else { 0.0 };
    // σ′ = B′·B″/σ and σ″ = (|B″|² + B′·B‴)/σ − σ′²/σ.
    let ds = (d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]) * inv;
    let dds = (d2[0] * d2[0]
        + d2[1] * d2[1]
        + d2[2] * d2[2]
        + d1[0] * d3[0]
        + d1[1] * d3[1]
        + d1[2] * d3[2])
        * inv
        - ds * ds * inv;
    let inv3 = inv * inv * inv;
    let inv4 = inv3 * inv;
    (
        (3.0 * ds * ds - sigma * dds) * inv4 * inv,
        -3.0 * ds * inv4,
        inv3,
    )
}

/// `N` evenly spaced parameters from 0 to 1, both included.
const fn grid<const N: usize>() -> [f64; N] {
    let mut u = [0.0; N];
    let mut k = 0;
    while k < N {
        u[k] = k as f64 / (N - 1) as f64;
        k += 1;
    }
    u
}

/// Five-point Gauss–Legendre nodes on -1..1, and their weights.
const GAUSS_X: [f64; 5] = [
    0.0,
    -0.538_469_310_105_683,
    0.538_469_310_105_683,
    -0.906_179_845_938_664,
    0.906_179_845_938_664,
];
const GAUSS_W: [f64; 5] = [
    0.568_888_888_888_889,
    0.478_628_670_499_366,
    0.478_628_670_499_366,
    0.236_926_885_056_189,
    0.236_926_885_056_189,
];

/// How densely [`Blend::sampled`] samples a blend for its extremes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sampling {
    /// A control polygon that bends by at most [`SMOOTH_BEND`] at each
    /// point (a dense curve's blends): [`SMOOTH_SAMPLES`] intervals.
    Smooth,
    /// A corner turned by at most 60°: [`SAMPLES`] intervals, the
    /// curvature rate from the interval means and the exact rates at the
    /// ends.
    Gentle,
    /// Sharper: [`SAMPLES`] intervals, the curvature rate exactly at
    /// twice as many parameters.
    Sharp,
}

impl Sampling {
    fn of(control: &[Vec9; 6]) -> Sampling {
        let step =
            |k: usize| -> [f64; 3] { std::array::from_fn(|i| control[k + 1][i] - control[k][i]) };
        let (t0, t1) = (step(0), step(4));
        let dot = t0[0] * t1[0] + t0[1] * t1[1] + t0[2] * t1[2];
        let norms = norm3(&t0) * norm3(&t1);
        // (NaN is sharp, as it always was.)
        if dot.partial_cmp(&(0.5 * norms)) != Some(std::cmp::Ordering::Greater) {
            return Sampling::Sharp;
        }
        // Each step of the control polygon against the mean step: where
        // none differs from the next by more than SMOOTH_BEND of it, the
        // quintic is close to a line traced at an even pace, and its
        // tangent, curvature and curvature rate change slowly enough for
        // a few samples with crest allowances. (Squared lengths: no
        // square roots on every blend.)
        let square = |v: [f64; 3]| v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
        let chord2 = square(std::array::from_fn(|i| control[5][i] - control[0][i]));
        let allowed2 = SMOOTH_BEND * SMOOTH_BEND * chord2 / 25.0;
        let smooth = (0..4).all(|k| {
            let (a, b) = (step(k), step(k + 1));
            square(std::array::from_fn(|i| b[i] - a[i])) <= allowed2
        });
        if smooth && chord2 > 0.0 {
            Sampling::Smooth
        } else {
            Sampling::Gentle
        }
    }
}

/// Parameter intervals of [`Blend::sampled`] on [`Sampling::Smooth`]
/// blends.
const SMOOTH_SAMPLES: usize = 8;

/// Largest difference between neighbouring steps of a
/// [`Sampling::Smooth`] blend's control polygon, as a fraction of the mean
/// step (about the turn in radians between them, where the steps are
/// even).
const SMOOTH_BEND: f64 = 0.1;

/// Length of an X Y Z vector.
pub(crate) fn norm3(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The extremes of [`Blend::sampled`] from `S` intervals of the Bézier
/// parameter (`N` = S + 1 samples, `M` = S + 2).
#[inline(always)]
fn extremes<const S: usize, const N: usize, const M: usize>(
    poly: &Poly,
    kind: Sampling,
) -> BlendExtremes {
    // Loops over arrays of parameters, one axis at a time, so that the
    // compiler evaluates several parameters per instruction (exclusive
    // ranges: inclusive ones keep loops from being vectorised).
    const { assert!(N == S + 1 && M == S + 2) };
    let u: [f64; N] = const { grid() };
    let [d1, d2, _] = poly.derivatives_on::<N, false>(&u);
    let mut speed = [0.0; N];
    let mut inv = [0.0; N];
    for k in 0..N {
        speed[k] = (d1[0][k] * d1[0][k] + d1[1][k] * d1[1][k] + d1[2][k] * d1[2][k]).sqrt();
        inv[k] = 1.0 / speed[k];
    }
    // t = d1/|d1|, and d²p/ds² = (d2 − (d2·t) t) / |d1|² in the Bézier
    // parameter; d2·t is also d|d1|/du.
    let mut tangent = [[0.0; N]; 3];
    let mut curvature = [[0.0; N]; 3];
    let mut along = [0.0; N];
    for i in 0..3 {
        for k in 0..N {
            tangent[i][k] = d1[i][k] * inv[k];
            along[k] += d2[i][k] * tangent[i][k];
        }
    }
    for i in 0..3 {
        for k in 0..N {
            curvature[i][k] = (d2[i][k] - along[k] * tangent[i][k]) * (inv[k] * inv[k]);
        }
    }
    // Arc length between samples by the trapezoidal rule with its
    // end-derivative correction (Euler–Maclaurin), which the speeds and
    // their derivatives at the samples give for free: error O(h⁵),
    // as Simpson's rule.
    let h = 1.0 / S as f64;
    let mut inv_ds = [0.0; S];
    for k in 0..S {
        let ds = h / 2.0 * (speed[k] + speed[k + 1]) + h * h / 12.0 * (along[k] - along[k + 1]);
        inv_ds[k] = if ds > 0.0 { 1.0 / ds } else { 0.0 };
    }
    let mut out = BlendExtremes {
        tangent: [0.0; 3],
        curvature: [0.0; 3],
        curvature_rate: [0.0; 3],
    };
    // Between samples at most the larger neighbour plus a crest
    // allowance, as for the rate below: the largest sample alone fell
    // short of the exact extremes by up to 0.3 % on corners and 4 % on
    // curve blends (the tests `..._extremes_bound_the_exact_ones`).
    for i in 0..3 {
        out.tangent[i] = crest_bound(&tangent[i], 0.25);
        out.curvature[i] = crest_bound(&curvature[i], 0.25);
    }
    // dκ_i/ds exactly at twice as many parameters, and between them at
    // most the larger neighbour plus an allowance for a crest: a
    // parabola through three neighbours rises above its samples by at
    // most an eighth of their second difference, taken twice over.
    // Never below the largest difference of the curvature over an
    // interval's arc length (its mean over the interval) with the 25 %
    // the planner used to add to those alone, so that plans change
    // only where those missed a crest.
    //
    // Only on corners turned by more than 60°: on gentler ones (dense
    // curves, where planning speed matters most) the means and the
    // exact rate at the two ends bound it (below; the tests
    // `sampled_curvature_rate_bounds_the_exact_one` and `..._on_curve_
    // blends` cover both), and the exact rate at 65 parameters would
    // cost a third of the planning throughput.
    if kind != Sampling::Sharp {
        // The rate at the two ends exactly, and between them the means
        // over the intervals, as if samples at their middles: between
        // two neighbours at most the larger plus an allowance for a
        // crest, as below. A mean alone can miss most of an end's
        // rate where the curvature turns fast there (a dense curve's
        // blends take the fitted curve's end curvature): 25 % on top of
        // the means, as this used to add, fell short on stellabee1.ngc.
        // Spaced unevenly at the ends (half an interval), so the crest
        // allowance is twice the one below.
        let ends = [0.0, 1.0].map(|u| third(poly.d1(u), poly.d2(u), poly.d3(u)));
        for i in 0..3 {
            let c = &curvature[i];
            let mut g = [0.0; M];
            g[0] = ends[0][i];
            for k in 0..S {
                g[k + 1] = (c[k + 1] - c[k]) * inv_ds[k];
            }
            g[M - 1] = ends[1][i];
            out.curvature_rate[i] = crest_bound(&g, 0.5);
        }
    } else {
        // `third` over arrays of parameters, as above; the reciprocal
        // of |B′| is zero where B′ vanishes, which zeroes the rate.
        const F: usize = 2 * SAMPLES + 1;
        const UF: [f64; F] = grid();
        let [e1, e2, e3] = poly.derivatives_on::<F, true>(&UF);
        let mut w1 = [0.0; F];
        let mut w2 = [0.0; F];
        let mut w3 = [0.0; F];
        for k in 0..F {
            let (d1, d2, d3) = (
                [e1[0][k], e1[1][k], e1[2][k]],
                [e2[0][k], e2[1][k], e2[2][k]],
                [e3[0][k], e3[1][k], e3[2][k]],
            );
            (w1[k], w2[k], w3[k]) = third_weights(d1, d2, d3);
        }
        let mut rate = [[0.0; F]; 3];
        for i in 0..3 {
            for k in 0..F {
                rate[i][k] = e3[i][k] * w3[k] + e2[i][k] * w2[k] + e1[i][k] * w1[k];
            }
        }
        for i in 0..3 {
            let c = &curvature[i];
            let mut mean = [0.0; S];
            for k in 0..S {
                mean[k] = (c[k + 1] - c[k]).abs() * inv_ds[k];
            }
            let floor = 1.25 * largest(&mean);
            let exact = crest_bound(&rate[i], 0.25);
            // Plain comparison rather than f64::max (no NaN here).
            out.curvature_rate[i] = if exact > floor { exact } else { floor };
        }
    }
    out
}

/// Parameter intervals of [`Blend::sampled`].
pub const SAMPLES: usize = 32;

/// The largest values along a blend, per axis X Y Z, that the planner's
/// limits depend on, from its frames at u = k/SAMPLES, k = 0..=SAMPLES
/// (k/8 on smooth blends, see [`Blend::sampled`]).
#[derive(Clone, Copy, Debug)]
pub struct BlendExtremes {
    /// Bound on |t_i| of the unit tangent: the samples' largest plus a
    /// quarter of the larger neighbouring second difference for a crest
    /// between them.
    pub tangent: [f64; 3],
    /// Bound on |κ_i| of the curvature vector, as for the tangent.
    pub curvature: [f64; 3],
    /// Bound on |dκ_i/ds| (= |d³p_i/ds³|): the exact rate at 2·SAMPLES + 1
    /// parameters plus an allowance for crests between them, and no less
    /// than 1.25·|Δκ_i / Δs| between neighbouring samples.
    pub curvature_rate: [f64; 3],
}

/// X, Y and Z of a blend as polynomials in the Bézier parameter (power
/// basis), with their first and second derivatives: converted once from the
/// control points, each evaluation is then a few multiply-adds per axis.
/// Blends join XYZ-only lines, so the other axes stay put.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Poly {
    /// `p[i][k]`: coefficient of u^k in axis i.
    p: [[f64; 6]; 3],
    d1: [[f64; 5]; 3],
    d2: [[f64; 4]; 3],
}

impl Poly {
    /// The quintic with control points `q`, X Y Z (the first three
    /// coordinates of each).
    pub(crate) fn new<const N: usize>(q: &[[f64; N]; 6]) -> Poly {
        // Bernstein to power basis: c_k = C(5, k)·Δ^k Q_0.
        const BINOMIAL: [f64; 6] = [1.0, 5.0, 10.0, 10.0, 5.0, 1.0];
        let mut poly = Poly {
            p: [[0.0; 6]; 3],
            d1: [[0.0; 5]; 3],
            d2: [[0.0; 4]; 3],
        };
        for i in 0..3 {
            let mut d = [q[0][i], q[1][i], q[2][i], q[3][i], q[4][i], q[5][i]];
            for k in 0..6 {
                poly.p[i][k] = BINOMIAL[k] * d[0];
                for j in 0..5 - k {
                    d[j] = d[j + 1] - d[j];
                }
            }
            for k in 0..5 {
                poly.d1[i][k] = (k + 1) as f64 * poly.p[i][k + 1];
            }
            for k in 0..4 {
                poly.d2[i][k] = (k + 1) as f64 * poly.d1[i][k + 1];
            }
        }
        poly
    }

    fn horner<const N: usize>(c: &[f64; N], u: f64) -> f64 {
        let mut r = c[N - 1];
        for k in (0..N - 1).rev() {
            r = r * u + c[k];
        }
        r
    }

    pub(crate) fn point(&self, u: f64) -> [f64; 3] {
        std::array::from_fn(|i| Self::horner(&self.p[i], u))
    }

    pub(crate) fn d1(&self, u: f64) -> [f64; 3] {
        std::array::from_fn(|i| Self::horner(&self.d1[i], u))
    }

    pub(crate) fn d2(&self, u: f64) -> [f64; 3] {
        std::array::from_fn(|i| Self::horner(&self.d2[i], u))
    }

    /// Third derivative, from the second's coefficients (not stored: only
    /// the lower bound needs it).
    pub(crate) fn d3(&self, u: f64) -> [f64; 3] {
        std::array::from_fn(|i| {
            let c = &self.d2[i];
            c[1] + u * (2.0 * c[2] + u * 3.0 * c[3])
        })
    }

    /// B′, B″ and (with `THIRD`; zeros otherwise) B‴ of each axis X Y Z
    /// at every parameter of `u`, one axis at a time over arrays of
    /// parameters, so that the compiler evaluates several per instruction
    /// (the same values as [`d1`](Self::d1) and its neighbours).
    #[inline(always)]
    fn derivatives_on<const N: usize, const THIRD: bool>(
        &self,
        u: &[f64; N],
    ) -> [[[f64; N]; 3]; 3] {
        let mut d = [[[0.0; N]; 3]; 3];
        for i in 0..3 {
            let (c1, c2) = (&self.d1[i], &self.d2[i]);
            for k in 0..N {
                let u = u[k];
                d[0][i][k] = (((c1[4] * u + c1[3]) * u + c1[2]) * u + c1[1]) * u + c1[0];
                d[1][i][k] = ((c2[3] * u + c2[2]) * u + c2[1]) * u + c2[0];
                if THIRD {
                    d[2][i][k] = c2[1] + u * (2.0 * c2[2] + u * 3.0 * c2[3]);
                }
            }
        }
        d
    }

    /// |dB/du|.
    pub(crate) fn speed(&self, u: f64) -> f64 {
        let d = self.d1(u);
        (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
    }

    /// Arc length between parameters u0 and u1 (5-point Gauss–Legendre).
    fn speed_integral(&self, u0: f64, u1: f64) -> f64 {
        let (mid, half) = ((u0 + u1) / 2.0, (u1 - u0) / 2.0);
        (0..5)
            .map(|k| GAUSS_W[k] * self.speed(mid + half * GAUSS_X[k]))
            .sum::<f64>()
            * half
    }
}

impl Shape {
    /// Path length, mm (degrees for pure rotary moves).
    pub fn length(&self) -> f64 {
        match self {
            Shape::Line(l) => l.length(),
            Shape::Arc(a) => a.length(),
            Shape::Blend(b) => b.length(),
        }
    }

    /// Start point.
    pub fn start(&self) -> Vec9 {
        match self {
            Shape::Line(l) => l.start,
            Shape::Arc(a) => self.frame_arc(a, 0.0).point,
            Shape::Blend(b) => b.control_point(0),
        }
    }

    /// End point.
    pub fn end(&self) -> Vec9 {
        match self {
            Shape::Line(l) => l.end,
            Shape::Arc(a) => self.frame_arc(a, a.length()).point,
            Shape::Blend(b) => b.control_point(5),
        }
    }

    /// Point only, at arc length `s` (clamped to the shape).
    pub fn point(&self, s: f64) -> Vec9 {
        match self {
            Shape::Line(l) => {
                let len = l.length();
                if len == 0.0 || s >= len {
                    return l.end;
                }
                let f = (s / len).max(0.0);
                std::array::from_fn(|i| l.start[i] + (l.end[i] - l.start[i]) * f)
            }
            _ => self.frame(s).point,
        }
    }

    /// Point, tangent and curvature at arc length `s` (clamped to the shape).
    pub fn frame(&self, s: f64) -> Frame {
        match self {
            Shape::Line(l) => Frame {
                point: self.point(s),
                tangent: l.direction(),
                curvature: [0.0; 9],
            },
            Shape::Arc(a) => self.frame_arc(a, s),
            // d²p/ds² = (d2 − (d2·t) t) / |d1|² in the Bézier parameter.
            Shape::Blend(b) => b.frame_at_parameter(b.parameter(s)),
        }
    }

    /// A circle or helix, or a spiral: a logarithmic one (`Arc::end_radius`)
    /// by arc length, radius r0 + D·q at fraction q of the length L and
    /// angle θ0 + sweep·ln(r/r0)/g (growth g), so dθ/ds = w =
    /// sweep·h/(r·L) and r·w is constant, the tangent a unit vector and
    /// the curvature w·((D/L)·n1 − r·w·n2) with n1 = (−sin θ, cos θ),
    /// n2 = (cos θ, sin θ); one from or to its centre with angle and radius
    /// linear in q.
    fn frame_arc(&self, a: &Arc, s: f64) -> Frame {
        // Worked out once: the executor asks for a frame every period.
        let (growth, h) = a.growth();
        let len = a.length_with((growth, h));
        let q = if len > 0.0 {
            (s / len).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let logarithmic = growth != 0.0;
        let f = a.sweep_fraction_with(q, growth);
        let d = a.end_radius - a.radius;
        let theta = a.start_angle + a.sweep * f;
        let (sin, cos) = theta.sin_cos();
        let r = a.radius + d * q;
        let axial = a.axial_delta();
        let mut p: Vec9 = std::array::from_fn(|i| a.start[i] + axial[i] * q);
        p[a.plane.0] = a.center.0 + r * cos;
        p[a.plane.1] = a.center.1 + r * sin;
        if q >= 1.0 {
            // End exactly where the program said.
            p = a.end;
        }
        if len == 0.0 {
            return Frame {
                point: p,
                tangent: [0.0; 9],
                curvature: [0.0; 9],
            };
        }
        // dθ/ds = w, dr/ds = dr; the axial part moves at axial / len.
        let dr = d / len;
        let mut t: Vec9 = std::array::from_fn(|i| axial[i] / len);
        let mut k = [0.0; 9];
        if logarithmic {
            let rw = a.sweep * h / len;
            let w = rw / r;
            t[a.plane.0] = dr * cos - rw * sin;
            t[a.plane.1] = dr * sin + rw * cos;
            k[a.plane.0] = w * (-dr * sin - rw * cos);
            k[a.plane.1] = w * (dr * cos - rw * sin);
        } else {
            let w = a.sweep / len;
            t[a.plane.0] = dr * cos - r * sin * w;
            t[a.plane.1] = dr * sin + r * cos * w;
            k[a.plane.0] = -2.0 * dr * w * sin - r * cos * w * w;
            k[a.plane.1] = 2.0 * dr * w * cos - r * sin * w * w;
        }
        Frame {
            point: p,
            tangent: t,
            curvature: k,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> Vec9 {
        [x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    }

    /// Numerical derivative of the point by arc length.
    fn numeric(shape: &Shape, s: f64) -> (Vec9, Vec9) {
        let h = 1e-4;
        let (a, b, c) = (shape.point(s - h), shape.point(s), shape.point(s + h));
        (
            std::array::from_fn(|i| (c[i] - a[i]) / (2.0 * h)),
            std::array::from_fn(|i| (c[i] - 2.0 * b[i] + a[i]) / (h * h)),
        )
    }

    #[test]
    fn sampling_gives_the_same_bits_with_and_without_avx() {
        for (k, leg) in [(0.0, 2.0), (0.3, 0.5), (-1.5, 0.01)] {
            let th: f64 = 1.1;
            let u_out = v(th.cos(), th.sin(), 0.2);
            let n = norm(&u_out);
            let u_out: Vec9 = std::array::from_fn(|i| u_out[i] / n);
            let c = Blend::hermite_control(
                &v(150.0 - leg, 100.0, -3.0),
                &v(1.0, 0.0, 0.0),
                &v(0.0, k, 0.0),
                &add(&v(150.0, 100.0, -3.0), &u_out, leg),
                &u_out,
                &[0.0; 9],
                2.0 * leg,
            );
            let (a, x) = Blend::sampled(c);
            let (b, y) = Blend::sampled_here(c);
            assert_eq!(a, b);
            assert_eq!(
                (x.tangent, x.curvature, x.curvature_rate),
                (y.tangent, y.curvature, y.curvature_rate)
            );
        }
    }

    #[test]
    fn helix_is_arc_length_parametrised_with_exact_curvature() {
        // Radius 10 quarter turn, climbing 5 mm in Z: length sqrt((5π)² + 25).
        let arc = Arc {
            plane: (0, 1),
            center: (0.0, 0.0),
            radius: 10.0,
            end_radius: 10.0,
            start_angle: 0.0,
            sweep: std::f64::consts::FRAC_PI_2,
            start: v(10.0, 0.0, 0.0),
            end: v(0.0, 10.0, 5.0),
        };
        let shape = Shape::Arc(arc);
        let len = ((5.0 * std::f64::consts::PI).powi(2) + 25.0).sqrt();
        assert!((shape.length() - len).abs() < 1e-12);
        let end = shape.end();
        assert!(end
            .iter()
            .zip(v(0.0, 10.0, 5.0))
            .all(|(a, b)| (a - b).abs() < 1e-12));
        // Helix curvature r/(r² + c²) with c = pitch/2π: here c = 5/(π/2).
        let c = 5.0 / std::f64::consts::FRAC_PI_2;
        let kappa = 10.0 / (100.0 + c * c);
        for s in [0.3, 4.0, 9.9] {
            let f = shape.frame(s);
            assert!((norm(&f.tangent) - 1.0).abs() < 1e-12);
            assert!((norm(&f.curvature) - kappa).abs() < 1e-12);
            let (d1, d2) = numeric(&shape, s);
            for i in 0..9 {
                assert!((d1[i] - f.tangent[i]).abs() < 1e-6);
                assert!((d2[i] - f.curvature[i]).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn arcs_from_programs_sweep_as_linuxcnc_counts_turns() {
        use std::f64::consts::PI;
        let (s, e) = (v(10.0, 0.0, 0.0), v(0.0, 10.0, 0.0));
        let sweep = |turns| Arc::from_program(&s, &e, (0, 1), (0.0, 0.0), turns).sweep;
        assert!((sweep(1) - PI / 2.0).abs() < 1e-12, "G3 quarter");
        assert!(
            (sweep(-1) + 3.0 * PI / 2.0).abs() < 1e-12,
            "G2 the long way"
        );
        assert!((sweep(2) - (PI / 2.0 + 2.0 * PI)).abs() < 1e-12, "G3 P2");
        let full = |turns| Arc::from_program(&s, &s, (0, 1), (0.0, 0.0), turns).sweep;
        assert!((full(1) - 2.0 * PI).abs() < 1e-12 && (full(-3) + 6.0 * PI).abs() < 1e-12);
        // G18 is the ZX plane: first axis Z, second X; counter-clockwise
        // seen from +Y takes +Z towards +X.
        let zx = Arc::from_program(&v(0.0, 0.0, 5.0), &v(5.0, 0.0, 0.0), (2, 0), (0.0, 0.0), 1);
        assert!((zx.sweep - PI / 2.0).abs() < 1e-12);
        let mid = Shape::Arc(zx).point(Shape::Arc(zx).length() / 2.0);
        let r = 5.0 / 2f64.sqrt();
        assert!((mid[0] - r).abs() < 1e-12 && (mid[2] - r).abs() < 1e-12 && mid[1] == 0.0);
    }

    /// A spiral's points are spaced by arc length: the tool moves at the
    /// path speed all along it, as at the lines and blends it joins (with
    /// the radius linear in angle and the path parameter a fraction of the
    /// sweep, an arc of 0.01 mm spiralling out to 0.03 mm started at half
    /// the path speed and ended at 1.5 times it: the speed jumped at both
    /// junctions, 1.45 times the Y jerk limit on mill3). Checked against an
    /// independent route: the length of a fine polyline through
    /// `point_at_fraction`, and chords between nearby points.
    #[test]
    fn a_spiral_is_followed_at_the_path_speed() {
        let mut r = crate::testkit::uniform(11);
        for case in 0..60 {
            let r0 = 0.01 + 10.0 * r();
            let r1 = r0 * [1.0 + 1e-12, 1.0 + 1e-4, 1.5, 3.0, 1.0 / 3.0][case % 5];
            let sweep = (0.2 + 6.0 * r()) * if r() < 0.5 { 1.0 } else { -1.0 };
            let a0: f64 = 6.0 * r();
            let rise = if case % 2 == 0 { 0.0 } else { 5.0 * r() };
            let start = v(r0 * a0.cos(), r0 * a0.sin(), 0.0);
            let end = v(r1 * (a0 + sweep).cos(), r1 * (a0 + sweep).sin(), rise);
            let arc = Arc {
                plane: (0, 1),
                center: (0.0, 0.0),
                radius: r0,
                end_radius: r1,
                start_angle: a0,
                sweep,
                start,
                end,
            };
            let shape = Shape::Arc(arc);
            let length = shape.length();
            // The length, against 20,000 chords through the sweep.
            let n = 20_000;
            let polyline: f64 = (0..n)
                .map(|k| {
                    let (p, q) = (
                        arc.point_at_fraction(k as f64 / n as f64),
                        arc.point_at_fraction((k + 1) as f64 / n as f64),
                    );
                    norm(&std::array::from_fn(|i| q[i] - p[i]))
                })
                .sum();
            assert!(
                (polyline - length).abs() <= 1e-6 * length,
                "{r0} {r1} {sweep}: length {length}, polyline {polyline}"
            );
            assert_eq!(shape.point(0.0), start);
            assert_eq!(shape.point(length), end);
            let h = length * 1e-5;
            for k in 1..50 {
                let s = length * k as f64 / 50.0;
                let (p, q) = (shape.point(s - h), shape.point(s + h));
                let speed = norm(&std::array::from_fn(|i| q[i] - p[i])) / (2.0 * h);
                assert!(
                    (speed - 1.0).abs() < 1e-6,
                    "{r0} {r1}: speed {speed} at {s}"
                );
                let f = shape.frame(s);
                assert!((norm(&f.tangent) - 1.0).abs() < 1e-12);
                // The same point as the sweep's fraction gives.
                let at = arc.point_at_fraction(arc.sweep_fraction(s / length));
                assert!(norm(&std::array::from_fn(|i| at[i] - f.point[i])) < 1e-9 * r0.max(1.0));
                // And the curvature is the tangent's rate of change.
                let (_, d2) = numeric(&shape, s);
                for i in 0..3 {
                    assert!((d2[i] - f.curvature[i]).abs() < 1e-4 * (1.0 + d2[i].abs()));
                }
            }
        }
    }

    #[test]
    fn an_arc_ending_off_its_circle_spirals_to_its_exact_end() {
        // End radius 10.002 against a start radius of 10 (a program rounding).
        let e = v(0.0, 10.002, 0.0);
        let arc = Arc::from_program(&v(10.0, 0.0, 0.0), &e, (0, 1), (0.0, 0.0), 1);
        let shape = Shape::Arc(arc);
        assert_eq!(shape.end(), e);
        let half = shape.point(shape.length() / 2.0);
        assert!(((half[0].powi(2) + half[1].powi(2)).sqrt() - 10.001).abs() < 1e-9);
        let (d1, _) = numeric(&shape, shape.length() / 3.0);
        let f = shape.frame(shape.length() / 3.0);
        for i in 0..3 {
            assert!((d1[i] - f.tangent[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn blend_is_tangent_flat_at_its_ends_and_within_its_deviation() {
        let corner = v(10.0, 0.0, 0.0);
        let u_in = v(1.0, 0.0, 0.0);
        let u_out = v(0.0, 1.0, 0.0);
        let b = Blend::corner(&corner, &u_in, &u_out, 2.0);
        let shape = Shape::Blend(b);
        let start = shape.frame(0.0);
        let end = shape.frame(shape.length());
        for i in 0..9 {
            assert!((start.tangent[i] - u_in[i]).abs() < 1e-12);
            assert!((end.tangent[i] - u_out[i]).abs() < 1e-12);
        }
        assert!(norm(&start.curvature) < 1e-12 && norm(&end.curvature) < 1e-12);
        // Midpoint distance from the corner: (16 − 10σ)/32 · 2 · √2, with
        // σ = 0.9 at 90° (`SPREAD`).
        let want = Blend::deviation(2.0, &u_in, &u_out);
        assert!((want - 7.0 / 32.0 * 2.0 * 2f64.sqrt()).abs() < 1e-12);
        let mid = shape.point(shape.length() / 2.0);
        let dmid = norm(&std::array::from_fn(|i| mid[i] - corner[i]));
        assert!((dmid - want).abs() < 1e-9, "{dmid} vs {want}");
        // Arc length parametrisation: numerical |dp/ds| = 1 and matches the frame.
        for k in 1..10 {
            let s = shape.length() * k as f64 / 10.0;
            let (d1, d2) = numeric(&shape, s);
            let f = shape.frame(s);
            assert!((norm(&d1) - 1.0).abs() < 1e-6, "speed {} at {s}", norm(&d1));
            for i in 0..3 {
                assert!((d2[i] - f.curvature[i]).abs() < 1e-3, "curvature at {s}");
            }
        }
    }

    #[test]
    fn blend_curvature_rate_is_the_derivative_of_its_curvature() {
        let corner = v(10.0, 0.0, 0.0);
        let u_in = v(1.0, 0.0, 0.0);
        let u_out = v(0.0, 0.6, 0.8);
        let b = Blend::corner(&corner, &u_in, &u_out, 2.0);
        let shape = Shape::Blend(b);
        let kappa = |s: f64| norm(&shape.frame(s).curvature);
        let h = 1e-5;
        let mut largest: f64 = 0.0;
        for k in 1..20 {
            let s = shape.length() * k as f64 / 20.0;
            let want = (kappa(s + h) - kappa(s - h)) / (2.0 * h);
            let got = b.curvature_rate_at_parameter(b.parameter(s));
            largest = largest.max(want.abs());
            assert!(
                (got - want).abs() < 1e-4 * (1.0 + want.abs()),
                "{got} vs {want} at {s}"
            );
        }
        assert!(largest > 0.1, "{largest}");
        // At the ends κ = 0 and the rate is the normal part of p‴.
        for (u, near) in [(0.0, 1e-7), (1.0, 1.0 - 1e-7)] {
            let end = norm(&b.third_normal_where_straight(u));
            let rate = b.curvature_rate_at_parameter(near).abs();
            assert!((end - rate).abs() < 1e-4 * rate, "{end} vs {rate}");
        }
    }

    #[test]
    fn blend_third_derivative_is_the_derivative_of_its_curvature() {
        let b = Blend::corner(
            &v(10.0, 0.0, 0.0),
            &v(1.0, 0.0, 0.0),
            &v(0.0, 0.6, 0.8),
            2.0,
        );
        let shape = Shape::Blend(b);
        let h = 1e-5;
        for k in 1..20 {
            let s = shape.length() * k as f64 / 20.0;
            let (a, c) = (shape.frame(s - h).curvature, shape.frame(s + h).curvature);
            let got = b.third_at_parameter(b.parameter(s));
            for i in 0..3 {
                let want = (c[i] - a[i]) / (2.0 * h);
                assert!(
                    (got[i] - want).abs() < 1e-4 * (1.0 + want.abs()),
                    "axis {i}: {} vs {want} at {s}",
                    got[i]
                );
            }
        }
    }

    /// Time to run through a corner blend whose midpoint is 0.01 mm from
    /// the corner, at the speed where the curvature rate alone uses a jerk
    /// of 1 (v³·max |d³p_i/ds³| = 1): length / speed, with the largest
    /// |d³p_i/ds³| from 4001 exact samples.
    fn corner_time(u_in: &Vec9, u_out: &Vec9, spread: Option<f64>) -> f64 {
        let corner = v(10.0, 0.0, 0.0);
        let bend = norm(&add(u_out, u_in, -1.0));
        let sigma = spread.unwrap_or_else(|| corner_spread(bend));
        // Midpoint at (16 − 10σ)/32 · leg · bend from the corner.
        let leg = 0.01 * 32.0 / ((16.0 - 10.0 * sigma) * bend);
        let zero = [0.0; 9];
        let b = Blend::hermite(
            &add(&corner, u_in, -leg),
            u_in,
            &zero,
            &add(&corner, u_out, leg),
            u_out,
            &zero,
            2.0 * leg * sigma,
        );
        let mid = b.point_at_parameter(0.5);
        let deviation = norm(&add(&mid, &corner, -1.0));
        assert!((deviation - 0.01).abs() < 1e-12, "{deviation}");
        let rate = (0..=4000)
            .flat_map(|k| b.third_at_parameter(k as f64 / 4000.0))
            .fold(0.0f64, |m, x| m.max(x.abs()));
        b.length() * rate.cbrt()
    }

    /// Evenly spaced control points (σ = 1) suit gentle corners, but on
    /// sharp ones they pack the turn into the blend's middle; the planner's
    /// spread runs a 90° corner 1.3 times and a 150° one 5 times faster
    /// under a jerk limit, at the same deviation, and no corner slower.
    #[test]
    fn spread_control_points_speed_up_sharp_corners() {
        let u_in = v(1.0, 0.0, 0.0);
        let turn = |deg: f64| {
            let r = deg.to_radians();
            v(r.cos(), r.sin(), 0.0)
        };
        let gain = |deg: f64| {
            let u_out = turn(deg);
            corner_time(&u_in, &u_out, Some(1.0)) / corner_time(&u_in, &u_out, None)
        };
        assert!(gain(90.0) > 1.25, "{}", gain(90.0));
        assert!(gain(150.0) > 5.0, "{}", gain(150.0));
        for deg in (5..=150).step_by(5) {
            assert!(
                gain(deg as f64) >= 1.0 - 1e-12,
                "{deg}°: {}",
                gain(deg as f64)
            );
            if deg < 60 {
                continue;
            }
            // Past 60°, each σ is the best of its neighbours 0.05 either
            // side. (Below, σ = 1.05 would gain 5–8 %.)
            let u_out = turn(deg as f64);
            let sigma = corner_spread(norm(&add(&u_out, &u_in, -1.0)));
            let here = corner_time(&u_in, &u_out, None);
            for other in [sigma - 0.05, sigma + 0.05] {
                let there = corner_time(&u_in, &u_out, Some(other));
                assert!(
                    here <= there * 1.01,
                    "{deg}°: σ {sigma} {here}, σ {other} {there}"
                );
            }
        }
    }

    /// The largest exact |dκ_i/ds| of `b` ([`exact_largest`]) over
    /// what [`Blend::sampled`] bounds it by, over the axes that have one.
    fn rate_excess(b: &Blend) -> f64 {
        let bound = Blend::sampled(b.control_points()).1.curvature_rate;
        let [exact] = exact_largest(|u| [b.third_at_parameter(u).map(f64::abs)]);
        (0..3)
            .filter(|&i| exact[i] > 0.0)
            .map(|i| exact[i] / bound[i])
            .fold(0.0, f64::max)
    }

    /// A random corner blend, or None (its draws spent) where the corner
    /// is sharper than the 150° the planner blends (see plan.rs): legs
    /// from 1e-3 to 10 mm.
    fn random_corner(rnd: &mut dyn FnMut() -> f64) -> Option<Blend> {
        let u_in: Vec9 = random_unit(rnd);
        let u_out: Vec9 = random_unit(rnd);
        let cos = (0..3).map(|i| u_in[i] * u_out[i]).sum::<f64>();
        if cos < -(3f64.sqrt() / 2.0) {
            return None;
        }
        let leg = 10f64.powf(-3.0 + 4.0 * rnd());
        Some(Blend::corner(&v(50.0, 50.0, -20.0), &u_in, &u_out, leg))
    }

    /// A random blend as a dense curve's fit makes them, or None (its
    /// draws spent) where its ends turn by more than 53°: the curve fit's
    /// pieces turn by a few degrees, and past 60° the exact rate is
    /// sampled anyway. Lengths from 0.01 to 1 mm; end curvatures normal
    /// to the tangents, radii from a tenth of the piece to a hundred
    /// times it.
    fn random_curve_piece(rnd: &mut dyn FnMut() -> f64) -> Option<Blend> {
        let t0 = random_unit(rnd);
        let t1 = random_unit(rnd);
        if (0..3).map(|i| t0[i] * t1[i]).sum::<f64>() < 0.6 {
            return None;
        }
        let length = 10f64.powf(-2.0 + 2.0 * rnd());
        let mut bend = |t: &Vec9| {
            let radius = length * 10f64.powf(-1.0 + 3.0 * rnd());
            random_curvature(t, radius, rnd)
        };
        let (k0, k1) = (bend(&t0), bend(&t1));
        let p0 = v(10.0, 20.0, -5.0);
        let p1: Vec9 = std::array::from_fn(|i| p0[i] + length * (t0[i] + t1[i]) / 2.0);
        Some(Blend::hermite(&p0, &t0, &k0, &p1, &t1, &k1, length))
    }

    /// A curvature vector of `radius` normal to unit tangent `t`, in a
    /// random direction.
    fn random_curvature(t: &Vec9, radius: f64, rnd: &mut dyn FnMut() -> f64) -> Vec9 {
        let d = random_unit(rnd);
        let along: f64 = (0..3).map(|i| d[i] * t[i]).sum();
        let n: Vec9 = std::array::from_fn(|i| d[i] - along * t[i]);
        let (size, curvature) = (norm(&n), 1.0 / radius);
        std::array::from_fn(|i| n[i] / size * curvature)
    }

    /// A random X Y Z unit vector, uniform in direction (rejection from
    /// the cube, away from the origin).
    fn random_unit(rnd: &mut dyn FnMut() -> f64) -> Vec9 {
        loop {
            let d = v(2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
            let n = norm(&d);
            if n > 0.1 && n <= 1.0 {
                return std::array::from_fn(|i| d[i] / n);
            }
        }
    }

    /// The planner's bound on |dκ_i/ds| along a blend is above the exact
    /// largest |d³p_i/ds³| found by dense sampling, on random corners up
    /// to the 150° the planner blends, short and long. (Differences
    /// between the 33 samples padded by 25 %, the bound before, fall short
    /// by up to 1 % here, and many times over on sharper corners.)
    #[test]
    fn sampled_curvature_rate_bounds_the_exact_one() {
        let mut rnd = crate::testkit::uniform(0x2545_f491_4f6c_dd1d);
        let mut worst: f64 = 0.0;
        for _ in 0..2000 {
            if let Some(b) = random_corner(&mut rnd) {
                worst = worst.max(rate_excess(&b));
            }
        }
        assert!(worst <= 1.0, "exact |dκ/ds| is {worst} times the bound");
    }

    /// A dense curve's blends join fitted pieces: their ends take the
    /// curve's curvature, and their curvature can turn fastest right at
    /// an end, where the means over the intervals say least.
    #[test]
    fn sampled_curvature_rate_bounds_the_exact_one_on_curve_blends() {
        let mut rnd = crate::testkit::uniform(0x9e37_79b9_7f4a_7c15);
        let (mut worst, mut tested): (f64, usize) = (0.0, 0);
        while tested < 2000 {
            let Some(b) = random_curve_piece(&mut rnd) else {
                continue;
            };
            worst = worst.max(rate_excess(&b));
            tested += 1;
        }
        assert!(worst <= 1.0, "exact |dκ/ds| is {worst} times the bound");
    }

    /// The exact largest |t_i|, |κ_i| and |dκ_i/ds| of `b` per axis
    /// ([`exact_largest`]).
    fn exact_extremes(b: &Blend) -> [[f64; 3]; 3] {
        exact_largest(|u| {
            let f = b.frame_at_parameter(u);
            let rate = b.third_at_parameter(u);
            [
                std::array::from_fn(|i| f.tangent[i].abs()),
                std::array::from_fn(|i| f.curvature[i].abs()),
                std::array::from_fn(|i| rate[i].abs()),
            ]
        })
    }

    /// The largest of each of `Q` per-axis values of the Bézier parameter
    /// over [0, 1]: the largest of 2001 evenly spaced parameters, refined
    /// at 201 more across the two intervals around it (as fine as
    /// 200,001 evenly spaced near the crest, at a tenth of the cost of
    /// 20,001 in a debug build).
    fn exact_largest<const Q: usize>(values: impl Fn(f64) -> [[f64; 3]; Q]) -> [[f64; 3]; Q] {
        const COARSE: usize = 2000;
        let mut most = [[0.0f64; 3]; Q];
        let mut at = [[0.0f64; 3]; Q];
        for k in 0..=COARSE {
            let u = k as f64 / COARSE as f64;
            let v = values(u);
            for q in 0..Q {
                for i in 0..3 {
                    if v[q][i] > most[q][i] {
                        (most[q][i], at[q][i]) = (v[q][i], u);
                    }
                }
            }
        }
        let h = 1.0 / COARSE as f64;
        for q in 0..Q {
            for i in 0..3 {
                for k in 0..=200 {
                    let u = (at[q][i] - h + 2.0 * h * k as f64 / 200.0).clamp(0.0, 1.0);
                    most[q][i] = most[q][i].max(values(u)[q][i]);
                }
            }
        }
        most
    }

    /// Largest shortfall of `b`'s sampled tangent and curvature extremes
    /// below the exact ones, and their largest excess, per quantity, as
    /// fractions of the exact largest component; and the shortfall of
    /// the largest of 33 plain samples, as the planner took them before
    /// it added the crest allowance to these two. Also the curvature
    /// rate's shortfall.
    fn extremes_against_exact(b: &Blend) -> ([f64; 3], [f64; 2], [f64; 2]) {
        let as_array = |e: BlendExtremes| [e.tangent, e.curvature, e.curvature_rate];
        let sampled = as_array(Blend::sampled(b.control_points()).1);
        let mut plain = [[0.0f64; 3]; 2];
        for k in 0..=SAMPLES {
            let f = b.frame_at_parameter(k as f64 / SAMPLES as f64);
            for i in 0..3 {
                plain[0][i] = plain[0][i].max(f.tangent[i].abs());
                plain[1][i] = plain[1][i].max(f.curvature[i].abs());
            }
        }
        let exact = exact_extremes(b);
        let (mut short, mut over, mut short_plain) = ([0.0f64; 3], [0.0f64; 2], [0.0f64; 2]);
        for q in 0..3 {
            let scale = exact[q].iter().fold(0.0f64, |m, &x| m.max(x));
            for i in 0..3 {
                short[q] = short[q].max((exact[q][i] - sampled[q][i]) / scale);
                if q < 2 {
                    over[q] = over[q].max((sampled[q][i] - exact[q][i]) / scale);
                    short_plain[q] = short_plain[q].max((exact[q][i] - plain[q][i]) / scale);
                }
            }
        }
        (short, over, short_plain)
    }

    /// The larger of each entry.
    fn larger_of<const N: usize>(a: [f64; N], b: [f64; N]) -> [f64; N] {
        std::array::from_fn(|i| a[i].max(b[i]))
    }

    /// Blends sampled coarsely ([`Sampling::Smooth`]) keep their extremes
    /// at or above the exact ones, on 500 random pieces like a dense
    /// curve's (turns up to 0.3 rad, radii from the piece's length to a
    /// thousand times it) and 500 gentle corners (turns up to 0.3 rad),
    /// and the tangent's and curvature's only a little above: the crest
    /// allowance costs speed where the samples are few.
    ///
    /// The allowance is a parabola's, not a proof: the test holds it to
    /// 1e-5 of the largest component. Here it never falls short; on other
    /// pieces (with a SMOOTH_BEND of 0.05), one tangent fell 1.4e-6 short.
    #[test]
    fn smooth_blends_extremes_bound_the_exact_ones() {
        let mut rnd = crate::testkit::uniform(0x5851_f42d_4c95_7f2d);
        let (mut tested, mut tries) = (0, 0);
        let (mut short, mut over) = ([0.0f64; 3], [0.0f64; 2]);
        while tested < 1000 {
            tries += 1;
            let t0 = random_unit(&mut rnd);
            // Within 0.3 rad of t0.
            let t1 = {
                let d = random_unit(&mut rnd);
                let turn = 0.3 * rnd();
                let t: Vec9 = std::array::from_fn(|i| t0[i] + turn * d[i]);
                let n = norm(&t);
                std::array::from_fn::<f64, 9, _>(|i| t[i] / n)
            };
            // Half pieces of curve, half gentle corners (legs from 1e-3
            // to 10 mm), as a G64 corner of a few degrees makes them.
            let b = if tested % 2 == 0 {
                let length = 10f64.powf(-2.0 + 2.0 * rnd());
                let mut bend = |t: &Vec9| {
                    let radius = length * 10f64.powf(3.0 * rnd());
                    random_curvature(t, radius, &mut rnd)
                };
                let (k0, k1) = (bend(&t0), bend(&t1));
                let p0 = v(10.0, 20.0, -5.0);
                let p1: Vec9 = std::array::from_fn(|i| p0[i] + length * (t0[i] + t1[i]) / 2.0);
                Blend::hermite(&p0, &t0, &k0, &p1, &t1, &k1, length)
            } else {
                let leg = 10f64.powf(-3.0 + 4.0 * rnd());
                Blend::corner(&v(50.0, 50.0, -20.0), &t0, &t1, leg)
            };
            if Sampling::of(&b.control_points()) != Sampling::Smooth {
                continue;
            }
            tested += 1;
            let (s, o, _) = extremes_against_exact(&b);
            (short, over) = (larger_of(short, s), larger_of(over, o));
        }
        assert!(
            short.iter().all(|&s| s <= 1e-5),
            "below the exact extremes by {short:?}"
        );
        assert!(
            over[0] <= 0.01 && over[1] <= 0.25,
            "extremes high by {over:?}"
        );
        // Most such pieces take the coarse sampling.
        assert!(
            tries < 4 * tested,
            "{tested} of {tries} pieces sampled coarsely"
        );
    }

    /// The tangent's and curvature's extremes of the planner's other
    /// blends, 33 samples with the crest allowance, are at or above the
    /// exact ones too: on 500 random corners up to the 150° the planner
    /// blends, and 500 random pieces of curve as in
    /// `sampled_curvature_rate_bounds_the_exact_one_on_curve_blends`, that
    /// are not smooth. The largest of 33 plain samples, as the planner
    /// took them before, falls short of them by up to 0.34 % on the
    /// tangent and 3.0 % on the curvature here.
    #[test]
    fn corner_and_curve_blends_extremes_bound_the_exact_ones() {
        let mut rnd = crate::testkit::uniform(0x1234_5678);
        let (mut short, mut short_plain) = ([0.0f64; 2], [0.0f64; 2]);
        let mut over = [[0.0f64; 2]; 2];
        for (kind, over) in over.iter_mut().enumerate() {
            let mut tested = 0;
            while tested < 500 {
                let b = if kind == 0 {
                    random_corner(&mut rnd)
                } else {
                    random_curve_piece(&mut rnd)
                };
                let Some(b) = b else {
                    continue;
                };
                if Sampling::of(&b.control_points()) == Sampling::Smooth {
                    continue;
                }
                tested += 1;
                let (s, o, p) = extremes_against_exact(&b);
                short = larger_of(short, [s[0], s[1]]);
                *over = larger_of(*over, o);
                short_plain = larger_of(short_plain, p);
            }
        }
        assert!(
            short.iter().all(|&s| s <= 1e-5),
            "below the exact extremes by {short:?}"
        );
        // Corners: a few per mille high; pieces of curve, which bend
        // faster between samples, up to a tenth on the curvature.
        assert!(
            over[0][0] <= 0.01 && over[0][1] <= 0.02 && over[1][0] <= 0.05 && over[1][1] <= 0.15,
            "extremes high by {over:?}"
        );
        // Without the allowance the samples do fall short: the test can
        // tell.
        assert!(
            short_plain[1] > 1e-3,
            "plain samples short by {short_plain:?}"
        );
    }

    /// A dense curve's blends, between the exact frames of a circle's
    /// chord midpoints, take the coarse sampling: planning dense curves
    /// depends on it.
    #[test]
    fn dense_curves_blends_sample_coarsely() {
        for (r, chord) in [
            (1.0, 0.02),
            (5.0, 0.02),
            (50.0, 0.01),
            (2.0, 0.1),
            (0.5, 0.05),
        ] {
            let step = chord / r;
            let frame = |a: f64| {
                let p = v(r * a.cos(), r * a.sin(), 0.0);
                let t = v(-a.sin(), a.cos(), 0.0);
                let k = v(-a.cos() / r, -a.sin() / r, 0.0);
                (p, t, k)
            };
            let ((p0, t0, k0), (p1, t1, k1)) = (frame(0.3), frame(0.3 + step));
            let b = Blend::hermite(&p0, &t0, &k0, &p1, &t1, &k1, chord);
            assert_eq!(
                Sampling::of(&b.control_points()),
                Sampling::Smooth,
                "R{r} in {chord} mm chords"
            );
        }
    }
}
