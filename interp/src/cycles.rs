//! Canned cycles G73, G74, G81–G89 in all six planes, with L repeats and
//! G98/G99 retract, as LinuxCNC runs them: the cycle's moves are exact-path
//! moves, and the path mode in force before is restored after.

use crate::block::{g, Block};
use crate::canon::{CanonCmd, MotionMode, OrientDirection, Plane, Units};
use crate::error::{bail, chk, Fault, R};
use crate::interp::{Distance, FeedMode, Interp, Retract, Side, Turning};

/// How far above the last depth G83 rapids back down, inch.
const G83_RAPID_DELTA: f64 = 0.010;

/// The axes of a cycle plane: first, second, and the drilling axis.
struct CyclePlane {
    plane: Plane,
    a: usize,
    b: usize,
    c: usize,
    /// Letters of those axes.
    la: u8,
    lb: u8,
    lc: u8,
    unspecified: &'static str,
    r_less: &'static str,
}

fn cycle_plane(p: Plane) -> CyclePlane {
    match p {
        Plane::XY => CyclePlane {
            plane: p,
            a: 0,
            b: 1,
            c: 2,
            la: b'x',
            lb: b'y',
            lc: b'z',
            unspecified: "Z value unspecified in xy plane canned cycle",
            r_less: "R less than z in cycle in xy plane",
        },
        Plane::YZ => CyclePlane {
            plane: p,
            a: 1,
            b: 2,
            c: 0,
            la: b'y',
            lb: b'z',
            lc: b'x',
            unspecified: "X value unspecified in yz plane canned cycle",
            r_less: "R less than x in cycle in yz plane",
        },
        Plane::XZ => CyclePlane {
            plane: p,
            a: 2,
            b: 0,
            c: 1,
            la: b'z',
            lb: b'x',
            lc: b'y',
            unspecified: "Y value unspecified in xz plane canned cycle",
            r_less: "R less than y in cycle in xz plane",
        },
        Plane::UV => CyclePlane {
            plane: p,
            a: 6,
            b: 7,
            c: 8,
            la: b'u',
            lb: b'v',
            lc: b'w',
            unspecified: "W value unspecified in UV plane canned cycle",
            r_less: "R less than W in cycle in UV plane",
        },
        Plane::VW => CyclePlane {
            plane: p,
            a: 7,
            b: 8,
            c: 6,
            la: b'v',
            lb: b'w',
            lc: b'u',
            unspecified: "U value unspecified in VW plane canned cycle",
            r_less: "R less than U in cycle in VW plane",
        },
        Plane::UW => CyclePlane {
            plane: p,
            a: 8,
            b: 6,
            c: 7,
            la: b'w',
            lb: b'u',
            lc: b'v',
            unspecified: "V value unspecified in UW plane canned cycle",
            r_less: "R less than V in cycle in UW plane",
        },
    }
}

fn plane_name(p: Plane) -> &'static str {
    match p {
        Plane::XY => "XY",
        Plane::YZ => "YZ",
        Plane::XZ => "XZ",
        Plane::UV => "UV",
        Plane::VW => "VW",
        Plane::UW => "UW",
    }
}

impl Interp<'_> {
    fn cycle_point(&self, cp: &CyclePlane, a: f64, b: f64, c: f64) -> [f64; 9] {
        let mut p = self.cur;
        p[cp.a] = a;
        p[cp.b] = b;
        p[cp.c] = c;
        p
    }

    fn cycle_feed(&mut self, cp: &CyclePlane, a: f64, b: f64, c: f64) {
        let p = self.cycle_point(cp, a, b, c);
        self.canon_straight_feed(p);
    }

    fn cycle_traverse(&mut self, cp: &CyclePlane, a: f64, b: f64, c: f64) {
        let p = self.cycle_point(cp, a, b, c);
        self.canon_straight_traverse(p);
    }

    fn spindle_restart(&mut self, direction: Turning) {
        self.emit(if direction == Turning::Clockwise {
            CanonCmd::StartSpindleClockwise { spindle: 0 }
        } else {
            CanonCmd::StartSpindleCounterclockwise { spindle: 0 }
        });
    }

    /// Stop the spindle and orient it to 0° (G87 back boring).
    fn stop_and_orient(&mut self, direction: OrientDirection) {
        self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
        self.emit(CanonCmd::OrientSpindle {
            spindle: 0,
            degrees: 0.0,
            direction,
        });
    }

    /// A canned cycle (G73, G74, G81–G89).
    pub(crate) fn convert_cycle(&mut self, motion: i32, b: &mut Block) -> R {
        chk!(self.feed_rate == 0.0, "Cannot feed with zero feed rate");
        chk!(
            self.feed_mode == FeedMode::InverseTime,
            "Cannot use inverse time feed with canned cycles"
        );
        chk!(
            self.cutter_comp_side != Side::Off,
            "Cannot use canned cycles with cutter compensation on"
        );
        if !b.has(b'r') {
            if self.motion_mode == motion {
                b.set(b'r', self.cycle_r);
            } else {
                bail!("R clearance plane unspecified in cycle");
            }
        }
        chk!(b.get(b'l') == Some(0.0), "Cannot do zero repeats of cycle");
        if !b.has(b'l') {
            b.set(b'l', 1.0);
        }
        let plane = self.plane;
        let pn = plane_name(plane);
        if matches!(plane, Plane::XY | Plane::XZ | Plane::YZ) {
            for l in [b'u', b'v', b'w'] {
                chk!(
                    b.has(l),
                    "Cannot put a {} in a canned cycle in the {pn} plane",
                    (l as char).to_ascii_uppercase()
                );
            }
        } else {
            for (l, article) in [(b'x', "an"), (b'y', "a"), (b'z', "a")] {
                chk!(
                    b.has(l),
                    "Cannot put {article} {} in a canned cycle in the {pn} plane",
                    (l as char).to_ascii_uppercase()
                );
            }
        }
        let cp = cycle_plane(plane);
        self.convert_cycle_plane(motion, b, &cp)?;
        self.cycle_l = b.l();
        self.cycle_r = b.or(b'r', 0.0);
        self.motion_mode = motion;
        Ok(())
    }

    fn convert_cycle_plane(&mut self, motion: i32, b: &mut Block, cp: &CyclePlane) -> R {
        let mut current_cc = self.cur[cp.c];
        if self.motion_mode != motion {
            chk!(!b.has(cp.lc), "{}", cp.unspecified);
        }
        let z = b.get(cp.lc).unwrap_or(self.cycle_cc);
        b.set(cp.lc, z);
        let mut old_cc = if self.cycle_il_flag {
            self.cycle_il
        } else {
            self.cycle_il = current_cc;
            self.cycle_il_flag = true;
            current_cc
        };
        let (mut aa, mut bb, r, cc);
        let (mut aa_inc, mut bb_inc, mut radius_inc, mut theta_inc) = (0.0, 0.0, 0.0, 0.0);
        let polar = cp.plane == Plane::XY;
        if self.distance_mode == Distance::Absolute {
            r = b.or(b'r', 0.0);
            cc = z;
            if polar && (b.radius.is_some() || b.theta.is_some()) {
                let radius = b.radius.unwrap_or_else(|| self.cur[1].hypot(self.cur[0]));
                let theta = b
                    .theta
                    .map(f64::to_radians)
                    .unwrap_or_else(|| self.cur[1].atan2(self.cur[0]));
                aa = radius * theta.cos();
                bb = radius * theta.sin();
            } else {
                aa = b.get(cp.la).unwrap_or(self.cur[cp.a]);
                bb = b.get(cp.lb).unwrap_or(self.cur[cp.b]);
            }
        } else {
            aa_inc = b.or(cp.la, 0.0);
            bb_inc = b.or(cp.lb, 0.0);
            if polar {
                radius_inc = b.radius.unwrap_or(0.0);
                theta_inc = b.theta.map(f64::to_radians).unwrap_or(0.0);
            }
            r = b.or(b'r', 0.0) + old_cc;
            cc = r + z;
            aa = self.cur[cp.a];
            bb = self.cur[cp.b];
        }
        chk!(r < cc, "{}", cp.r_less);
        if old_cc < r {
            let mut p = self.cur;
            p[cp.c] = r;
            self.canon_straight_traverse(p);
            old_cc = r;
            current_cc = old_cc;
        }
        let clear_cc = if self.retract_mode == Retract::RPlane {
            r
        } else {
            old_cc
        };
        let save_mode = self.control_mode;
        let save_cam = self.naivecam_tolerance;
        if save_mode != MotionMode::ExactPath {
            self.emit(CanonCmd::SetMotionControlMode(MotionMode::ExactPath));
        }

        // Cycle parameters, sticky from the previous block of the same cycle.
        let mut p_dwell = 0.0;
        let mut q_delta = 0.0;
        let (mut ci, mut cj, mut ck) = (0.0, 0.0, 0.0);
        match motion {
            g::G82 | g::G86 | g::G88 | g::G89 => {
                chk!(
                    self.motion_mode != motion && !b.has(b'p'),
                    "Dwell time p word missing with g{}",
                    motion / 10
                );
                p_dwell = b.get(b'p').unwrap_or(self.cycle_p);
            }
            g::G73 | g::G83 => {
                chk!(
                    self.motion_mode != motion && !b.has(b'q'),
                    "Q word missing with g{}",
                    motion / 10
                );
                q_delta = b.get(b'q').unwrap_or(self.cycle_q);
            }
            g::G74 | g::G84 => {
                p_dwell = b.get(b'p').unwrap_or(self.cycle_p);
                if let Some(d) = b.dollar {
                    chk!(
                        d < 0.0 || d >= self.cfg.spindles as f64,
                        "Invalid spindle ($) number in G74/G84 cycle"
                    );
                    self.active_spindle = d as u32;
                }
            }
            g::G87 => {
                if self.motion_mode != g::G87 {
                    chk!(!b.has(b'i'), "I word missing with g87");
                    chk!(!b.has(b'j'), "J word missing with g87");
                    chk!(!b.has(b'k'), "K word missing with g87");
                }
                ci = b.get(b'i').unwrap_or(self.cycle_i);
                cj = b.get(b'j').unwrap_or(self.cycle_j);
                ck = b.get(b'k').unwrap_or(self.cycle_k);
                self.cycle_i = ci;
                self.cycle_j = cj;
                self.cycle_k = ck;
                if self.distance_mode == Distance::Incremental {
                    ck += cc;
                }
            }
            _ => {}
        }
        let direction = self.spindle_turning;
        let repeats = b.l();
        let mut repeat = repeats;
        while repeat > 0 {
            aa += aa_inc;
            bb += bb_inc;
            if radius_inc != 0.0 {
                chk!(
                    bb == 0.0 && aa == 0.0,
                    "Incremental motion with polar coordinates is indeterminate when at the origin"
                );
                let theta = bb.atan2(aa);
                let radius = bb.hypot(aa) + radius_inc;
                aa = radius * theta.cos();
                bb = radius * theta.sin();
            }
            if theta_inc != 0.0 {
                chk!(
                    bb == 0.0 && aa == 0.0,
                    "Incremental motion with polar coordinates is indeterminate when at the origin"
                );
                let theta = bb.atan2(aa) + theta_inc;
                let radius = bb.hypot(aa);
                aa = radius * theta.cos();
                bb = radius * theta.sin();
            }
            if repeat == repeats && current_cc > r {
                self.cycle_traverse(cp, aa, bb, current_cc);
                self.cycle_traverse(cp, aa, bb, r);
            } else {
                self.cycle_traverse(cp, aa, bb, clear_cc);
                if clear_cc > r {
                    self.cycle_traverse(cp, aa, bb, r);
                }
            }
            match motion {
                g::G81 => {
                    self.cycle_feed(cp, aa, bb, cc);
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                }
                g::G82 => {
                    self.cycle_feed(cp, aa, bb, cc);
                    self.emit(CanonCmd::Dwell { seconds: p_dwell });
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                }
                g::G73 | g::G83 => {
                    chk!(q_delta <= 0.0, "Negative or zero q value used");
                    let rapid_delta = if self.length_units == Units::Mm {
                        G83_RAPID_DELTA * 25.4
                    } else {
                        G83_RAPID_DELTA
                    };
                    let mut depth = r - q_delta;
                    while depth > cc {
                        self.cycle_feed(cp, aa, bb, depth);
                        if motion == g::G83 {
                            self.cycle_traverse(cp, aa, bb, r);
                        }
                        self.cycle_traverse(cp, aa, bb, depth + rapid_delta);
                        depth -= q_delta;
                    }
                    self.cycle_feed(cp, aa, bb, cc);
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                }
                g::G74 | g::G84 => {
                    let name = if motion == g::G74 { "G74" } else { "G84" };
                    match direction {
                        Turning::Stopped => bail!("Spindle not turning in {name}"),
                        Turning::Clockwise => {
                            chk!(motion == g::G74, "Spindle turning clockwise in G74")
                        }
                        Turning::CounterClockwise => {
                            chk!(motion == g::G84, "Spindle turning counterclockwise in G84")
                        }
                    }
                    if !matches!(cp.plane, Plane::XY | Plane::YZ | Plane::XZ) {
                        bail!("{name} for plane {} not implemented", plane_name(cp.plane));
                    }
                    // LinuxCNC passes the tap's coordinates to its plane
                    // mapping in a different order for G18 and G19 (the
                    // tap moves along a plane axis there); kept so that
                    // programs behave as on LinuxCNC.
                    let tap = |depth: f64| match cp.plane {
                        Plane::YZ => (depth, aa, bb),
                        Plane::XZ => (bb, depth, aa),
                        _ => (aa, bb, depth),
                    };
                    let (feed_was, speed_was) = (self.feed_override, self.speed_override);
                    self.emit(CanonCmd::DisableFeedOverride);
                    self.emit(CanonCmd::DisableSpeedOverride { spindle: 0 });
                    let (ta, tb, tc) = tap(cc);
                    self.cycle_feed(cp, ta, tb, tc);
                    self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
                    self.spindle_restart(if motion == g::G84 {
                        Turning::CounterClockwise
                    } else {
                        Turning::Clockwise
                    });
                    self.emit(CanonCmd::Dwell { seconds: p_dwell });
                    let (ta, tb, tc) = tap(clear_cc);
                    self.cycle_feed(cp, ta, tb, tc);
                    self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
                    self.spindle_restart(if motion == g::G84 {
                        Turning::Clockwise
                    } else {
                        Turning::CounterClockwise
                    });
                    if feed_was {
                        self.emit(CanonCmd::EnableFeedOverride);
                    }
                    if speed_was {
                        self.emit(CanonCmd::EnableSpeedOverride { spindle: 0 });
                    }
                }
                g::G85 => {
                    self.cycle_feed(cp, aa, bb, cc);
                    self.cycle_feed(cp, aa, bb, r);
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                }
                g::G86 => {
                    chk!(direction == Turning::Stopped, "Spindle not turning in g86");
                    self.cycle_feed(cp, aa, bb, cc);
                    self.emit(CanonCmd::Dwell { seconds: p_dwell });
                    self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                    self.spindle_restart(direction);
                }
                g::G87 => {
                    chk!(direction == Turning::Stopped, "Spindle not turning in g87");
                    let orient = if direction == Turning::Clockwise {
                        OrientDirection::Clockwise
                    } else {
                        OrientDirection::CounterClockwise
                    };
                    let (oa, ob) = (aa + ci, bb + cj);
                    self.cycle_traverse(cp, oa, ob, r);
                    self.stop_and_orient(orient);
                    self.cycle_traverse(cp, oa, ob, cc);
                    self.cycle_traverse(cp, aa, bb, cc);
                    self.spindle_restart(direction);
                    self.cycle_feed(cp, aa, bb, ck);
                    self.cycle_feed(cp, aa, bb, cc);
                    self.stop_and_orient(orient);
                    self.cycle_traverse(cp, oa, ob, cc);
                    self.cycle_traverse(cp, oa, ob, clear_cc);
                    self.cycle_traverse(cp, aa, bb, clear_cc);
                    self.spindle_restart(direction);
                }
                g::G88 => {
                    chk!(direction == Turning::Stopped, "Spindle not turning in g88");
                    self.cycle_feed(cp, aa, bb, cc);
                    self.emit(CanonCmd::Dwell { seconds: p_dwell });
                    self.emit(CanonCmd::StopSpindleTurning { spindle: 0 });
                    self.emit(CanonCmd::ProgramStop);
                    self.spindle_restart(direction);
                }
                g::G89 => {
                    self.cycle_feed(cp, aa, bb, cc);
                    self.emit(CanonCmd::Dwell { seconds: p_dwell });
                    self.cycle_feed(cp, aa, bb, clear_cc);
                }
                _ => return Err(Fault::new("Bug function should not have been called")),
            }
            repeat -= 1;
        }
        match motion {
            g::G82 | g::G86 | g::G88 | g::G89 | g::G74 | g::G84 => self.cycle_p = p_dwell,
            g::G73 | g::G83 => self.cycle_q = q_delta,
            _ => {}
        }
        self.cur[cp.a] = aa;
        self.cur[cp.b] = bb;
        self.cur[cp.c] = clear_cc;
        self.cycle_cc = z;
        if save_mode != MotionMode::ExactPath {
            let restored = match save_mode {
                MotionMode::Continuous { tolerance } => MotionMode::Continuous {
                    tolerance: self.len_mm(tolerance),
                },
                other => other,
            };
            self.emit(CanonCmd::SetMotionControlMode(restored));
            self.emit(CanonCmd::SetNaivecamTolerance {
                tolerance: self.len_mm(save_cam),
            });
        }
        Ok(())
    }
}
