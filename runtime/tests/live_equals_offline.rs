//! The live reader and the offline session decoder publish the same radar frames from the same
//! bytes: a simulated session is replayed by the HIL rig, with bytes dropped on the wire, into a
//! real pseudo-terminal; the runtime's reader reads it as it would a UART, and what it read is
//! recorded as a session (bytes and read times) and decoded offline. Frames that lost a byte and
//! ended inside the next frame's magic word are retracted by the framer: neither path may publish
//! them.

use milliego_hil::{replay, FaultPlan, Pacing, ReplayOptions, Sink, StreamKind};
use milliego_runtime::reader::{read_loop, RadarDecoder, RadarItem, ReaderCtx, ReaderStats};
use milliego_runtime::reader::{SerialSource, Source};
use milliego_session::streams::radar_frames;
use milliego_session::{Session, SessionWriter};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use radar_driver::cfg::RadarConfig;
use radar_driver::host::DecoderConfig;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What the live reader published and what it read.
struct Live {
    frames: Vec<(u32, usize)>,
    chunks: Vec<(u64, Vec<u8>)>,
    retracted: u64,
    held: u64,
}

/// Runs the replay into the live reader; returns what it published and the offsets (in the
/// session's radar data) of the bytes that did not reach it, with the frame start offsets.
fn live_run(s: &Session, plan: FaultPlan) -> (Live, Vec<u64>, Vec<u64>) {
    let schedules: Vec<_> = milliego_hil::schedule::build(s, None, None)
        .unwrap()
        .into_iter()
        .filter(|sc| sc.kind == StreamKind::Radar)
        .collect();
    let baud = schedules[0].baud;
    let frame_starts = schedules[0].frame_starts.clone();
    let sink = Sink::pty(StreamKind::Radar).unwrap();
    let mut src = SerialSource {
        path: sink.path().to_string(),
        baud,
    };
    let port = src.open().unwrap();
    let cfg = s
        .radar_cfg()
        .unwrap()
        .and_then(|t| RadarConfig::parse(&t).ok())
        .and_then(|c| c.derive(None).ok());
    let stop = Arc::new(AtomicBool::new(false));
    let stats = Arc::new(ReaderStats::default());
    let ctx = ReaderCtx {
        epoch: Instant::now(),
        stop: Arc::clone(&stop),
        stats: Arc::clone(&stats),
        backoff: Duration::from_millis(20),
        max_backoff: Duration::from_millis(200),
    };
    let live = Arc::new(Mutex::new(Live {
        frames: Vec::new(),
        chunks: Vec::new(),
        retracted: 0,
        held: 0,
    }));
    let l2 = Arc::clone(&live);
    let reader = std::thread::spawn(move || {
        let mut dec = RadarDecoder::new(DecoderConfig::from_derived(cfg.as_ref()));
        let mut src = src;
        read_loop(&mut src, Some(port), &ctx, |bytes, _host_s, ns, _| {
            let mut l = l2.lock().unwrap();
            l.chunks.push((ns, bytes.to_vec()));
            dec.feed(bytes, ns as f64 * 1e-9, ns, |fill| {
                let mut it = RadarItem::default();
                fill(&mut it);
                l.frames.push((it.frame_number, it.points.len()));
            });
            let p = dec.report();
            (l.retracted, l.held) = (p.plausibility.retracted, p.held);
        });
    });
    let opts = ReplayOptions {
        pacing: Pacing::Speed(2.0),
        faults: plan,
        ..ReplayOptions::default()
    };
    let (report, sinks) = replay(schedules, vec![sink], &opts).unwrap();
    let written = report.stream(StreamKind::Radar).unwrap().bytes_written;
    let deadline = Instant::now() + Duration::from_secs(10);
    while stats.bytes.load(Ordering::Relaxed) < written && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, Ordering::Relaxed);
    reader.join().unwrap();
    drop(sinks);
    let lost: Vec<u64> = report
        .stream(StreamKind::Radar)
        .unwrap()
        .events
        .iter()
        .filter(|e| e.kind == milliego_hil::FaultKind::Drop)
        .map(|e| e.offset)
        .collect();
    let live = Arc::into_inner(live).unwrap().into_inner().unwrap();
    (live, lost, frame_starts)
}

#[test]
fn a_live_replay_with_dropped_bytes_publishes_the_frames_the_offline_run_publishes() {
    let dir = tempfile::tempdir().unwrap();
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 5);
    sc.duration_s = 8.0;
    simulate(&sc, dir.path(), &mut |_| {}).expect("simulate");
    let s = Session::open(dir.path()).unwrap();
    let (clean, _) = radar_frames(&s).unwrap();

    let plan = FaultPlan {
        drop: 1.5e-3,
        seed: 7,
        ..FaultPlan::default()
    };
    let (live, lost, starts) = live_run(&s, plan);
    let dropped = lost.len();

    // What the reader read, as a recorded session: the same bytes, chunked as read.
    let rec_dir = dir.path().join("recorded");
    let mut meta = s.meta.clone();
    (meta.imu, meta.groundtruth) = (None, None);
    let mut w = SessionWriter::create(&rec_dir, meta).unwrap();
    if let Some(t) = s.radar_cfg().unwrap() {
        w.radar_cfg(&t).unwrap();
    }
    let mut sw = w.stream(StreamKind::Radar).unwrap();
    for (ns, b) in &live.chunks {
        sw.write_chunk(*ns, b).unwrap();
    }
    sw.finish().unwrap();
    w.finish().unwrap();
    let rec = Session::open(&rec_dir).unwrap();
    let (offline, rep) = radar_frames(&rec).unwrap();
    let offline: Vec<(u32, usize)> = offline
        .iter()
        .map(|f| (f.frame_number, f.cloud.points.len()))
        .collect();
    eprintln!(
        "{} bytes dropped; live {} frames, offline {} (clean {}); retracted {} live / {} offline, \
         held {}",
        dropped,
        live.frames.len(),
        offline.len(),
        clean.len(),
        live.retracted,
        rep.retracted,
        live.held,
    );
    // The faults did what this test is about: frames lost bytes and some were retracted.
    assert!(dropped > 0 && offline.len() < clean.len());
    assert!(
        rep.retracted >= 1,
        "no frame was retracted: pick another seed"
    );
    assert_eq!(live.frames, offline);
    assert_eq!((live.retracted, live.held), (rep.retracted, rep.held));
    // Exactly the frames that reached the reader whole are published.
    assert_eq!(
        clean.len(),
        starts.len(),
        "the clean session decodes every frame"
    );
    let hit = |i: usize| {
        let end = starts.get(i + 1).copied().unwrap_or(u64::MAX);
        lost.iter().any(|&o| (starts[i]..end).contains(&o))
    };
    let whole: Vec<(u32, usize)> = clean
        .iter()
        .enumerate()
        .filter(|&(i, _)| !hit(i))
        .map(|(_, f)| (f.frame_number, f.cloud.points.len()))
        .collect();
    assert_eq!(offline, whole);
}
