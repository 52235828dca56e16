//! Every real capture in ../shared/captures/ti-mmwave decodes to exactly the counts its README
//! states, fed in random chunk sizes (fixed seeds) and all at once.

use milliego_tests::{captures_dir, SeededChunks};
use radar_driver::error::FrameError;
use radar_driver::host::PointCloud;
use radar_driver::{Framer, Poll, DEFAULT_MAX_FRAME};
use std::collections::BTreeMap;

#[derive(Debug, Default, PartialEq)]
struct Report {
    frame_numbers: Vec<u32>,
    points_per_frame: Vec<usize>,
    tlv_counts: BTreeMap<u32, u64>,
    empty_points_tlv_without_side_info: u64,
    tlv_decode_errors: u64,
    drops: Vec<FrameError>,
    bytes_skipped: u64,
    frames_bad: u64,
    all_points_finite: bool,
}

fn decode<'a>(chunks: impl Iterator<Item = &'a [u8]>) -> Report {
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let mut r = Report {
        all_points_finite: true,
        ..Report::default()
    };
    for chunk in chunks {
        let mut input = chunk;
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => {
                    let c = PointCloud::from_frame(&f, None);
                    r.frame_numbers.push(f.header().frame_number);
                    r.points_per_frame.push(c.points.len());
                    r.all_points_finite &= c
                        .points
                        .iter()
                        .all(|p| p.x.is_finite() && p.y.is_finite() && p.z.is_finite());
                    for t in &c.tlv_types {
                        *r.tlv_counts.entry(*t).or_default() += 1;
                    }
                    if c.empty_points_tlv && !c.tlv_types.contains(&7) {
                        r.empty_points_tlv_without_side_info += 1;
                    }
                    r.tlv_decode_errors += c.tlv_errors.len() as u64;
                }
                Poll::Dropped { error, .. } => r.drops.push(error),
                Poll::NeedMore => break,
            }
        }
    }
    if let Some((e, _)) = framer.finish() {
        r.drops.push(e);
    }
    r.bytes_skipped = framer.counters().bytes_skipped;
    r.frames_bad = framer.counters().frames_bad_total();
    assert_eq!(
        framer.counters().bytes_in,
        framer.counters().bytes_ok + framer.counters().bytes_skipped
    );
    r
}

/// Decodes a capture all at once and in several seeded chunkings; all must agree.
fn decode_capture(name: &str) -> Option<Report> {
    let dir = captures_dir("ti-mmwave")?;
    let data = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let once = decode(std::iter::once(&data[..]));
    for (seed, max) in [(1u64, 1usize), (2, 7), (3, 300), (4, 5000)] {
        let chunked = decode(SeededChunks::new(&data, seed, max));
        assert_eq!(
            chunked, once,
            "{name}: chunking (seed {seed}, max {max}) changed the output"
        );
    }
    Some(once)
}

fn contiguous(from: u32, to: u32) -> Vec<u32> {
    (from..=to).collect()
}

#[test]
fn xwr68xx_sdk33_automated_doors() {
    let Some(r) = decode_capture("xwr68xx_sdk3.3_automated_doors.dat") else {
        return;
    };
    assert_eq!(
        r.frame_numbers,
        contiguous(209, 309),
        "101 frames, 209..309, no gaps"
    );
    assert_eq!(
        r.tlv_counts,
        BTreeMap::from([(1, 101), (2, 101), (6, 101), (7, 97)])
    );
    assert_eq!(r.points_per_frame.iter().sum::<usize>(), 825);
    assert_eq!(r.points_per_frame.iter().min(), Some(&0));
    assert_eq!(r.points_per_frame.iter().max(), Some(&23));
    assert_eq!(
        r.empty_points_tlv_without_side_info, 4,
        "zero-length TLV 1 without TLV 7"
    );
    assert_eq!(
        (r.frames_bad, r.bytes_skipped, r.tlv_decode_errors),
        (0, 0, 0)
    );
    assert!(r.all_points_finite);
}

#[test]
fn xwr68xx_sdk35_people_counting() {
    let Some(r) = decode_capture("xwr68xx_sdk3.5_people_counting_3d.bin") else {
        return;
    };
    assert_eq!(r.frame_numbers.len(), 992);
    let mut expect = contiguous(1, 45);
    expect.extend(54..=1000);
    assert_eq!(
        r.frame_numbers, expect,
        "frames 1..1000 with one gap 45->54"
    );
    assert_eq!(
        r.drops,
        vec![FrameError::Truncated {
            claimed: 403,
            got: 82
        }],
        "frame 46 truncated"
    );
    assert_eq!(r.bytes_skipped, 82);
    assert_eq!(r.tlv_counts, BTreeMap::from([(6, 992), (7, 984), (8, 984)]));
    assert_eq!(r.points_per_frame.iter().sum::<usize>(), 15_552);
    assert_eq!(r.points_per_frame.iter().min(), Some(&1));
    assert_eq!(r.points_per_frame.iter().max(), Some(&78));
    assert_eq!(r.tlv_decode_errors, 0);
    assert!(r.all_points_finite);
}

#[test]
fn xwr16xx_sdk20_vital_signs_passes_lab_tlvs_through() {
    let Some(r) = decode_capture("xwr16xx_sdk2.0_vital_signs.bin") else {
        return;
    };
    assert_eq!(r.frame_numbers, contiguous(131, 378), "248 frames 131..378");
    assert_eq!(r.tlv_counts, BTreeMap::from([(2, 248), (6, 248)]));
    assert!(
        r.points_per_frame.iter().all(|&n| n == 0),
        "lab payloads are never read as points"
    );
    assert_eq!(
        r.tlv_decode_errors,
        2 * 248,
        "types 6 and 2 do not fit the OOB layouts: passed through raw"
    );
    assert_eq!((r.frames_bad, r.bytes_skipped), (0, 0));
}

#[test]
fn xwr16xx_sdk30_truncated_frames_are_all_reported() {
    let Some(r) = decode_capture("xwr16xx_sdk3.0_vital_signs_truncated_frames.bin") else {
        return;
    };
    assert!(
        r.frame_numbers.is_empty(),
        "no frame of this capture is whole"
    );
    assert_eq!(r.drops.len(), 3096, "one drop per magic word in the file");
    assert!(r
        .drops
        .iter()
        .all(|d| matches!(d, FrameError::Truncated { claimed: 288, .. })));
    assert_eq!(r.bytes_skipped, 792_064);
}

/// Each frame's points' radial velocities \[m/s\], decoded at once.
fn radial_velocities(name: &str) -> Option<Vec<Vec<f32>>> {
    let dir = captures_dir("ti-mmwave")?;
    let data = std::fs::read(dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let mut input = &data[..];
    let mut frames = Vec::new();
    loop {
        match framer.poll(&mut input) {
            Poll::Frame(f) => frames.push(
                PointCloud::from_frame(&f, None)
                    .points
                    .iter()
                    .map(|p| p.velocity)
                    .collect(),
            ),
            Poll::Dropped { .. } => {}
            Poll::NeedMore => break,
        }
    }
    Some(frames)
}

#[test]
fn the_doppler_step_of_real_captures_is_read_from_their_points() {
    use milliego_odometry::ego_velocity::Detection;
    use milliego_odometry::lattice::{DopplerLattice, LATTICE_TOLERANCE};
    // The OOB demo reports bin x resolution; the people-counting lab's compressed points are
    // multiples of their own unit, close to (not exactly) multiples of a step.
    for name in [
        "xwr68xx_sdk3.3_automated_doors.dat",
        "xwr68xx_sdk3.5_people_counting_3d.bin",
    ] {
        let Some(frames) = radial_velocities(name) else {
            return;
        };
        let mut lattice = DopplerLattice::new();
        for f in &frames {
            let dets: Vec<Detection> = f
                .iter()
                .map(|&v| Detection {
                    position: [0.0, 1.0, 0.0],
                    radial_velocity: v,
                })
                .collect();
            lattice.observe(&dets);
        }
        let step = lattice.step().unwrap_or_else(|| panic!("{name}: no step"));
        let all: Vec<f64> = frames
            .iter()
            .flatten()
            .map(|v| f64::from(v.abs()))
            .filter(|&v| v > 1e-4)
            .collect();
        let smallest = all.iter().copied().fold(f64::INFINITY, f64::min);
        let on = all
            .iter()
            .filter(|&&v| ((v / step) - (v / step).round()).abs() <= LATTICE_TOLERANCE)
            .count();
        println!(
            "{name}: step {step:.5} m/s, smallest |v| {smallest:.5} m/s, {on} of {} non-zero values on it",
            all.len()
        );
        // The first bin is in both captures: the step is the smallest value, and (nearly)
        // every value of the whole capture is on it, not only the last ones it looked at.
        assert!((step - smallest).abs() < 0.005 * smallest, "{name}");
        assert!(on * 100 >= all.len() * 99, "{name}");
    }
}
