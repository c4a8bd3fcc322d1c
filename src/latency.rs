//! Wake-up latency of the servo thread: how late after its deadline each
//! tick started.
//!
//! A fixed histogram (no allocation after construction, O(1) per sample)
//! with 1 µs buckets up to 1 ms, 10 µs buckets up to 10 ms, and one bucket
//! for anything later; the exact minimum and maximum are kept besides.
//! Percentiles are the upper edge of the bucket they fall in, so they are
//! at most 1 µs high below 1 ms (10 µs up to 10 ms).

/// Fine buckets: 1 µs each, [0, 1 ms).
const FINE: usize = 1000;
/// Coarse buckets: 10 µs each, [1 ms, 10 ms).
const COARSE: usize = 900;
/// Buckets in all: fine, coarse, and one for 10 ms and later.
const BUCKETS: usize = FINE + COARSE + 1;

/// Summary of the wake-up latencies seen, ns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LatencyStats {
    /// Wake-ups measured.
    pub samples: u64,
    /// Smallest, exact.
    pub min_ns: u64,
    /// 50th percentile (upper edge of its bucket).
    pub median_ns: u64,
    /// 99th percentile.
    pub p99_ns: u64,
    /// 99.9th percentile.
    pub p999_ns: u64,
    /// Largest, exact.
    pub max_ns: u64,
}

/// The histogram.
#[derive(Clone, Debug)]
pub struct LatencyHistogram {
    counts: Box<[u64; BUCKETS]>,
    samples: u64,
    min: u64,
    max: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        LatencyHistogram {
            counts: Box::new([0; BUCKETS]),
            samples: 0,
            min: u64::MAX,
            max: 0,
        }
    }
}

fn bucket(ns: u64) -> usize {
    let us = ns / 1000;
    if us < FINE as u64 {
        us as usize
    } else if us < 10_000 {
        FINE + ((us - FINE as u64) / 10) as usize
    } else {
        BUCKETS - 1
    }
}

/// Upper edge of bucket `b`, ns.
fn upper_edge(b: usize) -> u64 {
    if b < FINE {
        (b as u64 + 1) * 1000
    } else if b < FINE + COARSE {
        (FINE as u64 + (b - FINE) as u64 * 10 + 10) * 1000
    } else {
        u64::MAX
    }
}

impl LatencyHistogram {
    /// Count one wake-up `ns` late.
    pub fn record(&mut self, ns: u64) {
        self.counts[bucket(ns)] += 1;
        self.samples += 1;
        self.min = self.min.min(ns);
        self.max = self.max.max(ns);
    }

    /// Minimum, median, 99th and 99.9th percentile and maximum.
    pub fn stats(&self) -> LatencyStats {
        if self.samples == 0 {
            return LatencyStats::default();
        }
        // The smallest latency with at least `q` of the samples at or below it.
        let quantile = |q: f64| {
            let rank = ((q * self.samples as f64).ceil() as u64).max(1);
            let mut seen = 0;
            for (b, &c) in self.counts.iter().enumerate() {
                seen += c;
                if seen >= rank {
                    return upper_edge(b).clamp(self.min, self.max);
                }
            }
            self.max
        };
        LatencyStats {
            samples: self.samples,
            min_ns: self.min,
            median_ns: quantile(0.5),
            p99_ns: quantile(0.99),
            p999_ns: quantile(0.999),
            max_ns: self.max,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_match_the_sorted_samples_within_a_bucket() {
        // A spread of latencies over all three bucket sizes, from a fixed
        // sequence (a linear congruential generator).
        let mut h = LatencyHistogram::default();
        let mut samples = Vec::new();
        let mut x: u64 = 12345;
        for _ in 0..100_000 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = (x >> 33) % 1000;
            let ns = match r {
                0..=900 => (x >> 20) % 60_000,              // mostly under 60 µs
                901..=995 => 100_000 + (x >> 20) % 800_000, // some up to 0.9 ms
                _ => 1_000_000 + (x >> 20) % 20_000_000,    // a few up to 21 ms
            };
            h.record(ns);
            samples.push(ns);
        }
        samples.sort_unstable();
        let exact = |q: f64| samples[((q * samples.len() as f64).ceil() as usize).max(1) - 1];
        let s = h.stats();
        assert_eq!(s.samples, 100_000);
        assert_eq!(s.min_ns, samples[0]);
        assert_eq!(s.max_ns, *samples.last().unwrap());
        for (got, q) in [(s.median_ns, 0.5), (s.p99_ns, 0.99), (s.p999_ns, 0.999)] {
            let want = exact(q);
            let width = if want < 1_000_000 {
                1000
            } else if want < 10_000_000 {
                10_000
            } else {
                u64::MAX
            };
            // At or above the true percentile, by less than one bucket.
            assert!(got >= want && got - want <= width, "q {q}: {got} vs {want}");
        }
    }

    #[test]
    fn empty_and_single() {
        assert_eq!(LatencyHistogram::default().stats(), LatencyStats::default());
        let mut h = LatencyHistogram::default();
        h.record(42_500);
        let s = h.stats();
        assert_eq!(
            (s.min_ns, s.median_ns, s.p999_ns, s.max_ns),
            (42_500, 42_500, 42_500, 42_500)
        );
    }
}
