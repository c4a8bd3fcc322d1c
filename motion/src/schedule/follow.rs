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
//! Not yet here: feed override, holds and the fall-back to the executor's
//! own profiles where the schedule is not ready (`docs/motion.md`, *Known
//! limits*).

use super::Piece;

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
}

/// Follows intervals of a schedule one servo period at a time.
#[derive(Clone, Debug)]
pub struct Follower {
    period: f64,
    /// Periods run.
    periods: u64,
    /// The interval being followed, its number and the time it began
    /// (s since the first interval's start).
    current: Option<Interval>,
    index: usize,
    begun: f64,
    /// The last position in the current interval, where the next search
    /// starts (the motion only moves forward).
    near: f64,
}

impl Follower {
    /// A follower at the start of the first interval it will be handed,
    /// stepping `period` seconds a tick.
    pub fn new(period: f64) -> Follower {
        Follower {
            period,
            periods: 0,
            current: None,
            index: 0,
            begun: 0.0,
            near: 0.0,
        }
    }

    /// Runs one servo period: the path position at its end, taking
    /// intervals from `queue` as the motion reaches them. `None` when the
    /// queue runs dry before the period ends (the end of the motion, or a
    /// planner that has fallen behind); the period is then not counted,
    /// and a later tick with more intervals carries on from where this one
    /// stopped.
    pub fn tick(&mut self, queue: &mut impl Iterator<Item = Interval>) -> Option<Sample> {
        // Times from the period count, not a running sum: no drift over a
        // long program.
        let t = (self.periods + 1) as f64 * self.period;
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
        })
    }

    /// Time the intervals already passed took, s: once the queue has run
    /// dry, the motion time.
    pub fn passed_time(&self) -> f64 {
        self.begun
    }
}
