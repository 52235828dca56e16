//! Property tests: random valid frames of every layout through encoder -> framer (random
//! chunking, random junk between frames) -> decoder equal their input field by field; random
//! garbage never panics and every byte stays accounted for.

use proptest::prelude::*;
use radar_driver::encode::{CompressedRaw, FrameBuilder, QPointRaw, TlvOut};
use radar_driver::frame::Layout;
use radar_driver::tlv::{CompressedUnits, Dialect, Target, Tlv};
use radar_driver::{Framer, Poll, MAGIC};

/// An owned TLV description that both the encoder input and the decoder output map to.
#[derive(Debug, Clone, PartialEq)]
enum Spec {
    Points(Vec<[u32; 4]>),
    PointsQ(u16, Vec<(u16, i16, u16, [i16; 3])>),
    SideInfo(Vec<(i16, i16)>),
    U16s(u32, Vec<u16>),
    Stats([u32; 6]),
    Temperature(i32, u32, [i16; 10]),
    Compressed(u32, [u32; 5], Vec<(i8, i8, i16, u16, u16)>),
    Targets(u32, Vec<(u32, [u32; 27])>),
    TargetIndex(u32, Vec<u8>),
    Heights(Vec<(u32, u32, u32)>),
    Presence(u32, u32),
    Raw(u32, Vec<u8>),
}

#[derive(Debug, Clone)]
struct FrameSpec {
    layout: Layout,
    version: u32,
    platform: u32,
    frame_number: u32,
    cycles: u32,
    subframe: u32,
    tlvs: Vec<Spec>,
}

fn f(bits: u32) -> f32 {
    f32::from_bits(bits)
}

fn target(t: &(u32, [u32; 27])) -> Target {
    let v = t.1.map(f);
    let mut out = Target {
        tid: t.0,
        ..Target::default()
    };
    out.position.copy_from_slice(&v[0..3]);
    out.velocity.copy_from_slice(&v[3..6]);
    out.acceleration.copy_from_slice(&v[6..9]);
    out.error_covariance.copy_from_slice(&v[9..25]);
    out.gain = v[25];
    out.confidence = v[26];
    out
}

fn target_spec(t: &Target) -> (u32, [u32; 27]) {
    let mut v = [0u32; 27];
    let all = t
        .position
        .iter()
        .chain(&t.velocity)
        .chain(&t.acceleration)
        .chain(&t.error_covariance);
    for (d, s) in v.iter_mut().zip(all.chain([&t.gain, &t.confidence])) {
        *d = s.to_bits();
    }
    (t.tid, v)
}

/// Encodes a frame spec (owned buffers kept alive in `store`).
fn encode(s: &FrameSpec) -> Vec<u8> {
    let pts: Vec<Vec<[f32; 4]>> = s
        .tlvs
        .iter()
        .map(|t| {
            if let Spec::Points(p) = t {
                p.iter().map(|a| a.map(f)).collect()
            } else {
                vec![]
            }
        })
        .collect();
    let qpts: Vec<Vec<QPointRaw>> = s
        .tlvs
        .iter()
        .map(|t| match t {
            Spec::PointsQ(_, p) => p
                .iter()
                .map(|&(r, d, pk, xyz)| QPointRaw {
                    range_idx: r,
                    doppler_idx: d,
                    peak: pk,
                    xyz,
                })
                .collect(),
            _ => vec![],
        })
        .collect();
    let comp: Vec<Vec<CompressedRaw>> = s
        .tlvs
        .iter()
        .map(|t| match t {
            Spec::Compressed(_, _, p) => p
                .iter()
                .map(|&(elevation, azimuth, doppler, range, snr)| CompressedRaw {
                    elevation,
                    azimuth,
                    doppler,
                    range,
                    snr,
                })
                .collect(),
            _ => vec![],
        })
        .collect();
    let tg: Vec<Vec<Target>> = s
        .tlvs
        .iter()
        .map(|t| {
            if let Spec::Targets(_, v) = t {
                v.iter().map(target).collect()
            } else {
                vec![]
            }
        })
        .collect();
    let hs: Vec<Vec<(u32, f32, f32)>> = s
        .tlvs
        .iter()
        .map(|t| {
            if let Spec::Heights(v) = t {
                v.iter().map(|h| (h.0, f(h.1), f(h.2))).collect()
            } else {
                vec![]
            }
        })
        .collect();
    let mut b = FrameBuilder::new(s.layout, s.version, s.platform, s.frame_number).cycles(s.cycles);
    b.subframe = s.subframe;
    for (i, t) in s.tlvs.iter().enumerate() {
        let out = match t {
            Spec::Points(_) => TlvOut::Points(&pts[i]),
            Spec::PointsQ(q, _) => TlvOut::PointsQ(*q, &qpts[i]),
            Spec::SideInfo(v) => TlvOut::SideInfo(v),
            Spec::U16s(ty, v) => TlvOut::U16s(*ty, v),
            Spec::Stats(v) => TlvOut::Stats(*v),
            Spec::Temperature(a, b, c) => TlvOut::Temperature(*a, *b, *c),
            Spec::Compressed(ty, u, _) => TlvOut::Compressed(
                *ty,
                CompressedUnits {
                    elevation: f(u[0]),
                    azimuth: f(u[1]),
                    doppler: f(u[2]),
                    range: f(u[3]),
                    snr: f(u[4]),
                },
                &comp[i],
            ),
            Spec::Targets(ty, _) => TlvOut::Targets(*ty, &tg[i]),
            Spec::TargetIndex(ty, v) => TlvOut::TargetIndex(*ty, v),
            Spec::Heights(_) => TlvOut::Heights(&hs[i]),
            Spec::Presence(ty, v) => TlvOut::Presence(*ty, *v),
            Spec::Raw(ty, v) => TlvOut::Raw(*ty, v),
        };
        b = b.tlv(out);
    }
    b.to_vec()
}

/// Maps a decoded TLV back to a spec.
fn spec_of(t: Tlv<'_>, raw_ty: u32) -> Spec {
    match t {
        Tlv::Points(p) => Spec::Points(
            p.iter()
                .map(|q| [q.x, q.y, q.z, q.velocity].map(f32::to_bits))
                .collect(),
        ),
        Tlv::PointsQ(p) => {
            let s = f32::from(1u16 << p.q_format());
            Spec::PointsQ(
                p.q_format(),
                p.iter()
                    .map(|q| {
                        (
                            q.range_idx,
                            q.doppler_idx,
                            q.peak,
                            [q.x, q.y, q.z].map(|v| (v * s) as i16),
                        )
                    })
                    .collect(),
            )
        }
        Tlv::SideInfo(s) => Spec::SideInfo(s.iter().map(|e| (e.snr_raw, e.noise_raw)).collect()),
        Tlv::RangeProfile(v) | Tlv::NoiseProfile(v) | Tlv::RangeDopplerHeatmap(v) => {
            Spec::U16s(raw_ty, v.iter().collect())
        }
        Tlv::Stats(s) => Spec::Stats([
            s.inter_frame_processing_time_us,
            s.transmit_output_time_us,
            s.inter_frame_processing_margin_us,
            s.inter_chirp_processing_margin_us,
            s.active_frame_cpu_load_pct,
            s.inter_frame_cpu_load_pct,
        ]),
        Tlv::Temperature(t) => Spec::Temperature(t.report_valid, t.time_ms, t.sensors_c),
        Tlv::CompressedPoints(c) => {
            let u = c.units();
            let raw = |v: f32, unit: f32| v / unit;
            Spec::Compressed(
                raw_ty,
                [u.elevation, u.azimuth, u.doppler, u.range, u.snr].map(f32::to_bits),
                c.iter()
                    .map(|s| {
                        (
                            raw(s.elevation, u.elevation).round() as i8,
                            raw(s.azimuth, u.azimuth).round() as i8,
                            raw(s.doppler, u.doppler).round() as i16,
                            raw(s.range, u.range).round() as u16,
                            raw(s.snr, u.snr).round() as u16,
                        )
                    })
                    .collect(),
            )
        }
        Tlv::Targets(t) => Spec::Targets(raw_ty, t.iter().map(|x| target_spec(&x)).collect()),
        Tlv::TargetIndex(v) => Spec::TargetIndex(raw_ty, v.to_vec()),
        Tlv::TargetHeights(h) => Spec::Heights(
            (0..h.len())
                .filter_map(|i| h.get(i))
                .map(|x| (x.tid, x.max_z.to_bits(), x.min_z.to_bits()))
                .collect(),
        ),
        Tlv::Presence(v) => Spec::Presence(raw_ty, v),
        Tlv::Unknown { ty, payload } => Spec::Raw(ty, payload.to_vec()),
        other => panic!("unexpected {other:?}"),
    }
}

fn bits() -> impl Strategy<Value = u32> {
    any::<u32>()
}

fn pow2_u16s() -> impl Strategy<Value = Vec<u16>> {
    (0u32..7).prop_flat_map(|k| prop::collection::vec(any::<u16>(), 1usize << k))
}

/// Units are non-zero powers of two so raw = value / unit is exact.
fn units() -> impl Strategy<Value = [u32; 5]> {
    prop::array::uniform5((-12i32..0).prop_map(|e| 2f32.powi(e).to_bits()))
}

fn compressed(ty: u32) -> impl Strategy<Value = Spec> {
    (
        units(),
        prop::collection::vec(any::<(i8, i8, i16, u16, u16)>(), 0..20),
    )
        .prop_map(move |(u, p)| Spec::Compressed(ty, u, p))
}

fn targets(ty: u32) -> impl Strategy<Value = Spec> {
    prop::collection::vec((any::<u32>(), prop::array::uniform27(bits())), 0..3)
        .prop_map(move |v| Spec::Targets(ty, v))
}

fn sdk3_tlv() -> impl Strategy<Value = Spec> {
    prop_oneof![
        prop::collection::vec(prop::array::uniform4(bits()), 0..30).prop_map(Spec::Points),
        prop::collection::vec(any::<(i16, i16)>(), 0..30).prop_map(Spec::SideInfo),
        (prop_oneof![Just(2u32), Just(3), Just(5)], pow2_u16s())
            .prop_map(|(t, v)| Spec::U16s(t, v)),
        prop::array::uniform6(any::<u32>()).prop_map(Spec::Stats),
        (
            any::<i32>(),
            any::<u32>(),
            prop::array::uniform10(any::<i16>())
        )
            .prop_map(|(a, b, c)| Spec::Temperature(a, b, c)),
        compressed(1020),
        targets(1010),
        prop::collection::vec(any::<u8>(), 0..40).prop_map(|v| Spec::TargetIndex(1011, v)),
        prop::collection::vec((any::<u32>(), bits(), bits()), 0..4).prop_map(Spec::Heights),
        any::<u32>().prop_map(|v| Spec::Presence(1021, v)),
        (2000u32..3000, prop::collection::vec(any::<u8>(), 0..50))
            .prop_map(|(t, v)| Spec::Raw(t, v)),
    ]
}

fn sdk2_tlv() -> impl Strategy<Value = Spec> {
    prop_oneof![
        (
            0u16..16,
            prop::collection::vec(any::<(u16, i16, u16, [i16; 3])>(), 0..20)
        )
            .prop_map(|(q, p)| Spec::PointsQ(q, p)),
        (prop_oneof![Just(2u32), Just(3)], pow2_u16s()).prop_map(|(t, v)| Spec::U16s(t, v)),
        prop::array::uniform6(any::<u32>()).prop_map(Spec::Stats),
    ]
}

fn pc_tlv() -> impl Strategy<Value = Spec> {
    prop_oneof![
        compressed(6),
        targets(7),
        prop::collection::vec(any::<u8>(), 0..40).prop_map(|v| Spec::TargetIndex(8, v)),
        any::<u32>().prop_map(|v| Spec::Presence(11, v)),
        (
            prop_oneof![Just(10u32), Just(12), Just(1000)],
            prop::collection::vec(any::<u8>(), 0..30)
        )
            .prop_map(|(t, v)| Spec::Raw(t, v)),
    ]
}

fn frame_spec() -> impl Strategy<Value = FrameSpec> {
    let head = (any::<u32>(), any::<u32>(), 0u32..4);
    prop_oneof![
        (head.clone(), prop::collection::vec(sdk3_tlv(), 0..6)).prop_map(|((n, c, s), tlvs)| {
            FrameSpec {
                layout: Layout::Oob40,
                version: 0x0305_0004,
                platform: 0xA6843,
                frame_number: n,
                cycles: c,
                subframe: s,
                tlvs,
            }
        }),
        (head.clone(), prop::collection::vec(sdk2_tlv(), 0..4)).prop_map(|((n, c, s), tlvs)| {
            FrameSpec {
                layout: Layout::Oob40,
                version: 0x0200_0004,
                platform: 0xA1642,
                frame_number: n,
                cycles: c,
                subframe: s,
                tlvs,
            }
        }),
        (head.clone(), prop::collection::vec(sdk2_tlv(), 0..4)).prop_map(|((n, c, _), tlvs)| {
            FrameSpec {
                layout: Layout::Oob36,
                version: 0x0102_0000,
                platform: 0xA1443,
                frame_number: n,
                cycles: c,
                subframe: 0,
                tlvs,
            }
        }),
        (head.clone(), prop::collection::vec(pc_tlv(), 0..5)).prop_map(|((n, _, s), tlvs)| {
            FrameSpec {
                layout: Layout::PeopleCounting48,
                version: 0x0305_0004,
                platform: 0xA6843,
                frame_number: n,
                cycles: 0,
                subframe: s,
                tlvs,
            }
        }),
        (head, prop::collection::vec(pc_tlv(), 0..5)).prop_map(|((n, c, s), tlvs)| FrameSpec {
            layout: Layout::PeopleCounting52,
            version: 0x0104_0000,
            platform: 0xA1642,
            frame_number: n,
            cycles: c,
            subframe: s,
            tlvs
        }),
    ]
}

/// Junk that cannot contain a magic word (no 0x02 byte), so every byte of it must be skipped.
fn junk() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(any::<u8>().prop_map(|b| if b == 2 { 3 } else { b }), 0..40)
}

/// One decoded frame: layout, frame number, cycles, sub-frame, TLVs.
type Decoded = (Layout, u32, u32, Option<u32>, Vec<Spec>);

fn decode_stream(wire: &[u8], chunks: &[usize]) -> (Vec<Decoded>, radar_driver::Counters) {
    let mut framer: Box<Framer<65536>> = Box::default();
    let mut out = Vec::new();
    let mut rest = wire;
    let mut sizes = chunks.iter().cycle();
    while !rest.is_empty() {
        let n = (*sizes.next().unwrap_or(&1)).clamp(1, rest.len());
        let (mut chunk, tail) = rest.split_at(n);
        rest = tail;
        loop {
            match framer.poll(&mut chunk) {
                Poll::Frame(fr) => {
                    let d = Dialect::of(&fr);
                    let h = *fr.header();
                    let tlvs = fr
                        .tlvs()
                        .map(|t| spec_of(t.decode(d).expect("valid TLV decodes"), t.ty))
                        .collect();
                    let cycles = h.time_cpu_cycles.unwrap_or(0);
                    out.push((h.layout, h.frame_number, cycles, h.subframe, tlvs));
                }
                Poll::Dropped { error, .. } => panic!("valid stream dropped a frame: {error}"),
                Poll::NeedMore => break,
            }
        }
    }
    assert_eq!(framer.finish(), None);
    (out, *framer.counters())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn encode_frame_decode_round_trip(
        frames in prop::collection::vec((junk(), frame_spec()), 1..6),
        chunks in prop::collection::vec(1usize..700, 1..8),
    ) {
        let mut wire = Vec::new();
        let mut junk_total = 0u64;
        for (j, s) in &frames {
            junk_total += j.len() as u64;
            wire.extend(j);
            wire.extend(encode(s));
        }
        let (got, counters) = decode_stream(&wire, &chunks);
        let want: Vec<_> = frames
            .iter()
            .map(|(_, s)| {
                let sub = (s.layout != Layout::Oob36).then_some(s.subframe);
                (s.layout, s.frame_number, s.cycles, sub, s.tlvs.clone())
            })
            .collect();
        prop_assert_eq!(got, want);
        prop_assert_eq!(counters.bytes_skipped, junk_total);
        prop_assert_eq!(counters.frames_ok, frames.len() as u64);
        prop_assert_eq!(counters.bytes_in, wire.len() as u64);

        // Same stream all at once: identical output.
        let (once, _) = decode_stream(&wire, &[wire.len()]);
        let (chunked, _) = decode_stream(&wire, &chunks);
        prop_assert_eq!(once, chunked);
    }

    #[test]
    fn garbage_never_panics_and_every_byte_is_counted(
        parts in prop::collection::vec(prop_oneof![
            prop::collection::vec(any::<u8>(), 0..200),
            Just(MAGIC.to_vec()),
            frame_spec().prop_map(|s| encode(&s)),
            (frame_spec(), any::<usize>()).prop_map(|(s, cut)| { let v = encode(&s); v[..cut % v.len()].to_vec() }),
        ], 0..12),
        chunk in 1usize..300,
    ) {
        let wire: Vec<u8> = parts.concat();
        let mut framer: Framer<4096> = Framer::default();
        let mut released = 0u64;
        for c in wire.chunks(chunk) {
            let mut input = c;
            loop {
                match framer.poll(&mut input) {
                    Poll::Frame(fr) => {
                        released += fr.as_bytes().len() as u64;
                        for t in fr.tlvs() { let _ = t.decode(Dialect::of(&fr)); }
                    }
                    // A retraction takes back the frame released just before.
                    Poll::Dropped { error: radar_driver::FrameError::OverlapsNextFrame { len, .. }, .. } => {
                        released -= u64::from(len);
                    }
                    Poll::Dropped { .. } => {}
                    Poll::NeedMore => break,
                }
            }
        }
        let c = *framer.counters();
        prop_assert_eq!(c.bytes_in, wire.len() as u64);
        prop_assert_eq!(c.bytes_ok, released);
        prop_assert_eq!(c.bytes_in, c.bytes_ok + c.bytes_skipped + framer.buffered() as u64);
        framer.finish();
        let c = *framer.counters();
        prop_assert_eq!(c.bytes_in, c.bytes_ok + c.bytes_skipped);
    }
}
