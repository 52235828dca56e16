//! Recording from pseudo-terminals fed by a replay: the recorded bytes equal the session's, the
//! index is valid, a stall shows in it, and a port that disappears ends the recording with an
//! error naming it (the bytes read until then are still saved).
#![cfg(unix)]

mod common;

use common::*;
use milliego_hil::schedule;
use milliego_hil::{
    record, replay, HilError, Live, Pacing, PortFault, RecordConfig, RecordReport, ReplayOptions,
    Sink, StreamKind,
};
use milliego_session::Session;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

/// Replays `session` into ptys while `record` reads their slaves into `out`; stops the recorder
/// once it has read every byte the replay wrote (or after a grace period when a port fails).
fn replay_and_record(
    session: &Path,
    out: &Path,
    opts: ReplayOptions,
    queue_chunks: usize,
) -> (Result<RecordReport, HilError>, milliego_hil::ReplayReport) {
    let s = Session::open(session).unwrap();
    let schedules = schedule::build(&s, None, None).unwrap();
    let sinks = vec![
        Sink::pty(StreamKind::Radar).unwrap(),
        Sink::pty(StreamKind::Imu).unwrap(),
    ];
    let stop = Arc::new(AtomicBool::new(false));
    let cfg = RecordConfig {
        out: out.to_path_buf(),
        radar: Some(milliego_hil::RadarPorts {
            data: sinks[0].path().to_string(),
            data_baud: 921_600,
            cli: None,
            cfg: None,
        }),
        imu: Some(milliego_hil::ImuPort {
            path: sinks[1].path().to_string(),
            baud: 115_200,
            rate_hz: 100,
        }),
        configure: false,
        stop: stop.clone(),
        queue_chunks,
        ..RecordConfig::default()
    };
    let live = Arc::new(Live::default());
    let rec = {
        let live = live.clone();
        thread::spawn(move || record(&cfg, &live))
    };
    for s in &sinks {
        assert!(
            s.wait_open(Some(Duration::from_secs(5)), &|| false),
            "the recorder did not open {}",
            s.path()
        );
    }
    let (report, sinks) = replay(schedules, sinks, &opts).unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline && !rec.is_finished() {
        let all = report
            .streams
            .iter()
            .all(|r| live.stream(r.stream).bytes_read.load(Ordering::SeqCst) >= r.bytes_written);
        if all {
            break;
        }
        thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, Ordering::SeqCst);
    let result = rec.join().unwrap();
    drop(sinks);
    (result, report)
}

fn session_dir(dir: &Path) -> PathBuf {
    synthetic_session(&dir.join("src"), 2.0)
}

#[test]
fn recording_a_replay_reproduces_the_session_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let src = session_dir(dir.path());
    let out = dir.path().join("rec");
    let opts = ReplayOptions {
        pacing: Pacing::Speed(10.0),
        ..ReplayOptions::default()
    };
    let (rec, _) = replay_and_record(&src, &out, opts, 1024);
    let rec = rec.unwrap();
    for r in &rec.streams {
        assert_eq!(r.bytes_read, r.bytes_written);
        assert_eq!(r.queue_full, 0);
    }
    for (name, kind) in [
        ("radar.bin", StreamKind::Radar),
        ("imu.bin", StreamKind::Imu),
    ] {
        let got = std::fs::read(out.join(name)).unwrap();
        assert!(got == stream_bytes(&src, kind), "{name} differs");
    }
    let s = Session::open(&out).unwrap();
    for st in [s.radar.unwrap(), s.imu.unwrap()] {
        let idx = st.index.as_ref().expect("an index");
        assert!(!idx.is_empty());
        assert_eq!(idx.last().unwrap().end, st.len, "{:?}", st.kind);
    }
    assert_eq!(s.meta.source, milliego_session::Source::Recorded);
    // The live decode on the writer side saw every frame.
    let r = rec
        .streams
        .iter()
        .find(|r| r.stream == StreamKind::Radar)
        .unwrap();
    assert_eq!(r.frames_ok, 20);
    assert_eq!(r.frames_bad + r.bytes_skipped, 0);
    let i = rec
        .streams
        .iter()
        .find(|r| r.stream == StreamKind::Imu)
        .unwrap();
    assert_eq!(i.frames_ok, 200);
}

#[test]
fn recording_a_bare_capture_replay_reproduces_its_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let Some(src) = capture_session(&dir.path().join("src"), usize::MAX) else {
        return;
    };
    let out = dir.path().join("rec");
    let opts = ReplayOptions {
        pacing: Pacing::Speed(10.0),
        ..ReplayOptions::default()
    };
    let (rec, _) = replay_and_record(&src, &out, opts, 1024);
    rec.unwrap();
    let s = Session::open(&src).unwrap();
    let want_radar = s.radar.unwrap().read_all().unwrap();
    let want_imu = s.imu.unwrap().read_all().unwrap();
    assert!(std::fs::read(out.join("radar.bin")).unwrap() == want_radar);
    assert!(std::fs::read(out.join("imu.bin")).unwrap() == want_imu);
}

#[test]
fn a_stalled_stream_shows_as_a_gap_in_the_recorded_index() {
    let dir = tempfile::tempdir().unwrap();
    let src = session_dir(dir.path());
    let out = dir.path().join("rec");
    let opts = ReplayOptions {
        pacing: Pacing::Speed(2.0),
        faults: milliego_hil::FaultPlan {
            // 1.2 s of session time = 0.6 s of wall time at 2x.
            stalls: vec![PortFault {
                stream: StreamKind::Imu,
                at_s: 1.0,
                dur_s: 1.2,
            }],
            ..Default::default()
        },
        ..ReplayOptions::default()
    };
    let (rec, rep) = replay_and_record(&src, &out, opts, 1024);
    rec.unwrap();
    assert_eq!(rep.stream(StreamKind::Imu).unwrap().faults.stalls, 1);
    let s = Session::open(&out).unwrap();
    let max_gap = |idx: &[milliego_session::IndexEntry]| {
        idx.windows(2)
            .map(|w| w[1].host_ns - w[0].host_ns)
            .max()
            .unwrap_or(0)
    };
    let imu_gap = max_gap(s.imu.as_ref().unwrap().index.as_ref().unwrap());
    let radar_gap = max_gap(s.radar.as_ref().unwrap().index.as_ref().unwrap());
    // IMU messages come every 5 ms of wall time, radar frames every 50 ms; the stall is 600 ms
    // (generous bounds: a late read before the stall shortens the gap a little).
    assert!(imu_gap >= 450_000_000, "imu gap {imu_gap} ns");
    assert!(radar_gap < 300_000_000, "radar gap {radar_gap} ns");
    // Nothing lost: the stall only delays.
    assert!(std::fs::read(out.join("imu.bin")).unwrap() == stream_bytes(&src, StreamKind::Imu));
}

#[test]
fn a_port_that_disappears_ends_the_recording_with_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let src = session_dir(dir.path());
    let out = dir.path().join("rec");
    let opts = ReplayOptions {
        pacing: Pacing::Speed(4.0),
        faults: milliego_hil::FaultPlan {
            reopens: vec![PortFault {
                stream: StreamKind::Radar,
                at_s: 1.0,
                dur_s: 0.0,
            }],
            ..Default::default()
        },
        ..ReplayOptions::default()
    };
    let (rec, _) = replay_and_record(&src, &out, opts, 1024);
    let err = rec.expect_err("the radar port went away");
    let msg = err.to_string();
    println!("{msg}");
    match &err {
        HilError::Port { stream, path, .. } => {
            assert_eq!(*stream, StreamKind::Radar);
            assert!(path.starts_with("/dev/"), "{path}");
            assert!(msg.contains(path.as_str()), "{msg}");
        }
        other => panic!("expected a port error, got {other:?}"),
    }
    // What was read before is saved as a valid session.
    let s = Session::open(&out).unwrap();
    let radar = s.radar.unwrap();
    assert!(radar.len > 0);
    let want = stream_bytes(&src, StreamKind::Radar);
    let got = radar.read_all().unwrap();
    assert!(
        want.starts_with(&got),
        "the saved radar bytes are a prefix of the session"
    );
}

#[test]
fn nothing_to_record_and_missing_ports_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let live = Arc::new(Live::default());
    let e = record(
        &RecordConfig {
            out: dir.path().join("a"),
            ..RecordConfig::default()
        },
        &live,
    )
    .unwrap_err();
    assert!(e.to_string().contains("nothing to record"), "{e}");
    let e = record(
        &RecordConfig {
            out: dir.path().join("b"),
            imu: Some(milliego_hil::ImuPort {
                path: "/dev/does-not-exist-42".into(),
                baud: 115_200,
                rate_hz: 100,
            }),
            configure: false,
            ..RecordConfig::default()
        },
        &live,
    )
    .unwrap_err();
    let m = e.to_string();
    assert!(
        m.contains("/dev/does-not-exist-42") && m.contains("open"),
        "{m}"
    );
}

#[test]
fn a_one_chunk_queue_still_loses_nothing() {
    // The readers block on the full queue (counted) instead of dropping.
    let dir = tempfile::tempdir().unwrap();
    let src = session_dir(dir.path());
    let out = dir.path().join("rec");
    let opts = ReplayOptions {
        pacing: Pacing::Fast,
        ..ReplayOptions::default()
    };
    let (rec, _) = replay_and_record(&src, &out, opts, 1);
    let rec = rec.unwrap();
    for r in &rec.streams {
        assert_eq!(r.bytes_read, r.bytes_written);
        println!(
            "{:?}: queue full {}x, longest wait {} us",
            r.stream,
            r.queue_full,
            r.max_wait_ns / 1000
        );
    }
    for (name, kind) in [
        ("radar.bin", StreamKind::Radar),
        ("imu.bin", StreamKind::Imu),
    ] {
        assert!(
            std::fs::read(out.join(name)).unwrap() == stream_bytes(&src, kind),
            "{name}"
        );
    }
}
