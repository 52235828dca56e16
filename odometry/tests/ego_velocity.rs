//! Ego-velocity on synthetic frames with known motion: accuracy within the noise budget under
//! 50-80% outliers, covariance consistency, and every degenerate case reported.

use milliego_odometry::ego_velocity::{
    Config, Detection, EgoVelocityEstimator, Estimate, Model, Status,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIGMA: f32 = 0.04;

/// A frame of `n` points: exactly `round(n * outliers)` with arbitrary radial velocities (moving
/// objects, multipath), the rest static.
fn frame(
    rng: &mut ChaCha8Rng,
    v: [f64; 3],
    n: usize,
    outliers: f64,
    max_el_deg: f64,
) -> (Vec<Detection>, Vec<bool>) {
    let mut dets = Vec::new();
    let mut is_static = Vec::new();
    let n_out = (n as f64 * outliers).round() as usize;
    for k in 0..n {
        let az = rng.gen_range(-60f64..60.0).to_radians();
        let el = if max_el_deg > 0.0 {
            rng.gen_range(-max_el_deg..max_el_deg).to_radians()
        } else {
            0.0
        };
        let r = rng.gen_range(1.0..10.0);
        let d = [el.cos() * az.sin(), el.cos() * az.cos(), el.sin()];
        let outlier = k < n_out;
        // Box-Muller noise.
        let (u1, u2): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen_range(0.0..1.0));
        let noise =
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos() * f64::from(SIGMA);
        let vr = if outlier {
            rng.gen_range(-3.0..3.0)
        } else {
            -(d[0] * v[0] + d[1] * v[1] + d[2] * v[2]) + noise
        };
        dets.push(Detection {
            position: [(r * d[0]) as f32, (r * d[1]) as f32, (r * d[2]) as f32],
            radial_velocity: vr as f32,
        });
        is_static.push(!outlier);
    }
    (dets, is_static)
}

/// The synthetic points have exact directions: no direction-error allowance.
fn cfg() -> Config {
    Config {
        sigma: SIGMA,
        direction_sigma: 0.0,
        ..Config::default()
    }
}

/// Squared Mahalanobis distance of the error under the estimate's covariance.
fn nees(est: &milliego_odometry::ego_velocity::Estimate, v: [f64; 3]) -> f64 {
    let e = nalgebra::Vector3::new(
        f64::from(est.velocity[0]) - v[0],
        f64::from(est.velocity[1]) - v[1],
        f64::from(est.velocity[2]) - v[2],
    );
    let c = nalgebra::Matrix3::from_fn(|r, k| f64::from(est.covariance[r][k]));
    let ci = c.try_inverse().expect("covariance invertible");
    (e.transpose() * ci * e)[(0, 0)]
}

#[test]
fn accurate_and_consistent_under_heavy_outliers() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut est = EgoVelocityEstimator::new(cfg());
    for outliers in [0.5, 0.65, 0.8] {
        let mut nees_sum = 0.0;
        let trials = 200;
        for _ in 0..trials {
            let v = [
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.5..1.5),
                rng.gen_range(-0.3..0.3),
            ];
            let (dets, is_static) = frame(&mut rng, v, 120, outliers, 20.0);
            let e = est.estimate(&dets);
            assert!(e.is_ok(), "{:?} at {outliers}", e.status);
            let n_static = is_static.iter().filter(|s| **s).count();
            let hits = e
                .inlier_mask
                .iter()
                .zip(&is_static)
                .filter(|(m, s)| **m && **s)
                .count();
            assert!(
                hits as f64 >= 0.8 * n_static as f64,
                "found {hits} of {n_static} static points"
            );
            let err = ((f64::from(e.velocity[0]) - v[0]).powi(2)
                + (f64::from(e.velocity[1]) - v[1]).powi(2))
            .sqrt();
            assert!(
                err < 0.1,
                "planar speed error {err} m/s at outlier share {outliers}"
            );
            nees_sum += nees(&e, v);
        }
        let mean = nees_sum / f64::from(trials);
        // 3 degrees of freedom: a consistent covariance gives a mean NEES near 3.
        assert!(
            (1.5..6.0).contains(&mean),
            "mean NEES {mean} at outlier share {outliers}"
        );
    }
}

#[test]
fn planar_points_are_degenerate_in_3d_and_fine_in_planar_mode() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let v = [0.3, 1.2, 0.0];
    let (dets, _) = frame(&mut rng, v, 60, 0.3, 0.0);
    let e = EgoVelocityEstimator::new(cfg()).estimate(&dets);
    match e.status {
        Status::Degenerate {
            weak_direction,
            spread,
        } => {
            assert!(
                weak_direction[2].abs() > 0.99,
                "weak direction should be z: {weak_direction:?}"
            );
            assert!(spread < 1e-6);
        }
        other => panic!("expected degenerate, got {other:?}"),
    }
    let e = EgoVelocityEstimator::new(Config {
        model: Model::Planar,
        ..cfg()
    })
    .estimate(&dets);
    assert!(e.is_ok(), "{:?}", e.status);
    assert!((f64::from(e.velocity[1]) - 1.2).abs() < 0.05 && e.velocity[2] == 0.0);
}

#[test]
fn narrow_azimuth_spread_is_degenerate() {
    // Every point straight ahead: only the boresight component is observable.
    let dets: Vec<Detection> = (0..30)
        .map(|i| Detection {
            position: [0.0, 1.0 + i as f32 * 0.2, 0.0],
            radial_velocity: -0.5,
        })
        .collect();
    let e = EgoVelocityEstimator::new(Config {
        model: Model::Planar,
        ..cfg()
    })
    .estimate(&dets);
    assert!(
        matches!(e.status, Status::Degenerate { .. }),
        "{:?}",
        e.status
    );
}

#[test]
fn too_few_points_and_no_consensus_are_reported() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (dets, _) = frame(&mut rng, [0.0, 1.0, 0.0], 4, 0.0, 20.0);
    let e = EgoVelocityEstimator::new(cfg()).estimate(&dets);
    assert_eq!(e.status, Status::TooFewPoints { usable: 4, need: 5 });
    let (dets, _) = frame(&mut rng, [0.0, 1.0, 0.0], 60, 1.0, 20.0);
    let e = EgoVelocityEstimator::new(Config {
        min_inlier_share: 0.5,
        ..cfg()
    })
    .estimate(&dets);
    assert!(
        matches!(e.status, Status::NoConsensus { .. }),
        "{:?}",
        e.status
    );
}

#[test]
fn points_without_direction_are_skipped_and_counted() {
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let (mut dets, _) = frame(&mut rng, [0.2, 0.8, 0.0], 50, 0.2, 20.0);
    dets.push(Detection {
        position: [0.0, 0.0, 0.0],
        radial_velocity: 0.0,
    });
    dets.push(Detection {
        position: [f32::NAN, 1.0, 0.0],
        radial_velocity: 0.0,
    });
    let e = EgoVelocityEstimator::new(cfg()).estimate(&dets);
    assert!(e.is_ok());
    assert_eq!((e.skipped, e.usable), (2, 50));
    assert!(!e.inlier_mask[50] && !e.inlier_mask[51]);
}

#[test]
fn deterministic_for_a_seed() {
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (dets, _) = frame(&mut rng, [0.5, 0.5, 0.1], 80, 0.7, 20.0);
    let a = EgoVelocityEstimator::new(cfg()).estimate(&dets);
    let b = EgoVelocityEstimator::new(cfg()).estimate(&dets);
    assert_eq!(a, b);
}

#[test]
fn estimating_into_a_reused_estimate_gives_the_same_results() {
    // One estimator and one estimate reused over frames of every outcome (ok, too few points,
    // no consensus, sizes up and down) against a fresh estimator per frame.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut reused = EgoVelocityEstimator::new(cfg());
    let mut est = reused.estimate(&[]);
    for (n, outliers) in [
        (80, 0.5),
        (3, 0.0),
        (120, 0.7),
        (40, 0.95),
        (60, 0.2),
        (10, 0.0),
    ] {
        let (dets, _) = frame(&mut rng, [0.4, -0.3, 0.05], n, outliers, 20.0);
        reused.estimate_guided_into(&dets, None, &mut est);
        let fresh = EgoVelocityEstimator::new(cfg()).estimate(&dets);
        assert_eq!(est, fresh, "{n} points, {outliers} outliers");
    }
}

#[test]
fn a_prior_picks_the_static_world_over_a_larger_coherent_ghost_set() {
    // 12 static points moving with v, 25 ghosts coherent with a mirrored velocity: unguided RANSAC
    // takes the ghosts, the filter's prior picks the world.
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let v = [0.1, 1.2, 0.0];
    let ghost_v = [-1.1, -0.4, 0.2];
    let (mut dets, _) = frame(&mut rng, v, 12, 0.0, 20.0);
    let (ghosts, _) = frame(&mut rng, ghost_v, 25, 0.0, 20.0);
    dets.extend(ghosts);
    let mut est = EgoVelocityEstimator::new(cfg());
    let free = est.estimate(&dets);
    assert!(
        (f64::from(free.velocity[0]) - ghost_v[0]).abs() < 0.1,
        "unguided follows the larger set: {:?}",
        free.velocity
    );
    let c = 0.05;
    let prior = milliego_odometry::ego_velocity::Prior {
        velocity: [0.0, 1.1, 0.0],
        covariance: [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, c]],
        gate: 16.27,
    };
    let guided = est.estimate_guided(&dets, Some(prior));
    assert!(guided.is_ok());
    assert!(
        (f64::from(guided.velocity[1]) - v[1]).abs() < 0.05,
        "guided: {:?}",
        guided.velocity
    );
    assert_eq!(guided.inlier_mask[..12].iter().filter(|m| **m).count(), 12);
}

#[test]
fn weights_pick_the_points_seen_again_over_a_larger_set_seen_once() {
    // 8 static points (seen again: weight 1) and 14 ghosts coherent with another velocity (seen
    // once: weight 0.25). Unweighted, the ghosts win; weighted, the world does.
    let mut rng = ChaCha8Rng::seed_from_u64(78);
    let v = [0.2, 1.1, 0.0];
    let ghost_v = [-0.9, 0.3, 0.1];
    let (mut dets, _) = frame(&mut rng, v, 8, 0.0, 45.0);
    let (ghosts, _) = frame(&mut rng, ghost_v, 14, 0.0, 45.0);
    dets.extend(ghosts);
    let mut weights = vec![1.0f32; 8];
    weights.extend([0.25f32; 14]);
    let mut est = EgoVelocityEstimator::new(cfg());
    let mut out = Estimate::with_capacity(dets.len());
    est.estimate_weighted_into(&dets, None, None, &mut out);
    assert!(
        (f64::from(out.velocity[0]) - ghost_v[0]).abs() < 0.1,
        "unweighted follows the larger set: {:?}",
        out.velocity
    );
    est.estimate_weighted_into(&dets, Some(&weights), None, &mut out);
    assert!(out.is_ok(), "{:?}", out.status);
    for (got, want) in out.velocity.iter().zip(v) {
        assert!(
            (f64::from(*got) - want).abs() < 0.2,
            "weighted: {:?}",
            out.velocity
        );
    }
    // Every static point, and at most a ghost that happens to fit (this seed has one).
    assert!((8..=9).contains(&out.inliers), "{}", out.inliers);
    assert!(out.inlier_mask[..8].iter().all(|m| *m));
    // Equal weights change nothing.
    let ones = vec![1.0f32; dets.len()];
    let plain = est.estimate(&dets);
    est.estimate_weighted_into(&dets, Some(&ones), None, &mut out);
    assert_eq!(out, plain);
    // Missing (a short slice) and non-finite weights count 1.
    let mut odd = weights.clone();
    odd[8] = f32::NAN;
    est.estimate_weighted_into(&dets, Some(&odd[..20]), None, &mut out);
    assert!(out.is_ok());
}

#[test]
fn a_coarse_doppler_step_at_low_speed_widens_the_covariance_to_the_rounding_it_cannot_average() {
    // A slow radar (0.1-0.3 m/s) with 0.38 m/s Doppler steps and little noise: most static points
    // read 0 or one step, and the rounding errors of a frame's points are nearly the same function
    // of the velocity, so they do not average out over the points. A covariance that divides the
    // rounding by the point count claims a precision the frame does not have.
    let step = 0.38f32;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let quantised = |dets: &mut Vec<Detection>| {
        for d in dets.iter_mut() {
            d.radial_velocity = (d.radial_velocity / step).round() * step;
        }
    };
    let mut coarse = EgoVelocityEstimator::new(cfg().with_velocity_resolution(f64::from(step)));
    let (mut nees_sum, mut n) = (0.0, 0);
    for _ in 0..300 {
        let speed = rng.gen_range(0.1..0.3);
        let az: f64 = rng.gen_range(-1.0..1.0);
        let v = [speed * az.sin(), speed * az.cos(), 0.0];
        let (mut dets, _) = frame(&mut rng, v, 40, 0.0, 20.0);
        quantised(&mut dets);
        let e = coarse.estimate(&dets);
        if e.is_ok() {
            nees_sum += nees(&e, v);
            n += 1;
        }
    }
    assert!(n > 200, "{n} of 300 frames gave a velocity");
    let mean = nees_sum / f64::from(n);
    assert!(
        (0.5..6.0).contains(&mean),
        "mean NEES {mean} over {n} slow coarse frames (3 is consistent)"
    );

    // Fast motion dithers the rounding: the covariance keeps the per-point rounding deviation
    // (step / sqrt(12)) divided over the points, as for fine steps.
    let fast = [0.6, 1.3, 0.1];
    let (mut dets, _) = frame(&mut rng, fast, 40, 0.0, 20.0);
    for d in dets.iter_mut() {
        d.radial_velocity += rng.gen_range(-0.3f32..0.3);
    }
    quantised(&mut dets);
    let mut dithered = EgoVelocityEstimator::new(Config {
        direction_sigma: 0.3,
        ..cfg().with_velocity_resolution(f64::from(step))
    });
    let e = dithered.estimate(&dets);
    assert!(e.is_ok(), "{:?}", e.status);
    let mut plain = EgoVelocityEstimator::new(Config {
        direction_sigma: 0.3,
        quantisation_correlation: false,
        ..cfg().with_velocity_resolution(f64::from(step))
    });
    let p = plain.estimate(&dets);
    let ratio = f64::from(e.covariance[1][1]) / f64::from(p.covariance[1][1]);
    assert!(
        (1.0..1.05).contains(&ratio),
        "dithered frame's forward variance {ratio}x the independent-rounding one"
    );
}

#[test]
fn the_rounding_a_coarse_step_shares_is_reported_apart_and_not_counted_twice() {
    // A radar at 0.15 m/s under 0.46 m/s steps: every static point reads 0, the frame says
    // "at rest" and its error is the whole velocity. That error is the rounding the points share.
    let step = 0.46f32;
    let v = [0.05, 0.14, 0.0];
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (mut dets, _) = frame(&mut rng, v, 20, 0.0, 20.0);
    for d in dets.iter_mut() {
        d.radial_velocity = (d.radial_velocity / step).round() * step;
    }
    assert!(dets.iter().all(|d| d.radial_velocity == 0.0));
    let coarse = cfg().with_velocity_resolution(f64::from(step));
    let e = EgoVelocityEstimator::new(coarse).estimate(&dets);
    assert!(e.is_ok(), "{:?}", e.status);
    let tr = |m: &[[f32; 3]; 3]| (0..3).map(|k| f64::from(m[k][k])).sum::<f64>();
    let white: Vec<f64> = (0..3)
        .map(|k| f64::from(e.covariance[k][k] - e.shared_covariance[k][k]))
        .collect();
    assert!(white.iter().all(|&w| w >= 0.0), "{white:?}");
    // The total still covers the error.
    assert!(nees(&e, v) < 16.27, "NEES {}", nees(&e, v));
    // Apart from the shared part, a point's rounding counts only as far as the Doppler noise
    // dithers it: the rest is what the Doppler noise gives, well below the rounding taken as
    // independent per point (the estimate without the shared part).
    let independent = EgoVelocityEstimator::new(Config {
        quantisation_correlation: false,
        ..coarse
    })
    .estimate(&dets);
    let ratio = white.iter().sum::<f64>() / tr(&independent.covariance);
    assert!(
        ratio < 0.5,
        "white part {ratio}x the independent-rounding covariance"
    );
    assert!(tr(&e.shared_covariance) > 10.0 * white.iter().sum::<f64>());
    // Continuous Doppler shares nothing.
    let fine = EgoVelocityEstimator::new(cfg()).estimate(&frame(&mut rng, v, 20, 0.0, 20.0).0);
    assert!(fine.is_ok());
    assert_eq!(fine.shared_covariance, [[0.0; 3]; 3]);
}

#[test]
fn the_rounding_likelihood_reads_a_slow_robot_closer_and_knows_its_uncertainty() {
    // A robot at 0.2-0.45 m/s under 0.26 m/s steps with 0.04 m/s noise: each static point reads
    // 0 or one step. Least squares takes the readings as radial velocities; the likelihood of
    // the rounded readings knows which radial velocities round to them.
    let step = 0.26f32;
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let coarse = cfg().with_velocity_resolution(f64::from(step));
    let mut ls = EgoVelocityEstimator::new(coarse);
    let mut ml = EgoVelocityEstimator::new(Config {
        rounding_likelihood: true,
        ..coarse
    });
    let (mut ls_sq, mut ml_sq, mut ml_nees, mut n) = (0.0, 0.0, 0.0, 0);
    for _ in 0..300 {
        let speed = rng.gen_range(0.2..0.45);
        let v = [0.0, speed, 0.0];
        let (mut dets, _) = frame(&mut rng, v, 60, 0.0, 20.0);
        for d in dets.iter_mut() {
            d.radial_velocity = (d.radial_velocity / step).round() * step;
        }
        let (a, b) = (ls.estimate(&dets), ml.estimate(&dets));
        if a.is_ok() && b.is_ok() {
            // Forward speed errors.
            ls_sq += (f64::from(a.velocity[1]) - speed).powi(2);
            ml_sq += (f64::from(b.velocity[1]) - speed).powi(2);
            ml_nees += nees(&b, v);
            n += 1;
        }
    }
    assert!(n > 250, "{n} of 300 frames gave both velocities");
    let (ls_rms, ml_rms) = ((ls_sq / f64::from(n)).sqrt(), (ml_sq / f64::from(n)).sqrt());
    assert!(
        ml_rms < 0.6 * ls_rms,
        "forward speed error {ml_rms:.3} m/s rms against least squares' {ls_rms:.3}"
    );
    let mean_nees = ml_nees / f64::from(n);
    // Its covariance covers its error (the larger of the likelihood's and the least squares').
    assert!(
        mean_nees < 6.0,
        "likelihood's mean NEES {mean_nees} (3 is consistent, below is cautious)"
    );
    // Continuous Doppler (nothing rounded): the least squares as it is.
    let (dets, _) = frame(&mut rng, [0.3, 1.0, 0.0], 30, 0.0, 20.0);
    assert_eq!(
        EgoVelocityEstimator::new(Config {
            rounding_likelihood: true,
            ..cfg()
        })
        .estimate(&dets),
        EgoVelocityEstimator::new(cfg()).estimate(&dets)
    );
}
