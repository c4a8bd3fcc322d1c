//! A latched [`HalFault`] shared between a backend's I/O thread and the
//! servo tick without locks.

use std::sync::atomic::{AtomicPtr, AtomicU8, AtomicUsize, Ordering};

use crate::HalFault;

const EMPTY: u8 = 0;
const WRITING: u8 = 1;
const SET: u8 = 2;

/// Holds the first fault raised until it is cleared. Writers race with a
/// compare-and-swap (the first fault wins, later ones are the consequence);
/// the reader sees either nothing or a complete fault.
#[derive(Debug, Default)]
pub(crate) struct FaultCell {
    state: AtomicU8,
    drive: AtomicU8,
    joint: AtomicUsize,
    reason_ptr: AtomicPtr<u8>,
    reason_len: AtomicUsize,
}

impl FaultCell {
    /// Latch `fault` unless one is latched already.
    pub fn raise(&self, fault: HalFault) {
        if self
            .state
            .compare_exchange(EMPTY, WRITING, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            return;
        }
        let (drive, joint, reason) = match fault {
            HalFault::Link { reason } => (0, 0, reason),
            HalFault::Drive { joint, reason } => (1, joint, reason),
        };
        self.drive.store(drive, Ordering::Relaxed);
        self.joint.store(joint, Ordering::Relaxed);
        self.reason_ptr
            .store(reason.as_ptr() as *mut u8, Ordering::Relaxed);
        self.reason_len.store(reason.len(), Ordering::Relaxed);
        self.state.store(SET, Ordering::Release);
    }

    /// The latched fault, if any. Does not allocate or block.
    pub fn get(&self) -> Option<HalFault> {
        if self.state.load(Ordering::Acquire) != SET {
            return None;
        }
        let ptr = self.reason_ptr.load(Ordering::Relaxed);
        let len = self.reason_len.load(Ordering::Relaxed);
        // SAFETY: ptr and len were taken from a `&'static str` in `raise`
        // and published before `SET` with release ordering.
        let reason: &'static str =
            unsafe { std::str::from_utf8_unchecked(std::slice::from_raw_parts(ptr, len)) };
        Some(if self.drive.load(Ordering::Relaxed) == 1 {
            HalFault::Drive {
                joint: self.joint.load(Ordering::Relaxed),
                reason,
            }
        } else {
            HalFault::Link { reason }
        })
    }

    /// Forget the latched fault (the operator's reset); a fault that
    /// still stands is raised again by whoever detects it.
    pub fn clear(&self) {
        self.state.store(EMPTY, Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_fault_wins() {
        let cell = FaultCell::default();
        assert_eq!(cell.get(), None);
        cell.raise(HalFault::Drive {
            joint: 4,
            reason: "overcurrent",
        });
        cell.raise(HalFault::Link { reason: "later" });
        assert_eq!(
            cell.get(),
            Some(HalFault::Drive {
                joint: 4,
                reason: "overcurrent"
            })
        );
    }
}
