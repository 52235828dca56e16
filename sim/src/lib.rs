//! The milliEgo radar-inertial scenario simulator.
//!
//! Data flow, one module per stage:
//!
//! 1. [`world`]: a procedural indoor floor (or an open outdoor plaza) of a named
//!    [`Family`](world::Family), deterministic from (family, seed): walls, floor, ceiling,
//!    pillars, furniture, glass, edge scatterers.
//! 2. [`motion`]: a smooth body [`Trajectory`](motion::Trajectory) through its free space (ground
//!    robot, walking person, car).
//! 3. [`radar`]: an AWR1843-like radar: sparse point clouds with ~75 % outliers, Doppler from the
//!    true motion; encoded as the TI out-of-box demo's UART frames, with the matching `.cfg`.
//! 4. [`imu`]: an MTi-1-like IMU with datasheet noise (other grades as presets), encoded as
//!    MTData2 messages, and an optional barometer in the same stream.
//! 5. [`clock`]: each sensor's clock (offset, drift) and its UART (baud, host read chunks).
//! 6. [`scenario`]: all of the above written as a milliEgo session with ground truth.
//! 7. [`split`]: the benchmark's train / validation / held-out test scenarios.
//!
//! Same scenario and seed, same bytes: every random draw comes from a ChaCha8 stream seeded
//! from the scenario seed and a purpose label ([`rng`]). The model assumptions and their
//! sources are in `docs/simulator.md`, which also lists the failure-mode settings of
//! [`Scenario`](scenario::Scenario) (radar mounts, coarse Doppler, near-field leakage, IMU
//! grades and gaps, barometer, vehicle and height-change motion); at their defaults the output
//! is unchanged.
//!
//! ```no_run
//! use milliego_sim::{scenario::{run, Scenario}, world::Family, motion::MotionKind};
//! let sc = Scenario::new(Family::Office, MotionKind::Handheld, 7);
//! let summary = run(&sc, std::path::Path::new("/tmp/office-7"), &mut |_| {}).unwrap();
//! println!("{} frames, {:.1} points per frame", summary.frames, summary.points_mean());
//! ```
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod clock;
pub mod imu;
pub mod motion;
pub mod radar;
pub mod rng;
pub mod scenario;
pub mod split;
pub mod world;

use std::fmt;

/// Why a simulation could not run, naming the setting or file concerned.
#[derive(Debug)]
pub enum SimError {
    /// A setting is out of range (which and why).
    Config(String),
    /// The world has no room for the requested motion.
    World(String),
    /// Writing the session failed.
    Session(milliego_session::SessionError),
    /// Writing a side file failed (path and cause).
    Io(String),
}

impl fmt::Display for SimError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SimError::Config(m) => write!(f, "bad scenario: {m}"),
            SimError::World(m) => write!(f, "world: {m}"),
            SimError::Session(e) => write!(f, "session: {e}"),
            SimError::Io(m) => write!(f, "{m}"),
        }
    }
}

impl std::error::Error for SimError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SimError::Session(e) => Some(e),
            _ => None,
        }
    }
}

impl From<milliego_session::SessionError> for SimError {
    fn from(e: milliego_session::SessionError) -> SimError {
        SimError::Session(e)
    }
}
