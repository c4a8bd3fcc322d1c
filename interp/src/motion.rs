//! Motion: end points (absolute, incremental, polar, G53), straight moves,
//! arcs (centre or radius format, full circles, helices, P turns), probes,
//! spindle-synchronised moves, and the inverse-time feed rates they need.

use crate::block::{g, gm, is_cycle, round_to_int, Block};
use crate::canon::{CanonCmd, Plane, ProbeKind, Units};
use crate::emit::rotate;
use crate::error::{bail, chk, Fault, R};
use crate::interp::{Distance, FeedMode, Interp, Side, Turning, A, C, X, Y, Z};

/// The smallest arc radius, inch (and its mm equivalent).
const RADIUS_TOLERANCE_INCH: f64 = 0.00005;
/// Allowed relative difference between start and end radius of an arc.
const SPIRAL_RELATIVE_TOLERANCE: f64 = 0.001;
/// Ratio within which a radius-format arc counts as a half circle.
const TINY: f64 = 1e-12;

/// C's `%.{precision}g`.
pub(crate) fn fmt_g(v: f64, precision: usize) -> String {
    let p = precision.max(1);
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let e = format!("{:.*e}", p - 1, v);
    let exp: i32 = e
        .split('e')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    if exp < -4 || exp >= p as i32 {
        let (mant, _) = e.split_once('e').unwrap_or((&e, "0"));
        let mant = trim_zeros(mant);
        format!("{mant}e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs())
    } else {
        let decimals = (p as i32 - 1 - exp).max(0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

impl Interp<'_> {
    /// Tolerances for centre-format arcs: (start/end radius difference,
    /// smallest radius), in program units.
    pub(crate) fn arc_tolerances(&self) -> (f64, f64) {
        if self.length_units == Units::Inch {
            (
                self.cfg.center_arc_radius_tolerance_inch,
                RADIUS_TOLERANCE_INCH,
            )
        } else {
            (
                self.cfg.center_arc_radius_tolerance_mm,
                RADIUS_TOLERANCE_INCH * 25.4,
            )
        }
    }

    /// The end point of a move in program coordinates: absolute,
    /// incremental, polar (`@` `^`) or machine (G53).
    pub(crate) fn find_ends(&self, b: &Block) -> R<[f64; 9]> {
        let middle = !self.cutter_comp_firstmove;
        let comp = self.cutter_comp_side != Side::Off;
        let mut e = [0.0; 9];
        let axes = b"xyzabcuvw";
        if b.g_modes[gm::MODAL_0] == g::G53 {
            chk!(
                b.radius.is_some() || b.theta.is_some(),
                "Cannot use polar coordinates with G53"
            );
            self.emit_comment_direct("interpreter: offsets temporarily suspended");
            let (cx, cy) = rotate(
                self.cur[X] + self.axis_offset[X],
                self.cur[Y] + self.axis_offset[Y],
                self.rotation_xy,
            );
            let mut px = match b.get(b'x') {
                Some(x) => x - self.origin_offset[X] - self.tool_offset[X],
                None => cx,
            };
            let mut py = match b.get(b'y') {
                Some(y) => y - self.origin_offset[Y] - self.tool_offset[Y],
                None => cy,
            };
            (px, py) = rotate(px, py, -self.rotation_xy);
            e[X] = px - self.axis_offset[X];
            e[Y] = py - self.axis_offset[Y];
            for i in 2..9 {
                e[i] = match b.get(axes[i]) {
                    Some(v) => {
                        let mut r = v - self.origin_offset[i] - self.axis_offset[i];
                        if !(A..=C).contains(&i) {
                            r -= self.tool_offset[i];
                        } else if self.cfg.wrapped_rotary[i - A] {
                            r = self.unwrap_rotary(v, r - self.tool_offset[i], self.cur[i], i)?;
                        }
                        r
                    }
                    None => self.cur[i],
                };
            }
            return Ok(e);
        }
        chk!(
            (b.radius.is_some() || b.theta.is_some()) && (b.has(b'x') || b.has(b'y')),
            "Cannot specify X or Y words with polar coordinate"
        );
        if self.distance_mode == Distance::Absolute {
            e[X] = b.get(b'x').unwrap_or(if comp && middle {
                self.program[0]
            } else {
                self.cur[X]
            });
            e[Y] = b
                .get(b'y')
                .unwrap_or(if comp && middle && self.plane == Plane::XY {
                    self.program[1]
                } else {
                    self.cur[Y]
                });
            match (b.radius, b.theta) {
                (Some(r), Some(t)) => {
                    e[X] = r * t.to_radians().cos();
                    e[Y] = r * t.to_radians().sin();
                }
                (Some(r), None) => {
                    chk!(
                        e[Y] == 0.0 && e[X] == 0.0,
                        "Must specify angle in polar coordinate if at the origin"
                    );
                    let theta = e[Y].atan2(e[X]);
                    e[X] = r * theta.cos();
                    e[Y] = r * theta.sin();
                }
                (None, Some(t)) => {
                    let radius = e[Y].hypot(e[X]);
                    e[X] = radius * t.to_radians().cos();
                    e[Y] = radius * t.to_radians().sin();
                }
                (None, None) => {}
            }
            e[Z] = b
                .get(b'z')
                .unwrap_or(if comp && middle && self.plane == Plane::XZ {
                    self.program[2]
                } else {
                    self.cur[Z]
                });
            for i in 3..9 {
                e[i] = match b.get(axes[i]) {
                    Some(v) if (A..=C).contains(&i) && self.cfg.wrapped_rotary[i - A] => {
                        self.unwrap_rotary(v, v, self.cur[i], i)?
                    }
                    Some(v) => v,
                    None => self.cur[i],
                };
            }
        } else {
            e[X] = (if comp && middle {
                self.program[0]
            } else {
                self.cur[X]
            }) + b.or(b'x', 0.0);
            e[Y] = (if comp && middle && self.plane == Plane::XY {
                self.program[1]
            } else {
                self.cur[Y]
            }) + b.or(b'y', 0.0);
            if let Some(r) = b.radius {
                chk!(
                    e[Y] == 0.0 && e[X] == 0.0,
                    "Incremental motion with polar coordinates is indeterminate when at the origin"
                );
                let theta = e[Y].atan2(e[X]);
                let radius = e[Y].hypot(e[X]) + r;
                e[X] = radius * theta.cos();
                e[Y] = radius * theta.sin();
            }
            if let Some(t) = b.theta {
                chk!(
                    e[Y] == 0.0 && e[X] == 0.0,
                    "G91 motion with polar coordinates is indeterminate when at the origin"
                );
                let theta = e[Y].atan2(e[X]) + t.to_radians();
                let radius = e[Y].hypot(e[X]);
                e[X] = radius * theta.cos();
                e[Y] = radius * theta.sin();
            }
            e[Z] = (if comp && middle && self.plane == Plane::XZ {
                self.program[2]
            } else {
                self.cur[Z]
            }) + b.or(b'z', 0.0);
            for i in 3..9 {
                e[i] = self.cur[i] + b.or(axes[i], 0.0);
            }
        }
        Ok(e)
    }

    /// A wrapped rotary axis takes the shorter way to an absolute position
    /// in -360..360, its sign choosing the direction.
    fn unwrap_rotary(&self, sign_of: f64, commanded: f64, current: f64, axis: usize) -> R<f64> {
        let letter = b"XYZABCUVW"[axis] as char;
        chk!(
            sign_of <= -360.0 || sign_of >= 360.0,
            "Invalid absolute position {sign_of:5.2} for wrapped rotary axis {letter}"
        );
        let neg = sign_of.is_sign_negative();
        let d = (current / 360.0).floor();
        let mut result = commanded.abs() + d * 360.0;
        if !neg && result < current {
            result += 360.0;
        }
        if neg && result > current {
            result -= 360.0;
        }
        Ok(result)
    }

    /// A comment given at once (not queued behind compensated moves).
    pub(crate) fn emit_comment_direct(&self, _text: &str) {}

    pub(crate) fn convert_motion(&mut self, motion: i32, b: &mut Block) -> R {
        if !is_cycle(motion) {
            self.cycle_il_flag = false;
        }
        match motion {
            g::G0 | g::G1 | g::G33 | g::G33_1 | g::G76 => self.convert_straight(motion, b),
            g::G2 | g::G3 => self.convert_arc(motion, b),
            g::G38_2 | g::G38_3 | g::G38_4 | g::G38_5 => self.convert_probe(motion, b),
            g::G80 => {
                self.enqueue_debug_comment("interpreter: motion mode set to none");
                self.motion_mode = g::G80;
                Ok(())
            }
            m if is_cycle(m) => self.convert_cycle(m, b),
            g::G5 | g::G5_1 => bail!("G5 and G5.1 splines are not supported"),
            g::G5_2 => bail!("G5.2 NURBS curves are not supported"),
            g::G70 | g::G71 | g::G71_1 | g::G71_2 | g::G72 | g::G72_1 | g::G72_2 => {
                self.convert_g7x(motion, b)
            }
            _ => bail!("Bug unknown motion code"),
        }
    }

    /// Set the feed rate an inverse-time straight move needs.
    pub(crate) fn inverse_time_rate_straight(&mut self, end: [f64; 9], b: &Block) {
        if self.feed_mode != FeedMode::InverseTime {
            return;
        }
        let c = if self.cutter_comp_side != Side::Off
            && self.cutter_comp_radius > 0.0
            && !self.cutter_comp_firstmove
        {
            self.program
        } else {
            [self.cur[X], self.cur[Y], self.cur[Z]]
        };
        let tiny = 1e-7;
        let d = |i: usize, from: f64| end[i] - from;
        let length = if (c[0] - end[X]).abs() > tiny
            || (c[1] - end[Y]).abs() > tiny
            || (c[2] - end[Z]).abs() > tiny
        {
            (d(X, c[0]).powi(2) + d(Y, c[1]).powi(2) + d(Z, c[2]).powi(2)).sqrt()
        } else if (6..9).any(|i| (self.cur[i] - end[i]).abs() > tiny) {
            (6..9)
                .map(|i| d(i, self.cur[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        } else {
            (3..6)
                .map(|i| d(i, self.cur[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let rate = (length * b.or(b'f', 0.0)).max(0.1);
        self.enqueue(CanonCmd::SetFeedRate {
            mm_per_min: self.len_mm(rate),
        });
        self.feed_rate = rate;
    }

    /// Set the feed rate an inverse-time arc needs (plane coordinates).
    pub(crate) fn inverse_time_rate_arc(
        &mut self,
        start: [f64; 3],
        center: [f64; 2],
        turn: i32,
        end: [f64; 3],
        b: &Block,
    ) {
        if self.feed_mode != FeedMode::InverseTime {
            return;
        }
        let radius = (center[0] - start[0]).hypot(center[1] - start[1]);
        let theta = crate::comp::find_turn(
            start[0], start[1], center[0], center[1], turn, end[0], end[1],
        );
        let length = if end[2] == start[2] {
            radius * theta.abs()
        } else {
            (radius * theta).hypot(end[2] - start[2])
        };
        let rate = (length * b.or(b'f', 0.0)).max(0.1);
        self.enqueue(CanonCmd::SetFeedRate {
            mm_per_min: self.len_mm(rate),
        });
        self.feed_rate = rate;
    }

    fn check_feed(&self, b: &Block, what: &str) -> R {
        match self.feed_mode {
            FeedMode::UnitsPerMinute => {
                chk!(self.feed_rate == 0.0, "Cannot {what} with zero feed rate");
            }
            FeedMode::UnitsPerRevolution => {
                chk!(self.feed_rate == 0.0, "Cannot {what} with zero feed rate");
                chk!(
                    self.speed == 0.0,
                    "Cannot feed with zero spindle speed in feed per rev mode"
                );
            }
            FeedMode::InverseTime => {
                chk!(
                    !b.has(b'f'),
                    "F word missing with inverse time {} move",
                    if what == "do g1" { "g1" } else { "arc" }
                );
            }
        }
        Ok(())
    }

    fn convert_straight(&mut self, mv: i32, b: &mut Block) -> R {
        self.arc_not_allowed = false;
        if mv == g::G1 {
            self.check_feed(b, "do g1")?;
        }
        self.motion_mode = mv;
        let end = self.find_ends(b)?;
        if mv == g::G1 {
            self.inverse_time_rate_straight(end, b);
        }
        let rest = [end[3], end[4], end[5], end[6], end[7], end[8]];
        if self.cutter_comp_side != Side::Off && self.cutter_comp_radius > 0.0 {
            chk!(
                b.g_modes[gm::MODAL_0] == g::G53,
                "Cannot use g53 with cutter radius comp"
            );
            let p = if self.plane == Plane::XZ {
                [end[Z], end[X], end[Y]]
            } else if self.plane == Plane::XY {
                [end[X], end[Y], end[Z]]
            } else {
                bail!("BUG: Invalid plane for cutter compensation");
            };
            if mv != g::G0 && mv != g::G1 {
                bail!(
                    "{} is not supported with cutter radius compensation",
                    crate::interp::gcode_name(mv)
                );
            }
            if self.cutter_comp_firstmove {
                return self.convert_straight_comp1(mv, p, rest);
            }
            return self.convert_straight_comp2(mv, p, rest);
        }
        match mv {
            g::G0 => {
                self.canon_straight_traverse(end);
                self.cur = end;
            }
            g::G1 => {
                self.canon_straight_feed(end);
                self.cur = end;
            }
            g::G33 => {
                self.start_position_sync("G33", b)?;
                self.canon_straight_feed(end);
                self.emit(CanonCmd::StopSpeedFeedSync);
                self.cur = end;
            }
            g::G33_1 => {
                self.start_position_sync("G33.1", b)?;
                let scale = b.get(b'i').map(|i| i.max(1.0)).unwrap_or(1.0);
                self.canon_rigid_tap(end, scale);
                self.emit(CanonCmd::StopSpeedFeedSync);
            }
            _ => {
                // G76 threading.
                self.check_synced_spindle("G76", b)?;
                chk!(
                    (3..9).any(|i| self.cur[i] != end[i]),
                    "Cannot move rotary axes during threading move"
                );
                self.convert_threading_cycle(b, end)?;
            }
        }
        self.cur[3..9].copy_from_slice(&rest);
        Ok(())
    }

    /// Check the spindle for `code` and lock following moves to it at K
    /// program units per revolution.
    fn start_position_sync(&mut self, code: &str, b: &Block) -> R {
        self.check_synced_spindle(code, b)?;
        let k = b.or(b'k', 0.0);
        self.emit(CanonCmd::StartSpeedFeedSync {
            spindle: self.active_spindle,
            mm_per_rev: self.len_mm(k),
            velocity_mode: false,
        });
        Ok(())
    }

    fn check_synced_spindle(&mut self, what: &str, b: &Block) -> R {
        if let Some(d) = b.dollar {
            chk!(
                d < 0.0 || d >= self.cfg.spindles as f64,
                "Invalid spindle ($) number in {what} move"
            );
            self.active_spindle = d as u32;
        }
        chk!(
            self.spindle_turning == Turning::Stopped,
            "Spindle not turning in {what}"
        );
        Ok(())
    }

    fn convert_probe(&mut self, code: i32, b: &Block) -> R {
        let probe_type = code - g::G38_2;
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot probe with cutter radius compensation on"
        );
        chk!(self.feed_rate == 0.0, "Cannot probe with zero feed rate");
        chk!(
            self.feed_mode == FeedMode::UnitsPerRevolution,
            "Cannot probe with feed per rev mode"
        );
        let end = self.find_ends(b)?;
        chk!(
            probe_type & 1 == 0 && end == self.cur,
            "Start point too close to probe point"
        );
        let kind = ProbeKind {
            toward: probe_type & 2 == 0,
            error_if_no_trip: probe_type & 1 == 0,
        };
        self.canon_straight_probe(end, kind);
        self.motion_mode = code;
        self.probe_flag = true;
        Ok(())
    }

    fn convert_arc(&mut self, mv: i32, b: &mut Block) -> R {
        chk!(
            self.arc_not_allowed,
            "The move just after exiting cutter compensation mode must be straight, not an arc"
        );
        let ijk = b.has(b'i') || b.has(b'j') || b.has(b'k');
        let first = self.cutter_comp_firstmove;
        chk!(
            matches!(self.plane, Plane::UV | Plane::VW | Plane::UW),
            "Cannot do an arc in planes G17.1, G18.1, or G19.1"
        );
        chk!(!b.has(b'r') && !ijk, "R i j k words all missing for arc");
        chk!(b.has(b'r') && ijk, "Mixed radius-ijk format for arc");
        self.check_feed(b, "make arc")?;
        let absolute = self.ijk_distance_mode == Distance::Absolute;
        if ijk {
            let (present, missing_a, missing_b, forbidden, forbidden_msg) = match self.plane {
                Plane::XY => (
                    (b'i', b'j'),
                    'I',
                    'J',
                    b'k',
                    "K word given for arc in xy plane",
                ),
                Plane::YZ => (
                    (b'j', b'k'),
                    'J',
                    'K',
                    b'i',
                    "I word given for arc in yz plane",
                ),
                _ => (
                    (b'i', b'k'),
                    'I',
                    'K',
                    b'j',
                    "J word given for arc in xz plane",
                ),
            };
            chk!(b.has(forbidden), "{forbidden_msg}");
            if !b.has(present.0) {
                chk!(absolute, "{missing_a} word missing in absolute center arc");
                b.set(present.0, 0.0);
            } else if !b.has(present.1) {
                chk!(absolute, "{missing_b} word missing in absolute center arc");
                b.set(present.1, 0.0);
            }
        } else {
            match self.plane {
                Plane::XY => chk!(
                    !b.has(b'x') && !b.has(b'y') && b.radius.is_none() && b.theta.is_none(),
                    "X and Y words missing for arc in xy plane"
                ),
                Plane::YZ => chk!(
                    !b.has(b'y') && !b.has(b'z'),
                    "Y and Z words missing for arc in yz plane"
                ),
                _ => chk!(
                    !b.has(b'x') && !b.has(b'z'),
                    "X and Z words missing for arc in xz plane"
                ),
            }
        }
        let end = self.find_ends(b)?;
        self.motion_mode = mv;
        let rest = [end[3], end[4], end[5], end[6], end[7], end[8]];
        let comp = self.cutter_comp_side != Side::Off && self.cutter_comp_radius != 0.0;
        let i = b.or(b'i', 0.0);
        let j = b.or(b'j', 0.0);
        let k = b.or(b'k', 0.0);
        match self.plane {
            Plane::XY => {
                let e = [end[X], end[Y], end[Z]];
                if !comp {
                    self.convert_arc2(mv, b, [X, Y, Z], e, [i, j], rest)
                } else if first {
                    self.convert_arc_comp1(mv, b, e, [i, j], rest)
                } else {
                    self.convert_arc_comp2(mv, b, e, [i, j], rest)
                }
            }
            Plane::XZ => {
                let e = [end[Z], end[X], end[Y]];
                if !comp {
                    self.convert_arc2(mv, b, [Z, X, Y], e, [k, i], rest)
                } else if first {
                    self.convert_arc_comp1(mv, b, e, [k, i], rest)
                } else {
                    self.convert_arc_comp2(mv, b, e, [k, i], rest)
                }
            }
            _ => self.convert_arc2(mv, b, [Y, Z, X], [end[Y], end[Z], end[X]], [j, k], rest),
        }
    }

    /// An uncompensated arc; `axes` are the indices of the plane's first,
    /// second and normal axes.
    fn convert_arc2(
        &mut self,
        mv: i32,
        b: &Block,
        axes: [usize; 3],
        end: [f64; 3],
        offset: [f64; 2],
        rest: [f64; 6],
    ) -> R {
        let (spiral_abs, radius_tol) = self.arc_tolerances();
        let cur = [self.cur[axes[0]], self.cur[axes[1]], self.cur[axes[2]]];
        let p_turns = b.get(b'p').map(round_to_int).unwrap_or(1);
        let (center, turn) = if let Some(r) = b.get(b'r') {
            self.arc_data_r(mv, cur[0], cur[1], end[0], end[1], r, p_turns, radius_tol)?
        } else {
            self.arc_data_ijk(
                mv, cur[0], cur[1], end[0], end[1], offset, p_turns, radius_tol, spiral_abs,
            )?
        };
        self.inverse_time_rate_arc(cur, center, turn, end, b);
        self.canon_arc_feed(
            end[0],
            end[1],
            center[0],
            center[1],
            turn,
            end[2],
            [rest[0], rest[1], rest[2]],
            [rest[3], rest[4], rest[5]],
        )?;
        for k in 0..3 {
            self.cur[axes[k]] = end[k];
        }
        self.cur[3..9].copy_from_slice(&rest);
        Ok(())
    }

    fn arc_axis_names(&self) -> (char, char) {
        match self.plane {
            Plane::XY => ('X', 'Y'),
            Plane::XZ => ('Z', 'X'),
            Plane::YZ => ('Y', 'Z'),
            _ => ('!', '!'),
        }
    }

    /// Centre and turn of a centre-format (I J K) arc, checking that the
    /// end lies on the circle within tolerance.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn arc_data_ijk(
        &self,
        mv: i32,
        cx: f64,
        cy: f64,
        ex: f64,
        ey: f64,
        offset: [f64; 2],
        p_number: i32,
        radius_tolerance: f64,
        spiral_abs: f64,
    ) -> R<([f64; 2], i32)> {
        let (a, bb) = self.arc_axis_names();
        let center = if self.ijk_distance_mode == Distance::Absolute {
            offset
        } else {
            [cx + offset[0], cy + offset[1]]
        };
        let radius = (center[0] - cx).hypot(center[1] - cy);
        let radius2 = (center[0] - ex).hypot(center[1] - ey);
        if radius < radius_tolerance || radius2 < radius_tolerance {
            return Err(Fault::new(format!(
                "Zero-radius arc: start=({a}{cx:.4},{bb}{cy:.4}) center=({a}{:.4},{bb}{:.4}) end=({a}{ex:.4},{bb}{ey:.4}) r1={radius:.4} r2={radius2:.4}",
                center[0], center[1]
            )));
        }
        let abs_err = (radius - radius2).abs();
        let rel_err = abs_err / radius.max(radius2);
        if abs_err > spiral_abs * 100.0
            || (rel_err > SPIRAL_RELATIVE_TOLERANCE && abs_err > spiral_abs)
        {
            return Err(Fault::new(format!(
                "Radius to end of arc differs from radius to start: start=({a}{cx:.4},{bb}{cy:.4}) center=({a}{:.4},{bb}{:.4}) end=({a}{ex:.4},{bb}{ey:.4}) r1={radius:.4} r2={radius2:.4} abs_err={} rel_err={:.4}%",
                center[0],
                center[1],
                fmt_g(abs_err, 4),
                rel_err * 100.0
            )));
        }
        let turn = if mv == g::G2 { -p_number } else { p_number };
        Ok((center, turn))
    }

    /// Centre and turn of a radius-format (R) arc: negative R takes the
    /// long way round.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn arc_data_r(
        &self,
        mv: i32,
        cx: f64,
        cy: f64,
        ex: f64,
        ey: f64,
        radius: f64,
        p_number: i32,
        tolerance: f64,
    ) -> R<([f64; 2], i32)> {
        chk!(
            ex == cx && ey == cy,
            "Current point same as end point of arc"
        );
        let abs_radius = radius.abs();
        let mid_x = (ex + cx) / 2.0;
        let mid_y = (ey + cy) / 2.0;
        let mut half_length = (mid_x - ex).hypot(mid_y - ey);
        chk!(
            half_length - abs_radius > tolerance,
            "Arc radius too small to reach end point"
        );
        if half_length / abs_radius > 1.0 - TINY {
            half_length = abs_radius;
        }
        // LinuxCNC adds the long double M_PI_2l; rounding the same way keeps
        // centres that land on zero on the same side.
        let clockwise_short = (mv == g::G2 && radius > 0.0) || (mv == g::G3 && radius < 0.0);
        let theta = crate::ld::add_half_pi((ey - cy).atan2(ex - cx), clockwise_short);
        let turn2 = (half_length / abs_radius).asin();
        let offset = abs_radius * turn2.cos();
        let center = [mid_x + offset * theta.cos(), mid_y + offset * theta.sin()];
        let turn = if mv == g::G2 { -p_number } else { p_number };
        Ok((center, turn))
    }
}

#[cfg(test)]
mod tests {
    use super::fmt_g;

    #[test]
    fn c_style_g_format() {
        assert_eq!(fmt_g(0.2857, 4), "0.2857");
        assert_eq!(fmt_g(2.857142, 4), "2.857");
        assert_eq!(fmt_g(3.0000001, 4), "3");
        assert_eq!(fmt_g(0.002857, 4), "0.002857");
        assert_eq!(fmt_g(0.00002857, 4), "2.857e-05");
        assert_eq!(fmt_g(123456.0, 4), "1.235e+05");
        assert_eq!(fmt_g(1000.0, 4), "1000");
    }
}
