//! The reachable workspace of a machine, found through the [`Kinematics`]
//! trait alone, so it works for every kinematics module.
//!
//! A pose is *reachable* when inverse kinematics succeed and every joint is
//! inside its stroke; the axis travel is not applied, so the result shows
//! what the mechanism can do and the travel can be compared with it.
//!
//! Both analyses sample on a grid and then bisect each boundary they cross
//! to [`BOUNDARY_TOLERANCE`]; a reachable sliver thinner than the grid step
//! between two unreachable samples can be missed.

use kerf_interp::{Axis, Position};
use kerf_motion::kinematics::{check_joints, Kinematics, MAX_JOINTS};

/// Boundaries found by bisection are located to within this, mm.
pub const BOUNDARY_TOLERANCE: f64 = 1e-7;

/// True if the mechanism reaches `pose` with every joint inside its stroke.
pub fn reachable(kins: &dyn Kinematics, pose: &Position) -> bool {
    let n = kins.joints().len();
    let mut q = [0.0; MAX_JOINTS];
    kins.inverse(pose, &mut q[..n]).is_ok() && check_joints(kins.joints(), &q[..n]).is_ok()
}

/// A closed interval lo..=hi, mm (or degrees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

impl Interval {
    /// hi − lo.
    pub fn len(&self) -> f64 {
        self.hi - self.lo
    }

    /// The overlap of two intervals, if any.
    pub fn intersect(&self, other: &Interval) -> Option<Interval> {
        let lo = self.lo.max(other.lo);
        let hi = self.hi.min(other.hi);
        (lo <= hi).then_some(Interval { lo, hi })
    }
}

/// The reachable x intervals at one height z of an XZ section.
#[derive(Clone, Debug, PartialEq)]
pub struct SectionRow {
    /// Height, mm.
    pub z: f64,
    /// Reachable x intervals at this height, left to right, mm.
    pub x: Vec<Interval>,
}

/// A section of the workspace in the XZ plane, rows at fixed z spacing.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// The pose the section goes through (its y and every other axis), mm.
    pub base: Position,
    /// Distance between rows, mm.
    pub z_step: f64,
    /// Rows from low z to high z that reach something.
    pub rows: Vec<SectionRow>,
}

/// An axis-aligned rectangle in the XZ plane, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rectangle {
    /// Its x extent.
    pub x: Interval,
    /// Its z extent.
    pub z: Interval,
}

impl Rectangle {
    /// Width times height, mm².
    pub fn area(&self) -> f64 {
        self.x.len() * self.z.len()
    }
}

/// The last value `probe` accepts between `inside` (accepted) and
/// `outside` (refused), by bisection.
fn bisect(mut inside: f64, mut outside: f64, probe: impl Fn(f64) -> bool) -> f64 {
    while (outside - inside).abs() > BOUNDARY_TOLERANCE {
        let mid = 0.5 * (inside + outside);
        if probe(mid) {
            inside = mid;
        } else {
            outside = mid;
        }
    }
    inside
}

/// The reachable intervals of `probe` over `window`, sampled every `step`
/// and refined by bisection.
fn intervals(window: Interval, step: f64, probe: impl Fn(f64) -> bool) -> Vec<Interval> {
    let n = (window.len() / step).ceil() as usize;
    let at = |i: usize| (window.lo + i as f64 * step).min(window.hi);
    let mut found = Vec::new();
    let mut start: Option<f64> = None;
    let mut previous = f64::NAN;
    for i in 0..=n {
        let v = at(i);
        let ok = probe(v);
        match (start, ok) {
            (None, true) => {
                start = Some(if i == 0 {
                    v
                } else {
                    bisect(v, previous, &probe)
                });
            }
            (Some(lo), false) => {
                found.push(Interval {
                    lo,
                    hi: bisect(previous, v, &probe),
                });
                start = None;
            }
            _ => {}
        }
        previous = v;
    }
    if let Some(lo) = start {
        found.push(Interval { lo, hi: window.hi });
    }
    found
}

/// Where to look for the workspace around `base`: every axis ± the sum of
/// all joint strokes, which no mechanism of those joints can exceed by much.
pub fn search_window(kins: &dyn Kinematics, base: &Position, axis: Axis) -> Interval {
    let span: f64 = kins
        .joints()
        .iter()
        .map(|j| j.limits.max - j.limits.min)
        .sum();
    let c = base.get(axis);
    Interval {
        lo: c - span,
        hi: c + span,
    }
}

/// The XZ section of the workspace through `base`, with rows every
/// `z_step` mm. A coarse pass (`coarse` mm grid) over the search window
/// finds the section's extent; the rows then sample x every `z_step` mm
/// inside it and bisect each edge.
pub fn xz_section(kins: &dyn Kinematics, base: &Position, coarse: f64, z_step: f64) -> Section {
    let probe = |x: f64, z: f64| {
        let mut p = *base;
        p.x = x;
        p.z = z;
        reachable(kins, &p)
    };
    let xw = search_window(kins, base, Axis::X);
    let zw = search_window(kins, base, Axis::Z);
    // Coarse pass: the bounding box of reachable grid points.
    let mut bbox: Option<(Interval, Interval)> = None;
    let nx = (xw.len() / coarse).ceil() as usize;
    let nz = (zw.len() / coarse).ceil() as usize;
    for iz in 0..=nz {
        let z = zw.lo + iz as f64 * coarse;
        for ix in 0..=nx {
            let x = xw.lo + ix as f64 * coarse;
            if probe(x, z) {
                let (bx, bz) =
                    bbox.get_or_insert((Interval { lo: x, hi: x }, Interval { lo: z, hi: z }));
                bx.lo = bx.lo.min(x);
                bx.hi = bx.hi.max(x);
                bz.lo = bz.lo.min(z);
                bz.hi = bz.hi.max(z);
            }
        }
    }
    let Some((bx, bz)) = bbox else {
        return Section {
            base: *base,
            z_step,
            rows: Vec::new(),
        };
    };
    let widen = |i: Interval, w: Interval| Interval {
        lo: (i.lo - coarse).max(w.lo),
        hi: (i.hi + coarse).min(w.hi),
    };
    let (bx, mut bz) = (widen(bx, xw), widen(bz, zw));
    // Rows on multiples of the step, so that their heights read well.
    bz.lo = (bz.lo / z_step).floor() * z_step;
    let n = (bz.len() / z_step).ceil() as usize;
    let rows = (0..=n)
        .map(|i| bz.lo + i as f64 * z_step)
        .map(|z| {
            let mut x = intervals(bx, z_step, |x| probe(x, z));
            // A row wider than the coarse box (the section can flare
            // between coarse rows) is scanned again over the whole window.
            let touches = |i: &Interval| i.lo <= bx.lo || i.hi >= bx.hi;
            if x.iter().any(touches) {
                x = intervals(xw, z_step, |x| probe(x, z));
            }
            SectionRow { z, x }
        })
        .filter(|row| !row.x.is_empty())
        .collect();
    Section {
        base: *base,
        z_step,
        rows,
    }
}

/// The largest-area axis-aligned rectangle whose every row lies inside the
/// section. Its z edges are rows of the section; between rows the section
/// is assumed not to pinch in by more than it does at the rows around it.
pub fn largest_rectangle(section: &Section) -> Option<Rectangle> {
    let rows = &section.rows;
    let mut best: Option<Rectangle> = None;
    let mut current: Vec<Interval> = Vec::new();
    let mut next: Vec<Interval> = Vec::new();
    for (i, first) in rows.iter().enumerate() {
        current.clear();
        current.extend_from_slice(&first.x);
        for (j, row) in rows.iter().enumerate().skip(i) {
            // Rows must be consecutive: a gap in z breaks the rectangle.
            if j > i && row.z - rows[j - 1].z > 1.5 * section.z_step {
                break;
            }
            next.clear();
            for a in &current {
                next.extend(row.x.iter().filter_map(|b| a.intersect(b)));
            }
            std::mem::swap(&mut current, &mut next);
            if current.is_empty() {
                break;
            }
            let z = Interval {
                lo: first.z,
                hi: row.z,
            };
            for x in &current {
                let candidate = Rectangle { x: *x, z };
                if best.is_none_or(|b| candidate.area() > b.area()) {
                    best = Some(candidate);
                }
            }
        }
    }
    best
}

/// How the tool is tilted in [`TiltRow`]: about X only, about Y only, or
/// every direction at once.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TiltDirection {
    /// A = tilt, B = 0.
    AboutX,
    /// A = 0, B = tilt.
    AboutY,
    /// The tool axis leans `tilt` from vertical towards every azimuth
    /// sampled; the range is the one all of them share.
    Any,
}

/// The reachable tool-tip Z range at one tilt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TiltRow {
    /// Angle between the tool axis and the vertical, degrees.
    pub tilt: f64,
    /// Z range tilting about X, mm, if any.
    pub about_x: Option<Interval>,
    /// Z range tilting about Y, mm, if any.
    pub about_y: Option<Interval>,
    /// Z range shared by every tilt direction, mm, if any.
    pub any: Option<Interval>,
}

/// A and B (degrees) that lean the tool axis `tilt` degrees from vertical
/// towards azimuth `azimuth` (degrees from +X towards +Y), for a tool axis
/// k = R_y(B)·R_x(A)·ẑ = (cos A sin B, −sin A, cos A cos B).
pub fn tilt_to_ab(tilt: f64, azimuth: f64) -> (f64, f64) {
    let (st, ct) = tilt.to_radians().sin_cos();
    let (sp, cp) = azimuth.to_radians().sin_cos();
    let a = (-st * sp).asin();
    let b = (st * cp).atan2(ct);
    (a.to_degrees(), b.to_degrees())
}

/// The longest reachable Z interval at orientation (a, b), degrees.
fn z_range(kins: &dyn Kinematics, base: &Position, a: f64, b: f64, step: f64) -> Option<Interval> {
    let window = search_window(kins, base, Axis::Z);
    intervals(window, step, |z| {
        let mut p = *base;
        p.z = z;
        p.a = a;
        p.b = b;
        reachable(kins, &p)
    })
    .into_iter()
    .max_by(|p, q| p.len().total_cmp(&q.len()))
}

/// The reachable Z range against tilt, from 0 to `max_tilt` every
/// `tilt_step` degrees, for a machine with A and B axes; X, Y and the other
/// axes stay at `base`. "Any direction" samples the azimuth every
/// `azimuth_step` degrees. Z is sampled every `z_step` mm and bisected.
pub fn z_against_tilt(
    kins: &dyn Kinematics,
    base: &Position,
    max_tilt: f64,
    tilt_step: f64,
    azimuth_step: f64,
    z_step: f64,
) -> Vec<TiltRow> {
    let n = (max_tilt / tilt_step).round() as usize;
    let azimuths = (360.0 / azimuth_step).round() as usize;
    (0..=n)
        .map(|i| {
            let tilt = i as f64 * tilt_step;
            let (a, b) = tilt_to_ab(tilt, 0.0);
            let mut any = z_range(kins, base, a, b, z_step);
            for k in 1..azimuths {
                let Some(so_far) = any else { break };
                let (a, b) = tilt_to_ab(tilt, k as f64 * azimuth_step);
                any = z_range(kins, base, a, b, z_step).and_then(|r| r.intersect(&so_far));
            }
            TiltRow {
                tilt,
                about_x: z_range(kins, base, tilt, 0.0, z_step),
                about_y: z_range(kins, base, 0.0, tilt, z_step),
                any,
            }
        })
        .collect()
}
