//! Shared helpers: simulate a session into a temporary directory, decode its streams with the
//! real drivers (chunk by chunk, as the timing index says they were read), and interpolate the
//! ground truth.
#![allow(dead_code)]

use milliego_session::{Session, TumPose};
use milliego_sim::motion::MotionKind;
use milliego_sim::radar::CPU_HZ;
use milliego_sim::scenario::{run, Scenario, Summary};
use milliego_sim::world::Family;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use radar_driver::tlv::{Dialect, Tlv};
use std::path::Path;

/// A simulated session in a temporary directory.
pub struct Sim {
    pub dir: tempfile::TempDir,
    pub scenario: Scenario,
    pub summary: Summary,
    pub session: Session,
}

pub fn simulate(family: Family, motion: MotionKind, seed: u64, duration_s: f64) -> Sim {
    simulate_with(family, motion, seed, |s| s.duration_s = duration_s)
}

pub fn simulate_with(
    family: Family,
    motion: MotionKind,
    seed: u64,
    edit: impl FnOnce(&mut Scenario),
) -> Sim {
    let mut sc = Scenario::new(family, motion, seed);
    edit(&mut sc);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let summary = run(&sc, &out, &mut |_| {}).unwrap();
    let session = Session::open(&out).unwrap();
    Sim {
        dir,
        scenario: sc,
        summary,
        session,
    }
}

impl Sim {
    pub fn path(&self) -> std::path::PathBuf {
        self.dir.path().join("s")
    }
}

/// One decoded radar frame.
#[derive(Debug, Clone)]
pub struct RadarFrame {
    /// Host time of the read that completed the frame [ns].
    pub host_ns: u64,
    pub frame_number: u32,
    pub cycles: u32,
    pub version: u32,
    pub platform: u32,
    pub total_len: u32,
    pub points: Vec<[f32; 4]>,
    pub side: Vec<(f32, f32)>,
    pub tlv_types: Vec<u32>,
}

/// Decodes the radar stream read chunk by read chunk; returns the frames and the framer counters.
pub fn decode_radar(s: &Session) -> (Vec<RadarFrame>, radar_driver::Counters) {
    let stream = s.radar.as_ref().expect("radar stream");
    let bytes = stream.read_all().unwrap();
    let mut framer: radar_driver::Framer<{ radar_driver::DEFAULT_MAX_FRAME }> = Default::default();
    let mut out = Vec::new();
    for c in stream.chunks() {
        let mut input = &bytes[c.start as usize..c.end as usize];
        loop {
            match framer.poll(&mut input) {
                radar_driver::Poll::Frame(f) => {
                    let h = f.header();
                    let mut fr = RadarFrame {
                        host_ns: c.host_ns.expect("indexed"),
                        frame_number: h.frame_number,
                        cycles: h.time_cpu_cycles.unwrap_or(0),
                        version: h.version.0,
                        platform: h.platform,
                        total_len: h.total_len,
                        points: Vec::new(),
                        side: Vec::new(),
                        tlv_types: Vec::new(),
                    };
                    for raw in f.tlvs() {
                        fr.tlv_types.push(raw.ty);
                        match raw.decode(Dialect::of(&f)) {
                            Ok(Tlv::Points(p)) => {
                                fr.points = p.iter().map(|p| [p.x, p.y, p.z, p.velocity]).collect()
                            }
                            Ok(Tlv::SideInfo(si)) => {
                                fr.side = si.iter().map(|e| (e.snr_db(), e.noise_db())).collect()
                            }
                            _ => {}
                        }
                    }
                    out.push(fr);
                }
                radar_driver::Poll::Dropped { .. } => {}
                radar_driver::Poll::NeedMore => break,
            }
        }
    }
    assert!(framer.finish().is_none(), "a frame was cut off at the end");
    (out, *framer.counters())
}

/// One decoded IMU message.
#[derive(Debug, Clone, Copy)]
pub struct ImuMsg {
    pub host_ns: u64,
    pub counter: u16,
    pub stf: u32,
    pub acc: Vector3<f64>,
    pub gyr: Vector3<f64>,
    pub status: u32,
}

/// Decodes the IMU stream read chunk by read chunk; returns the MTData2 samples and the number
/// of bad frames plus non-MTData2 messages.
pub fn decode_imu(s: &Session) -> (Vec<ImuMsg>, u64) {
    let stream = s.imu.as_ref().expect("imu stream");
    let bytes = stream.read_all().unwrap();
    let mut framer = imu_driver::LogFramer::new();
    let mut out = Vec::new();
    let mut other = 0;
    for c in stream.chunks() {
        let mut input = &bytes[c.start as usize..c.end as usize];
        loop {
            match framer.poll(&mut input) {
                imu_driver::Poll::Frame(f) => match imu_driver::Message::decode(&f) {
                    Ok(imu_driver::Message::MtData2(d)) if pressure_of(&d).is_some() => {}
                    Ok(imu_driver::Message::MtData2(d)) => {
                        let s = d.sample();
                        let v = |a: Option<[f64; 3]>| Vector3::from(a.expect("item"));
                        out.push(ImuMsg {
                            host_ns: c.host_ns.expect("indexed"),
                            counter: s.packet_counter.expect("counter"),
                            stf: s.sample_time_fine.expect("sample time"),
                            acc: v(s.acceleration),
                            gyr: v(s.rate_of_turn),
                            status: s.status.expect("status"),
                        });
                    }
                    _ => other += 1,
                },
                imu_driver::Poll::Dropped { .. } => other += 1,
                imu_driver::Poll::NeedMore => break,
            }
        }
    }
    (
        out,
        framer.counters().frames_bad.total() + framer.counters().bytes_skipped + other,
    )
}

fn pressure_of(d: &imu_driver::MtData2<'_>) -> Option<u32> {
    d.items().find_map(|i| match i.and_then(|i| i.value()) {
        Ok(imu_driver::Value::BaroPressure(p)) => Some(p),
        _ => None,
    })
}

/// One decoded pressure message.
#[derive(Debug, Clone, Copy)]
pub struct PressureMsg {
    pub host_ns: u64,
    pub counter: u16,
    pub stf: u32,
    pub pa: u32,
}

/// Every MTData2 message of the IMU stream in stream order as (counter, SampleTimeFine), and the
/// pressure messages among them.
pub fn decode_imu_all(s: &Session) -> (Vec<(u16, u32)>, Vec<PressureMsg>) {
    let stream = s.imu.as_ref().expect("imu stream");
    let bytes = stream.read_all().unwrap();
    let mut framer = imu_driver::LogFramer::new();
    let (mut all, mut baro) = (Vec::new(), Vec::new());
    for c in stream.chunks() {
        let mut input = &bytes[c.start as usize..c.end as usize];
        loop {
            match framer.poll(&mut input) {
                imu_driver::Poll::Frame(f) => {
                    if let Ok(imu_driver::Message::MtData2(d)) = imu_driver::Message::decode(&f) {
                        let smp = d.sample();
                        let (counter, stf) = (
                            smp.packet_counter.expect("counter"),
                            smp.sample_time_fine.expect("sample time"),
                        );
                        all.push((counter, stf));
                        if let Some(pa) = pressure_of(&d) {
                            baro.push(PressureMsg {
                                host_ns: c.host_ns.expect("indexed"),
                                counter,
                                stf,
                                pa,
                            });
                        }
                    }
                }
                imu_driver::Poll::Dropped { .. } => {}
                imu_driver::Poll::NeedMore => break,
            }
        }
    }
    (all, baro)
}

/// Ground truth with interpolation: position linear, orientation slerp, velocity from a
/// five-point stencil at the samples, interpolated linearly.
pub struct Gt {
    pub poses: Vec<TumPose>,
    pub dt: f64,
}

impl Gt {
    pub fn load(s: &Session) -> Gt {
        let poses = s.groundtruth().unwrap().expect("ground truth");
        let dt = poses[1].t - poses[0].t;
        Gt { poses, dt }
    }

    fn at(&self, i: usize, offset: &Vector3<f64>) -> Vector3<f64> {
        let p = &self.poses[i];
        Vector3::from(p.p) + q_of(p) * offset
    }

    fn bracket(&self, t: f64) -> (usize, f64) {
        let x = (t - self.poses[0].t) / self.dt;
        let i = (x.floor().max(0.0) as usize).min(self.poses.len() - 2);
        (i, x - i as f64)
    }

    /// Orientation of the body at `t`.
    pub fn q(&self, t: f64) -> UnitQuaternion<f64> {
        let (i, f) = self.bracket(t);
        q_of(&self.poses[i]).slerp(&q_of(&self.poses[i + 1]), f)
    }

    /// Position of the body point `offset` at `t`.
    pub fn p(&self, t: f64, offset: &Vector3<f64>) -> Vector3<f64> {
        let (i, f) = self.bracket(t);
        self.at(i, offset) * (1.0 - f) + self.at(i + 1, offset) * f
    }

    /// Velocity of the body point `offset` at `t` (world frame).
    pub fn v(&self, t: f64, offset: &Vector3<f64>) -> Vector3<f64> {
        let (i, f) = self.bracket(t);
        let vi = |i: usize| {
            let i = i.clamp(2, self.poses.len() - 3);
            (self.at(i - 2, offset) - 8.0 * self.at(i - 1, offset) + 8.0 * self.at(i + 1, offset)
                - self.at(i + 2, offset))
                / (12.0 * self.dt)
        };
        vi(i) * (1.0 - f) + vi(i + 1) * f
    }
}

pub fn q_of(p: &TumPose) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(p.q[3], p.q[0], p.q[1], p.q[2]))
}

/// Radar time of a frame's header [s]: timeCpuCycles unwrapped with the help of the host time it
/// arrived at (the counter wraps every 21.5 s; the host time is known to within milliseconds).
pub fn radar_header_time(cycles: u32, approx_sensor_s: f64) -> f64 {
    let wrap = (1u64 << 32) as f64 / CPU_HZ;
    let base = f64::from(cycles) / CPU_HZ;
    let m = ((approx_sensor_s - base) / wrap).round();
    base + m * wrap
}

/// One row of radar_truth.csv.
#[derive(Debug, Clone)]
pub struct TruthRow {
    pub frame: u32,
    pub index: usize,
    pub class: String,
    pub true_xyz: Vector3<f64>,
    pub true_v: f64,
    pub xyzv: [f32; 4],
}

pub fn radar_truth(dir: &Path) -> Vec<TruthRow> {
    let text = std::fs::read_to_string(dir.join(milliego_sim::scenario::RADAR_TRUTH_FILE)).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let n = |i: usize| f[i].parse::<f64>().unwrap();
            TruthRow {
                frame: f[0].parse().unwrap(),
                index: f[1].parse().unwrap(),
                class: f[2].to_string(),
                true_xyz: Vector3::new(n(3), n(4), n(5)),
                true_v: n(6),
                xyzv: [n(7) as f32, n(8) as f32, n(9) as f32, n(10) as f32],
            }
        })
        .collect()
}

/// IMU biases from imu_truth.csv: (host time, accel bias, gyro bias).
pub fn imu_truth(dir: &Path) -> Vec<(f64, Vector3<f64>, Vector3<f64>)> {
    let text = std::fs::read_to_string(dir.join(milliego_sim::scenario::IMU_TRUTH_FILE)).unwrap();
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (
                v[0],
                Vector3::new(v[1], v[2], v[3]),
                Vector3::new(v[4], v[5], v[6]),
            )
        })
        .collect()
}
