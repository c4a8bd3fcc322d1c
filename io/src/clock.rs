//! Host clocks. Backend I/O threads read time only through [`Clock`], so
//! tests and offline simulation can run them on a [`VirtualClock`].

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// A monotonic host clock in nanoseconds. Backend threads read time only
/// through this, so tests can run them on a virtual clock.
pub trait Clock: Send + Sync {
    /// Nanoseconds since an arbitrary origin; never decreases.
    fn now_ns(&self) -> u64;
}

/// `CLOCK_MONOTONIC`.
#[derive(Clone, Copy, Debug, Default)]
pub struct Monotonic;

impl Clock for Monotonic {
    fn now_ns(&self) -> u64 {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists.
        unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
        ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
    }
}

/// A clock that moves only when told: deterministic tests and offline
/// simulation.
#[derive(Clone, Debug, Default)]
pub struct VirtualClock(Arc<AtomicU64>);

impl VirtualClock {
    /// A virtual clock at `ns`.
    pub fn at(ns: u64) -> VirtualClock {
        VirtualClock(Arc::new(AtomicU64::new(ns)))
    }

    /// Move the clock forward by `ns`.
    pub fn advance(&self, ns: u64) {
        self.0.fetch_add(ns, Ordering::SeqCst);
    }
}

impl Clock for VirtualClock {
    fn now_ns(&self) -> u64 {
        self.0.load(Ordering::SeqCst)
    }
}
