//! Strapdown IMU integration: orientation, velocity and position from specific force and rate of
//! turn. Dead reckoning uses it alone (the weakest baseline); the radar-inertial filter uses it as
//! its propagation step, so both integrate the same way.
//!
//! Conventions: the body frame is the IMU sensor frame; the world frame is z-up with gravity
//! `[0, 0, -g]`; `q` rotates body vectors into the world frame. An accelerometer at rest, level,
//! reads `[0, 0, +g]` (specific force).

use nalgebra::{UnitQuaternion, Vector3};

/// Standard gravity \[m/s^2\].
pub const STANDARD_GRAVITY: f64 = 9.806_65;

/// One IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Sensor time \[s\].
    pub t: f64,
    /// Specific force in the body frame \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn in the body frame \[rad/s\].
    pub gyro: [f64; 3],
}

/// Navigation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Time \[s\].
    pub t: f64,
    /// Body-to-world rotation.
    pub q: UnitQuaternion<f64>,
    /// Velocity in the world frame \[m/s\].
    pub v: Vector3<f64>,
    /// Position in the world frame \[m\].
    pub p: Vector3<f64>,
}

impl NavState {
    /// At rest at the origin, level, at time `t`.
    pub fn at_rest(t: f64) -> NavState {
        NavState {
            t,
            q: UnitQuaternion::identity(),
            v: Vector3::zeros(),
            p: Vector3::zeros(),
        }
    }
}

/// The integrator.
#[derive(Debug, Clone)]
pub struct Strapdown {
    state: NavState,
    gravity: Vector3<f64>,
    /// Accelerometer bias subtracted from every sample \[m/s^2\].
    pub accel_bias: Vector3<f64>,
    /// Gyroscope bias subtracted from every sample \[rad/s\].
    pub gyro_bias: Vector3<f64>,
    last: Option<ImuSample>,
    /// Samples refused because time did not advance.
    pub rejected: u64,
}

impl Strapdown {
    /// Starts from `state` with gravity of magnitude `g` \[m/s^2\] along world -z.
    pub fn new(state: NavState, g: f64) -> Strapdown {
        Strapdown {
            state,
            gravity: Vector3::new(0.0, 0.0, -g),
            accel_bias: Vector3::zeros(),
            gyro_bias: Vector3::zeros(),
            last: None,
            rejected: 0,
        }
    }

    /// The current state.
    pub fn state(&self) -> &NavState {
        &self.state
    }

    /// Replaces the state (a filter update); keeps the last sample for the next step.
    pub fn set_state(&mut self, s: NavState) {
        self.state = s;
    }

    /// Integrates up to sample `s` (the first sample only sets the time). Samples whose time does
    /// not advance are counted in `rejected` and ignored.
    pub fn push(&mut self, s: ImuSample) -> &NavState {
        let Some(prev) = self.last else {
            self.last = Some(s);
            self.state.t = s.t;
            return &self.state;
        };
        let dt = s.t - prev.t;
        if !(dt > 0.0 && dt.is_finite()) {
            self.rejected += 1;
            return &self.state;
        }
        let w0 = Vector3::from(prev.gyro) - self.gyro_bias;
        let w1 = Vector3::from(s.gyro) - self.gyro_bias;
        let f0 = Vector3::from(prev.accel) - self.accel_bias;
        let f1 = Vector3::from(s.accel) - self.accel_bias;
        let q0 = self.state.q;
        // Rotation over the step with the mean rate (second order for linear rate changes).
        let q1 = q0 * UnitQuaternion::from_scaled_axis((w0 + w1) * 0.5 * dt);
        let a0 = q0 * f0 + self.gravity;
        let a1 = q1 * f1 + self.gravity;
        let a = (a0 + a1) * 0.5;
        self.state.p += self.state.v * dt + a0 * (dt * dt / 3.0) + a1 * (dt * dt / 6.0);
        self.state.v += a * dt;
        self.state.q = q1;
        self.state.t = s.t;
        self.last = Some(s);
        &self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(samples: impl Iterator<Item = ImuSample>) -> NavState {
        let mut s = Strapdown::new(NavState::at_rest(0.0), STANDARD_GRAVITY);
        for x in samples {
            s.push(x);
        }
        *s.state()
    }

    #[test]
    fn at_rest_stays_at_rest() {
        let st = run((0..=1000).map(|i| ImuSample {
            t: i as f64 * 0.005,
            accel: [0.0, 0.0, STANDARD_GRAVITY],
            gyro: [0.0; 3],
        }));
        assert!(st.p.norm() < 1e-12 && st.v.norm() < 1e-12, "{st:?}");
        assert!((st.t - 5.0).abs() < 1e-12);
    }

    #[test]
    fn constant_acceleration_gives_half_a_t_squared() {
        let st = run((0..=200).map(|i| ImuSample {
            t: i as f64 * 0.01,
            accel: [0.5, 0.0, STANDARD_GRAVITY],
            gyro: [0.0; 3],
        }));
        assert!((st.p.x - 0.5 * 0.5 * 4.0).abs() < 1e-9, "{}", st.p.x);
        assert!((st.v.x - 1.0).abs() < 1e-9);
    }

    #[test]
    fn constant_yaw_rate_turns_by_rate_times_time() {
        let st = run((0..=100).map(|i| ImuSample {
            t: i as f64 * 0.01,
            accel: [0.0, 0.0, STANDARD_GRAVITY],
            gyro: [0.0, 0.0, 0.3],
        }));
        let (_, _, yaw) = st.q.euler_angles();
        assert!((yaw - 0.3).abs() < 1e-9, "{yaw}");
        assert!(st.p.norm() < 1e-9);
    }

    #[test]
    fn circular_motion_closes_the_circle() {
        // Body x forward at speed u, yaw rate w: centripetal specific force u*w along body y.
        let (u, w, dt) = (1.0, 0.5, 0.001);
        let n = (2.0 * std::f64::consts::PI / w / dt).round() as usize;
        let mut s = Strapdown::new(
            NavState {
                v: Vector3::new(u, 0.0, 0.0),
                ..NavState::at_rest(0.0)
            },
            STANDARD_GRAVITY,
        );
        for i in 0..=n {
            s.push(ImuSample {
                t: i as f64 * dt,
                accel: [0.0, u * w, STANDARD_GRAVITY],
                gyro: [0.0, 0.0, w],
            });
        }
        assert!(
            s.state().p.norm() < 1e-3,
            "after one turn the body is back: {:?}",
            s.state().p
        );
    }

    #[test]
    fn non_advancing_samples_are_counted_and_ignored() {
        let mut s = Strapdown::new(NavState::at_rest(0.0), STANDARD_GRAVITY);
        let x = ImuSample {
            t: 1.0,
            accel: [1.0, 0.0, 9.8],
            gyro: [0.0; 3],
        };
        s.push(x);
        s.push(x);
        s.push(ImuSample { t: 0.5, ..x });
        assert_eq!(s.rejected, 2);
    }
}
