//! The executor following a jerk-limited schedule (`crate::schedule`)
//! where one is ready, and its own profiles elsewhere.
//!
//! The executor's own profiles give each segment one speed limit; the
//! schedule varies the speed inside segments under every axis's jerk and
//! passes dense blends up to a third quicker (`docs/motion.md`, *Following
//! a schedule*). The two meet only at rest, where any motion may start:
//! the executor takes a stretch of the schedule (from one rest to the
//! next) when it stands at the stretch's start and every interval of the
//! stretch has been handed over, so the follower can never run dry in
//! motion; at the stretch's end it is at rest again, and the queue's
//! markers, dwells and stops there are the executor's as before.
//!
//! On the schedule, feed override, the force controller's feed scale and
//! rapid override act through the follower's rate (0 to 100 %, ramped
//! within the reserve the schedule was solved with), and so do feed hold
//! and the stop that single block asks for: the tool slows along the path
//! and stays there. Above 100 % the schedule has no room; a stretch is
//! then run at 100 %, and the next is left to the executor's own profiles,
//! which honour it. Single block leaves the schedule once the tool has
//! stopped.

use crate::plan::Segment;
use crate::schedule::{Follower, Interval, RateLimits};

use super::{Executor, Sample, View};

/// Two slices read as one queue of schedule intervals (a ring's halves).
#[derive(Clone, Copy)]
pub struct Intervals<'a> {
    /// The older half.
    pub head: &'a [Interval],
    /// The newer half.
    pub tail: &'a [Interval],
}

impl<'a> Intervals<'a> {
    fn get(&self, k: usize) -> Option<&'a Interval> {
        match self.head.get(k) {
            Some(i) => Some(i),
            None => self.tail.get(k - self.head.len()),
        }
    }

    fn len(&self) -> usize {
        self.head.len() + self.tail.len()
    }
}

/// A stretch of schedule being followed.
#[derive(Clone, Debug)]
pub(super) struct Following {
    follower: Follower,
    /// Intervals handed to the follower, and the stretch's end, counted
    /// from the queue's first interval (which moves as the caller drops
    /// those reported consumed).
    taken: usize,
    end: usize,
    /// The follower's count of intervals passed when last reported.
    reported: usize,
}

/// The follower's queue: the stretch's intervals from the next not yet
/// taken.
struct Stretch<'a, 'b> {
    queue: Intervals<'a>,
    taken: &'b mut usize,
    end: usize,
}

impl Iterator for Stretch<'_, '_> {
    type Item = Interval;
    fn next(&mut self) -> Option<Interval> {
        if *self.taken >= self.end {
            return None;
        }
        let next = self.queue.get(*self.taken).copied();
        *self.taken += usize::from(next.is_some());
        next
    }
}

/// How far a stretch's first interval may start from the executor's
/// position on the same segment and still be taken to start there, mm.
const SAME_PLACE: f64 = 1e-9;

impl Executor {
    /// Follow schedules handed over with [`Executor::tick_following`],
    /// their rate changed within `limits` (those of the reserve they were
    /// solved with, [`RateLimits::for_machine`]).
    pub fn follow_schedules(&mut self, limits: RateLimits) {
        self.rate_limits = Some(limits);
    }

    /// True while the motion follows a stretch of schedule.
    pub fn is_following(&self) -> bool {
        self.following.is_some()
    }

    /// Stretches of schedule followed so far.
    pub fn stretches_followed(&self) -> u64 {
        self.stretches_followed
    }

    /// [`Executor::tick`] with the intervals of a schedule solved along
    /// the same segments (a `ScheduleStream` fed every segment queued
    /// since the executor was made or its queue reset, markers included,
    /// in order). The caller removes the `consumed` segments and the
    /// `intervals_consumed` intervals of the returned sample: those behind
    /// the motion, followed or not.
    pub fn tick_following(
        &mut self,
        dt: f64,
        head: &[Segment],
        tail: &[Segment],
        intervals: Intervals,
    ) -> Sample {
        let q = View { head, tail };
        self.period = dt;
        if self.following.is_none() {
            let stale = self.stale_intervals(q, intervals);
            if let Some(skip) = self.stretch_to_take(q, intervals, stale) {
                self.take_stretch(intervals, stale, skip);
            } else {
                // A stretch past markers at the head: the executor passes
                // them and waits at its start for the next period.
                let waits = self.stretch_past_markers(q, intervals, stale);
                let mut sample = self.tick_until(dt, head, tail, waits);
                sample.intervals_consumed = stale;
                self.passed += sample.consumed as u64;
                return sample;
            }
        }
        self.follow_tick(dt, q, intervals)
    }

    /// Intervals at the front of the queue that lie behind the motion.
    fn stale_intervals(&self, q: View, intervals: Intervals) -> usize {
        let mut k = 0;
        while let Some(i) = intervals.get(k) {
            let behind = match (i.segment as u64).checked_sub(self.passed) {
                None => true,
                // The head segment: behind once the motion is past its end.
                Some(0) => i.from + i.length <= self.s && q.get(0).is_some_and(|s| s.is_motion()),
                Some(_) => false,
            };
            if !behind {
                break;
            }
            k += 1;
        }
        k
    }

    /// Where a stretch can be taken now: the executor at rest, free to
    /// move at 100 % or less, on (or before only empty segments before)
    /// the start of a stretch whose every interval is queued. Returns the
    /// empty segments to pass first.
    fn stretch_to_take(&self, q: View, intervals: Intervals, stale: usize) -> Option<usize> {
        let (first, at) =
            self.stretch_ahead(q, intervals, stale, |s| s.is_motion() && s.length <= 0.0)?;
        let s = if at == 0 { self.s } else { 0.0 };
        ((first.from - s).abs() <= SAME_PLACE).then_some(at)
    }

    /// The first queued stretch and the queue item it starts at, where
    /// the executor could take it: at rest, free to move at 100 % or
    /// less, the stretch complete and moving, and every queue item before
    /// its segment one that `passable` accepts.
    fn stretch_ahead(
        &self,
        q: View,
        intervals: Intervals,
        stale: usize,
        passable: impl Fn(&Segment) -> bool,
    ) -> Option<(Interval, usize)> {
        self.rate_limits?;
        let at_rest = self.v == 0.0 && self.a == 0.0 && self.brake.is_none();
        let free = !self.hold && !self.single_block && self.feed_override * self.feed_scale <= 1.0;
        if !at_rest || !free {
            return None;
        }
        let first = *intervals.get(stale)?;
        if !first.from_rest() {
            return None;
        }
        let at = usize::try_from((first.segment as u64).checked_sub(self.passed)?).ok()?;
        if !(0..at).all(|k| q.get(k).is_some_and(&passable)) || !q.get(at)?.is_motion() {
            return None;
        }
        // Every interval to the stretch's rest, none standing still.
        let mut k = stale;
        loop {
            let i = intervals.get(k)?;
            if i.stands_still() {
                return None;
            }
            if i.to_rest() {
                return Some((first, at));
            }
            k += 1;
        }
    }

    /// The queue item a stretch starts at when only markers and empty
    /// segments lie before it, and the executor could take the stretch
    /// once past them.
    fn stretch_past_markers(&self, q: View, intervals: Intervals, stale: usize) -> Option<usize> {
        if self.s != 0.0 {
            return None;
        }
        let (first, at) =
            self.stretch_ahead(q, intervals, stale, |s| !s.is_motion() || s.length <= 0.0)?;
        (at > 0 && first.from.abs() <= SAME_PLACE).then_some(at)
    }

    fn take_stretch(&mut self, intervals: Intervals, stale: usize, skip: usize) {
        let limits = self.rate_limits.expect("checked by stretch_to_take");
        let mut end = stale;
        while intervals.get(end).is_some_and(|i| !i.to_rest()) {
            end += 1;
        }
        debug_assert!(end < intervals.len());
        let mut follower = Follower::with_override(self.period, limits);
        follower.start_at(self.follow_target(None));
        self.following = Some(Following {
            follower,
            taken: stale,
            end: end + 1,
            reported: 0,
        });
        self.skip_on_entry = skip;
        self.dropped_on_entry = stale;
        self.stretches_followed += 1;
    }

    /// The rate the operator asks for on `seg` (the segment the tool is
    /// on; `None` before it starts): 0 for hold and single block, the
    /// override of the segment's kind, at most 1.
    fn follow_target(&self, seg: Option<&Segment>) -> f64 {
        if self.hold || self.single_block {
            return 0.0;
        }
        let factor = match seg.map(|s| s.kind) {
            Some(crate::plan::SegmentKind::Rapid) => self.rapid_override,
            _ => self.feed_override * self.feed_scale,
        };
        factor.clamp(0.0, 1.0)
    }

    /// One period along the stretch being followed.
    fn follow_tick(&mut self, dt: f64, q: View, intervals: Intervals) -> Sample {
        let skip = std::mem::take(&mut self.skip_on_entry);
        let dropped = std::mem::take(&mut self.dropped_on_entry);
        let target = self.follow_target(q.get(skip));
        let following = self.following.as_mut().expect("caller checked");
        following.follower.set_override(target);
        let end = following.end;
        let sample = following.follower.tick(&mut Stretch {
            queue: intervals,
            taken: &mut following.taken,
            end,
        });
        // Where the tool is now: a segment (its index in the queue) and
        // the arc length into it.
        // Intervals now behind the tool, counted from the queue's front
        // (which the caller moves on by as many).
        let (at_segment, at, rate, done) = match sample {
            Some(s) => (
                s.segment,
                s.at,
                s.rate,
                dropped + s.interval - following.reported,
            ),
            None => {
                let last = intervals.get(end - 1).expect("the stretch is queued");
                (last.segment, last.from + last.length, 0.0, end)
            }
        };
        if let Some(s) = sample {
            following.reported = s.interval;
        }
        following.taken -= done.min(following.taken);
        following.end -= done;
        let index = usize::try_from(at_segment as u64 - self.passed).expect("segment in the queue");
        let mut travelled = at - self.s;
        for k in 0..index {
            let seg = q.get(k).expect("segment in the queue");
            travelled += seg.length;
        }
        // Leaving the stretch: at its rest, or held still for single block.
        let ended = sample.is_none();
        let seg = q.get(index).expect("segment in the queue");
        let (mut consumed, mut s) = (index, at);
        if ended && at >= seg.length - SAME_PLACE {
            consumed += 1;
            s = 0.0;
        }
        let v = if ended {
            0.0
        } else {
            (travelled / dt).max(0.0)
        };
        let a = if ended { 0.0 } else { (v - self.v) / dt };
        let stopped = rate == 0.0 && following.follower.target() == 0.0;
        let leave = ended || (stopped && self.single_block);
        self.position = seg.position_at(at);
        self.line = seg.line;
        self.moves = seg.moves;
        self.s = s;
        self.v = if leave { 0.0 } else { v };
        self.a = if leave { 0.0 } else { a };
        if leave {
            self.following = None;
            self.guard = None;
            self.brake = None;
        }
        self.passed += consumed as u64;
        let moving = !(ended || stopped);
        Sample {
            position: self.position,
            line: self.line,
            moves: self.moves,
            velocity: self.v,
            acceleration: self.a,
            moving,
            consumed,
            stopped_at: None,
            program_stop: false,
            waits_on_operator: stopped && !ended,
            intervals_consumed: done,
        }
    }
}
