//! The executor's guarantee: from every state the motion takes, a way to
//! rest that is checked, in closed form, against every machine limit it
//! meets.
//!
//! The executor chooses each period's jerk by a search with a look ahead
//! (the rest of `exec.rs`). That look ahead is not recursively feasible: a
//! state it accepts is not guaranteed a successor it accepts, and where
//! none is found the motion breaks a limit (random programs found such
//! states at a few in a hundred; `docs/motion-log.md`). The
//! guard closes that hole by construction. A next state is taken only if a
//! [`Guard`] from it exists: a chain of jerk-limited profiles ([`Brake`])
//! that ends at rest, each passing every junction under its speed cap,
//! entering every segment within its acceleration limit and using no
//! more jerk than any segment it crosses allows, and stopping before the
//! end of the queue and every dwell, stop or I/O point. If the chosen state
//! has none, the motion follows the guard it already has one period
//! further instead; the rest of that guard is a guard from there, so the
//! next period has one too.
//!
//! The guard meets the machine's limits only. The operator's caps (hold,
//! overrides, single block) and the programmed feed are the search's to
//! meet; a guard brakes below them anyway.

use super::{Brake, View};

/// Profiles in a guard at most: easing a positive acceleration off, a
/// stop, and before it aims at the junctions the stop alone would pass
/// too fast or enter too hard, or braking up to the end of a segment.
const LEGS: usize = 8;

/// Segments a guard may cross (a stop from 100 mm/s over 0.01 mm chords
/// crosses about 500).
const REACH: usize = 4096;

/// How far past a point where the motion must rest a stop may end: the
/// executor closes the last 10 pm at once (`Executor::travel`).
const AT_REST: f64 = 1e-8;

/// Relative slack for rounding in the checks.
const ROUNDING: f64 = 1e-12;

/// One profile of a guard: `brake` starts `start` seconds into the guard,
/// `from` mm ahead of the state the guard was found for, and after its
/// ramps holds its final speed until the next profile starts.
#[derive(Clone, Copy, Debug)]
struct Leg {
    brake: Brake,
    start: f64,
    from: f64,
}

/// A checked way to rest from the state it was found for, and how far
/// along it the motion is.
#[derive(Clone, Copy, Debug)]
pub(super) struct Guard {
    legs: [Leg; LEGS],
    n: usize,
    /// Time since the state it was found for, s.
    t: f64,
}

/// Why a profile failed its check.
enum Miss {
    /// It passes the junction `at` mm ahead faster than `cap` allows.
    Speed { at: f64, cap: f64 },
    /// It enters the segment starting `at` mm ahead (junction cap `cap`)
    /// with more acceleration or jerk than that segment allows.
    Limits { at: f64, cap: f64 },
    /// Anything else: an acceleration or jerk limit of the segment it
    /// starts in, a point where the motion must be at rest, or beyond the
    /// segments it may look at.
    Other,
}

impl Guard {
    /// (distance from the state it was found for, speed, acceleration) at
    /// time `t` along it.
    fn at(&self, t: f64) -> (f64, f64, f64) {
        let legs = &self.legs[..self.n];
        let leg = legs.iter().rev().find(|l| l.start <= t).unwrap_or(&legs[0]);
        let (s, v, a) = leg.brake.at(t - leg.start);
        (leg.from + s, v, a)
    }

    /// Moves one period of `dt` along the guard: the distance travelled,
    /// and the speed and acceleration after it.
    pub(super) fn step(&mut self, dt: f64) -> (f64, f64, f64) {
        let (s0, _, _) = self.at(self.t);
        self.t += dt;
        let (s1, v, a) = self.at(self.t);
        (s1 - s0, v, a)
    }

    /// A guard from speed `v` and acceleration `a`, `s_head` mm into
    /// segment `head` of `q`, or None if none of the chains tried keeps to
    /// every limit. At rest, the empty guard.
    pub(super) fn find(q: View, head: usize, s_head: f64, v: f64, a: f64) -> Option<Guard> {
        let at_rest = Brake {
            v0: 0.0,
            a0: 0.0,
            v1: 0.0,
            phases: [(0.0, 0.0); 3],
            t: 0.0,
            hold: false,
        };
        let mut guard = Guard {
            legs: [Leg {
                brake: at_rest,
                start: 0.0,
                from: 0.0,
            }; LEGS],
            n: 1,
            t: 0.0,
        };
        if v <= 0.0 && a == 0.0 {
            return Some(guard);
        }
        guard.n = 0;
        let path = Path { q, head, s_head };
        let (mut from, mut v, mut a, mut start) = (0.0, v, a, 0.0);
        if a > 0.0 {
            // Still speeding up: ease the acceleration off first, under the
            // jerk limits of the short stretch that takes. A stop under the
            // lowest limits of its whole reach would ease it under a blend's
            // far lower jerk limit further on, cresting far above the caps.
            let easing = path.ease(v, a)?;
            for &ease in &easing.legs[..easing.n] {
                let length = ease.length();
                path.check(from, &ease, from + length).ok()?;
                guard.legs[guard.n] = Leg {
                    brake: ease,
                    start,
                    from,
                };
                guard.n += 1;
                (from, start) = (from + length, start + ease.duration());
            }
            (v, a) = (easing.crest, 0.0);
        }
        loop {
            if guard.n >= LEGS {
                return None;
            }
            // Braking harder than a segment ahead allows, no stop under the
            // lowest limits within reach exists: stop under the limits
            // here, which enters that segment too hard, and aim at it.
            let here = path.lowest_limits(from, from);
            let rest = path
                .lowest_stop(from, v, a)
                .or_else(|| stop(v, a, here.0, here.1))?;
            let miss = match path.check(from, &rest, from + rest.length()) {
                Ok(()) => {
                    guard.legs[guard.n] = Leg {
                        brake: rest,
                        start,
                        from,
                    };
                    guard.n += 1;
                    return Some(guard);
                }
                Err(Miss::Speed { at, cap } | Miss::Limits { at, cap }) => Some((at, cap)),
                Err(Miss::Other) => None,
            };
            // The stop passes a junction too fast, or enters the segment
            // after it harder than that segment allows: aim at its cap
            // under the limits before it, arriving with zero acceleration,
            // and go on from there.
            if let Some((aim, at)) =
                miss.and_then(|(at, cap)| Some((path.aim(from, v, a, at, cap)?, at)))
            {
                guard.legs[guard.n] = Leg {
                    brake: aim,
                    start,
                    from,
                };
                guard.n += 1;
                start += aim.duration() + (at - from - aim.length()).max(0.0) / aim.v1;
                (from, v, a) = (at.max(from + aim.length()), aim.v1, 0.0);
                continue;
            }
            // Otherwise brake under the limits here up to the end of this
            // segment (holding the speed, if it is not braking), and look
            // again from there: the way the look ahead passes a cap below
            // its speed, braking on into the next segment.
            let end = path.end_of_segment_at(from)?;
            let brake = if a == 0.0 {
                Brake::cruise(v)
            } else {
                stop(v, a, here.0, here.1)?
            };
            if a != 0.0 && brake.length() <= end - from {
                // At rest within this segment after all.
                path.check(from, &brake, from + brake.length()).ok()?;
                guard.legs[guard.n] = Leg { brake, start, from };
                guard.n += 1;
                return Some(guard);
            }
            path.check(from, &brake, end).ok()?;
            let t = brake.time_at_distance(end - from);
            let (_, v_end, a_end) = brake.at(t);
            if v_end <= 0.0 {
                return None;
            }
            guard.legs[guard.n] = Leg { brake, start, from };
            guard.n += 1;
            start += t;
            (from, v, a) = (end, v_end, a_end);
        }
    }
}

/// The shortest stop from (`v`, `a`) under `amax` and `jmax`. A stop
/// approach played to its end arrives on the edge of running out (easing
/// its deceleration at once just meets rest), which rounding can tip
/// either way: within 1e-9 of the edge, ease at once.
fn stop(v: f64, a: f64, amax: f64, jmax: f64) -> Option<Brake> {
    Brake::shortest(v, a, 0.0, amax, jmax).or_else(|| {
        let t = -a / jmax;
        (a < 0.0 && -a <= amax && v >= a * a / (2.0 * jmax) * (1.0 - 1e-9)).then_some(Brake {
            v0: v,
            a0: a,
            v1: 0.0,
            phases: [(jmax, 0.0), (0.0, 0.0), (jmax, t)],
            t: 0.0,
            hold: false,
        })
    })
}

/// The highest speed the motion reaches easing acceleration `a` off at
/// once, `s_head` mm into segment `head` of `q` at speed `v`, under the
/// lowest jerk limit within its reach (as a guard does; `v` itself if `a`
/// ≤ 0), with the lowest `cap` and the lowest machine speed limit of the
/// segments it touches on the way and of the junctions it passes.
pub(super) fn crest(
    q: View,
    head: usize,
    s_head: f64,
    v: f64,
    a: f64,
    cap: impl Fn(&super::Segment) -> f64,
) -> (f64, f64, f64) {
    let path = Path { q, head, s_head };
    let (crest, reach) = match (a > 0.0).then(|| path.ease(v, a)).flatten() {
        Some(easing) => (easing.crest, easing.length),
        None => (v, 0.0),
    };
    let (mut lowest, mut machine) = (f64::INFINITY, f64::INFINITY);
    for (start, seg) in path.segments() {
        let Some(seg) = seg else { break };
        if start >= reach - AT_REST && start > 0.0 {
            break;
        }
        let end = start + seg.length;
        if end > 0.0 {
            lowest = lowest.min(cap(seg));
            machine = machine.min(seg.max_velocity);
        }
        // A junction passed while still speeding up.
        if end > 0.0 && end < reach {
            lowest = lowest.min(seg.exit_velocity);
            machine = machine.min(seg.exit_velocity);
        }
    }
    (crest, lowest, machine)
}

/// `t` seconds of easing acceleration `a` at speed `v` with jerk `-jmax`,
/// as a profile whose final speed is where it ends.
fn easing_piece(v: f64, a: f64, jmax: f64, t: f64) -> Brake {
    Brake {
        v0: v,
        a0: a,
        v1: v + a * t - jmax * t * t / 2.0,
        phases: [(-jmax, t), (0.0, 0.0), (0.0, 0.0)],
        t: 0.0,
        hold: false,
    }
}

/// The time constant jerk `-jmax` from speed `v` and acceleration `a` > 0
/// takes to travel `to` mm, not more (within the easing, where the speed
/// rises): safeguarded Newton steps on the cubic.
fn time_to(v: f64, a: f64, jmax: f64, to: f64) -> f64 {
    let travelled = |t: f64| v * t + a * t * t / 2.0 - jmax * t * t * t / 6.0;
    let (mut lo, mut hi) = (0.0, a / jmax);
    let mut t = if v > 0.0 { (to / v).min(hi) } else { hi / 2.0 };
    for _ in 0..40 {
        let err = travelled(t) - to;
        if err > 0.0 {
            hi = t;
        } else {
            lo = t;
            if err > -1e-15 * to.max(1e-9) {
                break;
            }
        }
        let newton = t - err / (v + a * t - jmax * t * t / 2.0);
        t = if newton > lo && newton < hi {
            newton
        } else {
            (lo + hi) / 2.0
        };
    }
    lo
}

/// Profiles easing a positive acceleration off at most (the jerk limit
/// falling at each of their junctions).
const EASE_LEGS: usize = 4;

/// Easing a positive acceleration off, segment by segment.
struct Easing {
    legs: [Brake; EASE_LEGS],
    n: usize,
    /// The speed it ends at, mm/s.
    crest: f64,
    /// Its length, mm.
    length: f64,
}

/// The queue as a guard reads it: distances are from the state asked
/// about, `s_head` mm into segment `head`.
struct Path<'a> {
    q: View<'a>,
    head: usize,
    s_head: f64,
}

impl Path<'_> {
    /// The motion segments from the head, each with the distance at which
    /// it starts, and None where the motion must be at rest (the end of
    /// the queue, a dwell, a stop, an I/O point) or the look gives out.
    fn segments(&self) -> impl Iterator<Item = (f64, Option<&super::Segment>)> + '_ {
        let mut start = -self.s_head;
        let last = self.head + REACH;
        // Past the last segment looked at the motion must be at rest, as at
        // the end of the queue: a stop that would go on is not checked.
        (self.head..=last).map(move |k| {
            let seg = self.q.get(k).filter(|s| s.is_motion() && k < last);
            let here = start;
            start += seg.map_or(0.0, |s| s.length);
            (here, seg)
        })
    }

    /// A profile from (`v`, `a`) `from` mm ahead that arrives at the
    /// junction `at` mm ahead, under the limits before it, no faster than
    /// its `cap` (and, braking already, no faster than easing that off at
    /// once leaves) with zero acceleration, checked. Cruising below the
    /// cap, it holds the speed.
    fn aim(&self, from: f64, v: f64, a: f64, at: f64, cap: f64) -> Option<Brake> {
        if cap <= 0.0 || at <= from {
            return None;
        }
        let (amax, jmax) = self.lowest_limits(from, at);
        let target = cap.min(v - a.min(0.0).powi(2) / (2.0 * jmax));
        let aim = if target < v {
            Brake::within(v, a, target, at - from, amax, jmax)?
        } else if a == 0.0 {
            Brake::cruise(v)
        } else {
            return None;
        };
        // Within the look ahead's rounding of the junction (it counts a
        // cap met 1e-9 mm late).
        if aim.length() > (at - from) * (1.0 + ROUNDING) + 1e-9 {
            return None;
        }
        self.check(from, &aim, at).ok()?;
        Some(aim)
    }

    /// Where the segment `from` mm ahead lies in ends, mm ahead (the next
    /// one's, if it ends there within rounding).
    fn end_of_segment_at(&self, from: f64) -> Option<f64> {
        self.segments()
            .map_while(|(start, seg)| seg.map(|s| start + s.length))
            .find(|&end| end > from + AT_REST)
    }

    /// The lowest acceleration and jerk limits of the segments touching
    /// `from`..`to` mm ahead.
    fn lowest_limits(&self, from: f64, to: f64) -> (f64, f64) {
        let (mut amax, mut jmax) = (f64::INFINITY, f64::INFINITY);
        for (start, seg) in self.segments() {
            let Some(seg) = seg else { break };
            // A segment starting where the stretch ends (within rounding)
            // is not touched.
            if start >= to - AT_REST && start > from {
                break;
            }
            // One ending where the stretch starts is behind it.
            if start + seg.length > from {
                amax = amax.min(seg.max_acceleration);
                jmax = jmax.min(seg.max_jerk);
            }
        }
        (amax, jmax)
    }

    /// The shortest stop from (`v`, `a`) `from` mm ahead under the lowest
    /// limits within its reach (which a longer stop may extend: a few
    /// rounds settle it).
    fn lowest_stop(&self, from: f64, v: f64, a: f64) -> Option<Brake> {
        self.settled(from, |amax, jmax| stop(v, a, amax, jmax))
    }

    /// The profile `make` gives under the lowest acceleration and jerk
    /// limits within its own reach from `from`: a longer profile may reach
    /// lower limits, so a few rounds settle it. None where `make` gives
    /// none.
    fn settled(&self, from: f64, make: impl Fn(f64, f64) -> Option<Brake>) -> Option<Brake> {
        let (mut amax, mut jmax) = self.lowest_limits(from, from);
        let mut profile = make(amax, jmax)?;
        for _ in 0..16 {
            let (a_low, j_low) = self.lowest_limits(from, from + profile.length());
            if a_low >= amax && j_low >= jmax {
                break;
            }
            (amax, jmax) = (a_low.min(amax), j_low.min(jmax));
            profile = make(amax, jmax)?;
        }
        Some(profile)
    }

    /// Easing acceleration `a` > 0 at speed `v` off to zero at once, from
    /// the state asked about, under each segment's jerk limit in turn: a
    /// profile of constant jerk up to each junction where the limit falls,
    /// and the last one to zero acceleration. Where the limit falls more
    /// often than [`EASE_LEGS`] allows (chords whose limits differ a
    /// little from one to the next), in one profile under the lowest limit
    /// within its reach.
    fn ease(&self, v: f64, a: f64) -> Option<Easing> {
        self.ease_in_steps(v, a)
            .or_else(|| self.ease_under_lowest(v, a))
    }

    /// [`ease`](Self::ease) in one profile under the lowest jerk limit
    /// within its reach.
    fn ease_under_lowest(&self, v: f64, a: f64) -> Option<Easing> {
        let ease = self.settled(0.0, |_, jmax| {
            jmax.is_finite().then(|| easing_piece(v, a, jmax, a / jmax))
        })?;
        Some(Easing {
            legs: [ease; EASE_LEGS],
            n: 1,
            crest: ease.v1,
            length: ease.length(),
        })
    }

    /// [`ease`](Self::ease) a profile per jerk limit, if there are at most
    /// [`EASE_LEGS`] of them.
    fn ease_in_steps(&self, v: f64, a: f64) -> Option<Easing> {
        let mut easing = Easing {
            legs: [easing_piece(v, a, 1.0, 0.0); EASE_LEGS],
            n: 0,
            crest: v,
            length: 0.0,
        };
        let (_, mut jmax) = self.lowest_limits(0.0, 0.0);
        if !jmax.is_finite() {
            return None;
        }
        let (mut from, mut v, mut a) = (0.0, v, a);
        let reach = |v: f64, a: f64, jmax: f64| {
            let t = a / jmax;
            v * t + a * t * t / 2.0 - jmax * t * t * t / 6.0
        };
        // One pass over the segments ahead: a piece ends at each junction
        // within reach where the jerk limit falls.
        for (start, seg) in self.segments() {
            let Some(seg) = seg else { break };
            if start <= from {
                continue;
            }
            if from + reach(v, a, jmax) <= start {
                break;
            }
            if seg.max_jerk >= jmax {
                continue;
            }
            if easing.n + 1 == EASE_LEGS {
                return None;
            }
            // Up to there under this limit: s(τ) = start − from, s rising
            // while the acceleration is still positive.
            let tau = time_to(v, a, jmax, start - from);
            let part = easing_piece(v, a, jmax, tau);
            easing.legs[easing.n] = part;
            easing.n += 1;
            // On from the junction itself, under the lower limit after it.
            (from, v, a, jmax) = (start, part.v1, a - jmax * tau, seg.max_jerk);
        }
        let last = easing_piece(v, a, jmax, a / jmax);
        easing.legs[easing.n] = last;
        easing.n += 1;
        easing.crest = last.v1;
        easing.length = from + reach(v, a, jmax);
        Some(easing)
    }

    /// Checks `brake`, starting `from` mm ahead and holding its final speed
    /// from the end of its ramps to `until`, against the limits of every
    /// segment it crosses.
    fn check(&self, from: f64, brake: &Brake, until: f64) -> Result<(), Miss> {
        let length = brake.length();
        let ramps = from + length;
        // Where the phases end, mm ahead.
        let mut ends = [0.0; 3];
        let mut t = 0.0;
        for (i, phase) in brake.phases.iter().enumerate() {
            t += phase.1;
            ends[i] = from + brake.at(t).0;
        }
        let peak = brake.peak();
        let a_most = brake.a0.abs().max(peak);
        let j_most = brake
            .phases
            .iter()
            .filter(|p| p.1 > 0.0)
            .fold(0.0, |m: f64, p| m.max(p.0.abs()));
        // A positive acceleration still raises the speed to a crest.
        // (A piece of an easing may end before its crest: then its end.)
        let crest = (brake.a0 > 0.0).then(|| {
            let t = (brake.a0 / brake.phases[0].0.abs()).min(brake.duration());
            let (s, v, _) = brake.at(t);
            (from + s, v)
        });
        let v_most = crest.map_or(brake.v0, |c| c.1.max(brake.v0));
        let state = |d: f64| {
            if d >= ramps {
                (brake.v1, 0.0)
            } else {
                brake.state_at_distance((d - from).max(0.0))
            }
        };
        let mut before: Option<&super::Segment> = None;
        // A stop ending within rounding of a segment's start does not
        // enter it (as its limits were found).
        let end = if brake.v1 == 0.0 {
            until - AT_REST
        } else {
            until
        };
        for (start, seg) in self.segments() {
            if start >= end && start > from {
                return Ok(());
            }
            let Some(seg) = seg else {
                // Must be at rest before here: only a stop may reach it,
                // and only at its end.
                let rests = brake.v1 == 0.0 && ramps <= start + AT_REST;
                return if rests { Ok(()) } else { Err(Miss::Other) };
            };
            let end = start + seg.length;
            if end < from {
                before = Some(seg);
                continue;
            }
            let lo = start.max(from);
            let hi = end.min(until);
            let slack = 1.0 + ROUNDING;
            // Entering it: under the junction's cap and its own.
            if start >= from && before.is_some() {
                let cap = before
                    .map_or(f64::INFINITY, |b| b.exit_velocity)
                    .min(seg.max_velocity);
                if cap == 0.0 {
                    // A stop in the program's path (an exact stop).
                    let rests = brake.v1 == 0.0 && ramps <= start + AT_REST;
                    return if rests { Ok(()) } else { Err(Miss::Other) };
                }
                if cap < v_most * slack {
                    let (v_in, _) = state(start);
                    if v_in > cap * slack {
                        return Err(Miss::Speed { at: start, cap });
                    }
                }
            } else if from == 0.0 && brake.v0 > seg.max_velocity * slack {
                // The state asked about is over the limit of its segment.
                return Err(Miss::Other);
            }
            if let Some((at, v)) = crest {
                if at >= lo && at <= hi && v > seg.max_velocity * slack {
                    return Err(Miss::Other);
                }
            }
            if lo < ramps {
                // Over a segment's limits: where the profile entered it, a
                // chain may aim at its junction instead.
                let over = || match before {
                    Some(b) if start >= from => Miss::Limits {
                        at: start,
                        cap: b.exit_velocity.min(seg.max_velocity),
                    },
                    _ => Miss::Other,
                };
                // |a| is monotone within each phase: its largest on the
                // segment is at an end, or the peak where the first phase
                // ends or the second runs.
                if seg.max_acceleration < a_most * slack {
                    let mut most = state(lo).1.abs().max(state(hi.min(ramps)).1.abs());
                    if hi >= ends[0] && lo <= ends[1] {
                        most = most.max(peak);
                    }
                    if most > seg.max_acceleration * slack {
                        return Err(over());
                    }
                }
                if seg.max_jerk < j_most * slack {
                    let mut phase_from = from;
                    for (i, phase) in brake.phases.iter().enumerate() {
                        let overlaps = ends[i] > lo && phase_from < hi && phase.1 > 0.0;
                        if overlaps && phase.0.abs() > seg.max_jerk * slack {
                            return Err(over());
                        }
                        phase_from = ends[i];
                    }
                }
            }
            before = Some(seg);
        }
        Err(Miss::Other)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{PathMode, Planner, PlannerConfig, Segment};
    use crate::testkit::xyz;
    use kerf_interp::{Interpreter, Position};

    fn planned(text: &str, mode: PathMode) -> Vec<Segment> {
        let machine = xyz(100.0, 1000.0, 50_000.0);
        // The cases here were sized on the limits this share gives the
        // transitions (the guard reads only lengths and limits).
        let config = PlannerConfig {
            mode,
            jerk_rate_share: 0.5,
            ..Default::default()
        };
        let mut planner = Planner::new(&machine, Position::ZERO, config);
        for command in Interpreter::from_text(text, "t.ngc", Position::ZERO) {
            planner.plan(&command.unwrap()).unwrap();
        }
        planner.finish();
        std::iter::from_fn(|| planner.next_segment()).collect()
    }

    /// The whole queue `q` as one view.
    fn whole(q: &[Segment]) -> View<'_> {
        View { head: q, tail: &[] }
    }

    /// Follows `guard`, found `s0` mm into the first segment of `q`, period
    /// by period to rest, and checks each period by sampling, apart from
    /// the closed forms the guard was checked with: speed within the
    /// segment's limit and the junction caps passed, acceleration within
    /// the limit of the segment it ends in, jerk (the change of
    /// acceleration over the period, an average of the jerk on each
    /// segment the period touches) within the highest of their limits, and
    /// rest before the end of the queue. Returns the distance travelled.
    fn follow(q: &[Segment], s0: f64, mut guard: Guard) -> f64 {
        let dt = 0.001;
        let starts: Vec<f64> = q
            .iter()
            .scan(0.0, |at, seg| {
                let start = *at;
                *at += seg.length;
                Some(start)
            })
            .collect();
        let total: f64 = q.iter().map(|seg| seg.length).sum();
        let index = |s: f64| starts.iter().rposition(|&start| start <= s).unwrap();
        let (mut s, mut v, mut a) = (s0, guard.at(0.0).1, guard.at(0.0).2);
        for _ in 0..100_000 {
            let (ds, v1, a1) = guard.step(dt);
            let (k0, k1) = (index(s), index((s + ds).min(total)));
            let slack = 1.0 + 1e-9;
            let jmax = q[k0..=k1]
                .iter()
                .map(|seg| seg.max_jerk)
                .fold(0.0, f64::max);
            assert!((a1 - a).abs() <= jmax * dt * slack, "jerk in {k0}..={k1}");
            assert!(a1.abs() <= q[k1].max_acceleration * slack, "a {a1} in {k1}");
            for k in k0..=k1 {
                let seg = &q[k];
                if k > k0 {
                    // Crossed into k: the speed there lies between v and
                    // v1 (it falls, but for a crest).
                    let cap = q[k - 1].exit_velocity.min(seg.max_velocity);
                    assert!(
                        v.min(v1) <= cap * slack,
                        "crossed {k} at {v}..{v1}, cap {cap}"
                    );
                }
            }
            assert!(v1 <= q[k1].max_velocity * (1.0 + 1e-9), "v {v1} in {k1}");
            (s, v, a) = (s + ds, v1, a1);
            assert!(s <= total + AT_REST, "past the end of the queue: {s}");
            if v == 0.0 && a == 0.0 {
                return s - s0;
            }
        }
        panic!("never came to rest");
    }

    #[test]
    fn a_guard_rests_before_the_end_of_the_queue_within_limits() {
        let q = planned("G1 X20 F6000\nM2\n", PathMode::ExactStop);
        let view = whole(&q);
        // 100 mm/s stops in 5 mm at 1000 mm/s² plus 2 ms for the jerk.
        let guard = Guard::find(view, 0, 10.0, 100.0, 0.0).expect("room to stop");
        let travelled = follow(&q, 10.0, guard);
        let expected = 100.0 * 100.0 / 2000.0 + 100.0 * 0.02 / 2.0;
        assert!(
            (travelled - expected).abs() < 1e-9,
            "{travelled} against {expected}"
        );
        // Speeding up, it eases the acceleration off first.
        let guard = Guard::find(view, 0, 5.0, 60.0, 800.0).expect("room to stop");
        follow(&q, 5.0, guard);
        // No room: no guard.
        assert!(Guard::find(view, 0, 16.0, 100.0, 0.0).is_none());
        // Running out: decelerating too hard to ease off before rest.
        assert!(Guard::find(view, 0, 5.0, 1.0, -1000.0).is_none());
    }

    #[test]
    fn a_guard_aims_at_a_cap_its_stop_would_pass_too_fast() {
        // A line into an arc of radius 10 mm, through a transition whose
        // speed and acceleration limits are below the line's.
        let q = planned(
            "G1 X20 F6000\nG2 X20 Y-20 J-10\nM2\n",
            PathMode::Blend { tolerance: 0.01 },
        );
        let view = whole(&q);
        let (line, next) = (&q[0], &q[1]);
        let cap = line.exit_velocity.min(next.max_velocity);
        assert!(cap < 60.0 && next.max_acceleration < line.max_acceleration);
        // A state on the profile from 100 mm/s that meets the cap exactly
        // where the transition starts, under the line's limits: a stop
        // under the transition's lower ones would enter it too fast.
        let approach =
            Brake::shortest(100.0, 0.0, cap, line.max_acceleration, line.max_jerk).unwrap();
        let (s, v, a) = approach.at(0.03);
        let s0 = line.length - (approach.length() - s);
        let guard = Guard::find(view, 0, s0, v, a).expect("on an approach");
        assert!(guard.n >= 2, "{guard:?}");
        let travelled = follow(&q, s0, guard);
        assert!(
            travelled > line.length - s0,
            "went on past the cap: {travelled}"
        );
    }

    #[test]
    fn speeding_up_into_lower_limits_eases_under_each_segments_jerk_limit() {
        // The line (1000 mm/s², 50,000 mm/s³) runs into a transition with
        // lower limits (748 mm/s², 23,847 mm/s³). Accelerating at 1000
        // mm/s² at 30 mm/s, 0.25 mm before it, easing under the line's
        // jerk limit gets below 748 in time; under the transition's all the
        // way it does not.
        let q = planned(
            "G1 X20 F6000\nG2 X20 Y-20 J-10\nM2\n",
            PathMode::Blend { tolerance: 0.01 },
        );
        let (line, next) = (&q[0], &q[1]);
        assert!(next.max_acceleration < 0.8 * line.max_acceleration);
        assert!(next.max_jerk < 0.5 * line.max_jerk);
        let view = whole(&q);
        let s0 = line.length - 0.25;
        let path = Path {
            q: view,
            head: 0,
            s_head: s0,
        };
        let (v, a) = (30.0, line.max_acceleration);
        let uniform = path.ease_under_lowest(v, a).unwrap();
        let length = uniform.length;
        assert!(path.check(0.0, &uniform.legs[0], length).is_err());
        let stepped = path.ease(v, a).unwrap();
        assert_eq!(stepped.n, 2);
        let guard = Guard::find(view, 0, s0, v, a).expect("eases in time");
        follow(&q, s0, guard);
    }

    #[test]
    fn a_stop_longer_than_the_segments_looked_at_has_no_guard() {
        // 0.001 mm pieces of a line (the guard reads only lengths and
        // limits): a stop from 100 mm/s crosses 6000 of them, more than
        // it may look at, so it has no guard; from 10 mm/s it crosses 70.
        let line = planned("G1 X20 F6000\nM2\n", PathMode::ExactStop)[0];
        let piece = Segment {
            length: 0.001,
            exit_velocity: line.max_velocity,
            ..line
        };
        let q = vec![piece; 2 * REACH];
        let view = whole(&q);
        assert!(Guard::find(view, 0, 0.0, 100.0, 0.0).is_none());
        let guard = Guard::find(view, 0, 0.0, 10.0, 0.0).expect("a short stop");
        follow(&q, 0.0, guard);
    }

    #[test]
    fn a_crest_inside_a_segment_counts_its_speed_limit() {
        let q = planned(
            "G64 P0.01\nG1 X20 F6000\nY20\nM2\n",
            PathMode::Blend { tolerance: 0.01 },
        );
        let view = whole(&q);
        let blend = q[1].max_velocity;
        // Just into the corner's blend, below its limit but still
        // speeding up hard enough to crest over it.
        let s = q[0].length + 1e-4;
        let (crest, cap, machine) = crest(view, 0, s, blend - 1.0, 800.0, |seg| seg.max_velocity);
        assert!(
            crest > blend && cap == blend && machine == blend,
            "{crest} {cap} {machine}"
        );
        assert!(Guard::find(view, 0, s, blend - 1.0, 800.0).is_none());
    }
}
