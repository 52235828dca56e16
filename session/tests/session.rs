//! Session writer -> reader round trips, bare captures, and every validation error.

use milliego_session::*;
use radar_driver::encode::FrameBuilder;
use std::fs;

fn radar_bytes(frames: u32) -> Vec<u8> {
    (1..=frames)
        .flat_map(|n| {
            FrameBuilder::oob(0x0303_0002, 0xA6843, n)
                .points(&[[1.0, 2.0, 0.0, 0.5]])
                .to_vec()
        })
        .collect()
}

/// A minimal valid Xbus MTData2 frame (FA FF 36 len ... cs) with a PacketCounter item.
fn xbus(counter: u16) -> Vec<u8> {
    let payload = [0x10, 0x20, 2, (counter >> 8) as u8, counter as u8];
    let mut f = vec![0xFA, 0xFF, 0x36, payload.len() as u8];
    f.extend(payload);
    let sum = f[1..].iter().fold(0u8, |a, b| a.wrapping_add(*b));
    f.push(0u8.wrapping_sub(sum));
    f
}

#[test]
fn written_session_opens_with_its_chunks_metadata_and_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s1");
    let mut meta = Meta::new(Source::Simulated);
    meta.description = "unit test".into();
    meta.extrinsics.radar.translation_m = [0.1, 0.0, 0.05];
    let mut w = SessionWriter::create(&path, meta).unwrap();
    let bytes = radar_bytes(4);
    let mut rs = w.stream(StreamKind::Radar).unwrap();
    for (i, c) in bytes.chunks(50).enumerate() {
        rs.write_chunk(1_000 * i as u64, c).unwrap();
    }
    assert_eq!(rs.finish().unwrap(), bytes.len() as u64);
    let imu: Vec<u8> = (0..10).flat_map(xbus).collect();
    let mut is = w.stream(StreamKind::Imu).unwrap();
    is.write_chunk(5, &imu[..17]).unwrap();
    is.write_chunk(9, &[]).unwrap(); // ignored
    is.write_chunk(10, &imu[17..]).unwrap();
    is.finish().unwrap();
    w.radar_cfg("sensorStop\nsensorStart\n").unwrap();
    let gt = vec![
        TumPose {
            t: 0.0,
            p: [0.0; 3],
            q: [0.0, 0.0, 0.0, 1.0],
        },
        TumPose {
            t: 0.005,
            p: [0.001, 2.0e-7, -3.5],
            q: [
                0.0,
                0.0,
                std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
            ],
        },
    ];
    w.groundtruth(&gt).unwrap();
    w.finish().unwrap();

    let s = Session::open(&path).unwrap();
    assert_eq!(s.meta.source, Source::Simulated);
    assert_eq!(s.meta.description, "unit test");
    assert_eq!(s.meta.extrinsics.radar.translation_m, [0.1, 0.0, 0.05]);
    let r = s.radar.as_ref().unwrap();
    assert_eq!(r.read_all().unwrap(), bytes);
    let chunks = r.chunks();
    assert_eq!(chunks.len(), bytes.len().div_ceil(50));
    assert_eq!(
        chunks[1],
        Chunk {
            host_ns: Some(1_000),
            start: 50,
            end: 100
        }
    );
    assert_eq!(chunks.last().unwrap().end, bytes.len() as u64);
    let i = s.imu.as_ref().unwrap();
    assert_eq!(i.read_all().unwrap(), imu);
    assert_eq!(
        i.chunks().iter().map(|c| c.host_ns).collect::<Vec<_>>(),
        vec![Some(5), Some(10)]
    );
    assert_eq!(
        s.radar_cfg().unwrap().as_deref(),
        Some("sensorStop\nsensorStart\n")
    );
    assert_eq!(s.groundtruth().unwrap().unwrap(), gt);

    // A second writer refuses to overwrite it.
    let e = SessionWriter::create(&path, Meta::new(Source::Recorded)).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::Exists), "{e}");
}

#[test]
fn bare_captures_open_as_sessions_without_timing() {
    let dir = tempfile::tempdir().unwrap();
    let dat = dir.path().join("capture.dat");
    fs::write(&dat, radar_bytes(3)).unwrap();
    let s = Session::open(&dat).unwrap();
    assert_eq!(s.meta.source, Source::Imported);
    let r = s.radar.unwrap();
    assert!(r.index.is_none());
    assert_eq!(
        r.chunks(),
        vec![Chunk {
            host_ns: None,
            start: 0,
            end: r.len
        }]
    );
    assert!(s.imu.is_none());

    let mtb = dir.path().join("log.mtb");
    let mut imu = vec![0x00, 0xFA, 0x12]; // junk before the first frame
    imu.extend((0..5).flat_map(xbus));
    fs::write(&mtb, &imu).unwrap();
    assert!(Session::open(&mtb).unwrap().imu.is_some());

    // The directory of both opens as one session.
    let s = Session::open(dir.path()).unwrap();
    assert!(s.radar.is_some() && s.imu.is_some());
}

#[test]
fn unknown_files_and_empty_directories_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.bin");
    fs::write(&junk, b"hello world, not a sensor").unwrap();
    let e = Session::open(&junk).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::UnknownStream));
    assert!(e.to_string().contains("junk.bin"));
    let e = Session::open(dir.path()).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::Empty), "{e}");
}

#[test]
fn malformed_index_metadata_and_ground_truth_are_rejected_with_evidence() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("s");
    let mut w = SessionWriter::create(&p, Meta::new(Source::Recorded)).unwrap();
    let mut rs = w.stream(StreamKind::Radar).unwrap();
    rs.write_chunk(10, &radar_bytes(1)).unwrap();
    rs.finish().unwrap();
    w.finish().unwrap();
    assert!(Session::open(&p).is_ok());

    // Index longer than the data.
    let data = p.join("radar.bin");
    let full = fs::read(&data).unwrap();
    fs::write(&data, &full[..10]).unwrap();
    let e = Session::open(&p).unwrap_err();
    assert!(e.to_string().contains("indexes"), "{e}");
    fs::write(&data, &full).unwrap();

    // Time going back.
    let idx = p.join("radar.idx");
    let mut bytes = fs::read(&idx).unwrap();
    bytes.extend(5u64.to_le_bytes());
    bytes.extend((full.len() as u64 + 1).to_le_bytes());
    fs::write(&idx, &bytes).unwrap();
    let e = Session::open(&p).unwrap_err();
    assert!(e.to_string().contains("goes back"), "{e}");
    fs::write(&idx, b"not an index").unwrap();
    assert!(Session::open(&p)
        .unwrap_err()
        .to_string()
        .contains("MEGOIDX1"));

    // Newer format version.
    let meta = p.join("session.toml");
    let text = fs::read_to_string(&meta)
        .unwrap()
        .replace("version = 1", "version = 99");
    fs::write(&meta, text).unwrap();
    assert!(Session::open(&p).unwrap_err().to_string().contains("newer"));

    // Ground truth lines.
    let gt = dir.path().join("gt.tum");
    fs::write(&gt, "# c\n0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 2\n").unwrap();
    let e = read_tum(&gt).unwrap_err();
    assert!(
        matches!(e.kind, ErrorKind::GroundTruth { line: 3, .. }),
        "{e}"
    );
    fs::write(&gt, "0 0 0 0 0 0 1\n").unwrap();
    assert!(read_tum(&gt).unwrap_err().to_string().contains("7 fields"));
}

#[test]
fn real_captures_sniff_as_what_they_are() {
    let Some(ti) = milliego_tests::captures_dir("ti-mmwave") else {
        return;
    };
    for f in [
        "xwr68xx_sdk3.3_automated_doors.dat",
        "xwr68xx_sdk3.5_people_counting_3d.bin",
    ] {
        assert_eq!(
            sniff_file(&ti.join(f)).unwrap(),
            Some(StreamKind::Radar),
            "{f}"
        );
    }
    let Some(xs) = milliego_tests::captures_dir("xsens") else {
        return;
    };
    assert_eq!(
        sniff_file(&xs.join("mti-g-710_1/output.bin")).unwrap(),
        Some(StreamKind::Imu)
    );
}

#[test]
fn implausible_radar_frames_are_left_out_and_counted_by_reason() {
    use milliego_session::streams::radar_frames;
    let pts = [[1.0, 2.0, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
    let nan = [[1.0, f32::NAN, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
    let mut bytes = Vec::new();
    for n in 1..=12u32 {
        let number = match n {
            4 => 1004, // a corrupted frame number
            9 => 20,   // in the window: would move the anchor, but the frame is retracted
            _ => n,
        };
        let p: &[[f32; 4]] = if n == 7 { &nan } else { &pts };
        let mut f = FrameBuilder::oob(0x0303_0002, 0xA6843, number)
            .points(p)
            .to_vec();
        assert_eq!(f.len(), 96, "16 B of padding");
        if n == 9 {
            // One byte lost on the wire: frame 9 ends inside frame 10's magic and is retracted.
            f.pop();
        }
        bytes.extend(f);
    }
    let dir = tempfile::tempdir().unwrap();
    let dat = dir.path().join("capture.dat");
    fs::write(&dat, &bytes).unwrap();
    let (frames, rep) = radar_frames(&Session::open(&dat).unwrap()).unwrap();
    let numbers: Vec<u32> = frames.iter().map(|f| f.frame_number).collect();
    assert_eq!(
        numbers,
        [1, 2, 3, 5, 6, 8, 10, 11, 12],
        "frame 10 follows 8: the retracted frame did not move the anchor to 20"
    );
    assert_eq!((rep.ok, rep.bad, rep.reanchored), (9, 1, 0));
    let by: Vec<(&str, u64)> = rep.implausible_by_reason().filter(|r| r.1 > 0).collect();
    assert_eq!(by, [("frame_number", 1), ("non_finite", 1)]);
    assert_eq!(rep.implausible_total(), 2);
}
