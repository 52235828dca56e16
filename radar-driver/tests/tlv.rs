//! Unit vectors per TLV type and header variant: hand-written bytes (independent of the
//! encoder), then encoder round trips for every typed TLV.

use radar_driver::encode::{CompressedRaw, FrameBuilder, QPointRaw, TlvOut};
use radar_driver::error::{Expected, TlvError};
use radar_driver::frame::{ones_complement_fold, Frame, Layout, Version};
use radar_driver::tlv::{CompressedUnits, Dialect, Point, Target, Tlv};

/// SDK 3.3 xWR68xx frame 7 with one point {1.0, 2.0, 0.5, -1.5} and side info {snr 123, noise 45},
/// padded to 96 B with 0xEE, written byte by byte.
#[rustfmt::skip]
static OOB_FRAME: [u8; 96] = [
    0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x07, // magic
    0x02, 0x00, 0x03, 0x03, // version 3.3.0.2
    0x60, 0x00, 0x00, 0x00, // totalPacketLen 96
    0x43, 0x68, 0x0A, 0x00, // platform 0xA6843
    0x07, 0x00, 0x00, 0x00, // frameNumber 7
    0x78, 0x56, 0x34, 0x12, // timeCpuCycles 0x12345678
    0x01, 0x00, 0x00, 0x00, // numDetectedObj 1
    0x02, 0x00, 0x00, 0x00, // numTLVs 2
    0x00, 0x00, 0x00, 0x00, // subFrameNumber 0
    0x01, 0x00, 0x00, 0x00, 0x10, 0x00, 0x00, 0x00, // TLV 1, 16 B
    0x00, 0x00, 0x80, 0x3F, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x3F, 0x00, 0x00, 0xC0, 0xBF,
    0x07, 0x00, 0x00, 0x00, 0x04, 0x00, 0x00, 0x00, // TLV 7, 4 B
    0x7B, 0x00, 0x2D, 0x00,
    0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, // padding (20 B)
    0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE, 0xEE,
];

#[test]
fn handwritten_oob_frame_decodes() {
    let f = Frame::new_checked(&OOB_FRAME, Layout::Oob40).unwrap();
    let h = f.header();
    assert_eq!(h.version, Version(0x0303_0002));
    assert_eq!(h.version.to_string(), "3.3.0.2");
    assert_eq!((h.total_len, h.platform, h.frame_number), (96, 0xA6843, 7));
    assert_eq!(
        (h.time_cpu_cycles, h.num_detected_obj, h.subframe),
        (Some(0x1234_5678), Some(1), Some(0))
    );
    assert_eq!(f.padding_len(), 20);
    let d = Dialect::of(&f);
    let tlvs: Vec<_> = f.tlvs().map(|t| t.decode(d).unwrap()).collect();
    let Tlv::Points(p) = tlvs[0] else {
        panic!("{:?}", tlvs[0])
    };
    assert_eq!(
        p.get(0),
        Some(Point {
            x: 1.0,
            y: 2.0,
            z: 0.5,
            velocity: -1.5
        })
    );
    assert_eq!(p.get(1), None);
    let Tlv::SideInfo(s) = tlvs[1] else { panic!() };
    assert_eq!(
        (s.get(0).unwrap().snr_db(), s.get(0).unwrap().noise_db()),
        (12.3, 4.5)
    );
    // The encoder writes the same bytes (padding aside).
    let mut b = FrameBuilder::oob(0x0303_0002, 0xA6843, 7)
        .cycles(0x1234_5678)
        .points(&[[1.0, 2.0, 0.5, -1.5]]);
    b = b.tlv(TlvOut::SideInfo(&[(123, 45)]));
    b.pad_byte = 0xEE;
    assert_eq!(b.to_vec(), OOB_FRAME.to_vec());
}

#[test]
fn handwritten_people_counting_header_checksum() {
    let mut h = [0u8; 48];
    h[..8].copy_from_slice(&radar_driver::MAGIC);
    h[8..12].copy_from_slice(&0x0305_0004u32.to_le_bytes());
    h[12..16].copy_from_slice(&48u32.to_le_bytes());
    h[16..20].copy_from_slice(&0xA6843u32.to_le_bytes());
    h[20..24].copy_from_slice(&1u32.to_le_bytes());
    let ck = !ones_complement_fold(&h);
    h[46..48].copy_from_slice(&ck.to_le_bytes());
    assert_eq!(ones_complement_fold(&h), 0xFFFF);
    let f = Frame::new_checked(&h, Layout::PeopleCounting48).unwrap();
    assert_eq!(f.header().checksum, Some(ck));
    assert_eq!(f.header().num_tlvs, 0);
    h[30] ^= 1;
    assert!(Frame::new_checked(&h, Layout::PeopleCounting48).is_err());
}

fn decode_one(b: FrameBuilder<'_>) -> (Vec<u8>, Layout) {
    let v = b.to_vec();
    let l = b.layout;
    (v, l)
}

fn single_tlv<R>(
    layout: Layout,
    version: u32,
    t: TlvOut<'_>,
    check: impl FnOnce(Tlv<'_>) -> R,
) -> R {
    let (v, l) = decode_one(FrameBuilder::new(layout, version, 0xA6843, 1).tlv(t));
    let f = Frame::new_checked(&v, l).unwrap();
    let raw = f.tlvs().next().unwrap();
    check(raw.decode(Dialect::of(&f)).unwrap())
}

#[test]
fn sdk2_q_format_points() {
    let pts = [QPointRaw {
        range_idx: 10,
        doppler_idx: -3,
        peak: 999,
        xyz: [512, -1024, 256],
    }];
    single_tlv(Layout::Oob40, 0x0200_0004, TlvOut::PointsQ(9, &pts), |t| {
        let Tlv::PointsQ(p) = t else { panic!("{t:?}") };
        assert_eq!(p.q_format(), 9);
        let q = p.get(0).unwrap();
        assert_eq!((q.range_idx, q.doppler_idx, q.peak), (10, -3, 999));
        assert_eq!((q.x, q.y, q.z), (1.0, -2.0, 0.5));
    });
}

#[test]
fn q_format_count_must_match_length() {
    let mut payload = vec![2u8, 0, 9, 0];
    payload.extend([0u8; 12]); // declares 2 points, carries 1
    let v = FrameBuilder::oob(0x0200_0004, 0xA1642, 1)
        .tlv(TlvOut::Raw(1, &payload))
        .to_vec();
    let f = Frame::new_checked(&v, Layout::Oob40).unwrap();
    let err = f
        .tlvs()
        .next()
        .unwrap()
        .decode(Dialect::of(&f))
        .unwrap_err();
    assert_eq!(
        err,
        TlvError::BadLength {
            ty: 1,
            len: 16,
            expected: Expected::FromCount {
                count: 2,
                implied: 28
            }
        }
    );
}

#[test]
fn profiles_stats_temperature_heatmaps() {
    let prof: Vec<u16> = (0..64).collect();
    single_tlv(Layout::Oob40, 0x0303_0002, TlvOut::U16s(2, &prof), |t| {
        let Tlv::RangeProfile(p) = t else { panic!() };
        assert_eq!(p.len(), 64);
        assert_eq!(p.iter().collect::<Vec<_>>(), prof);
    });
    single_tlv(Layout::Oob40, 0x0303_0002, TlvOut::U16s(3, &prof), |t| {
        assert!(matches!(t, Tlv::NoiseProfile(_)))
    });
    single_tlv(Layout::Oob40, 0x0303_0002, TlvOut::U16s(5, &prof), |t| {
        assert!(matches!(t, Tlv::RangeDopplerHeatmap(_)))
    });
    single_tlv(
        Layout::Oob40,
        0x0303_0002,
        TlvOut::Stats([1, 2, 3, 4, 5, 6]),
        |t| {
            let Tlv::Stats(s) = t else { panic!() };
            assert_eq!(
                (s.inter_frame_processing_time_us, s.inter_frame_cpu_load_pct),
                (1, 6)
            );
        },
    );
    let temps = [30, 31, 32, 33, 40, 41, 42, 35, 36, 37];
    single_tlv(
        Layout::Oob40,
        0x0303_0002,
        TlvOut::Temperature(0, 1234, temps),
        |t| {
            let Tlv::Temperature(s) = t else { panic!() };
            assert_eq!((s.time_ms, s.sensors_c), (1234, temps));
        },
    );
    let heat = [1u8, 0, 2, 0, 3, 0, 4, 0];
    single_tlv(Layout::Oob40, 0x0303_0002, TlvOut::Raw(4, &heat), |t| {
        let Tlv::AzimuthHeatmap(h) = t else { panic!() };
        assert_eq!(h.get(0), Some((2, 1)), "imaginary part first");
    });
    single_tlv(Layout::Oob40, 0x0303_0002, TlvOut::Raw(8, &heat), |t| {
        assert!(matches!(t, Tlv::AzElHeatmap(_)))
    });
}

#[test]
fn non_oob_payloads_under_oob_types_fail_typed_decode_not_the_frame() {
    // The vital-signs lab sends 104 B under type 2 and 128 B under type 6.
    let a = [0u8; 104];
    let b = [0u8; 128];
    let v = FrameBuilder::oob(0x0200_0004, 0xA1642, 1)
        .tlv(TlvOut::Raw(6, &b))
        .tlv(TlvOut::Raw(2, &a))
        .to_vec();
    let f = Frame::new_checked(&v, Layout::Oob40).unwrap();
    let d = Dialect::of(&f);
    let errs: Vec<_> = f.tlvs().map(|t| t.decode(d).unwrap_err()).collect();
    assert_eq!(
        errs[0],
        TlvError::BadLength {
            ty: 6,
            len: 128,
            expected: Expected::Exactly(24)
        }
    );
    assert_eq!(
        errs[1],
        TlvError::BadLength {
            ty: 2,
            len: 104,
            expected: Expected::PowerOfTwoU16s
        }
    );
    assert_eq!(
        f.tlvs().map(|t| t.payload.len()).collect::<Vec<_>>(),
        vec![128, 104]
    );
}

#[test]
fn compressed_points_both_type_numbers() {
    let units = CompressedUnits {
        elevation: 0.01,
        azimuth: 0.01,
        doppler: 0.05,
        range: 0.0025,
        snr: 0.04,
    };
    let pts = [CompressedRaw {
        elevation: 0,
        azimuth: 0,
        doppler: -20,
        range: 800,
        snr: 100,
    }];
    for (layout, ty) in [(Layout::PeopleCounting48, 6), (Layout::Oob40, 1020)] {
        single_tlv(
            layout,
            0x0305_0004,
            TlvOut::Compressed(ty, units, &pts),
            |t| {
                let Tlv::CompressedPoints(c) = t else {
                    panic!("{t:?}")
                };
                let s = c.get(0).unwrap();
                assert_eq!((s.range, s.doppler, s.snr), (2.0, -1.0, 4.0));
                let p = s.to_cartesian();
                assert!((p.y - 2.0).abs() < 1e-6 && p.x.abs() < 1e-6 && p.z.abs() < 1e-6);
            },
        );
    }
    let pts = [CompressedRaw {
        elevation: 0,
        azimuth: 50,
        doppler: 0,
        range: 400,
        snr: 0,
    }];
    single_tlv(
        Layout::Oob40,
        0x0305_0004,
        TlvOut::Compressed(1020, units, &pts),
        |t| {
            let Tlv::CompressedPoints(c) = t else {
                panic!()
            };
            let p = c.get(0).unwrap().to_cartesian();
            assert!(
                (p.x - 0.5f32.sin()).abs() < 1e-5 && (p.y - 0.5f32.cos()).abs() < 1e-5,
                "{p:?}"
            );
        },
    );
}

#[test]
fn targets_index_height_presence() {
    let mut t = Target {
        tid: 7,
        position: [1.0, 2.0, 3.0],
        confidence: 0.9,
        ..Target::default()
    };
    t.error_covariance[15] = 5.0;
    for (layout, tty, ity, pty) in [
        (Layout::PeopleCounting48, 7, 8, 11),
        (Layout::Oob40, 1010, 1011, 1021),
    ] {
        single_tlv(layout, 0x0305_0004, TlvOut::Targets(tty, &[t, t]), |x| {
            let Tlv::Targets(ts) = x else { panic!("{x:?}") };
            assert_eq!(ts.len(), 2);
            assert_eq!(ts.get(1), Some(t));
        });
        single_tlv(
            layout,
            0x0305_0004,
            TlvOut::TargetIndex(ity, &[0, 253, 7]),
            |x| {
                assert_eq!(x, Tlv::TargetIndex(&[0, 253, 7]));
            },
        );
        single_tlv(layout, 0x0305_0004, TlvOut::Presence(pty, 1), |x| {
            assert_eq!(x, Tlv::Presence(1))
        });
    }
    single_tlv(
        Layout::Oob40,
        0x0305_0004,
        TlvOut::Heights(&[(3, 1.8, 0.1)]),
        |x| {
            let Tlv::TargetHeights(h) = x else { panic!() };
            assert_eq!((h.get(0).unwrap().tid, h.get(0).unwrap().max_z), (3, 1.8));
        },
    );
}

#[test]
fn unknown_types_pass_through_raw() {
    single_tlv(
        Layout::Oob40,
        0x0303_0002,
        TlvOut::Raw(4242, &[1, 2, 3]),
        |t| {
            assert_eq!(
                t,
                Tlv::Unknown {
                    ty: 4242,
                    payload: &[1, 2, 3]
                }
            );
        },
    );
    single_tlv(
        Layout::PeopleCounting48,
        0x0305_0004,
        TlvOut::Raw(10, &[9; 12]),
        |t| {
            assert_eq!(
                t,
                Tlv::Unknown {
                    ty: 10,
                    payload: &[9; 12]
                }
            );
        },
    );
}

#[test]
fn pc52_header_fields() {
    let mut b = FrameBuilder::new(Layout::PeopleCounting52, 0x0101_0000, 0xA1642, 77).cycles(555);
    b.lab_timing = [1, 2, 3, 4];
    let v = b.tlv(TlvOut::Presence(11, 0)).to_vec();
    let f = Frame::new_checked(&v, Layout::PeopleCounting52).unwrap();
    let h = f.header();
    assert_eq!(
        (
            h.frame_number,
            h.platform,
            h.time_cpu_cycles,
            h.total_len as usize
        ),
        (77, 0xA1642, Some(555), v.len())
    );
    assert_eq!(h.lab_timing.unwrap().uart_sending, 4);
    assert_eq!(f.padding_len(), 0);
}

#[cfg(feature = "std")]
#[test]
fn decode_into_a_reused_cloud_equals_from_frame() {
    use radar_driver::host::PointCloud;
    // Frames with and without side info, stats and points, in sizes up and down.
    let p3 = [
        [1.0, 2.0, 0.5, -1.5],
        [0.0, 3.0, 0.0, 0.2],
        [-1.0, 1.0, 0.1, 0.0],
    ];
    let p1 = [[0.5, 4.0, -0.2, 1.0]];
    let frames = [
        FrameBuilder::oob(0x0303_0002, 0xA6843, 1)
            .points(&p3)
            .tlv(TlvOut::SideInfo(&[(123, 45), (99, 10), (5, 1)]))
            .tlv(TlvOut::Stats([1, 2, 3, 4, 5, 6]))
            .to_vec(),
        FrameBuilder::oob(0x0303_0002, 0xA6843, 2)
            .points(&p1)
            .to_vec(),
        FrameBuilder::oob(0x0303_0002, 0xA6843, 3)
            .points(&[])
            .tlv(TlvOut::SideInfo(&[]))
            .to_vec(),
        FrameBuilder::oob(0x0303_0002, 0xA6843, 4)
            .points(&p3)
            .tlv(TlvOut::SideInfo(&[(1, 2), (3, 4), (5, 6)]))
            .to_vec(),
    ];
    let mut reused = PointCloud::default();
    for (k, bytes) in frames.iter().enumerate() {
        let f = radar_driver::Frame::new_checked(bytes, Layout::Oob40).unwrap();
        reused.decode_into(&f, Some(0.1));
        assert_eq!(reused, PointCloud::from_frame(&f, Some(0.1)), "frame {k}");
    }
}
