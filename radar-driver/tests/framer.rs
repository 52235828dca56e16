//! Framer behaviours: chunking, resync, truncation, bounds, accounting.

use radar_driver::encode::{FrameBuilder, TlvOut};
use radar_driver::error::FrameError;
use radar_driver::frame::{Layout, LayoutHint};
use radar_driver::tlv::{Dialect, Tlv};
use radar_driver::{Counters, Framer, Poll};

type F = Framer<8192>;

const V3: u32 = 0x0303_0002;
const P68: u32 = 0xA6843;

fn oob(frame: u32, pts: &[[f32; 4]]) -> Vec<u8> {
    FrameBuilder::oob(V3, P68, frame)
        .points(pts)
        .cycles(frame * 1000)
        .to_vec()
}

/// Everything one feeding produced: good frame numbers and drop reasons.
#[derive(Debug, Default, PartialEq)]
struct Out {
    frames: Vec<u32>,
    dropped: Vec<(FrameError, usize)>,
}

fn feed_chunks<'a>(f: &mut F, chunks: impl IntoIterator<Item = &'a [u8]>) -> Out {
    let mut out = Out::default();
    for chunk in chunks {
        let mut input = chunk;
        loop {
            match f.poll(&mut input) {
                Poll::Frame(fr) => out.frames.push(fr.header().frame_number),
                Poll::Dropped { error, skipped } => out.dropped.push((error, skipped)),
                Poll::NeedMore => break,
            }
        }
        assert!(input.is_empty(), "NeedMore must mean the chunk was used up");
    }
    if let Some(d) = f.finish() {
        out.dropped.push(d);
    }
    out
}

fn accounted(c: &Counters, f: &F) {
    assert_eq!(
        c.bytes_in,
        c.bytes_ok + c.bytes_skipped + f.buffered() as u64,
        "{c:?}"
    );
}

#[test]
fn empty_input_needs_more() {
    let mut f = F::default();
    let mut input: &[u8] = &[];
    assert!(matches!(f.poll(&mut input), Poll::NeedMore));
    assert_eq!(f.finish(), None);
    assert_eq!(*f.counters(), Counters::default());
}

#[test]
fn all_at_once_and_byte_by_byte_agree() {
    let mut wire = Vec::new();
    for n in 1..=5 {
        wire.extend(oob(n, &[[n as f32, 1.0, 0.5, -0.25]; 3]));
    }
    let mut a = F::default();
    let once = feed_chunks(&mut a, [&wire[..]]);
    let mut b = F::default();
    let bytewise = feed_chunks(&mut b, wire.chunks(1));
    assert_eq!(once.frames, vec![1, 2, 3, 4, 5]);
    assert_eq!(once, bytewise);
    assert_eq!(a.counters(), b.counters());
    assert_eq!(a.counters().bytes_skipped, 0);
    assert_eq!(a.counters().resyncs, 0);
    accounted(a.counters(), &a);
}

#[test]
fn frame_is_released_with_its_last_byte() {
    let wire = oob(9, &[[0.0; 4]]);
    let mut f = F::default();
    let mut input = &wire[..wire.len() - 1];
    assert!(matches!(f.poll(&mut input), Poll::NeedMore));
    let last = [wire[wire.len() - 1]];
    let mut input = &last[..];
    match f.poll(&mut input) {
        Poll::Frame(fr) => assert_eq!(fr.header().frame_number, 9),
        other => panic!("frame not released on its last byte: {other:?}"),
    }
}

#[test]
fn split_magic_across_chunks() {
    let wire = oob(3, &[]);
    for cut in 1..8 {
        let mut f = F::default();
        let out = feed_chunks(&mut f, [&wire[..cut], &wire[cut..]]);
        assert_eq!(out.frames, vec![3], "cut at {cut}");
    }
}

#[test]
fn junk_prefix_and_false_magic_prefixes_are_skipped_and_counted() {
    let mut wire = vec![
        0xAA, 0x02, 0x01, 0x04, 0x55, 0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x00,
    ];
    let junk = wire.len();
    wire.extend(oob(1, &[[1.0; 4]]));
    for chunk in [1, 2, 5, 1000] {
        let mut f = F::default();
        let out = feed_chunks(&mut f, wire.chunks(chunk));
        assert_eq!(out.frames, vec![1], "chunk {chunk}");
        assert_eq!(f.counters().bytes_skipped, junk as u64);
        assert_eq!(f.counters().resyncs, 1);
        accounted(f.counters(), &f);
    }
}

#[test]
fn truncated_frame_then_good_frame() {
    let first = oob(1, &[[1.0; 4]; 10]);
    let second = oob(2, &[[2.0; 4]; 2]);
    let mut wire = first[..first.len() - 50].to_vec();
    let cut = wire.len();
    wire.extend(&second);
    for chunk in [1, 7, 64, 100_000] {
        let mut f = F::default();
        let out = feed_chunks(&mut f, wire.chunks(chunk));
        assert_eq!(
            out.frames,
            vec![2],
            "the frame after a truncated one is still found (chunk {chunk})"
        );
        assert_eq!(
            out.dropped,
            vec![(
                FrameError::Truncated {
                    claimed: first.len() as u32,
                    got: cut as u32
                },
                cut
            )]
        );
        accounted(f.counters(), &f);
    }
}

#[test]
fn truncation_is_reported_before_the_claimed_length_arrives() {
    // A frame claiming 4 KiB, cut after its header; the next magic must end it at once.
    let mut first = FrameBuilder::oob(V3, P68, 1);
    first.extra_len = 4000;
    let first = first.to_vec();
    let mut wire = first[..64].to_vec();
    wire.extend(oob(2, &[]));
    let mut f = F::default();
    let mut input = &wire[..];
    assert!(matches!(
        f.poll(&mut input),
        Poll::Dropped {
            error: FrameError::Truncated { got: 64, .. },
            ..
        }
    ));
    assert!(matches!(f.poll(&mut input), Poll::Frame(_)));
}

#[test]
fn absurd_length_drops_only_the_magic() {
    let mut bad = oob(1, &[]);
    bad[12..16].copy_from_slice(&0x7FFF_FFF0u32.to_le_bytes());
    let mut wire = bad.clone();
    wire.extend(oob(2, &[]));
    let mut f = F::default();
    let out = feed_chunks(&mut f, [&wire[..]]);
    assert_eq!(out.frames, vec![2]);
    assert_eq!(
        out.dropped,
        vec![(
            FrameError::LengthTooLarge {
                len: 0x7FFF_FFF0,
                max: 8192
            },
            8
        )]
    );
    assert_eq!(f.counters().bytes_skipped, bad.len() as u64);

    let mut g = F::new(LayoutHint::Auto).with_max_len(100);
    let big = oob(3, &[[0.0; 4]; 10]);
    let out = feed_chunks(&mut g, [&big[..]]);
    assert_eq!(
        out.dropped[0].0,
        FrameError::LengthTooLarge {
            len: big.len() as u32,
            max: 100
        }
    );
}

#[test]
fn length_smaller_than_header_is_rejected() {
    let mut bad = oob(1, &[]);
    bad[12..16].copy_from_slice(&8u32.to_le_bytes());
    let mut f = F::new(LayoutHint::Fixed(Layout::Oob40));
    let out = feed_chunks(&mut f, [&bad[..]]);
    assert!(out.frames.is_empty());
    assert_eq!(
        out.dropped[0],
        (FrameError::LengthTooSmall { len: 8, min: 40 }, 8)
    );
}

#[test]
fn bad_tlv_length_is_rejected_and_resynced() {
    let mut bad = oob(1, &[[1.0; 4]; 2]);
    bad[44..48].copy_from_slice(&5000u32.to_le_bytes()); // TLV 0 length
    let mut wire = bad;
    wire.extend(oob(2, &[]));
    let mut f = F::default();
    let out = feed_chunks(&mut f, [&wire[..]]);
    assert_eq!(out.frames, vec![2]);
    assert!(matches!(
        out.dropped[0].0,
        FrameError::BadTlvLength {
            index: 0,
            ty: 1,
            len: 5000,
            ..
        }
    ));
}

#[test]
fn zero_point_frame_with_empty_tlv1() {
    let wire = FrameBuilder::oob(V3, P68, 5)
        .tlv(TlvOut::Points(&[]))
        .to_vec();
    let mut f = F::default();
    let mut input = &wire[..];
    let Poll::Frame(fr) = f.poll(&mut input) else {
        panic!("zero-point frame rejected")
    };
    let tlvs: Vec<_> = fr.tlvs().collect();
    assert_eq!(tlvs.len(), 1);
    assert_eq!(tlvs[0].payload.len(), 0);
    match tlvs[0].decode(Dialect::of(&fr)).unwrap() {
        Tlv::Points(p) => assert!(p.is_empty()),
        other => panic!("{other:?}"),
    }
}

#[test]
fn people_counting_bad_checksum_then_good_frame() {
    let pc = |n| {
        FrameBuilder::new(Layout::PeopleCounting48, 0x0305_0004, P68, n)
            .tlv(TlvOut::Presence(11, 1))
            .to_vec()
    };
    let mut bad = pc(1);
    bad[20] ^= 0x40; // frame number bit: checksum no longer folds to 0xFFFF
    let mut wire = bad;
    wire.extend(pc(2));
    wire.extend(pc(3));
    let mut f = F::new(LayoutHint::Fixed(Layout::PeopleCounting48));
    let out = feed_chunks(&mut f, wire.chunks(3));
    assert_eq!(out.frames, vec![2, 3]);
    assert!(matches!(out.dropped[0].0, FrameError::BadChecksum { .. }));
}

#[test]
fn auto_layout_detects_each_header() {
    for layout in [
        Layout::Oob40,
        Layout::PeopleCounting48,
        Layout::PeopleCounting52,
    ] {
        let (v, p) = if layout == Layout::Oob40 {
            (V3, P68)
        } else {
            (0x0305_0004, P68)
        };
        let mut wire = Vec::new();
        for n in 0..3 {
            wire.extend(
                FrameBuilder::new(layout, v, p, n)
                    .tlv(TlvOut::TargetIndex(8, &[1, 2, 3]))
                    .to_vec(),
            );
        }
        let mut f = F::default();
        let out = feed_chunks(&mut f, wire.chunks(5));
        assert_eq!(out.frames, vec![0, 1, 2], "{layout:?}");
        assert_eq!(f.last_layout(), Some(layout));
    }
    // xWR14xx with SDK 2: 36-byte header.
    let wire = FrameBuilder::oob(0x0200_0004, 0xA1443, 4).to_vec();
    let mut f = F::default();
    let mut input = &wire[..];
    let Poll::Frame(fr) = f.poll(&mut input) else {
        panic!()
    };
    assert_eq!(fr.layout(), Layout::Oob36);
    assert_eq!(fr.header().subframe, None);
}

#[test]
fn padding_is_never_validated() {
    let mut b = FrameBuilder::oob(V3, P68, 1).points(&[[1.0; 4]]);
    b.pad_byte = 0xFF;
    let a = b.to_vec();
    b.pad_byte = 0x0F;
    let c = b.to_vec();
    for w in [a, c] {
        let mut f = F::default();
        assert_eq!(feed_chunks(&mut f, [&w[..]]).frames, vec![1]);
    }
}

#[test]
fn finish_reports_a_trailing_partial_frame() {
    let wire = oob(1, &[[1.0; 4]; 4]);
    let mut f = F::default();
    let out = feed_chunks(&mut f, [&wire[..wire.len() - 3]]);
    assert!(out.frames.is_empty());
    assert_eq!(
        out.dropped,
        vec![(
            FrameError::Truncated {
                claimed: wire.len() as u32,
                got: wire.len() as u32 - 3
            },
            wire.len() - 3
        )]
    );
    assert_eq!(f.counters().bytes_skipped, wire.len() as u64 - 3);
}

#[test]
fn a_byte_lost_inside_a_frame_is_caught_when_the_next_magic_arrives() {
    // No checksum covers the payload: the short frame is released when its claimed length is in
    // (it then ends inside the next magic word), and retracted as soon as the rest of that magic
    // shows it overlapped; the next frame is still found.
    for lost in 1..=7usize {
        let first = oob(1, &[[1.0, 2.0, 3.0, 4.0]; 6]);
        let mut wire = first.clone();
        wire.drain(60..60 + lost);
        wire.extend(oob(2, &[[5.0; 4]; 2]));
        wire.extend(oob(3, &[]));
        for chunk in [1, 3, 8, 100, 100_000] {
            let mut f = F::default();
            let out = feed_chunks(&mut f, wire.chunks(chunk));
            assert_eq!(
                out.frames,
                vec![1, 2, 3],
                "lost {lost}, chunk {chunk}: frame 1 is released first"
            );
            assert_eq!(
                out.dropped,
                vec![(
                    FrameError::OverlapsNextFrame {
                        overlap: lost as u32,
                        len: first.len() as u32
                    },
                    first.len() - lost
                )],
                "lost {lost}, chunk {chunk}"
            );
            let c = f.counters();
            assert_eq!(c.frames_ok, 2, "the retracted frame is not counted good");
            assert_eq!(
                c.frames_bad[FrameError::OverlapsNextFrame { overlap: 0, len: 0 }.kind_index()],
                1
            );
            accounted(c, &f);
            assert_eq!(c.bytes_in, wire.len() as u64);
        }
    }
}

#[test]
fn a_frame_ending_in_magic_like_padding_is_not_retracted() {
    // Padding that happens to end in 02 01 04 followed by a real magic: nothing to retract.
    let mut b = FrameBuilder::oob(V3, P68, 1).points(&[[1.0; 4]]);
    b.pad_byte = 0x02;
    let mut wire = b.to_vec();
    let n = wire.len();
    wire[n - 3..].copy_from_slice(&[0x02, 0x01, 0x04]);
    wire.extend(oob(2, &[]));
    let mut f = F::default();
    let out = feed_chunks(&mut f, wire.chunks(5));
    assert_eq!(out.frames, vec![1, 2]);
    assert!(out.dropped.is_empty());
}
