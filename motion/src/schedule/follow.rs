//! Following a schedule's speed in arc length one servo period at a time:
//! the executor's half of third-order planning.
//!
//! A [`Schedule`](super::Schedule) is a speed profile x(s) = v² along the
//! path, interval by interval ([`Interpolant::SpeedInLength`](super::Interpolant)).
//! Its limits hold for the motion that moves along the path at that speed,
//! so the follower advances the path position by the profile's own clock
//! (t(s) = ∫ ds/√x) each period instead of tracking positions sampled in
//! time. Intervals arrive through any iterator (a slice, or a lock-free
//! queue's `pop` wrapped in [`std::iter::from_fn`]), so the planner thread
//! can solve ahead in windows and hand the committed intervals over; the
//! tick itself never allocates, locks or blocks (`tests/servo_rt.rs`
//! counts).
//!
//! Feed override and feed hold are a change of clock: the follower runs
//! the schedule's time τ at a rate k = dτ/dt between 0 (held) and 1 (the
//! schedule as solved), so the tool stays on the path and only its timing
//! changes. Moving at k·v_s along a schedule that moves an axis at v_s,
//! accelerates it at a_s and jerks it at j_s, the axis accelerates at
//! k²·a_s + k̇·v_s and jerks at k³·j_s + 3·k·k̇·a_s + k̈·v_s. A schedule
//! solved with a share r of each acceleration and jerk limit kept back
//! (`ScheduleConfig::reserve`) leaves room for the k̇ and k̈ terms, and
//! [`RateLimits`] bounds k̇ and k̈ so that they fit in it; the rate moves
//! to each new override along the quickest ramp within those bounds, in
//! closed form, so the limits hold between samples too. Above 100 % the
//! schedule cannot go: it already runs at the axes' limits wherever the
//! feed does not hold it, so the override is capped at 1.
//!
//! Not yet here: the fall-back to the executor's own profiles where the
//! schedule is not ready, and the executor switching to the follower
//! (`docs/motion.md`, *Known limits*).

use super::{axis_limits, Piece, ScheduleError};
use crate::kinematics::Kinematics;

/// One interval of a schedule as it is followed: where it lies on the
/// path and how its speed varies along it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    /// The planned segment the interval lies on (its index in the
    /// segments the schedule was made from).
    pub segment: usize,
    /// Arc length into the segment where the interval starts, mm.
    pub from: f64,
    /// Length of the interval, mm.
    pub length: f64,
    /// How long the motion takes over it, s (infinite where the schedule
    /// stands still).
    pub duration: f64,
    pub(super) piece: Piece,
}

impl Interval {
    /// The motion starts the interval at rest: the first of a stretch.
    pub fn from_rest(&self) -> bool {
        matches!(self.piece, Piece::Out { .. })
    }

    /// The motion ends the interval at rest: the last of a stretch.
    pub fn to_rest(&self) -> bool {
        matches!(self.piece, Piece::In { .. })
    }

    /// The schedule stands still here: its stretch found no motion within
    /// the limits (`Schedule::stranded`).
    pub fn stands_still(&self) -> bool {
        matches!(self.piece, Piece::Still)
    }

    /// Arc length into the interval `t` seconds into it, searched from
    /// `near` (an earlier position in it, or 0), mm.
    fn position(&self, t: f64, near: f64) -> f64 {
        self.piece.position(self.length, t, near)
    }
}

/// A path position the follower reached at the end of a servo period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Which interval of those handed over (counted from 0).
    pub interval: usize,
    /// The segment it lies on.
    pub segment: usize,
    /// Arc length into that segment, mm.
    pub at: f64,
    /// The rate k the schedule's clock ran at, at the end of the period:
    /// the path speed is k times the schedule's there (1 at 100 %, 0 when
    /// held).
    pub rate: f64,
}

/// How fast a [`Follower`] may change its rate k, the share of the
/// schedule's speed it runs at (its feed override, at most 1).
///
/// With the schedule keeping every axis within (1 − r) of its
/// acceleration limit A and jerk limit J, and within its velocity limit
/// V, an axis's acceleration under a changing rate, k²·a_s + k̇·v_s, stays
/// within A while |k̇| ≤ r·A/V, and its jerk, k³·j_s + 3·k·k̇·a_s + k̈·v_s,
/// stays within J while 3·|k̇|·(1 − r)·A + |k̈|·V ≤ r·J (0 ≤ k ≤ 1). The
/// bounds take the slowest axis, and spend at most half of the jerk's
/// share on k̇, so that k̈ has the rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateLimits {
    /// Largest |dk/dt|, 1/s: a hold from 100 % takes at least 1/`slope`.
    pub slope: f64,
    /// Largest |d²k/dt²|, 1/s².
    pub bend: f64,
}

impl RateLimits {
    /// The bounds for a schedule solved on `kins` with `reserve` of each
    /// acceleration and jerk limit kept back. A reserve of 0 gives 0 and
    /// 0: the rate cannot change.
    pub fn for_machine(kins: &dyn Kinematics, reserve: f64) -> Result<RateLimits, ScheduleError> {
        if !(0.0..1.0).contains(&reserve) {
            return Err(ScheduleError::Reserve(reserve));
        }
        let l = axis_limits(kins)?;
        let r = reserve;
        let axes =
            (0..9).filter(|&i| l.v[i].is_finite() && l.a[i].is_finite() && l.j[i].is_finite());
        let mut slope = f64::INFINITY;
        for i in axes.clone() {
            slope = slope.min(r * l.a[i] / l.v[i]);
            if r > 0.0 {
                slope = slope.min(r * l.j[i] / (6.0 * (1.0 - r) * l.a[i]));
            }
        }
        let mut bend = f64::INFINITY;
        for i in axes {
            bend = bend.min((r * l.j[i] - 3.0 * slope * (1.0 - r) * l.a[i]) / l.v[i]);
        }
        if !slope.is_finite() || !bend.is_finite() {
            // No axis with limits: nothing to keep.
            return Ok(RateLimits {
                slope: 0.0,
                bend: 0.0,
            });
        }
        Ok(RateLimits {
            slope: slope.max(0.0),
            bend: bend.max(0.0),
        })
    }

    /// How long the quickest change of rate from 1 to 0 (or back) takes,
    /// s: a ramp of slope × bend, its slope capped at `slope`.
    pub fn hold_time(&self) -> f64 {
        Ramp::new(1.0, 0.0, 0.0, *self).duration()
    }
}

/// The rate k over time from a change of override on: up to three phases
/// of constant k̈ (towards the new rate, cruising at the largest slope,
/// and easing into it), the quickest within [`RateLimits`] from the rate
/// and slope the follower had.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ramp {
    /// Rate and slope at the ramp's start.
    k0: f64,
    w0: f64,
    /// Each phase's length, s, and its k̈, 1/s².
    phases: [(f64, f64); 3],
    /// The rate from the ramp's end on.
    k1: f64,
}

impl Ramp {
    /// Staying at `k`.
    fn steady(k: f64) -> Ramp {
        Ramp {
            k0: k,
            w0: 0.0,
            phases: [(0.0, 0.0); 3],
            k1: k,
        }
    }

    /// From rate `k0` moving at slope `w0` to rest at `k1`.
    fn new(k0: f64, w0: f64, k1: f64, limits: RateLimits) -> Ramp {
        let RateLimits { slope, bend } = limits;
        if slope <= 0.0 || bend <= 0.0 {
            return Ramp::steady(k0);
        }
        // Go the way that is left after braking at once.
        let d = k1 - k0;
        let braking = w0 * w0.abs() / (2.0 * bend);
        let sign = if d >= braking { 1.0 } else { -1.0 };
        let (d, w0s) = (sign * d, sign * w0);
        // Peak slope of accelerate-then-brake, capped.
        let mut peak = (0.5 * (2.0 * bend * d + w0s * w0s)).max(0.0).sqrt();
        let mut cruise = 0.0;
        if peak > slope {
            peak = slope;
            let ramps = (2.0 * peak * peak - w0s * w0s) / (2.0 * bend);
            cruise = ((d - ramps) / peak).max(0.0);
        }
        Ramp {
            k0,
            w0,
            phases: [
                (((peak - w0s) / bend).max(0.0), sign * bend),
                (cruise, 0.0),
                (peak / bend, -sign * bend),
            ],
            k1,
        }
    }

    fn duration(&self) -> f64 {
        self.phases.iter().map(|p| p.0).sum()
    }

    /// Rate and slope `t` seconds into the ramp, and the schedule time
    /// run by then, ∫k dt, s.
    fn at(&self, t: f64) -> (f64, f64, f64) {
        let (mut k, mut w, mut run, mut left) = (self.k0, self.w0, 0.0, t.max(0.0));
        for &(length, c) in &self.phases {
            let dt = length.min(left);
            run += dt * (k + dt * (0.5 * w + dt * c / 6.0));
            k += dt * (w + 0.5 * dt * c);
            w += dt * c;
            left -= dt;
            if left <= 0.0 {
                return (k.clamp(0.0, 1.0), w, run);
            }
        }
        // Past the ramp: steady at its end rate (where rounding left k a
        // hair off it).
        (self.k1, 0.0, run + left * self.k1)
    }
}

/// Follows intervals of a schedule one servo period at a time.
#[derive(Clone, Debug)]
pub struct Follower {
    period: f64,
    /// Periods run.
    periods: u64,
    /// The interval being followed, its number and the schedule time it
    /// began (s since the first interval's start).
    current: Option<Interval>,
    index: usize,
    begun: f64,
    /// The last position in the current interval, where the next search
    /// starts (the motion only moves forward).
    near: f64,
    /// How fast the rate may change.
    limits: RateLimits,
    /// The rate's course since the last change of override: it began at
    /// period `ramp_from`, with the schedule's clock at `ramp_clock`.
    ramp: Ramp,
    ramp_from: u64,
    ramp_clock: f64,
}

impl Follower {
    /// A follower at the start of the first interval it will be handed,
    /// stepping `period` seconds a tick, at 100 % for good.
    pub fn new(period: f64) -> Follower {
        Follower::with_override(
            period,
            RateLimits {
                slope: 0.0,
                bend: 0.0,
            },
        )
    }

    /// A follower whose override may change within `limits`: those of
    /// [`RateLimits::for_machine`] for the reserve its schedule was solved
    /// with, or smaller.
    pub fn with_override(period: f64, limits: RateLimits) -> Follower {
        Follower {
            period,
            periods: 0,
            current: None,
            index: 0,
            begun: 0.0,
            near: 0.0,
            limits,
            ramp: Ramp::steady(1.0),
            ramp_from: 0,
            ramp_clock: 0.0,
        }
    }

    /// Sets the feed override the follower moves its rate to, from the
    /// next period on: `factor` clamped into 0..=1 (0 holds the motion
    /// where it can stop; above 1 the schedule has no room). Where its
    /// [`RateLimits`] are 0, the rate stays at 1.
    pub fn set_override(&mut self, factor: f64) {
        let target = if factor.is_nan() {
            1.0
        } else {
            factor.clamp(0.0, 1.0)
        };
        if target == self.ramp.k1 {
            return;
        }
        let (k, w, run) = self.ramp.at(self.since_ramp(self.periods));
        let clock = self.ramp_clock + run;
        let ramp = Ramp::new(k, w, target, self.limits);
        if ramp == Ramp::steady(k) && k != target {
            // No room to change the rate.
            return;
        }
        self.ramp = ramp;
        self.ramp_from = self.periods;
        self.ramp_clock = clock;
    }

    /// Starts the rate at `factor` (clamped into 0..=1) instead of 1:
    /// for a follower set off from rest, before its first tick, where the
    /// rate can take any value (nothing moves). Ignored after the first
    /// tick.
    pub fn start_at(&mut self, factor: f64) {
        if self.periods == 0 {
            let k = if factor.is_nan() {
                1.0
            } else {
                factor.clamp(0.0, 1.0)
            };
            self.ramp = Ramp::steady(k);
        }
    }

    /// The override the rate is moving to (or holds).
    pub fn target(&self) -> f64 {
        self.ramp.k1
    }

    /// Seconds into the current ramp at the end of period `periods`.
    fn since_ramp(&self, periods: u64) -> f64 {
        (periods - self.ramp_from) as f64 * self.period
    }

    /// Runs one servo period: the path position at its end, taking
    /// intervals from `queue` as the motion reaches them. `None` when the
    /// queue runs dry before the period ends (the end of the motion, or a
    /// planner that has fallen behind); the period is then not counted,
    /// and a later tick with more intervals carries on from where this one
    /// stopped.
    pub fn tick(&mut self, queue: &mut impl Iterator<Item = Interval>) -> Option<Sample> {
        // The schedule's clock from the period count, not a running sum:
        // no drift over a long program (at 100 % from the start it is the
        // period count times the period, exactly).
        let (rate, _, run) = self.ramp.at(self.since_ramp(self.periods + 1));
        let t = self.ramp_clock + run;
        let current = loop {
            let current = match self.current {
                Some(current) => current,
                None => {
                    let next = queue.next()?;
                    self.current = Some(next);
                    self.near = 0.0;
                    next
                }
            };
            if t <= self.begun + current.duration {
                break current;
            }
            self.begun += current.duration;
            self.current = None;
            self.index += 1;
        };
        self.periods += 1;
        self.near = current.position(t - self.begun, self.near);
        Some(Sample {
            interval: self.index,
            segment: current.segment,
            at: current.from + self.near,
            rate,
        })
    }

    /// Schedule time of the intervals already passed, s: once the queue
    /// has run dry, the schedule's motion time (at 100 % throughout, the
    /// motion's).
    pub fn passed_time(&self) -> f64 {
        self.begun
    }

    /// Periods run so far: times the period, the time the motion took.
    pub fn periods(&self) -> u64 {
        self.periods
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every ramp, from any rate and slope a ramp can leave the follower
    /// at, ends at rest on its target, keeps its slope and bend within
    /// the limits (checked by differences on a fine grid, not by the
    /// phases it was built from), stays within 0..=1, and its clock is
    /// the integral of its rate.
    #[test]
    fn ramps_reach_their_target_within_the_limits() {
        let limits = RateLimits {
            slope: 0.9,
            bend: 20.0,
        };
        let dt = 1e-4;
        let mut checked = 0;
        // Starting states: each the middle of an earlier ramp.
        for &(from, via, to) in &[
            (1.0, 0.0, 0.5),
            (1.0, 0.0, 0.98),
            (1.0, 0.2, 0.0),
            (0.0, 1.0, 0.3),
            (0.3, 0.0, 0.31),
            (0.5, 1.0, 0.0),
            (1.0, 0.0, 1.0),
        ] {
            let first = Ramp::new(from, 0.0, via, limits);
            for cut in [0.0, 0.013, 0.1, 0.37, 0.5 * first.duration()] {
                let (k0, w0, _) = first.at(cut);
                let ramp = Ramp::new(k0, w0, to, limits);
                let n = (ramp.duration() / dt).ceil() as usize + 20;
                let (mut k_before, mut w_before) = (k0, w0);
                let mut clock = 0.0;
                for step in 1..=n {
                    let (k, _, run) = ramp.at(step as f64 * dt);
                    assert!((0.0..=1.0).contains(&k), "rate {k}");
                    let w = (k - k_before) / dt;
                    assert!(w.abs() <= limits.slope * (1.0 + 1e-9) + 1e-9, "slope {w}");
                    // Bend between mid-step slopes (the first step's
                    // against the start's exact slope, half a step).
                    let bend = if step == 1 {
                        (w - w_before) / (0.5 * dt)
                    } else {
                        (w - w_before) / dt
                    };
                    assert!(
                        bend.abs() <= limits.bend * (1.0 + 1e-6) + 1e-6,
                        "bend {bend} from ({k0}, {w0}) to {to} at step {step}"
                    );
                    // Trapezoids of k: the clock is ∫k dt to O(dt²).
                    clock += 0.5 * (k + k_before) * dt;
                    assert!((run - clock).abs() < 1e-6, "clock {run} against {clock}");
                    k_before = k;
                    w_before = w;
                }
                let (k, w, _) = ramp.at(ramp.duration());
                assert!(
                    (k - to).abs() < 1e-12 && w.abs() < 1e-9,
                    "ended at ({k}, {w})"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 35);
    }

    /// A hold from 100 % at rest is the symmetric ramp: 1/slope +
    /// slope/bend seconds (slope reached after slope/bend, cruised, eased
    /// out), and the clock runs half of it.
    #[test]
    fn a_hold_from_full_rate_takes_the_symmetric_ramp() {
        let limits = RateLimits {
            slope: 0.9,
            bend: 20.0,
        };
        let expected = 1.0 / 0.9 + 0.9 / 20.0;
        assert!((limits.hold_time() - expected).abs() < 1e-12);
        let ramp = Ramp::new(1.0, 0.0, 0.0, limits);
        let (_, _, run) = ramp.at(expected);
        assert!((run - 0.5 * expected).abs() < 1e-12, "{run}");
    }
}
