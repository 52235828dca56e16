//! Radar mounts: lever arm, yaw and tilt reach the session's extrinsics and the simulated radar
//! sees the world (and its own motion, lever arm included) from that mount.

mod common;

use common::{decode_radar, radar_truth, Gt};
use milliego_sim::motion::MotionKind;
use milliego_sim::radar::RadarModel;
use milliego_sim::scenario::{sensor_pose, Scenario, RADAR_START_S};
use milliego_sim::world::Family;
use nalgebra::{UnitQuaternion, Vector3};

/// The real rig: radar 1.1 m ahead of the IMU, yawed 30°, tilted 25° up.
fn mounted(yaw: f64) -> common::Sim {
    common::simulate_with(Family::Office, MotionKind::Handheld, 7, |s| {
        s.duration_s = 12.0;
        s.radar_lever_m = Some([1.1, 0.0, 0.0]);
        s.radar_yaw_deg = yaw;
        s.radar_tilt_deg = 25.0;
    })
}

#[test]
fn extrinsics_carry_the_mount() {
    let s = mounted(30.0);
    let (t, q) = sensor_pose(&s.session.meta.extrinsics.radar);
    assert!((t - Vector3::new(1.1, 0.0, 0.0)).norm() < 1e-12);
    // Boresight (radar y) along body x yawed 30° left and tilted 25° up; radar x stays
    // horizontal (tilt about it), pointing right of the boresight.
    let (y, p) = (30f64.to_radians(), 25f64.to_radians());
    let bore = Vector3::new(p.cos() * y.cos(), p.cos() * y.sin(), p.sin());
    assert!(
        (q * Vector3::y() - bore).norm() < 1e-12,
        "{}",
        q * Vector3::y()
    );
    let right = Vector3::new(y.sin(), -y.cos(), 0.0);
    assert!((q * Vector3::x() - right).norm() < 1e-12);
    assert!(s.session.meta.description.contains("yawed 30 deg"));
    // Defaults: the mount of before.
    let d = Scenario::new(Family::Office, MotionKind::Handheld, 7);
    assert_eq!(
        d.extrinsics(),
        milliego_sim::scenario::extrinsics(MotionKind::Handheld)
    );
    // Out-of-range settings are refused, naming the setting.
    for (edit, what) in [
        (
            Box::new(|s: &mut Scenario| s.radar_lever_m = Some([2.5, 0.0, 0.0]))
                as Box<dyn Fn(&mut Scenario)>,
            "radar lever arm",
        ),
        (
            Box::new(|s: &mut Scenario| s.radar_yaw_deg = 200.0),
            "radar yaw",
        ),
        (
            Box::new(|s: &mut Scenario| s.radar_tilt_deg = -70.0),
            "radar tilt",
        ),
        (
            Box::new(|s: &mut Scenario| s.radar_tilt_deg = f64::NAN),
            "radar tilt",
        ),
    ] {
        let mut sc = d.clone();
        edit(&mut sc);
        let e = sc.validate().unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
}

/// Inlier Doppler against the velocity of the mount point computed here from the ground truth
/// and the mount settings (not from the session's extrinsics): −v_radar · direction.
#[test]
fn doppler_is_the_mount_velocity_on_the_ray() {
    for yaw in [30.0, -30.0] {
        let s = mounted(yaw);
        let sigma = RadarModel::new(20.0).unwrap().doppler_sigma_mps();
        let t_br = Vector3::new(1.1, 0.0, 0.0);
        let q_br = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), f64::to_radians(yaw))
            * UnitQuaternion::from_euler_angles(0.0, 0.0, -std::f64::consts::FRAC_PI_2)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 25f64.to_radians());
        let gt = Gt::load(&s.session);
        let clk = s.session.meta.clock.unwrap();
        let k = 1.0 + clk.radar_drift_ppm * 1e-6;
        let model = RadarModel::new(s.scenario.radar_hz).unwrap();
        let s0 = k * RADAR_START_S + clk.radar_offset_s;
        let (frames, _) = decode_radar(&s.session);
        let truth = radar_truth(&s.path());
        let mut rows = truth.iter();
        let (mut res, mut res_origin) = (Vec::new(), Vec::new());
        for f in &frames {
            // Frame n's chirps start at s0 + (n - 1) T on the radar clock; the points are
            // computed at their middle.
            let start = s0 + f64::from(f.frame_number - 1) * model.frame_period_s();
            let mid = (start + 0.5 * model.active_time_s() - clk.radar_offset_s) / k;
            let q_wr = gt.q(mid) * q_br;
            let v_radar = q_wr.inverse() * gt.v(mid, &t_br);
            let v_origin = q_wr.inverse() * gt.v(mid, &Vector3::zeros());
            for p in &f.points {
                let r = rows.next().unwrap();
                if r.class != "inlier" {
                    continue;
                }
                let u = r.true_xyz.normalize();
                res.push(f64::from(p[3]) + v_radar.dot(&u));
                res_origin.push(f64::from(p[3]) + v_origin.dot(&u));
            }
        }
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        eprintln!(
            "yaw {yaw}: {} inliers, Doppler residual rms {:.4} m/s at the mount, {:.4} at the body origin (sigma {sigma:.4})",
            res.len(),
            rms(&res),
            rms(&res_origin)
        );
        assert!(res.len() > 100);
        assert!(rms(&res) < 1.3 * sigma, "rms {} m/s", rms(&res));
        // The lever arm matters: the body origin's velocity does not explain the Doppler.
        assert!(rms(&res_origin) > 2.0 * sigma, "{}", rms(&res_origin));
    }
}
