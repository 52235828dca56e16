//! `milliego selftest`: a single-threaded self-check for cross-built binaries (qemu-user runs
//! single-threaded programs only). It decodes fixed vectors built by the encoders and, when
//! present, the shared captures, and prints one digest per check; it runs the preprocessing on fixed
//! frames (digested) and the shipped fp32 and int8 models on their golden windows (outputs with
//! their distance to onnxruntime's). The same binary built for two architectures must print
//! identical digests and model outputs within the int8 tolerance; CI compares the native run
//! against qemu-aarch64 (scripts/compare-selftest.py).

use clap::Args;
use imu_driver::{DataId, DataKind, Message, MtData2Writer, Precision, BID_MASTER};
use milliego_preprocess::RadarInput;
use radar_driver::encode::{CompressedRaw, FrameBuilder, QPointRaw, TlvOut};
use radar_driver::host::PointCloud;
use radar_driver::tlv::{CompressedUnits, Target};
use radar_driver::{Framer, Layout, Poll, DEFAULT_MAX_FRAME};
use serde_json::{json, Map, Value};
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Args)]
pub struct SelftestArgs {
    /// Directory holding ti-mmwave/ and xsens/ captures (default: ../shared/captures if present).
    #[arg(long)]
    captures: Option<PathBuf>,
    /// Directory of the shipped model: model.onnx, model-int8.onnx, golden.safetensors.
    #[arg(long, default_value = "models/compact")]
    model_dir: PathBuf,
}

/// FNV-1a, 64 bit: a digest that is the same on every architecture.
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 = (self.0 ^ u64::from(x)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.bytes(&v.to_bits().to_le_bytes());
    }
    fn hex(self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Frames `bytes` in 7-byte chunks and digests every decoded point cloud and the counters.
fn radar_digest(bytes: &[u8]) -> Value {
    let mut framer: Box<Framer<DEFAULT_MAX_FRAME>> = Box::default();
    let mut h = Fnv::new();
    let mut points = 0u64;
    for chunk in bytes.chunks(7) {
        let mut input = chunk;
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => {
                    h.u64(u64::from(f.header().frame_number));
                    let c = PointCloud::from_frame(&f, Some(0.125));
                    points += c.points.len() as u64;
                    for p in &c.points {
                        [p.x, p.y, p.z, p.velocity]
                            .into_iter()
                            .for_each(|v| h.f32(v));
                    }
                    c.snr_db
                        .iter()
                        .flatten()
                        .chain(c.noise_db.iter().flatten())
                        .for_each(|v| h.f32(*v));
                    for t in &c.targets {
                        h.u64(u64::from(t.tid));
                        t.position.iter().for_each(|v| h.f32(*v));
                    }
                }
                Poll::Dropped { error, skipped } => {
                    h.bytes(error.kind_name().as_bytes());
                    h.u64(skipped as u64);
                }
                Poll::NeedMore => break,
            }
        }
    }
    framer.finish();
    let c = framer.counters();
    json!({"digest": h.hex(), "frames_ok": c.frames_ok, "frames_bad": c.frames_bad_total(),
           "bytes_skipped": c.bytes_skipped, "points": points})
}

/// Frames Xbus bytes in 5-byte chunks and digests every decoded MTData2 value.
fn imu_digest(bytes: &[u8]) -> Value {
    let mut framer: Box<imu_driver::LogFramer> = Box::new(imu_driver::LogFramer::new());
    let mut h = Fnv::new();
    let (mut messages, mut values) = (0u64, 0u64);
    for chunk in bytes.chunks(5) {
        let mut input = chunk;
        loop {
            match framer.poll(&mut input) {
                imu_driver::Poll::Frame(f) => {
                    messages += 1;
                    if let Ok(Message::MtData2(d)) = Message::decode(&f) {
                        for item in d.items().flatten() {
                            h.u64(u64::from(item.id.0));
                            match item.value() {
                                Ok(v) => {
                                    for x in v.floats() {
                                        h.u64(x.to_bits());
                                        values += 1;
                                    }
                                    if v.floats().is_empty() {
                                        h.bytes(format!("{v:?}").as_bytes());
                                        values += 1;
                                    }
                                }
                                Err(e) => h.bytes(format!("{e:?}").as_bytes()),
                            }
                        }
                    }
                }
                imu_driver::Poll::Dropped { .. } => h.bytes(b"dropped"),
                imu_driver::Poll::NeedMore => break,
            }
        }
    }
    json!({"digest": h.hex(), "messages": messages, "values": values})
}

fn radar_vectors() -> Vec<u8> {
    let pts: Vec<[f32; 4]> = (0..40)
        .map(|i| {
            [
                i as f32 * 0.1 - 2.0,
                0.5 + i as f32 * 0.05,
                -0.3,
                0.01 * i as f32,
            ]
        })
        .collect();
    let side: Vec<(i16, i16)> = (0..40).map(|i| (100 + i, 300 - i)).collect();
    let q: Vec<QPointRaw> = (0..10)
        .map(|i| QPointRaw {
            range_idx: i,
            doppler_idx: i as i16 - 5,
            peak: 7 * i,
            xyz: [i as i16 * 100, 512, -64],
        })
        .collect();
    let units = CompressedUnits {
        elevation: 0.01,
        azimuth: 0.01,
        doppler: 0.0139,
        range: 0.00025,
        snr: 0.04,
    };
    let comp: Vec<CompressedRaw> = (0..50)
        .map(|i| CompressedRaw {
            elevation: (i % 30) as i8 - 15,
            azimuth: (i * 3 % 120) as i8 - 60,
            doppler: i as i16 - 25,
            range: 2000 + 97 * i as u16,
            snr: 300,
        })
        .collect();
    let targets = [Target {
        tid: 3,
        position: [0.5, 2.5, 0.1],
        ..Target::default()
    }];
    let mut out = Vec::new();
    for n in 0..4 {
        let b = FrameBuilder::oob(0x0305_0004, 0xA6843, 100 + n)
            .cycles(n * 20_000_000)
            .points(&pts)
            .tlv(TlvOut::SideInfo(&side));
        out.extend(b.tlv(TlvOut::Stats([1, 2, 3, 4, 5, 6])).to_vec());
    }
    out.extend(
        FrameBuilder::oob(0x0200_0004, 0xA1642, 7)
            .tlv(TlvOut::PointsQ(9, &q))
            .to_vec(),
    );
    out.extend(
        FrameBuilder::oob(0x0102_0000, 0xA1443, 8)
            .tlv(TlvOut::PointsQ(7, &q))
            .to_vec(),
    );
    out.extend(
        FrameBuilder::new(Layout::PeopleCounting48, 0x0305_0004, 0xA6843, 9)
            .tlv(TlvOut::Compressed(6, units, &comp))
            .tlv(TlvOut::Targets(7, &targets))
            .to_vec(),
    );
    out.extend(
        FrameBuilder::oob(0x0305_0004, 0xA6843, 10)
            .tlv(TlvOut::Compressed(1020, units, &comp))
            .to_vec(),
    );
    out.extend([0x02, 0x01, 0x04, 0x03, 0x55, 0x66]); // junk and a broken magic
    out
}

fn imu_vectors() -> Result<Vec<u8>> {
    let mut out = Vec::new();
    for (k, p) in [
        Precision::Float32,
        Precision::Fp1220,
        Precision::Fp1632,
        Precision::Float64,
    ]
    .into_iter()
    .enumerate()
    {
        for i in 0..5u16 {
            let mut buf = [0u8; 512];
            let mut w = MtData2Writer::new(&mut buf);
            let id = |kind| DataId::of(kind, p).ok_or("no data id");
            w.item(
                id(DataKind::PacketCounter)?,
                &(i + 100 * k as u16).to_be_bytes(),
            )?;
            w.item(
                id(DataKind::SampleTimeFine)?,
                &(1_000_000 + 100 * u32::from(i)).to_be_bytes(),
            )?;
            let t = f64::from(i) * 0.1;
            w.floats(
                id(DataKind::Acceleration)?,
                &[0.1 + t, -9.81 + t / 3.0, 0.02 * t],
            )?;
            w.floats(id(DataKind::RateOfTurn)?, &[0.001 * t, -0.25 + t, 3.0e-4])?;
            w.floats(
                id(DataKind::Quaternion)?,
                &[0.5f64.sqrt(), 0.0, 0.5f64.sqrt(), 0.0],
            )?;
            let n = w.finish(BID_MASTER)?;
            out.extend_from_slice(&buf[..n]);
        }
    }
    Ok(out)
}

fn pose_digest() -> Value {
    let mut h = Fnv::new();
    for seq in 0..10u32 {
        let m = pose_link::PoseMessage {
            seq,
            position: [f64::from(seq) * 0.1, 1.0 / (1.0 + f64::from(seq)), -2.5],
            rel_translation: [0.01 * seq as f32, 0.0, 0.0],
            ..pose_link::PoseMessage::default()
        };
        let mut b = [0u8; pose_link::MESSAGE_LEN];
        if m.encode(&mut b).is_ok() {
            h.bytes(&b);
        }
    }
    json!({"digest": h.hex(), "messages": 10})
}

/// Preprocessing on fixed synthetic frames: panoramas, IMU windows and the radar tensor, digested
/// bit for bit (the same code path as training export and the runtime).
fn preprocess_digest() -> Result<Value> {
    use milliego_preprocess::window::{BuilderConfig, WindowBuilder};
    let mut b = WindowBuilder::new(BuilderConfig::default())?;
    let mut h = Fnv::new();
    let mut tensor = Box::new([0.0f32; milliego_preprocess::RADAR_LEN]);
    let norm = milliego_preprocess::Norm {
        min: 0.0,
        max: 0.99,
        mean: 0.027,
    };
    let mut windows = 0u64;
    let mut imu_t = 0.0f64;
    for n in 1..=20u32 {
        let t = f64::from(n) * 0.05;
        while imu_t <= t {
            b.push_imu(imu_t, [0.1 * imu_t, 0.02, 9.81], [0.0, 0.01, 0.3 * imu_t]);
            imu_t += 0.0025;
        }
        let points: Vec<radar_driver::tlv::Point> = (0..40)
            .map(|i| {
                let a = f32::from(i as u8) * 0.37 + n as f32 * 0.01;
                radar_driver::tlv::Point {
                    x: 4.0 * a.sin(),
                    y: 1.0 + 6.0 * (a * 0.5).cos().abs(),
                    z: 0.3 * (a * 1.7).sin(),
                    velocity: -0.5 + 0.1 * a.cos(),
                }
            })
            .collect();
        if let Some((p, d)) = b.push_radar(n, t, &points) {
            p.iter().chain(d.iter()).for_each(|v| h.f32(*v));
        }
        while let Some(w) = b.poll() {
            windows += 1;
            w.imu.iter().flatten().for_each(|v| h.f32(*v));
            for input in [RadarInput::Depth, RadarInput::DepthDoppler] {
                w.radar_tensor(input, &norm, &mut tensor);
                tensor.iter().for_each(|v| h.f32(*v));
            }
        }
    }
    Ok(json!({"digest": h.hex(), "windows": windows}))
}

/// The shipped fp32 and int8 models on the golden windows: outputs and their distance to the
/// onnxruntime outputs stored with the model. Floating-point kernels differ between architectures,
/// so these are compared within a tolerance (scripts/cross-check), not digested.
fn model_checks(dir: &std::path::Path, checks: &mut Map<String, Value>) -> Result<bool> {
    let golden = dir.join("golden.safetensors");
    if !golden.is_file() {
        eprintln!("milliego selftest: skipped model: no {}", golden.display());
        return Ok(true);
    }
    let bytes = std::fs::read(&golden).map_err(|e| format!("{}: {e}", golden.display()))?;
    let st = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| format!("{}: {e}", golden.display()))?;
    let f32s = |name: &str| -> Result<Vec<f32>> {
        let t = st
            .tensor(name)
            .map_err(|e| format!("{}: {name}: {e}", golden.display()))?;
        Ok(t.data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect())
    };
    let windows = (0..)
        .take_while(|k| st.tensor(&format!("radar_{k}")).is_ok())
        .count();
    let mut all_ok = true;
    for (file, key, tol) in [
        ("model.onnx", "fp32", 1e-4f64),
        (
            "model-int8.onnx",
            "int8",
            f64::from(milliego_models::INT8_TOLERANCE),
        ),
    ] {
        let mut m = milliego_models::Model::load(&dir.join(file), None)?;
        let h = m.meta().hidden;
        let mut outputs = Vec::new();
        let mut worst = 0.0f64;
        for k in 0..windows {
            let radar = m.tensor(&[1, 6, 64, 256], &f32s(&format!("radar_{k}"))?)?;
            let imu = m.tensor(&[1, 20, 6], &f32s(&format!("imu_{k}"))?)?;
            let state = m.tensor(&[1, 4, h], &f32s(&format!("state_{k}"))?)?;
            let (pose, _) = m.run_raw(radar, imu, state)?;
            let want = f32s(&format!("pose_{key}_{k}"))?;
            for (a, b) in pose.iter().zip(&want) {
                worst = worst.max(f64::from((a - b).abs()));
            }
            outputs.extend(pose.iter().map(|v| f64::from(*v)));
        }
        let ok = worst <= tol;
        all_ok &= ok;
        checks.insert(
            format!("model_{key}"),
            json!({"outputs": outputs, "tolerance": tol, "max_abs_diff_to_onnxruntime": worst, "ok": ok,
                   "accel": m.accel().map(|r| r.to_string()), "amx_guard": m.amx_guard().to_string()}),
        );
    }
    Ok(all_ok)
}

pub fn run(a: SelftestArgs) -> Result<()> {
    let mut checks = Map::new();
    checks.insert("preprocess_vectors".into(), preprocess_digest()?);
    let models_ok = model_checks(&a.model_dir, &mut checks)?;
    checks.insert("radar_vectors".into(), radar_digest(&radar_vectors()));
    checks.insert("imu_vectors".into(), imu_digest(&imu_vectors()?));
    checks.insert("pose_link_vectors".into(), pose_digest());
    let captures = a
        .captures
        .unwrap_or_else(|| PathBuf::from("../shared/captures"));
    if captures.is_dir() {
        let mut files: Vec<PathBuf> = Vec::new();
        for family in ["ti-mmwave", "xsens"] {
            let mut stack = vec![captures.join(family)];
            while let Some(d) = stack.pop() {
                for e in std::fs::read_dir(&d)
                    .map_err(|e| format!("{}: {e}", d.display()))?
                    .flatten()
                {
                    let p = e.path();
                    if p.is_dir() {
                        stack.push(p);
                    } else if matches!(p.extension().and_then(|x| x.to_str()), Some("dat" | "bin"))
                    {
                        files.push(p);
                    }
                }
            }
        }
        files.sort();
        for f in files {
            let bytes = std::fs::read(&f).map_err(|e| format!("{}: {e}", f.display()))?;
            let rel = f
                .strip_prefix(&captures)
                .unwrap_or(&f)
                .display()
                .to_string();
            let v = if rel.starts_with("ti-mmwave") {
                radar_digest(&bytes)
            } else {
                imu_digest(&bytes)
            };
            checks.insert(rel, v);
        }
    } else {
        eprintln!(
            "milliego selftest: skipped captures: not found at {}",
            captures.display()
        );
    }
    eprintln!(
        "milliego selftest: {} checks on {}",
        checks.len(),
        std::env::consts::ARCH
    );
    println!(
        "{}",
        serde_json::to_string_pretty(&json!({"selftest": 1, "checks": checks}))?
    );
    if !models_ok {
        return Err("model outputs differ from the golden bundle beyond tolerance".into());
    }
    Ok(())
}
