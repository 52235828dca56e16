//! Round trips and damage: any message through the serial encoder and the deframer, in any
//! chunking, comes back equal; a damaged frame is dropped and counted, never mis-decoded, and the
//! next frame decodes.

use hub_link::{
    cobs, encode_serial, Deframer, Event, FrameError, Header, Health, Kind, Message, PortHealth,
    FRAME_MAX,
};
use proptest::prelude::*;

fn wire(m: &Message<'_>) -> Vec<u8> {
    let mut w = Vec::new();
    let n = m.encode_serial(&mut |b| w.push(b));
    assert_eq!(n, w.len());
    w
}

/// Owned copy of a decoded message, to compare after the deframer moved on.
#[derive(Debug, Clone, PartialEq)]
enum Owned {
    Radar(Header, Vec<u8>),
    Imu(Header, Vec<u8>),
    Health(Header, Health),
}

fn own(m: &Message<'_>) -> Owned {
    match *m {
        Message::Radar { header, bytes } => Owned::Radar(header, bytes.to_vec()),
        Message::Imu { header, bytes } => Owned::Imu(header, bytes.to_vec()),
        Message::Health { header, health } => Owned::Health(header, health),
    }
}

fn deframe(bytes: &[u8], chunk: usize) -> (Vec<Owned>, Vec<FrameError>, Box<Deframer<FRAME_MAX>>) {
    let mut d: Box<Deframer<FRAME_MAX>> = Box::default();
    let (mut ok, mut bad) = (Vec::new(), Vec::new());
    for c in bytes.chunks(chunk.max(1)) {
        let mut input = c;
        loop {
            match d.poll(&mut input) {
                Event::Message(m) => ok.push(own(&m)),
                Event::BadFrame(e) => bad.push(e),
                Event::NeedMore => break,
            }
        }
    }
    (ok, bad, d)
}

fn port() -> impl Strategy<Value = PortHealth> {
    prop::array::uniform10(any::<u32>()).prop_map(|w| PortHealth {
        rx_bytes: w[0],
        ring_overflow: w[1],
        ring_high_water: w[2],
        uart_errors: w[3],
        frames_ok: w[4],
        frames_bad: w[5],
        bytes_skipped: w[6],
        resyncs: w[7],
        frames_forwarded: w[8],
        frames_retracted: w[9],
    })
}

fn health() -> impl Strategy<Value = Health> {
    (port(), port(), prop::array::uniform11(any::<u32>())).prop_map(|(radar, imu, w)| Health {
        timer_hz: w[0],
        radar,
        imu,
        link_sent: w[1],
        link_dropped: w[2],
        link_dropped_bytes: w[3],
        link_high_water: w[4],
        stamps_merged: w[5],
        isr_max_per_byte: w[6],
        isr_clock: w[7],
        capacities: [w[8], w[9], w[10]],
    })
}

fn header() -> impl Strategy<Value = Header> {
    (any::<u16>(), any::<u32>(), any::<u64>()).prop_map(|(flags, seq, t_ns)| Header {
        flags,
        seq,
        t_ns,
    })
}

fn owned() -> impl Strategy<Value = Owned> {
    // Bodies biased towards zeros and 254-byte runs (COBS edge cases).
    let body = prop::collection::vec(prop_oneof![Just(0u8), any::<u8>()], 0..1200);
    prop_oneof![
        (header(), body.clone()).prop_map(|(h, b)| Owned::Radar(h, b)),
        (header(), body).prop_map(|(h, b)| Owned::Imu(h, b)),
        (header(), health()).prop_map(|(h, x)| Owned::Health(h, x)),
    ]
}

fn borrow(o: &Owned) -> Message<'_> {
    match o {
        Owned::Radar(header, b) => Message::Radar {
            header: *header,
            bytes: b,
        },
        Owned::Imu(header, b) => Message::Imu {
            header: *header,
            bytes: b,
        },
        Owned::Health(header, health) => Message::Health {
            header: *header,
            health: *health,
        },
    }
}

proptest! {
    #[test]
    fn messages_round_trip_in_any_chunking(msgs in prop::collection::vec(owned(), 1..8), chunk in 1usize..300) {
        let mut bytes = Vec::new();
        for m in &msgs {
            let w = wire(&borrow(m));
            let body = match m {
                Owned::Radar(_, b) | Owned::Imu(_, b) => b.len(),
                Owned::Health(..) => hub_link::HEALTH_LEN,
            };
            prop_assert!(w.len() <= hub_link::serial_len_max(body));
            prop_assert_eq!(w.iter().filter(|&&b| b == 0).count(), 1);
            bytes.extend(w);
        }
        let (ok, bad, d) = deframe(&bytes, chunk);
        prop_assert!(bad.is_empty());
        prop_assert_eq!(&ok, &msgs);
        prop_assert_eq!(d.counters().bytes_in, bytes.len() as u64);
        prop_assert_eq!(d.buffered(), 0);
    }

    #[test]
    fn a_damaged_frame_is_dropped_and_the_next_one_decodes(
        a in owned(), b in owned(), at in any::<prop::sample::Index>(), x in 1u8..=255,
    ) {
        let wa = wire(&borrow(&a));
        let wb = wire(&borrow(&b));
        let mut bytes = wa.clone();
        // Damage one byte of the first frame (not its delimiter).
        let i = at.index(wa.len() - 1);
        bytes[i] ^= x;
        bytes.extend(&wb);
        let (ok, bad, d) = deframe(&bytes, 7);
        // A damaged byte that became 0x00 splits the frame in two bad pieces (or, the first
        // byte, into an empty frame and one bad piece).
        prop_assert!(!bad.is_empty() && bad.len() <= 2, "{:?}", bad);
        prop_assert_eq!(ok, vec![b]);
        let c = d.counters();
        // Every byte of the damaged frame is counted: dropped, or as an empty frame.
        prop_assert!(c.empty_frames <= u64::from(i == 0));
        prop_assert_eq!(c.bytes_dropped + c.empty_frames, wa.len() as u64);
    }

    #[test]
    fn raw_encoding_equals_the_streaming_one(o in owned()) {
        let m = borrow(&o);
        let w = wire(&m);
        let mut raw = vec![0u8; w.len() + 8];
        let n = cobs::decode(&w[..w.len() - 1], &mut raw).unwrap();
        prop_assert_eq!(Message::decode(&raw[..n]), Ok(m));
        prop_assert_eq!(raw[0], m.kind() as u8);
        prop_assert_eq!(raw[1], hub_link::VERSION);
    }
}

#[test]
fn body_parts_are_concatenated() {
    let h = Header {
        seq: 1,
        t_ns: 2,
        ..Header::default()
    };
    let (mut one, mut two) = (Vec::new(), Vec::new());
    encode_serial(Kind::Radar, &h, &[b"abcdef"], &mut |b| one.push(b));
    encode_serial(Kind::Radar, &h, &[b"ab", b"", b"cdef"], &mut |b| {
        two.push(b)
    });
    assert_eq!(one, two);
}

#[test]
fn a_first_byte_damaged_into_a_delimiter_is_an_empty_frame_and_the_rest_is_dropped() {
    let h = Header {
        seq: 7,
        t_ns: 3,
        ..Header::default()
    };
    let a = wire(&Message::Radar {
        header: h,
        bytes: b"payload",
    });
    let b = Message::Imu {
        header: h,
        bytes: &[0xFA, 0xFF],
    };
    let mut bytes = a.clone();
    // The COBS code byte, never 0 on the wire, turned into a delimiter.
    assert_ne!(bytes[0], 0);
    bytes[0] = 0;
    bytes.extend(wire(&b));
    let (ok, bad, d) = deframe(&bytes, 3);
    assert_eq!(ok, vec![own(&b)]);
    assert_eq!(bad.len(), 1, "{bad:?}");
    let c = d.counters();
    assert_eq!((c.empty_frames, c.bytes_dropped), (1, a.len() as u64 - 1));
}

#[test]
fn oversize_frames_and_garbage_are_counted() {
    let mut bytes = vec![0x55u8; FRAME_MAX + 10];
    bytes.push(0);
    bytes.extend([1, 2, 3, 0]);
    let (ok, bad, d) = deframe(&bytes, 4096);
    assert!(ok.is_empty());
    assert_eq!(bad.len(), 2);
    assert_eq!(bad[0].kind_name(), "overflow");
    let c = d.counters();
    assert_eq!(
        (c.frames_overflow, c.frames_bad_cobs + c.frames_bad_message),
        (1, 1)
    );
    assert_eq!(c.bytes_dropped, bytes.len() as u64);
}

#[test]
fn resync_drops_the_partial_frame_and_keeps_the_counters() {
    let h = Header {
        seq: 4,
        t_ns: 9,
        ..Header::default()
    };
    let m = Message::Imu {
        header: h,
        bytes: &[0xFA, 0xFF, 0x36, 0x00, 0xCB],
    };
    let w = wire(&m);
    let mut d: Box<Deframer<FRAME_MAX>> = Box::default();
    let mut input = &w[..];
    assert!(matches!(d.poll(&mut input), Event::Message(_)));
    // Half a frame, then the stream is interrupted (port reopened).
    let mut input = &w[..w.len() / 2];
    assert_eq!(d.poll(&mut input), Event::NeedMore);
    assert_eq!(d.resync(), w.len() / 2);
    assert_eq!(d.buffered(), 0);
    // The next whole frame decodes (without the resync it would be glued to the half frame).
    let mut input = &w[..];
    assert_eq!(d.poll(&mut input), Event::Message(m));
    let c = d.counters();
    assert_eq!(c.messages_ok, 2);
    assert_eq!(c.bytes_in, (2 * w.len() + w.len() / 2) as u64);
    assert_eq!(c.bytes_dropped, (w.len() / 2) as u64);
}
