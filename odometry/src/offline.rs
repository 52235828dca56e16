//! Running the classical estimators over a recorded or simulated session: Doppler radar-inertial
//! odometry, or IMU-only dead reckoning (the same integration code), giving a trajectory of the
//! body frame at radar rate on the session host clock, ready for `milliego eval` against ground
//! truth.

use crate::ego_velocity::{Config as EgoConfig, Detection, EgoVelocityEstimator, Prior, Status};
use crate::rio::{RadarMount, Rio, RioConfig, VelocityMeasurement};
use crate::strapdown::ImuSample;
use milliego_session::streams::{imu_samples, radar_frames, ClockFit, SessionClock, StreamReport};
use milliego_session::{Extrinsic, Session, SessionError, TumPose};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Which estimator to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimator {
    /// Radar ego-velocity fused with the IMU.
    Doppler,
    /// IMU integration alone.
    ImuOnly,
}

/// Settings of an offline run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OfflineConfig {
    /// Estimator.
    pub estimator: Estimator,
    /// Filter settings.
    pub rio: RioConfig,
    /// Ego-velocity settings.
    pub ego: EgoConfig,
    /// Time at the start used to level the attitude from gravity \[s\].
    pub level_window_s: f64,
    /// Factor on the ego-velocity covariance before the filter takes it: the least-squares
    /// covariance ignores direction errors (angular resolution) and ghost points that slip into
    /// the consensus of a sparse frame.
    pub velocity_cov_scale: f64,
}

impl Default for OfflineConfig {
    fn default() -> Self {
        OfflineConfig {
            estimator: Estimator::Doppler,
            rio: RioConfig::default(),
            ego: EgoConfig::default(),
            level_window_s: 1.0,
            velocity_cov_scale: 1.0,
        }
    }
}

/// What an offline run did.
#[derive(Debug, Clone, PartialEq)]
pub struct OfflineResult {
    /// Body poses in the world frame at radar rate (time: session host clock \[s\]).
    pub trajectory: Vec<TumPose>,
    /// Radar stream decoding.
    pub radar: StreamReport,
    /// IMU stream decoding.
    pub imu: StreamReport,
    /// Radar frames decoded.
    pub radar_frames: usize,
    /// Frames with a usable ego-velocity.
    pub ego_ok: usize,
    /// Frames whose geometry could not determine the velocity.
    pub ego_degenerate: usize,
    /// Frames with too few points.
    pub ego_too_few: usize,
    /// Frames without consensus.
    pub ego_no_consensus: usize,
    /// Filter updates applied and gated.
    pub updates: u64,
    /// Filter updates rejected by the gate.
    pub gated: u64,
    /// IMU samples integrated.
    pub imu_samples: usize,
    /// Sensor-to-host clock maps (None when the session has no timing index).
    pub radar_clock: Option<ClockFit>,
    /// IMU clock map.
    pub imu_clock: Option<ClockFit>,
    /// True when the streams could not be put on one clock (no index): sensor clocks are then
    /// assumed to start together.
    pub clock_unsynced: bool,
}

/// Why a run could not start.
#[derive(Debug)]
pub enum OfflineError {
    /// Reading the session failed.
    Session(SessionError),
    /// A stream the estimator needs is missing or empty.
    Missing(&'static str),
}

impl std::fmt::Display for OfflineError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OfflineError::Session(e) => write!(f, "{e}"),
            OfflineError::Missing(what) => write!(f, "the session has no {what}"),
        }
    }
}

impl std::error::Error for OfflineError {}

impl From<SessionError> for OfflineError {
    fn from(e: SessionError) -> Self {
        OfflineError::Session(e)
    }
}

fn iso(e: &Extrinsic) -> (UnitQuaternion<f64>, Vector3<f64>) {
    let [w, x, y, z] = e.rotation_wxyz;
    (
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        Vector3::from(e.translation_m),
    )
}

/// Runs `cfg.estimator` over `session`.
pub fn run(session: &Session, cfg: &OfflineConfig) -> Result<OfflineResult, OfflineError> {
    let (frames, radar_rep) = radar_frames(session)?;
    let (imu, imu_rep) = imu_samples(session)?;
    if imu.is_empty() {
        return Err(OfflineError::Missing(
            "IMU samples (acceleration, rate of turn, SampleTimeFine)",
        ));
    }
    if cfg.estimator == Estimator::Doppler && frames.is_empty() {
        return Err(OfflineError::Missing("radar frames"));
    }
    // One time base for both streams (the lower-envelope clock fits of the session crate).
    let clock = SessionClock::fit(session, &frames, &imu)?;
    let (radar_clock, imu_clock, clock_unsynced) = (clock.radar, clock.imu, clock.unsynced());
    let imu_t = |s: f64| clock.imu_s(s);
    let radar_t = |f: &milliego_session::streams::RadarFrame| clock.radar_s(f);

    // Radar and IMU placement: the filter runs in the IMU frame.
    let (q_bi, t_bi) = iso(&session.meta.extrinsics.imu);
    let (q_br, t_br) = iso(&session.meta.extrinsics.radar);
    let q_ir = q_bi.inverse() * q_br;
    let t_ir = q_bi.inverse() * (t_br - t_bi);
    let mount = RadarMount {
        rotation: q_ir,
        translation: t_ir,
    };

    // Level from the mean specific force over the first window.
    let t0 = imu_t(imu[0].sensor_s);
    let head: Vec<&milliego_session::streams::ImuSample> = imu
        .iter()
        .take_while(|s| imu_t(s.sensor_s) - t0 <= cfg.level_window_s)
        .collect();
    let mean_f = head
        .iter()
        .fold(Vector3::zeros(), |a, s| a + Vector3::from(s.accel))
        / head.len().max(1) as f64;
    let mut rio = Rio::levelled(cfg.rio, mount, t0, mean_f.into());

    let mut ego = EgoVelocityEstimator::new(cfg.ego);
    let mut res = OfflineResult {
        trajectory: Vec::new(),
        radar: radar_rep,
        imu: imu_rep,
        radar_frames: frames.len(),
        ego_ok: 0,
        ego_degenerate: 0,
        ego_too_few: 0,
        ego_no_consensus: 0,
        updates: 0,
        gated: 0,
        imu_samples: imu.len(),
        radar_clock,
        imu_clock,
        clock_unsynced,
    };
    let mut radar_times: Vec<(f64, usize)> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| Some((radar_t(f)?, i)))
        .collect();
    radar_times.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut next = 0;
    let mut outputs: Vec<f64> = Vec::new();
    let (q_ib, t_ib) = (q_bi.inverse(), -(q_bi.inverse() * t_bi));
    let mut dets = Vec::new();
    let mut rejected_in_row = 0u32;
    for s in &imu {
        let t = imu_t(s.sensor_s);
        while next < radar_times.len() && radar_times[next].0 <= t {
            let (tr, i) = radar_times[next];
            next += 1;
            if tr < t0 {
                continue;
            }
            outputs.push(tr);
            if cfg.estimator != Estimator::Doppler {
                continue;
            }
            dets.clear();
            dets.extend(frames[i].cloud.points.iter().map(|p| Detection {
                position: [p.x, p.y, p.z],
                radial_velocity: p.velocity,
            }));
            // Guide the consensus with the filter's prediction once the velocity is known and
            // the filter is healthy (its last frames were accepted): a diverged filter's prior
            // would only keep rejecting the truth.
            let healthy = rio.counters().updates >= 10 && rejected_in_row < 3;
            let prior = healthy.then(|| {
                let (velocity, covariance) = rio.predicted_radar_velocity();
                Prior {
                    velocity,
                    covariance,
                    gate: cfg.rio.gate,
                }
            });
            let e = ego.estimate_guided(&dets, prior);
            match e.status {
                Status::Ok => {
                    res.ego_ok += 1;
                    let c = e
                        .covariance
                        .map(|r| r.map(|x| f64::from(x) * cfg.velocity_cov_scale));
                    rio.push_velocity(VelocityMeasurement {
                        t: tr,
                        velocity: e.velocity.map(f64::from),
                        covariance: c,
                    });
                }
                Status::Degenerate { .. } => res.ego_degenerate += 1,
                Status::TooFewPoints { .. } => res.ego_too_few += 1,
                Status::NoConsensus { .. } => {
                    res.ego_no_consensus += 1;
                    rejected_in_row += u32::from(healthy);
                }
            }
        }
        let before = *rio.counters();
        rio.push_imu(ImuSample {
            t,
            accel: s.accel,
            gyro: s.gyro,
        });
        let after = rio.counters();
        if after.updates > before.updates {
            rejected_in_row = 0;
        } else if after.gated > before.gated {
            rejected_in_row += 1;
        }
        for tr in outputs.drain(..) {
            let st = rio.state();
            // Body pose: T_wb = T_wi * T_ib.
            let q = st.q * q_ib;
            let p = st.p + st.q * t_ib;
            res.trajectory.push(TumPose {
                t: tr,
                p: p.into(),
                q: [q.i, q.j, q.k, q.w],
            });
        }
    }
    res.updates = rio.counters().updates;
    res.gated = rio.counters().gated;
    Ok(res)
}
