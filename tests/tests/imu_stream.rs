//! The real captures as a serial port delivers them: random chunking with fixed seeds, byte by
//! byte, concatenated with noise and corruption; plausibility checks on real and doctored data.

use imu_driver::time::{Checker, Flags, MessageKind, TimeWrap};
use imu_driver::{Counters, DeviceFramer, Framer, LogFramer, Message, MtData2, Poll};
use milliego_tests::SeededChunks;
use rand::{rngs::StdRng, Rng, SeedableRng};
use std::fs;

fn captures() -> Option<Vec<Vec<u8>>> {
    let root = milliego_tests::captures_dir("xsens")?;
    let mut dirs: Vec<_> = fs::read_dir(root)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("output.bin").is_file())
        .collect();
    dirs.sort();
    Some(
        dirs.iter()
            .map(|d| fs::read(d.join("output.bin")).unwrap())
            .collect(),
    )
}

/// (offset, bid, mid, payload) of every frame, and the counters, for a chunking of `data`.
type Frames = Vec<(u8, u8, Vec<u8>)>;

fn run<const N: usize>(
    framer: &mut Framer<N>,
    chunks: impl Iterator<Item = Vec<u8>>,
) -> (Frames, Counters) {
    let mut frames = Vec::new();
    for chunk in chunks {
        let mut input = &chunk[..];
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => frames.push((f.bid(), f.mid(), f.payload().to_vec())),
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
        assert!(input.is_empty());
        let c = framer.counters();
        assert_eq!(
            c.frame_bytes + c.bytes_skipped + framer.buffered() as u64,
            c.bytes_in,
            "byte accounting"
        );
    }
    framer.finish();
    (frames, *framer.counters())
}

#[test]
fn random_chunkings_give_the_same_frames_as_one_read() {
    let Some(caps) = captures() else { return };
    let all: Vec<u8> = caps.concat();
    let (reference, rc) = run(&mut LogFramer::new(), std::iter::once(all.clone()));
    assert_eq!(reference.len(), 500);
    assert_eq!(
        (rc.frames_ok, rc.bytes_skipped, rc.frames_bad.total()),
        (500, 0, 0)
    );
    for (seed, max_chunk) in [
        (1u64, 1usize),
        (2, 7),
        (3, 64),
        (4, 300),
        (5, 4096),
        (6, 100_000),
    ] {
        let chunks = SeededChunks::new(&all, seed, max_chunk).map(<[u8]>::to_vec);
        let (frames, c) = run(&mut DeviceFramer::new(), chunks);
        assert_eq!(frames, reference, "seed {seed} max chunk {max_chunk}");
        assert_eq!(c.bytes_in, all.len() as u64);
        assert_eq!(c.bytes_skipped, 0);
    }
}

/// Frames of the clean stream with their byte ranges.
fn frame_ranges(data: &[u8]) -> Vec<(usize, usize)> {
    let mut framer = LogFramer::new();
    let mut input = data;
    let mut out = Vec::new();
    loop {
        let before = data.len() - input.len();
        match framer.poll(&mut input) {
            Poll::Frame(f) => out.push((before, before + f.as_bytes().len())),
            Poll::Dropped { .. } => {}
            Poll::NeedMore => break,
        }
    }
    out
}

#[test]
fn corruption_loses_only_the_touched_frames() {
    let Some(caps) = captures() else { return };
    let clean: Vec<u8> = caps.concat();
    let ranges = frame_ranges(&clean);
    let mut rng = StdRng::seed_from_u64(0x5EED);
    let mut dirty = clean.clone();
    let mut touched = vec![false; ranges.len()];
    for _ in 0..60 {
        let at = rng.gen_range(0..dirty.len());
        dirty[at] ^= rng.gen_range(1..=255u8);
        if let Some(i) = ranges.iter().position(|(s, e)| (*s..*e).contains(&at)) {
            touched[i] = true;
        }
    }
    let untouched: Vec<Vec<u8>> = ranges
        .iter()
        .zip(&touched)
        .filter(|(_, t)| !**t)
        .map(|((s, e), _)| clean[*s..*e].to_vec())
        .collect();
    let chunks = SeededChunks::new(&dirty, 9, 512).map(<[u8]>::to_vec);
    let mut framer = DeviceFramer::new();
    let mut found: Vec<Vec<u8>> = Vec::new();
    for chunk in chunks {
        let mut input = &chunk[..];
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => found.push(f.as_bytes().to_vec()),
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
    }
    framer.finish();
    let c = framer.counters();
    assert!(c.frames_bad.checksum > 0 && c.resyncs > 0);
    let false_frames = found
        .iter()
        .filter(|f| !clean.windows(f.len()).any(|w| w == &f[..]))
        .count();
    let missing = untouched.iter().filter(|u| !found.contains(u)).count();
    // One-byte resync finds every intact frame unless a false frame (a checksum passed by
    // chance, ~1/256 per candidate) swallowed it.
    assert!(
        missing <= 2 * false_frames,
        "{missing} intact frames lost, {false_frames} false frames"
    );
    assert!(found.len() + touched.iter().filter(|t| **t).count() >= untouched.len());
}

#[test]
fn real_captures_are_plausible_and_gnss_time_runs_on_its_own_track() {
    let Some(caps) = captures() else { return };
    let mut gnss_messages = 0;
    for cap in &caps {
        let mut checker = Checker::new(TimeWrap::Pow32);
        let mut framer = LogFramer::new();
        let mut input = &cap[..];
        let mut inertial_times = Vec::new();
        while let Poll::Frame(f) = framer.poll(&mut input) {
            let Ok(Message::MtData2(m)) = Message::decode(&f) else {
                panic!()
            };
            let s = m.sample();
            let checked = checker.check(&s);
            assert!(
                checked.flags.is_clean(),
                "real message flagged {:?}: {s:?}",
                checked.flags.names().collect::<Vec<_>>()
            );
            match checked.kind {
                MessageKind::GnssPvt | MessageKind::GnssSatInfo => gnss_messages += 1,
                _ => inertial_times.push(checked.time_ticks.unwrap()),
            }
        }
        assert!(inertial_times.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(checker.counters().gaps, 0);
    }
    assert!(gnss_messages > 0);
}

/// The first frame of the first capture, doctored and re-sealed so the checksum passes.
fn doctored(edit: impl Fn(&mut [u8], &MtData2<'_>)) -> Vec<u8> {
    let caps = captures().unwrap();
    let mut framer = LogFramer::new();
    let mut input = &caps[0][..];
    let Poll::Frame(f) = framer.poll(&mut input) else {
        panic!()
    };
    let mut raw = f.as_bytes().to_vec();
    let payload = f.payload().to_vec();
    let header = raw.len() - payload.len() - 1;
    let m = MtData2::new(&payload);
    edit(&mut raw[header..header + payload.len()], &m);
    let n = raw.len();
    raw[n - 1] = raw[1..n - 1]
        .iter()
        .fold(0u8, |a, b| a.wrapping_add(*b))
        .wrapping_neg();
    raw
}

/// Offset in the payload of the data of the first item with kind `name`.
fn item_offset(m: &MtData2<'_>, name: &str) -> usize {
    let mut at = 0;
    for item in m.items() {
        let item = item.unwrap();
        if item.id.kind().name() == name {
            return at + 3;
        }
        at += 3 + item.data.len();
    }
    panic!("no {name}")
}

fn check_after_first(raw_second: &[u8]) -> Flags {
    let caps = captures().unwrap();
    let mut framer = LogFramer::new();
    let mut checker = Checker::new(TimeWrap::Pow32);
    let mut input = &caps[0][..];
    let Poll::Frame(first) = framer.poll(&mut input) else {
        panic!()
    };
    let Ok(Message::MtData2(m)) = Message::decode(&first) else {
        panic!()
    };
    checker.check(&m.sample());
    // The doctored frame stands for the capture's second message.
    let Poll::Frame(_) = framer.poll(&mut input) else {
        panic!()
    };
    let f = imu_driver::XbusFrame::new_checked(raw_second).unwrap();
    let Ok(Message::MtData2(m)) = Message::decode(&f) else {
        panic!()
    };
    checker.check(&m.sample()).flags
}

#[test]
fn frames_the_checksum_lets_through_are_flagged() {
    if captures().is_none() {
        return;
    }
    // Unchanged but for the packet counter +1 and the time +100 ticks: the honest second message.
    let honest = doctored(|p, m| {
        let pc = item_offset(m, "PacketCounter");
        let v = u16::from_be_bytes([p[pc], p[pc + 1]]) + 1;
        p[pc..pc + 2].copy_from_slice(&v.to_be_bytes());
        let t = item_offset(m, "SampleTimeFine");
        let v = u32::from_be_bytes(p[t..t + 4].try_into().unwrap()) + 100;
        p[t..t + 4].copy_from_slice(&v.to_be_bytes());
    });
    assert_eq!(check_after_first(&honest), Flags::NONE);
    // Counter skipping ahead.
    let gap = doctored(|p, m| {
        let pc = item_offset(m, "PacketCounter");
        p[pc] ^= 0x10;
        let t = item_offset(m, "SampleTimeFine");
        let v = u32::from_be_bytes(p[t..t + 4].try_into().unwrap()) + 100;
        p[t..t + 4].copy_from_slice(&v.to_be_bytes());
    });
    assert!(check_after_first(&gap).contains(Flags::COUNTER_GAP));
    // Acceleration exponent byte hit: |a| far beyond full scale.
    let acc = doctored(|p, m| {
        let a = item_offset(m, "Acceleration");
        p[a] = 0x7F;
        p[a + 1] |= 0x80;
    });
    assert!(check_after_first(&acc).contains(Flags::VALUE_RANGE));
    // Same counter and time as the first message: repeat and time not advancing.
    let stale = doctored(|_, _| {});
    let flags = check_after_first(&stale);
    assert!(flags.contains(Flags::COUNTER_BACKWARD) && flags.contains(Flags::TIME_BACKWARD));
}
