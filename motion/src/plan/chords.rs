//! The programmed lines as the curve fit sees them: chords of the curve a
//! dense program samples, kept field by field so that the fit's walk and
//! sums read each field as a run of numbers, four to an instruction.

use super::{Programmed, FIT_BEND, FIT_REACH, FIT_TURN};

/// A programmed line as the curve fit sees it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Chord {
    pub midpoint: [f64; 3],
    pub direction: [f64; 3],
    pub length: f64,
    /// Path length of the midpoint along the polyline the chord belongs
    /// to, mm, from an origin that only differences cancel.
    pub station: f64,
    /// Whether the polyline is broken between this chord and the one
    /// before it: a bend over [`FIT_BEND`], or either is a
    /// [`Chord::BREAK`].
    pub corner: bool,
}

impl Chord {
    /// Where the polyline the fit may use ends (an arc, or a line that
    /// moves more than X Y Z).
    pub const BREAK: Chord = Chord {
        midpoint: [0.0; 3],
        direction: [0.0; 3],
        length: f64::NAN,
        station: 0.0,
        corner: true,
    };

    pub fn is_break(&self) -> bool {
        self.length.is_nan()
    }

    /// The chord of `p`, following `before` (the chord queued before it).
    pub fn of(p: &Programmed, before: Option<&Chord>) -> Chord {
        let mut chord = Chord {
            midpoint: std::array::from_fn(|i| 0.5 * (p.line.start[i] + p.line.end[i])),
            direction: std::array::from_fn(|i| p.direction[i]),
            length: p.length,
            station: 0.0,
            corner: true,
        };
        if let Some(b) = before.filter(|b| !b.is_break()) {
            chord.corner = b.bend2(&chord) > FIT_BEND * FIT_BEND;
            chord.station = b.station + 0.5 * (b.length + chord.length);
        }
        chord
    }

    /// |u1 − u2|² between the chords' directions.
    pub fn bend2(&self, other: &Chord) -> f64 {
        bend2(&self.direction, &other.direction)
    }
}

/// |b − a|² of two directions, added in the order the vector walk adds
/// them.
fn bend2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d: [f64; 3] = std::array::from_fn(|i| b[i] - a[i]);
    (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]
}

/// Zeros kept after the last chord in every field, so that a fit's last
/// group of four reads numbers (which it weighs zero) rather than past
/// the end.
const PAD: usize = 4;

/// Chords dropped from the front before their storage is moved down.
const COMPACT: usize = 4096;

/// A queue of chords, oldest first, one vector per field.
///
/// Chords are counted from the front (`0` is the oldest); the fields'
/// storage starts `head` earlier, where chords were dropped, and ends
/// with [`PAD`] zeros. Storage is moved down only every [`COMPACT`]
/// chords, so a queue that has grown to its working size allocates no
/// more.
#[derive(Clone, Debug)]
pub(super) struct Chords {
    head: usize,
    pub(super) station: Vec<f64>,
    length: Vec<f64>,
    /// 1 where the chord is a corner, 0 where not.
    corner: Vec<f64>,
    direction: [Vec<f64>; 3],
    pub(super) midpoint: [Vec<f64>; 3],
}

impl Chords {
    pub fn new() -> Chords {
        let padded = || vec![0.0; PAD];
        Chords {
            head: 0,
            station: padded(),
            length: padded(),
            corner: padded(),
            direction: std::array::from_fn(|_| padded()),
            midpoint: std::array::from_fn(|_| padded()),
        }
    }

    pub fn len(&self) -> usize {
        self.station.len() - self.head - PAD
    }

    /// Where chord `k` is kept in the fields.
    pub(super) fn slot(&self, k: usize) -> usize {
        debug_assert!(k < self.len());
        self.head + k
    }

    /// The length every field is kept at: the chords, the ones dropped
    /// before them and [`PAD`] zeros after them. Checked here, once per
    /// caller, so that loads of four numbers from any slot of a chord
    /// need no check of their own.
    pub(super) fn storage(&self) -> usize {
        let storage = self.station.len();
        let fields = [&self.length, &self.corner];
        assert!(
            fields
                .into_iter()
                .chain(&self.direction)
                .chain(&self.midpoint)
                .all(|f| f.len() == storage),
            "the chords' fields are kept at one length"
        );
        storage
    }

    fn fields_mut(&mut self) -> [&mut Vec<f64>; 9] {
        let [d0, d1, d2] = &mut self.direction;
        let [m0, m1, m2] = &mut self.midpoint;
        [
            &mut self.station,
            &mut self.length,
            &mut self.corner,
            d0,
            d1,
            d2,
            m0,
            m1,
            m2,
        ]
    }

    pub fn push_back(&mut self, c: Chord) {
        let at = self.head + self.len();
        let values = [
            c.station,
            c.length,
            if c.corner { 1.0 } else { 0.0 },
            c.direction[0],
            c.direction[1],
            c.direction[2],
            c.midpoint[0],
            c.midpoint[1],
            c.midpoint[2],
        ];
        for (field, value) in self.fields_mut().into_iter().zip(values) {
            // The first pad takes the chord; a new pad follows.
            field[at] = value;
            field.push(0.0);
        }
    }

    /// Drop the `n` oldest chords.
    pub fn drain_front(&mut self, n: usize) {
        assert!(n <= self.len(), "dropping {n} of {} chords", self.len());
        self.head += n;
        if self.head >= COMPACT && self.head >= self.len() {
            let head = self.head;
            for field in self.fields_mut() {
                field.copy_within(head.., 0);
                field.truncate(field.len() - head);
            }
            self.head = 0;
        }
    }

    pub fn pop_front(&mut self) {
        self.drain_front(1);
    }

    /// Chord `k`, whole.
    pub fn get(&self, k: usize) -> Chord {
        let s = self.slot(k);
        Chord {
            midpoint: std::array::from_fn(|i| self.midpoint[i][s]),
            direction: std::array::from_fn(|i| self.direction[i][s]),
            length: self.length[s],
            station: self.station[s],
            corner: self.corner[s] != 0.0,
        }
    }

    pub fn back(&self) -> Option<Chord> {
        self.len().checked_sub(1).map(|k| self.get(k))
    }

    pub fn is_break(&self, k: usize) -> bool {
        self.length[self.slot(k)].is_nan()
    }

    pub fn corner(&self, k: usize) -> bool {
        self.corner[self.slot(k)] != 0.0
    }

    pub fn station(&self, k: usize) -> f64 {
        self.station[self.slot(k)]
    }

    pub fn midpoint(&self, k: usize) -> [f64; 3] {
        let s = self.slot(k);
        std::array::from_fn(|i| self.midpoint[i][s])
    }

    /// Whether the chord kept at `slot` may be in a fit centred on the
    /// chord kept at `centre`: within FIT_REACH of path and FIT_TURN of
    /// turn (its corner flag is the caller's).
    fn within(&self, centre: usize, slot: usize) -> bool {
        let dir = |s: usize| std::array::from_fn(|i| self.direction[i][s]);
        (self.station[slot] - self.station[centre]).abs() + 0.5 * self.length[slot] <= FIT_REACH
            && bend2(&dir(centre), &dir(slot)) <= FIT_TURN * FIT_TURN
    }
}

/// How many chords a fit centred on the midpoint of chord `at` may take
/// on each side, seeing those before `end`: as many as both sides have,
/// up to `most`, before a corner (a bend over FIT_BEND), within FIT_REACH
/// and FIT_TURN of the centre (turn measured as |u − u_centre|, which
/// bounds how far the curve strays from a cubic there).
///
/// Four chords at a time where the processor has AVX
/// ([`fit_side_avx`]): the walk was a sixth of planning a dense curve.
pub(super) fn fit_side(chords: &Chords, at: usize, end: usize, most: usize) -> usize {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the processor supports AVX, checked just above.
        return unsafe { fit_side_avx(chords, at, end, most) };
    }
    fit_side_plain(chords, at, end, most)
}

/// [`fit_side`] one chord at a time: the reference the AVX walk is held to.
fn fit_side_plain(chords: &Chords, at: usize, end: usize, most: usize) -> usize {
    let centre = chords.slot(at);
    let take = |slot: usize| chords.corner[slot] == 0.0 && chords.within(centre, slot);
    let after = (0..most.min(end.saturating_sub(at + 1)))
        .take_while(|&m| take(centre + 1 + m))
        .count();
    // A chord's `corner` is its bend to the one before it: going back,
    // the chord nearer the centre must not be one.
    (0..after.min(at))
        .take_while(|&m| {
            let slot = centre - 1 - m;
            chords.corner[slot + 1] == 0.0 && chords.within(centre, slot)
        })
        .count()
}

/// [`fit_side`] four chords at a time: each test in the same operations
/// as [`fit_side_plain`]'s, so the same count.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn fit_side_avx(chords: &Chords, at: usize, end: usize, most: usize) -> usize {
    use std::arch::x86_64::*;
    let centre = chords.slot(at);
    // The loads below read four chords from a slot between the first
    // chord and the last one's, within the fields and their PAD ≥ 3.
    let fields = chords.storage();
    macro_rules! load {
        ($field:expr, $slot:expr) => {{
            let slot: usize = $slot;
            debug_assert!(slot >= chords.head && slot + 4 <= fields);
            // SAFETY: `slot` is at a chord's, so slot + 3 is within the
            // chords and their PAD (asserted above).
            unsafe { _mm256_loadu_pd($field.as_ptr().add(slot)) }
        }};
    }
    let sign = _mm256_set1_pd(-0.0);
    let half = _mm256_set1_pd(0.5);
    let reach = _mm256_set1_pd(FIT_REACH);
    let turn = _mm256_set1_pd(FIT_TURN * FIT_TURN);
    let zero = _mm256_setzero_pd();
    let station = _mm256_set1_pd(chords.station[centre]);
    let dir: [__m256d; 3] = [
        _mm256_set1_pd(chords.direction[0][centre]),
        _mm256_set1_pd(chords.direction[1][centre]),
        _mm256_set1_pd(chords.direction[2][centre]),
    ];
    // Which of the four chords kept from `slot` are within reach and turn
    // and not corners (the corner flags kept from `flags`), as bits. (A
    // macro, not a closure: a closure would not inherit this function's
    // AVX.)
    macro_rules! tests {
        ($slot:expr, $flags:expr) => {{
            let (slot, flags) = ($slot, $flags);
            let gap = _mm256_andnot_pd(sign, _mm256_sub_pd(load!(chords.station, slot), station));
            let span = _mm256_add_pd(gap, _mm256_mul_pd(half, load!(chords.length, slot)));
            let d: [__m256d; 3] = [
                _mm256_sub_pd(load!(chords.direction[0], slot), dir[0]),
                _mm256_sub_pd(load!(chords.direction[1], slot), dir[1]),
                _mm256_sub_pd(load!(chords.direction[2], slot), dir[2]),
            ];
            let bend = _mm256_add_pd(
                _mm256_add_pd(_mm256_mul_pd(d[0], d[0]), _mm256_mul_pd(d[1], d[1])),
                _mm256_mul_pd(d[2], d[2]),
            );
            let ok = _mm256_and_pd(
                _mm256_and_pd(
                    _mm256_cmp_pd::<_CMP_LE_OQ>(span, reach),
                    _mm256_cmp_pd::<_CMP_LE_OQ>(bend, turn),
                ),
                _mm256_cmp_pd::<_CMP_EQ_OQ>(load!(chords.corner, flags), zero),
            );
            _mm256_movemask_pd(ok)
        }};
    }
    let take =
        |slot: usize, flags: usize| chords.corner[flags] == 0.0 && chords.within(centre, slot);
    // After the centre: lane k is chord m + k.
    let ahead = most.min(end.saturating_sub(at + 1));
    let mut after = 0;
    loop {
        if after + 4 <= ahead {
            let slot = centre + 1 + after;
            let bits = tests!(slot, slot);
            after += bits.trailing_ones() as usize;
            if bits != 0b1111 {
                break;
            }
        } else {
            while after < ahead && take(centre + 1 + after, centre + 1 + after) {
                after += 1;
            }
            break;
        }
    }
    // Before it, nearest first: lane 3 is chord m back, lane 0 chord m + 3.
    let behind = after.min(at);
    let mut side = 0;
    loop {
        if side + 4 <= behind {
            let slot = centre - side - 4;
            let bits = tests!(slot, slot + 1);
            let nearest = ((bits as u8) << 4).leading_ones() as usize;
            side += nearest;
            if nearest < 4 {
                break;
            }
        } else {
            while side < behind && take(centre - 1 - side, centre - side) {
                side += 1;
            }
            break;
        }
    }
    side
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::path::Line;
    use crate::testkit::uniform;

    /// Random chords: short ones and a few long, turning a little and
    /// sometimes a lot, with breaks.
    pub(in crate::plan) fn random_chords(seed: u64, n: usize) -> Chords {
        let mut rand = uniform(seed);
        let mut chords = Chords::new();
        let (mut p, mut heading) = ([0.0f64; 3], 0.0f64);
        for k in 0..n {
            if k % 700 == 350 {
                chords.push_back(Chord::BREAK);
                continue;
            }
            let length = if rand() < 0.05 {
                0.2 * rand()
            } else {
                0.01 + 0.03 * rand()
            };
            heading += if rand() < 0.02 {
                0.3
            } else {
                0.04 * (rand() - 0.5)
            };
            let direction = [heading.cos(), heading.sin(), 0.1 * (rand() - 0.5)];
            let end: [f64; 3] = std::array::from_fn(|i| p[i] + length * direction[i]);
            let line = Line {
                start: std::array::from_fn(|i| if i < 3 { p[i] } else { 0.0 }),
                end: std::array::from_fn(|i| if i < 3 { end[i] } else { 0.0 }),
            };
            chords.push_back(Chord::of(&Programmed::new(line), chords.back().as_ref()));
            p = end;
        }
        chords
    }

    #[test]
    fn a_queue_gives_back_the_chords_it_was_given() {
        let mut chords = Chords::new();
        let mut kept = std::collections::VecDeque::new();
        let mut rand = uniform(5);
        let mut compactions = 0;
        // Long enough to move its storage down several times.
        for n in 0..20_000 {
            let c = Chord {
                midpoint: [n as f64, rand(), -rand()],
                direction: [rand(), 0.5, rand()],
                length: if n % 97 == 0 { f64::NAN } else { rand() },
                station: n as f64 * 0.5,
                corner: n % 3 == 0,
            };
            chords.push_back(c);
            kept.push_back(c);
            // A queue that grows to a working size, then drops about as
            // many as it takes, by ones, twos and runs.
            let drop = if kept.len() > 300 {
                1 + (rand() < 0.1) as usize
            } else if rand() < 0.3 {
                (rand() * 3.0) as usize
            } else {
                0
            };
            let drop = drop.min(kept.len());
            let head = chords.head;
            chords.drain_front(drop);
            kept.drain(..drop);
            compactions += (chords.head < head) as usize;
            assert_eq!(chords.len(), kept.len());
            // Every field at one length, within a compaction's worth.
            assert!(chords.storage() <= COMPACT.max(kept.len()) + kept.len() + PAD);
        }
        assert!(compactions >= 3, "{compactions} compactions");
        let same = |a: &Chord, b: &Chord| format!("{a:?}") == format!("{b:?}");
        for (k, c) in kept.iter().enumerate() {
            assert!(same(&chords.get(k), c), "chord {k}");
            assert_eq!(chords.is_break(k), c.is_break());
        }
        assert!(same(&chords.back().unwrap(), kept.back().unwrap()));
    }

    #[test]
    fn the_avx_walk_takes_the_chords_the_plain_one_takes() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            let chords = random_chords(11, 3000);
            let mut sides = [0usize; 3];
            for at in 0..chords.len() {
                for end in [chords.len(), (at + 3).min(chords.len()), at + 1] {
                    for most in [1, 3, 48, 50] {
                        let plain = fit_side_plain(&chords, at, end, most);
                        // SAFETY: the processor supports AVX, checked above.
                        let avx = unsafe { fit_side_avx(&chords, at, end, most) };
                        assert_eq!(plain, avx, "at {at}, end {end}, most {most}");
                        sides[plain.min(2)] += 1;
                    }
                }
            }
            // Windows of every kind: none, short, long.
            assert!(sides.iter().all(|&n| n > 1000), "{sides:?}");
        }
    }
}
