//! Cutter radius compensation (G40, G41, G42, G41.1, G42.1), following
//! LinuxCNC's algorithm.
//!
//! With compensation on, each move is held back in a small queue until the
//! next move shows how the corner between them must be cut: a convex
//! corner gets an arc around it, a concave one moves the end points of the
//! held moves back to where the tool touches both sides, and a corner the
//! tool cannot reach without cutting into the part (gouging) is an error.
//! Other commands given while moves are held wait in the queue behind them
//! so that their order is kept.

use std::f64::consts::{FRAC_PI_2, PI};

use crate::block::{g, gm, round_to_int, Block};
use crate::canon::{Canon, CanonCmd, Plane, Source};
use crate::error::{chk, Fault, R};
use crate::interp::{Interp, Side, X, Y, Z};

/// Corners within this angle (radians) of straight need no arc.
const TOLERANCE_CONCAVE_CORNER: f64 = 0.05;

/// A command held back by cutter compensation.
#[derive(Clone, Debug)]
pub(crate) enum Queued {
    /// A straight move; `end` and `dir` in X Y Z order (program units).
    Straight {
        feed: bool,
        source: Source,
        dir: [f64; 3],
        end: [f64; 9],
    },
    /// An arc in the compensation plane: end and centre on the plane's
    /// first and second axes, `end3` on the normal, `rest` A B C U V W.
    Arc {
        source: Source,
        original_turns: f64,
        end1: f64,
        end2: f64,
        center1: f64,
        center2: f64,
        turn: i32,
        end3: f64,
        rest: [f64; 6],
    },
    /// Any other command, already converted.
    Cmd(Canon),
}

/// True if the tool is on the inside of an arc turning this way.
fn tool_inside_arc(side: Side, turn: i32) -> bool {
    (side == Side::Left && turn > 0) || (side == Side::Right && turn < 0)
}

/// The angle swept from start to end around a centre, positive CCW, with
/// `turn` full or partial turns (LinuxCNC's `find_turn`).
pub(crate) fn find_turn(x1: f64, y1: f64, cx: f64, cy: f64, turn: i32, x2: f64, y2: f64) -> f64 {
    if turn == 0 {
        return 0.0;
    }
    let mut alpha = (y1 - cy).atan2(x1 - cx);
    let mut beta = (y2 - cy).atan2(x2 - cx);
    if turn > 0 {
        if beta <= alpha {
            beta += 2.0 * PI;
        }
        (beta - alpha) + (turn - 1) as f64 * 2.0 * PI
    } else {
        if alpha <= beta {
            alpha += 2.0 * PI;
        }
        (beta - alpha) + (turn + 1) as f64 * 2.0 * PI
    }
}

impl Interp<'_> {
    /// Give a command now, or queue it behind held moves.
    pub(crate) fn enqueue(&mut self, cmd: CanonCmd) {
        if self.queue.is_empty() {
            self.emit(cmd);
        } else {
            let source = self.source();
            self.queue.push(Queued::Cmd(Canon { source, cmd }));
        }
    }

    /// The current point in the compensation plane: (first, second, normal).
    pub(crate) fn comp_get_current(&self) -> [f64; 3] {
        if self.plane == Plane::XZ {
            [self.cur[Z], self.cur[X], self.cur[Y]]
        } else {
            [self.cur[X], self.cur[Y], self.cur[Z]]
        }
    }

    pub(crate) fn comp_set_current(&mut self, p: [f64; 3]) {
        if self.plane == Plane::XZ {
            self.cur[X] = p[1];
            self.cur[Y] = p[2];
            self.cur[Z] = p[0];
        } else {
            self.cur[X] = p[0];
            self.cur[Y] = p[1];
            self.cur[Z] = p[2];
        }
    }

    fn comp_get_programmed(&self) -> [f64; 3] {
        if self.plane == Plane::XZ {
            [self.program[2], self.program[0], self.program[1]]
        } else {
            self.program
        }
    }

    fn comp_set_programmed(&mut self, p: [f64; 3]) {
        if self.plane == Plane::XZ {
            self.program = [p[1], p[2], p[0]];
        } else {
            self.program = p;
        }
    }

    /// Plane-ordered (first, second, normal) to X Y Z order.
    fn plane_to_xyz(&self, p: [f64; 3]) -> [f64; 3] {
        if self.plane == Plane::XZ {
            [p[1], p[2], p[0]]
        } else {
            p
        }
    }

    fn enqueue_straight(&mut self, feed: bool, dir: [f64; 3], end: [f64; 3], rest: [f64; 6]) {
        let mut full = [0.0; 9];
        let xyz = self.plane_to_xyz(end);
        full[..3].copy_from_slice(&xyz);
        full[3..].copy_from_slice(&rest);
        let dir = self.plane_to_xyz(dir);
        let source = self.source();
        self.queue.push(Queued::Straight {
            feed,
            source,
            dir,
            end: full,
        });
    }

    #[allow(clippy::too_many_arguments)]
    fn enqueue_arc(
        &mut self,
        original_turns: f64,
        end1: f64,
        end2: f64,
        center1: f64,
        center2: f64,
        turn: i32,
        end3: f64,
        rest: [f64; 6],
    ) {
        let source = self.source();
        self.queue.push(Queued::Arc {
            source,
            original_turns,
            end1,
            end2,
            center1,
            center2,
            turn,
            end3,
            rest,
        });
    }

    fn set_endpoint(&mut self, x: f64, y: f64) {
        self.queue_endpoint = Some([x, y]);
    }

    /// Lathe tools are compensated about the tip radius centre, which is
    /// off the tool's control point for orientations 1–8: the shift from
    /// that centre to the control point on X and on Z (zero off G18).
    fn lathe_tip_shift(&self) -> (f64, f64) {
        if self.plane != Plane::XZ {
            return (0.0, 0.0);
        }
        let r = self.cutter_comp_radius;
        let dx = match self.cutter_comp_orientation {
            1 | 2 | 6 => -r,
            3 | 4 | 8 => r,
            _ => 0.0,
        };
        let dz = match self.cutter_comp_orientation {
            2 | 3 | 7 => -r,
            1 | 4 | 5 => r,
            _ => 0.0,
        };
        (dx, dz)
    }

    fn lathe_origin_x(&self, x: f64) -> f64 {
        x + self.lathe_tip_shift().0
    }

    fn lathe_origin_z(&self, z: f64) -> f64 {
        z + self.lathe_tip_shift().1
    }

    /// Give every held command, in order.
    pub(crate) fn dequeue_canons(&mut self) -> R {
        self.queue_endpoint = None;
        let queue = std::mem::take(&mut self.queue);
        for q in queue {
            match q {
                Queued::Cmd(c) => self.out.push_back(c),
                Queued::Straight {
                    feed, source, end, ..
                } => {
                    let mut p = end;
                    p[X] = self.lathe_origin_x(p[X]);
                    p[Z] = self.lathe_origin_z(p[Z]);
                    let end = self.program_to_machine(p);
                    let cmd = if feed {
                        CanonCmd::StraightFeed { end }
                    } else {
                        CanonCmd::StraightTraverse { end }
                    };
                    self.out.push_back(Canon { source, cmd });
                }
                Queued::Arc {
                    source,
                    end1,
                    end2,
                    center1,
                    center2,
                    turn,
                    end3,
                    rest,
                    ..
                } => {
                    let (e1, e2, c1, c2) = if self.plane == Plane::XZ {
                        (
                            self.lathe_origin_z(end1),
                            self.lathe_origin_x(end2),
                            self.lathe_origin_z(center1),
                            self.lathe_origin_x(center2),
                        )
                    } else {
                        (end1, end2, center1, center2)
                    };
                    let before = self.out.len();
                    self.canon_arc_feed(
                        e1,
                        e2,
                        c1,
                        c2,
                        turn,
                        end3,
                        [rest[0], rest[1], rest[2]],
                        [rest[3], rest[4], rest[5]],
                    )?;
                    if let Some(c) = self.out.get_mut(before) {
                        c.source = source;
                    }
                }
            }
        }
        Ok(())
    }

    /// Move the end of every held move to (x, y) in the compensation
    /// plane, checking that none now runs backwards (a gouge), then give
    /// them.
    pub(crate) fn move_endpoint_and_flush(&mut self, x: f64, y: f64) -> R {
        if self.queue.is_empty() {
            return Ok(());
        }
        let endpoint = self.queue_endpoint;
        let endpoint_valid = endpoint.is_some();
        let ep = endpoint.unwrap_or([0.0, 0.0]);
        let xz = self.plane == Plane::XZ;
        let tol = if self.length_units == crate::canon::Units::Mm {
            0.0254
        } else {
            0.001
        };
        let mut queue = std::mem::take(&mut self.queue);
        for q in queue.iter_mut() {
            match q {
                Queued::Arc {
                    original_turns,
                    end1,
                    end2,
                    center1,
                    center2,
                    turn,
                    ..
                } => {
                    let r1 = (*end1 - *center1).hypot(*end2 - *center2);
                    let l1 = *original_turns;
                    let r2 = (x - *center1).hypot(y - *center2);
                    let l2 = find_turn(ep[0], ep[1], *center1, *center2, *turn, x, y);
                    if (r1 - r2).abs() > 0.01 {
                        self.queue = queue;
                        return Err(Fault::new(format!(
                            "BUG: cutter compensation has generated an invalid arc with mismatched radii r1 {r1:.6} r2 {r2:.6}\n"
                        )));
                    }
                    if l1 != 0.0 && endpoint_valid && l2.abs() > l1.abs() + tol {
                        self.queue = queue;
                        return Err(Fault::new(
                            "Arc move in concave corner cannot be reached by the tool without gouging",
                        ));
                    }
                    *end1 = x;
                    *end2 = y;
                }
                Queued::Straight { feed, dir, end, .. } => {
                    let (x1, y1) = if xz {
                        (dir[2], dir[0])
                    } else {
                        (dir[0], dir[1])
                    };
                    let (x2, y2) = (x - ep[0], y - ep[1]);
                    let dot = x1 * x2 + y1 * y2;
                    if endpoint_valid && dot < 0.0 {
                        let what = if *feed {
                            "Straight feed"
                        } else {
                            "Straight traverse"
                        };
                        self.queue = queue;
                        return Err(Fault::new(format!(
                            "{what} in concave corner cannot be reached by the tool without gouging"
                        )));
                    }
                    if xz {
                        end[Z] = x;
                        end[X] = y;
                    } else {
                        end[X] = x;
                        end[Y] = y;
                    }
                }
                Queued::Cmd(_) => {}
            }
        }
        self.queue = queue;
        self.dequeue_canons()?;
        self.set_endpoint(x, y);
        Ok(())
    }

    /// Flush held moves at the current point (program end, compensation off).
    pub(crate) fn comp_flush_all(&mut self) -> R {
        let c = self.comp_get_current();
        self.move_endpoint_and_flush(c[0], c[1])?;
        self.dequeue_canons()
    }

    /// Rescale held moves after a unit change.
    pub(crate) fn comp_queue_scale(&mut self, k: f64) {
        if self.queue.is_empty() {
            return;
        }
        if let Some(ep) = &mut self.queue_endpoint {
            ep[0] *= k;
            ep[1] *= k;
        }
        for q in &mut self.queue {
            match q {
                Queued::Arc {
                    end1,
                    end2,
                    center1,
                    center2,
                    end3,
                    rest,
                    ..
                } => {
                    *end1 *= k;
                    *end2 *= k;
                    *end3 *= k;
                    *center1 *= k;
                    *center2 *= k;
                    for v in &mut rest[3..] {
                        *v *= k;
                    }
                }
                Queued::Straight { end, .. } => {
                    for i in [0, 1, 2, 6, 7, 8] {
                        end[i] *= k;
                    }
                }
                Queued::Cmd(_) => {}
            }
        }
    }

    /// G40, G41, G42, G41.1, G42.1.
    pub(crate) fn convert_cutter_compensation(&mut self, b: &Block) -> R {
        let code = b.g_modes[gm::CUTTER_COMP];
        if code == g::G40 {
            self.enqueue_debug_comment("interpreter: cutter radius compensation off");
            if self.cutter_comp_side != Side::Off
                && self.cutter_comp_radius > 0.0
                && !self.cutter_comp_firstmove
            {
                let c = self.comp_get_current();
                self.move_endpoint_and_flush(c[0], c[1])?;
                self.dequeue_canons()?;
                self.cur[X] = self.program[0];
                self.cur[Y] = self.program[1];
                self.cur[Z] = self.program[2];
                self.arc_not_allowed = true;
            }
            self.cutter_comp_side = Side::Off;
            self.cutter_comp_firstmove = true;
            return Ok(());
        }
        let mut side = if code == g::G41 || code == g::G41_1 {
            Side::Left
        } else {
            Side::Right
        };
        chk!(
            self.plane != Plane::XY && self.plane != Plane::XZ,
            "Radius compensation allowed only in XY and XZ planes"
        );
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot turn cutter radius comp on when already on"
        );
        let (mut radius, orientation);
        if code == g::G41_1 || code == g::G42_1 {
            let Some(d) = b.get(b'd') else {
                return Err(Fault::new(format!("G{}.1 with no D word", code / 10)));
            };
            radius = d / 2.0;
            if b.has(b'l') {
                chk!(
                    self.plane != Plane::XZ,
                    "G{}.1 with L word, but plane is not G18",
                    code / 10
                );
                orientation = b.l();
            } else {
                orientation = 0;
            }
        } else {
            let idx = match b.get(b'd') {
                None => 0,
                Some(d) => {
                    let tool = (d + 0.5) as i32;
                    chk!(
                        (tool as f64 - d).abs() >= 0.0001,
                        "G{} requires D word to be a whole number",
                        code / 10
                    );
                    chk!(tool < 0, "Negative d word tool radius index used");
                    self.find_tool_index(tool)?
                }
            };
            let t = self.tools.get(idx);
            radius = self.user_len_to_program(t.diameter) / 2.0;
            orientation = t.orientation;
            chk!(
                self.plane != Plane::XZ && orientation != 0 && orientation != 9,
                "G{} with lathe tool, but plane is not G18",
                code / 10
            );
        }
        if radius < 0.0 {
            radius = -radius;
            side = if side == Side::Right {
                Side::Left
            } else {
                Side::Right
            };
        }
        self.enqueue_debug_comment(if side == Side::Right {
            "interpreter: cutter radius compensation on right"
        } else {
            "interpreter: cutter radius compensation on left"
        });
        self.cutter_comp_radius = radius;
        self.cutter_comp_orientation = orientation;
        self.cutter_comp_side = side;
        Ok(())
    }

    /// The first straight move after compensation comes on: end tangent to
    /// the programmed end point on the compensation side.
    pub(crate) fn convert_straight_comp1(&mut self, mv: i32, p: [f64; 3], rest: [f64; 6]) -> R {
        let radius = self.cutter_comp_radius;
        let side = self.cutter_comp_side;
        let c = self.comp_get_current();
        let distance = (p[0] - c[0]).hypot(p[1] - c[1]);
        chk!(
            distance <= radius,
            "Length of cutter compensation entry move is not greater than the tool radius"
        );
        let alpha = (p[1] - c[1]).atan2(p[0] - c[0])
            + if side == Side::Left {
                FRAC_PI_2
            } else {
                -FRAC_PI_2
            };
        let end_x = p[0] + radius * alpha.cos();
        let end_y = p[1] + radius * alpha.sin();
        self.set_endpoint(c[0], c[1]);
        self.enqueue_straight(
            mv == g::G1,
            [alpha.cos(), alpha.sin(), 0.0],
            [end_x, end_y, p[2]],
            rest,
        );
        self.cutter_comp_firstmove = false;
        self.comp_set_current([end_x, end_y, p[2]]);
        self.set_rest(rest);
        self.comp_set_programmed(p);
        Ok(())
    }

    fn set_rest(&mut self, rest: [f64; 6]) {
        self.cur[3..9].copy_from_slice(&rest);
    }

    /// A straight move with compensation on, after the first.
    pub(crate) fn convert_straight_comp2(&mut self, mv: i32, p: [f64; 3], rest: [f64; 6]) -> R {
        let c = self.comp_get_current();
        let mut end = c;
        let op = self.comp_get_programmed();
        let feed = mv == g::G1;
        if p[1] == op[1] && p[0] == op[0] {
            self.enqueue_straight(
                feed,
                [p[0] - op[0], p[1] - op[1], p[2] - op[2]],
                [c[0], c[1], p[2]],
                rest,
            );
        } else {
            let side = self.cutter_comp_side;
            let radius = self.cutter_comp_radius;
            let small = TOLERANCE_CONCAVE_CORNER;
            let mut theta = (c[1] - op[1]).atan2(c[0] - op[0]);
            let mut alpha = (p[1] - op[1]).atan2(p[0] - op[0]);
            let (beta, gamma) = if side == Side::Left {
                if theta < alpha {
                    theta += 2.0 * PI;
                }
                ((theta - alpha) - FRAC_PI_2, FRAC_PI_2)
            } else {
                if alpha < theta {
                    alpha += 2.0 * PI;
                }
                ((alpha - theta) - FRAC_PI_2, -FRAC_PI_2)
            };
            end[0] = p[0] + radius * (alpha + gamma).cos();
            end[1] = p[1] + radius * (alpha + gamma).sin();
            let mut mid_x = op[0] + radius * (alpha + gamma).cos();
            let mut mid_y = op[1] + radius * (alpha + gamma).sin();
            let front_arc_turn = match self.queue.first() {
                Some(Queued::Arc { turn, .. }) => Some(*turn),
                _ => None,
            };
            let concave = if beta < -small || beta > PI + small {
                true
            } else {
                beta > PI - small
                    && front_arc_turn.is_some_and(|t| {
                        (side == Side::Right && t > 0) || (side == Side::Left && t < 0)
                    })
            };
            if !concave && beta > small {
                self.move_endpoint_and_flush(c[0], c[1])?;
                if feed {
                    self.enqueue_arc(
                        0.0,
                        mid_x,
                        mid_y,
                        op[0],
                        op[1],
                        if side == Side::Left { -1 } else { 1 },
                        c[2],
                        rest,
                    );
                } else {
                    self.enqueue_straight(false, [0.0; 3], [mid_x, mid_y, c[2]], rest);
                }
                self.dequeue_canons()?;
                self.set_endpoint(mid_x, mid_y);
            } else if concave {
                if let Some(Queued::Arc {
                    end1,
                    end2,
                    center1,
                    center2,
                    turn,
                    ..
                }) = self.queue.first().cloned()
                {
                    let oldrad = (center2 - end2).hypot(center1 - end1);
                    let base_dir = (p[1] - op[1]).atan2(p[0] - op[0]);
                    let theta = if turn > 0 {
                        base_dir + FRAC_PI_2
                    } else {
                        base_dir - FRAC_PI_2
                    };
                    let phi = (center2 - op[1]).atan2(center1 - op[0]);
                    let inside = tool_inside_arc(side, turn);
                    let oldrad_uncomp = if inside {
                        oldrad + radius
                    } else {
                        oldrad - radius
                    };
                    let d = oldrad_uncomp * (theta - phi).cos();
                    let d2 = if inside { d - radius } else { d + radius };
                    let l = d2 / oldrad;
                    chk!(
                        !(-1.0..=1.0).contains(&l),
                        "Arc to straight motion makes a corner the compensated tool can't fit in without gouging"
                    );
                    let angle = if inside == (turn > 0) {
                        -l.acos() + theta + PI
                    } else {
                        l.acos() + theta + PI
                    };
                    mid_x = center1 + oldrad * angle.cos();
                    mid_y = center2 + oldrad * angle.sin();
                    self.move_endpoint_and_flush(mid_x, mid_y)?;
                } else {
                    let halfcorner = (beta + PI) / 2.0;
                    chk!(
                        halfcorner == 0.0,
                        "Zero degree inside corner is invalid for cutter compensation"
                    );
                    let retreat = radius / halfcorner.tan();
                    mid_x = c[0] + retreat * (theta + gamma).cos();
                    mid_y = c[1] + retreat * (theta + gamma).sin();
                    self.move_endpoint_and_flush(mid_x, mid_y)?;
                }
            } else {
                self.dequeue_canons()?;
                self.set_endpoint(c[0], c[1]);
            }
            self.enqueue_straight(
                feed,
                [p[0] - op[0], p[1] - op[1], p[2] - op[2]],
                [end[0], end[1], p[2]],
                rest,
            );
        }
        self.comp_set_current([end[0], end[1], p[2]]);
        self.set_rest(rest);
        self.comp_set_programmed(p);
        Ok(())
    }

    /// The first arc after compensation comes on.
    pub(crate) fn convert_arc_comp1(
        &mut self,
        mv: i32,
        b: &Block,
        end: [f64; 3],
        offset: [f64; 2],
        rest: [f64; 6],
    ) -> R {
        let side = self.cutter_comp_side;
        let tool_radius = self.cutter_comp_radius;
        let (spiral_abs, radius_tol) = self.arc_tolerances();
        let c = self.comp_get_current();
        chk!(
            (end[0] - c[0]).hypot(end[1] - c[1]) <= tool_radius,
            "Radius of cutter compensation entry arc is not greater than the tool radius"
        );
        let p_turns = b.get(b'p').map(round_to_int).unwrap_or(1);
        let (mut center, turn) = if let Some(r) = b.get(b'r') {
            chk!(
                r.abs() <= tool_radius
                    && ((side == Side::Left && mv == g::G3)
                        || (side == Side::Right && mv == g::G2)),
                "Tool radius not less than arc radius with comp"
            );
            self.arc_data_r(mv, c[0], c[1], end[0], end[1], r, p_turns, radius_tol)?
        } else {
            let (center, turn) = self.arc_data_ijk(
                mv, c[0], c[1], end[0], end[1], offset, p_turns, radius_tol, spiral_abs,
            )?;
            let arc_radius = (center[0] - c[0]).hypot(center[1] - c[1]);
            chk!(
                arc_radius <= tool_radius
                    && ((side == Side::Left && mv == g::G3)
                        || (side == Side::Right && mv == g::G2)),
                "Tool radius not less than arc radius with comp"
            );
            (center, turn)
        };
        self.inverse_time_rate_arc(c, center, turn, end, b);
        let gamma = if tool_inside_arc(side, turn) {
            (center[1] - end[1]).atan2(center[0] - end[0])
        } else {
            (end[1] - center[1]).atan2(end[0] - center[0])
        };
        self.cutter_comp_firstmove = false;
        self.comp_set_programmed(end);
        let end_x = end[0] + tool_radius * gamma.cos();
        let end_y = end[1] + tool_radius * gamma.sin();
        let b_len = (c[1] - end_y).hypot(c[0] - end_x) / 2.0;
        let ab_ang = (center[1] - end_y).atan2(center[0] - end_x);
        let a_ang = (c[1] - end_y).atan2(c[0] - end_x) - ab_ang;
        chk!(
            a_ang.cos().abs() < 0.0001,
            "Tool radius not less than arc radius with comp"
        );
        let c_len = b_len / a_ang.cos();
        center = [end_x + c_len * ab_ang.cos(), end_y + c_len * ab_ang.sin()];
        chk!(
            ((center[0] - end_x).hypot(center[1] - end_y)
                - (center[0] - c[0]).hypot(center[1] - c[1]))
            .abs()
                > spiral_abs,
            "Bug in tool radius comp"
        );
        if self.cutter_comp_orientation != 0 && self.cutter_comp_orientation != 9 {
            self.enqueue_straight(true, [0.0; 3], c, rest);
            self.set_endpoint(c[0], c[1]);
        }
        let sweep = find_turn(c[0], c[1], center[0], center[1], turn, end_x, end_y);
        self.enqueue_arc(
            sweep, end_x, end_y, center[0], center[1], turn, end[2], rest,
        );
        self.comp_set_current([end_x, end_y, end[2]]);
        self.set_rest(rest);
        Ok(())
    }

    /// An arc with compensation on, after the first move.
    pub(crate) fn convert_arc_comp2(
        &mut self,
        mv: i32,
        b: &Block,
        end: [f64; 3],
        offset: [f64; 2],
        rest: [f64; 6],
    ) -> R {
        let (spiral_abs, radius_tol) = self.arc_tolerances();
        let op = self.comp_get_programmed();
        let c = self.comp_get_current();
        let p_turns = b.get(b'p').map(round_to_int).unwrap_or(1);
        let ([cx_, cy_], turn) = if let Some(r) = b.get(b'r') {
            self.arc_data_r(mv, op[0], op[1], end[0], end[1], r, p_turns, radius_tol)?
        } else {
            self.arc_data_ijk(
                mv, op[0], op[1], end[0], end[1], offset, p_turns, radius_tol, spiral_abs,
            )?
        };
        let (centerx, centery) = (cx_, cy_);
        self.inverse_time_rate_arc(op, [centerx, centery], turn, end, b);
        let side = self.cutter_comp_side;
        let tool_radius = self.cutter_comp_radius;
        let small = TOLERANCE_CONCAVE_CORNER;
        let arc_radius = (centerx - end[0]).hypot(centery - end[1]);
        let mut theta = (c[1] - op[1]).atan2(c[0] - op[0]);
        theta = if side == Side::Left {
            theta - FRAC_PI_2
        } else {
            theta + FRAC_PI_2
        };
        let mut delta = (centery - op[1]).atan2(centerx - op[0]);
        let alpha = if mv == g::G3 {
            delta - FRAC_PI_2
        } else {
            delta + FRAC_PI_2
        };
        let mut beta = if side == Side::Left {
            theta - alpha
        } else {
            alpha - theta
        };
        if beta > 1.5 * PI {
            beta -= 2.0 * PI;
        } else if beta < -FRAC_PI_2 {
            beta += 2.0 * PI;
        }
        let gamma;
        if (side == Side::Left && mv == g::G3) || (side == Side::Right && mv == g::G2) {
            gamma = (centery - end[1]).atan2(centerx - end[0]);
            chk!(
                arc_radius <= tool_radius,
                "Tool radius not less than arc radius with comp"
            );
        } else {
            gamma = (end[1] - centery).atan2(end[0] - centerx);
            delta += PI;
        }
        let new_end_x = end[0] + tool_radius * gamma.cos();
        let new_end_y = end[1] + tool_radius * gamma.sin();
        let sweep = || find_turn(op[0], op[1], centerx, centery, turn, end[0], end[1]);
        if beta < -small
            || beta > PI + small
            || ((beta - PI).abs() < small && !tool_inside_arc(side, turn))
        {
            let front = self.queue.first().cloned();
            if let Some(Queued::Arc {
                end1,
                end2,
                center1,
                center2,
                turn: prev_turn,
                ..
            }) = front
            {
                let oldrad = (center2 - end2).hypot(center1 - end1);
                let newrad = if tool_inside_arc(side, turn) {
                    arc_radius - tool_radius
                } else {
                    arc_radius + tool_radius
                };
                let arc_cc = (center2 - centery).hypot(center1 - centerx);
                chk!(
                    oldrad == 0.0 || arc_cc == 0.0,
                    "Arc to arc motion is invalid because the arcs have the same center"
                );
                let a =
                    (oldrad * oldrad + arc_cc * arc_cc - newrad * newrad) / (2.0 * oldrad * arc_cc);
                chk!(
                    !(-1.0..=1.0).contains(&a),
                    "Arc to arc motion makes a corner the compensated tool can't fit in without gouging"
                );
                let pullback = a.acos();
                let cc_dir = (centery - center2).atan2(centerx - center1);
                let dir = if tool_inside_arc(side, prev_turn) == (turn > 0) {
                    cc_dir + pullback
                } else {
                    cc_dir - pullback
                };
                let midx = center1 + oldrad * dir.cos();
                let midy = center2 + oldrad * dir.sin();
                self.move_endpoint_and_flush(midx, midy)?;
            } else {
                let cyy = arc_radius * (beta - FRAC_PI_2).sin();
                let (dist_from_center, angle_from_center);
                if tool_inside_arc(side, turn) {
                    dist_from_center = arc_radius - tool_radius;
                    let l = (cyy + tool_radius) / dist_from_center;
                    chk!(
                        !(-1.0..=1.0).contains(&l),
                        "Arc move in concave corner cannot be reached by the tool without gouging"
                    );
                    angle_from_center = if turn > 0 {
                        theta + l.asin()
                    } else {
                        theta - l.asin()
                    };
                } else {
                    dist_from_center = arc_radius + tool_radius;
                    let l = (cyy - tool_radius) / dist_from_center;
                    chk!(
                        !(-1.0..=1.0).contains(&l),
                        "Arc move in concave corner cannot be reached by the tool without gouging"
                    );
                    angle_from_center = if turn > 0 {
                        theta + PI - l.asin()
                    } else {
                        theta + PI + l.asin()
                    };
                }
                let midx = centerx + dist_from_center * angle_from_center.cos();
                let midy = centery + dist_from_center * angle_from_center.sin();
                self.move_endpoint_and_flush(midx, midy)?;
            }
            let s = sweep();
            self.enqueue_arc(
                s, new_end_x, new_end_y, centerx, centery, turn, end[2], rest,
            );
        } else if beta > small {
            let midx = op[0] + tool_radius * delta.cos();
            let midy = op[1] + tool_radius * delta.sin();
            self.dequeue_canons()?;
            self.enqueue_arc(
                0.0,
                midx,
                midy,
                op[0],
                op[1],
                if side == Side::Left { -1 } else { 1 },
                c[2],
                rest,
            );
            self.dequeue_canons()?;
            self.set_endpoint(midx, midy);
            let s = sweep();
            self.enqueue_arc(
                s, new_end_x, new_end_y, centerx, centery, turn, end[2], rest,
            );
        } else {
            self.dequeue_canons()?;
            self.set_endpoint(c[0], c[1]);
            let s = sweep();
            self.enqueue_arc(
                s, new_end_x, new_end_y, centerx, centery, turn, end[2], rest,
            );
        }
        self.comp_set_programmed(end);
        self.comp_set_current([new_end_x, new_end_y, end[2]]);
        self.set_rest(rest);
        Ok(())
    }
}
