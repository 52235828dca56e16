//! Single-producer single-consumer rings shared between a receive interrupt (producer) and the
//! main loop (consumer), without locks: the producer owns `head`, the consumer `tail`, both
//! free-running u32 counters (`N` a power of two).

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

/// Receive-interrupt stamps: (bytes received so far, timer ticks) per interrupt.
pub struct StampRing<const N: usize> {
    ends: UnsafeCell<[u32; N]>,
    ticks: UnsafeCell<[u64; N]>,
    head: AtomicU32,
    tail: AtomicU32,
    merged: AtomicU32,
}

// SAFETY: as for `Ring`; the only write to a published slot is the producer's merge into the
// newest slot, which the consumer reads only when it is also the oldest (checked in `find`).
unsafe impl<const N: usize> Sync for StampRing<N> {}

impl<const N: usize> StampRing<N> {
    const MASK: u32 = {
        assert!(N.is_power_of_two() && N >= 2);
        N as u32 - 1
    };

    /// Empty.
    pub const fn new() -> Self {
        StampRing {
            ends: UnsafeCell::new([0; N]),
            ticks: UnsafeCell::new([0; N]),
            head: AtomicU32::new(0),
            tail: AtomicU32::new(0),
            merged: AtomicU32::new(0),
        }
    }

    /// Producer (interrupt): bytes `..end` were received by `ticks`. A full ring merges into the
    /// newest stamp (those bytes get the later time; counted).
    #[inline(always)]
    pub fn push(&self, end: u32, ticks: u64) {
        let head = self.head.load(Ordering::Relaxed);
        let used = head.wrapping_sub(self.tail.load(Ordering::Acquire));
        let (slot, publish) = if (used as usize) < N {
            (head, true)
        } else {
            self.merged.fetch_add(1, Ordering::Relaxed);
            (head.wrapping_sub(1), false)
        };
        let i = (slot & Self::MASK) as usize;
        // SAFETY: see the Sync impl.
        unsafe {
            (*self.ends.get())[i] = end;
            (*self.ticks.get())[i] = ticks;
        }
        if publish {
            self.head.store(head.wrapping_add(1), Ordering::Release);
        }
    }

    /// Consumer: the time of the interrupt that received byte `end - 1`; older stamps are
    /// released. Called with non-decreasing `end`.
    pub fn find(&self, end: u32) -> Option<u64> {
        loop {
            let head = self.head.load(Ordering::Acquire);
            let tail = self.tail.load(Ordering::Relaxed);
            if head == tail {
                return None;
            }
            let i = (tail & Self::MASK) as usize;
            let (e, t) = cortex_m::interrupt::free(|_| {
                // SAFETY: published slot; read with interrupts off so a merge cannot tear it.
                unsafe { ((*self.ends.get())[i], (*self.ticks.get())[i]) }
            });
            if (e.wrapping_sub(end) as i32) >= 0 {
                return Some(t);
            }
            self.tail.store(tail.wrapping_add(1), Ordering::Release);
        }
    }

    /// Stamps merged because the ring was full.
    pub fn merged(&self) -> u32 {
        self.merged.load(Ordering::Relaxed)
    }
}
