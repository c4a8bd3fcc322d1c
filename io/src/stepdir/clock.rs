//! The host ↔ MCU clock estimate (and the host clocks, re-exported).

pub use crate::clock::{Clock, Monotonic, VirtualClock};

/// Estimate of the MCU clock as a function of host time, from clock
/// request/reply pairs.
///
/// Each sample pairs the MCU clock with the middle of the request's round
/// trip. The offset comes from the latest sample; the rate from the
/// oldest and newest samples in a window once they are far enough apart
/// to beat the round-trip jitter, else the nominal frequency.
#[derive(Clone, Debug)]
pub struct ClockEstimate {
    nominal: f64,
    /// Ticks per host nanosecond.
    rate: f64,
    anchor: Option<(u64, u64)>,
    base: Option<(u64, u64)>,
}

/// Shortest host-time baseline (ns) before the measured rate replaces the
/// nominal one: 0.2 s, so 50 µs of round-trip jitter is 250 ppm at worst.
const RATE_BASELINE_NS: u64 = 200_000_000;
/// Longest baseline kept, so the rate follows slow drift (temperature).
const RATE_WINDOW_NS: u64 = 30_000_000_000;
/// A measured rate further than this from nominal means a broken link or
/// MCU, not a crystal: 1000 ppm.
pub const MAX_RATE_ERROR: f64 = 1e-3;

impl ClockEstimate {
    /// An estimate for an MCU whose clock runs at `clock_hz`.
    pub fn new(clock_hz: u32) -> ClockEstimate {
        let nominal = clock_hz as f64 * 1e-9;
        ClockEstimate {
            nominal,
            rate: nominal,
            anchor: None,
            base: None,
        }
    }

    /// Add a sample: request sent at host `sent_ns`, reply read at
    /// `received_ns`, MCU clock `mcu`. Returns false if the implied rate is
    /// implausible (more than [`MAX_RATE_ERROR`] from nominal).
    pub fn sample(&mut self, sent_ns: u64, received_ns: u64, mcu: u64) -> bool {
        let host = sent_ns + (received_ns.saturating_sub(sent_ns)) / 2;
        let base = *self.base.get_or_insert((host, mcu));
        if host.saturating_sub(base.0) >= RATE_BASELINE_NS {
            let rate = (mcu as f64 - base.1 as f64) / (host - base.0) as f64;
            if (rate / self.nominal - 1.0).abs() > MAX_RATE_ERROR {
                return false;
            }
            self.rate = rate;
            if host - base.0 > RATE_WINDOW_NS {
                self.base = self.anchor;
            }
        }
        self.anchor = Some((host, mcu));
        true
    }

    /// Whether a sample has been taken.
    pub fn ready(&self) -> bool {
        self.anchor.is_some()
    }

    /// Estimated MCU ticks per host nanosecond.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Estimated MCU clock at host time `ns`.
    pub fn mcu_at(&self, ns: u64) -> f64 {
        match self.anchor {
            Some((h, m)) => m as f64 + (ns as f64 - h as f64) * self.rate,
            None => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimate_tracks_offset_and_rate() {
        // MCU at 10 MHz running 80 ppm fast, offset 12345 ticks.
        let mcu = |ns: u64| 12_345 + (ns as f64 * 0.01 * (1.0 + 80e-6)) as u64;
        let mut e = ClockEstimate::new(10_000_000);
        for k in 0..40u64 {
            let sent = k * 10_000_000;
            let rtt = 200_000 + (k * 7919 % 50) * 1000; // 200-250 µs
            assert!(e.sample(sent, sent + rtt, mcu(sent + rtt / 2)));
        }
        let ppm = (e.rate() / 0.01 - 1.0) * 1e6;
        assert!((ppm - 80.0).abs() < 1.0, "rate off by {ppm} ppm");
        let at = 500_000_000;
        assert!((e.mcu_at(at) - mcu(at) as f64).abs() < 2.0);
        // A sample implying a 2000 ppm clock is refused.
        assert!(!e.sample(800_000_000, 800_000_000, mcu(800_000_000) + 1_000_000));
    }
}
