//! The classical radar-inertial loop, once, as a stream: IMU samples and radar frames go in one at
//! a time (in time order, which the caller keeps), body poses at the radar frames come out.
//!
//! Both the offline runner ([`crate::offline::run`]) and the on-device runtime's `doppler` and
//! `imu` estimators are loops over a [`Runner`], so what the filter does is written here only:
//!
//! * levelling: the attitude starts level from the mean specific force over the first
//!   [`ClassicalConfig::level_window_s`] of IMU samples; samples and frames seen meanwhile are
//!   kept and replayed when the filter starts (their poses then come out together);
//! * priors: a frame's ego-velocity consensus is guided by the filter's predicted radar velocity
//!   at the last IMU sample before the frame, but only while the filter is healthy
//!   ([`guided`], the one health rule);
//! * ego-velocity gating and the [`Rio`] updates (chi-square gate and velocity re-anchoring after
//!   a run of gated measurements live in the filter);
//! * rest ([`crate::rest`]): while the IMU is still and the radar's ego-velocity is zero, the
//!   filter takes zero-velocity and zero-rate pseudo-measurements (gyro bias from the whole rest,
//!   no drift);
//! * sparse frames (optional, [`ClassicalConfig::stack_window_s`]): a frame whose points alone
//!   give no ego-velocity is kept; its points, carried to a later frame with the motion the IMU
//!   integrated in between, join that frame's consensus (each point is used once);
//! * IMU gaps: a frame more than [`ClassicalConfig::imu_gap_s`] after the last IMU sample is
//!   dead-reckoned from its ego-velocity alone, and the filter re-anchors at the dead-reckoned
//!   state when the IMU returns;
//! * aids: each pose says how long it has rested on the IMU alone ([`FramePose::unaided_s`]: since
//!   the last radar velocity, rest update or learned measurement), and the run keeps its longest
//!   such stretch ([`Runner::longest_unaided`]).
//!
//! Order: a frame may come either just before the first IMU sample at or past its time (the
//! offline order) or just after it (the runtime synchroniser's order). Either way its prior is
//! the filter's prediction at the last sample before it, and its pose is the filter state at the
//! first sample at or past it with its update applied: at once in the runtime order, at that
//! sample in the offline order. Where several frames fall between two samples (an IMU gap), the
//! filter's state after each sample is still the same in both orders (their updates count into
//! the run of rejected frames at that sample in both); the poses given differ: offline each is
//! the state with all those frames' updates, in the runtime order with those up to its own.

use crate::ego_velocity::{
    Config as EgoConfig, Detection, EgoVelocityEstimator, Estimate, Prior, Status,
};
use crate::lattice::DopplerLattice;
use crate::leakage::{LeakageDetector, LEAK_RANGE_M};
use crate::learned::{
    Calibration, LearnedConfig, LearnedCounters, Monitor, Outcome, RelativeMotion, SCALE_COVERS,
};
use crate::persist::{radar_pose, PersistConfig, PointHistory};
use crate::rest::{RestConfig, RestDetector, Verdict};
use crate::rio::{RadarMount, Rio, RioConfig, RioCounters, VelocityMeasurement};
use crate::strapdown::{ImuSample, NavState};
use nalgebra::{Isometry3, Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};
use radar_driver::tlv::Point;
use std::collections::VecDeque;

/// Radar updates the filter needs before its prediction may guide the ego-velocity consensus.
pub const GUIDE_AFTER_UPDATES: u64 = 10;

/// Consecutive rejected frames (gated by the filter, or no consensus under its prior) after which
/// the prior stops guiding: a diverged filter's prior would only keep rejecting the truth.
pub const MAX_REJECTED_IN_ROW: u32 = 3;

/// IMU samples kept for levelling at most (the filter starts when the buffer is full).
pub const LEVEL_CAPACITY: usize = 4096;

/// Radar frames kept while levelling at most (later ones get no pose).
pub const EARLY_CAPACITY: usize = 256;

/// Frame poses kept for learned measurements ([`Runner::push_relative_motion`]): 3.2 s at 20 Hz.
pub const ANCHOR_CAPACITY: usize = 64;

/// Frames kept for stacking at most ([`ClassicalConfig::stack_window_s`]).
pub const STACK_FRAMES: usize = 16;

/// How long a pose may rest on the IMU alone before it is called unaided \[s\]
/// ([`FramePose::unaided_s`]; the runtime's `dead_reckoning` health flag): no radar velocity, rest
/// or learned measurement was applied for longer than this. One second: about 20 radar frames,
/// after which an MTi-1-class IMU's velocity error alone (tilt and bias, no aid) grows past
/// walking-pace precision (0.05 m/s), and a sparse scene has shown it cannot give a velocity.
pub const UNAIDED_AFTER_S: f64 = 1.0;

/// Points kept for stacking at most (older frames give way).
pub const STACK_POINTS: usize = 1024;

/// Inliers a velocity from stacked frames needs at least: more than one frame's
/// ([`EgoConfig::min_inliers`]), since carried points from several sparse frames also carry
/// their ghosts and moving objects, which can agree by chance.
pub const STACK_MIN_INLIERS: usize = 8;

/// Share of the stacked points that must agree with a velocity from stacked frames.
pub const STACK_MIN_INLIER_SHARE: f32 = 0.5;

/// Largest difference between two keyframe times taken as the same \[s\]: a learned
/// measurement's and a frame pose's, or one measurement's end and the next one's start.
pub(crate) const ANCHOR_TOLERANCE_S: f64 = 1e-3;

/// The health rule: whether a filter with `updates` applied radar updates (and rest updates, which
/// pin the velocity as well) and `rejected_in_row` frames rejected in a row may guide the next
/// frame's ego-velocity with its prediction.
pub fn guided(updates: u64, rejected_in_row: u32) -> bool {
    updates >= GUIDE_AFTER_UPDATES && rejected_in_row < MAX_REJECTED_IN_ROW
}

/// The updates the health rule counts: radar updates applied and rest updates (which pin the
/// velocity as well).
fn health_updates(c: &RioCounters) -> u64 {
    c.updates + c.rest_updates
}

/// Where the sensors sit on the body (body frame = the ground-truth body frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mounting {
    /// IMU in the body frame (translation \[m\]).
    pub imu: Isometry3<f64>,
    /// Radar in the body frame (translation \[m\]).
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
    /// Factor on the ego-velocity covariance before the filter takes it: the least-squares
    /// covariance ignores direction errors (angular resolution) and ghost points that slip into
    /// the consensus of a sparse frame.
    pub velocity_cov_scale: f64,
    /// Sensor placement.
    pub mounting: Mounting,
    /// Rest detection and the updates at rest.
    pub rest: RestConfig,
    /// IMU silent for longer than this before a radar frame: the frame is dead-reckoned from
    /// its ego-velocity alone and the filter restarts when the IMU returns \[s\]
    /// (`f64::INFINITY`: never).
    pub imu_gap_s: f64,
    /// Learned relative motions as measurements ([`crate::learned`]; only the fused estimators
    /// give any).
    pub learned: LearnedConfig,
    /// Frames whose points alone give no ego-velocity (too few, no consensus, degenerate
    /// directions) are kept this long \[s\]: their points, each carried to a later frame with
    /// the rotation and the velocity change the IMU integrated in between, join that frame's
    /// points when it cannot decide alone either. Sparse scenes (an atrium, outdoors) then still
    /// give velocities. Each point serves one estimate at most. 0 (the default): off; 0.15 s
    /// helps the Doppler filter on the validation and training sets but makes `auto` and fused
    /// worse on v1's validation set and on unseen seeds (docs/odometry.md).
    pub stack_window_s: f64,
    /// Points seen again weigh more in the ego-velocity consensus than points seen once
    /// ([`crate::persist`]).
    pub persist: PersistConfig,
    /// Which rigs' ego-velocities take the likelihood of the rounded Doppler readings
    /// ([`EgoConfig::rounding_likelihood`]); a stated `ego.rounding_likelihood` turns it on for
    /// every rig.
    pub rounding_likelihood: RoundingRule,
}

/// Which rigs' ego-velocities take the likelihood of the rounded Doppler readings
/// ([`EgoConfig::rounding_likelihood`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RoundingRule {
    /// None: least squares on the readings (the default: docs/odometry.md, "A slow robot under a
    /// coarse Doppler step").
    #[default]
    Never,
    /// Ground vehicles ([`crate::rio::RioConfig::nonholonomic_std`] finite): their velocity lies
    /// along the body, and a slow one under a coarse step is where least squares fails.
    GroundVehicles,
    /// Every rig.
    Always,
}

impl core::str::FromStr for RoundingRule {
    type Err = String;

    /// `never`, `vehicles` or `always`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "never" => Ok(RoundingRule::Never),
            "vehicles" => Ok(RoundingRule::GroundVehicles),
            "always" => Ok(RoundingRule::Always),
            o => Err(format!("{o:?} is none of never, vehicles, always")),
        }
    }
}

impl RoundingRule {
    /// Whether a rig with `cfg` takes the likelihood.
    pub fn applies(self, cfg: &ClassicalConfig) -> bool {
        cfg.ego.rounding_likelihood
            || match self {
                RoundingRule::Never => false,
                RoundingRule::GroundVehicles => cfg.rio.nonholonomic_std.is_finite(),
                RoundingRule::Always => true,
            }
    }
}

impl Default for ClassicalConfig {
    fn default() -> Self {
        ClassicalConfig {
            rio: RioConfig::default(),
            ego: EgoConfig::default(),
            level_window_s: 1.0,
            velocity_cov_scale: 1.0,
            mounting: Mounting::default(),
            rest: RestConfig::default(),
            imu_gap_s: 0.1,
            learned: LearnedConfig::default(),
            stack_window_s: 0.0,
            persist: PersistConfig::default(),
            rounding_likelihood: RoundingRule::default(),
        }
    }
}

/// One radar frame for the runner.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// Measurement time on the IMU's clock \[s\].
    pub t: f64,
    /// The caller's name for the frame (echoed in its [`FramePose`]).
    pub id: u64,
    /// Points (radar frame: x right, y boresight, z up \[m\]; radial velocity \[m/s\]).
    pub points: &'a [Point],
}

/// The body pose at a radar frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePose {
    /// [`FrameInput::id`] of the frame.
    pub id: u64,
    /// Its time \[s\].
    pub t: f64,
    /// Body pose in the world frame (the levelled start; translation \[m\]).
    pub body: Isometry3<f64>,
    /// Body velocity in the world frame \[m/s\].
    pub velocity_world: Vector3<f64>,
    /// How long the pose has rested on the IMU alone \[s\]: the time since the filter last
    /// applied a velocity from the radar, a rest (zero-velocity update) or the learned model
    /// (since it started, before the first). Position error grows with it: past
    /// [`UNAIDED_AFTER_S`] the pose is dead-reckoned ([`Runner::longest_unaided`]).
    pub unaided_s: f64,
}

/// The longest stretch a run's poses rested on the IMU alone ([`FramePose::unaided_s`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UnaidedStretch {
    /// When it began (the last aid before it, or the filter's start) \[s\].
    pub from_s: f64,
    /// How long it lasted, up to the last pose in it \[s\].
    pub length_s: f64,
    /// Poses given more than [`UNAIDED_AFTER_S`] after an aid, over the whole run.
    pub poses_unaided: u64,
}

/// What the runner did with its inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RunnerCounters {
    /// Frames with a usable ego-velocity.
    pub ego_ok: u64,
    /// Frames whose geometry could not determine the velocity.
    pub ego_degenerate: u64,
    /// Frames with too few points.
    pub ego_too_few: u64,
    /// Frames without consensus.
    pub ego_no_consensus: u64,
    /// Frames dead-reckoned without the IMU.
    pub dead_reckoned: u64,
    /// Times the filter re-anchored at the dead-reckoned state after an IMU gap.
    pub imu_restarts: u64,
    /// Frames seen while levelling beyond [`EARLY_CAPACITY`] (no pose).
    pub early_dropped: u64,
    /// IMU samples at which the body was at rest (IMU still, radar ego-velocity zero).
    pub rest_samples: u64,
    /// Frames whose ego-velocity was not applied because the body was at rest (the
    /// zero-velocity update stands in).
    pub rest_frames: u64,
    /// Radar points skipped as near-field leakage (zero Doppler within
    /// [`EgoConfig::near_field_m`]).
    pub near_field_points: u64,
    /// Rests the filter refuted: its velocity was not consistent with zero
    /// ([`crate::rest::RestDetector::refute`]).
    pub rest_refuted: u64,
    /// Frames whose ego-velocity came from their points together with those of earlier frames
    /// that gave none alone ([`ClassicalConfig::stack_window_s`]); they are also counted under
    /// the status they had alone.
    pub ego_stacked: u64,
    /// Barometer readings seen.
    pub pressure_readings: u64,
    /// Of them, those before the filter started or during an IMU gap (not used).
    pub pressure_unused: u64,
}

/// Radar frame seen while levelling, measured and applied once the filter starts.
#[derive(Debug, Clone)]
struct Early {
    t: f64,
    id: u64,
    dets: Vec<Detection>,
}

/// A frame kept for stacking: its time, and the filter's attitude, IMU-integrated velocity
/// ([`Rio::imu_velocity`]) and rate of turn when it came; its points are the next `len` of the
/// stack's.
#[derive(Debug, Clone, Copy)]
struct Stacked {
    t: f64,
    q: UnitQuaternion<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
    len: usize,
}

/// The filter's prediction just before the latest IMU sample: the prior of a frame that comes
/// after the first sample at or past its time.
#[derive(Debug, Clone, Copy)]
struct Before {
    prior: ([f64; 3], [[f64; 3]; 3]),
    updates: u64,
    // The state there (where the frame's points are placed, [`crate::persist`]).
    nav: NavState,
}

/// Doppler radar-inertial odometry (or, without radar, IMU dead reckoning) over a stream.
#[derive(Debug)]
pub struct Runner {
    cfg: ClassicalConfig,
    use_radar: bool,
    mount: RadarMount,
    q_ib: UnitQuaternion<f64>,
    t_ib: Vector3<f64>,
    rio: Option<Rio>,
    level: Vec<ImuSample>,
    early: Vec<Early>,
    ego: EgoVelocityEstimator,
    // The same with the stricter consensus carried points need ([`STACK_MIN_INLIERS`]).
    ego_stacked: EgoVelocityEstimator,
    est: Estimate,
    dets: Vec<Detection>,
    // The Doppler step the frames' radial velocities show ([`EgoConfig::step_from_data`]).
    lattice: DopplerLattice,
    // Whether the near field leaks ([`EgoConfig::near_field_from_data`]).
    leakage: LeakageDetector,
    // The step from the configuration, before the data's replaced it.
    configured_step: f32,
    rest: RestDetector,
    // Where the current rest began (the position held while it lasts).
    rest_anchor: Option<Vector3<f64>>,
    before: Option<Before>,
    // The filter's counters before the first radar update applied behind the latest IMU sample
    // (the runtime order), counted into the rejection run at the next sample: in the offline
    // order those updates are applied, and counted, together at that sample, so a second frame
    // in the same IMU interval is guided by the same run in both orders.
    behind_counted: Option<RioCounters>,
    rejected_in_row: u32,
    last_imu_t: Option<f64>,
    // Radar-only dead reckoning while the IMU is missing.
    dr: Option<NavState>,
    // Frames measured ahead of the IMU: their pose is the state at the first sample past them.
    waiting: VecDeque<(u64, f64)>,
    out: VecDeque<FramePose>,
    counters: RunnerCounters,
    // Recent frame poses (time, body pose, radar updates applied so far), for learned
    // measurements.
    anchors: VecDeque<(f64, Isometry3<f64>, u64)>,
    // Frames that gave no velocity alone, oldest first, and their points in the same order.
    stack: VecDeque<Stacked>,
    stack_points: Vec<Detection>,
    // A frame's points with the stack's carried to it.
    stacked: Vec<Detection>,
    monitor: Monitor,
    learned: LearnedCounters,
    calibration: Calibration,
    // Recent frames' points in the world frame, for the consensus weights.
    history: PointHistory,
    // Aids applied so far (radar velocities, rest updates, learned measurements; counted over
    // every filter, as the filter's own counters restart with it), as last seen at a pose.
    aids_seen: u64,
    // Aids applied by filters before the current one (an IMU gap restarts the filter).
    aids_before: u64,
    // When the last aid was seen (at a pose), or the filter started.
    aided_at: Option<f64>,
    unaided: UnaidedStretch,
}

impl Runner {
    /// Doppler radar-inertial odometry (`use_radar`), or IMU dead reckoning with poses at the
    /// radar frames' times (no radar updates).
    pub fn new(cfg: &ClassicalConfig, use_radar: bool) -> Runner {
        let q_bi = cfg.mounting.imu.rotation;
        let t_bi = cfg.mounting.imu.translation.vector;
        let q_br = cfg.mounting.radar.rotation;
        let t_br = cfg.mounting.radar.translation.vector;
        // The filter runs in the IMU frame.
        let mount = RadarMount {
            rotation: q_bi.inverse() * q_br,
            translation: q_bi.inverse() * (t_br - t_bi),
        };
        let mut cfg = *cfg;
        cfg.ego.rounding_likelihood = cfg.rounding_likelihood.applies(&cfg);
        let cfg = &cfg;
        Runner {
            cfg: *cfg,
            use_radar,
            mount,
            q_ib: q_bi.inverse(),
            t_ib: -(q_bi.inverse() * t_bi),
            rio: None,
            level: Vec::with_capacity(LEVEL_CAPACITY),
            early: Vec::with_capacity(EARLY_CAPACITY),
            ego: EgoVelocityEstimator::with_capacity(cfg.ego, 1024),
            // A stacked frame: its own points and up to STACK_POINTS carried ones.
            ego_stacked: EgoVelocityEstimator::with_capacity(
                EgoConfig {
                    min_inliers: cfg.ego.min_inliers.max(STACK_MIN_INLIERS),
                    min_inlier_share: cfg.ego.min_inlier_share.max(STACK_MIN_INLIER_SHARE),
                    ..cfg.ego
                },
                2 * STACK_POINTS,
            ),
            est: Estimate::with_capacity(2 * STACK_POINTS),
            dets: Vec::with_capacity(1024),
            lattice: DopplerLattice::new(),
            leakage: LeakageDetector::new(),
            configured_step: cfg.ego.doppler_step,
            rest: RestDetector::new(RestConfig {
                // A ground vehicle has no gait: braking and rough roads swing its IMU too.
                gait_accel_std: if cfg.rio.nonholonomic_std.is_finite() {
                    f64::INFINITY
                } else {
                    cfg.rest.gait_accel_std
                },
                ..cfg.rest
            }),
            rest_anchor: None,
            before: None,
            behind_counted: None,
            rejected_in_row: 0,
            last_imu_t: None,
            dr: None,
            waiting: VecDeque::with_capacity(64),
            out: VecDeque::with_capacity(EARLY_CAPACITY + 64),
            counters: RunnerCounters::default(),
            anchors: VecDeque::with_capacity(ANCHOR_CAPACITY),
            stack: VecDeque::with_capacity(STACK_FRAMES),
            stack_points: Vec::with_capacity(STACK_POINTS),
            stacked: Vec::with_capacity(2 * STACK_POINTS),
            monitor: Monitor::new(cfg.learned),
            learned: LearnedCounters::default(),
            calibration: Calibration::default(),
            history: PointHistory::new(cfg.persist),
            aids_seen: 0,
            aids_before: 0,
            aided_at: None,
            unaided: UnaidedStretch::default(),
        }
    }

    /// The longest stretch the poses so far rested on the IMU alone, and how many poses were
    /// unaided ([`FramePose::unaided_s`]).
    pub fn longest_unaided(&self) -> UnaidedStretch {
        self.unaided
    }

    /// When the filter last took a velocity aid (a radar velocity, a rest update or a learned
    /// measurement) as seen at the latest pose, or when its first pose was given \[s\]; None
    /// before the first pose. A pose at `t` has rested on the IMU alone for `t - last_aid_s`.
    pub fn last_aid_s(&self) -> Option<f64> {
        self.aided_at
    }

    /// Velocity aids applied so far: radar velocities, rest updates (over every filter of the
    /// run) and learned measurements, and radar velocities that carried a gap in the IMU.
    fn aids(&self) -> u64 {
        self.aids_before + self.filter_aids() + self.learned.applied
    }

    /// Radar velocities and rest updates the current filter applied.
    fn filter_aids(&self) -> u64 {
        self.rio
            .as_ref()
            .map_or(0, |r| r.counters().updates + r.counters().rest_updates)
    }

    /// The time since the last aid at a pose at `t` \[s\] ([`FramePose::unaided_s`]), noting a
    /// new aid and the longest stretch.
    fn unaided_at(&mut self, t: f64) -> f64 {
        let aids = self.aids();
        if aids != self.aids_seen {
            self.aids_seen = aids;
            self.aided_at = Some(t);
        }
        let from = *self.aided_at.get_or_insert(t);
        let since = (t - from).max(0.0);
        if since > self.unaided.length_s {
            self.unaided.from_s = from;
            self.unaided.length_s = since;
        }
        self.unaided.poses_unaided += u64::from(since > UNAIDED_AFTER_S);
        since
    }

    /// What the persistence weighting did ([`crate::persist`]).
    pub fn persist_counters(&self) -> &crate::persist::PersistCounters {
        self.history.counters()
    }

    /// Whether radar frames update the filter (Doppler) or only mark pose times (IMU only).
    pub fn uses_radar(&self) -> bool {
        self.use_radar
    }

    /// True once levelling is over and the filter runs.
    pub fn started(&self) -> bool {
        self.rio.is_some()
    }

    /// The filter, once levelled.
    pub fn filter(&self) -> Option<&Rio> {
        self.rio.as_ref()
    }

    /// Filter counters (all zero before the filter starts; reset when it re-anchors after an IMU
    /// gap).
    pub fn filter_counters(&self) -> RioCounters {
        self.rio.as_ref().map(|r| *r.counters()).unwrap_or_default()
    }

    /// What the runner did.
    pub fn counters(&self) -> &RunnerCounters {
        &self.counters
    }

    /// Frames rejected in a row (see [`MAX_REJECTED_IN_ROW`]).
    pub fn rejected_in_row(&self) -> u32 {
        self.rejected_in_row
    }

    /// True when the filter's prediction would guide a frame now ([`guided`]).
    pub fn guiding(&self) -> bool {
        self.rio
            .as_ref()
            .is_some_and(|r| guided(health_updates(r.counters()), self.rejected_in_row))
    }

    /// Time \[s\], body pose in the world frame and world velocity \[m/s\] of the current state
    /// (the dead-reckoned one during an IMU gap).
    pub fn body_state(&self) -> Option<(f64, Isometry3<f64>, Vector3<f64>)> {
        let st = match (&self.dr, &self.rio) {
            (Some(d), _) => *d,
            (None, Some(r)) => *r.state(),
            _ => return None,
        };
        Some((st.t, self.body(&st), st.v))
    }

    /// The next frame pose, oldest first.
    pub fn pop_pose(&mut self) -> Option<FramePose> {
        self.out.pop_front()
    }

    /// A new filter with the body frame as its vehicle frame (the ground vehicle constraint
    /// holds in the session's body frame).
    fn filter_from(&self, mut rio: Rio) -> Rio {
        rio.set_vehicle_frame(RadarMount {
            rotation: self.q_ib,
            translation: self.t_ib,
        });
        rio
    }

    /// One IMU sample (IMU frame: specific force \[m/s^2\], rate of turn \[rad/s\]; time \[s\]).
    pub fn push_imu(&mut self, s: ImuSample) {
        self.last_imu_t = Some(s.t);
        if let Some(d) = self.dr.take() {
            // The IMU is back after a gap the radar bridged: re-anchor a fresh filter at the
            // dead-reckoned state (tilt and biases re-learned, the pose kept).
            let st = NavState { t: s.t, ..d };
            self.count_behind();
            self.aids_before += self.filter_aids();
            self.rio = Some(self.filter_from(Rio::new(self.cfg.rio, self.mount, st)));
            self.counters.imu_restarts += 1;
            self.clear_stack();
        }
        if self.rio.is_none() {
            if self.level.is_empty() {
                // Frames before the first sample get no pose (there is no filter time yet).
                self.early.retain(|e| e.t >= s.t);
            }
            // Level over the samples within the window of the first one.
            let past = self
                .level
                .first()
                .is_some_and(|f| s.t - f.t > self.cfg.level_window_s);
            if !past && self.level.len() < LEVEL_CAPACITY {
                self.level.push(s);
                return;
            }
            self.start_filter();
        }
        let Some(rio) = self.rio.as_ref() else {
            return;
        };
        self.before = Some(Before {
            prior: rio.predicted_radar_velocity(),
            updates: health_updates(rio.counters()),
            nav: *rio.state(),
        });
        self.filter_imu(s);
        while let Some(&(id, t)) = self.waiting.front() {
            if t > s.t {
                break;
            }
            self.waiting.pop_front();
            self.emit(id, t);
        }
    }

    /// One radar frame. Its pose comes out of [`Runner::pop_pose`] now (a frame at or behind the
    /// latest IMU sample, or dead-reckoned across an IMU gap), at the first IMU sample at or past
    /// it (a frame ahead of the IMU), or when levelling ends (a frame seen while levelling).
    pub fn push_radar(&mut self, f: &FrameInput<'_>) {
        if self.rio.is_none() {
            if self.early.len() < EARLY_CAPACITY {
                let dets = if self.use_radar {
                    f.points.iter().map(detection).collect()
                } else {
                    Vec::new()
                };
                self.early.push(Early {
                    t: f.t,
                    id: f.id,
                    dets,
                });
            } else {
                self.counters.early_dropped += 1;
            }
            return;
        }
        self.dets.clear();
        if self.use_radar {
            self.dets.extend(f.points.iter().map(detection));
        }
        if self.last_imu_t.is_none_or(|t| f.t - t > self.cfg.imu_gap_s) {
            self.dead_reckon(f.t);
            self.emit(f.id, f.t);
            return;
        }
        let behind = self.last_imu_t.is_some_and(|t| t >= f.t);
        if self.use_radar {
            // The prediction at the last sample before the frame: the one before the latest
            // sample when the frame is behind it.
            let prior = if behind {
                self.before
                    .filter(|b| guided(b.updates, self.rejected_in_row))
                    .map(|b| b.prior)
            } else {
                self.current_prior()
            };
            let dets = std::mem::take(&mut self.dets);
            self.radar_update(f.t, behind, &dets, prior);
            self.dets = dets;
        }
        if behind {
            self.emit(f.id, f.t);
        } else {
            self.waiting.push_back((f.id, f.t));
        }
    }

    /// One barometer reading: pressure `pa` \[Pa\] at `t` \[s\] on the IMU clock (the barometer
    /// sits at the IMU). Aids the height once the filter runs ([`Rio::push_height`]); readings
    /// while levelling only count.
    pub fn push_pressure(&mut self, t: f64, pa: f64) {
        self.counters.pressure_readings += 1;
        match self.rio.as_mut() {
            Some(rio) if self.dr.is_none() => rio.push_height(t, crate::rio::pressure_altitude(pa)),
            _ => self.counters.pressure_unused += 1,
        }
    }

    /// Counters of the learned measurements ([`Runner::push_relative_motion`]).
    pub fn learned_counters(&self) -> &LearnedCounters {
        &self.learned
    }

    /// The network's scale as calibrated against the filter (1 when not calibrated).
    pub fn learned_scale(&self) -> f64 {
        if self.cfg.learned.calibrate_scale {
            self.calibration.scale()
        } else {
            1.0
        }
    }

    /// The factor on the learned measurements' stated covariance (1 when not adapted;
    /// [`crate::learned::Calibration::noise_factor`]).
    pub fn learned_noise_factor(&self) -> f64 {
        if self.cfg.learned.adapt_noise {
            self.calibration.noise_factor()
        } else {
            1.0
        }
    }

    /// Whether learned measurements are applied (the online check has not failed, or is off).
    pub fn learned_trusted(&self) -> bool {
        self.monitor.trusted()
    }

    /// A learned relative motion between two radar frames whose poses this runner gave (their
    /// times within 1 ms): gated, checked online and applied as described in [`crate::learned`].
    /// Give it right after the `to` frame's pose came out (at most one radar period later).
    pub fn push_relative_motion(&mut self, m: &RelativeMotion) -> Outcome {
        let o = self.relative_motion(m);
        self.learned.count(o);
        o
    }

    fn relative_motion(&mut self, m: &RelativeMotion) -> Outcome {
        let dt = m.t_to - m.t_from;
        let d = Vector3::from(m.translation);
        if !(dt > 1e-3 && d.iter().all(|x| x.is_finite())) {
            return Outcome::Invalid;
        }
        let find = |t: f64| {
            self.anchors
                .iter()
                .rev()
                .find(|(ta, _, _)| (ta - t).abs() <= ANCHOR_TOLERANCE_S)
                .map(|(_, b, u)| (*b, *u))
        };
        let (Some((from, u_from)), Some((to, u_to))) = (find(m.t_from), find(m.t_to)) else {
            return Outcome::NoAnchor;
        };
        let c = self.cfg.learned;
        if c.doppler_covers > 0 && u_to.saturating_sub(u_from) >= c.doppler_covers {
            return Outcome::Covered;
        }
        if self.dr.is_some() {
            return Outcome::NoAnchor;
        }
        let Some(rio) = self.rio.as_mut() else {
            return Outcome::NoAnchor;
        };
        // At rest, or the IMU still while the filter's velocity is zero within its uncertainty
        // (a rest the radar cannot confirm: too few points for a zero-Doppler verdict). A network
        // trained on simulation "walked" on a real rig standing still.
        let still =
            self.rest.was_still(false) && rio.at_rest_consistent(self.cfg.rest.zero_velocity_std);
        if self.rest.resting() || still {
            return Outcome::AtRest;
        }
        let r_from = from.rotation.to_rotation_matrix().into_inner();
        let moved = to.translation.vector - from.translation.vector;
        // The filter's own displacement over the interval, in the body frame at `from`.
        let f = r_from.transpose() * moved;
        let k = if c.calibrate_scale {
            self.calibration.scale()
        } else {
            1.0
        };
        let offset = if c.calibrate_offset {
            self.calibration.offset()
        } else {
            Vector3::zeros()
        };
        // The calibration learned from earlier intervals applies; then this one joins it if the
        // radar covered it, or if the filter of a ground vehicle knows its own motion over it
        // ([`LearnedConfig::known_share`]).
        let stated = c.deviation(&(d * k), m.translation_std);
        let covered = u_to.saturating_sub(u_from) >= SCALE_COVERS;
        let known =
            !covered && c.known_share > 0.0 && self.cfg.rio.nonholonomic_std.is_finite() && {
                let velocity_std = (rio.covariance().fixed_view::<3, 3>(3, 3).trace() / 3.0)
                    .max(0.0)
                    .sqrt();
                velocity_std * dt <= c.known_share * stated.min()
            };
        if covered || known {
            if c.calibrate_offset {
                self.calibration.push_offset(&((d * k - f) / dt));
            }
            if c.calibrate_scale {
                self.calibration.push_scale(&d, &f);
            }
            if c.adapt_noise {
                self.calibration
                    .push_noise(m.t_from, m.t_to, &(d * k - f).component_div(&stated));
            }
        }
        let v_filter = moved / dt;
        // The online check judges the network before its offset is taken off: the offset
        // calibration would otherwise absorb a wrong axis convention (reversed motions read as a
        // steady offset on a steady walk) and hide it from the check.
        let raw = d * k;
        let d = raw - offset * dt;
        // A translation's innovation (world velocity) and its covariance.
        let innovation = |d: &Vector3<f64>| {
            let s = c.deviation(d, m.translation_std) / dt;
            let rm = r_from * Matrix3::from_diagonal(&s.component_mul(&s)) * r_from.transpose();
            (r_from * d / dt - v_filter, rm)
        };
        let (y, rm) = innovation(&d);
        let Some(nis) = rio.world_velocity_nis(&y, &rm) else {
            return Outcome::Invalid;
        };
        let nis_raw = if offset == Vector3::zeros() {
            nis
        } else {
            let (y_raw, rm_raw) = innovation(&raw);
            rio.world_velocity_nis(&y_raw, &rm_raw).unwrap_or(nis)
        };
        let trusted = self.monitor.trusted();
        self.learned.switched_off += u64::from(self.monitor.record(nis_raw));
        if nis > c.gate {
            return Outcome::Gated(nis);
        }
        if !trusted {
            return Outcome::Suspended(nis);
        }
        // The check and the gate judge the stated deviation; the update weighs what the
        // covered intervals measured of the network's error.
        let rm = if c.adapt_noise {
            rm * self.calibration.noise_factor()
        } else {
            rm
        };
        rio.world_velocity_update(&y, &rm);
        Outcome::Applied(nis)
    }

    /// The end of the stream: a filter still levelling starts now (over every sample seen), and
    /// the poses of the frames seen while levelling come out.
    pub fn finish(&mut self) {
        if self.rio.is_none() && !self.level.is_empty() {
            self.start_filter();
        }
    }

    fn body(&self, st: &NavState) -> Isometry3<f64> {
        // T_wb = T_wi * T_ib.
        let q = st.q * self.q_ib;
        let p = st.p + st.q * self.t_ib;
        Isometry3::from_parts(Translation3::from(p), q)
    }

    fn emit(&mut self, id: u64, t: f64) {
        if let Some((_, body, velocity_world)) = self.body_state() {
            if self.anchors.len() == ANCHOR_CAPACITY {
                self.anchors.pop_front();
            }
            let updates = self.rio.as_ref().map_or(0, |r| r.counters().updates);
            self.anchors.push_back((t, body, updates));
            let unaided_s = self.unaided_at(t);
            self.out.push_back(FramePose {
                id,
                t,
                body,
                velocity_world,
                unaided_s,
            });
        }
    }

    /// The filter's prior for a frame now, when it is healthy.
    fn current_prior(&self) -> Option<([f64; 3], [[f64; 3]; 3])> {
        let rio = self.rio.as_ref()?;
        guided(health_updates(rio.counters()), self.rejected_in_row)
            .then(|| rio.predicted_radar_velocity())
    }

    /// Counts a change of the filter's counters into the rejection run: an applied update ends
    /// it, a gated one extends it.
    fn track(&mut self, before: RioCounters, after: RioCounters) {
        if after.updates > before.updates {
            self.rejected_in_row = 0;
        } else if after.gated > before.gated {
            self.rejected_in_row += 1;
        }
    }

    /// Counts the updates applied behind the latest sample into the rejection run
    /// ([`Runner::track`]), against the filter that applied them.
    fn count_behind(&mut self) {
        if let (Some(before), Some(rio)) = (self.behind_counted.take(), self.rio.as_ref()) {
            let after = *rio.counters();
            self.track(before, after);
        }
    }

    fn filter_imu(&mut self, s: ImuSample) {
        if self.rio.is_none() {
            return;
        }
        self.count_behind();
        // Rest at the previous sample, decided now that every frame up to it is in (in either
        // input order), applied before propagating to this one.
        let due = self.rest.push_imu(&s);
        if self.rest.resting() {
            self.counters.rest_samples += 1;
        } else {
            self.rest_anchor = None;
        }
        let Some(rio) = self.rio.as_mut() else {
            return;
        };
        let c = *self.rest.config();
        // A refuted rest is tried again once the radar frames applied since have brought the
        // filter's velocity to where it is consistent with rest.
        if self.rest.refuted_before_frame(false)
            && self.rest.was_still(false)
            && rio.at_rest_consistent(c.zero_velocity_std)
        {
            self.rest.retry();
        }
        let due = due.filter(|_| {
            // A rest the filter's velocity contradicts is refuted, not applied (not the rest the
            // session starts in: the filter starts from it).
            let ok = self.rest.initial()
                || self.rest.stopped_walker()
                || rio.at_rest_consistent(c.zero_velocity_std);
            if !ok {
                self.rest.refute();
                self.counters.rest_refuted += 1;
                self.rest_anchor = None;
            }
            ok
        });
        if let Some(u) = due {
            rio.zero_velocity(c.zero_velocity_std);
            if u.first || self.rest_anchor.is_none() {
                self.rest_anchor = Some(rio.state().p);
            }
            if let Some(a) = self.rest_anchor {
                rio.hold_position(a, c.hold_position_std);
            }
            if let Some((mean_gyro, span_s)) = u.rate {
                // The floor is per update period: a span of k periods counts as k of them.
                let periods = (span_s / c.update_period_s).round().max(1.0);
                let floor = c.zero_rate_std_min / periods.sqrt();
                rio.zero_rate(mean_gyro, span_s, floor);
            }
        }
        let before = *rio.counters();
        rio.push_imu(s);
        let after = *rio.counters();
        self.track(before, after);
    }

    /// The Doppler quantisation step \[m/s\]: the configured one, and the one the frames' radial
    /// velocities show ([`crate::lattice`]; None until they show one, or when
    /// [`EgoConfig::step_from_data`] is off). The second, when there is one, is the step in use.
    pub fn doppler_step(&self) -> (f32, Option<f32>) {
        let seen = self.cfg.ego.step_from_data.then(|| self.lattice.step());
        (self.configured_step, seen.flatten().map(|q| q as f32))
    }

    /// Near-field leakage as the points show it ([`crate::leakage`]): tested near points, how
    /// many of them read zero Doppler, and whether the near field was turned on from them (None
    /// when [`EgoConfig::near_field_from_data`] is off).
    pub fn near_field_leakage(&self) -> Option<(u32, u32, bool)> {
        self.cfg.ego.near_field_from_data.then(|| {
            let (tested, zero) = self.leakage.counts();
            (tested, zero, self.leakage.found())
        })
    }

    /// The near field in use \[m\] ([`EgoConfig::near_field_m`]; 0: off).
    pub fn near_field_m(&self) -> f32 {
        self.cfg.ego.near_field_m
    }

    /// Looks for near-field leakage in a frame's points against the filter's prediction `prior`
    /// of the radar's velocity and the frame's own estimate (the latest, when it gave one); once
    /// found, the near field is left out of the vote from the next frame on.
    fn learn_leakage(&mut self, dets: &[Detection], prior: Option<&Prior>) {
        if !self.cfg.ego.near_field_from_data
            || self.leakage.found()
            || self.est.status != Status::Ok
        {
            return;
        }
        let Some(prior) = prior else {
            return;
        };
        let frame = self.est.velocity.map(f64::from);
        let gate = f64::from(self.cfg.ego.inlier_threshold());
        let min_range = f64::from(self.cfg.ego.min_range);
        if self.leakage.observe(
            dets,
            (&prior.velocity, &prior.covariance),
            &frame,
            gate,
            min_range,
        ) && self.cfg.ego.near_field_m < LEAK_RANGE_M
        {
            self.cfg.ego.near_field_m = LEAK_RANGE_M;
            self.ego.set_near_field(LEAK_RANGE_M);
            self.ego_stacked.set_near_field(LEAK_RANGE_M);
        }
    }

    /// Takes the Doppler step the stream shows, once it shows one, for the ego-velocity's gate
    /// and noise floor and the rest verdict's zero.
    fn learn_doppler_step(&mut self, dets: &[Detection]) {
        if !self.cfg.ego.step_from_data {
            return;
        }
        if let Some(q) = self.lattice.observe(dets) {
            let q = q as f32;
            if q != self.cfg.ego.doppler_step {
                self.cfg.ego.doppler_step = q;
                self.ego.set_doppler_step(q);
                self.ego_stacked.set_doppler_step(q);
            }
        }
    }

    /// The latest ego-velocity estimate as the filter's measurement at `t` \[s\], its covariances
    /// scaled by [`ClassicalConfig::velocity_cov_scale`] (`carried`: from stacked frames).
    fn estimate_as_measurement(&self, t: f64, carried: bool) -> VelocityMeasurement {
        let s = self.cfg.velocity_cov_scale;
        let scaled = |c: [[f32; 3]; 3]| c.map(|r| r.map(|x| f64::from(x) * s));
        VelocityMeasurement {
            t,
            carried,
            velocity: self.est.velocity.map(f64::from),
            covariance: scaled(self.est.covariance),
            shared_covariance: scaled(self.est.shared_covariance),
            doppler_step: f64::from(self.cfg.ego.doppler_step.max(0.0)),
        }
    }

    /// The ego-velocity of `dets` guided by `prior` (status counted); with the radar's pose
    /// `radar_in_world`, the points seen again weigh more ([`crate::persist`]).
    fn measure(
        &mut self,
        t: f64,
        dets: &[Detection],
        prior: Option<Prior>,
        radar_in_world: Option<Isometry3<f64>>,
    ) -> Option<VelocityMeasurement> {
        self.learn_doppler_step(dets);
        let weights = radar_in_world.and_then(|pose| self.history.weigh(t, &pose, dets));
        self.ego
            .estimate_weighted_into(dets, weights, prior, &mut self.est);
        match self.est.status {
            Status::Ok => {
                self.counters.ego_ok += 1;
                Some(self.estimate_as_measurement(t, false))
            }
            Status::Degenerate { .. } => {
                self.counters.ego_degenerate += 1;
                None
            }
            Status::TooFewPoints { .. } => {
                self.counters.ego_too_few += 1;
                None
            }
            Status::NoConsensus { .. } => {
                self.counters.ego_no_consensus += 1;
                None
            }
        }
    }

    /// Ego-velocity of a frame at `t` \[s\] guided by `prior`, pushed into the filter (applied at
    /// once when the filter is past `t`, else at the first sample at or past it); `behind`: the
    /// frame came after the first IMU sample at or past it (the runtime order).
    fn radar_update(
        &mut self,
        t: f64,
        behind: bool,
        dets: &[Detection],
        prior: Option<([f64; 3], [[f64; 3]; 3])>,
    ) {
        let gate = self.cfg.rio.gate;
        let prior = prior.map(|(velocity, covariance)| Prior {
            velocity,
            covariance,
            gate,
        });
        let guided_now = prior.is_some();
        // The radar's pose at the frame: the filter's state at the last sample before it (as the
        // prior), carried to the frame's time; the same in both input orders (needed only for the
        // weighting).
        let nav = if !self.cfg.persist.enabled() {
            None
        } else if behind {
            self.before.map(|b| b.nav)
        } else {
            self.rio.as_ref().map(|r| *r.state())
        };
        let pose = nav.map(|st| {
            let p = st.p + st.v * (t - st.t);
            radar_pose(&st.q, &p, &self.mount.rotation, &self.mount.translation)
        });
        let m = self.measure(t, dets, prior, pose);
        self.learn_leakage(dets, prior.as_ref());
        let no_consensus = matches!(self.est.status, Status::NoConsensus { .. });
        let near_field = self.est.near_field;
        // The radar's verdict on rest: its own estimate (before the filter takes it) and the
        // share of points with zero Doppler.
        // Near-field points are left out: leakage there has zero Doppler whatever the motion.
        let zero = self.cfg.ego.doppler_std().abs();
        let near2 = self.cfg.ego.near_field_m * self.cfg.ego.near_field_m;
        let (mut still, mut seen) = (0, 0);
        for d in dets {
            let [x, y, z] = d.position;
            if x * x + y * y + z * z >= near2 {
                seen += 1;
                still += usize::from(d.radial_velocity.abs() <= zero);
            }
        }
        self.counters.near_field_points += near_field as u64;
        let verdict = self
            .rest
            .push_radar(t, m.map(|m| (m.velocity, m.covariance)), still, seen);
        // At rest the zero-velocity update replaces the frame's: the radar's own estimate is poor
        // where its points do not spread (vertical velocity of a horizontal fan), the rest exact.
        // Rest and stillness as decided at the sample before the last one at or before the frame
        // (the same in both input orders: the latest decided sample unless the frame is behind
        // the latest), with the frame's own verdict: a frame that says "moving" is applied, one
        // that says "still" while the IMU is still starts the rest, unless the filter refuted
        // that rest: then the frame is applied, since nothing else would correct the velocity
        // (a coarse Doppler step reads 0 for a slow robot and for one that came to rest; before,
        // such frames were dropped while the refuted rest applied nothing, and a robot that
        // stopped with 0.1 m/s left in its filter drove on through a 5 s rest).
        let resting = self.rest.resting_before_frame(behind);
        let still = self.rest.was_still(behind);
        let refuted = self.rest.refuted_before_frame(behind);
        let resting_now = verdict != Verdict::Moving
            && (resting || (still && !refuted && verdict == Verdict::Still));
        let m = if resting_now {
            self.counters.rest_frames += u64::from(m.is_some());
            // The frame agrees with the filter (zero velocity): the rejection run ends.
            self.rejected_in_row = 0;
            None
        } else if m.is_none() && !still {
            // Moving and no velocity alone: with the points of the frames before. Not while
            // the IMU is still (rest is decided on the frame's own points: carried points add
            // the IMU's integration error, which at rest is all they would say).
            self.measure_stacked(t, dets, prior)
        } else {
            m
        };
        let at_rest = resting_now;
        if at_rest || m.is_some() {
            // At rest, or the frame decided (alone, or with the stack's points, now used).
            self.clear_stack();
        } else {
            self.keep_for_stack(t, dets);
        }
        if let Some(rio) = self.rio.as_mut() {
            if still && !at_rest {
                // The IMU is still where no rest is declared: a walker may have stopped where
                // the radar sees nothing, so the pace it walked at no longer holds.
                rio.forget_pace();
            }
            if let Some(m) = m {
                // Applied now only behind the latest sample (else at the next one, where
                // `filter_imu` counts it): counted at the next sample, as offline.
                let before = *rio.counters();
                rio.push_velocity(m);
                self.behind_counted.get_or_insert(before);
            } else if !at_rest {
                // No velocity from this frame: the vertical velocity bound still applies.
                rio.push_frame_without_velocity(t);
            }
        }
        if no_consensus && m.is_none() {
            // No consensus under the prior: the frame disagrees with the filter.
            self.rejected_in_row += u32::from(guided_now);
        }
    }

    /// Forgets the frames kept for stacking.
    fn clear_stack(&mut self) {
        self.stack.clear();
        self.stack_points.clear();
    }

    /// Drops the oldest kept frame.
    fn drop_oldest_stacked(&mut self) {
        if let Some(f) = self.stack.pop_front() {
            self.stack_points
                .drain(..f.len.min(self.stack_points.len()));
        }
    }

    /// Keeps a frame that gave no velocity, with the filter's state now, for later frames
    /// ([`ClassicalConfig::stack_window_s`]). Near-field points with zero Doppler (possible
    /// leakage, zero whatever the motion) are not kept.
    fn keep_for_stack(&mut self, t: f64, dets: &[Detection]) {
        let Some(rio) = self.rio.as_ref() else {
            return;
        };
        let (q, v, w) = (rio.state().q, rio.imu_velocity(), rio.angular_rate());
        let window = self.cfg.stack_window_s;
        if !(window.is_finite() && window > 0.0) {
            return;
        }
        let zero = self.cfg.ego.inlier_threshold();
        let near2 = self.cfg.ego.near_field_m * self.cfg.ego.near_field_m;
        let kept = |d: &&Detection| {
            let [x, y, z] = d.position;
            x * x + y * y + z * z >= near2 || d.radial_velocity.abs() > zero
        };
        let n = dets.iter().filter(kept).count();
        if n == 0 || n > STACK_POINTS {
            return;
        }
        while self.stack.len() >= STACK_FRAMES || self.stack_points.len() + n > STACK_POINTS {
            self.drop_oldest_stacked();
        }
        self.stack.push_back(Stacked { t, q, v, w, len: n });
        self.stack_points.extend(dets.iter().filter(kept).copied());
    }

    /// The ego-velocity of a frame that gave none alone, from its points and those of the kept
    /// frames within [`ClassicalConfig::stack_window_s`] before it, each carried to this frame:
    /// a static point seen from frame k, `vr = -u . v_k`, reads `vr + u . (v_k' - M v_n') =
    /// -(M^T u) . v_n` here, where `M` rotates this frame's radar axes into frame k's and `v'`
    /// are the radar velocities the filter predicts from its IMU-integrated velocity (so only
    /// the change between the two frames, which the IMU measured, enters; not the filter's
    /// velocity error). Counted as [`RunnerCounters::ego_stacked`] when it succeeds.
    fn measure_stacked(
        &mut self,
        t: f64,
        dets: &[Detection],
        prior: Option<Prior>,
    ) -> Option<VelocityMeasurement> {
        let window = self.cfg.stack_window_s;
        while self
            .stack
            .front()
            .is_some_and(|f| (t - f.t).is_nan() || t - f.t > window)
        {
            self.drop_oldest_stacked();
        }
        let rio = self.rio.as_ref()?;
        if self.stack.is_empty() || dets.len() > STACK_POINTS {
            return None;
        }
        let q_br = self.mount.rotation;
        let t_br = self.mount.translation;
        let radar_velocity = |q: &UnitQuaternion<f64>, v: &Vector3<f64>, w: &Vector3<f64>| {
            q_br.inverse() * (q.inverse() * v + w.cross(&t_br))
        };
        let st = rio.state();
        let q_wr_n = st.q * q_br;
        let v_n = radar_velocity(&st.q, &rio.imu_velocity(), &rio.angular_rate());
        self.stacked.clear();
        self.stacked.extend_from_slice(dets);
        let mut at = 0;
        for f in &self.stack {
            let v_k = radar_velocity(&f.q, &f.v, &f.w);
            // This frame's radar axes into frame k's: M = R_wr(k)^T R_wr(n).
            let m = (f.q * q_br).inverse() * q_wr_n;
            for d in &self.stack_points[at..at + f.len] {
                let p = Vector3::new(
                    f64::from(d.position[0]),
                    f64::from(d.position[1]),
                    f64::from(d.position[2]),
                );
                let r = p.norm();
                if r.is_nan() || r <= 0.0 {
                    continue;
                }
                let u = p / r;
                let p_n = m.inverse() * p;
                let u_n = p_n / r;
                let vr = f64::from(d.radial_velocity) + u.dot(&v_k) - u_n.dot(&v_n);
                self.stacked.push(Detection {
                    position: [p_n.x as f32, p_n.y as f32, p_n.z as f32],
                    radial_velocity: vr as f32,
                });
            }
            at += f.len;
        }
        // The carried points are off by the error of the velocity change the filter integrated
        // since their frame: its tilt error on gravity and its accelerometer bias error, over
        // the span (a common offset of each frame's points, so added to the estimate's
        // covariance as such).
        let p = rio.covariance();
        let g = self.cfg.rio.gravity;
        let tilt = p[(6, 6)].max(p[(7, 7)]).max(0.0);
        let bias = p[(9, 9)].max(p[(10, 10)]).max(p[(11, 11)]).max(0.0);
        let span = self.stack.front().map_or(0.0, |f| (t - f.t).max(0.0));
        let carried = (g * g * tilt + bias) * span * span;
        let pts = std::mem::take(&mut self.stacked);
        self.ego_stacked
            .estimate_guided_into(&pts, prior, &mut self.est);
        self.stacked = pts;
        if self.est.status != Status::Ok {
            return None;
        }
        self.counters.ego_stacked += 1;
        let mut m = self.estimate_as_measurement(t, true);
        for (k, row) in m.covariance.iter_mut().enumerate() {
            row[k] += carried;
        }
        Some(m)
    }

    /// No IMU: hold the attitude, integrate the radar velocity to `t` \[s\].
    fn dead_reckon(&mut self, t: f64) {
        self.clear_stack();
        self.history.clear();
        let Some(rio) = self.rio.as_ref() else {
            return;
        };
        let mut st = self.dr.unwrap_or(*rio.state());
        if self.use_radar {
            let dets = std::mem::take(&mut self.dets);
            // No pose to place the points with: no weights.
            let m = self.measure(t, &dets, None, None);
            self.dets = dets;
            if let Some(m) = m {
                self.aids_before += 1;
                // The radar's own velocity in its frame (lever arm neglected without gyro).
                let v_i = self.mount.rotation * Vector3::from(m.velocity);
                st.v = st.q * v_i;
            }
        }
        let dt = (t - st.t).max(0.0);
        st.p += st.v * dt;
        st.t = t;
        self.dr = Some(st);
        self.counters.dead_reckoned += 1;
    }

    /// Levels the filter from the buffered samples and replays them with the frames seen
    /// meanwhile, in the offline order: the frames due at or before a sample go first, measured
    /// with the prior the filter has at that point; their poses are the state after that sample.
    fn start_filter(&mut self) {
        let Some(first) = self.level.first() else {
            return;
        };
        let t0 = first.t;
        let n = self.level.len().max(1) as f64;
        let mean_f = self
            .level
            .iter()
            .fold(Vector3::zeros(), |a, s| a + Vector3::from(s.accel))
            / n;
        self.rio =
            Some(self.filter_from(Rio::levelled(self.cfg.rio, self.mount, t0, mean_f.into())));
        let early = std::mem::take(&mut self.early);
        let level = std::mem::take(&mut self.level);
        let mut next = 0;
        for s in &level {
            let from = next;
            while next < early.len() && early[next].t <= s.t {
                let e = &early[next];
                next += 1;
                if e.t < t0 || !self.use_radar {
                    continue;
                }
                let prior = self.current_prior();
                self.radar_update(e.t, false, &e.dets, prior);
            }
            self.filter_imu(*s);
            for e in &early[from..next] {
                if e.t >= t0 {
                    self.emit(e.id, e.t);
                }
            }
        }
        // Frames after the last buffered sample (offline order: they came before the sample that
        // ended levelling): measured now, their poses at the next sample.
        for e in &early[next..] {
            if self.use_radar {
                let prior = self.current_prior();
                self.radar_update(e.t, false, &e.dets, prior);
            }
            self.waiting.push_back((e.id, e.t));
        }
        self.early = early;
        self.early.clear();
        self.level = level;
        self.level.clear();
    }
}

fn detection(p: &Point) -> Detection {
    Detection {
        position: [p.x, p.y, p.z],
        radial_velocity: p.velocity,
    }
}
