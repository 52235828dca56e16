//! Shared by the HIL tests: sessions made with the encoders, excerpts of the real captures, direct
//! decoding of the files, and reading frames back from a pty slave through the drivers.
#![allow(dead_code)]

use imu_driver::{DataId, LogFramer, MtData2Writer, Value};
use milliego_hil::{Sink, StreamKind};
use milliego_session::{Meta, Session, SessionWriter, Source};
use radar_driver::encode::FrameBuilder;
use radar_driver::host::{FrameReader, ReadEvent};
use radar_driver::{Framer, LayoutHint, Poll, DEFAULT_MAX_FRAME};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Radar frame period of the generated sessions \[s\].
pub const RADAR_PERIOD: f64 = 0.1;
/// IMU period \[s\].
pub const IMU_PERIOD: f64 = 0.01;

/// One radar frame of the generated stream.
pub fn radar_frame(n: u32) -> Vec<u8> {
    let k = (n % 7) as usize + 1;
    let pts: Vec<[f32; 4]> = (0..k)
        .map(|i| [i as f32 * 0.5, 2.0 + n as f32 * 0.01, 0.1, -0.3])
        .collect();
    let frame = FrameBuilder::oob(0x0303_0002, 0xA6843, n)
        .cycles(n.wrapping_mul(20_000_000))
        .points(&pts)
        .to_vec();
    frame
}

/// One IMU MTData2 message of the generated stream.
pub fn imu_msg(n: u16) -> Vec<u8> {
    let mut buf = [0u8; 128];
    let mut w = MtData2Writer::new(&mut buf);
    w.value(DataId(0x1020), &Value::PacketCounter(n)).unwrap();
    w.value(DataId(0x1060), &Value::SampleTimeFine(u32::from(n) * 100))
        .unwrap();
    w.value(DataId(0x4020), &Value::Acceleration([0.1, -0.2, 9.81]))
        .unwrap();
    w.value(DataId(0x8020), &Value::RateOfTurn([0.01, 0.02, -0.03]))
        .unwrap();
    let len = w.finish(0xFF).unwrap();
    buf[..len].to_vec()
}

/// Writes a recorded-like session of `seconds` with a timing index: a radar frame every 100 ms
/// (first at 50 ms) and an IMU message every 10 ms, each read as one chunk at its time.
pub fn synthetic_session(dir: &Path, seconds: f64) -> PathBuf {
    let mut w = SessionWriter::create(dir, Meta::new(Source::Simulated)).unwrap();
    let mut radar = w.stream(StreamKind::Radar).unwrap();
    let mut imu = w.stream(StreamKind::Imu).unwrap();
    let frames = (seconds / RADAR_PERIOD) as u32;
    for n in 0..frames {
        let t = ((n as f64 + 0.5) * RADAR_PERIOD * 1e9) as u64;
        radar.write_chunk(t, &radar_frame(n + 1)).unwrap();
    }
    let msgs = (seconds / IMU_PERIOD) as u16;
    for n in 0..msgs {
        let t = ((n as f64 + 1.0) * IMU_PERIOD * 1e9) as u64;
        imu.write_chunk(t, &imu_msg(n)).unwrap();
    }
    radar.finish().unwrap();
    imu.finish().unwrap();
    w.finish().unwrap()
}

/// A directory of bare captures (no index): the first `radar_bytes` of the TI .dat (cut at a
/// frame end) and the first Xsens log, or `None` (with a skip line) without the captures.
pub fn capture_session(dir: &Path, radar_frames: usize) -> Option<PathBuf> {
    let ti = milliego_tests::captures_dir("ti-mmwave")?;
    let xs = milliego_tests::captures_dir("xsens")?;
    let dat = std::fs::read(ti.join("xwr68xx_sdk3.3_automated_doors.dat")).unwrap();
    let frames = radar_frames_of(&dat);
    let cut: usize = frames.iter().take(radar_frames).map(Vec::len).sum();
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("radar.dat"), &dat[..cut]).unwrap();
    std::fs::copy(xs.join("mti-g-710_1/output.bin"), dir.join("imu.mtb")).unwrap();
    Some(dir.to_path_buf())
}

/// Radar frames of a byte stream, decoded directly.
pub fn radar_frames_of(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut f: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let mut input = bytes;
    let mut out = Vec::new();
    loop {
        match f.poll(&mut input) {
            Poll::Frame(fr) => out.push(fr.as_bytes().to_vec()),
            Poll::Dropped {
                error: radar_driver::FrameError::OverlapsNextFrame { .. },
                ..
            } => {
                out.pop();
            }
            Poll::Dropped { .. } => {}
            Poll::NeedMore => break,
        }
    }
    out
}

/// Xbus messages of a byte stream, decoded directly.
pub fn imu_frames_of(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut f: Box<LogFramer> = Box::default();
    let mut input = bytes;
    let mut out = Vec::new();
    loop {
        match f.poll(&mut input) {
            imu_driver::Poll::Frame(fr) => out.push(fr.as_bytes().to_vec()),
            imu_driver::Poll::Dropped { .. } => {}
            imu_driver::Poll::NeedMore => break,
        }
    }
    out
}

/// The bytes of one stream of a session.
pub fn stream_bytes(session: &Path, kind: StreamKind) -> Vec<u8> {
    let s = Session::open(session).unwrap();
    match kind {
        StreamKind::Radar => s.radar.unwrap().read_all().unwrap(),
        StreamKind::Imu => s.imu.unwrap().read_all().unwrap(),
    }
}

/// Opens a pty slave the way a system under test does (serialport path).
pub fn open_slave(sink: &Sink) -> Box<dyn serialport::SerialPort> {
    serialport::new(sink.path(), 921_600)
        .timeout(Duration::from_millis(20))
        .open()
        .expect("open the pty slave")
}

/// What a driver saw on a port: good frames and its counters.
#[derive(Debug, Default, Clone)]
pub struct Seen {
    pub frames: Vec<Vec<u8>>,
    /// Host time each frame's last byte was read.
    pub times: Vec<Instant>,
    pub frames_bad: u64,
    pub bytes_skipped: u64,
    pub bytes_in: u64,
}

/// Reads radar frames with the radar driver's `FrameReader` until `idle` passes without data after
/// `done()` turned true, or `limit` passes.
pub fn read_radar(
    port: Box<dyn serialport::SerialPort>,
    done: &dyn Fn() -> bool,
    idle: Duration,
    limit: Duration,
) -> Seen {
    let mut r = FrameReader::new(port, LayoutHint::Auto, 4096);
    let mut seen = Seen::default();
    let t0 = Instant::now();
    let mut last = Instant::now();
    while t0.elapsed() < limit {
        match r.next_event() {
            Ok(Some(ReadEvent::Frame(f))) => {
                seen.frames.push(f.as_bytes().to_vec());
                seen.times.push(f.host_time);
                last = Instant::now();
            }
            Ok(Some(ReadEvent::Dropped { error, .. })) => {
                // A retraction takes back the frame released just before.
                if matches!(error, radar_driver::FrameError::OverlapsNextFrame { .. }) {
                    seen.frames.pop();
                    seen.times.pop();
                }
                last = Instant::now();
            }
            Ok(Some(ReadEvent::Idle)) => {
                if done() && last.elapsed() > idle {
                    break;
                }
            }
            Ok(None) | Err(_) => break,
        }
    }
    let c = r.counters();
    seen.frames_bad = c.frames_bad_total();
    seen.bytes_skipped = c.bytes_skipped;
    seen.bytes_in = c.bytes_in;
    seen
}

/// The same for the IMU with imu-driver's `Reader`.
pub fn read_imu(
    port: Box<dyn serialport::SerialPort>,
    done: &dyn Fn() -> bool,
    idle: Duration,
    limit: Duration,
) -> Seen {
    let mut r: imu_driver::host::Reader<_, { imu_driver::frame_capacity(65535) }> =
        imu_driver::host::Reader::new(port);
    let mut seen = Seen::default();
    let t0 = Instant::now();
    let mut last = Instant::now();
    while t0.elapsed() < limit {
        match r.next_event() {
            Ok(Some(imu_driver::host::Event::Frame { frame, at })) => {
                seen.frames.push(frame.as_bytes().to_vec());
                seen.times.push(at);
                last = Instant::now();
            }
            Ok(Some(imu_driver::host::Event::Dropped { .. })) => last = Instant::now(),
            Ok(None) => break,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                if done() && last.elapsed() > idle {
                    break;
                }
            }
            Err(_) => break,
        }
    }
    let c = r.counters();
    seen.frames_bad = c.frames_bad.total();
    seen.bytes_skipped = c.bytes_skipped;
    seen.bytes_in = c.bytes_in;
    seen
}

/// Reads a port to the end (a helper for tests that only count bytes).
pub fn read_all(mut port: Box<dyn serialport::SerialPort>, idle: Duration) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; 4096];
    let mut last = Instant::now();
    while last.elapsed() < idle {
        match port.read(&mut buf) {
            Ok(n) if n > 0 => {
                out.extend_from_slice(&buf[..n]);
                last = Instant::now();
            }
            _ => {}
        }
    }
    out
}
