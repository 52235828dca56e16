//! The estimator interface and the classical estimators behind it: `doppler` (radar ego-velocity
//! fused with the IMU in the error-state filter of `milliego-odometry`, as its offline runner does)
//! and `imu` (the same integration, no radar updates). The learned model plugs in through
//! [`build_estimator`].

use milliego_odometry::ego_velocity::{
    Config as EgoConfig, Detection, EgoVelocityEstimator, Estimate, Prior, Status,
};
use milliego_odometry::rio::{RadarMount, Rio, RioConfig, VelocityMeasurement};
use milliego_odometry::strapdown::{ImuSample, NavState};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// One radar frame for an estimator.
#[derive(Debug, Clone, Copy)]
pub struct RadarInput<'a> {
    /// Measurement time on the common clock \[s\].
    pub t: f64,
    /// Frame counter of the radar.
    pub frame_number: u32,
    /// Points (radar frame: x right, y boresight, z up \[m\]; radial velocity \[m/s\]).
    pub points: &'a [radar_driver::host::Point],
}

/// One IMU sample for an estimator (IMU sensor frame, SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuInput {
    /// Time on the common clock \[s\].
    pub t: f64,
    /// Specific force \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn \[rad/s\].
    pub gyro: [f64; 3],
}

/// Motion of the body between two radar frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativePose {
    /// Frame the motion starts at.
    pub from_frame: u32,
    /// Frame the motion ends at.
    pub to_frame: u32,
    /// Time of `from_frame` \[s\].
    pub t_from: f64,
    /// Time of `to_frame` \[s\].
    pub t_to: f64,
    /// Body pose at `to`, in the body frame at `from` (translation \[m\]).
    pub rel: Isometry3<f64>,
    /// Body velocity in the world frame at `to` \[m/s\], when the estimator knows it.
    pub velocity_world: Option<Vector3<f64>>,
}

/// Why an estimator could not process an input.
#[derive(Debug, Clone, PartialEq)]
pub enum EstimatorError {
    /// The estimator is not usable (for example, the learned model failed); carries why.
    Unhealthy(String),
}

impl std::fmt::Display for EstimatorError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EstimatorError::Unhealthy(why) => write!(f, "estimator unhealthy: {why}"),
        }
    }
}

impl std::error::Error for EstimatorError {}

/// An egomotion estimator fed in time order.
pub trait Estimator: Send {
    /// Short name (`doppler`, `imu`, `model`).
    fn name(&self) -> &'static str;
    /// One IMU sample.
    fn push_imu(&mut self, s: &ImuInput);
    /// One radar frame; the relative pose it produces, if any.
    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError>;
    /// False when the estimator's outputs should not be trusted.
    fn healthy(&self) -> bool;
}

/// Which estimator a run uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorKind {
    /// The learned milliEgo model.
    Model,
    /// Doppler radar-inertial odometry.
    Doppler,
    /// IMU dead reckoning.
    Imu,
    /// The model when available and healthy, else Doppler; IMU propagation while radar is
    /// missing.
    Auto,
}

impl EstimatorKind {
    /// Lowercase name.
    pub fn name(self) -> &'static str {
        match self {
            EstimatorKind::Model => "model",
            EstimatorKind::Doppler => "doppler",
            EstimatorKind::Imu => "imu",
            EstimatorKind::Auto => "auto",
        }
    }
}

/// Where the sensors sit on the body (body frame = the ground-truth body frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mounting {
    /// IMU in the body frame.
    pub imu: Isometry3<f64>,
    /// Radar in the body frame.
    pub radar: Isometry3<f64>,
}

impl Default for Mounting {
    fn default() -> Self {
        Mounting {
            imu: Isometry3::identity(),
            radar: Isometry3::identity(),
        }
    }
}

impl Mounting {
    /// From a session's extrinsics.
    pub fn from_session(e: &milliego_session::Extrinsics) -> Mounting {
        let iso = |x: &milliego_session::Extrinsic| {
            let [w, i, j, k] = x.rotation_wxyz;
            Isometry3::from_parts(
                Translation3::from(Vector3::from(x.translation_m)),
                UnitQuaternion::from_quaternion(Quaternion::new(w, i, j, k)),
            )
        };
        Mounting {
            imu: iso(&e.imu),
            radar: iso(&e.radar),
        }
    }
}

/// Settings of the classical estimators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassicalConfig {
    /// Filter settings.
    pub rio: RioConfig,
    /// Ego-velocity settings.
    pub ego: EgoConfig,
    /// Time at the start used to level the attitude from gravity \[s\].
    pub level_window_s: f64,
    /// Factor on the ego-velocity covariance.
    pub velocity_cov_scale: f64,
    /// Sensor placement.
    pub mounting: Mounting,
    /// IMU silent for longer than this before a radar frame: the frame is dead-reckoned from
    /// its ego-velocity alone and the filter restarts when the IMU returns \[s\].
    pub imu_gap_s: f64,
}

impl Default for ClassicalConfig {
    fn default() -> Self {
        let o = milliego_odometry::offline::OfflineConfig::default();
        ClassicalConfig {
            rio: o.rio,
            ego: o.ego,
            level_window_s: o.level_window_s,
            velocity_cov_scale: o.velocity_cov_scale,
            mounting: Mounting::default(),
            imu_gap_s: 0.1,
        }
    }
}

/// Radar frame seen while levelling, measured and applied once the filter starts.
#[derive(Debug, Clone)]
struct Early {
    t: f64,
    frame_number: u32,
    points: Vec<radar_driver::host::Point>,
}

/// Doppler radar-inertial odometry (or, with `use_radar = false`, IMU dead reckoning): the
/// filter of `milliego-odometry`, fed the way its offline runner feeds it.
#[derive(Debug)]
pub struct Classical {
    cfg: ClassicalConfig,
    use_radar: bool,
    mount: RadarMount,
    q_ib: UnitQuaternion<f64>,
    t_ib: Vector3<f64>,
    rio: Option<Rio>,
    // Levelling: the first IMU samples and radar measurements, replayed when the filter starts.
    level: Vec<ImuSample>,
    early: Vec<Early>,
    ego: EgoVelocityEstimator,
    est: Estimate,
    dets: Vec<Detection>,
    // The prior and health as they were before the latest IMU sample (what the offline runner
    // uses for a frame that falls between two samples).
    prior_before: Option<([f64; 3], [[f64; 3]; 3])>,
    healthy_before: bool,
    rejected_in_row: u32,
    last_imu_t: Option<f64>,
    prev: Option<(u32, f64, Isometry3<f64>)>,
    // Radar-only dead reckoning while the IMU is missing.
    dr: Option<NavState>,
    /// Frames with a usable ego-velocity.
    pub ego_ok: u64,
    /// Frames dead-reckoned without the IMU.
    pub radar_only: u64,
}

impl Classical {
    /// Doppler radar-inertial odometry.
    pub fn doppler(cfg: ClassicalConfig) -> Self {
        Self::new(cfg, true)
    }

    /// IMU dead reckoning.
    pub fn imu_only(cfg: ClassicalConfig) -> Self {
        Self::new(cfg, false)
    }

    fn new(cfg: ClassicalConfig, use_radar: bool) -> Self {
        let q_bi = cfg.mounting.imu.rotation;
        let t_bi = cfg.mounting.imu.translation.vector;
        let q_br = cfg.mounting.radar.rotation;
        let t_br = cfg.mounting.radar.translation.vector;
        let mount = RadarMount {
            rotation: q_bi.inverse() * q_br,
            translation: q_bi.inverse() * (t_br - t_bi),
        };
        Classical {
            cfg,
            use_radar,
            mount,
            q_ib: q_bi.inverse(),
            t_ib: -(q_bi.inverse() * t_bi),
            rio: None,
            level: Vec::with_capacity(4096),
            early: Vec::with_capacity(256),
            ego: EgoVelocityEstimator::new(cfg.ego),
            est: Estimate {
                velocity: [0.0; 3],
                covariance: [[0.0; 3]; 3],
                status: Status::Ok,
                inliers: 0,
                usable: 0,
                skipped: 0,
                residual_rms: 0.0,
                inlier_mask: Vec::with_capacity(1024),
                iterations: 0,
            },
            dets: Vec::with_capacity(1024),
            prior_before: None,
            healthy_before: false,
            rejected_in_row: 0,
            last_imu_t: None,
            prev: None,
            dr: None,
            ego_ok: 0,
            radar_only: 0,
        }
    }

    /// The filter, once levelled.
    pub fn filter(&self) -> Option<&Rio> {
        self.rio.as_ref()
    }

    /// Body pose in the world frame and world velocity of the current filter state.
    pub fn body_state(&self) -> Option<(f64, Isometry3<f64>, Vector3<f64>)> {
        let st = match (&self.dr, &self.rio) {
            (Some(d), _) => *d,
            (None, Some(r)) => *r.state(),
            _ => return None,
        };
        Some((st.t, self.body(&st), st.v))
    }

    fn body(&self, st: &NavState) -> Isometry3<f64> {
        // T_wb = T_wi * T_ib.
        let q = st.q * self.q_ib;
        let p = st.p + st.q * self.t_ib;
        Isometry3::from_parts(Translation3::from(p), q)
    }

    /// The ego-velocity of a frame (status in `self.est`), with `prior`.
    fn ego_measure(
        &mut self,
        f: &RadarInput<'_>,
        prior: Option<Prior>,
    ) -> Option<VelocityMeasurement> {
        self.dets.clear();
        self.dets.extend(f.points.iter().map(|p| Detection {
            position: [p.x, p.y, p.z],
            radial_velocity: p.velocity,
        }));
        self.ego
            .estimate_guided_into(&self.dets, prior, &mut self.est);
        match self.est.status {
            Status::Ok => {
                self.ego_ok += 1;
                let s = self.cfg.velocity_cov_scale;
                Some(VelocityMeasurement {
                    t: f.t,
                    velocity: self.est.velocity.map(f64::from),
                    covariance: self.est.covariance.map(|r| r.map(|x| f64::from(x) * s)),
                })
            }
            _ => None,
        }
    }

    fn start_filter(&mut self) {
        let n = self.level.len().max(1) as f64;
        let mean_f = self
            .level
            .iter()
            .fold(Vector3::zeros(), |a, s| a + Vector3::from(s.accel))
            / n;
        let t0 = self.level[0].t;
        tracing::debug!(t0, samples = self.level.len(), t_last = self.level[self.level.len() - 1].t, early = self.early.len(), mean_f = ?mean_f, "levelled; filter starts");
        self.rio = Some(Rio::levelled(self.cfg.rio, self.mount, t0, mean_f.into()));
        // Replay as the offline runner orders it: frames due at or before a sample go first,
        // measured with the prior the filter has at that point.
        let early = std::mem::take(&mut self.early);
        let level = std::mem::take(&mut self.level);
        let mut next = 0;
        for s in &level {
            while next < early.len() && early[next].t <= s.t {
                let e = &early[next];
                next += 1;
                if e.t < t0 {
                    continue;
                }
                let f = RadarInput {
                    t: e.t,
                    frame_number: e.frame_number,
                    points: &e.points,
                };
                self.radar_update(&f, self.current_prior());
            }
            let Some(rio) = self.rio.as_mut() else {
                return;
            };
            let before = *rio.counters();
            rio.push_imu(*s);
            let after = rio.counters();
            if after.updates > before.updates {
                self.rejected_in_row = 0;
            } else if after.gated > before.gated {
                self.rejected_in_row += 1;
            }
        }
        self.early = early;
        self.early.clear();
        self.level = level;
        self.level.clear();
    }

    /// The filter's prior for the next frame, when it is healthy (as the offline runner).
    fn current_prior(&self) -> Option<([f64; 3], [[f64; 3]; 3])> {
        let rio = self.rio.as_ref()?;
        (rio.counters().updates >= 10 && self.rejected_in_row < 3)
            .then(|| rio.predicted_radar_velocity())
    }

    /// Ego-velocity of `f` guided by `prior`, pushed into the filter; tracks rejections.
    fn radar_update(&mut self, f: &RadarInput<'_>, prior: Option<([f64; 3], [[f64; 3]; 3])>) {
        let gate = self.cfg.rio.gate;
        let prior = prior.map(|(velocity, covariance)| Prior {
            velocity,
            covariance,
            gate,
        });
        let healthy = prior.is_some();
        let m = self.ego_measure(f, prior);
        let no_consensus = matches!(self.est.status, Status::NoConsensus { .. });
        if let Some(rio) = self.rio.as_mut() {
            let before = *rio.counters();
            if let Some(m) = m {
                rio.push_velocity(m);
            }
            let after = rio.counters();
            if after.updates > before.updates {
                self.rejected_in_row = 0;
            } else if after.gated > before.gated {
                self.rejected_in_row += 1;
            }
        }
        if no_consensus {
            self.rejected_in_row += u32::from(healthy);
        }
    }

    fn restart_after_imu_gap(&mut self, s: &ImuSample) {
        // The IMU is back after a gap the radar bridged: a fresh filter at the dead-reckoned
        // state (tilt and biases re-learned, the pose kept).
        if let Some(d) = self.dr.take() {
            let st = NavState { t: s.t, ..d };
            self.rio = Some(Rio::new(self.cfg.rio, self.mount, st));
        }
    }
}

impl Estimator for Classical {
    fn name(&self) -> &'static str {
        if self.use_radar {
            "doppler"
        } else {
            "imu"
        }
    }

    fn push_imu(&mut self, s: &ImuInput) {
        let sample = ImuSample {
            t: s.t,
            accel: s.accel,
            gyro: s.gyro,
        };
        self.last_imu_t = Some(s.t);
        if self.dr.is_some() {
            self.restart_after_imu_gap(&sample);
        }
        if self.rio.is_none() {
            // Level over the samples within the window of the first one (as the offline runner).
            let past = self
                .level
                .first()
                .is_some_and(|f| s.t - f.t > self.cfg.level_window_s);
            if past || self.level.len() == self.level.capacity() {
                self.start_filter();
            } else {
                self.level.push(sample);
                return;
            }
        }
        let Some(rio) = self.rio.as_mut() else {
            return;
        };
        self.healthy_before = rio.counters().updates >= 10 && self.rejected_in_row < 3;
        self.prior_before = Some(rio.predicted_radar_velocity());
        rio.push_imu(sample);
    }

    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        let imu_gap = self.last_imu_t.is_none_or(|t| f.t - t > self.cfg.imu_gap_s);
        if self.rio.is_none() {
            // Levelling: measure now (no prior before 10 updates anyway), apply at the start.
            if self.use_radar && self.early.len() < self.early.capacity() {
                self.early.push(Early {
                    t: f.t,
                    frame_number: f.frame_number,
                    points: f.points.to_vec(),
                });
            }
            return Ok(None);
        }
        if imu_gap {
            // No IMU: hold the attitude, integrate the radar velocity.
            let Some(rio) = self.rio.as_ref() else {
                return Ok(None);
            };
            let mut st = self.dr.unwrap_or(*rio.state());
            if self.use_radar {
                if let Some(m) = self.ego_measure(f, None) {
                    // The radar's own velocity in its frame (lever arm neglected without gyro).
                    let v_i = self.mount.rotation * Vector3::from(m.velocity);
                    st.v = st.q * v_i;
                }
            }
            let dt = (f.t - st.t).max(0.0);
            st.p += st.v * dt;
            st.t = f.t;
            self.dr = Some(st);
            self.radar_only += 1;
        } else if self.use_radar {
            let prior = if self.healthy_before {
                self.prior_before
            } else {
                None
            };
            self.radar_update(f, prior);
        }
        let Some((_, body, v)) = self.body_state() else {
            return Ok(None);
        };
        let out = match self.prev {
            Some((pf, pt, pb)) => RelativePose {
                from_frame: pf,
                to_frame: f.frame_number,
                t_from: pt,
                t_to: f.t,
                rel: pb.inverse() * body,
                velocity_world: Some(v),
            },
            // The first pose: relative to the world origin (the levelled start), announced as
            // coming from a frame the composer does not know.
            None => RelativePose {
                from_frame: f.frame_number.wrapping_sub(1),
                to_frame: f.frame_number,
                t_from: f.t,
                t_to: f.t,
                rel: body,
                velocity_world: Some(v),
            },
        };
        self.prev = Some((f.frame_number, f.t, body));
        Ok(Some(out))
    }

    fn healthy(&self) -> bool {
        self.rio.is_some()
    }
}

/// Why an estimator could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum BuildError {
    /// No model file was given.
    ModelUnavailable,
    /// The model file could not be loaded.
    BadModel(String),
}

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BuildError::ModelUnavailable => {
                write!(
                    f,
                    "the learned-model estimator needs a model file (--model PATH)"
                )
            }
            BuildError::BadModel(why) => write!(f, "cannot load the model: {why}"),
        }
    }
}

impl std::error::Error for BuildError {}

/// The estimators of a run: the primary one, and for `auto` the fallback beside it.
pub struct Built {
    /// The estimator that produces poses while healthy.
    pub primary: Box<dyn Estimator>,
    /// Fallback used when the primary is unavailable or unhealthy (`auto` only).
    pub fallback: Option<Box<dyn Estimator>>,
    /// True when `auto` could not get the model (poses carry MODEL_FALLBACK).
    pub model_fallback: bool,
}

impl std::fmt::Debug for Built {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Built")
            .field("primary", &self.primary.name())
            .field("fallback", &self.fallback.as_ref().map(|e| e.name()))
            .field("model_fallback", &self.model_fallback)
            .finish()
    }
}

/// Builds one estimator of `kind`. The single place where estimators are made: the learned
/// model joins here (`model_path` is its file).
pub fn build_estimator(
    kind: EstimatorKind,
    cfg: &ClassicalConfig,
    model_path: Option<&std::path::Path>,
) -> Result<Box<dyn Estimator>, BuildError> {
    match kind {
        EstimatorKind::Doppler => Ok(Box::new(Classical::doppler(*cfg))),
        EstimatorKind::Imu => Ok(Box::new(Classical::imu_only(*cfg))),
        EstimatorKind::Model => {
            let path = model_path.ok_or(BuildError::ModelUnavailable)?;
            crate::model::ModelEstimator::load(path, &cfg.mounting)
                .map(|m| Box::new(m) as Box<dyn Estimator>)
                .map_err(BuildError::BadModel)
        }
        EstimatorKind::Auto => match build_estimator(EstimatorKind::Model, cfg, model_path) {
            Ok(m) => Ok(m),
            Err(_) => build_estimator(EstimatorKind::Doppler, cfg, model_path),
        },
    }
}

/// The estimators for a run of `kind`: `auto` tries the model and falls back to Doppler
/// (MODEL_FALLBACK on every pose) when it is unavailable; a fixed kind fails at start-up.
pub fn build_run_estimators(
    kind: EstimatorKind,
    cfg: &ClassicalConfig,
    model_path: Option<&std::path::Path>,
) -> Result<Built, BuildError> {
    match kind {
        EstimatorKind::Auto => match build_estimator(EstimatorKind::Model, cfg, model_path) {
            Ok(m) => Ok(Built {
                primary: m,
                fallback: Some(build_estimator(EstimatorKind::Doppler, cfg, None)?),
                model_fallback: false,
            }),
            Err(BuildError::BadModel(why)) if model_path.is_some() => {
                Err(BuildError::BadModel(why))
            }
            Err(_) => Ok(Built {
                primary: build_estimator(EstimatorKind::Doppler, cfg, None)?,
                fallback: None,
                model_fallback: true,
            }),
        },
        k => Ok(Built {
            primary: build_estimator(k, cfg, model_path)?,
            fallback: None,
            model_fallback: false,
        }),
    }
}
