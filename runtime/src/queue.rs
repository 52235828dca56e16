//! Bounded lock-free queues between stages. A full queue drops its OLDEST item (the freshest
//! sensor data is what a pose stream needs) and counts it; producers never block on later stages.
//! Items that own buffers are recycled through a [`Pool`] so the steady state allocates nothing.

use crossbeam_queue::ArrayQueue;
use std::sync::atomic::{AtomicU64, Ordering};

/// A bounded queue whose `push` never blocks: when full, the oldest item is displaced, counted
/// and handed back to the producer (to recycle its buffers).
#[derive(Debug)]
pub struct DropOldest<T> {
    q: ArrayQueue<T>,
    pushed: AtomicU64,
    dropped: AtomicU64,
}

impl<T> DropOldest<T> {
    /// A queue of `capacity` items (at least 1).
    pub fn new(capacity: usize) -> Self {
        DropOldest {
            q: ArrayQueue::new(capacity.max(1)),
            pushed: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
        }
    }

    /// Pushes `item`; when the queue is full the oldest item is removed, counted as dropped and
    /// returned.
    pub fn push(&self, item: T) -> Option<T> {
        self.pushed.fetch_add(1, Ordering::Relaxed);
        let displaced = self.q.force_push(item);
        if displaced.is_some() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        displaced
    }

    /// Pushes `item` only if there is room (offline feeders wait instead of dropping); gives it
    /// back when full.
    pub fn try_push(&self, item: T) -> Result<(), T> {
        self.q.push(item)?;
        self.pushed.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Pushes `item` without dropping anything: while the queue is full, waits for the consumer
    /// (spinning briefly, then sleeping 50 us at a time). For offline runs, where every item must
    /// get through and the producer may go at the consumer's pace; live producers use
    /// [`DropOldest::push`].
    pub fn push_wait(&self, mut item: T) {
        let mut tries = 0u32;
        loop {
            match self.try_push(item) {
                Ok(()) => return,
                Err(back) => item = back,
            }
            tries += 1;
            if tries < 64 {
                std::hint::spin_loop();
                std::thread::yield_now();
            } else {
                std::thread::sleep(std::time::Duration::from_micros(50));
            }
        }
    }

    /// The oldest item, if any.
    pub fn pop(&self) -> Option<T> {
        self.q.pop()
    }

    /// Items waiting.
    pub fn len(&self) -> usize {
        self.q.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.q.is_empty()
    }

    /// Capacity.
    pub fn capacity(&self) -> usize {
        self.q.capacity()
    }

    /// Items pushed since creation.
    pub fn pushed(&self) -> u64 {
        self.pushed.load(Ordering::Relaxed)
    }

    /// Items displaced because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// A free list of reusable boxes (radar frames carry a point buffer): the consumer gives items
/// back, the producer takes them before allocating a new one.
#[derive(Debug)]
pub struct Pool<T> {
    free: ArrayQueue<Box<T>>,
    allocated: AtomicU64,
}

impl<T: Default> Pool<T> {
    /// A pool holding up to `capacity` spare items, `prefill` of them allocated now.
    pub fn new(capacity: usize, prefill: usize) -> Self {
        let p = Pool {
            free: ArrayQueue::new(capacity.max(1)),
            allocated: AtomicU64::new(0),
        };
        for _ in 0..prefill.min(capacity) {
            let _ = p.free.push(Box::default());
            p.allocated.fetch_add(1, Ordering::Relaxed);
        }
        p
    }

    /// A spare item, or a new one when the pool is empty.
    pub fn take(&self) -> Box<T> {
        self.free.pop().unwrap_or_else(|| {
            self.allocated.fetch_add(1, Ordering::Relaxed);
            Box::default()
        })
    }

    /// Gives an item back (dropped when the pool is full).
    pub fn give(&self, item: Box<T>) {
        let _ = self.free.push(item);
    }

    /// Items allocated since creation (prefill included).
    pub fn allocated(&self) -> u64 {
        self.allocated.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn push_wait_delivers_everything_in_order_through_a_small_queue() {
        let q = Arc::new(DropOldest::new(2));
        let q2 = Arc::clone(&q);
        let producer = std::thread::spawn(move || {
            for i in 0..500u32 {
                q2.push_wait(i);
            }
        });
        let mut got = Vec::new();
        while got.len() < 500 {
            match q.pop() {
                Some(v) => got.push(v),
                None => std::thread::yield_now(),
            }
        }
        producer.join().unwrap();
        assert_eq!(got, (0..500).collect::<Vec<_>>());
        assert_eq!((q.pushed(), q.dropped()), (500, 0));
    }

    #[test]
    fn full_queue_drops_the_oldest_and_counts_it() {
        let q = DropOldest::new(3);
        for i in 0..3 {
            assert_eq!(q.push(i), None);
        }
        assert_eq!(q.push(3), Some(0));
        assert_eq!(q.push(4), Some(1));
        assert_eq!((q.pushed(), q.dropped()), (5, 2));
        let got: Vec<i32> = std::iter::from_fn(|| q.pop()).collect();
        assert_eq!(got, vec![2, 3, 4]);
        assert_eq!(q.try_push(9), Ok(()));
    }

    #[test]
    fn concurrent_producer_never_blocks_and_every_item_is_delivered_or_counted() {
        const N: u64 = 200_000;
        let q = Arc::new(DropOldest::new(64));
        let qp = Arc::clone(&q);
        let producer = std::thread::spawn(move || {
            let mut displaced = Vec::new();
            for i in 0..N {
                if let Some(old) = qp.push(i) {
                    displaced.push(old);
                }
            }
            displaced
        });
        let mut got = Vec::new();
        let mut done = false;
        while !done {
            done = producer.is_finished();
            while let Some(v) = q.pop() {
                got.push(v);
                if got.len() % 1000 == 0 {
                    // A slow consumer: the queue fills up meanwhile.
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
            }
        }
        let displaced = producer.join().unwrap();
        // Every item arrived exactly once or was displaced exactly once and counted.
        assert_eq!(got.len() as u64 + displaced.len() as u64, N);
        assert_eq!(q.dropped(), displaced.len() as u64);
        assert_eq!(q.pushed(), N);
        assert!(
            q.dropped() > 0,
            "the slow consumer must have made the queue overflow"
        );
        // Delivered items keep their order; the newest item is never the one dropped.
        assert!(got.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(got.last(), Some(&(N - 1)));
        // Displaced items are the oldest at the time: increasing too.
        assert!(displaced.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn pool_recycles_boxes() {
        let p: Pool<Vec<u8>> = Pool::new(4, 2);
        let a = p.take();
        let b = p.take();
        assert_eq!(p.allocated(), 2);
        let c = p.take();
        assert_eq!(p.allocated(), 3);
        p.give(a);
        p.give(b);
        p.give(c);
        let _ = p.take();
        assert_eq!(p.allocated(), 3);
    }
}
