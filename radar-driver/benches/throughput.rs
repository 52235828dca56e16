//! Framer + TLV decoder throughput on the real captures, side by side with the `mmwave-tlv`
//! crate decoding the same bytes in the same run.
//!
//! Run: `cargo bench -p radar-driver --bench throughput` (captures from ../shared/captures or
//! $MILLIEGO_CAPTURES). Prints MB/s per capture and the ratio ours / peer; timings are medians of
//! interleaved rounds, so a noisy shared machine affects both sides alike.

use radar_driver::host::PointCloud;
use radar_driver::{Framer, Poll, DEFAULT_MAX_FRAME};
use std::hint::black_box;
use std::time::{Duration, Instant};

const CHUNK: usize = 4096;
const ROUNDS: usize = 7;

/// Ours: frame in 4 KiB chunks, decode every TLV into a point cloud reused from frame to frame
/// (`decode_into`, the runtime's path: no allocation once it has grown; the peer's API allocates
/// per frame).
fn ours(data: &[u8]) -> (usize, usize) {
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let (mut frames, mut points) = (0, 0);
    let mut c = PointCloud::default();
    for chunk in data.chunks(CHUNK) {
        let mut input = chunk;
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => {
                    c.decode_into(&f, None);
                    frames += 1;
                    points += black_box(&c).points.len();
                }
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
    }
    (frames, points)
}

/// Peer: mmwave-tlv's stream reader over the same bytes (4 KiB reads inside).
fn peer(data: &[u8]) -> (usize, usize) {
    use mmwave_tlv::prelude::*;
    let mut r = FrameStreamReader::new(std::io::Cursor::new(data));
    let (mut frames, mut points) = (0, 0);
    while let Ok(Some(f)) = r.read_frame::<Vec<StandardTlv>>() {
        frames += 1;
        for t in &black_box(f).payload {
            if let StandardTlv::PointCloud(c) = t {
                points += c.0.len();
            }
        }
    }
    (frames, points)
}

fn time(f: impl Fn() -> (usize, usize), min: Duration) -> (f64, (usize, usize)) {
    let start = Instant::now();
    let mut iters = 0u32;
    let mut out = (0, 0);
    while start.elapsed() < min {
        out = f();
        iters += 1;
    }
    (start.elapsed().as_secs_f64() / f64::from(iters), out)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let Some(dir) = milliego_tests::captures_dir("ti-mmwave") else {
        return;
    };
    let min = Duration::from_millis(150);
    println!(
        "{:<52} {:>8} {:>8} {:>10} {:>10} {:>7}",
        "capture", "frames", "points", "ours MB/s", "peer MB/s", "ratio"
    );
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_default();
    names.retain(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("dat" | "bin")));
    names.sort();
    for path in names {
        let data = std::fs::read(&path).expect("capture readable");
        let mb = data.len() as f64 / 1e6;
        // The peer reads the 40-byte out-of-box header only; compare where it decodes the capture.
        let peer_ok = peer(&data) == ours(&data) && ours(&data).0 > 0;
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let mut counts = (0, 0);
        for _ in 0..ROUNDS {
            let (t, c) = time(|| ours(&data), min);
            a.push(t);
            counts = c;
            if peer_ok {
                b.push(time(|| peer(&data), min).0);
            }
        }
        let ours_mbs = mb / median(a);
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if peer_ok {
            let peer_mbs = mb / median(b);
            println!(
                "{name:<52} {:>8} {:>8} {ours_mbs:>10.1} {peer_mbs:>10.1} {:>7.2}",
                counts.0,
                counts.1,
                ours_mbs / peer_mbs
            );
        } else {
            println!(
                "{name:<52} {:>8} {:>8} {ours_mbs:>10.1} {:>10} {:>7}",
                counts.0, counts.1, "n/a", "n/a"
            );
        }
    }
    println!("ratio = ours / peer throughput (higher is better); n/a = the peer does not decode that capture the same way");
}
