//! The sensor hub's receive rings (`firmware/src/ring.rs`, compiled here unchanged) on the host:
//! what QEMU cannot show. A full byte ring refuses the byte (the receive interrupt counts it as
//! overflow) and never blocks; a full stamp ring gives up its oldest stamp (counted) and keeps the
//! newest; a frame gets the stamp of the interrupt that received its last byte, also across the
//! u32 wrap of the byte counters; producer and consumer on two threads lose or reorder nothing.
// The rings' own unsafe code (UnsafeCell slots published by atomics), exactly as the firmware
// builds it.
#![allow(unsafe_code)]

/// The firmware's `hw::critical` without interrupts to mask: the host tests call the consumer and
/// the producer of a stamp ring from one thread.
mod hw {
    pub fn critical<R>(f: impl FnOnce() -> R) -> R {
        f()
    }
}

#[path = "../../firmware/src/ring.rs"]
#[allow(dead_code, missing_debug_implementations)]
mod ring;

use ring::{Ring, StampRing};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

#[test]
fn a_full_byte_ring_refuses_bytes_and_keeps_what_it_holds_in_order() {
    let r: Ring<8> = Ring::new();
    for b in 0..8u8 {
        assert!(r.push(b));
    }
    // Full: refused (the interrupt counts these as ring_overflow), nothing overwritten.
    assert!(!r.push(100));
    assert!(!r.push(101));
    assert_eq!(r.written(), 8, "refused bytes are not counted as received");
    assert_eq!((r.free(), r.high_water()), (0, 8));
    assert_eq!(r.readable(), &[0, 1, 2, 3, 4, 5, 6, 7]);
    r.consume(5);
    assert_eq!(r.free(), 5);
    for b in 8..13u8 {
        assert!(r.push(b));
    }
    // Across the end of the storage: the tail first, the wrapped part with the next call.
    let mut got = Vec::new();
    while !r.readable().is_empty() {
        let n = r.readable().len();
        got.extend_from_slice(r.readable());
        r.consume(n);
    }
    assert_eq!(got, [5, 6, 7, 8, 9, 10, 11, 12]);
    assert_eq!(r.high_water(), 8);
}

#[test]
fn a_frame_gets_the_stamp_of_the_interrupt_that_received_its_last_byte() {
    let s: StampRing<8> = StampRing::new();
    // Three receive interrupts: bytes ..3 by tick 100, ..8 by 200, ..12 by 300.
    s.push(3, 100);
    s.push(8, 200);
    s.push(12, 300);
    // A frame of bytes 0..3 ends in the first batch; one ending at byte 4 (index 3) in the second,
    // as does one ending exactly with the second batch; the next in the third.
    assert_eq!(s.find(3), Some(100));
    assert_eq!(s.find(4), Some(200));
    assert_eq!(s.find(8), Some(200));
    assert_eq!(s.find(9), Some(300));
    assert_eq!(s.find(12), Some(300));
    // Nothing received yet for a later end: the caller takes the clock now.
    assert_eq!(s.find(13), None);
    assert_eq!(s.merged(), 0);
}

#[test]
fn a_full_stamp_ring_gives_up_its_oldest_stamps_and_counts_them() {
    let s: StampRing<4> = StampRing::new();
    for k in 1..=6u32 {
        s.push(10 * k, u64::from(k) * 1000);
    }
    assert_eq!(s.merged(), 2, "two pushes found the ring full");
    // The two oldest stamps (..10, ..20) are gone: their bytes carry the next, later, stamp.
    assert_eq!(s.find(5), Some(3000));
    // The newest, where frames end, stay exact.
    assert_eq!(s.find(45), Some(5000));
    assert_eq!(s.find(60), Some(6000));
}

#[test]
fn stamps_follow_the_byte_counter_across_its_wrap() {
    let s: StampRing<8> = StampRing::new();
    let before = u32::MAX - 2;
    s.push(before, 10);
    s.push(5, 20); // the counter wrapped: 8 bytes later
    assert_eq!(s.find(before), Some(10));
    assert_eq!(s.find(u32::MAX), Some(20));
    assert_eq!(s.find(2), Some(20));
    // prune releases the stamps before an end no later frame can precede.
    s.push(9, 30);
    s.prune(5);
    assert_eq!(s.find(6), Some(30));
}

#[test]
fn an_interrupt_and_a_main_loop_on_two_threads_lose_and_reorder_nothing() {
    const BYTES: u64 = 2_000_000;
    let ring: Arc<Ring<256>> = Arc::new(Ring::new());
    let refused = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let producer = {
        let (ring, refused, done) = (ring.clone(), refused.clone(), done.clone());
        std::thread::spawn(move || {
            // Byte k of the stream is k mod 251; a refused byte is skipped, as the UART's would be.
            for k in 0..BYTES {
                if !ring.push((k % 251) as u8) {
                    refused.fetch_add(1, Ordering::Relaxed);
                }
            }
            done.store(true, Ordering::Release);
        })
    };
    let mut got = 0u64;
    let mut last: Option<u8> = None;
    let mut order_ok = true;
    loop {
        let finished = done.load(Ordering::Acquire);
        // One look at the readable bytes: a second `readable()` may hold more (the producer runs
        // on), and checking those while consuming only the first look's would see them again.
        let readable = ring.readable();
        let n = readable.len();
        if n == 0 {
            if finished && ring.readable().is_empty() {
                break;
            }
            std::hint::spin_loop();
            continue;
        }
        for &b in readable {
            // Without refusals each byte follows its predecessor; with them it is later in the
            // stream, never a byte from the past or a torn slot (checked by the count below).
            if refused.load(Ordering::Relaxed) == 0 {
                order_ok &= last.is_none_or(|p| b == ((u16::from(p) + 1) % 251) as u8);
            }
            last = Some(b);
        }
        got += n as u64;
        ring.consume(n);
    }
    producer.join().unwrap();
    let refused = refused.load(Ordering::Relaxed);
    assert_eq!(
        got + refused,
        BYTES,
        "every byte received or counted as refused"
    );
    assert_eq!(u64::from(ring.written()), got);
    assert!(order_ok, "bytes reordered");
    assert!(ring.high_water() <= 256);
}
