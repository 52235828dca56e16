//! The estimator interface (this module: inputs, outputs, errors, the [`Estimator`] trait) and the
//! estimators behind it, each a thin adapter over the one streaming implementation of its stage:
//!
//! * [`classical`]: `doppler` (radar ego-velocity fused with the IMU) and `imu` (the same
//!   integration, no radar updates) over [`milliego_odometry::runner::Runner`], the loop
//!   `milliego odometry` runs offline;
//! * [`fused`]: the Doppler filter with the learned model's relative motion as a measurement
//!   (`auto` when a model is given, with its online consistency check; `fused` without it);
//! * [`model`]: the learned model over [`milliego_models::chain::KeyframeChain`], the chain
//!   `milliego score` runs offline;
//! * [`factory`]: the one place estimators are built ([`build_estimator`],
//!   [`build_run_estimators`]).
//!
//! The adapters depend on this module, never on each other.

pub mod classical;
pub mod factory;
pub mod fused;
pub mod model;

pub use classical::Classical;
pub use factory::{build_estimator, build_run_estimators, BuildError, Built, ModelSource};
pub use fused::Fused;
pub use milliego_odometry::runner::{ClassicalConfig, Mounting};
pub use model::ModelEstimator;

use nalgebra::{Isometry3, Vector3};

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
    /// A barometer reading just before this sample: its time on the common clock \[s\] and
    /// pressure \[Pa\].
    pub pressure: Option<(f64, f64)>,
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
    /// The learned model's output for a window is not a finite pose.
    BadOutput {
        /// Frame number of the window's current frame.
        frame: u32,
        /// Its time \[s\].
        t: f64,
        /// The output `[tx, ty, tz [m], roll, pitch, yaw [deg]]`.
        output: [f32; 6],
    },
}

impl std::fmt::Display for EstimatorError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EstimatorError::Unhealthy(why) => write!(f, "estimator unhealthy: {why}"),
            EstimatorError::BadOutput { frame, t, output } => write!(
                f,
                "model output for frame {frame} at {t:.3} s is not a finite pose: {output:?}"
            ),
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
    /// The radar-to-IMU time offset the estimator estimated and its standard deviation \[s\],
    /// when it estimates one.
    fn radar_time_offset(&self) -> Option<(f64, f64)> {
        None
    }
    /// The Doppler quantisation step \[m/s\] the estimator configured and the one the points
    /// showed ([`milliego_odometry::runner::Runner::doppler_step`]), when it uses the radar's
    /// Doppler.
    fn doppler_step(&self) -> Option<(f32, Option<f32>)> {
        None
    }
    /// What became of the learned model's measurements (the fused estimator only).
    fn learned(&self) -> Option<crate::summary::LearnedSummary> {
        None
    }
    /// What the Doppler filter did with its measurements, when the estimator runs one.
    fn filter(&self) -> Option<crate::summary::FilterSummary> {
        None
    }
    /// When the estimator last took a velocity aid (radar velocity, rest, learned measurement)
    /// \[s, the input clock\], for an estimator that integrates the IMU between aids
    /// ([`milliego_odometry::runner::Runner::last_aid_s`]); None otherwise (the model alone).
    /// A pose at `t` more than [`milliego_odometry::runner::UNAIDED_AFTER_S`] after it is
    /// flagged `DEAD_RECKONING`.
    fn last_aid_s(&self) -> Option<f64> {
        None
    }
}

/// Which estimator a run uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EstimatorKind {
    /// The learned milliEgo model alone (the paper's network).
    Model,
    /// The Doppler filter with the learned model's relative motion as a gated measurement,
    /// every one that passes its gate applied.
    Fused,
    /// Doppler radar-inertial odometry.
    Doppler,
    /// IMU dead reckoning.
    Imu,
    /// With a model: the fused estimator until its learned measurements fail the online
    /// consistency check, then Doppler (hand-over); without one: Doppler. IMU propagation while
    /// radar is missing.
    Auto,
}

impl EstimatorKind {
    /// Lowercase name.
    pub fn name(self) -> &'static str {
        match self {
            EstimatorKind::Model => "model",
            EstimatorKind::Fused => "fused",
            EstimatorKind::Doppler => "doppler",
            EstimatorKind::Imu => "imu",
            EstimatorKind::Auto => "auto",
        }
    }
}
