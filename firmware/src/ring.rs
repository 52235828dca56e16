//! Single-producer single-consumer rings shared between a receive interrupt (producer) and the
//! main loop (consumer), without locks: the producer owns `head`, the consumer `tail`, both
//! free-running u32 counters (`N` a power of two).
//!
//! Hardware-free (the one critical section is `crate::hw::critical`), so the host tests compile
//! this file unchanged: `tests/tests/firmware_rings.rs`.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU32, Ordering};

/// A byte ring.
pub struct Ring<const N: usize> {
    buf: UnsafeCell<[u8; N]>,
    head: AtomicU32,
    tail: AtomicU32,
    high: AtomicU32,
}

// SAFETY: one producer context writes `buf[head]` then publishes `head`; one consumer reads
// `buf[tail..head]` then publishes `tail`. A slot is never written while readable.
unsafe impl<const N: usize> Sync for Ring<N> {}

impl<const N: usize> Ring<N> {
    const MASK: u32 = {
        assert!(N.is_power_of_two());
        N as u32 - 1
    };

    /// An empty ring.
    pub const fn new() -> Self {
        Ring {
            buf: UnsafeCell::new([0; N]),
            head: AtomicU32::new(0),
            tail: AtomicU32::new(0),
            high: AtomicU32::new(0),
        }
    }

    /// Producer: appends a byte; false (nothing written) when full.
    #[inline(always)]
    pub fn push(&self, b: u8) -> bool {
        let head = self.head.load(Ordering::Relaxed);
        let used = head.wrapping_sub(self.tail.load(Ordering::Acquire));
        if used as usize >= N {
            return false;
        }
        // SAFETY: the slot at `head` is outside the readable range (see the Sync impl).
        unsafe { (*self.buf.get())[(head & Self::MASK) as usize] = b };
        self.head.store(head.wrapping_add(1), Ordering::Release);
        if used + 1 > self.high.load(Ordering::Relaxed) {
            self.high.store(used + 1, Ordering::Relaxed);
        }
        true
    }

    /// Bytes ever pushed (wrapping).
    #[inline(always)]
    pub fn written(&self) -> u32 {
        self.head.load(Ordering::Relaxed)
    }

    /// Consumer: free space \[B\].
    pub fn free(&self) -> usize {
        N - self
            .head
            .load(Ordering::Acquire)
            .wrapping_sub(self.tail.load(Ordering::Relaxed)) as usize
    }

    /// Consumer: the readable bytes up to the end of the storage (the rest, after wrapping, comes
    /// with the next call).
    pub fn readable(&self) -> &[u8] {
        let head = self.head.load(Ordering::Acquire);
        let tail = self.tail.load(Ordering::Relaxed);
        let used = head.wrapping_sub(tail) as usize;
        let start = (tail & Self::MASK) as usize;
        let n = used.min(N - start);
        // SAFETY: `tail..tail + n` is published by the producer and not rewritten until
        // `consume` moves `tail` past it.
        unsafe { &(&*self.buf.get())[start..start + n] }
    }

    /// Consumer: releases `n` bytes read through [`readable`](Self::readable).
    pub fn consume(&self, n: usize) {
        let tail = self.tail.load(Ordering::Relaxed);
        self.tail
            .store(tail.wrapping_add(n as u32), Ordering::Release);
    }

    /// Highest fill seen \[B\].
    pub fn high_water(&self) -> u32 {
        self.high.load(Ordering::Relaxed)
    }
}

/// Receive-interrupt stamps: (bytes received so far, timer ticks) per interrupt. The receive
/// interrupt pushes; the main loop reads and prunes inside critical sections, so the two never
/// interleave (the sensor interrupts share one priority and do not preempt each other).
pub struct StampRing<const N: usize> {
    inner: UnsafeCell<Stamps<N>>,
    merged: AtomicU32,
}

struct Stamps<const N: usize> {
    ends: [u32; N],
    ticks: [u64; N],
    head: u32,
    tail: u32,
}

// SAFETY: see the type's documentation: every access is exclusive (interrupt context, or the
// main loop with interrupts masked).
unsafe impl<const N: usize> Sync for StampRing<N> {}

impl<const N: usize> StampRing<N> {
    const MASK: u32 = {
        assert!(N.is_power_of_two() && N >= 2);
        N as u32 - 1
    };

    /// Empty.
    pub const fn new() -> Self {
        StampRing {
            inner: UnsafeCell::new(Stamps {
                ends: [0; N],
                ticks: [0; N],
                head: 0,
                tail: 0,
            }),
            merged: AtomicU32::new(0),
        }
    }

    /// Producer (receive interrupt only): bytes `..end` were received by `ticks`. A full ring
    /// gives up its oldest stamp (its bytes then carry the next one's, later, time; counted):
    /// the newest stamps, where frames end, stay exact.
    #[inline(always)]
    pub fn push(&self, end: u32, ticks: u64) {
        // SAFETY: interrupt context; the main loop touches the ring only with interrupts masked.
        let s = unsafe { &mut *self.inner.get() };
        if s.head.wrapping_sub(s.tail) as usize >= N {
            s.tail = s.tail.wrapping_add(1);
            self.merged.fetch_add(1, Ordering::Relaxed);
        }
        let i = (s.head & Self::MASK) as usize;
        s.ends[i] = end;
        s.ticks[i] = ticks;
        s.head = s.head.wrapping_add(1);
    }

    /// Consumer: the time of the interrupt that received byte `end - 1`, releasing the stamps of
    /// earlier bytes. Called with non-decreasing `end`.
    pub fn find(&self, end: u32) -> Option<u64> {
        crate::hw::critical(|| {
            // SAFETY: interrupts are masked: no producer runs.
            let s = unsafe { &mut *self.inner.get() };
            while s.head != s.tail {
                let i = (s.tail & Self::MASK) as usize;
                if (s.ends[i].wrapping_sub(end) as i32) >= 0 {
                    return Some(s.ticks[i]);
                }
                s.tail = s.tail.wrapping_add(1);
            }
            None
        })
    }

    /// Consumer: releases the stamps of bytes before `end` (no later frame can end there).
    pub fn prune(&self, end: u32) {
        let _ = self.find(end.wrapping_add(1));
    }

    /// Stamps given up because the ring was full.
    pub fn merged(&self) -> u32 {
        self.merged.load(Ordering::Relaxed)
    }
}
