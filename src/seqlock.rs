//! A single-writer sequence lock for publishing the servo status snapshot.
//!
//! The servo thread writes a `Copy` snapshot every tick without ever
//! waiting; readers copy it out and retry if a write overlapped their read.
//! Nothing here allocates or blocks the writer.

use std::cell::UnsafeCell;
use std::sync::atomic::{fence, AtomicU64, Ordering};
use std::sync::Arc;

struct Shared<T> {
    seq: AtomicU64,
    data: UnsafeCell<T>,
}

// SAFETY: the data is only written by the one `Writer` and read by copying
// under the sequence protocol; `T: Copy` means a torn read is discarded
// without ever being used.
unsafe impl<T: Copy + Send> Sync for Shared<T> {}

/// The one writer of a seqlock. Not `Clone`: there is exactly one.
pub struct Writer<T> {
    shared: Arc<Shared<T>>,
}

/// A reader of a seqlock; clone freely.
pub struct Reader<T> {
    shared: Arc<Shared<T>>,
}

impl<T> Clone for Reader<T> {
    fn clone(&self) -> Self {
        Reader {
            shared: self.shared.clone(),
        }
    }
}

/// A seqlock holding `initial`, as its writer and a reader.
pub fn seqlock<T: Copy + Send>(initial: T) -> (Writer<T>, Reader<T>) {
    let shared = Arc::new(Shared {
        seq: AtomicU64::new(0),
        data: UnsafeCell::new(initial),
    });
    (
        Writer {
            shared: shared.clone(),
        },
        Reader { shared },
    )
}

impl<T: Copy + Send> Writer<T> {
    /// Publish a new value. Wait-free.
    pub fn write(&mut self, value: &T) {
        let s = self.shared.seq.load(Ordering::Relaxed);
        self.shared.seq.store(s.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        // SAFETY: only this writer writes; readers discard reads that overlap
        // an odd sequence or a change of sequence.
        unsafe { std::ptr::write_volatile(self.shared.data.get(), *value) };
        self.shared.seq.store(s.wrapping_add(2), Ordering::Release);
    }
}

impl<T: Copy + Send> Reader<T> {
    /// Copy out the latest complete value.
    pub fn read(&self) -> T {
        loop {
            let before = self.shared.seq.load(Ordering::Acquire);
            if before & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            // SAFETY: see `Writer::write`; a torn copy is detected below and dropped.
            let value = unsafe { std::ptr::read_volatile(self.shared.data.get()) };
            fence(Ordering::Acquire);
            if self.shared.seq.load(Ordering::Relaxed) == before {
                return value;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readers_never_see_a_torn_value() {
        // The writer keeps every element of the array equal; a torn read
        // would show two different elements.
        let (mut w, r) = seqlock([0u64; 16]);
        let reader = std::thread::spawn(move || {
            let mut last = 0;
            for _ in 0..200_000 {
                let v = r.read();
                assert!(v.iter().all(|&x| x == v[0]), "torn read {v:?}");
                assert!(v[0] >= last, "went backwards");
                last = v[0];
            }
        });
        for i in 1..=200_000u64 {
            w.write(&[i; 16]);
        }
        reader.join().unwrap();
    }
}
