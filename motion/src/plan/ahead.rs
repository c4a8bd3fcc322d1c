//! Blends worked out ahead of the planner, on a second thread.
//!
//! Most of the planner's time per line goes into blends: on a dense curve
//! the fit at the line's midpoint, the proofs that the blends stay within
//! the tolerance and the blend's sampled table; at a corner the proofs for
//! each leg length tried, and the table. All of that is a function of the
//! programmed lines alone once one thing is assumed about where the blend
//! starts: at a corner on the line, a leg from its end; on a dense curve at
//! the previous line's fitted midpoint, where the blend before ended all
//! along a smooth curve. So a worker thread works blends out while the
//! planner is still busy with earlier lines, a hundred or so lines ahead,
//! and the two share the junctions (`worker_takes`).
//!
//! The planner takes a worked-out blend only after checking, bit for bit,
//! that the start and legs it was made from are what the planner has, and
//! works out everything else itself, including any blend the worker has
//! not reached yet. Whether the worker kept up, fell behind or is off, the
//! plan is the same to the last bit (the test
//! `the_blend_worker_changes_no_plan_bit` holds it to that).
//!
//! The worker never checks the machine's reach (that needs the
//! kinematics, which belong to the planner's thread); the planner does
//! that for every blend it takes.

use std::cell::{Cell, UnsafeCell};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::{
    blend_legs, blend_near, corner_legs, fitted_frame, frame_on, hairpin, vertex_midpoint,
    xyz_frame, Chord, Chords, FittedPoints, FrameXyz, PathMode, Programmed, CORNER_TRIES, FIT_SIDE,
};
use crate::path::{Blend, BlendExtremes, Frame};

/// How many more lines the planner holds back while the worker runs, so
/// that the worker has them before the planner needs their blends.
pub(super) const LEAD: usize = 102;

/// Moves handed over at once (one lock per batch, not per move).
const BATCH: usize = 16;

/// How the worker and the planner share the junctions: in share
/// `(n, k)` junction `j` is the worker's when `j % n < k`, and the planner
/// keeps the rest, one in every `n`. That one is always followed by one
/// of the worker's, whose blend starts at the fit the planner's junction
/// needs, so the planner takes that fit too ([`Ahead::fit`]) and every
/// line is fitted once.
///
/// Which share keeps both threads busy depends on what else the
/// planner's thread does (a 200,000-chord spiral, read beforehand, ran
/// fastest at one in two, 1.13–1.17 M lines/s; with the interpreter on
/// the planner's thread, at one in three, 0.84 M; stellabee1.ngc, whose
/// corners cost the planner more, leaves the worker idle even at three
/// in four and gains 3–4 % at seven in eight and beyond), so the worker
/// moves between these as it goes (`Worker::adapt`).
const SHARES: [(u64, u64); 7] = [(2, 1), (3, 2), (4, 3), (6, 5), (8, 7), (16, 15), (32, 31)];

/// Most periods in a row the worker must find itself idle before it
/// raises its share again.
const MAX_HOLD: u64 = 64;

/// The share a worker starts with.
const FIRST_SHARE: usize = 1;

/// Junctions the worker judges its share over.
const SHARE_PERIOD: u64 = 1024;

/// Whether junction `index` is the worker's in share `share` (an index
/// into [`SHARES`]).
fn worker_takes(index: u64, share: usize) -> bool {
    let (n, k) = SHARES[share];
    index % n < k
}

/// A value on cache lines of its own (a pair: x86 fetches them
/// together), so that one thread writing it does not take away the line
/// of what the other reads beside it.
#[repr(align(128))]
struct Padded<T>(T);

impl<T> std::ops::Deref for Padded<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.0
    }
}

/// Junctions the planner moves on before it lets the worker reuse the
/// slots behind it (`Shared::consumed`): the worker reads that only
/// when it is about to pass it, which it never is, the planner holding
/// back fewer moves than SLOTS.
const CONSUMED_STEP: u64 = 16;

/// Junctions kept worked out: more than the lead, so that the worker's
/// results are not overwritten before the planner reaches them.
const SLOTS: usize = 2 * LEAD;

/// How long the worker keeps looking for more moves before it sleeps:
/// long enough to span the planner's work between two batches, so that
/// a busy planner never pays for waking it.
const SPIN: Duration = Duration::from_micros(200);

/// A waiting move as the worker sees it. (Not boxed: nearly all are
/// lines, and they travel in batches.)
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub(super) enum Move {
    /// A line in X Y Z only, with the path mode it was programmed in.
    Line { line: Programmed, mode: PathMode },
    /// Anything else (an arc, or a line that moves other axes): it ends
    /// the polyline the curve fit sees.
    Other,
}

/// What the planner hands the worker.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
enum Input {
    Move(Move),
    /// The planner released every waiting move (program end, a dwell...):
    /// the blends up to here were decided seeing no move after this.
    Flush,
}

/// The blend at the vertex between lines `a` and `b` (the move with the
/// junction's index, `c` the one after) as the planner would work it out
/// from `start` with these legs, but for the machine's reach.
///
/// X Y Z only, of frames and control points: the lines are X Y Z lines,
/// so the other axes are the lines' own, and the planner has them. A
/// speculation crosses from the worker's core to the planner's, and every
/// byte of it costs there (with the two threads on distant cores of this
/// VM, 1.7 kB more per speculation planned 11 % slower).
#[derive(Clone, Copy, Debug)]
pub(super) struct Speculation {
    /// Where the blend starts on `a`: `a`'s fitted midpoint on a dense
    /// curve (where the blend before it ended), else on the line.
    start: FrameXyz,
    /// Legs at a's end and b's start, and at b's end and c's start.
    legs: (f64, f64),
    legs_bc: Option<(f64, f64)>,
    pub worked: Worked,
    /// The chosen blend sampled ([`Blend::sampled`]), if there is one:
    /// its control points are the blend's.
    pub sampled: Option<(Blend, BlendExtremes)>,
}

/// A junction's blend legs (`blend_legs`; none where it gives none).
type Legs = Option<(f64, f64)>;

/// The fallback of a dense junction whose fit gave no blends within
/// tolerance (`Planner::choose_blend`'s `vertices`), as the worker found it.
/// (Not boxed, as [`Worked`].)
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub(super) enum Fallback {
    /// Not tried: the fit's blends were within tolerance (if the planner
    /// finds them out of reach, it tries the fallback itself).
    Untried,
    /// A blend from `start` or the one onto c leaves the tolerance.
    Outside,
    /// Both are within tolerance: the midpoint frame (X Y Z) and the X Y Z
    /// control points of the blend onto c; the blend into it is
    /// `sampled`.
    Within { mid: FrameXyz, bc: [[f64; 3]; 6] },
}

/// A speculation [`Ahead::take`] found usable, read in place in its
/// slot. The worker has finished with that junction for good, and while
/// this lives the planner does not tell it that the slot may be reused
/// (`Shared::consumed`).
pub(super) struct Taken<'a> {
    speculation: &'a Speculation,
    reading: &'a Cell<bool>,
}

impl std::ops::Deref for Taken<'_> {
    type Target = Speculation;
    fn deref(&self) -> &Speculation {
        self.speculation
    }
}

impl Drop for Taken<'_> {
    fn drop(&mut self) {
        self.reading.set(false);
    }
}

/// What the worker worked out at a junction, by the planner's branch.
/// (Not boxed: it lives in a slot of a ring made once.)
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
pub(super) enum Worked {
    /// On a dense curve (blends take the whole halves of a and b).
    Dense {
        /// The fitted frame at b's midpoint.
        fit: Option<FrameXyz>,
        /// The X Y Z control points of the blend from `fit` onto c, when
        /// both it and the blend from `start` to `fit` (then `sampled`)
        /// are within tolerance.
        bc: Option<[[f64; 3]; 6]>,
        /// Where there is no `bc`, the planner's fallback: the blends
        /// through b's midpoint with the curvature its two vertices give.
        fallback: Fallback,
    },
    /// At a corner (b's start is not a whole half): the first of the
    /// legs, shrinking by 0.7 from the tolerance's, whose blend (then
    /// `sampled`) is within b's tolerance; from a's fitted midpoint
    /// (`from_midpoint`, the blend before took a's other half) only the
    /// tolerance's legs, as the planner tries.
    Corner {
        chosen: Option<(f64, f64)>,
        from_midpoint: bool,
    },
}

/// One junction's place in the ring of worked-out blends.
///
/// Written by the worker alone, once per junction, and read by the
/// planner in place, without a lock: a lock's word would cross between
/// the cores twice per junction, as would a slot the planner emptied.
/// `index` says what `filled` holds, and orders it: the worker stores
/// it (Release) after filling, the planner loads it (Acquire) before
/// reading, and once it names a junction the worker never writes that
/// slot again until the planner has let the slot go (`Shared::consumed`).
struct Slot {
    /// The junction whose work `filled` holds (`u64::MAX`: none yet).
    index: AtomicU64,
    filled: UnsafeCell<Filled>,
}

/// What the worker left in a slot for one junction: a blend, or the fit
/// at a junction the planner keeps, never both.
struct Filled {
    /// Its blend.
    speculation: Option<Speculation>,
    /// At a junction the planner keeps: the fitted frame at the midpoint
    /// of its second line, which the worker fitted anyway (the next
    /// junction's blend starts there), with the fit's window
    /// ([`window_end`]).
    fit: Option<(u64, Option<FrameXyz>)>,
}

/// Where the fit at the midpoint of move `index` stops looking, seeing
/// moves before `end`: it takes at most FIT_SIDE lines after the centre
/// (fewer at a corner or a move that is not a line, which both planner
/// and worker see alike). Two fits at one move with the same window end
/// see the same chords, so they are the same to the bit.
pub(super) fn window_end(index: u64, end: u64) -> u64 {
    end.min(index + 1 + FIT_SIDE as u64)
}

struct Inbox {
    inputs: Vec<Input>,
    sleeping: bool,
}

/// What the planner and the worker share.
struct Shared {
    inbox: Mutex<Inbox>,
    wake: Condvar,
    /// Moves handed over so far: the worker watches it before sleeping.
    handed: Padded<AtomicU64>,
    /// The junction the planner is deciding now: the worker skips it and
    /// everything before it.
    deciding: Padded<AtomicU64>,
    /// The planner is gone: stop. (Set before the inbox is locked to wake
    /// the worker, and read under that lock before it sleeps, so the
    /// wake-up is not lost.)
    closed: AtomicBool,
    /// The next junction the worker looks at: it has passed every one
    /// before (a patient planner waits on it).
    passed: Padded<AtomicU64>,
    /// The planner reads no slot of a junction before this one any more:
    /// their slots are the worker's to fill again. Moved on in steps of
    /// [`CONSUMED_STEP`], and only while the planner holds no [`Taken`].
    consumed: Padded<AtomicU64>,
    /// The planner waits for the worker's blends and fits, so that every
    /// one the worker can make is taken (tests).
    patient: bool,
    /// The worker takes every junction, leaving none to the planner
    /// (tests).
    all: bool,
    /// Which of [`SHARES`] is in force. Planner and worker may read it
    /// either side of a change: a junction both think the other's is
    /// worked out by the planner, and one both think theirs is taken
    /// from the worker if it got there first; a slot is filled once, so
    /// the worker never puts a fit where it left a blend. The plan stays
    /// the same.
    share: Padded<AtomicUsize>,
    slots: Box<[Slot]>,
}

// SAFETY: the slots' `filled` cells are shared by the protocol on `Slot`:
// the worker writes a cell only for a junction j with j < consumed +
// SLOTS (so the planner is done with the junction the slot held before)
// and before it stores `index = j`; it writes each junction's cell once.
// The planner reads a cell only after loading `index` equal to its
// junction, and moves `consumed` past it only when done reading.
unsafe impl Sync for Shared {}

impl Shared {
    fn new(patient: bool, all: bool) -> Shared {
        Shared {
            inbox: Mutex::new(Inbox {
                inputs: Vec::with_capacity(4 * BATCH),
                sleeping: false,
            }),
            wake: Condvar::new(),
            handed: Padded(AtomicU64::new(0)),
            deciding: Padded(AtomicU64::new(0)),
            closed: AtomicBool::new(false),
            passed: Padded(AtomicU64::new(0)),
            consumed: Padded(AtomicU64::new(0)),
            patient,
            all,
            share: Padded(AtomicUsize::new(FIRST_SHARE)),
            slots: (0..SLOTS)
                .map(|_| Slot {
                    index: AtomicU64::new(u64::MAX),
                    filled: UnsafeCell::new(Filled {
                        speculation: None,
                        fit: None,
                    }),
                })
                .collect(),
        }
    }

    /// Whether junction `index` is the worker's.
    fn takes(&self, index: u64) -> bool {
        self.all || worker_takes(index, self.share.load(Ordering::Relaxed))
    }

    fn slot_of(&self, index: u64) -> &Slot {
        &self.slots[(index % SLOTS as u64) as usize]
    }

    /// What the worker left for junction `index`, if it has (and so is
    /// done with it). A patient planner (tests) first waits until the
    /// worker has passed junction `filled_by`; it always gets there,
    /// since the planner holds back LEAD moves, more than a batch, or has
    /// flushed.
    ///
    /// The planner must not move `consumed` past `index` while it uses
    /// the answer.
    fn filled(&self, index: u64, filled_by: u64) -> Option<&Filled> {
        if self.patient {
            while self.passed.load(Ordering::Acquire) <= filled_by {
                std::thread::yield_now();
            }
        }
        let slot = self.slot_of(index);
        if slot.index.load(Ordering::Acquire) != index {
            return None;
        }
        // SAFETY: `index` names this junction, so the worker has filled
        // the cell and will not write it again while `consumed` stays at
        // or below `index` (see `Shared`).
        Some(unsafe { &*slot.filled.get() })
    }

    /// Fill the slot of junction `index` (the worker), unless the planner
    /// may still read what the slot holds now, or the worker already
    /// filled it for this junction: `fill` gets the cell to write, and the
    /// slot then names `index`. False if it could not.
    fn fill(&self, index: u64, consumed: &mut u64, fill: impl FnOnce(&mut Filled)) -> bool {
        if index >= *consumed + SLOTS as u64 {
            *consumed = self.consumed.load(Ordering::Acquire);
            if index >= *consumed + SLOTS as u64 {
                return false;
            }
        }
        let slot = self.slot_of(index);
        if slot.index.load(Ordering::Relaxed) == index {
            return false;
        }
        // SAFETY: the slot holds a junction below `consumed`, which the
        // planner reads no more, and only this thread writes cells.
        fill(unsafe { &mut *slot.filled.get() });
        slot.index.store(index, Ordering::Release);
        true
    }

    fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Relaxed)
    }

    fn inbox(&self) -> MutexGuard<'_, Inbox> {
        self.inbox
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// The planner's end of the worker: hands it moves, takes its blends.
pub(super) struct Ahead {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    batch: Vec<Input>,
    /// Moves handed over so far, batched or not.
    pushed: u64,
    /// A [`Taken`] is out: `consumed` must stay where it is.
    reading: Cell<bool>,
    /// What the planner last stored in `Shared::consumed`.
    consumed: Cell<u64>,
    /// What the planner looked for and took (tests only).
    #[cfg(test)]
    tally: std::cell::Cell<Tally>,
}

/// How often the planner looked for a worked-out blend and a fit from the
/// worker, and how often it took one: the tests hold the share taken.
#[cfg(test)]
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    /// Blends the planner looked for at the worker's junctions.
    looked: u64,
    /// Blends taken from the worker.
    taken: u64,
    /// Fits the planner looked for at its own junctions.
    fit_looked: u64,
    /// Fits the planner took from the worker.
    fitted: u64,
    /// Blends the planner worked out itself at the worker's junctions.
    own: u64,
}

impl Ahead {
    /// Start a worker; `None` if no thread can be started (the planner
    /// then works everything out itself).
    pub(super) fn start() -> Option<Ahead> {
        Ahead::spawn(false, false)
    }

    /// A worker whose every blend and fit the planner waits for and
    /// takes, working out every junction (`all`) or its share (tests: the
    /// plan must still be the same to the last bit).
    #[cfg(test)]
    pub(super) fn start_patient(all: bool) -> Option<Ahead> {
        Ahead::spawn(true, all)
    }

    fn spawn(patient: bool, all: bool) -> Option<Ahead> {
        let mut ahead = Ahead::over(Arc::new(Shared::new(patient, all)));
        let theirs = Arc::clone(&ahead.shared);
        let worker = std::thread::Builder::new()
            .name("kerf-blends".into())
            .spawn(move || Worker::new(theirs).run())
            .ok()?;
        ahead.worker = Some(worker);
        Some(ahead)
    }

    /// The planner's end of `shared`, with no worker yet.
    fn over(shared: Arc<Shared>) -> Ahead {
        Ahead {
            shared,
            worker: None,
            batch: Vec::with_capacity(BATCH + 1),
            pushed: 0,
            reading: Cell::new(false),
            consumed: Cell::new(0),
            #[cfg(test)]
            tally: Default::default(),
        }
    }

    /// The planner worked out the blend at junction `index` itself
    /// (counted in the tally if it is the worker's; tests only).
    #[cfg(test)]
    pub(super) fn worked_here(&self, index: u64) {
        if self.shared.takes(index) {
            self.count(|t| t.own += 1);
        }
    }

    /// Count in the tally (tests only).
    #[cfg(test)]
    fn count(&self, f: impl FnOnce(&mut Tally)) {
        let mut t = self.tally.get();
        f(&mut t);
        self.tally.set(t);
    }

    /// The planner queued `m` (every waiting move, in order).
    pub(super) fn push(&mut self, m: Move) {
        self.batch.push(Input::Move(m));
        self.pushed += 1;
        if self.batch.len() >= BATCH {
            self.hand_over();
        }
    }

    /// The planner is about to release every waiting move.
    pub(super) fn flush(&mut self) {
        self.batch.push(Input::Flush);
        self.hand_over();
    }

    fn hand_over(&mut self) {
        let sleeping = {
            let mut inbox = self.shared.inbox();
            inbox.inputs.append(&mut self.batch);
            inbox.sleeping
        };
        self.shared.handed.store(self.pushed, Ordering::Release);
        if sleeping {
            self.shared.wake.notify_one();
        }
    }

    /// The planner is at junction `index` (every junction it asks about
    /// comes later): the slots of the junctions before may be filled
    /// again, once it holds no [`Taken`], in steps of [`CONSUMED_STEP`].
    fn consume(&self, index: u64) {
        if !self.reading.get() && index >= self.consumed.get() + CONSUMED_STEP {
            self.consumed.set(index);
            self.shared.consumed.store(index, Ordering::Release);
        }
    }

    /// The worked-out blend at junction `index` (the index of its second
    /// line among all moves queued), if the worker has it and made it
    /// from this `start` with these legs; otherwise `None` says to work
    /// it out (also when the worker has not got there: no waiting, unless
    /// patient). Held at most one at a time.
    pub(super) fn take(
        &self,
        index: u64,
        start: &FrameXyz,
        legs: (f64, f64),
        legs_bc: Option<(f64, f64)>,
    ) -> Option<Taken<'_>> {
        self.consume(index);
        if !self.shared.takes(index) || self.reading.get() {
            return None;
        }
        #[cfg(test)]
        self.count(|t| t.looked += 1);
        if !self.shared.patient {
            self.shared.deciding.store(index, Ordering::Relaxed);
        }
        // Checked and read in place: copying a speculation out showed in
        // profiles.
        let s = self.shared.filled(index, index)?.speculation.as_ref()?;
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        let frame_same = |a: &FrameXyz, b: &FrameXyz| same(a.as_flattened(), b.as_flattened());
        let pair = |l: Option<(f64, f64)>| l.map(|(x, y)| [x, y]);
        let legs_same = same(&[s.legs.0, s.legs.1], &[legs.0, legs.1])
            && match (pair(s.legs_bc), pair(legs_bc)) {
                (Some(x), Some(y)) => same(&x, &y),
                (None, None) => true,
                _ => false,
            };
        if !(legs_same && frame_same(&s.start, start)) {
            return None;
        }
        #[cfg(test)]
        self.count(|t| t.taken += 1);
        self.reading.set(true);
        Some(Taken {
            speculation: s,
            reading: &self.reading,
        })
    }

    /// The fitted frame at the midpoint of move `index` (the second line
    /// of a junction the planner keeps), if the worker has it from a fit
    /// whose window ends at `window` ([`window_end`]); `None`: fit it.
    /// Never waits, unless patient.
    pub(super) fn fit(&self, index: u64, window: u64) -> Option<Option<FrameXyz>> {
        self.consume(index);
        if self.shared.takes(index) {
            return None;
        }
        #[cfg(test)]
        self.count(|t| t.fit_looked += 1);
        // The worker hands it over at the next junction.
        match self.shared.filled(index, index + 1)?.fit {
            Some((at, fit)) if at == window => {
                #[cfg(test)]
                self.count(|t| t.fitted += 1);
                Some(fit)
            }
            _ => None,
        }
    }
}

impl Drop for Ahead {
    fn drop(&mut self) {
        self.shared.closed.store(true, Ordering::Relaxed);
        drop(self.shared.inbox());
        self.shared.wake.notify_one();
        if let Some(worker) = self.worker.take() {
            // A worker that panicked has nothing left to clean up.
            let _ = worker.join();
        }
    }
}

/// The worker's copy of the waiting moves and their chords.
struct Worker {
    shared: Arc<Shared>,
    /// Moves from index `first` on, with their chords.
    moves: VecDeque<Move>,
    chords: Chords,
    first: u64,
    /// Where the planner flushed: the number of moves queued then.
    flushes: VecDeque<u64>,
    /// The next junction to look at.
    next: u64,
    /// The last move that is not a line.
    last_break: Option<u64>,
    /// The planner's `consumed`, as last read.
    consumed: u64,
    /// The last fitted frame worked out, with its move's index.
    last_fit: Option<(u64, Option<Frame>)>,
    /// The fitted points its frames take differences of.
    points: FittedPoints,
    /// Where the last blend worked out that took b's whole first half
    /// ended (X Y Z, at b's midpoint: the fit's frame or the fallback's on
    /// a dense curve, on b with no curvature before a hairpin), with its
    /// junction: the blend after it starts there if the planner takes it.
    ended: Option<(u64, FrameXyz)>,
    /// The last junction worked out, with its legs and those of the
    /// junction after it (`blend_legs`, none where it gives none).
    legs_seen: Option<(u64, Legs, Legs)>,
    /// The junction at which the share is next judged (`adapt`).
    judge_at: u64,
    /// Since the share was last judged: the worker's junctions the
    /// planner got to first, and the times the worker ran out of moves.
    late: u64,
    idle: u64,
    /// Periods in a row the worker ran out of moves, never late; how many
    /// it takes to raise the share; whether the last period raised it.
    calm: u64,
    hold: u64,
    raised: bool,
}

impl Worker {
    fn new(shared: Arc<Shared>) -> Worker {
        Worker {
            shared,
            moves: VecDeque::new(),
            chords: Chords::new(),
            first: 0,
            flushes: VecDeque::new(),
            next: 1,
            last_break: None,
            consumed: 0,
            last_fit: None,
            points: FittedPoints::new(),
            ended: None,
            legs_seen: None,
            judge_at: SHARE_PERIOD,
            late: 0,
            idle: 0,
            calm: 0,
            hold: 1,
            raised: false,
        }
    }

    /// Move to a smaller share if the planner keeps getting to the
    /// worker's junctions first (the worker is the slower); to a larger
    /// one if the worker keeps running out of moves and never falls
    /// behind (the planner is), for `hold` periods in a row. A larger
    /// share that turned out too large doubles `hold`, so that the share
    /// settles where the two threads balance instead of swinging.
    fn adapt(&mut self) {
        if !(self.shared.patient || self.shared.all) {
            let share = self.shared.share.load(Ordering::Relaxed);
            let mut next = share;
            if self.late > SHARE_PERIOD / 64 {
                next = share.saturating_sub(1);
                if self.raised {
                    self.hold = (2 * self.hold).min(MAX_HOLD);
                }
                self.calm = 0;
            } else if self.late == 0 && self.idle >= 16 {
                self.calm += 1;
                if self.calm >= self.hold {
                    next = (share + 1).min(SHARES.len() - 1);
                    self.calm = 0;
                }
            } else {
                self.calm = 0;
            }
            self.raised = next > share;
            if next != share {
                self.shared.share.store(next, Ordering::Relaxed);
            }
        }
        self.late = 0;
        self.idle = 0;
        self.judge_at = self.next + SHARE_PERIOD;
    }

    fn run(mut self) {
        let mut inputs = Vec::with_capacity(4 * BATCH);
        loop {
            {
                let mut inbox = self.shared.inbox();
                if inbox.inputs.is_empty() && !self.shared.is_closed() {
                    drop(inbox);
                    self.idle += 1;
                    self.spin();
                    inbox = self.shared.inbox();
                }
                while inbox.inputs.is_empty() && !self.shared.is_closed() {
                    inbox.sleeping = true;
                    inbox = self
                        .shared
                        .wake
                        .wait(inbox)
                        .unwrap_or_else(|poisoned| poisoned.into_inner());
                }
                inbox.sleeping = false;
                if self.shared.is_closed() {
                    return;
                }
                std::mem::swap(&mut inputs, &mut inbox.inputs);
            }
            for input in inputs.drain(..) {
                self.receive(input);
            }
            self.work();
        }
    }

    /// Look for more moves for a while before sleeping.
    fn spin(&self) {
        let seen = self.shared.handed.load(Ordering::Acquire);
        let since = Instant::now();
        while since.elapsed() < SPIN {
            for _ in 0..64 {
                std::hint::spin_loop();
            }
            if self.shared.handed.load(Ordering::Acquire) != seen {
                return;
            }
        }
    }

    fn receive(&mut self, input: Input) {
        match input {
            Input::Move(m) => {
                let chord = match &m {
                    Move::Line { line, .. } => Chord::of(line, self.chords.back().as_ref()),
                    Move::Other => {
                        self.last_break = Some(self.first + self.moves.len() as u64);
                        Chord::BREAK
                    }
                };
                self.moves.push_back(m);
                self.chords.push_back(chord);
            }
            Input::Flush => self.flushes.push_back(self.first + self.moves.len() as u64),
        }
    }

    /// Work out every junction whose lines are all here, in order.
    fn work(&mut self) {
        loop {
            let total = self.first + self.moves.len() as u64;
            let j = self.next;
            while self.flushes.front().is_some_and(|&f| f <= j) {
                self.flushes.pop_front();
            }
            // The planner decides junction j seeing the moves up to its
            // next flush, or at least FIT_SIDE after j (the fit sees no
            // further, nor past a move that is not a line).
            let end = match self.flushes.front() {
                Some(&flush) => flush,
                None => {
                    let broken = self.last_break.is_some_and(|k| k > j);
                    if total < j + 1 + FIT_SIDE as u64 && !broken {
                        return;
                    }
                    total
                }
            };
            // Junctions the planner has decided, or keeps for itself, are
            // left.
            let decided = j <= self.shared.deciding.load(Ordering::Relaxed);
            let takes = self.shared.takes(j);
            if j + 1 < end && !decided && takes {
                self.junction(j, end);
            }
            self.late += (decided && takes) as u64;
            self.next += 1;
            self.shared.passed.store(self.next, Ordering::Release);
            if self.next >= self.judge_at {
                self.adapt();
            }
            // Keep what the fits of the next junctions may look back on.
            while self.first + (FIT_SIDE as u64 + 2) < self.next {
                self.moves.pop_front();
                self.chords.pop_front();
                self.first += 1;
            }
            if self.shared.is_closed() {
                return;
            }
        }
    }

    /// The fitted frame at move `index`'s midpoint, seeing moves before `end`.
    /// (Fields one by one, so that a slot can be borrowed meanwhile.)
    fn fit(
        last_fit: &mut Option<(u64, Option<Frame>)>,
        points: &mut FittedPoints,
        moves: &VecDeque<Move>,
        chords: &Chords,
        first: u64,
        index: u64,
        end: u64,
    ) -> Option<Frame> {
        if let Some((at, fit)) = *last_fit {
            if at == index {
                return fit;
            }
        }
        let Move::Line { line, .. } = &moves[(index - first) as usize] else {
            return None;
        };
        let fit = fitted_frame(
            chords,
            (index - first) as usize,
            (end - first) as usize,
            line,
            first,
            points,
        );
        *last_fit = Some((index, fit));
        fit
    }

    /// Work out junction `j` (moves j − 1, j and j + 1), seeing moves
    /// before `end`, into its slot (which the planner reads only if it
    /// has not decided the junction already).
    fn junction(&mut self, j: u64, end: u64) {
        // By reference: a programmed line is over 200 bytes.
        let at = |k: u64| match &self.moves[(k - self.first) as usize] {
            Move::Line { line, mode } => Some((line, *mode)),
            Move::Other => None,
        };
        let (Some((a, a_mode)), Some((b, b_mode))) = (at(j - 1), at(j)) else {
            return;
        };
        let PathMode::Blend { tolerance } = b_mode else {
            return;
        };
        // The legs at junction j − 1 and at this one, from the junction
        // before where the worker worked that out (its `legs_bc` are this
        // one's legs).
        let seen = self.legs_seen.filter(|&(at, ..)| at + 1 == j);
        let legs = match seen {
            Some((_, _, legs)) => legs,
            None => blend_legs(a, b, b_mode),
        };
        let Some(legs) = legs else {
            return;
        };
        let c = at(j + 1);
        let legs_bc = c.and_then(|(c, c_mode)| blend_legs(b, c, c_mode));
        self.legs_seen = Some((j, Some(legs), legs_bc));
        // The planner's branches (`Planner::choose_blend`): a dense curve
        // where blends take whole halves of b, a corner where they do not;
        // either from a's fitted midpoint where the blend before took a's
        // other half, else from a leg on a.
        let (half_a, half_b) = (a.length / 2.0, b.length / 2.0);
        let b_whole = legs.1 == half_b
            && legs_bc.is_some_and(|l| l.0 == half_b)
            && !c.is_some_and(|(c, _)| hairpin(b, c));
        let a_whole = legs.0 == half_a;
        // Whether the blend before takes a's other half (if it is made):
        // then this one starts at a's fitted midpoint.
        let before = match seen {
            Some((_, before, _)) => before,
            None => (j >= self.first + 2)
                .then(|| at(j - 2))
                .flatten()
                .and_then(|(p, _)| blend_legs(p, a, a_mode)),
        };
        let a_taken = a_whole && before.is_some_and(|l| l.1 == half_a);
        let (moves, chords, first) = (&self.moves, &self.chords, self.first);
        let start = if a_taken {
            // The blend before ended at a's fitted midpoint, as the planner
            // keeps it: X Y Z from the fit, the other axes where the
            // trimmed line starts. (Had the planner decided a's blend
            // seeing other moves, or with another frame, the start differs
            // and it works this one out itself.)
            let fit_a = Self::fit(
                &mut self.last_fit,
                &mut self.points,
                moves,
                chords,
                first,
                j - 1,
                end,
            );
            if !self.shared.takes(j - 1) {
                // Junction j − 1 is the planner's: it needs this fit too.
                let fit = (window_end(j - 1, end), fit_a.as_ref().map(xyz_frame));
                self.shared.fill(j - 1, &mut self.consumed, |filled| {
                    filled.speculation = None;
                    filled.fit = Some(fit);
                });
            }
            // Where the worker's own blend before ended, else the fit (the
            // planner's junction, or the worker's that made no blend).
            let mid = match (self.ended, fit_a) {
                (Some((at, mid)), _) if at == j - 1 => mid,
                (_, Some(fit_a)) => xyz_frame(&fit_a),
                (_, None) => return,
            };
            let rest: [f64; 6] =
                std::array::from_fn(|i| a.line.start[i + 3] + half_a * a.direction[i + 3]);
            frame_on(&mid, &rest)
        } else {
            // On the line, a leg from its end: at a corner, and where a
            // dense curve starts after one (the planner starts there
            // wherever the blend before left a's other half, even if this
            // one takes a's whole half).
            a.frame_at(legs.0, true)
        };
        // Dense: the blend from that start to b's fitted midpoint, and on
        // to c.
        let dense = match (b_whole, c, legs_bc) {
            (true, Some((c, c_mode)), Some(legs_bc)) => {
                let PathMode::Blend { tolerance: tol_c } = c_mode else {
                    return;
                };
                Some((c, tol_c, legs_bc))
            }
            _ => None,
        };
        let last_fit = &mut self.last_fit;
        let points = &mut self.points;
        let mut ended = None;
        // Worked out in its slot: copying a speculation in showed in
        // profiles.
        self.shared.fill(j, &mut self.consumed, |filled| {
            filled.fit = None;
            let s = filled.speculation.insert(Speculation {
                start: xyz_frame(&start),
                legs,
                legs_bc,
                worked: Worked::Corner {
                    chosen: None,
                    from_midpoint: a_taken,
                },
                sampled: None,
            });
            if let Some((c, tol_c, legs_bc)) = dense {
                let fit = Self::fit(last_fit, points, moves, chords, first, j, end);
                let mut bc = None;
                if let Some(mid) = &fit {
                    let (control, near) = blend_near(a, b, tolerance, legs, &start, mid);
                    if near {
                        let c_start = c.frame_at(legs_bc.1, false);
                        let (control_bc, near) = blend_near(b, c, tol_c, legs_bc, mid, &c_start);
                        if near {
                            bc = Some(control_bc.map(|q| [q[0], q[1], q[2]]));
                            s.sampled = Some(Blend::sampled(control));
                        }
                    }
                }
                // The fit's blends leave the tolerance (or there is no
                // fit): the planner's fallback through b's midpoint.
                let fallback = if bc.is_some() {
                    Fallback::Untried
                } else {
                    match vertex_midpoint(a, b, c, legs, legs_bc, &start, tolerance, tol_c) {
                        Some((mid, control, control_bc)) => {
                            s.sampled = Some(Blend::sampled(control));
                            Fallback::Within {
                                mid: xyz_frame(&mid),
                                bc: control_bc.map(|q| [q[0], q[1], q[2]]),
                            }
                        }
                        None => Fallback::Outside,
                    }
                };
                ended = match (&fit, bc, &fallback) {
                    (Some(fit), Some(_), _) => Some((j, xyz_frame(fit))),
                    (_, None, Fallback::Within { mid, .. }) => Some((j, *mid)),
                    _ => None,
                };
                s.worked = Worked::Dense {
                    fit: fit.as_ref().map(xyz_frame),
                    bc,
                    fallback,
                };
            } else {
                // The planner's corner: from a's fitted midpoint these legs
                // alone (the blend before fixed a's end); from a leg on a,
                // the tolerance's legs, then shorter.
                let tries = if a_taken { 1 } else { CORNER_TRIES };
                for legs in corner_legs(legs).take(tries) {
                    let from = if a_taken {
                        start
                    } else {
                        a.frame_at(legs.0, true)
                    };
                    let to = b.frame_at(legs.1, false);
                    let (control, near) = blend_near(a, b, tolerance, legs, &from, &to);
                    if near {
                        s.worked = Worked::Corner {
                            chosen: Some(legs),
                            from_midpoint: a_taken,
                        };
                        s.sampled = Some(Blend::sampled(control));
                        // Taking b's whole half (before a hairpin), it
                        // ends on b: the next blend starts there.
                        if legs.1 == half_b {
                            ended = Some((j, xyz_frame(&to)));
                        }
                        break;
                    }
                }
            }
        });
        self.ended = ended;
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Planner, PlannerConfig};
    use super::{Ahead, Shared, Tally, Worker, CONSUMED_STEP, FIRST_SHARE, SHARES, SLOTS};
    use crate::testkit::{uniform, xyz};
    use kerf_interp::{Interpreter, Position};
    use std::fmt::Write;
    use std::sync::atomic::Ordering;

    /// How the planner gets its blends.
    #[derive(Clone, Copy, Debug)]
    enum Helper {
        /// Works everything out itself.
        None,
        /// With the worker, as it ships.
        Worker,
        /// Waits for every blend and fit the worker can make, at every
        /// junction (`all`) or at its share of them.
        Patient { all: bool },
    }

    /// Every segment of `text` planned with `helper`, as text that shows
    /// every bit of every number, with what the planner took from the
    /// worker on dense curves and at corners.
    fn plan(text: &str, helper: Helper) -> (Vec<String>, Tally) {
        let kins = xyz(200.0, 3000.0, 60_000.0);
        let config = PlannerConfig {
            blend_worker: !matches!(helper, Helper::None),
            ..PlannerConfig::default()
        };
        let mut p = Planner::new(&kins, Position::ZERO, config);
        if let Helper::Patient { all } = helper {
            p.ahead = Ahead::start_patient(all);
        }
        let mut out = Vec::new();
        for c in Interpreter::from_text(text, "t.ngc", Position::ZERO) {
            p.plan(&c.unwrap()).unwrap();
            while let Some(s) = p.next_segment() {
                out.push(format!("{s:?}"));
            }
        }
        p.finish();
        while let Some(s) = p.next_segment() {
            out.push(format!("{s:?}"));
        }
        let tally = p.ahead.as_ref().map_or(Tally::default(), |a| a.tally.get());
        (out, tally)
    }

    /// Dense CAM-like curves, rounded to 3 to 5 decimals, interrupted by
    /// everything that changes what a blend sees: dwells (the planner
    /// releases everything), arcs, rapids, sharp corners, path mode and
    /// tolerance changes, and lines long enough to need no blend.
    fn program(seed: u64, pieces: usize) -> String {
        let mut r = uniform(seed);
        let mut t = String::from("G21 G90 G64 P0.01 Q0 F2400\nG0 X0 Y0 Z0\nG1\n");
        let (mut x, mut y) = (0.0f64, 0.0f64);
        for _ in 0..pieces {
            match (r() * 9.0) as u32 {
                0 => t += "G4 P0.01\n",
                1 => {
                    x += 3.0;
                    writeln!(t, "G2 X{x:.4} Y{y:.4} R2\nG1").unwrap();
                }
                2 => {
                    x += 5.0 * (r() - 0.5);
                    writeln!(t, "G0 X{x:.4} Y{y:.4}\nG1").unwrap();
                }
                7 => {
                    // A polyline along and off the edge of the travel (X
                    // 1000): corners, some of whose blends would leave it.
                    writeln!(t, "G0 X1000 Y{y:.4}\nG1").unwrap();
                    x = 1000.0;
                    for _ in 0..(5 + (r() * 40.0) as usize) {
                        y += 0.05 + 2.0 * r();
                        x = if x == 1000.0 && r() < 0.7 {
                            1000.0 - 3.0 * r()
                        } else {
                            1000.0
                        };
                        writeln!(t, "X{x:.4} Y{y:.4}").unwrap();
                    }
                    x = 900.0;
                    writeln!(t, "G0 X{x:.4}\nG1").unwrap();
                }
                3 => {
                    y += 2.0;
                    writeln!(t, "X{x:.4} Y{y:.4}").unwrap();
                }
                _ => {
                    // Chords of a circle through the current point, mostly
                    // blended, in one of the path modes.
                    let n = 30 + (r() * 400.0) as usize;
                    // (Q0: no collinear merge, which P alone implies; it
                    // would merge most of the chords.)
                    let mode = [
                        "G64 P0.01 Q0",
                        "G64 P0.005 Q0",
                        "G64",
                        "G64 P0.02",
                        "G61",
                        "G61.1",
                    ];
                    let pick = (r() * r() * mode.len() as f64) as usize;
                    writeln!(t, "{}", mode[pick]).unwrap();

                    let (radius, chord) = (2.0 + 15.0 * r(), 0.01 + 0.09 * r());
                    let decimals = 3 + (r() * 3.0) as usize;
                    let (cx, cy) = (x - radius, y);
                    let turn = if r() < 0.5 { 1.0 } else { -1.0 };
                    for k in 1..=n {
                        let a = turn * k as f64 * chord / radius;
                        x = cx + radius * a.cos();
                        y = cy + radius * a.sin();
                        writeln!(t, "X{x:.decimals$} Y{y:.decimals$}").unwrap();
                    }
                }
            }
        }
        t + "M2\n"
    }

    #[test]
    fn a_slot_is_filled_once_and_only_when_the_planner_has_let_it_go() {
        let shared = Shared::new(false, false);
        let slots = SLOTS as u64;
        // The worker's view of the planner's `consumed`.
        let mut consumed = 0;
        let fit_at = |window: u64| move |f: &mut super::Filled| f.fit = Some((window, None));
        let fit_of = |index: u64| shared.filled(index, index).map(|f| f.fit.map(|(w, _)| w));

        assert!(fit_of(5).is_none(), "nothing there yet");
        assert!(shared.fill(5, &mut consumed, fit_at(7)));
        assert_eq!(
            fit_of(5),
            Some(Some(7)),
            "the planner reads what was filled"
        );
        assert!(
            !shared.fill(5, &mut consumed, fit_at(8)),
            "a junction's slot is filled once"
        );
        assert_eq!(fit_of(5), Some(Some(7)));
        assert!(
            fit_of(5 + slots).is_none(),
            "the same slot, another junction"
        );

        // Junction 5 + SLOTS reuses junction 5's slot: not while the
        // planner may still read junction 5.
        assert!(!shared.fill(5 + slots, &mut consumed, fit_at(9)));
        assert_eq!(fit_of(5), Some(Some(7)), "what the planner may read stays");
        // The planner lets go of the junctions before 6, in steps.
        let ahead = Ahead::over(std::sync::Arc::new(shared));
        ahead.consume(CONSUMED_STEP - 1);
        assert!(!ahead.shared.fill(5 + slots, &mut consumed, fit_at(9)));
        // Not while it reads a speculation either.
        ahead.reading.set(true);
        ahead.consume(CONSUMED_STEP + 6);
        assert!(!ahead.shared.fill(5 + slots, &mut consumed, fit_at(9)));
        ahead.reading.set(false);
        ahead.consume(CONSUMED_STEP + 6);
        assert!(ahead.shared.fill(5 + slots, &mut consumed, fit_at(9)));
        let fit_of = |index: u64| {
            ahead
                .shared
                .filled(index, index)
                .map(|f| f.fit.map(|(w, _)| w))
        };
        assert_eq!(fit_of(5 + slots), Some(Some(9)));
        assert!(fit_of(5).is_none(), "junction 5 is gone");
    }

    #[test]
    fn the_share_follows_whichever_thread_is_slower() {
        let shared = std::sync::Arc::new(Shared::new(false, false));
        let mut w = Worker::new(shared.clone());
        let share = || shared.share.load(Ordering::Relaxed);
        // period: the planner got to `late` of the worker's junctions
        // first; the worker ran out of moves `idle` times.
        let mut period = |late: u64, idle: u64| {
            w.late = late;
            w.idle = idle;
            w.adapt();
        };
        assert_eq!(share(), FIRST_SHARE);
        period(40, 0);
        assert_eq!(share(), FIRST_SHARE - 1, "the worker was late: less for it");
        period(0, 0);
        assert_eq!(share(), FIRST_SHARE - 1, "busy and in time: as it is");
        period(0, 30);
        assert_eq!(share(), FIRST_SHARE, "idle and in time: more for it");
        period(40, 0);
        assert_eq!(share(), FIRST_SHARE - 1, "too much: back");
        // That raise did not hold, so the next takes two idle periods.
        period(0, 30);
        assert_eq!(share(), FIRST_SHARE - 1);
        period(0, 30);
        assert_eq!(share(), FIRST_SHARE);
        for _ in 0..10 {
            period(0, 30);
        }
        assert_eq!(share(), SHARES.len() - 1, "no larger share than the last");
        for _ in 0..10 {
            period(40, 0);
        }
        assert_eq!(share(), 0, "no smaller share than the first");
    }

    /// LinuxCNC's stellabee1.ngc (beside the repository, as CI has it)
    /// turns between dense curves, corners and fits that fail near them:
    /// a patient worker that takes every junction leaves the planner
    /// hardly any blend to work out itself, and the plan is the same.
    #[test]
    fn the_worker_makes_nearly_every_blend_of_stellabee() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shared/conformance/linuxcnc-programs/tp-stress/performance/stellabee1.ngc"
        );
        let Ok(text) = std::fs::read_to_string(path) else {
            eprintln!("{path} not found: skipped");
            return;
        };
        // Millimetres, into mill3's travel; the first 20,000 lines.
        let body: Vec<&str> = text.lines().take(20_000).collect();
        let text = format!(
            "G21 G10 L2 P1 X100 Y50 Z-20\nG54\n{}\nM2\n",
            body.join("\n")
        );
        let (alone, _) = plan(&text, Helper::None);
        let (helped, t) = plan(&text, Helper::Patient { all: true });
        assert!(alone == helped, "the worker changed the plan");
        eprintln!("stellabee1.ngc, first 20,000 lines: {t:?}");
        assert!(t.taken > 15_000, "{t:?}");
        assert!(t.own as f64 <= 0.02 * t.taken as f64, "{t:?}");
    }

    #[test]
    fn the_blend_worker_changes_no_plan_bit() {
        // A spiral of 0.02 mm chords, to 5 decimals as CAM writes them,
        // with a dwell halfway, then the random programs.
        let mut spiral = String::from("G21 G90 G64 P0.01 Q0 F3000\nG0 X1 Y0\nG1\n");
        let mut theta = 0.0f64;
        for k in 0..4000 {
            let r = 1.0 + 0.08 * theta;
            theta += 0.02 / r;
            let (x, y) = (r * theta.cos(), r * theta.sin());
            writeln!(spiral, "X{x:.5} Y{y:.5}").unwrap();
            if k == 2000 {
                spiral += "G4 P0.5\n";
            }
        }
        spiral += "M2\n";
        let programs = [(spiral, 0.99)]
            .into_iter()
            .chain([3, 17, 29].map(|seed| (program(seed, 60), 0.95)));
        for (seed, (text, share)) in programs.enumerate() {
            let (alone, _) = plan(&text, Helper::None);
            let helpers = [
                Helper::Patient { all: true },
                Helper::Patient { all: false },
                Helper::Worker,
            ];
            for helper in helpers {
                let (helped, t) = plan(&text, helper);
                assert_eq!(
                    alone.len(),
                    helped.len(),
                    "program {seed} {helper:?}: segment count"
                );
                for (k, (a, h)) in alone.iter().zip(&helped).enumerate() {
                    assert_eq!(a, h, "program {seed} {helper:?}: segment {k} differs");
                }
                // The comparison means something only if the planner took
                // the worker's blends (and, at its own junctions, its
                // fits). A patient planner takes every one made from where
                // the blend before really ended: nearly all (the rest
                // follow a blend whose fit failed, and the planner's
                // fallback ended elsewhere).
                if let Helper::Patient { all } = helper {
                    let least = if all { 1000 } else { 600 };
                    assert!(t.looked > least, "program {seed} {helper:?}: {t:?}");
                    assert!(
                        t.taken as f64 >= share * t.looked as f64,
                        "program {seed} {helper:?}: {t:?}"
                    );
                    // Nor does the planner work many out itself: only
                    // those after a blend the worker did not make (since
                    // 2026-11-26 the worker also makes the fit's
                    // fallback, the blend after it, and the blends from a
                    // dense curve into a corner and back).
                    assert!(
                        t.own as f64 <= (1.0 - share) * t.taken as f64,
                        "program {seed} {helper:?}: {t:?}"
                    );
                    if !all {
                        assert!(t.fit_looked > 300, "program {seed}: {t:?}");
                        assert!(
                            t.fitted as f64 >= share * t.fit_looked as f64,
                            "program {seed}: {t:?}"
                        );
                    }
                }
                eprintln!("program {seed} {helper:?}: {t:?}");
            }
        }
    }
}
