//! Running the classical estimators over a recorded or simulated session: Doppler radar-inertial
//! odometry, or IMU-only dead reckoning (the same integration code), giving a trajectory of the
//! body frame at radar rate on the session host clock, ready for `milliego eval` against ground
//! truth. The loop itself is [`crate::runner::Runner`], the one the on-device runtime runs.

use crate::ego_velocity::Config as EgoConfig;
use crate::rest::RestConfig;
use crate::rio::{ImuNoise, RioConfig};
use crate::runner::{ClassicalConfig, FrameInput, Mounting, Runner};
use crate::strapdown::ImuSample;
use milliego_session::streams::{
    imu_and_pressure, radar_frames, ClockFit, SessionClock, StreamReport,
};
use milliego_session::{Session, SessionError, TumPose};

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
    /// Rest detection and the updates at rest.
    pub rest: RestConfig,
    /// Take the Doppler quantisation step ([`EgoConfig::doppler_step`]) from the session's
    /// `.cfg` (its velocity resolution) when it has one.
    pub doppler_step_from_cfg: bool,
    /// Aid the height with the barometer readings in the IMU stream, when there are any.
    pub use_barometer: bool,
    /// A known radar latency \[s\] added to every radar frame's time on the IMU clock
    /// (positive: the frames were taken later than their stamps say).
    pub radar_time_shift_s: f64,
    /// Whether the filter estimates the radar-to-IMU time offset online.
    pub time_offset: TimeOffsetMode,
    /// How long a frame that gave no velocity alone is kept for the next ones \[s\]
    /// ([`ClassicalConfig::stack_window_s`]; 0: off).
    pub stack_window_s: f64,
    /// Consensus weights from point persistence ([`ClassicalConfig::persist`]).
    pub persist: crate::persist::PersistConfig,
    /// Which rigs take the likelihood of the rounded Doppler readings
    /// ([`ClassicalConfig::rounding_likelihood`]).
    pub rounding_likelihood: crate::runner::RoundingRule,
    /// The IMU's noise preset ([`RioConfig::with_imu_noise`]); `None`: the one the session's IMU
    /// device names ([`ImuNoise::from_device`]), or `rio` as given when it names none.
    pub imu_noise: Option<ImuNoise>,
}

/// How the reports name the filter's IMU settings when no preset applies.
pub const DEFAULT_IMU_NOISE: &str = "the defaults (MTi-1 noise, a gyro bias prior for any part)";

/// The IMU noise preset for `session` when `asked` is none ([`OfflineConfig::imu_noise`]), and
/// where it came from (for the reports).
pub fn imu_noise_of(session: &Session, asked: Option<ImuNoise>) -> (Option<ImuNoise>, String) {
    let device = session.meta.imu.as_ref().and_then(|i| i.device.as_deref());
    imu_noise_for(device, asked, "the session names no IMU device")
}

/// The IMU noise preset for an IMU named `device` (a session's, or a live rig's configuration)
/// when `asked` is none, and where it came from (for the reports); `unnamed` says why no device
/// name was given.
pub fn imu_noise_for(
    device: Option<&str>,
    asked: Option<ImuNoise>,
    unnamed: &str,
) -> (Option<ImuNoise>, String) {
    if let Some(n) = asked {
        return (Some(n), format!("{}, asked for", n.name()));
    }
    match device.map(|d| (d, ImuNoise::from_device(d))) {
        Some((d, Some(n))) => (Some(n), format!("{}, from the IMU device {d:?}", n.name())),
        Some((d, None)) => (
            None,
            format!("{DEFAULT_IMU_NOISE}: no preset for the IMU device {d:?}"),
        ),
        None => (None, format!("{DEFAULT_IMU_NOISE}: {unnamed}")),
    }
}

/// When the filter estimates the radar-to-IMU time offset ([`RioConfig::time_offset_std`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimeOffsetMode {
    /// Where the session says its radar times are late by an unknown amount: imported scans
    /// timed by their arrival in the bag (zero header stamps, no trigger;
    /// [`untrusted_radar_timing`]). With the default initial uncertainty
    /// [`TimeOffsetMode::DEFAULT_STD_S`]. Header stamps are trusted (the ROS convention: the
    /// sensor's time); a driver known to stamp late wants [`TimeOffsetMode::Estimate`]: on a
    /// session with right stamps, estimating costs accuracy (a short walk: 1.33 m ATE against
    /// 1.18 m).
    Auto,
    /// Never (the session's clock mapping is trusted).
    Off,
    /// Always, with this initial uncertainty \[s\].
    Estimate(f64),
}

impl OfflineConfig {
    /// For a ground vehicle (car, wheeled robot on a floor): its lateral and vertical velocity
    /// are held at zero in the session's body frame ([`RioConfig::ground_vehicle`]).
    pub fn ground_vehicle(mut self) -> Self {
        self.rio = self.rio.ground_vehicle();
        self
    }
}

impl TimeOffsetMode {
    /// Initial uncertainty of the offset when it is estimated and none was given \[s\]: the
    /// late stamps of ti_mmwave_rospkg and USB-serial buffering are tens of milliseconds.
    pub const DEFAULT_STD_S: f64 = 0.05;
}

/// Why the time offset is estimated for `session` under [`TimeOffsetMode::Auto`], or `None`
/// (the one rule for the offline runner and `milliego run --session`).
pub fn untrusted_radar_timing(session: &Session) -> Option<String> {
    let import = session.meta.import.as_ref()?;
    let radar = import.streams.iter().find(|s| s.stream == "radar")?;
    radar
        .timing
        .starts_with("arrival")
        .then(|| format!("imported radar scans timed by {}", radar.timing))
}

impl Default for OfflineConfig {
    /// Doppler, with the classical estimators' defaults ([`ClassicalConfig::default`]).
    fn default() -> Self {
        let c = ClassicalConfig::default();
        OfflineConfig {
            estimator: Estimator::Doppler,
            rio: c.rio,
            ego: c.ego,
            level_window_s: c.level_window_s,
            velocity_cov_scale: c.velocity_cov_scale,
            rest: c.rest,
            doppler_step_from_cfg: true,
            use_barometer: true,
            radar_time_shift_s: 0.0,
            time_offset: TimeOffsetMode::Auto,
            stack_window_s: c.stack_window_s,
            persist: c.persist,
            rounding_likelihood: c.rounding_likelihood,
            imu_noise: None,
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
    /// Of the frames without a velocity alone, those that gave one with the points of the frames
    /// before them ([`crate::runner::ClassicalConfig::stack_window_s`]).
    pub ego_stacked: usize,
    /// Radar points weighed by whether they were seen again ([`crate::persist`]).
    pub persist: crate::persist::PersistCounters,
    /// Filter updates applied and gated.
    pub updates: u64,
    /// Filter updates rejected by the gate.
    pub gated: u64,
    /// IMU samples at which the body was at rest ([`crate::rest`]).
    pub rest_samples: u64,
    /// Rests the filter's velocity refuted ([`crate::runner::RunnerCounters::rest_refuted`]).
    pub rest_refuted: u64,
    /// Zero-velocity and zero-rate updates applied at rest.
    pub rest_updates: u64,
    /// The longest stretch the poses rested on the IMU alone (no radar velocity, rest or
    /// learned measurement; times on the host clock, as the trajectory's), and the poses given
    /// more than [`crate::runner::UNAIDED_AFTER_S`] after an aid
    /// ([`crate::runner::FramePose::unaided_s`]).
    pub unaided: crate::runner::UnaidedStretch,
    /// Vertical velocity bounds applied ([`RioConfig::vertical_velocity_std`]).
    pub vertical_bounds: u64,
    /// Horizontal velocity bounds applied ([`RioConfig::horizontal_velocity_std`]).
    pub horizontal_bounds: u64,
    /// Walking-pace bounds applied ([`RioConfig::pace_std`]).
    pub pace_bounds: u64,
    /// Mean normalised innovation square of the applied radar updates (3 when consistent).
    pub nis_mean: Option<f64>,
    /// The scale the filter applied to the radar velocity covariances at the end of the run
    /// ([`crate::rio::RioConfig::radar_noise_window`]; 1 when not adapted or no filter ran).
    pub radar_noise_scale: f64,
    /// Barometer readings in the session.
    pub pressure_readings: usize,
    /// Barometric heights applied and rejected by the filter.
    pub baro_updates: u64,
    /// Barometric heights rejected (gate, or not finite).
    pub baro_rejected: u64,
    /// Times the filter re-anchored its height to the barometer after a run of rejections
    /// ([`crate::rio::RioCounters::baro_reanchors`]).
    pub baro_reanchors: u64,
    /// Ground vehicle constraints applied and rejected by their gate
    /// ([`RioConfig::nonholonomic_std`]).
    pub nonholonomic: (u64, u64),
    /// Radar points that did not vote as possible near-field leakage
    /// ([`EgoConfig::near_field_m`]).
    pub near_field_points: u64,
    /// IMU samples integrated.
    pub imu_samples: usize,
    /// Sensor-to-host clock maps (None when the session has no timing index).
    pub radar_clock: Option<ClockFit>,
    /// IMU clock map.
    pub imu_clock: Option<ClockFit>,
    /// True when the streams could not be put on one clock (no index): sensor clocks are then
    /// assumed to start together.
    pub clock_unsynced: bool,
    /// The estimated radar-to-IMU time offset and its standard deviation \[s\] (a frame stamped
    /// `t` was taken at `t + offset`), when it was estimated ([`OfflineConfig::time_offset`]),
    /// and why.
    pub time_offset: Option<(f64, f64, String)>,
    /// What became of the learned motions given to [`run_with_motions`] (zero otherwise).
    pub learned: crate::learned::LearnedCounters,
    /// The factor the filter applied to the learned measurements' stated covariance at the end
    /// of the run ([`crate::learned::LearnedConfig::adapt_noise`]; 1 when not adapted).
    pub learned_noise_factor: f64,
    /// The Doppler quantisation step \[m/s\]: the configured one (the `.cfg`'s, or the
    /// caller's) and the one the radial velocities showed, which replaced it
    /// ([`crate::runner::Runner::doppler_step`]).
    pub doppler_step: (f32, Option<f32>),
    /// The IMU noise the filter assumed and where it came from ([`imu_noise_of`]).
    pub imu_noise: String,
    /// The near field in use at the end \[m\] (0: off) and, when it was left to the data, the
    /// near points tested for leakage, how many read zero Doppler and whether that turned it on
    /// ([`crate::runner::Runner::near_field_leakage`]).
    pub near_field: (f32, Option<(u32, u32, bool)>),
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

/// Runs `cfg.estimator` over `session`: a loop over one [`Runner`] fed in time order (each
/// radar frame just before the first IMU sample at or past its time). Frames before the first
/// or after the last IMU sample get no pose.
pub fn run(session: &Session, cfg: &OfflineConfig) -> Result<OfflineResult, OfflineError> {
    run_with_motions(session, cfg, &[], crate::learned::LearnedConfig::default())
}

/// [`run`] with relative motions between radar frames from elsewhere (a learned model run
/// offline, another odometry) as measurements ([`crate::learned`], settings `learned`): each is
/// given as soon as the pose of its `to` frame came out (frame times on the session clock, as in
/// [`OfflineResult::trajectory`]; sorted by `t_to`).
pub fn run_with_motions(
    session: &Session,
    cfg: &OfflineConfig,
    motions: &[crate::learned::RelativeMotion],
    learned: crate::learned::LearnedConfig,
) -> Result<OfflineResult, OfflineError> {
    let (frames, radar_rep) = radar_frames(session)?;
    let (imu, baro, imu_rep) = imu_and_pressure(session)?;
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
    let (noise, imu_noise) = imu_noise_of(session, cfg.imu_noise);
    let mut rio = noise.map_or(cfg.rio, |n| cfg.rio.with_imu_noise(n));
    let offset_why = match cfg.time_offset {
        TimeOffsetMode::Off => None,
        TimeOffsetMode::Estimate(std) => {
            rio.time_offset_std = std;
            Some("asked for".to_string())
        }
        TimeOffsetMode::Auto => untrusted_radar_timing(session).inspect(|_| {
            rio.time_offset_std = TimeOffsetMode::DEFAULT_STD_S;
        }),
    };

    // The Doppler quantisation step from the session's .cfg unless the caller set one: the same
    // rule as the runtime's (one place: `EgoConfig::with_velocity_resolution`).
    let mut ego = cfg.ego;
    if cfg.doppler_step_from_cfg {
        if let Some(d) = session
            .radar_cfg()?
            .and_then(|text| radar_driver::cfg::RadarConfig::parse(&text).ok())
            .and_then(|c| c.derive(None).ok())
        {
            ego = ego.with_velocity_resolution(d.velocity_resolution_mps);
        }
    }
    let mut runner = Runner::new(
        &ClassicalConfig {
            rio,
            ego,
            level_window_s: cfg.level_window_s,
            velocity_cov_scale: cfg.velocity_cov_scale,
            rest: cfg.rest,
            // The filter runs in the IMU frame, placed by the session's extrinsics.
            mounting: Mounting::from_session(&session.meta.extrinsics),
            // Offline, both streams are complete: no radar-only dead reckoning.
            imu_gap_s: f64::INFINITY,
            learned,
            stack_window_s: cfg.stack_window_s,
            persist: cfg.persist,
            rounding_likelihood: cfg.rounding_likelihood,
        },
        cfg.estimator == Estimator::Doppler,
    );
    let mut radar_times: Vec<(f64, usize)> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| Some((clock.radar_s(f)? + cfg.radar_time_shift_s, i)))
        .collect();
    radar_times.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut trajectory = Vec::with_capacity(radar_times.len());
    let mut next_motion = 0;
    let mut drain = |runner: &mut Runner| {
        while let Some(p) = runner.pop_pose() {
            let q = p.body.rotation;
            trajectory.push(TumPose {
                t: p.t,
                p: p.body.translation.vector.into(),
                q: [q.i, q.j, q.k, q.w],
            });
            while next_motion < motions.len() && motions[next_motion].t_to <= p.t + 1e-3 {
                runner.push_relative_motion(&motions[next_motion]);
                next_motion += 1;
            }
        }
    };
    let mut next = 0;
    let mut next_baro = 0;
    for s in &imu {
        let t = clock.imu_s(s.sensor_s);
        // Barometer readings due at or before this sample, in the stream's order (they share
        // the IMU's clock and stream).
        while next_baro < baro.len() && clock.imu_s(baro[next_baro].sensor_s) <= t {
            let b = &baro[next_baro];
            next_baro += 1;
            if cfg.use_barometer {
                runner.push_pressure(clock.imu_s(b.sensor_s), b.pa);
            }
        }
        while next < radar_times.len() && radar_times[next].0 <= t {
            let (tr, i) = radar_times[next];
            next += 1;
            runner.push_radar(&FrameInput {
                t: tr,
                id: i as u64,
                points: &frames[i].cloud.points,
            });
        }
        runner.push_imu(ImuSample {
            t,
            accel: s.accel,
            gyro: s.gyro,
        });
        drain(&mut runner);
    }
    runner.finish();
    drain(&mut runner);
    let n = |x: u64| usize::try_from(x).unwrap_or(usize::MAX);
    let c = *runner.counters();
    let filter = runner.filter_counters();
    Ok(OfflineResult {
        trajectory,
        radar: radar_rep,
        imu: imu_rep,
        radar_frames: frames.len(),
        ego_ok: n(c.ego_ok),
        ego_degenerate: n(c.ego_degenerate),
        ego_too_few: n(c.ego_too_few),
        ego_no_consensus: n(c.ego_no_consensus),
        ego_stacked: n(c.ego_stacked),
        persist: *runner.persist_counters(),
        updates: filter.updates,
        gated: filter.gated,
        rest_samples: c.rest_samples,
        rest_refuted: c.rest_refuted,
        rest_updates: filter.rest_updates,
        unaided: runner.longest_unaided(),
        vertical_bounds: filter.vertical_bounds,
        horizontal_bounds: filter.horizontal_bounds,
        pace_bounds: filter.pace_bounds,
        nis_mean: runner.filter().and_then(|f| f.nis_mean()),
        radar_noise_scale: runner.filter().map_or(1.0, |f| f.radar_noise_scale()),
        pressure_readings: baro.len(),
        baro_updates: filter.baro_updates,
        baro_rejected: filter.baro_rejected,
        baro_reanchors: filter.baro_reanchors,
        nonholonomic: (filter.nonholonomic_updates, filter.nonholonomic_gated),
        near_field_points: c.near_field_points,
        imu_samples: imu.len(),
        radar_clock,
        imu_clock,
        clock_unsynced,
        time_offset: runner
            .filter()
            .and_then(|f| f.time_offset())
            .zip(offset_why)
            .map(|((o, sd), why)| (o, sd, why)),
        learned: *runner.learned_counters(),
        learned_noise_factor: runner.learned_noise_factor(),
        doppler_step: runner.doppler_step(),
        imu_noise,
        near_field: (runner.near_field_m(), runner.near_field_leakage()),
    })
}
