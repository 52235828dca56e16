//! Motions of real rigs: a car outdoors, and walks that climb or descend.

mod common;

use common::{decode_radar, Gt};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::Scenario;
use milliego_sim::world::{Family, World};
use nalgebra::Vector3;

#[test]
fn vehicle_drives_without_side_slip_at_car_speeds() {
    for seed in [1, 2] {
        let s = common::simulate_with(Family::Outdoor, MotionKind::Vehicle, seed, |s| {
            s.duration_s = 60.0;
        });
        let (frames, c) = decode_radar(&s.session);
        assert_eq!(c.frames_bad_total(), 0);
        assert!(!frames.is_empty());
        // The short-chirp .cfg: car speeds do not alias, so inlier Doppler is the truth's.
        let model = s.scenario.radar_model().unwrap();
        assert!(model.derived.max_velocity_mps > 11.5);
        let truth = common::radar_truth(&s.path());
        let res: Vec<f64> = truth
            .iter()
            .filter(|r| r.class == "inlier")
            .map(|r| f64::from(r.xyzv[3]) - r.true_v)
            .collect();
        let fastest = truth
            .iter()
            .filter(|r| r.class == "inlier")
            .fold(0.0f64, |a, r| a.max(r.true_v.abs()));
        let doppler_rms = (res.iter().map(|x| x * x).sum::<f64>() / res.len() as f64).sqrt();
        eprintln!(
            "vehicle {seed}: {} inliers, fastest {fastest:.2} m/s, Doppler error rms {doppler_rms:.3} m/s (sigma {:.3})",
            res.len(),
            model.doppler_sigma_mps()
        );
        assert!(fastest > 5.0, "{fastest}");
        assert!(
            doppler_rms < 1.3 * model.doppler_sigma_mps(),
            "{doppler_rms}"
        );
        let gt = Gt::load(&s.session);
        let world = World::generate_vehicle_lot(seed);
        let (mut lat, mut vert, mut speeds) = (Vec::new(), Vec::new(), Vec::new());
        let mut min_clear = f64::INFINITY;
        let mut t = 1.0;
        while t < 59.0 {
            let v = gt.q(t).inverse() * gt.v(t, &Vector3::zeros());
            lat.push(v.y);
            vert.push(v.z);
            speeds.push(v.x);
            let p = gt.p(t, &Vector3::zeros());
            // Half a car's width (0.9 m) from any obstacle or the edge of the lot.
            let c = world.clearance([p.x, p.y]);
            assert!(c > 0.9, "seed {seed} at {t} s: {c} m from an obstacle");
            min_clear = min_clear.min(c);
            t += 0.05;
        }
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let mean = speeds.iter().sum::<f64>() / speeds.len() as f64;
        let max = speeds.iter().fold(0.0f64, |a, &b| a.max(b));
        let min = speeds.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        eprintln!(
            "vehicle {seed}: forward speed mean {mean:.2} m/s ({min:.2}..{max:.2}), lateral rms {:.4} m/s, vertical rms {:.4} m/s, clearance >= {min_clear:.2} m",
            rms(&lat),
            rms(&vert)
        );
        assert!(rms(&lat) < 0.02, "side slip {} m/s", rms(&lat));
        assert!(rms(&vert) < 0.01, "vertical {} m/s", rms(&vert));
        assert!((3.0..=12.0).contains(&mean), "mean speed {mean}");
        assert!(min > 0.5 && max < 12.0 * 1.3, "{min}..{max}");
    }
    let sc = Scenario::new(Family::Office, MotionKind::Vehicle, 1);
    let e = sc.validate().unwrap_err().to_string();
    assert!(e.contains("vehicle motion needs the outdoor family"), "{e}");
}

#[test]
fn walks_climb_and_descend() {
    use milliego_sim::imu::standard_altitude;
    for h in [3.0, -2.0] {
        let s = common::simulate_with(Family::Outdoor, MotionKind::Handheld, 5, |s| {
            s.duration_s = 30.0;
            s.height_change_m = h;
            s.baro_hz = 50.0;
        });
        assert!(s.session.meta.description.contains("height change"));
        let gt = Gt::load(&s.session);
        let o = Vector3::zeros();
        let z0 = (0..100)
            .map(|i| gt.p(0.01 * f64::from(i), &o).z)
            .sum::<f64>()
            / 100.0;
        let z1 = (0..100)
            .map(|i| gt.p(28.0 + 0.01 * f64::from(i), &o).z)
            .sum::<f64>()
            / 100.0;
        // The barometer sees it too (first and last second of pressure, bias ignored).
        let (_, baro) = common::decode_imu_all(&s.session);
        let alt = |m: &[common::PressureMsg]| {
            m.iter()
                .map(|p| standard_altitude(f64::from(p.pa)))
                .sum::<f64>()
                / m.len() as f64
        };
        let db = alt(&baro[baro.len() - 50..]) - alt(&baro[..50]);
        eprintln!(
            "height change {h}: ground truth {:.3} m, barometer {db:.3} m",
            z1 - z0
        );
        assert!((z1 - z0 - h).abs() < 0.1, "{} vs {h}", z1 - z0);
        assert!((db - h).abs() < 0.3, "barometer {db} vs {h}");
        // Never below the walk's base height.
        assert!(z0.min(z1) > 0.9);
    }
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 1);
    sc.height_change_m = 3.0;
    let dir = tempfile::tempdir().unwrap();
    let e = milliego_sim::scenario::run(&sc, &dir.path().join("s"), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("ceiling"), "{e}");
    for (edit, what) in [
        (
            Box::new(|s: &mut Scenario| s.motion = MotionKind::Robot) as Box<dyn Fn(&mut Scenario)>,
            "only handheld and headworn",
        ),
        (
            Box::new(|s: &mut Scenario| s.height_change_m = 12.0),
            "outside ±10 m",
        ),
        (Box::new(|s: &mut Scenario| s.duration_s = 5.0), "m/s"),
    ] {
        let mut x = sc.clone();
        edit(&mut x);
        let e = x.validate().unwrap_err().to_string();
        assert!(e.contains("height change") && e.contains(what), "{e}");
    }
}
