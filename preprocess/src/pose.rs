//! Pose conventions shared by labels, the trainer and the runtime's composer.
//!
//! - A pose `T` is the body frame in the world: `p_world = T * p_body` (nalgebra `Isometry3`).
//! - The relative pose from frame a to frame b is `T_ab = T_a^-1 * T_b`: the body at b expressed
//!   in the body frame at a; composing `T_b = T_a * T_ab` walks a trajectory forward.
//! - Labels and model outputs are `[tx, ty, tz, roll, pitch, yaw]`: the translation of `T_ab`
//!   \[m\] and its rotation as Euler angles \[deg\] with `R = Rz(yaw) * Ry(pitch) * Rx(roll)`
//!   (intrinsic z-y'-x'', the convention of nalgebra's `from_euler_angles`), pitch in
//!   \[-90, 90\] deg.

use milliego_session::TumPose;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// Rotation from roll, pitch, yaw \[deg\] (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
pub fn rotation_from_euler_deg(rpy_deg: [f64; 3]) -> UnitQuaternion<f64> {
    let [r, p, y] = rpy_deg.map(f64::to_radians);
    UnitQuaternion::from_euler_angles(r, p, y)
}

/// Roll, pitch, yaw \[deg\] of a rotation (`R = Rz(yaw) Ry(pitch) Rx(roll)`).
pub fn euler_deg(q: &UnitQuaternion<f64>) -> [f64; 3] {
    let (r, p, y) = q.euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}

/// The relative pose `T_a^-1 * T_b`.
pub fn relative(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Isometry3<f64> {
    a.inverse() * b
}

/// A relative pose as a label `[tx, ty, tz [m], roll, pitch, yaw [deg]]`.
pub fn to_label(rel: &Isometry3<f64>) -> [f64; 6] {
    let t = rel.translation.vector;
    let [r, p, y] = euler_deg(&rel.rotation);
    [t.x, t.y, t.z, r, p, y]
}

/// A label (or model output) as a relative pose. Non-finite values give None.
pub fn from_label(l: &[f64; 6]) -> Option<Isometry3<f64>> {
    if !l.iter().all(|v| v.is_finite()) {
        return None;
    }
    Some(Isometry3::from_parts(
        Translation3::new(l[0], l[1], l[2]),
        rotation_from_euler_deg([l[3], l[4], l[5]]),
    ))
}

/// A TUM pose as an isometry.
pub fn from_tum(p: &TumPose) -> Isometry3<f64> {
    let [x, y, z, w] = p.q;
    Isometry3::from_parts(
        Translation3::new(p.p[0], p.p[1], p.p[2]),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}

/// An isometry as a TUM pose at time `t` \[s\].
pub fn to_tum(t: f64, iso: &Isometry3<f64>) -> TumPose {
    let q = iso.rotation.quaternion();
    let v = iso.translation.vector;
    TumPose {
        t,
        p: [v.x, v.y, v.z],
        q: [q.i, q.j, q.k, q.w],
    }
}

/// The pose of a time-sorted trajectory at time `t` \[s\]: position interpolated linearly,
/// orientation by slerp between the two bracketing poses. None outside the trajectory or across
/// a gap longer than `max_gap_s`.
pub fn interpolate(traj: &[TumPose], t: f64, max_gap_s: f64) -> Option<Isometry3<f64>> {
    let i = traj.partition_point(|p| p.t < t);
    if i == traj.len() {
        return None;
    }
    if traj[i].t == t {
        return Some(from_tum(&traj[i]));
    }
    if i == 0 {
        return None;
    }
    let (a, b) = (&traj[i - 1], &traj[i]);
    if b.t - a.t > max_gap_s {
        return None;
    }
    let w = (t - a.t) / (b.t - a.t);
    let (ia, ib) = (from_tum(a), from_tum(b));
    let p: Vector3<f64> = ia.translation.vector.lerp(&ib.translation.vector, w);
    let q = ia.rotation.slerp(&ib.rotation, w);
    Some(Isometry3::from_parts(Translation3::from(p), q))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_1_SQRT_2;

    #[test]
    fn euler_convention_matches_hand_computed_rotations() {
        // Yaw 90 deg: body x points along world y.
        let q = rotation_from_euler_deg([0.0, 0.0, 90.0]);
        let v = q * Vector3::x();
        assert!((v - Vector3::y()).norm() < 1e-12);
        // Pitch 90 deg about y: x goes to -z.
        let v = rotation_from_euler_deg([0.0, 90.0, 0.0]) * Vector3::x();
        assert!((v + Vector3::z()).norm() < 1e-12);
        // Roll 90 deg about x: y goes to z.
        let v = rotation_from_euler_deg([90.0, 0.0, 0.0]) * Vector3::y();
        assert!((v - Vector3::z()).norm() < 1e-12);
        // Order: R = Rz(yaw) Ry(pitch) Rx(roll). Roll 90 then yaw 90: y -> z (roll), z stays
        // under yaw. x -> (roll keeps x) -> yaw -> y.
        let q = rotation_from_euler_deg([90.0, 0.0, 90.0]);
        assert!((q * Vector3::y() - Vector3::z()).norm() < 1e-12);
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
        // Quaternion of yaw 90: (w, z) = (cos 45, sin 45).
        let q = rotation_from_euler_deg([0.0, 0.0, 90.0]);
        assert!((q.w - FRAC_1_SQRT_2).abs() < 1e-12 && (q.k - FRAC_1_SQRT_2).abs() < 1e-12);
        // Round trip.
        let e = [10.0, -20.0, 170.0];
        let back = euler_deg(&rotation_from_euler_deg(e));
        for i in 0..3 {
            assert!((back[i] - e[i]).abs() < 1e-9, "{back:?}");
        }
    }

    #[test]
    fn relative_pose_is_expressed_in_the_first_body_frame() {
        // Body a at (1, 2, 0) facing world +y (yaw 90); body b one metre further along world +y
        // and turned 10 deg more to the left. In a's frame b is 1 m ahead (+x), yaw +10 deg.
        let a = Isometry3::from_parts(
            Translation3::new(1.0, 2.0, 0.0),
            rotation_from_euler_deg([0.0, 0.0, 90.0]),
        );
        let b = Isometry3::from_parts(
            Translation3::new(1.0, 3.0, 0.0),
            rotation_from_euler_deg([0.0, 0.0, 100.0]),
        );
        let l = to_label(&relative(&a, &b));
        let want = [1.0, 0.0, 0.0, 0.0, 0.0, 10.0];
        for i in 0..6 {
            assert!((l[i] - want[i]).abs() < 1e-9, "{l:?}");
        }
        let back = a * from_label(&l).unwrap();
        assert!((back.translation.vector - b.translation.vector).norm() < 1e-12);
        assert!(back.rotation.angle_to(&b.rotation) < 1e-12);
        assert!(from_label(&[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]).is_none());
    }

    #[test]
    fn interpolation_lerps_and_slerps() {
        let a = to_tum(0.0, &Isometry3::identity());
        let b = to_tum(
            1.0,
            &Isometry3::from_parts(
                Translation3::new(2.0, 0.0, 0.0),
                rotation_from_euler_deg([0.0, 0.0, 40.0]),
            ),
        );
        let m = interpolate(&[a, b], 0.25, 2.0).unwrap();
        assert!((m.translation.vector.x - 0.5).abs() < 1e-12);
        assert!((euler_deg(&m.rotation)[2] - 10.0).abs() < 1e-9);
        assert!(interpolate(&[a, b], 1.5, 2.0).is_none());
        assert!(interpolate(&[a, b], -0.1, 2.0).is_none());
        assert!(interpolate(&[a, b], 0.5, 0.5).is_none());
        assert_eq!(
            interpolate(&[a, b], 1.0, 2.0).unwrap().translation.vector.x,
            2.0
        );
    }
}
