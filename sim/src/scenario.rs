//! A scenario end to end: world, motion, sensors, clocks, links, written as a session.
//!
//! Radar: frame k starts at radar time `s0 + k T` (T from the .cfg), its chirps take the active
//! time, the points are computed at the middle of the chirps, the frame is ready after the
//! processing delay (with jitter) and its header carries the 200 MHz timeCpuCycles of that moment;
//! then it goes out on the 921600-baud UART. IMU: sample k at IMU time `s0 + k / f`, out on its
//! UART 1 ms later. Host read chunks are timed when their last byte arrived plus the USB latency.

use crate::clock::{SensorClock, Uart};
use crate::imu::{self, Baro, Gaps, Imu, ImuGrade, ImuSpec, GRAVITY};
use crate::motion::{MotionKind, Trajectory};
use crate::radar::{NearField, PointClass, RadarModel, CPU_HZ};
use crate::rng::SimRng;
use crate::world::{Family, World};
use crate::SimError;
use milliego_session::{
    ClockTruth, Extrinsic, Extrinsics, ImuMeta, Meta, RadarMeta, SessionWriter, Source, StreamKind,
    TumPose,
};
use nalgebra::{UnitQuaternion, Vector3};
use std::fmt::Write as _;
use std::path::Path;

/// Host time of the first radar frame's start \[s\].
pub const RADAR_START_S: f64 = 0.2;
/// Host time of the first IMU sample \[s\].
pub const IMU_START_S: f64 = 0.05;
/// Ground-truth rate \[Hz\].
pub const GT_HZ: f64 = 200.0;
/// Ground truth runs this long past the scenario's duration \[s\] (covers the last frames'
/// transmission).
pub const GT_TAIL_S: f64 = 0.5;
/// Radar processing delay after the chirps: base \[s\].
pub const RADAR_PROC_S: f64 = 3e-3;
/// Radar processing delay per point \[s\].
pub const RADAR_PROC_PER_POINT_S: f64 = 15e-6;
/// Radar processing jitter: uniform in \[0, this) \[s\].
pub const RADAR_JITTER_S: f64 = 1.5e-3;
/// IMU output latency after the sample instant \[s\].
pub const IMU_LATENCY_S: f64 = 1e-3;
/// Ground-truth file of the radar points' causes, beside the session files.
pub const RADAR_TRUTH_FILE: &str = "radar_truth.csv";
/// Ground-truth file of the IMU biases.
pub const IMU_TRUTH_FILE: &str = "imu_truth.csv";
/// Ground-truth file of the barometer (only with the barometer on).
pub const BARO_TRUTH_FILE: &str = "baro_truth.csv";

/// What to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// World family.
    pub family: Family,
    /// Motion kind.
    pub motion: MotionKind,
    /// Seed of the world, the trajectory, the clocks and all noise.
    pub seed: u64,
    /// Length \[s\].
    pub duration_s: f64,
    /// Radar frame rate \[Hz\] (10-30).
    pub radar_hz: f64,
    /// IMU output rate \[Hz\] (50-400).
    pub imu_hz: f64,
    /// IMU UART rate \[bit/s\].
    pub imu_baud: u32,
    /// IMU noise ([`ImuGrade::spec`] gives the presets; default MTi-1).
    pub imu_spec: ImuSpec,
    /// Rest before the motion starts \[s\] (0: moving from the first sample).
    pub rest_start_s: f64,
    /// Rest after the motion stops, up to the end \[s\] (0: moving to the end).
    pub rest_end_s: f64,
    /// Radar origin in the body frame \[m\] (`None`: the default mount of [`extrinsics`], a few
    /// cm ahead of the body origin). Each component within ±[`MAX_LEVER_M`].
    pub radar_lever_m: Option<[f64; 3]>,
    /// Radar boresight yawed about the body's z axis \[deg\] (positive: to the left), ±180.
    pub radar_yaw_deg: f64,
    /// Radar boresight tilted up about the radar's own x axis \[deg\] (positive: up), ±60.
    pub radar_tilt_deg: f64,
    /// Coarse Doppler: every reported radial velocity is a multiple of this step \[m/s\]
    /// (0: off, the .cfg's 0.134 m/s bins; else 0.01-2).
    pub doppler_step_mps: f64,
    /// Near-field leakage: share of each frame's points that are spurious returns at 0.1-1.0 m,
    /// fixed in the radar frame, zero Doppler (0: off; else up to 0.5).
    pub near_field_share: f64,
    /// Share of IMU samples dropped in bursts: the message is never sent, so PacketCounter and
    /// SampleTimeFine jump over the gap (0: off; else up to 0.8).
    pub imu_gap_share: f64,
    /// Barometer rate \[Hz\]: pressure messages in the IMU stream (0: off; else 1-100).
    pub baro_hz: f64,
    /// Height change over the walk \[m\] (handheld and headworn only; 0: flat): the body climbs
    /// (positive) or descends (negative, starting that much higher) along a smooth ramp, peak
    /// vertical speed at most 0.5 m/s, |h| up to 10 m, below the world's ceiling.
    pub height_change_m: f64,
}

/// Largest height change of a walk \[m\].
pub const MAX_HEIGHT_CHANGE_M: f64 = 10.0;
/// Largest peak vertical speed of a height change \[m/s\] (brisk stair climbing).
pub const MAX_CLIMB_MPS: f64 = 0.5;

/// Largest lever-arm component of the radar mount \[m\].
pub const MAX_LEVER_M: f64 = 2.0;
/// Largest radar tilt \[deg\] (beyond it the ±20° elevation field of view sees only floor or sky).
pub const MAX_TILT_DEG: f64 = 60.0;

impl Scenario {
    /// Defaults: 30 s, radar 20 Hz, IMU 200 Hz at 921600 baud, MTi-1 noise.
    pub fn new(family: Family, motion: MotionKind, seed: u64) -> Scenario {
        Scenario {
            family,
            motion,
            seed,
            duration_s: 30.0,
            radar_hz: 20.0,
            imu_hz: 200.0,
            imu_baud: 921_600,
            imu_spec: ImuSpec::mti1(),
            rest_start_s: 0.0,
            rest_end_s: 0.0,
            radar_lever_m: None,
            radar_yaw_deg: 0.0,
            radar_tilt_deg: 0.0,
            doppler_step_mps: 0.0,
            near_field_share: 0.0,
            imu_gap_share: 0.0,
            baro_hz: 0.0,
            height_change_m: 0.0,
        }
    }

    /// The radar model these settings give.
    pub fn radar_model(&self) -> Result<RadarModel, SimError> {
        let mut m = if self.motion == MotionKind::Vehicle {
            RadarModel::vehicle(self.radar_hz)?
        } else if self.family == Family::Outdoor {
            RadarModel::outdoor(self.radar_hz)?
        } else {
            RadarModel::new(self.radar_hz)?
        };
        m.doppler_step_mps = self.doppler_step_mps;
        Ok(m)
    }

    /// Sensor poses on the body: [`extrinsics`] of the motion kind with the radar mount settings
    /// (lever arm, yaw, tilt) applied. These are the true poses the simulation uses and the
    /// session's metadata carries.
    pub fn extrinsics(&self) -> Extrinsics {
        let mut ext = extrinsics(self.motion);
        if let Some(t) = self.radar_lever_m {
            ext.radar.translation_m = t;
        }
        if self.radar_yaw_deg != 0.0 || self.radar_tilt_deg != 0.0 {
            let (_, q0) = sensor_pose(&ext.radar);
            let yaw = UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                self.radar_yaw_deg.to_radians(),
            );
            let tilt = UnitQuaternion::from_axis_angle(
                &Vector3::x_axis(),
                self.radar_tilt_deg.to_radians(),
            );
            let q = yaw * q0 * tilt;
            ext.radar.rotation_wxyz = [q.w, q.i, q.j, q.k];
        }
        ext
    }

    /// Checks the settings, naming the first one out of range.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Config(m));
        if !(self.duration_s.is_finite() && self.duration_s >= 1.0 && self.duration_s <= 3600.0) {
            return bad(format!(
                "duration {} s is outside 1-3600 s",
                self.duration_s
            ));
        }
        if !(50.0..=400.0).contains(&self.imu_hz) {
            return bad(format!("IMU rate {} Hz is outside 50-400 Hz", self.imu_hz));
        }
        if !(0.0..=0.8).contains(&self.imu_gap_share) {
            return bad(format!(
                "IMU gap share {} is outside 0-0.8",
                self.imu_gap_share
            ));
        }
        let rests = self.rest_start_s + self.rest_end_s;
        if !(self.rest_start_s >= 0.0 && self.rest_end_s >= 0.0 && rests.is_finite()) {
            return bad(format!(
                "rests {} s / {} s must be zero or positive",
                self.rest_start_s, self.rest_end_s
            ));
        }
        let ramps = f64::from(u8::from(self.rest_start_s > 0.0) + u8::from(self.rest_end_s > 0.0))
            * crate::motion::REST_RAMP_S;
        if self.motion != MotionKind::Static && rests > 0.0 && rests + ramps + 1.0 > self.duration_s
        {
            return bad(format!(
                "rests of {} s and {} s leave under 1 s of motion in {} s (ramps take {} s each)",
                self.rest_start_s,
                self.rest_end_s,
                self.duration_s,
                crate::motion::REST_RAMP_S
            ));
        }
        if let Some(t) = self.radar_lever_m {
            if !t.iter().all(|x| x.is_finite() && x.abs() <= MAX_LEVER_M) {
                return bad(format!(
                    "radar lever arm {t:?} m: each component must be within ±{MAX_LEVER_M} m"
                ));
            }
        }
        if !(self.radar_yaw_deg.is_finite() && self.radar_yaw_deg.abs() <= 180.0) {
            return bad(format!(
                "radar yaw {} deg is outside ±180 deg",
                self.radar_yaw_deg
            ));
        }
        if !(self.radar_tilt_deg.is_finite() && self.radar_tilt_deg.abs() <= MAX_TILT_DEG) {
            return bad(format!(
                "radar tilt {} deg is outside ±{MAX_TILT_DEG} deg",
                self.radar_tilt_deg
            ));
        }
        if !(self.doppler_step_mps == 0.0 || (0.01..=2.0).contains(&self.doppler_step_mps)) {
            return bad(format!(
                "Doppler step {} m/s must be 0 (off) or within 0.01-2 m/s",
                self.doppler_step_mps
            ));
        }
        if !(0.0..=0.5).contains(&self.near_field_share) {
            return bad(format!(
                "near-field share {} is outside 0-0.5",
                self.near_field_share
            ));
        }
        if self.motion == MotionKind::Vehicle && self.family != Family::Outdoor {
            return bad(format!(
                "vehicle motion needs the outdoor family, not {}",
                self.family
            ));
        }
        if self.height_change_m != 0.0 {
            let h = self.height_change_m;
            if !(h.is_finite() && h.abs() <= MAX_HEIGHT_CHANGE_M) {
                return bad(format!(
                    "height change {h} m is outside ±{MAX_HEIGHT_CHANGE_M} m"
                ));
            }
            if !matches!(self.motion, MotionKind::Handheld | MotionKind::Headworn) {
                return bad(format!(
                    "height change {h} m: only handheld and headworn motion change height, not {}",
                    self.motion
                ));
            }
            let moving = self.duration_s - self.rest_start_s - self.rest_end_s;
            let peak = 1.875 * h.abs() / moving.max(1e-9);
            if peak > MAX_CLIMB_MPS {
                return bad(format!(
                    "height change {h} m over {moving} s of motion climbs at up to {peak:.2} m/s, more than {MAX_CLIMB_MPS} m/s"
                ));
            }
        }
        if !(self.baro_hz == 0.0 || (1.0..=100.0).contains(&self.baro_hz)) {
            return bad(format!(
                "barometer rate {} Hz must be 0 (off) or within 1-100 Hz",
                self.baro_hz
            ));
        }
        let need = imu::MESSAGE_LEN as f64 * 10.0 * self.imu_hz;
        if need > 0.9 * f64::from(self.imu_baud) {
            return bad(format!(
                "IMU at {} Hz needs {need:.0} bit/s, more than 90 % of {} baud",
                self.imu_hz, self.imu_baud
            ));
        }
        let need = need + imu::PRESSURE_MESSAGE_LEN as f64 * 10.0 * self.baro_hz;
        if need > 0.9 * f64::from(self.imu_baud) {
            return bad(format!(
                "IMU at {} Hz with the barometer at {} Hz needs {need:.0} bit/s, more than 90 % of {} baud",
                self.imu_hz, self.baro_hz, self.imu_baud
            ));
        }
        RadarModel::new(self.radar_hz).map(|_| ())
    }

    /// One line saying what this is.
    pub fn description(&self) -> String {
        let rest = if self.rest_start_s > 0.0 || self.rest_end_s > 0.0 {
            format!(
                "; at rest {} s before and {} s after the motion",
                self.rest_start_s, self.rest_end_s
            )
        } else {
            String::new()
        };
        let mut extra = String::new();
        if self.radar_lever_m.is_some() || self.radar_yaw_deg != 0.0 || self.radar_tilt_deg != 0.0 {
            let t = self.extrinsics().radar.translation_m;
            let _ = write!(
                extra,
                "; radar mounted at ({}, {}, {}) m, yawed {} deg, tilted up {} deg",
                t[0], t[1], t[2], self.radar_yaw_deg, self.radar_tilt_deg
            );
        }
        if self.doppler_step_mps > 0.0 {
            let _ = write!(extra, "; Doppler in {} m/s steps", self.doppler_step_mps);
        }
        // A custom noise spec says nothing (as before the grades existed).
        if let Some(g) = ImuGrade::of(&self.imu_spec).filter(|&g| g != ImuGrade::Mti1) {
            let _ = write!(extra, "; IMU grade {g}");
        }
        if self.imu_gap_share > 0.0 {
            let _ = write!(
                extra,
                "; {} of the IMU samples dropped in bursts",
                self.imu_gap_share
            );
        }
        if self.baro_hz > 0.0 {
            let _ = write!(extra, "; barometer {} Hz", self.baro_hz);
        }
        if self.height_change_m != 0.0 {
            let _ = write!(extra, "; height change {} m", self.height_change_m);
        }
        if self.near_field_share > 0.0 {
            let _ = write!(
                extra,
                "; near-field leakage {} of the points",
                self.near_field_share
            );
        }
        format!(
            "milliego sim {}: {} family, {} motion, seed {}, {} s; radar {} Hz, IMU {} Hz{rest}{extra}",
            env!("CARGO_PKG_VERSION"),
            self.family,
            self.motion,
            self.seed,
            self.duration_s,
            self.radar_hz,
            self.imu_hz
        )
    }
}

/// The default sensor poses on the body for a motion kind: (radar, IMU), each
/// `p_body = R p_sensor + t` ([`Scenario::extrinsics`] applies the radar mount settings on top).
///
/// The radar looks along the body's x axis (radar y = body x, radar x = body −y). The IMU sits
/// beside it, rotated and offset as on the paper's rigs (a board mounted at 90° with a tilt).
pub fn extrinsics(motion: MotionKind) -> Extrinsics {
    let radar_q = UnitQuaternion::from_euler_angles(0.0, 0.0, -std::f64::consts::FRAC_PI_2);
    let imu_q = UnitQuaternion::from_euler_angles(0.02, -0.03, std::f64::consts::FRAC_PI_2 + 0.01);
    let (rt, it) = match motion {
        MotionKind::Robot => ([0.10, 0.0, 0.05], [-0.05, 0.04, -0.02]),
        _ => ([0.04, 0.0, 0.02], [-0.02, 0.03, -0.01]),
    };
    let ext = |t: [f64; 3], q: UnitQuaternion<f64>| Extrinsic {
        translation_m: t,
        rotation_wxyz: [q.w, q.i, q.j, q.k],
    };
    Extrinsics {
        radar: ext(rt, radar_q),
        imu: ext(it, imu_q),
    }
}

/// A sensor pose on the body as (translation, rotation).
pub fn sensor_pose(e: &Extrinsic) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let [w, x, y, z] = e.rotation_wxyz;
    (
        Vector3::from(e.translation_m),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
    )
}

/// What a simulation produced.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Summary {
    /// Radar frames.
    pub frames: u64,
    /// Points over all frames.
    pub points: u64,
    /// Outlier points (mirror, multipath, clutter) over all frames.
    pub outliers: u64,
    /// Fewest points in a frame.
    pub points_min: u64,
    /// Most points in a frame.
    pub points_max: u64,
    /// IMU samples.
    pub imu_samples: u64,
    /// Radar stream bytes \[B\].
    pub radar_bytes: u64,
    /// IMU stream bytes \[B\].
    pub imu_bytes: u64,
}

impl Summary {
    /// Mean points per frame.
    pub fn points_mean(&self) -> f64 {
        self.points as f64 / (self.frames.max(1)) as f64
    }
    /// Share of outliers among all points.
    pub fn outlier_share(&self) -> f64 {
        self.outliers as f64 / (self.points.max(1)) as f64
    }
}

/// The clocks of a scenario: (radar, IMU), drawn from its seed.
pub fn clocks(seed: u64) -> (SensorClock, SensorClock) {
    let mut rng = SimRng::new(seed, "clocks");
    (
        SensorClock::random(&mut rng, 1.0, 20.0, 30.0),
        SensorClock::random(&mut rng, 1.0, 500.0, 50.0),
    )
}

/// Simulates `sc` into a new session directory `dir`; `progress` gets the fraction done.
pub fn run(sc: &Scenario, dir: &Path, progress: &mut dyn FnMut(f64)) -> Result<Summary, SimError> {
    sc.validate()?;
    let world = if sc.motion == MotionKind::Vehicle {
        World::generate_vehicle_lot(sc.seed)
    } else {
        World::generate(sc.family, sc.seed)
    };
    let mut traj = Trajectory::generate(sc.motion, &world, sc.seed, sc.duration_s + GT_TAIL_S)?
        .with_rest(sc.rest_start_s, sc.rest_end_s, sc.duration_s);
    if sc.height_change_m != 0.0 {
        let top = traj.base_height() + sc.height_change_m.abs() + 0.2;
        if top >= world.height {
            return Err(SimError::Config(format!(
                "height change {} m lifts the body to {top:.2} m, above the {} ceiling at {:.2} m",
                sc.height_change_m, sc.family, world.height
            )));
        }
        traj = traj.with_height_change(sc.height_change_m, sc.duration_s);
    }
    let model = sc.radar_model()?;
    let ext = sc.extrinsics();
    let (t_br, q_br) = sensor_pose(&ext.radar);
    let (t_bi, q_bi) = sensor_pose(&ext.imu);
    let (rclk, iclk) = clocks(sc.seed);

    let mut meta = Meta::new(Source::Simulated);
    meta.description = sc.description();
    meta.radar = Some(RadarMeta {
        baud: model.derived.data_baud,
        device: Some("AWR1843 (simulated, mmWave SDK 3.5 out-of-box demo)".into()),
        ..RadarMeta::default()
    });
    meta.imu = Some(ImuMeta {
        baud: sc.imu_baud,
        device: Some(
            ImuGrade::of(&sc.imu_spec)
                .unwrap_or(ImuGrade::Mti1)
                .device()
                .into(),
        ),
        sample_time_wrap: "u32".into(),
        rate_hz: Some(sc.imu_hz),
        ..ImuMeta::default()
    });
    meta.extrinsics = ext;
    meta.clock = Some(ClockTruth {
        radar_offset_s: rclk.offset_s,
        radar_drift_ppm: rclk.drift_ppm,
        imu_offset_s: iclk.offset_s,
        imu_drift_ppm: iclk.drift_ppm,
    });
    let mut w = SessionWriter::create(dir, meta)?;
    w.radar_cfg(&model.cfg)?;
    let mut sum = Summary {
        points_min: u64::MAX,
        ..Summary::default()
    };

    // Radar.
    let mut rs = w.stream(StreamKind::Radar)?;
    let mut rng = SimRng::new(sc.seed, "radar");
    let mut link_rng = SimRng::new(sc.seed, "radar/link");
    let mut near_rng = SimRng::new(sc.seed, "radar/near-field");
    let near = (sc.near_field_share > 0.0)
        .then(|| NearField::new(&model, sc.near_field_share, &mut near_rng));
    let mut uart = Uart::new(model.derived.data_baud, (64, 1024), (0.2e-3, 1.5e-3));
    let mut truth = String::from(
        "# frame,index,class,true_x,true_y,true_z,true_v,x,y,z,v\n# radar frame [m], radial velocity [m/s]\n",
    );
    let period = model.frame_period_s();
    let s0 = rclk.to_sensor(RADAR_START_S);
    let mut prev_tx_us = 0u32;
    for k in 0u64.. {
        let start = s0 + k as f64 * period;
        if rclk.to_host(start) >= sc.duration_s {
            break;
        }
        let mid = rclk.to_host(start + 0.5 * model.active_time_s());
        let body = traj.pose(mid);
        let rp = body.compose(&t_br, &q_br);
        let v = traj.point_velocity(mid, &t_br);
        let mut pts = model.frame(&world, &rp.p, &rp.q, &v, &mut rng);
        if let Some(nf) = &near {
            nf.add(&model, &mut pts, &mut near_rng);
        }
        let proc = RADAR_PROC_S
            + RADAR_PROC_PER_POINT_S * pts.len() as f64
            + link_rng.uniform(0.0, RADAR_JITTER_S);
        let ready = start + model.active_time_s() + proc;
        let cycles = ((ready * CPU_HZ).floor() as u64 % (1u64 << 32)) as u32;
        let margin = ((period - model.active_time_s() - proc) * 1e6).max(0.0);
        let stats = [
            (proc * 1e6) as u32,
            prev_tx_us,
            margin as u32,
            20,
            (model.active_time_s() / period * 100.0) as u32,
            (proc / period * 100.0) as u32,
        ];
        let frame_number = (k + 1) as u32;
        let bytes = model.encode(frame_number, cycles, &pts, stats, &mut link_rng);
        prev_tx_us = (bytes.len() as f64 * uart.byte_time() * 1e6) as u32;
        let (_, reads) = uart.send(rclk.to_host(ready), bytes.len(), &mut link_rng);
        let mut at = 0;
        for r in reads {
            rs.write_chunk(r.host_ns, &bytes[at..at + r.len])?;
            at += r.len;
        }
        for (i, p) in pts.iter().enumerate() {
            let _ = writeln!(
                truth,
                "{frame_number},{i},{},{:.6},{:.6},{:.6},{:.6},{},{},{},{}",
                p.class.name(),
                p.true_xyz.x,
                p.true_xyz.y,
                p.true_xyz.z,
                p.true_v,
                p.xyz[0],
                p.xyz[1],
                p.xyz[2],
                p.v
            );
        }
        let n = pts.len() as u64;
        sum.frames += 1;
        sum.points += n;
        sum.outliers += pts.iter().filter(|p| p.class != PointClass::Inlier).count() as u64;
        sum.points_min = sum.points_min.min(n);
        sum.points_max = sum.points_max.max(n);
        if k % 20 == 0 {
            progress(0.8 * (rclk.to_host(start) / sc.duration_s).min(1.0));
        }
    }
    sum.radar_bytes = rs.finish()?;
    write_file(dir, RADAR_TRUTH_FILE, &truth)?;

    // IMU.
    let mut is = w.stream(StreamKind::Imu)?;
    let mut dev = Imu::new(sc.imu_spec, SimRng::new(sc.seed, "imu"));
    let mut link_rng = SimRng::new(sc.seed, "imu/link");
    let mut uart = Uart::new(sc.imu_baud, (8, 64), (0.1e-3, 1.0e-3));
    let mut itruth =
        String::from("# t_host[s],accel_bias_x,y,z[m/s^2],gyro_bias_x,y,z[rad/s] (IMU frame)\n");
    let dt = 1.0 / sc.imu_hz;
    let s0 = iclk.to_sensor(IMU_START_S);
    let g = Vector3::new(0.0, 0.0, -GRAVITY);
    let mut gaps = (sc.imu_gap_share > 0.0).then(|| {
        Gaps::new(
            sc.imu_gap_share,
            sc.imu_hz,
            SimRng::new(sc.seed, "imu/gaps"),
        )
    });
    let mut baro = (sc.baro_hz > 0.0).then(|| Baro::new(SimRng::new(sc.seed, "baro")));
    let mut btruth = baro.as_ref().map(|b| {
        format!(
            "# t_host[s],altitude[m],true_pressure[Pa],pressure_bias[Pa]\n# barometer at the IMU origin; altitude = start altitude {:.6} m + world z\n",
            b.start_altitude_m
        )
    });
    // Messages before this IMU sample that were not IMU samples (pressure): every message, sent
    // or dropped, takes the next PacketCounter value.
    let mut extra = 0u64;
    let mut baro_j = 0u64;
    for k in 0u64.. {
        let ts = s0 + k as f64 * dt;
        let th = iclk.to_host(ts);
        if th >= sc.duration_s {
            break;
        }
        if let (Some(b), Some(bt)) = (baro.as_mut(), btruth.as_mut()) {
            let bdt = 1.0 / sc.baro_hz;
            loop {
                let tb = s0 + baro_j as f64 * bdt;
                if tb > ts {
                    break;
                }
                let thb = iclk.to_host(tb);
                let z = traj.pose(thb).compose(&t_bi, &q_bi).p.z;
                let m = b.sample(z, bdt);
                let stf = ((tb * 1e4).round() as u64 % (1u64 << 32)) as u32;
                let bytes = imu::encode_pressure((k + extra) as u16, stf, m.pa);
                let (_, reads) = uart.send(thb + IMU_LATENCY_S, bytes.len(), &mut link_rng);
                let mut at = 0;
                for r in reads {
                    is.write_chunk(r.host_ns, &bytes[at..at + r.len])?;
                    at += r.len;
                }
                let _ = writeln!(
                    bt,
                    "{thb:.9},{:.6},{:.6},{:.6}",
                    m.altitude_m, m.true_pa, m.bias_pa
                );
                baro_j += 1;
                extra += 1;
            }
        }
        let q_wi = traj.pose(th).q * q_bi;
        let a = traj.point_acceleration(th, &t_bi);
        let f = q_wi.inverse() * (a - g);
        let wv = traj.angular_velocity(th, &q_bi);
        let s = dev.sample(f, wv, dt);
        if gaps.as_mut().is_some_and(|g| g.drop_next()) {
            // Measured (the noise processes run on) but never sent.
            continue;
        }
        let stf = ((ts * 1e4).round() as u64 % (1u64 << 32)) as u32;
        let bytes = imu::encode((k + extra) as u16, stf, &s);
        let (_, reads) = uart.send(th + IMU_LATENCY_S, bytes.len(), &mut link_rng);
        let mut at = 0;
        for r in reads {
            is.write_chunk(r.host_ns, &bytes[at..at + r.len])?;
            at += r.len;
        }
        let _ = writeln!(
            itruth,
            "{th:.9},{},{},{},{},{},{}",
            s.accel_bias.x,
            s.accel_bias.y,
            s.accel_bias.z,
            s.gyro_bias.x,
            s.gyro_bias.y,
            s.gyro_bias.z
        );
        sum.imu_samples += 1;
        if k % 2000 == 0 {
            progress(0.8 + 0.15 * (th / sc.duration_s).min(1.0));
        }
    }
    sum.imu_bytes = is.finish()?;
    write_file(dir, IMU_TRUTH_FILE, &itruth)?;
    if let Some(bt) = &btruth {
        write_file(dir, BARO_TRUTH_FILE, bt)?;
    }

    // Ground truth.
    let n = ((sc.duration_s + GT_TAIL_S) * GT_HZ).floor() as usize;
    let poses: Vec<TumPose> = (0..=n)
        .map(|i| {
            let t = i as f64 / GT_HZ;
            let p = traj.pose(t);
            TumPose {
                t,
                p: [p.p.x, p.p.y, p.p.z],
                q: [p.q.i, p.q.j, p.q.k, p.q.w],
            }
        })
        .collect();
    w.groundtruth(&poses)?;
    w.finish()?;
    if sum.frames == 0 {
        sum.points_min = 0;
    }
    progress(1.0);
    Ok(sum)
}

fn write_file(dir: &Path, name: &str, text: &str) -> Result<(), SimError> {
    let p = dir.join(name);
    std::fs::write(&p, text).map_err(|e| SimError::Io(format!("{}: {e}", p.display())))
}
