//! Evaluation on constructed cases with known answers.

use milliego_eval::*;
use nalgebra::{UnitQuaternion, Vector3};

fn line(n: usize, dt: f64, t0: f64) -> Trajectory {
    let mut tr = Trajectory::default();
    for i in 0..n {
        tr.t.push(t0 + i as f64 * dt);
        tr.p.push(Vector3::new(
            i as f64,
            (i as f64 * 0.3).sin(),
            0.1 * i as f64,
        ));
        tr.q.push(UnitQuaternion::from_euler_angles(0.0, 0.0, i as f64 * 0.1));
    }
    tr
}

#[test]
fn a_rigidly_moved_copy_aligns_to_zero_error() {
    let gt = line(50, 0.1, 0.0);
    let mut est = gt.clone();
    est.transform(&Alignment {
        rotation: *UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0)
            .to_rotation_matrix()
            .matrix(),
        translation: Vector3::new(5.0, -2.0, 1.0),
        scale: 1.0,
    });
    let r = evaluate(&gt, &est, &Settings::default()).unwrap();
    assert!(r.ate.rmse < 1e-9 && r.rpe.max < 1e-9, "{r:?}");
    let none = evaluate(
        &gt,
        &est,
        &Settings {
            align: Align::None,
            ..Settings::default()
        },
    )
    .unwrap();
    assert!(none.ate.rmse > 1.0);
    assert!(
        none.rpe.max < 1e-9,
        "RPE does not depend on a rigid transform of the estimate"
    );
}

#[test]
fn sim3_recovers_scale_and_se3_does_not() {
    let gt = line(40, 0.1, 0.0);
    let mut est = gt.clone();
    est.transform(&Alignment {
        rotation: nalgebra::Matrix3::identity(),
        translation: Vector3::zeros(),
        scale: 0.5,
    });
    let sim3 = evaluate(
        &gt,
        &est,
        &Settings {
            align: Align::Sim3,
            ..Settings::default()
        },
    )
    .unwrap();
    assert!((sim3.alignment.scale - 2.0).abs() < 1e-9 && sim3.ate.rmse < 1e-9);
    let se3 = evaluate(&gt, &est, &Settings::default()).unwrap();
    assert!(se3.ate.rmse > 0.5);
}

#[test]
fn statistics_match_hand_computed_values() {
    let s = Stats::of(&[1.0, 2.0, 3.0, 4.0]);
    assert_eq!(
        (s.mean, s.median, s.min, s.max, s.sse, s.count),
        (2.5, 2.5, 1.0, 4.0, 30.0, 4)
    );
    assert!((s.rmse - 7.5f64.sqrt()).abs() < 1e-12);
    assert!(
        (s.std - 1.25f64.sqrt()).abs() < 1e-12,
        "population standard deviation"
    );
    assert_eq!(Stats::of(&[3.0, 1.0, 2.0]).median, 2.0);
}

#[test]
fn association_matches_nearest_within_tolerance_and_reports_none() {
    let gt = line(10, 0.1, 0.0);
    let mut est = line(10, 0.1, 0.004);
    est.t[4] += 0.05; // too far from any reference stamp
    let (r, e) = associate(&gt, &est, 0.01, 0.0).unwrap();
    assert_eq!(r.len(), 9);
    assert!(r.t.iter().zip(&e.t).all(|(a, b)| (a - b).abs() <= 0.01));
    let far = line(10, 0.1, 50.0);
    assert!(matches!(
        associate(&gt, &far, 0.01, 0.0),
        Err(EvalError::NoMatches { .. })
    ));
    let (r, _) = associate(&gt, &far, 0.01, -50.0).unwrap();
    assert_eq!(r.len(), 10, "the offset shifts the estimate's clock");
}

#[test]
fn rpe_over_distance_and_frames() {
    let gt = line(30, 0.1, 0.0);
    let mut est = gt.clone();
    for (i, p) in est.p.iter_mut().enumerate() {
        p.x += 0.01 * i as f64; // 1 cm per frame of scale drift along x
    }
    let per_frame = rpe(&gt, &est, 1.0, DeltaUnit::Frames).unwrap();
    assert_eq!(per_frame.len(), 29);
    assert!(per_frame.iter().all(|e| (e - 0.01).abs() < 1e-9));
    let ten = rpe(&gt, &est, 10.0, DeltaUnit::Frames).unwrap();
    assert_eq!(ten.len(), 2);
    assert!(ten.iter().all(|e| (e - 0.1).abs() < 1e-9));
    assert!(matches!(
        rpe(&gt, &est, 1e6, DeltaUnit::Meters),
        Err(EvalError::NoPairs { .. })
    ));
}

#[test]
fn collinear_points_cannot_be_aligned() {
    let mut gt = Trajectory::default();
    for i in 0..10 {
        gt.t.push(i as f64);
        gt.p.push(Vector3::new(i as f64, 0.0, 0.0));
        gt.q.push(UnitQuaternion::identity());
    }
    assert!(matches!(
        evaluate(&gt, &gt.clone(), &Settings::default()),
        Err(EvalError::DegenerateAlignment { .. })
    ));
}
