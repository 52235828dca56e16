//! Classical radar-inertial odometry: the honest baseline beside the learned model, and the
//! fallback that keeps the pose stream alive when the model is missing, unhealthy or too slow.
//!
//! * [`ego_velocity`]: the sensor's velocity from one radar frame's (direction, radial velocity)
//!   pairs, with RANSAC against moving objects and multipath, a least-squares refinement, a
//!   covariance, and degenerate geometry reported rather than silently wrong.
//! * [`lattice`]: the Doppler quantisation step read from the radial velocities themselves.
//! * [`leakage`]: near-field leakage (returns near the radar at zero Doppler whatever the motion)
//!   read from the points and the filter's prediction.
//! * [`rio`]: the error-state Kalman filter that fuses both (IMU propagation, radar velocity
//!   updates, bias estimation, chi-square gating).
//! * [`learned`]: the learned model's relative motion as a filter measurement, and the online
//!   consistency check that decides whether it is applied.
//! * [`persist`]: which radar points were seen again in the last frames (a static reflector is, a
//!   false alarm is not): their weights in the ego-velocity consensus.
//! * [`rest`]: rest detection from the IMU and the radar's Doppler together, and the zero-velocity
//!   / zero-rate updates taken at rest.
//! * [`runner`]: the streaming loop over both (levelling, priors, the health rule, updates, IMU
//!   gaps), one IMU sample or radar frame at a time; the offline runner ([`offline`]) and the
//!   runtime's classical estimators are loops over it.
//! * [`strapdown`]: IMU integration (orientation, velocity, position) used for dead reckoning and,
//!   later, for the filter's propagation step.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod ego_velocity;
pub mod lattice;
pub mod leakage;
pub mod learned;
pub mod offline;
pub mod persist;
pub mod rest;
pub mod rio;
pub mod runner;
pub mod strapdown;
