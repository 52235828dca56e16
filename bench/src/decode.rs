//! Decoder throughput on the real captures, ours and the peer crate on the same bytes, in
//! interleaved rounds (the loops of radar-driver/benches/throughput.rs and
//! imu-driver/benches/throughput.rs, as library functions).

use crate::report::{median, Better, Row};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const GROUP: &str = "decoders (real captures)";

/// Repetition settings of the decoder rows.
#[derive(Debug, Clone, Copy)]
pub struct Reps {
    /// Interleaved rounds (ours, peer, ours, peer ...); the medians are reported.
    pub rounds: usize,
    /// Minimum time of one round of one side.
    pub min: Duration,
}

fn time_pass<T>(min: Duration, mut f: impl FnMut() -> T) -> f64 {
    let start = Instant::now();
    let mut n = 0u32;
    while n == 0 || start.elapsed() < min {
        black_box(f());
        n += 1;
    }
    start.elapsed().as_secs_f64() / f64::from(n)
}

/// Medians of `rounds` interleaved timings of `a` and `b` \[s per pass\].
fn interleaved<A, B>(reps: Reps, mut a: impl FnMut() -> A, mut b: impl FnMut() -> B) -> (f64, f64) {
    let (mut ta, mut tb) = (Vec::new(), Vec::new());
    for _ in 0..reps.rounds.max(1) {
        ta.push(time_pass(reps.min, &mut a));
        tb.push(time_pass(reps.min, &mut b));
    }
    (
        median(&ta).unwrap_or(f64::NAN),
        median(&tb).unwrap_or(f64::NAN),
    )
}

/// Ours: frame in 4 KiB chunks, decode every TLV into a point cloud reused from frame to frame
/// (`decode_into`, the runtime's path: no allocation once it has grown; the peer's API allocates
/// per frame).
pub fn radar_ours(data: &[u8]) -> (usize, usize) {
    use radar_driver::host::PointCloud;
    use radar_driver::{Framer, Poll, DEFAULT_MAX_FRAME};
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let (mut frames, mut points) = (0, 0);
    let mut c = PointCloud::default();
    for chunk in data.chunks(4096) {
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

/// Peer: mmwave-tlv's stream reader over the same bytes.
pub fn radar_peer(data: &[u8]) -> (usize, usize) {
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

fn files(dir: &Path, keep: impl Fn(&Path) -> Option<PathBuf>) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok())
                .filter_map(|e| keep(&e.path()))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Radar row: every TI capture both decoders read the same way (equal frame and point counts),
/// concatenated per capture into one MB/s figure each side.
pub fn radar_rows(reps: Reps) -> Vec<Row> {
    let name = "radar framer+TLV decoder";
    let Some(dir) = milliego_tests::captures_dir("ti-mmwave") else {
        return vec![Row::missing(GROUP, name, "n/a (captures not found)")];
    };
    let paths = files(dir.as_path(), |p| {
        matches!(p.extension().and_then(|e| e.to_str()), Some("dat" | "bin"))
            .then(|| p.to_path_buf())
    });
    let (mut bytes, mut t_ours, mut t_peer) = (0usize, 0.0, 0.0);
    let (mut used, mut skipped, mut frames) = (0, 0, 0);
    for p in &paths {
        let Ok(data) = std::fs::read(p) else { continue };
        let o = radar_ours(&data);
        if o.0 == 0 || radar_peer(&data) != o {
            skipped += 1;
            continue;
        }
        let (a, b) = interleaved(reps, || radar_ours(&data), || radar_peer(&data));
        bytes += data.len();
        t_ours += a;
        t_peer += b;
        used += 1;
        frames += o.0;
    }
    if used == 0 {
        return vec![Row::missing(
            GROUP,
            name,
            "n/a (no capture the peer decodes)",
        )];
    }
    let mb = bytes as f64 / 1e6;
    vec![Row::new(
        GROUP,
        name,
        Some(mb / t_ours),
        "MB/s",
        "mmwave-tlv 0.1.1",
        Some(mb / t_peer),
        Better::Higher,
        &format!(
            "{used} captures, {frames} frames, {:.1} MB; {skipped} skipped (peer decodes them differently)",
            mb
        ),
    )]
}

/// Totals of one Xbus pass (compared between the two sides).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct Pass {
    /// Frames with a good checksum.
    pub messages: u64,
    /// MTData2 items seen.
    pub items: u64,
    /// Items decoded to values.
    pub values: u64,
    /// Dropped frames and undecodable items.
    pub errors: u64,
    /// Sum of the decoded values (keeps the work observable).
    pub sum: f64,
}

type Big = imu_driver::Framer<{ imu_driver::frame_capacity(65_535) }>;

/// Ours: Xbus framer over the whole buffer, every MTData2 item decoded to a value.
pub fn imu_ours(data: &[u8]) -> Pass {
    use imu_driver::{Message, Poll, Value};
    let mut framer = Big::new();
    let mut p = Pass::default();
    let mut input = data;
    loop {
        match framer.poll(&mut input) {
            Poll::Frame(f) => {
                p.messages += 1;
                if let Ok(Message::MtData2(m)) = Message::decode(&f) {
                    for item in m.items() {
                        p.items += 1;
                        match item.and_then(|i| i.value()) {
                            Ok(v) => {
                                p.values += 1;
                                p.sum += match v {
                                    Value::PacketCounter(c) => f64::from(c),
                                    Value::SampleTimeFine(t) => f64::from(t),
                                    other => other.floats().iter().sum(),
                                };
                            }
                            Err(_) => p.errors += 1,
                        }
                    }
                }
            }
            Poll::Dropped { .. } => p.errors += 1,
            Poll::NeedMore => break,
        }
    }
    p
}

/// The values `xsens-mti` has types for (Float32, Float64, raw fixed-point words).
fn peer_item(pkt: &xsens_mti::wire::MTData2Packet<&[u8]>, p: &mut Pass) -> Result<(), ()> {
    use xsens_mti::prelude as x;
    use xsens_mti::prelude::{DataType as T, Precision as P};
    let d = pkt.payload();
    let id = pkt.data_id();
    macro_rules! vec3 {
        ($t:ident, $a:ident, $b:ident, $c:ident) => {
            match id.precision() {
                P::Float32 => x::$t::<f32>::from_be_slice(d).map(|v| f64::from(v.$a + v.$b + v.$c)),
                P::Float64 => x::$t::<f64>::from_be_slice(d).map(|v| v.$a + v.$b + v.$c),
                P::Fp1220 => x::$t::<u32>::from_be_slice(d).map(|v| f64::from(v.$a ^ v.$b ^ v.$c)),
                _ => x::$t::<u64>::from_be_slice(d).map(|v| (v.$a ^ v.$b ^ v.$c) as f64),
            }
        };
    }
    let v = match id.data_type() {
        T::PacketCounter => x::PacketCounter::from_be_slice(d).map(|v| f64::from(v.0)),
        T::SampleTimeFine => x::SampleTimeFine::from_be_slice(d).map(|v| f64::from(v.0)),
        T::SampleTimeCoarse => x::SampleTimeCoarse::from_be_slice(d).map(|v| f64::from(v.0)),
        T::UtcTime => x::UtcTime::from_be_slice(d).map(|v| f64::from(v.ns)),
        T::StatusWord => x::StatusWord::from_be_slice(d).map(|v| f64::from(v.self_test())),
        T::Acceleration => vec3!(Acceleration, x, y, z),
        T::RateOfTurn => vec3!(RateOfTurn, x, y, z),
        T::MagneticField => vec3!(MagneticField, x, y, z),
        T::EulerAngles => vec3!(EulerAngles, roll, pitch, yaw),
        T::VelocityXYZ => vec3!(VelocityXYZ, x, y, z),
        _ => return Err(()),
    };
    match v {
        Ok(v) => {
            p.values += 1;
            p.sum += v;
            Ok(())
        }
        Err(_) => Err(()),
    }
}

/// Peer: xsens-mti's byte-by-byte decoder, MTData2 items decoded where it has types.
pub fn imu_peer(data: &[u8], buf: &mut [u8]) -> Pass {
    use xsens_mti::prelude as x;
    let Ok(mut dec) = x::Decoder::new(buf) else {
        return Pass::default();
    };
    let mut p = Pass::default();
    for &b in data {
        match dec.decode(b) {
            Ok(Some(f)) => {
                p.messages += 1;
                if f.message_id() == <x::MTData2 as x::MessageExt>::MSG_ID {
                    if let Ok(m) = <x::MTData2 as x::MessageDecode>::decode(&f) {
                        for pkt in m {
                            p.items += 1;
                            match pkt {
                                Ok(pkt) => {
                                    if peer_item(&pkt, &mut p).is_err() {
                                        p.errors += 1;
                                    }
                                }
                                Err(_) => p.errors += 1,
                            }
                        }
                    }
                }
            }
            Ok(None) => {}
            Err(_) => p.errors += 1,
        }
    }
    p
}

/// Xbus row: all Xsens captures concatenated, frames + MTData2 items, ours vs xsens-mti.
pub fn imu_rows(reps: Reps) -> Vec<Row> {
    let name = "Xbus framer+MTData2 decoder";
    let Some(dir) = milliego_tests::captures_dir("xsens") else {
        return vec![Row::missing(GROUP, name, "n/a (captures not found)")];
    };
    let paths = files(dir.as_path(), |p| {
        let f = p.join("output.bin");
        f.is_file().then_some(f)
    });
    let data: Vec<u8> = paths
        .iter()
        .filter_map(|f| std::fs::read(f).ok())
        .flatten()
        .collect();
    if data.is_empty() {
        return vec![Row::missing(GROUP, name, "n/a (no Xsens capture)")];
    }
    let mut buf = vec![0u8; 65_542];
    let ours = imu_ours(&data);
    let peer = imu_peer(&data, &mut buf);
    let (a, b) = interleaved(reps, || imu_ours(&data), || imu_peer(&data, &mut buf));
    let mb = data.len() as f64 / 1e6;
    vec![Row::new(
        GROUP,
        name,
        Some(mb / a),
        "MB/s",
        "xsens-mti 0.7",
        Some(mb / b),
        Better::Higher,
        &format!(
            "{} captures, {:.1} MB, {} messages; values decoded ours {} / peer {} (peer lacks types for some items)",
            paths.len(),
            mb,
            ours.messages,
            ours.values,
            peer.values
        ),
    )]
}
