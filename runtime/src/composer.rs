//! From relative poses to the trajectory: `T(to) = T(from) * rel`, with a small ring of recent
//! frame poses so estimators with different strides (the model every 5th frame, Doppler every
//! frame) compose onto one trajectory. A `from` frame the ring does not hold starts a new origin
//! (`T(from)` = identity) and the pose is flagged RESET.

use crate::estimator::RelativePose;
use nalgebra::{Isometry3, UnitQuaternion};

/// Frames remembered.
pub const RING: usize = 32;

/// A composed pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Composed {
    /// Frame number.
    pub frame: u32,
    /// Time \[s\].
    pub t: f64,
    /// Body pose in the world frame (translation \[m\]).
    pub pose: Isometry3<f64>,
    /// Motion since the previous radar-rate pose, in the previous body frame.
    pub rel: Isometry3<f64>,
    /// True when a new origin was started.
    pub reset: bool,
}

/// The trajectory composer.
#[derive(Debug, Clone)]
pub struct Composer {
    ring: [(u32, f64, Isometry3<f64>); RING],
    len: usize,
    head: usize,
    last: Option<Composed>,
    /// Origins started (the first included).
    pub resets: u64,
}

impl Default for Composer {
    fn default() -> Self {
        Composer {
            ring: [(0, 0.0, Isometry3::identity()); RING],
            len: 0,
            head: 0,
            last: None,
            resets: 0,
        }
    }
}

impl Composer {
    /// World pose of `frame`, if remembered.
    pub fn pose_of(&self, frame: u32) -> Option<Isometry3<f64>> {
        (0..self.len)
            .map(|k| self.ring[(self.head + RING - 1 - k) % RING])
            .find(|e| e.0 == frame)
            .map(|e| e.2)
    }

    /// The latest composed pose.
    pub fn last(&self) -> Option<&Composed> {
        self.last.as_ref()
    }

    /// Forgets every frame: the next pose starts a new origin.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Composes `r` onto the trajectory. A `from` frame the ring does not hold starts a new
    /// origin (see [`Composer::push_from`] to continue instead).
    pub fn push(&mut self, r: &RelativePose) -> Composed {
        match self.pose_of(r.from_frame) {
            Some(p) => self.compose(r, p, false),
            None => {
                self.resets += 1;
                self.len = 0;
                self.compose(r, Isometry3::identity(), true)
            }
        }
    }

    /// Composes `r` from `from_pose`, the world pose of `r.from_frame` as known otherwise (for
    /// example from another estimator's chain at a hand-over): the trajectory goes on, no new
    /// origin. Frames already on the trajectory are kept.
    pub fn push_from(&mut self, r: &RelativePose, from_pose: Isometry3<f64>) -> Composed {
        self.compose(r, from_pose, false)
    }

    fn compose(&mut self, r: &RelativePose, from: Isometry3<f64>, reset: bool) -> Composed {
        let pose = from * r.rel;
        // Motion since the previous radar-rate pose (whatever the estimator's stride).
        let rel = match (&self.last, reset) {
            (Some(l), false) => l.pose.inverse() * pose,
            _ => r.rel,
        };
        self.ring[self.head] = (r.to_frame, r.t_to, pose);
        self.head = (self.head + 1) % RING;
        self.len = (self.len + 1).min(RING);
        let c = Composed {
            frame: r.to_frame,
            t: r.t_to,
            pose,
            rel,
            reset,
        };
        self.last = Some(c);
        c
    }
}

/// Orientation as (w, x, y, z) f32, as the pose link carries it.
pub fn wxyz_f32(q: &UnitQuaternion<f64>) -> [f32; 4] {
    [q.w as f32, q.i as f32, q.j as f32, q.k as f32]
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, Vector3};
    use std::f64::consts::FRAC_PI_2;

    fn rp(from: u32, to: u32, rel: Isometry3<f64>) -> RelativePose {
        RelativePose {
            from_frame: from,
            to_frame: to,
            t_from: f64::from(from) * 0.1,
            t_to: f64::from(to) * 0.1,
            rel,
            velocity_world: None,
        }
    }

    #[test]
    fn rel_translation_is_in_the_from_body_frame() {
        // Start at the origin facing +x; turn left 90 deg (yaw about +z) while moving 1 m forward
        // (body x). Then 1 m forward again in the new body frame: that is world +y.
        let mut c = Composer::default();
        let first = c.push(&rp(9, 0, Isometry3::identity()));
        assert!(first.reset);
        let yaw = UnitQuaternion::from_euler_angles(0.0, 0.0, FRAC_PI_2);
        let step = Isometry3::from_parts(Translation3::new(1.0, 0.0, 0.0), yaw);
        let a = c.push(&rp(0, 1, step));
        assert!(!a.reset);
        assert!((a.pose.translation.vector - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        let b = c.push(&rp(1, 2, step));
        // Second step: 1 m along body x = world +y, then another 90 deg: facing -x.
        assert!((b.pose.translation.vector - Vector3::new(1.0, 1.0, 0.0)).norm() < 1e-12);
        let (r, p, y) = b.pose.rotation.euler_angles();
        assert!(r.abs() < 1e-12 && p.abs() < 1e-12);
        assert!((y.abs() - std::f64::consts::PI).abs() < 1e-12);
        assert_eq!(
            wxyz_f32(&b.pose.rotation).map(|v| (v * 1e4).round() / 1e4),
            [0.0, 0.0, 0.0, 1.0]
        );
    }

    #[test]
    fn roll_pitch_yaw_conventions() {
        // nalgebra's from_euler_angles(roll, pitch, yaw) = Rz(yaw) Ry(pitch) Rx(roll): a body x
        // axis pitched up by 30 deg (pitch about +y turns x towards -z).
        let q = UnitQuaternion::from_euler_angles(0.0, 30f64.to_radians(), 0.0);
        let x = q * Vector3::x();
        assert!(
            (x - Vector3::new(30f64.to_radians().cos(), 0.0, -30f64.to_radians().sin())).norm()
                < 1e-12
        );
        let q = UnitQuaternion::from_euler_angles(0.1f64, -0.2, 0.3);
        let (r, p, y) = q.euler_angles();
        assert!((r - 0.1).abs() < 1e-12 && (p + 0.2).abs() < 1e-12 && (y - 0.3).abs() < 1e-12);
    }

    #[test]
    fn stride_and_unknown_from_frames() {
        let mut c = Composer::default();
        let step = Isometry3::translation(0.5, 0.0, 0.0);
        c.push(&rp(99, 0, Isometry3::identity()));
        for k in 1..=10 {
            c.push(&rp(k - 1, k, step));
        }
        // A 5-frame stride from frame 5 to 10 replaces frame 10's pose consistently.
        let five = Isometry3::translation(2.5, 0.0, 0.0);
        let a = c.push(&rp(5, 10, five));
        assert!((a.pose.translation.x - 5.0).abs() < 1e-12 && !a.reset);
        // Frame 1000 was never composed: a new origin.
        let b = c.push(&rp(1000, 1001, step));
        assert!(b.reset);
        assert!((b.pose.translation.x - 0.5).abs() < 1e-12);
        assert_eq!(c.resets, 2);
    }
}
