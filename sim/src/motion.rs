//! Motion: smooth body trajectories through a world's free space.
//!
//! The path is a uniform cubic B-spline (C2: position, velocity and acceleration are continuous)
//! through control points laid by a random walk that keeps clear of obstacles. Orientation is an
//! analytic function of time (heading from the path tangent, plus sinusoidal head and hand
//! motion for walkers), so every derivative the IMU needs is well defined. Body frame: x forward,
//! y left, z up.

use crate::rng::SimRng;
use crate::world::World;
use crate::SimError;
use nalgebra::{UnitQuaternion, Vector3};
use std::f64::consts::{PI, TAU};
use std::fmt;
use std::str::FromStr;

/// How the sensor rig moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MotionKind {
    /// Ground robot: planar, 0.2-0.6 m/s, smooth turns, sensors 0.25 m above the floor.
    Robot,
    /// Handheld rig, walking 1.0-1.5 m/s: ~2 Hz step bob, hand sway, free 3D rotation.
    Handheld,
    /// Head-worn rig, walking 1.0-1.5 m/s: step bob and larger looking-around rotations.
    Headworn,
    /// At rest on a tilted mount (IMU calibration and noise statistics).
    Static,
    /// Ground vehicle (car-like): non-holonomic, no side slip, 3-12 m/s, smooth turns, flat;
    /// outdoors only.
    Vehicle,
}

impl MotionKind {
    /// All kinds.
    pub const ALL: [MotionKind; 5] = [
        MotionKind::Robot,
        MotionKind::Handheld,
        MotionKind::Headworn,
        MotionKind::Static,
        MotionKind::Vehicle,
    ];

    /// Name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MotionKind::Robot => "robot",
            MotionKind::Handheld => "handheld",
            MotionKind::Headworn => "headworn",
            MotionKind::Static => "static",
            MotionKind::Vehicle => "vehicle",
        }
    }

    /// Nominal speed range \[m/s\].
    pub fn speed_range(self) -> (f64, f64) {
        match self {
            MotionKind::Robot => (0.2, 0.6),
            MotionKind::Handheld | MotionKind::Headworn => (1.0, 1.5),
            MotionKind::Static => (0.0, 0.0),
            MotionKind::Vehicle => (3.0, 12.0),
        }
    }
}

impl fmt::Display for MotionKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for MotionKind {
    type Err = String;
    fn from_str(s: &str) -> Result<MotionKind, String> {
        MotionKind::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown motion {s:?} (expected robot, handheld, headworn, static or vehicle)"
                )
            })
    }
}

/// A body pose in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Position \[m\].
    pub p: Vector3<f64>,
    /// Orientation (body to world).
    pub q: UnitQuaternion<f64>,
}

impl Pose {
    /// Composes this body pose with a sensor's pose in the body (`p_body = r t_sensor + t`).
    pub fn compose(&self, t: &Vector3<f64>, r: &UnitQuaternion<f64>) -> Pose {
        Pose {
            p: self.p + self.q * t,
            q: self.q * r,
        }
    }
}

/// One sinusoid: amplitude, frequency \[Hz\], phase \[rad\].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Wave {
    a: f64,
    f: f64,
    ph: f64,
}

impl Wave {
    fn at(&self, t: f64) -> f64 {
        self.a * (TAU * self.f * t + self.ph).sin()
    }
}

/// A body trajectory, defined for all t \[s\] (host clock) from 0 to its end.
#[derive(Debug, Clone)]
pub struct Trajectory {
    /// Kind of motion.
    pub kind: MotionKind,
    ctrl: Vec<[f64; 2]>,
    knot_s: f64,
    height: f64,
    /// Step frequency \[Hz\] (walkers).
    pub step_hz: f64,
    bob_m: f64,
    sway_m: f64,
    yaw: [Wave; 2],
    pitch: [Wave; 2],
    roll: [Wave; 2],
    static_q: UnitQuaternion<f64>,
    rest: Option<Rest>,
    climb: Option<Climb>,
}

/// A height change over the motion: z rises by `h` along a quintic smoothstep of motion time
/// over `span_s` (starting `h` up when `h` is negative, so the walk descends to its base height).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Climb {
    h: f64,
    span_s: f64,
}

impl Climb {
    fn dz(&self, t: f64) -> f64 {
        let u = (t / self.span_s).clamp(0.0, 1.0);
        let s = u * u * u * (u * (6.0 * u - 15.0) + 10.0);
        (-self.h).max(0.0) + self.h * s
    }
}

/// Rest at the start and at the end of a trajectory: motion time stands still, then ramps up
/// (and at the end down) over [`REST_RAMP_S`] with a quintic smoothstep of the time rate, so
/// velocity, acceleration and their derivative stay continuous.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rest {
    /// Motion starts here \[s\].
    start_s: f64,
    /// Motion has stopped here \[s\] (`f64::INFINITY`: never).
    stop_s: f64,
}

/// Time over which motion starts after (and stops before) a rest \[s\].
pub const REST_RAMP_S: f64 = 1.5;

/// `int_0^x (6u^5 - 15u^4 + 10u^3) du`, the motion time gained over a ramp of unit length.
fn ramp_integral(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x.powi(4) * (x * x - 3.0 * x + 2.5)
}

impl Rest {
    /// Motion time at host time `t` \[s\].
    fn warp(&self, t: f64) -> f64 {
        let l = REST_RAMP_S;
        let moving = |t: f64| {
            let u = t - self.start_s;
            if u <= 0.0 {
                0.0
            } else if u < l {
                l * ramp_integral(u / l)
            } else {
                0.5 * l + (u - l)
            }
        };
        let slow = self.stop_s - l;
        if t <= slow {
            return moving(t);
        }
        let base = moving(slow);
        let x = ((self.stop_s - t) / l).max(0.0);
        base + l * (0.5 - ramp_integral(x))
    }
}

/// Largest heading change between two control points \[rad\].
const MAX_TURN: f64 = 1.2;
/// Headings tried on each side up to [`MAX_TURN`].
const TURN_STEPS: u32 = 12;

/// Clearance kept from obstacles by the path's control points \[m\].
pub const CLEARANCE_M: f64 = 0.6;
/// Clearance a vehicle's path keeps \[m\] (half a car's width and a margin).
pub const VEHICLE_CLEARANCE_M: f64 = 3.0;
/// Largest heading change of a vehicle between two control points (1 s apart) \[rad\].
const VEHICLE_MAX_TURN: f64 = 0.5;

/// How far ahead a vehicle looks for free road \[m\] (at least; more at speed).
const VEHICLE_LOOK_M: f64 = 25.0;

/// One 1 s knot of a car: find the free direction closest to the current heading (looking
/// [`VEHICLE_LOOK_M`] or 3 s ahead, whichever is farther, all around), turn towards it by at
/// most [`VEHICLE_MAX_TURN`], and slow down to the lowest speed in proportion to how sharp the
/// turn is (so the turn radius stays a car's). None when nothing nearby is free.
fn vehicle_step(
    world: &World,
    p: [f64; 2],
    heading: &mut f64,
    speed: &mut f64,
    (vmin, vmax): (f64, f64),
) -> Option<[f64; 2]> {
    let look = VEHICLE_LOOK_M.max(3.0 * *speed);
    let n: u32 = 36;
    let target = (0..=n).find_map(|k| {
        let side = if k % 2 == 0 { 1.0 } else { -1.0 };
        let psi = *heading + side * f64::from(k.div_ceil(2)) * PI / f64::from(n / 2);
        let far = [p[0] + look * psi.cos(), p[1] + look * psi.sin()];
        world
            .path_free(p, far, VEHICLE_CLEARANCE_M)
            .then_some(psi - *heading)
    })?;
    let turn = target.clamp(-VEHICLE_MAX_TURN, VEHICLE_MAX_TURN);
    // Back towards a cruising speed of 3/4 of the top speed after slowing down.
    *speed += 0.3 * (0.75 * vmax - *speed);
    // Sharp turns at the lowest speed; straight on, the drawn speed.
    let sharp = (turn.abs() / VEHICLE_MAX_TURN).min(1.0);
    *speed = (*speed * (1.0 - sharp) + vmin * sharp).clamp(vmin, vmax);
    let psi = *heading + turn;
    let q = [p[0] + *speed * psi.cos(), p[1] + *speed * psi.sin()];
    if !world.path_free(p, q, 0.5 * VEHICLE_CLEARANCE_M) {
        return None;
    }
    *heading = psi;
    Some(q)
}

impl Trajectory {
    /// Lays a trajectory of `duration_s` \[s\] (plus a margin) through `world`, from `seed`.
    pub fn generate(
        kind: MotionKind,
        world: &World,
        seed: u64,
        duration_s: f64,
    ) -> Result<Trajectory, SimError> {
        let mut rng = SimRng::new(seed, &format!("motion/{}", kind.name()));
        let vehicle = kind == MotionKind::Vehicle;
        // A car keeps more room, looks a knot ahead and turns less per knot.
        let clearance = if vehicle {
            VEHICLE_CLEARANCE_M
        } else {
            CLEARANCE_M
        };
        let max_turn = if vehicle { VEHICLE_MAX_TURN } else { MAX_TURN };
        let start = world.free_point(&mut rng, clearance + 0.3)?;
        let (vmin, vmax) = kind.speed_range();
        let knot_s = match kind {
            MotionKind::Robot | MotionKind::Vehicle => 1.0,
            _ => 0.5,
        };
        let n = ((duration_s + 10.0) / knot_s).ceil() as usize + 6;
        let mut ctrl = vec![start];
        if kind != MotionKind::Static {
            let mut heading = rng.uniform(-PI, PI);
            let mut speed = rng.uniform(vmin, vmax);
            let turn_sigma: f64 = match kind {
                MotionKind::Robot => 0.25,
                MotionKind::Vehicle => 0.1,
                _ => 0.2,
            };
            let mut p = start;
            while ctrl.len() < n {
                speed = (speed + 0.08 * (vmax - vmin) * rng.normal()).clamp(vmin, vmax);
                heading += turn_sigma * rng.normal();
                if vehicle {
                    if let Some(q) = vehicle_step(world, p, &mut heading, &mut speed, (vmin, vmax))
                    {
                        ctrl.push(q);
                        p = q;
                        continue;
                    }
                }
                let step = speed * knot_s;
                let look0 = if vehicle { 3.0 * step } else { 1.0 };
                // Prefer the drawn heading, then ever larger turns to either side (at most
                // MAX_TURN per knot, so the path never reverses on the spot); look ahead so that
                // turns start early; slow down and accept less clearance in tight spots.
                let mut next = None;
                'search: for (scale, clr, look) in [
                    (1.0, clearance, look0),
                    (1.0, clearance, 0.0),
                    (0.5, clearance, 0.0),
                    (0.5, 0.5 * clearance, 0.0),
                    (0.25, 0.4 * clearance, 0.0),
                ] {
                    for k in 0..=2 * TURN_STEPS {
                        let side = if k % 2 == 0 { 1.0 } else { -1.0 };
                        let psi = heading
                            + side * f64::from(k.div_ceil(2)) * max_turn / f64::from(TURN_STEPS);
                        let dir = [psi.cos(), psi.sin()];
                        let reach = step * scale + look;
                        let far = [p[0] + reach * dir[0], p[1] + reach * dir[1]];
                        if world.path_free(p, far, clr) {
                            heading = psi;
                            next =
                                Some([p[0] + step * scale * dir[0], p[1] + step * scale * dir[1]]);
                            break 'search;
                        }
                    }
                }
                let q = next.unwrap_or_else(|| {
                    // Boxed in: creep while turning (never a full stop, which would make the
                    // heading undefined).
                    heading += max_turn;
                    [p[0] + 0.05 * heading.cos(), p[1] + 0.05 * heading.sin()]
                });
                ctrl.push(q);
                p = q;
            }
        } else {
            ctrl.resize(n, start);
        }
        let walker = matches!(kind, MotionKind::Handheld | MotionKind::Headworn);
        let w = |a: f64, f0: f64, f1: f64, rng: &mut SimRng| Wave {
            a: a * rng.uniform(0.6, 1.0),
            f: rng.uniform(f0, f1),
            ph: rng.uniform(0.0, TAU),
        };
        let deg = PI / 180.0;
        let (yaw_a, pitch_a, roll_a) = match kind {
            MotionKind::Handheld => (12.0, 8.0, 5.0),
            MotionKind::Headworn => (30.0, 12.0, 4.0),
            _ => (0.0, 0.0, 0.0),
        };
        let yaw = [
            w(yaw_a * deg, 0.05, 0.15, &mut rng),
            w(yaw_a * 0.3 * deg, 0.3, 0.6, &mut rng),
        ];
        let pitch = [
            w(pitch_a * deg, 0.05, 0.2, &mut rng),
            w(pitch_a * 0.2 * deg, 0.4, 0.8, &mut rng),
        ];
        let roll = [
            w(roll_a * deg, 0.05, 0.2, &mut rng),
            w(roll_a * 0.2 * deg, 0.4, 0.8, &mut rng),
        ];
        let height = match kind {
            MotionKind::Robot => 0.25,
            MotionKind::Handheld => rng.uniform(1.1, 1.4),
            MotionKind::Headworn => rng.uniform(1.55, 1.8),
            MotionKind::Static => rng.uniform(0.5, 1.2),
            MotionKind::Vehicle => rng.uniform(0.8, 1.5),
        };
        let static_q = UnitQuaternion::from_euler_angles(
            rng.uniform(-0.1, 0.1),
            rng.uniform(-0.1, 0.1),
            rng.uniform(-PI, PI),
        );
        Ok(Trajectory {
            kind,
            ctrl,
            knot_s,
            height,
            step_hz: if walker { rng.uniform(1.8, 2.1) } else { 0.0 },
            bob_m: if walker {
                rng.uniform(0.015, 0.03)
            } else {
                0.0
            },
            sway_m: if walker {
                rng.uniform(0.01, 0.025)
            } else {
                0.0
            },
            yaw,
            pitch,
            roll,
            static_q,
            rest: None,
            climb: None,
        })
    }

    /// Rests for `start_s` \[s\] before moving and comes to rest `end_s` \[s\] before
    /// `duration_s` (motion ramps up and down over [`REST_RAMP_S`] each). Zero rests leave the
    /// trajectory as it was.
    pub fn with_rest(mut self, start_s: f64, end_s: f64, duration_s: f64) -> Trajectory {
        self.rest = (start_s > 0.0 || end_s > 0.0).then_some(Rest {
            start_s: start_s.max(0.0),
            stop_s: if end_s > 0.0 {
                duration_s - end_s
            } else {
                f64::INFINITY
            },
        });
        self
    }

    /// Climbs (or, negative, descends) `h` \[m\] over the motion up to host time `duration_s`
    /// \[s\]: a quintic smoothstep of motion time, so vertical velocity and acceleration stay
    /// continuous; peak vertical speed 1.875 |h| / (motion time). A descent starts `|h|` above the
    /// base height. Zero leaves the trajectory as it was. Call after [`Trajectory::with_rest`].
    pub fn with_height_change(mut self, h: f64, duration_s: f64) -> Trajectory {
        let span_s = self.rest.map_or(duration_s, |r| r.warp(duration_s));
        self.climb = (h != 0.0 && span_s > 0.0).then_some(Climb { h, span_s });
        self
    }

    /// Base height of the body above the floor \[m\] (before bob and height change).
    pub fn base_height(&self) -> f64 {
        self.height
    }

    /// Segment index and local parameter of time `t` \[s\].
    fn seg(&self, t: f64) -> (usize, f64) {
        let u = (t / self.knot_s + 1.0).max(0.0);
        let last = self.ctrl.len().saturating_sub(4);
        let i = (u.floor() as usize).min(last);
        (i, (u - i as f64).min(1.0))
    }

    /// Floor-plan position of the path (before bob and sway) \[m\].
    fn path(&self, t: f64) -> [f64; 2] {
        let (i, s) = self.seg(t);
        let b = [
            (1.0 - s).powi(3) / 6.0,
            (3.0 * s.powi(3) - 6.0 * s * s + 4.0) / 6.0,
            (-3.0 * s.powi(3) + 3.0 * s * s + 3.0 * s + 1.0) / 6.0,
            s.powi(3) / 6.0,
        ];
        let mut p = [0.0; 2];
        for (k, bk) in b.iter().enumerate() {
            let c = self.ctrl[(i + k).min(self.ctrl.len() - 1)];
            p[0] += bk * c[0];
            p[1] += bk * c[1];
        }
        p
    }

    /// Floor-plan velocity of the path \[m/s\].
    fn path_velocity(&self, t: f64) -> [f64; 2] {
        let (i, s) = self.seg(t);
        let b = [
            -3.0 * (1.0 - s).powi(2),
            9.0 * s * s - 12.0 * s,
            -9.0 * s * s + 6.0 * s + 3.0,
            3.0 * s * s,
        ];
        let mut v = [0.0; 2];
        for (k, bk) in b.iter().enumerate() {
            let c = self.ctrl[(i + k).min(self.ctrl.len() - 1)];
            v[0] += bk * c[0] / (6.0 * self.knot_s);
            v[1] += bk * c[1] / (6.0 * self.knot_s);
        }
        v
    }

    /// Body pose at host time `t` \[s\].
    pub fn pose(&self, t: f64) -> Pose {
        let t = self.rest.map_or(t, |r| r.warp(t));
        let p2 = self.path(t);
        if self.kind == MotionKind::Static {
            return Pose {
                p: Vector3::new(p2[0], p2[1], self.height),
                q: self.static_q,
            };
        }
        let v = self.path_velocity(t);
        let heading = v[1].atan2(v[0]);
        let (sh, ch) = heading.sin_cos();
        let step = TAU * self.step_hz * t;
        let bob = self.bob_m * step.sin();
        let sway = self.sway_m * (0.5 * step).sin();
        let climb = self.climb.map_or(0.0, |c| c.dz(t));
        let p = Vector3::new(
            p2[0] - sh * sway,
            p2[1] + ch * sway,
            self.height + bob + climb,
        );
        let sum = |w: &[Wave; 2]| w[0].at(t) + w[1].at(t);
        let step_pitch = if self.step_hz > 0.0 {
            0.01 * step.cos()
        } else {
            0.0
        };
        let step_roll = if self.step_hz > 0.0 {
            0.015 * (0.5 * step).cos()
        } else {
            0.0
        };
        let q = UnitQuaternion::from_euler_angles(
            sum(&self.roll) + step_roll,
            sum(&self.pitch) + step_pitch,
            heading + sum(&self.yaw),
        );
        Pose { p, q }
    }

    /// Velocity of a point fixed on the body at `offset` (body frame) \[m/s\], world frame
    /// (central difference, 0.1 ms step).
    pub fn point_velocity(&self, t: f64, offset: &Vector3<f64>) -> Vector3<f64> {
        let h = 1e-4;
        let a = self.pose(t - h);
        let b = self.pose(t + h);
        ((b.p + b.q * offset) - (a.p + a.q * offset)) / (2.0 * h)
    }

    /// Acceleration of a point fixed on the body at `offset` \[m/s^2\], world frame.
    pub fn point_acceleration(&self, t: f64, offset: &Vector3<f64>) -> Vector3<f64> {
        let h = 1e-3;
        let at = |t| {
            let p = self.pose(t);
            p.p + p.q * offset
        };
        (at(t + h) - 2.0 * at(t) + at(t - h)) / (h * h)
    }

    /// Angular velocity of a frame rotated by `r` from the body, in that frame \[rad/s\].
    pub fn angular_velocity(&self, t: f64, r: &UnitQuaternion<f64>) -> Vector3<f64> {
        let h = 1e-4;
        let a = self.pose(t - h).q * r;
        let b = self.pose(t + h).q * r;
        (a.inverse() * b).scaled_axis() / (2.0 * h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::Family;

    #[test]
    fn speeds_and_rates_stay_in_range() {
        let world = World::generate(Family::Office, 2);
        for kind in [MotionKind::Robot, MotionKind::Handheld] {
            let tr = Trajectory::generate(kind, &world, 5, 60.0).unwrap();
            let (vmin, vmax) = kind.speed_range();
            let mut sum = 0.0;
            let n = 600;
            for i in 0..n {
                let t = i as f64 * 0.1;
                let v = tr.point_velocity(t, &Vector3::zeros()).xy().norm();
                assert!(v < vmax * 1.3 + 0.15, "{kind} at {t}: {v} m/s");
                sum += v;
                let p = tr.pose(t).p;
                assert!(
                    world.clearance([p.x, p.y]) > 0.2,
                    "{kind} at {t}: inside an obstacle"
                );
            }
            let mean = sum / n as f64;
            assert!(mean > vmin * 0.8 && mean < vmax, "{kind}: mean {mean} m/s");
        }
    }

    #[test]
    fn rests_hold_the_pose_and_motion_ramps_smoothly() {
        let world = World::generate(Family::Office, 2);
        let moving = Trajectory::generate(MotionKind::Handheld, &world, 5, 40.0).unwrap();
        let tr = moving.clone().with_rest(5.0, 8.0, 40.0);
        let z = Vector3::zeros();
        // At rest: the pose is the motion's first (or last) one, velocity and rate zero.
        for t in [0.0, 2.0, 4.99, 32.01, 35.0, 39.9] {
            assert!(tr.point_velocity(t, &z).norm() < 1e-9, "moving at {t}");
            assert!(tr.angular_velocity(t, &UnitQuaternion::identity()).norm() < 1e-9);
        }
        assert!((tr.pose(1.0).p - moving.pose(0.0).p).norm() < 1e-12);
        assert!((tr.pose(39.0).p - tr.pose(33.0).p).norm() < 1e-12);
        // Moving between, and no jump in acceleration at the ramps' ends.
        assert!(tr.point_velocity(20.0, &z).norm() > 0.3);
        for edge in [5.0, 5.0 + REST_RAMP_S, 32.0 - REST_RAMP_S, 32.0] {
            // Over 4 ms the gait's own jerk (~60 m/s^3) changes it by ~0.25 m/s^2; a ramp of the
            // time rate with a corner would add ~0.8 m/s^2 (speed over ramp time).
            let a = tr.point_acceleration(edge - 0.002, &z);
            let b = tr.point_acceleration(edge + 0.002, &z);
            assert!(
                (a - b).norm() < 0.5,
                "acceleration jumps at {edge}: {a} vs {b}"
            );
        }
        // Without rests the trajectory is unchanged.
        let same = moving.clone().with_rest(0.0, 0.0, 40.0);
        assert_eq!(same.pose(12.3).p, moving.pose(12.3).p);
    }
}
