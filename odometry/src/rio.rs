//! Radar-inertial odometry: an error-state Kalman filter that propagates with the IMU
//! ([`crate::strapdown`]) and updates with radar ego-velocity ([`crate::ego_velocity`]).
//!
//! Nominal state: position `p` and velocity `v` in the world frame, body-to-world rotation `q`,
//! accelerometer bias `b_a`, gyroscope bias `b_g` (body = IMU frame), and, once a barometer
//! reading came, the barometer bias `b_h` (barometric height minus the filter's). Error state
//! (20): `dp, dv, dtheta` (body-frame rotation error, `q = q_hat * Exp(dtheta)`), `db_a`, `db_g`,
//! `db_h` (zero variance until a barometer reading comes), and `dt_d`, the radar-to-IMU time
//! offset (zero variance unless [`RioConfig::time_offset_std`] asks for it to be estimated).
//!
//! Measurement: the radar's velocity in its own frame,
//! `h(x) = R_br^T (R^T v + (omega - b_g) x t_br)`, where `R_br`, `t_br` place the radar in the
//! body frame (session extrinsics) and `omega` is the measured rate of turn. Measurements are
//! gated with a chi-square test (3 dof) and rejected ones are counted.
//!
//! Time: the filter runs on the IMU clock. Radar measurements must already be mapped to it (the
//! synchroniser's clock offset); a measurement is applied at the first IMU step at or after its
//! time (at most one IMU period late). Where that mapping is doubtful (host-stamped or imported
//! streams without a trigger), the filter estimates what is left of the offset: a measurement
//! stamped `t` was taken at `t + t_d`, and the prediction moves along the radar velocity's rate
//! of change `J` (body acceleration, rotation, angular acceleration on the lever arm) by
//! `J (t + t_d - now)`; `t_d` is observable whenever the body accelerates or turns.

use crate::strapdown::{ImuSample, NavState, Strapdown};
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

/// Error-state size: 15 inertial states, the barometer bias, the radar time offset and the
/// radar's shared rounding error.
const N: usize = 20;
/// Index of the barometer bias in the error state.
const BARO: usize = 15;
/// Index of the radar-to-IMU time offset in the error state.
const TD: usize = 16;
/// Index of the radar's shared rounding error (3, radar frame) in the error state.
const RB: usize = 17;
/// Largest radar-to-IMU time offset the filter estimates \[s\].
const MAX_TIME_OFFSET_S: f64 = 0.5;
type Mn = SMatrix<f64, N, N>;
type Vn = SVector<f64, N>;
type M3xN = SMatrix<f64, 3, N>;

/// Smallest pace \[m/s\] the walking-pace bound holds ([`RioConfig::pace_std`]): below it the
/// rig creeps or stands, the speed's direction is poorly defined, and the horizontal bound is
/// the prior that fits.
pub const PACE_MIN: f64 = 0.3;

/// Time constant of the pace \[s\] ([`RioConfig::pace_std`]): the speed after each radar update
/// is averaged over about a step cycle (a walker's speed swings within each step; a single
/// update also carries its own noise), older updates fading as `exp(-dt / PACE_TAU_S)`.
pub const PACE_TAU_S: f64 = 0.5;

/// Smallest horizontal speed of the filter \[m/s\] that gives the walking-pace bound its
/// direction.
pub const PACE_DIRECTION_MIN: f64 = 0.1;

/// Deviation of a ground vehicle's lateral and vertical velocity from zero at standstill \[m/s\]
/// ([`RioConfig::ground_vehicle`]): a floor's or a road's unevenness, the suspension. (It was
/// 0.1 m/s, without the growth with speed, until 2026-12-07: a third of a 0.3 m/s robot's
/// speed; docs/odometry.md, "How tight the ground vehicle constraint is".)
pub const GROUND_VEHICLE_STD: f64 = 0.01;

/// Growth of that deviation with the forward speed \[rad\] ([`RioConfig::nonholonomic_angle`]):
/// a tyre's slip angle and the vehicle frame's misalignment, about a degree (0.17 m/s sideways
/// for a car at 10 m/s).
pub const GROUND_VEHICLE_ANGLE: f64 = 0.02;

/// Noise densities and initial uncertainties.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RioConfig {
    /// Accelerometer white noise \[m/s^2/sqrt(Hz)\].
    pub accel_noise: f64,
    /// Gyroscope white noise \[rad/s/sqrt(Hz)\].
    pub gyro_noise: f64,
    /// Accelerometer bias random walk \[m/s^3/sqrt(Hz)\].
    pub accel_bias_walk: f64,
    /// Gyroscope bias random walk \[rad/s^2/sqrt(Hz)\].
    pub gyro_bias_walk: f64,
    /// Initial velocity standard deviation \[m/s\].
    pub init_velocity_std: f64,
    /// Initial roll/pitch standard deviation \[rad\] (yaw starts at 0 and is unobservable).
    pub init_tilt_std: f64,
    /// Initial accelerometer bias standard deviation \[m/s^2\].
    pub init_accel_bias_std: f64,
    /// Initial gyroscope bias standard deviation \[rad/s\] (the turn-on bias: 0.01 by default,
    /// any MEMS part; [`XSENS_GYRO_TURN_ON_STD`] with an Xsens preset).
    pub init_gyro_bias_std: f64,
    /// Chi-square gate for radar updates (3 dof; 16.27 = 99.9%).
    pub gate: f64,
    /// Gravity magnitude \[m/s^2\].
    pub gravity: f64,
    /// Consecutive gated measurements after which the velocity is re-anchored to the measurement
    /// (its uncertainty reset to `init_velocity_std`), so one bad stretch cannot lock the filter
    /// out of every later update.
    pub reanchor_after: u32,
    /// Whether radar velocity updates may correct the heading (world yaw) and the gyroscope bias
    /// about the world vertical. Body-frame velocity cannot observe heading: rotating the state
    /// about the vertical leaves every Doppler prediction unchanged, so what a radar update does
    /// to the heading comes from linearisation error and model error (lever arm, mount, clock)
    /// and makes it worse than the gyro alone. `false` (the default) takes those components out
    /// of the radar updates' gain (a Schmidt "consider" update, kept consistent by the Joseph
    /// form); rest updates still estimate the whole gyro bias.
    pub radar_heading: bool,
    /// Vertical velocity pseudo-measurement \[m/s\]: at a radar frame that sees the world
    /// vertical velocity no better than this, or that gives no update at all, or when the filter
    /// is that uncertain of it, the
    /// filter takes "vertical velocity 0" with this standard deviation (walking and driving
    /// rarely climb faster), so a frame that cannot see vertical motion cannot let it run away
    /// (`f64::INFINITY`: never).
    pub vertical_velocity_std: f64,
    /// Horizontal velocity bound \[m/s\]: at a radar frame, when the filter is less sure of a
    /// world horizontal velocity component than this, it takes "that component 0" with this
    /// deviation: a handheld, headworn or robot rig moves at walking pace (1.4 m/s in any
    /// direction is about 1 m/s per axis), so where the radar gives no velocity for many
    /// seconds (a sparse outdoor scene, a radar tilted at the sky) the IMU alone cannot run
    /// the velocity away to 10 m/s. A filter that knows its velocity is never touched. Ground
    /// vehicles ([`RioConfig::nonholonomic_std`] finite) are exempt; `f64::INFINITY`: never.
    pub horizontal_velocity_std: f64,
    /// Walking-pace bound \[m/s\]: at a radar frame that gave no velocity, when the filter is
    /// less sure of its horizontal speed than this (plus the pace's own uncertainty), it takes
    /// "the speed is the pace" with that deviation, the pace being the speed it held after its
    /// aids (radar updates, learned velocities), averaged over [`PACE_TAU_S`] (a walker or
    /// robot keeps its pace when the radar stops seeing: 1.0-1.5 m/s walking, drifting
    /// slowly). The horizontal
    /// bound ([`RioConfig::horizontal_velocity_std`]) alone pulls a lost filter towards
    /// standing still: a walk the radar lost for 27 s read 0.3-0.6 m/s against the truth's
    /// 1.2-1.4 m/s. The direction stays the filter's own (from the IMU). A filter that knows
    /// its speed is never touched; no pace below [`PACE_MIN`] (the horizontal bound is then
    /// the right prior), none after a rest or [`Rio::forget_pace`]; ground vehicles
    /// ([`RioConfig::nonholonomic_std`] finite) are exempt. Default 0.25 (chosen on the
    /// validation sets, docs/odometry.md "Walking pace"); `f64::INFINITY`: never.
    pub pace_std: f64,
    /// Uncertainty of a radar measurement's time on the IMU clock \[s\] (exposure spread,
    /// clock mapping): the measurement covariance gains `J J^T sigma_t^2`, `J` the rate of change
    /// of the predicted radar velocity (body acceleration, rotation of the body velocity, angular
    /// acceleration on the lever arm), so fast motion on a long lever arm is not over-trusted.
    pub time_sigma_s: f64,
    /// Barometric height noise \[m\] (white, per reading).
    pub baro_std_m: f64,
    /// Barometer bias random walk \[m/sqrt(s)\] (weather, temperature).
    pub baro_bias_walk: f64,
    /// Initial uncertainty of the radar-to-IMU time offset \[s\]: 0 trusts the clock mapping
    /// (sessions with a timing index, trigger-timed imports, the sensor hub); above 0 the offset
    /// is estimated online from the Doppler updates ([`Rio::time_offset`]).
    pub time_offset_std: f64,
    /// Random walk of the estimated time offset \[s/sqrt(s)\] (clock drift between the fits).
    pub time_offset_walk: f64,
    /// Motion the IMU missed in a gap \[m/s^2\]: across missing samples the integration
    /// draws the specific force as a straight line between the samples either side; the true
    /// one departs from it by about this much, so the velocity variance grows by
    /// `(gap_accel_std x missing time)^2` (the white-noise density alone would keep the filter
    /// as sure of its velocity after a 0.2 s gap as after one sample). 0: off. (The same for
    /// the attitude, with the rate of turn, was tried and left out: it let radar updates turn
    /// the attitude on a sparse outdoor walk, docs/odometry.md.)
    pub gap_accel_std: f64,
    /// Ground vehicle constraint \[m/s\]: at each radar frame the vehicle frame's lateral and
    /// vertical velocity are 0 with this deviation at standstill, growing with the forward speed
    /// by [`RioConfig::nonholonomic_angle`] (a car does not slide sideways or lift off;
    /// [`Rio::set_vehicle_frame`] places that frame); `f64::INFINITY`: not a ground vehicle.
    /// [`RioConfig::ground_vehicle`] sets both to [`GROUND_VEHICLE_STD`] and
    /// [`GROUND_VEHICLE_ANGLE`].
    pub nonholonomic_std: f64,
    /// How far the ground vehicle constraint's deviation grows with the vehicle frame's forward
    /// speed `u` \[rad\]: the lateral and vertical deviation is
    /// `sqrt(nonholonomic_std^2 + (nonholonomic_angle u)^2)`, the velocity a slip angle or a
    /// misaligned vehicle frame of that angle gives at that speed.
    pub nonholonomic_angle: f64,
    /// Radar noise adaptation: the number of applied radar updates \[frames\] over which the
    /// filter estimates one scale `alpha` of the ego-velocity covariances it is given (their
    /// covariance becomes `alpha C`), by recursive maximum likelihood on the innovations
    /// (default 300: 15 s at 20 Hz, chosen on the validation sets, docs/odometry.md "Radar noise
    /// adaptation"; 0: off, the covariance as given). A radar noisier than the ego-velocity
    /// stage assumes (clutter that passes the consensus, multipath, coarse angle cells) would
    /// otherwise be over-trusted for the whole run. Updates taken without the gate (a
    /// re-anchoring) do not count. (At rest the runner gives no radar velocities: the
    /// zero-velocity update stands in.)
    pub radar_noise_window: f64,
    /// Bounds of the radar noise scale (`[min, max]`, default `[1, 10]`: the stated covariance
    /// is a floor; a scale below 1 fitted the simulator's walks and lost on the training set),
    /// see [`RioConfig::radar_noise_window`].
    pub radar_noise_scale_bounds: [f64; 2],
    /// The radar's shared rounding error as a state (default on): the part of a radar
    /// velocity's covariance that its points share through a coarse Doppler step
    /// ([`VelocityMeasurement::shared_covariance`]) is an error that lasts from frame to frame
    /// while the velocity stays within a fraction of a step, not noise drawn anew each frame. A
    /// filter that takes it as new each frame is pinned by twenty identical readings a second: a
    /// robot at 0.2 m/s under 0.46 m/s steps reads "0" until the filter believes it stopped. As a
    /// state (radar frame, three components) with that covariance in the stationary state, its
    /// correlation from one radar update to the next falls as `exp(-6 |dv| / step)` with the
    /// change `dv` of the predicted radar velocity \[m/s\] (half a step: 0.05) and as
    /// `exp(-dt / radar_error_time_s)` with time (the points come and go). Off: the whole
    /// covariance is white.
    pub radar_error_state: bool,
    /// Correlation time of the shared rounding error at a steady velocity \[s\] (default 2), see
    /// [`RioConfig::radar_error_state`].
    pub radar_error_time_s: f64,
}

/// The gyroscope turn-on bias deviation the Xsens presets ([`ImuNoise::Mti1`],
/// [`ImuNoise::Mti600`]) start the filter from \[rad/s\] (0.086 deg/s): a factory-calibrated
/// part's, where [`RioConfig::default`] keeps 0.01 rad/s for a part it knows nothing of. A prior
/// that wide let the radar take a walk's levelling error as horizontal gyro bias, which a head
/// that pitches turns into heading drift the radar may not correct (docs/odometry.md, "Gyro bias
/// prior"). Chosen on the validation sets (0.001-0.003 within 3% of each other). A part whose
/// bias is larger is still measured at a rest: the zero-rate update is not gated.
pub const XSENS_GYRO_TURN_ON_STD: f64 = 1.5e-3;

/// IMU noise presets for the filter's process noise, from the parts' datasheets (white noise
/// densities inflated by 1.4 for the gyro, as the MTi-1 default is, for vibration and
/// temperature; turn-on bias and random walks as docs/simulator.md assumes for each class; the
/// Xsens classes' gyro turn-on bias [`XSENS_GYRO_TURN_ON_STD`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImuNoise {
    /// Xsens MTi-1 series (MTi-1/2/3/7/8): gyro 0.007 deg/s/sqrt(Hz), accelerometer
    /// 120 ug/sqrt(Hz). The default's noise, with the gyro turn-on bias of a named Xsens part.
    Mti1,
    /// Xsens MTi-600 series (MTi-610/620/630/670/680): accelerometer 60 ug/sqrt(Hz), turn-on
    /// bias 30 mm/s^2.
    Mti600,
    /// A consumer MEMS part (Bosch BMI088, TDK ICM class): gyro 0.014 deg/s/sqrt(Hz),
    /// accelerometer 175 ug/sqrt(Hz), zero-g offset up to 20 mg (0.1 m/s^2 at one sigma
    /// taken), bias random walks five times the MTi-1's.
    Mems,
}

impl ImuNoise {
    /// Every preset.
    pub const ALL: [ImuNoise; 3] = [ImuNoise::Mti1, ImuNoise::Mti600, ImuNoise::Mems];

    /// Its name (`mti1`, `mti600`, `mems`).
    pub fn name(self) -> &'static str {
        match self {
            ImuNoise::Mti1 => "mti1",
            ImuNoise::Mti600 => "mti600",
            ImuNoise::Mems => "mems",
        }
    }

    /// The preset a device name (a session's `[imu] device`, free text) calls for, when it
    /// names a known part: `MTi-6..` is the 600 series, other `MTi-1`..`MTi-8` parts the MTi-1
    /// series, and BMI/ICM/MPU/LSM parts or "MEMS" a consumer MEMS IMU.
    pub fn from_device(device: &str) -> Option<ImuNoise> {
        let d = device.to_ascii_lowercase();
        if [
            "bmi0", "bmi1", "bmi2", "icm-", "icm2", "mpu-", "mpu6", "mpu9", "lsm6", "mems",
        ]
        .iter()
        .any(|k| d.contains(k))
        {
            return Some(ImuNoise::Mems);
        }
        let series = d.split("mti-").nth(1)?.chars().next()?;
        match series {
            '6' => Some(ImuNoise::Mti600),
            '1'..='8'
                if !d.contains("mti-10") && !d.contains("mti-20") && !d.contains("mti-30") =>
            {
                Some(ImuNoise::Mti1)
            }
            _ => None,
        }
    }
}

impl core::str::FromStr for ImuNoise {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        ImuNoise::ALL
            .into_iter()
            .find(|n| n.name() == s)
            .ok_or_else(|| {
                format!("unknown IMU noise preset {s:?} (expected mti1, mti600 or mems)")
            })
    }
}

impl RioConfig {
    /// For a ground vehicle (car, wheeled robot on a floor): its lateral and vertical velocity
    /// in the vehicle frame are zero within [`GROUND_VEHICLE_STD`] at standstill, growing with
    /// its forward speed by [`GROUND_VEHICLE_ANGLE`] ([`RioConfig::nonholonomic_std`]).
    pub fn ground_vehicle(mut self) -> Self {
        self.nonholonomic_std = GROUND_VEHICLE_STD;
        self.nonholonomic_angle = GROUND_VEHICLE_ANGLE;
        self
    }

    /// This configuration with the shared rounding state's correlation time `seconds` \[s\]
    /// ([`RioConfig::radar_error_time_s`]); 0, a negative or a non-finite value other than
    /// infinity turns the state off ([`RioConfig::radar_error_state`]).
    pub fn with_radar_error_time(mut self, seconds: f64) -> Self {
        if seconds > 0.0 {
            self.radar_error_state = true;
            self.radar_error_time_s = seconds;
        } else {
            self.radar_error_state = false;
        }
        self
    }

    /// These settings with the IMU noise of `imu` (white noise, bias random walks and turn-on
    /// bias uncertainty; nothing else changes).
    pub fn with_imu_noise(mut self, imu: ImuNoise) -> Self {
        let d = RioConfig::default();
        (
            self.accel_noise,
            self.gyro_noise,
            self.accel_bias_walk,
            self.gyro_bias_walk,
            self.init_accel_bias_std,
            self.init_gyro_bias_std,
        ) = match imu {
            ImuNoise::Mti1 => (
                d.accel_noise,
                d.gyro_noise,
                d.accel_bias_walk,
                d.gyro_bias_walk,
                d.init_accel_bias_std,
                XSENS_GYRO_TURN_ON_STD,
            ),
            ImuNoise::Mti600 => (
                0.6e-3,
                d.gyro_noise,
                d.accel_bias_walk,
                d.gyro_bias_walk,
                0.03,
                XSENS_GYRO_TURN_ON_STD,
            ),
            ImuNoise::Mems => (1.72e-3, 3.4e-4, 5e-4, 1e-5, 0.1, d.init_gyro_bias_std),
        };
        self
    }
}

impl Default for RioConfig {
    /// MTi-1-class IMU noise (datasheet-level densities), with a gyro turn-on bias prior wide
    /// enough for a part the filter knows nothing of (0.01 rad/s; see [`XSENS_GYRO_TURN_ON_STD`]).
    fn default() -> Self {
        RioConfig {
            accel_noise: 1.2e-3,
            gyro_noise: 1.7e-4,
            accel_bias_walk: 1e-4,
            gyro_bias_walk: 2e-6,
            init_velocity_std: 0.5,
            init_tilt_std: 0.05,
            init_accel_bias_std: 0.05,
            init_gyro_bias_std: 0.01,
            gate: 16.27,
            gravity: crate::strapdown::STANDARD_GRAVITY,
            reanchor_after: 5,
            radar_heading: false,
            vertical_velocity_std: 0.5,
            horizontal_velocity_std: 1.0,
            pace_std: 0.25,
            time_sigma_s: 0.005,
            baro_std_m: 0.3,
            baro_bias_walk: 0.02,
            time_offset_std: 0.0,
            time_offset_walk: 1e-4,
            nonholonomic_std: f64::INFINITY,
            nonholonomic_angle: 0.0,
            gap_accel_std: 1.0,
            radar_noise_window: 300.0,
            radar_noise_scale_bounds: [1.0, 10.0],
            radar_error_state: true,
            radar_error_time_s: 2.0,
        }
    }
}

/// Where the radar sits on the body: `p_body = R_br p_radar + t_br`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarMount {
    /// Radar-to-body rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Radar origin in the body frame \[m\].
    pub translation: Vector3<f64>,
}

impl Default for RadarMount {
    fn default() -> Self {
        RadarMount {
            rotation: UnitQuaternion::identity(),
            translation: Vector3::zeros(),
        }
    }
}

/// A radar ego-velocity measurement on the IMU clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityMeasurement {
    /// Time on the IMU clock \[s\].
    pub t: f64,
    /// Radar velocity in the radar frame \[m/s\].
    pub velocity: [f64; 3],
    /// Its covariance \[m^2/s^2\].
    pub covariance: [[f64; 3]; 3],
    /// The part of `covariance` the frame's points share through the rounding of a coarse
    /// Doppler step \[m^2/s^2\] ([`crate::ego_velocity::Estimate::shared_covariance`]; zeros
    /// for continuous Doppler), see [`RioConfig::radar_error_state`].
    pub shared_covariance: [[f64; 3]; 3],
    /// The Doppler quantisation step the velocity was estimated under \[m/s\] (0: continuous).
    pub doppler_step: f64,
    /// Estimated with points carried from earlier frames
    /// ([`crate::runner::ClassicalConfig::stack_window_s`]): when the gate rejects it, it does
    /// not count towards a re-anchoring ([`RioConfig::reanchor_after`]), which takes a
    /// measurement without the gate.
    pub carried: bool,
}

/// Counters of what the filter did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RioCounters {
    /// IMU samples integrated.
    pub imu_samples: u64,
    /// Radar updates applied.
    pub updates: u64,
    /// Radar updates rejected by the gate.
    pub gated: u64,
    /// Radar measurements older than the filter time (applied late, at the current time).
    pub late: u64,
    /// Times the filter re-anchored its velocity after a run of gated measurements (it had
    /// diverged or the motion changed faster than the model allows).
    pub reanchors: u64,
    /// Zero-velocity and zero-rate pseudo-measurements applied at rest ([`crate::rest`]).
    pub rest_updates: u64,
    /// Vertical velocity bounds applied ([`RioConfig::vertical_velocity_std`]).
    pub vertical_bounds: u64,
    /// Horizontal velocity bounds applied ([`RioConfig::horizontal_velocity_std`]).
    pub horizontal_bounds: u64,
    /// Walking-pace bounds applied ([`RioConfig::pace_std`]).
    pub pace_bounds: u64,
    /// Barometric heights applied.
    pub baro_updates: u64,
    /// Barometric heights rejected (not finite, or outside a 99.9% gate).
    pub baro_rejected: u64,
    /// Times the filter re-anchored its height to the barometer after rejecting every reading
    /// for [`BARO_REANCHOR_S`] (its height had run away and its own variance no longer admitted
    /// the barometer).
    pub baro_reanchors: u64,
    /// Ground vehicle constraints applied ([`RioConfig::nonholonomic_std`]).
    pub nonholonomic_updates: u64,
    /// Ground vehicle constraints rejected by their gate (a skid, a jump).
    pub nonholonomic_gated: u64,
}

/// Chi-square gate for one degree of freedom (99.9%).
const GATE_1DOF: f64 = 10.83;
/// How long the barometer must be rejected without a break before the filter's height, not the
/// barometer, is doubted \[s\]: the height and vertical velocity are re-anchored
/// ([`RioCounters::baro_reanchors`]). At 50 Hz that is 50 readings in a row outside a 99.9%
/// gate, which a barometer within its noise gives about never.
pub const BARO_REANCHOR_S: f64 = 1.0;
/// Fewest rejected readings in such a run (a slow barometer's run is not decided by two).
const BARO_REANCHOR_MIN: u32 = 5;
/// Chi-square gate for two degrees of freedom (99.9%).
const GATE_2DOF: f64 = 13.82;

/// Altitude \[m\] of pressure `pa` \[Pa\] in the standard atmosphere
/// (`44330.8 (1 - (p / 101325)^0.190263)`); only differences matter to the filter.
pub fn pressure_altitude(pa: f64) -> f64 {
    (1.0 - (pa / 101_325.0).powf(1.0 / 5.25588)) / 2.25577e-5
}

/// What waits in the filter for the IMU to reach its time.
#[derive(Debug, Clone, Copy)]
enum Pending {
    /// A radar velocity.
    Velocity(VelocityMeasurement),
    /// A radar frame without one.
    Frame(f64),
    /// A barometric height \[m\] at its time.
    Height(f64, f64),
}

impl Pending {
    fn t(&self) -> f64 {
        match self {
            Pending::Velocity(m) => m.t,
            Pending::Frame(t) | Pending::Height(t, _) => *t,
        }
    }
}

/// IMU steps remembered for moving a radar prediction back in time (time offset estimation):
/// 256 steps are 0.64 s at 400 Hz, 2.56 s at 100 Hz.
const HISTORY: usize = 256;

/// What each recent IMU step did to the predicted radar velocity: propagation only, corrections
/// excluded, so the prediction at an earlier time `tau` is the current one less the steps'
/// changes since `tau` (the errors of the state then and now are taken as equal).
#[derive(Debug, Clone)]
struct StepHistory {
    /// Step start and end times \[s\].
    span: [(f64, f64); HISTORY],
    /// Change of the predicted radar velocity over the step \[m/s, radar frame\].
    change: [Vector3<f64>; HISTORY],
    /// Next slot.
    head: usize,
    /// Slots in use.
    len: usize,
}

impl StepHistory {
    fn new() -> Self {
        StepHistory {
            span: [(0.0, 0.0); HISTORY],
            change: [Vector3::zeros(); HISTORY],
            head: 0,
            len: 0,
        }
    }

    fn push(&mut self, t0: f64, t1: f64, change: Vector3<f64>) {
        self.span[self.head] = (t0, t1);
        self.change[self.head] = change;
        self.head = (self.head + 1) % HISTORY;
        self.len = (self.len + 1).min(HISTORY);
    }

    /// The change of the prediction from `tau` to the newest step's end, and its rate at `tau`
    /// \[m/s^2\]; `None` when `tau` is older than the history.
    fn since(&self, tau: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let mut acc = Vector3::zeros();
        for k in 0..self.len {
            let i = (self.head + HISTORY - 1 - k) % HISTORY;
            let (t0, t1) = self.span[i];
            let dt = t1 - t0;
            if tau >= t0 {
                let rate = if dt > 0.0 {
                    self.change[i] / dt
                } else {
                    Vector3::zeros()
                };
                return Some((acc + rate * (t1 - tau).max(0.0), rate));
            }
            acc += self.change[i];
        }
        None
    }
}

/// The filter.
#[derive(Debug, Clone)]
pub struct Rio {
    cfg: RioConfig,
    mount: RadarMount,
    nav: Strapdown,
    p: Mn,
    last_gyro: Vector3<f64>,
    last_accel: Vector3<f64>,
    angular_accel: Vector3<f64>,
    pending: Vec<Pending>,
    counters: RioCounters,
    started: bool,
    gated_run: u32,
    /// The pace ([`RioConfig::pace_std`]): the horizontal speed \[m/s\] after the radar updates
    /// and the filter's variance of it then \[m^2/s^2\], both averaged over [`PACE_TAU_S`].
    pace: Option<(f64, f64)>,
    /// Time of the last aid that set the pace \[s\].
    pace_t: f64,
    /// Sum of the applied radar updates' normalised innovation squares (3 dof each).
    nis_sum: f64,
    /// Scale of the radar velocity covariances (1 unless adapted, [`RioConfig::radar_noise_window`]).
    noise_scale: f64,
    /// Fisher information about [`Rio::noise_scale`] gathered so far (forgotten over the window).
    noise_information: f64,
    /// Barometer bias \[m\] (barometric height minus the filter's), once a reading came.
    baro_bias: Option<f64>,
    /// The IMU's sample interval \[s\] (the shortest recent one; gaps do not move it).
    nominal_dt: f64,
    /// The current run of rejected barometer readings: its first reading's time \[s\] and
    /// length.
    baro_rejected_run: Option<(f64, u32)>,
    /// Radar-to-IMU time offset \[s\]: a radar measurement stamped `t` was taken at `t + t_d`.
    time_offset: f64,
    /// Recent steps' changes of the radar prediction (only while the offset is estimated).
    history: StepHistory,
    /// The vehicle frame in the IMU frame (x forward, z up), for the ground vehicle constraint.
    vehicle: RadarMount,
    /// Sum of the velocity corrections folded into the nominal state \[m/s, world\]: the
    /// nominal velocity minus it changes only with the IMU ([`Rio::imu_velocity`]).
    velocity_corrections: Vector3<f64>,
    /// The radar's shared rounding error \[m/s, radar frame\] ([`RioConfig::radar_error_state`]).
    radar_error: Vector3<f64>,
    /// The time \[s\] and predicted radar velocity \[m/s\] of the last radar update.
    last_radar: Option<(f64, Vector3<f64>)>,
}

impl Rio {
    /// A filter starting from `state` (biases zero) with the radar at `mount`.
    pub fn new(cfg: RioConfig, mount: RadarMount, state: NavState) -> Rio {
        let mut p = Mn::zeros();
        let set = |p: &mut Mn, at: usize, s: f64| {
            for k in at..at + 3 {
                p[(k, k)] = s * s;
            }
        };
        set(&mut p, 0, 1e-6);
        set(&mut p, 3, cfg.init_velocity_std);
        set(&mut p, 6, cfg.init_tilt_std);
        p[(8, 8)] = 1e-6; // yaw: the origin's heading is the reference
        set(&mut p, 9, cfg.init_accel_bias_std);
        set(&mut p, 12, cfg.init_gyro_bias_std);
        if cfg.time_offset_std.is_finite() && cfg.time_offset_std > 0.0 {
            p[(TD, TD)] = cfg.time_offset_std * cfg.time_offset_std;
        }
        Rio {
            cfg,
            mount,
            nav: Strapdown::new(state, cfg.gravity),
            p,
            last_gyro: Vector3::zeros(),
            last_accel: Vector3::zeros(),
            angular_accel: Vector3::zeros(),
            pending: Vec::new(),
            counters: RioCounters::default(),
            started: false,
            gated_run: 0,
            pace: None,
            pace_t: 0.0,
            nis_sum: 0.0,
            noise_scale: 1.0,
            noise_information: 0.0,
            baro_bias: None,
            baro_rejected_run: None,
            nominal_dt: 0.0,
            time_offset: 0.0,
            history: StepHistory::new(),
            vehicle: RadarMount::default(),
            velocity_corrections: Vector3::zeros(),
            radar_error: Vector3::zeros(),
            last_radar: None,
        }
    }

    /// Places the vehicle frame (x forward, y left, z up; its origin where the vehicle does not
    /// slide sideways, e.g. the rear axle) in the IMU frame, for
    /// [`RioConfig::nonholonomic_std`]. Default: the IMU frame itself.
    pub fn set_vehicle_frame(&mut self, vehicle_in_imu: RadarMount) {
        self.vehicle = vehicle_in_imu;
    }

    /// Levels the initial attitude from a stationary accelerometer reading (roll and pitch from
    /// gravity, yaw 0) and returns the filter.
    pub fn levelled(cfg: RioConfig, mount: RadarMount, t: f64, accel: [f64; 3]) -> Rio {
        let f = Vector3::from(accel);
        let q = UnitQuaternion::rotation_between(&f, &Vector3::z())
            .unwrap_or_else(UnitQuaternion::identity);
        // Remove any yaw the shortest rotation introduced.
        let (r, pch, _) = q.euler_angles();
        let q = UnitQuaternion::from_euler_angles(r, pch, 0.0);
        Rio::new(
            cfg,
            mount,
            NavState {
                q,
                ..NavState::at_rest(t)
            },
        )
    }

    /// The nominal velocity less every correction the filter has folded into it \[m/s, world\]:
    /// its change between two times is what the IMU alone integrated (with the filter's
    /// attitude and biases), whatever measurements came in between.
    pub fn imu_velocity(&self) -> Vector3<f64> {
        self.nav.state().v - self.velocity_corrections
    }

    /// The latest rate of turn less the gyro bias \[rad/s, IMU frame\].
    pub fn angular_rate(&self) -> Vector3<f64> {
        self.last_gyro - self.nav.gyro_bias
    }

    /// The radar's mounting in the IMU frame.
    pub fn mount(&self) -> &RadarMount {
        &self.mount
    }

    /// The current state.
    pub fn state(&self) -> &NavState {
        self.nav.state()
    }

    /// Accelerometer bias \[m/s^2\] and gyroscope bias \[rad/s\] estimates.
    pub fn biases(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.nav.accel_bias, self.nav.gyro_bias)
    }

    /// Error-state covariance (order: p, v, theta, b_a, b_g, b_h, t_d).
    pub fn covariance(&self) -> &Mn {
        &self.p
    }

    /// Counters.
    pub fn counters(&self) -> &RioCounters {
        &self.counters
    }

    /// The estimated radar-to-IMU time offset and its standard deviation \[s\] (a radar
    /// measurement stamped `t` was taken at `t + offset`), when it is estimated
    /// ([`RioConfig::time_offset_std`]).
    pub fn time_offset(&self) -> Option<(f64, f64)> {
        self.estimates_time_offset()
            .then(|| (self.time_offset, self.p[(TD, TD)].max(0.0).sqrt()))
    }

    fn estimates_time_offset(&self) -> bool {
        self.cfg.time_offset_std.is_finite() && self.cfg.time_offset_std > 0.0
    }

    /// Mean normalised innovation square of the applied radar updates (3 for a consistent
    /// filter; larger: the measurements' covariance or the model is too optimistic). `None`
    /// before the first update.
    pub fn nis_mean(&self) -> Option<f64> {
        (self.counters.updates > 0).then(|| self.nis_sum / self.counters.updates as f64)
    }

    /// Propagates with one IMU sample, then applies any radar measurement now due.
    pub fn push_imu(&mut self, s: ImuSample) {
        let before = *self.nav.state();
        let track = self.started && self.estimates_time_offset();
        let pred_before = if track {
            self.radar_model().0
        } else {
            Vector3::zeros()
        };
        let rejected = self.nav.rejected;
        self.nav.push(s);
        let gyro = Vector3::from(s.gyro);
        let dt_s = self.nav.state().t - before.t;
        if self.started && dt_s > 0.0 {
            self.angular_accel = (gyro - self.last_gyro) / dt_s;
        }
        self.last_gyro = gyro;
        self.last_accel = Vector3::from(s.accel);
        if !self.started {
            self.started = true;
            return;
        }
        if self.nav.rejected != rejected {
            return;
        }
        self.counters.imu_samples += 1;
        let dt = self.nav.state().t - before.t;
        self.propagate_cov(&before, &s, dt);
        if track {
            let change = self.radar_model().0 - pred_before;
            self.history.push(before.t, self.nav.state().t, change);
        }
        let now = self.nav.state().t;
        // In queue order, without a temporary vector (the runtime's hot path allocates nothing).
        while let Some(i) = self.pending.iter().position(|m| m.t() <= now) {
            match self.pending.remove(i) {
                Pending::Velocity(m) => {
                    self.update(&m);
                    self.nonholonomic();
                }
                Pending::Frame(_) => {
                    self.bound_velocity(true, false);
                    self.nonholonomic();
                }
                Pending::Height(_, h) => self.height_update(h),
            }
        }
    }

    /// Queues a radar measurement (applied when the IMU reaches its time; at once if it is
    /// already past).
    pub fn push_velocity(&mut self, m: VelocityMeasurement) {
        if self.started && m.t <= self.nav.state().t {
            self.counters.late += u64::from(self.nav.state().t - m.t > 0.05);
            self.update(&m);
            self.nonholonomic();
        } else {
            self.pending.push(Pending::Velocity(m));
        }
    }

    /// A radar frame at `t` \[s\] (IMU clock) that gave no velocity: the vertical velocity bound
    /// ([`RioConfig::vertical_velocity_std`]) is applied at its time, as after a frame's update.
    pub fn push_frame_without_velocity(&mut self, t: f64) {
        if self.started && t <= self.nav.state().t {
            self.bound_velocity(true, false);
            self.nonholonomic();
        } else {
            self.pending.push(Pending::Frame(t));
        }
    }

    /// Vertical velocity bound: when the frame did not see the vertical velocity (`unseen`) or
    /// the filter is uncertain of it by more than [`RioConfig::vertical_velocity_std`],
    /// "vertical velocity 0" with that deviation.
    fn bound_vertical(&mut self, unseen: bool) {
        let std = self.cfg.vertical_velocity_std;
        if !(std.is_finite() && std > 0.0) || !(unseen || self.p[(5, 5)] > std * std) {
            return;
        }
        let mut h = Vn::zeros();
        h[5] = 1.0;
        self.scalar_update(&h, -self.nav.state().v.z, std * std);
        self.counters.vertical_bounds += 1;
    }

    /// The velocity bounds after a radar frame: walking pace (unless the frame's velocity was
    /// just applied, `aided`: the pace would count that update twice), horizontal, then vertical
    /// (`unseen`: the frame did not see the vertical velocity).
    fn bound_velocity(&mut self, unseen: bool, aided: bool) {
        if !aided {
            self.bound_pace();
        }
        self.bound_horizontal();
        self.bound_vertical(unseen);
    }

    /// Walking-pace bound ([`RioConfig::pace_std`]): when the filter is less sure of its
    /// horizontal speed than the bound's deviation and the pace's own, "horizontal speed = the
    /// pace" (the speed it held after its aids) with that deviation, along its own velocity's
    /// direction, heading kept out of the gain as for radar updates. Not for ground vehicles,
    /// nor without a pace (none yet, or forgotten: [`Rio::forget_pace`], a rest), nor below
    /// [`PACE_MIN`], nor when the filter's own horizontal velocity is too small to give a
    /// direction.
    fn bound_pace(&mut self) {
        let std = self.cfg.pace_std;
        let Some((pace, pace_var)) = self.pace else {
            return;
        };
        if !(std.is_finite() && std > 0.0)
            || self.cfg.nonholonomic_std.is_finite()
            || pace < PACE_MIN
        {
            return;
        }
        let (speed, h, var) = self.speed_along_velocity();
        // The pace is as uncertain as the filter's speed was when the radar measured it.
        let r = std * std + pace_var;
        if speed < PACE_DIRECTION_MIN || var <= r {
            return;
        }
        self.scalar_update(&h, pace - speed, r);
        self.counters.pace_bounds += 1;
    }

    /// The horizontal speed \[m/s\], the Jacobian row of the speed (the unit horizontal velocity
    /// on the velocity states; zero below [`PACE_DIRECTION_MIN`]) and the filter's variance of
    /// the speed along it \[m^2/s^2\] (below [`PACE_DIRECTION_MIN`], the mean horizontal
    /// component variance).
    fn speed_along_velocity(&self) -> (f64, Vn, f64) {
        let v = self.nav.state().v;
        let speed = v.xy().norm();
        let mut h = Vn::zeros();
        if speed < PACE_DIRECTION_MIN {
            return (speed, h, 0.5 * (self.p[(3, 3)] + self.p[(4, 4)]));
        }
        h[3] = v.x / speed;
        h[4] = v.y / speed;
        (speed, h, h.dot(&(self.p * h)))
    }

    /// Forgets the pace the walking-pace bound holds ([`RioConfig::pace_std`]) until the next
    /// radar update: the IMU went still where no rest could be declared (a walker who stopped
    /// where the radar sees nothing).
    pub fn forget_pace(&mut self) {
        self.pace = None;
    }

    /// Horizontal velocity bound ([`RioConfig::horizontal_velocity_std`]): each world horizontal
    /// component the filter is less sure of than the bound is taken as 0 with that deviation,
    /// heading kept out of the gain as for radar updates.
    fn bound_horizontal(&mut self) {
        let std = self.cfg.horizontal_velocity_std;
        if !(std.is_finite() && std > 0.0) || self.cfg.nonholonomic_std.is_finite() {
            return;
        }
        let var = std * std;
        let lost = [self.p[(3, 3)] > var, self.p[(4, 4)] > var];
        if !lost.contains(&true) {
            return;
        }
        // Rows for the lost components; a zero row with zero innovation changes nothing.
        let mut h = M3xN::zeros();
        let v = self.nav.state().v;
        let mut y = Vector3::zeros();
        for (k, _) in lost.iter().enumerate().filter(|(_, l)| **l) {
            h[(k, 3 + k)] = 1.0;
            y[k] = -v[k];
        }
        let rm = Matrix3::from_diagonal(&Vector3::new(var, var, 1.0));
        let s = h * self.p * h.transpose() + rm;
        if let Some(si) = s.try_inverse() {
            self.correct(&y, &h, &rm, &si, !self.cfg.radar_heading);
            self.counters.horizontal_bounds += 1;
        }
    }

    /// A scalar measurement: innovation `y`, Jacobian row `h`, variance `r` (Joseph form).
    /// Returns the normalised innovation square. The heading is kept out of the gain as for
    /// radar updates (unless [`RioConfig::radar_heading`]): the vertical velocity bound and the
    /// barometer cannot observe it either, and through their correlations with it they turned
    /// the heading of a far-mounted handheld radar 1-3 deg from the truth in a minute, where the
    /// gyro alone stayed within 0.7 deg (docs/odometry.md, "Heading comes from the gyro").
    fn scalar_update(&mut self, h: &Vn, y: f64, r: f64) -> f64 {
        let ph = self.p * h;
        let s = h.dot(&ph) + r;
        let mut k: Vn = ph / s;
        if !self.cfg.radar_heading {
            keep_heading_out(&mut k, &self.up_in_body());
        }
        let ikh = Mn::identity() - k * h.transpose();
        self.p = ikh * self.p * ikh.transpose() + k * k.transpose() * r;
        self.p = (self.p + self.p.transpose()) * 0.5;
        self.inject(&(k * y));
        y * y / s
    }

    /// A barometric height \[m\] at `t` \[s\] (IMU clock; the altitude of the pressure in the
    /// standard atmosphere, [`pressure_altitude`]): applied when the IMU reaches `t`, at once
    /// if it is already past. The first reading sets the barometer bias (height is relative:
    /// the world origin is where the filter started); later ones aid the height with the bias
    /// as a random-walk state ([`RioConfig::baro_std_m`], [`RioConfig::baro_bias_walk`]).
    pub fn push_height(&mut self, t: f64, height_m: f64) {
        if !height_m.is_finite() {
            self.counters.baro_rejected += 1;
            return;
        }
        if self.started && t <= self.nav.state().t {
            self.height_update(height_m);
        } else {
            self.pending.push(Pending::Height(t, height_m));
        }
    }

    fn height_update(&mut self, height_m: f64) {
        let z = self.nav.state().p.z;
        let Some(bias) = self.baro_bias else {
            // First reading: the bias makes it agree with the filter's height now.
            self.baro_bias = Some(height_m - z);
            self.p[(BARO, BARO)] = self.p[(2, 2)] + self.cfg.baro_std_m * self.cfg.baro_std_m;
            for k in 0..N {
                if k != BARO {
                    self.p[(BARO, k)] = -self.p[(2, k)];
                    self.p[(k, BARO)] = -self.p[(k, 2)];
                }
            }
            return;
        };
        let mut h = Vn::zeros();
        h[2] = 1.0;
        h[BARO] = 1.0;
        let r = self.cfg.baro_std_m * self.cfg.baro_std_m;
        let y = height_m - (z + bias);
        let s = h.dot(&(self.p * h)) + r;
        if y * y / s > GATE_1DOF {
            self.counters.baro_rejected += 1;
            let t = self.nav.state().t;
            let (since, n) = self.baro_rejected_run.get_or_insert((t, 0));
            *n += 1;
            if t - *since < BARO_REANCHOR_S || *n < BARO_REANCHOR_MIN {
                return;
            }
            // Every reading for a second disagreed: the filter's height ran away (a vertical
            // velocity error it was too sure of) and its variance shuts the barometer out for
            // good. Forget the height and vertical velocity, then take this reading.
            self.counters.baro_reanchors += 1;
            self.forget(2, y * y + r);
            self.forget(5, self.cfg.init_velocity_std * self.cfg.init_velocity_std);
        }
        self.baro_rejected_run = None;
        self.scalar_update(&h, y, r);
        self.counters.baro_updates += 1;
    }

    /// Forgets what error-state component `k` was believed to be: its correlations go and its
    /// variance becomes `var` (a re-anchoring).
    fn forget(&mut self, k: usize, var: f64) {
        for j in 0..N {
            self.p[(k, j)] = 0.0;
            self.p[(j, k)] = 0.0;
        }
        self.p[(k, k)] = var;
    }

    fn propagate_cov(&mut self, before: &NavState, s: &ImuSample, dt: f64) {
        let r = before.q.to_rotation_matrix().into_inner();
        let f = Vector3::from(s.accel) - self.nav.accel_bias;
        let w = Vector3::from(s.gyro) - self.nav.gyro_bias;
        let mut fm = Mn::identity();
        let i3 = Matrix3::identity();
        fm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(i3 * dt));
        fm.fixed_view_mut::<3, 3>(3, 6)
            .copy_from(&(-r * f.cross_matrix() * dt));
        fm.fixed_view_mut::<3, 3>(3, 9).copy_from(&(-r * dt));
        fm.fixed_view_mut::<3, 3>(6, 6)
            .copy_from(&(i3 - w.cross_matrix() * dt));
        fm.fixed_view_mut::<3, 3>(6, 12).copy_from(&(-i3 * dt));
        let mut q = Mn::zeros();
        let c = self.cfg;
        for (at, density) in [
            (3, c.accel_noise),
            (6, c.gyro_noise),
            (9, c.accel_bias_walk),
            (12, c.gyro_bias_walk),
        ] {
            for k in at..at + 3 {
                q[(k, k)] = density * density * dt;
            }
        }
        if self.baro_bias.is_some() {
            q[(BARO, BARO)] = c.baro_bias_walk * c.baro_bias_walk * dt;
        }
        // Samples missing before this one: what the straight line between the two samples
        // either side could not see.
        if self.nominal_dt <= 0.0 || dt < self.nominal_dt {
            self.nominal_dt = dt;
        } else if dt < 1.5 * self.nominal_dt {
            self.nominal_dt += 0.05 * (dt - self.nominal_dt);
        } else {
            let missing = dt - self.nominal_dt;
            for k in 3..6 {
                q[(k, k)] += (c.gap_accel_std * missing).powi(2);
            }
        }
        if self.estimates_time_offset() {
            q[(TD, TD)] = c.time_offset_walk * c.time_offset_walk * dt;
        }
        self.p = fm * self.p * fm.transpose() + q;
        self.p = (self.p + self.p.transpose()) * 0.5;
    }

    /// The radar velocity the filter predicts now, in the radar frame \[m/s\], and its covariance
    /// (what [`crate::ego_velocity::EgoVelocityEstimator::estimate_guided`] takes as a prior).
    pub fn predicted_radar_velocity(&self) -> ([f64; 3], [[f64; 3]; 3]) {
        let (pred, h) = self.radar_model();
        let c = h * self.p * h.transpose();
        (
            pred.into(),
            [
                [c[(0, 0)], c[(0, 1)], c[(0, 2)]],
                [c[(1, 0)], c[(1, 1)], c[(1, 2)]],
                [c[(2, 0)], c[(2, 1)], c[(2, 2)]],
            ],
        )
    }

    /// What the measurement-time uncertainty adds to a radar velocity's covariance
    /// ([`RioConfig::time_sigma_s`]).
    fn timing_covariance(&self) -> Matrix3<f64> {
        let ts = self.cfg.time_sigma_s;
        if !(ts.is_finite() && ts > 0.0) {
            return Matrix3::zeros();
        }
        let j = self.velocity_rate();
        j * j.transpose() * (ts * ts)
    }

    /// Rate of change of the predicted radar velocity \[m/s^2, radar frame\].
    fn velocity_rate(&self) -> Vector3<f64> {
        let st = self.nav.state();
        let r_wb = st.q.to_rotation_matrix().into_inner();
        let r_br = self.mount.rotation.to_rotation_matrix().into_inner();
        let w = self.last_gyro - self.nav.gyro_bias;
        let v_b = r_wb.transpose() * st.v;
        let g_b = r_wb.transpose() * Vector3::new(0.0, 0.0, -self.cfg.gravity);
        // d/dt of R_br^T (v_b + w x t): body acceleration minus the rotation of v_b, plus the
        // angular acceleration on the lever arm.
        let a_b = self.last_accel - self.nav.accel_bias + g_b;
        r_br.transpose() * (a_b - w.cross(&v_b) + self.angular_accel.cross(&self.mount.translation))
    }

    /// Predicted radar velocity and its Jacobian with respect to the error state.
    fn radar_model(&self) -> (Vector3<f64>, M3xN) {
        let (pred, mut h) = self.frame_velocity(&self.mount);
        h.fixed_view_mut::<3, 3>(0, RB)
            .copy_from(&Matrix3::identity());
        (pred + self.radar_error, h)
    }

    /// Ground vehicle constraint ([`RioConfig::nonholonomic_std`]): the vehicle frame's lateral
    /// and vertical velocity are zero, gated (2 dof, 99.9%). Heading is kept out of the gain as
    /// for radar updates (body-frame velocity cannot observe it).
    fn nonholonomic(&mut self) {
        let std = self.cfg.nonholonomic_std;
        if !(std.is_finite() && std > 0.0) {
            return;
        }
        let (pred, mut h) = self.frame_velocity(&self.vehicle);
        // Row 0 (forward) is free: a zero row with zero innovation changes nothing.
        h.row_mut(0).fill(0.0);
        let y = Vector3::new(0.0, -pred.y, -pred.z);
        // A slip angle (or a vehicle frame misaligned by it) turns part of the forward speed
        // sideways: the deviation grows with the speed.
        let var = std * std + (self.cfg.nonholonomic_angle * pred.x).powi(2);
        let rm = Matrix3::from_diagonal(&Vector3::new(1.0, var, var));
        let s = h * self.p * h.transpose() + rm;
        let Some(si) = s.try_inverse() else {
            self.counters.nonholonomic_gated += 1;
            return;
        };
        let d2 = (y.transpose() * si * y)[(0, 0)];
        if !(d2.is_finite() && d2 <= GATE_2DOF) {
            self.counters.nonholonomic_gated += 1;
            return;
        }
        self.correct(&y, &h, &rm, &si, !self.cfg.radar_heading);
        self.counters.nonholonomic_updates += 1;
    }

    /// Velocity of a frame fixed on the body (`at`: its rotation and origin in the IMU frame), in
    /// that frame \[m/s\], and its Jacobian with respect to the error state.
    fn frame_velocity(&self, at: &RadarMount) -> (Vector3<f64>, M3xN) {
        let st = self.nav.state();
        let r_wb = st.q.to_rotation_matrix().into_inner();
        let r_br = at.rotation.to_rotation_matrix().into_inner();
        let t_br = at.translation;
        let v_b = r_wb.transpose() * st.v;
        let pred = self.velocity_in(at, &st.v);
        let mut h = M3xN::zeros();
        h.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(r_br.transpose() * r_wb.transpose()));
        h.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(r_br.transpose() * v_b.cross_matrix()));
        h.fixed_view_mut::<3, 3>(0, 12)
            .copy_from(&(r_br.transpose() * t_br.cross_matrix()));
        (pred, h)
    }

    /// The velocity \[m/s\] of a frame fixed on the body (`at`), in that frame, when the body
    /// moves at the world velocity `v` with the current attitude and rate of turn.
    fn velocity_in(&self, at: &RadarMount, v: &Vector3<f64>) -> Vector3<f64> {
        let r_wb = self.nav.state().q.to_rotation_matrix().into_inner();
        let r_br = at.rotation.to_rotation_matrix().into_inner();
        let w = self.last_gyro - self.nav.gyro_bias;
        r_br.transpose() * (r_wb.transpose() * v + w.cross(&at.translation))
    }

    fn update(&mut self, m: &VelocityMeasurement) {
        let applied = self.counters.updates;
        self.update_gated(m, true);
        let aided = self.counters.updates > applied;
        // How well this frame saw the world vertical velocity: its covariance rotated into the
        // world frame.
        let r_wr = (self.nav.state().q * self.mount.rotation)
            .to_rotation_matrix()
            .into_inner();
        let c = r_wr
            * Matrix3::from_fn(|i, j| m.covariance[i][j] * self.noise_scale)
            * r_wr.transpose();
        let std = self.cfg.vertical_velocity_std;
        self.bound_velocity(c[(2, 2)] > std * std, aided);
    }

    fn update_gated(&mut self, m: &VelocityMeasurement, gate: bool) {
        let (mut pred, mut h) = self.radar_model();
        if self.estimates_time_offset() {
            // The measurement was taken at tau = m.t + t_d: move the prediction there, along the
            // recent steps when tau is past (the motion between tau and now is what they did),
            // along the current rate of change when it is ahead.
            let tau = m.t + self.time_offset;
            let now = self.nav.state().t;
            let (shift, rate) = match (tau < now).then(|| self.history.since(tau)).flatten() {
                Some((change, rate)) => (-change, rate),
                None => {
                    let j = self.velocity_rate();
                    (j * (tau - now), j)
                }
            };
            pred += shift;
            h.set_column(TD, &rate);
        }
        let shared = Matrix3::from_fn(|i, j| m.shared_covariance[i][j]);
        let given = if self.cfg.radar_error_state {
            self.carry_radar_error(m, &shared);
            Matrix3::from_fn(|i, j| m.covariance[i][j]) - shared
        } else {
            Matrix3::from_fn(|i, j| m.covariance[i][j])
        };
        let rm = given * self.noise_scale + self.timing_covariance();
        let y = Vector3::from(m.velocity) - pred;
        let s = h * self.p * h.transpose() + rm;
        let Some(si) = s.try_inverse() else {
            self.counters.gated += 1;
            return;
        };
        let d2 = (y.transpose() * si * y)[(0, 0)];
        if gate && !(d2.is_finite() && d2 <= self.cfg.gate) {
            self.counters.gated += 1;
            if m.carried {
                return;
            }
            self.gated_run += 1;
            if self.gated_run < self.cfg.reanchor_after || !d2.is_finite() {
                return;
            }
            // Re-anchor: forget what the velocity was believed to be, then take this measurement.
            self.counters.reanchors += 1;
            self.gated_run = 0;
            // Tilt goes too: a tilt error leaks gravity into the velocity, which is what usually
            // drove the run of rejections.
            let sv = self.cfg.init_velocity_std * self.cfg.init_velocity_std;
            let st = self.cfg.init_tilt_std * self.cfg.init_tilt_std;
            for k in 3..8 {
                self.forget(k, if k < 6 { sv } else { st });
            }
            // Taken without the gate: after a run of rejections the filter, not the radar, is
            // the one to doubt.
            return self.update_gated(m, false);
        }
        self.gated_run = 0;
        if gate {
            self.adapt_noise(&y, &si, &given);
        }
        self.correct(&y, &h, &rm, &si, !self.cfg.radar_heading);
        self.refresh_pace();
        self.counters.updates += 1;
        self.nis_sum += d2;
    }

    /// Carries the shared rounding error to the radar measurement `m` (whose shared covariance
    /// is `shared`): its correlation with the last update's is `exp(-6 |dv| / step) exp(-dt / T)`
    /// ([`RioConfig::radar_error_state`]; `dv` the change of the radar velocity the IMU alone
    /// integrated), and the stationary covariance is this frame's shared covariance (scaled as
    /// the rest of the radar covariance is).
    fn carry_radar_error(&mut self, m: &VelocityMeasurement, shared: &Matrix3<f64>) {
        // The radar velocity the IMU alone carried the state to: the filter's own corrections
        // (which the shared error's decay itself drives) must not count as motion.
        let now = self.velocity_in(&self.mount, &self.imu_velocity());
        let step = m.doppler_step;
        let rho = match self.last_radar {
            Some((t, v)) if step > 0.0 && step.is_finite() => {
                let tau = self.cfg.radar_error_time_s;
                let dt = (m.t - t).abs();
                let time = if tau > 0.0 && tau.is_finite() {
                    (-dt / tau).exp()
                } else {
                    1.0
                };
                (-6.0 * (now - v).norm() / step).exp() * time
            }
            _ => 0.0,
        };
        self.last_radar = Some((m.t, now));
        let rho = if rho.is_finite() {
            rho.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.radar_error *= rho;
        self.p.fixed_rows_mut::<3>(RB).scale_mut(rho);
        self.p.fixed_columns_mut::<3>(RB).scale_mut(rho);
        let mut block = self.p.fixed_view_mut::<3, 3>(RB, RB);
        block += shared * (self.noise_scale * (1.0 - rho * rho));
    }

    /// One step of recursive maximum likelihood for the radar noise scale `alpha`
    /// ([`RioConfig::radar_noise_window`]), in `ln alpha` so that a step means the same at any
    /// scale: with the innovation `y`, its covariance's inverse `si` (`S = H P H^T + alpha C +
    /// timing`) and the given covariance `c`, `B = S^-1 alpha C`; the log-likelihood's slope in
    /// `ln alpha` is `(y^T B S^-1 y - tr B) / 2` and its Fisher information `tr(B^2) / 2` (3/2
    /// for a frame whose innovation the radar's noise dominates, less where the filter's own
    /// uncertainty does, which says little about the radar). The scale moves by the slope over the
    /// information gathered (forgotten by `1 - 1 / window` per update).
    fn adapt_noise(&mut self, y: &Vector3<f64>, si: &Matrix3<f64>, c: &Matrix3<f64>) {
        let n = self.cfg.radar_noise_window;
        if !(n.is_finite() && n >= 1.0) {
            return;
        }
        let b = si * c * self.noise_scale;
        let slope = 0.5 * ((y.transpose() * b * si * y)[(0, 0)] - b.trace());
        let info = 0.5 * (b * b).trace();
        if !(slope.is_finite() && info.is_finite() && info > 0.0) {
            return;
        }
        // The prior: as sure of the given covariance as 20 frames the radar dominates.
        if self.noise_information == 0.0 {
            self.noise_information = 30.0;
        }
        self.noise_information = self.noise_information * (1.0 - 1.0 / n) + info;
        let [lo, hi] = self.cfg.radar_noise_scale_bounds;
        let ln = self.noise_scale.ln() + slope / self.noise_information;
        self.noise_scale = ln.exp().clamp(lo, hi);
    }

    /// The scale the filter applies to the radar velocity covariances (1 unless
    /// [`RioConfig::radar_noise_window`] adapts it).
    pub fn radar_noise_scale(&self) -> f64 {
        self.noise_scale
    }

    /// Normalised innovation square of a world-velocity innovation `y` \[m/s\] with measurement
    /// covariance `rm` (Jacobian: identity on the velocity error), `None` when its innovation
    /// covariance is singular ([`crate::learned`]).
    pub fn world_velocity_nis(&self, y: &Vector3<f64>, rm: &Matrix3<f64>) -> Option<f64> {
        let s = self.p.fixed_view::<3, 3>(3, 3) + rm;
        let si = s.try_inverse()?;
        let d2 = (y.transpose() * si * y)[(0, 0)];
        d2.is_finite().then_some(d2)
    }

    /// Applies a world-velocity innovation `y` \[m/s\] with covariance `rm` (heading kept out of
    /// the gain unless [`RioConfig::radar_heading`]); see [`crate::learned`].
    pub fn world_velocity_update(&mut self, y: &Vector3<f64>, rm: &Matrix3<f64>) {
        let mut h = M3xN::zeros();
        h.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        let s = h * self.p * h.transpose() + rm;
        if let Some(si) = s.try_inverse() {
            self.correct(y, &h, rm, &si, !self.cfg.radar_heading);
            self.refresh_pace();
        }
    }

    /// After an aid (a radar update, a learned velocity): the pace the walking-pace bound holds
    /// ([`RioConfig::pace_std`]) takes the speed the filter holds now, and its variance.
    fn refresh_pace(&mut self) {
        let t = self.nav.state().t;
        let (speed, _, var) = self.speed_along_velocity();
        let a = self.pace.map_or(1.0, |_| {
            1.0 - (-(t - self.pace_t).max(0.0) / PACE_TAU_S).exp()
        });
        let (p, pv) = self.pace.unwrap_or((speed, var));
        self.pace = Some((p + a * (speed - p), pv + a * (var - pv)));
        self.pace_t = t;
    }

    /// Zero-velocity pseudo-measurement: the body is at rest, its world velocity zero with
    /// standard deviation `std` \[m/s\] per axis (see [`crate::rest`]). A world velocity cannot
    /// observe heading (rotating the state about the vertical leaves zero zero), so, as for the
    /// radar updates, its gain leaves the heading alone unless [`RioConfig::radar_heading`].
    pub fn zero_velocity(&mut self, std: f64) {
        self.pace = None;
        let mut h = M3xN::zeros();
        h.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        let y = -self.nav.state().v;
        self.pseudo(&y, &h, std, !self.cfg.radar_heading);
    }

    /// Whether the filter's velocity is consistent with rest: zero within its covariance plus
    /// `std` \[m/s\] per axis, by the chi-square gate ([`RioConfig::gate`]).
    pub fn at_rest_consistent(&self, std: f64) -> bool {
        let v = self.nav.state().v;
        let s = self.p.fixed_view::<3, 3>(3, 3) + Matrix3::identity() * (std * std);
        s.try_inverse()
            .is_some_and(|si| (v.transpose() * si * v)[(0, 0)] <= self.cfg.gate)
    }

    /// Position-hold pseudo-measurement: at rest the position is `anchor` \[m\] (where the rest
    /// began) with standard deviation `std` \[m\] per axis; heading kept out of the gain as for
    /// [`Rio::zero_velocity`].
    pub fn hold_position(&mut self, anchor: Vector3<f64>, std: f64) {
        let mut h = M3xN::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&Matrix3::identity());
        let y = anchor - self.nav.state().p;
        self.pseudo(&y, &h, std, !self.cfg.radar_heading);
    }

    /// Zero-rate pseudo-measurement: at rest the true rate of turn is zero, so the mean measured
    /// rate `mean_gyro` \[rad/s\] over `span_s` \[s\] is the gyroscope bias plus white noise of
    /// variance `gyro_noise^2 / span_s` (floored at `std_min` \[rad/s\]).
    pub fn zero_rate(&mut self, mean_gyro: Vector3<f64>, span_s: f64, std_min: f64) {
        let mut h = M3xN::zeros();
        h.fixed_view_mut::<3, 3>(0, 12)
            .copy_from(&Matrix3::identity());
        let y = mean_gyro - self.nav.gyro_bias;
        let white = self.cfg.gyro_noise / span_s.max(1e-3).sqrt();
        self.pseudo(&y, &h, white.max(std_min), false);
    }

    /// A rest pseudo-measurement `y` (Jacobian `h`, deviation `std` per axis); `keep_heading`
    /// as in [`Rio::correct`].
    fn pseudo(&mut self, y: &Vector3<f64>, h: &M3xN, std: f64, keep_heading: bool) {
        let rm = Matrix3::identity() * (std * std);
        let s = h * self.p * h.transpose() + rm;
        if let Some(si) = s.try_inverse() {
            self.correct(y, h, &rm, &si, keep_heading);
            self.counters.rest_updates += 1;
        }
    }

    /// The Kalman correction with innovation `y`, Jacobian `h`, measurement covariance `rm` and
    /// inverse innovation covariance `si` (Joseph form), folded into the nominal state.
    /// `keep_heading`: the gain leaves the world yaw and the gyroscope bias about the world
    /// vertical alone (see [`RioConfig::radar_heading`]).
    fn correct(
        &mut self,
        y: &Vector3<f64>,
        h: &M3xN,
        rm: &Matrix3<f64>,
        si: &Matrix3<f64>,
        keep_heading: bool,
    ) {
        let mut k = self.p * h.transpose() * si;
        if keep_heading {
            let up = self.up_in_body();
            for mut column in k.column_iter_mut() {
                keep_heading_out(&mut column, &up);
            }
        }
        let dx: Vn = k * y;
        let ikh = Mn::identity() - k * h;
        self.p = ikh * self.p * ikh.transpose() + k * rm * k.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        self.inject(&dx);
    }

    /// The world vertical in the body frame.
    fn up_in_body(&self) -> Vector3<f64> {
        self.nav.state().q.inverse() * Vector3::z()
    }

    /// Folds an error-state correction into the nominal state.
    fn inject(&mut self, dx: &Vn) {
        let mut ns = *self.nav.state();
        ns.p += dx.fixed_rows::<3>(0);
        ns.v += dx.fixed_rows::<3>(3);
        self.velocity_corrections += dx.fixed_rows::<3>(3);
        ns.q *= UnitQuaternion::from_scaled_axis(dx.fixed_rows::<3>(6).into_owned());
        self.nav.accel_bias += dx.fixed_rows::<3>(9);
        self.nav.gyro_bias += dx.fixed_rows::<3>(12);
        if let Some(b) = self.baro_bias.as_mut() {
            *b += dx[BARO];
        }
        // Beyond half a second the clock mapping is broken, not offset: held at the bound.
        self.time_offset = (self.time_offset + dx[TD]).clamp(-MAX_TIME_OFFSET_S, MAX_TIME_OFFSET_S);
        self.radar_error += dx.fixed_rows::<3>(RB);
        self.nav.set_state(ns);
    }
}

/// Projects the world vertical `up` (in the body frame) out of the attitude and gyro-bias rows
/// of one gain column: the correction leaves the world yaw and the gyroscope bias about the world
/// vertical alone. Any gain is consistent under the Joseph form.
fn keep_heading_out<S>(
    k: &mut nalgebra::Matrix<f64, nalgebra::Const<N>, nalgebra::U1, S>,
    up: &Vector3<f64>,
) where
    S: nalgebra::storage::StorageMut<f64, nalgebra::Const<N>, nalgebra::U1>,
{
    for at in [6, 12] {
        let along = k.fixed_rows::<3>(at).dot(up);
        let rows = k.fixed_rows::<3>(at) - up * along;
        k.fixed_rows_mut::<3>(at).copy_from(&rows);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_names_pick_their_preset_and_only_the_noise_changes() {
        for (device, want) in [
            ("MTi-1 (simulated)", Some(ImuNoise::Mti1)),
            ("MTi-3", Some(ImuNoise::Mti1)),
            ("MTi-8 RTK", Some(ImuNoise::Mti1)),
            ("MTi-630 (simulated)", Some(ImuNoise::Mti600)),
            ("Xsens MTi-680G", Some(ImuNoise::Mti600)),
            (
                "BMI088-class MEMS IMU (simulated, MTData2 stream)",
                Some(ImuNoise::Mems),
            ),
            ("TDK ICM-42688-P", Some(ImuNoise::Mems)),
            ("MTi-100", None),
            ("MTi-30 AHRS", None),
            ("MTi-G-710", None),
            ("unknown", None),
        ] {
            assert_eq!(ImuNoise::from_device(device), want, "{device}");
        }
        for n in ImuNoise::ALL {
            assert_eq!(n.name().parse::<ImuNoise>(), Ok(n));
        }
        assert!("mti100".parse::<ImuNoise>().is_err());
        let mine = RioConfig {
            gate: 9.0,
            baro_std_m: 0.7,
            ..RioConfig::default()
        };
        assert_eq!(
            mine.with_imu_noise(ImuNoise::Mti1),
            RioConfig {
                init_gyro_bias_std: XSENS_GYRO_TURN_ON_STD,
                ..mine
            },
            "MTi-1 is the default but for the gyro turn-on bias of a named part"
        );
        assert_eq!(
            mine.with_imu_noise(ImuNoise::Mti600).init_gyro_bias_std,
            XSENS_GYRO_TURN_ON_STD
        );
        assert!(XSENS_GYRO_TURN_ON_STD < 0.2 * mine.init_gyro_bias_std);
        let mems = mine.with_imu_noise(ImuNoise::Mems);
        assert!(mems.gyro_noise > 1.9 * mine.gyro_noise && mems.init_accel_bias_std == 0.1);
        assert_eq!(mems.init_gyro_bias_std, mine.init_gyro_bias_std);
        assert_eq!(
            (mems.gate, mems.baro_std_m),
            (9.0, 0.7),
            "nothing but the noise changes"
        );
        assert!(mine.with_imu_noise(ImuNoise::Mti600).accel_noise < mine.accel_noise);
    }
}
