//! Classical odometry end to end on simulated sessions: the simulator writes a session, the
//! offline runner decodes both streams, fits the clocks and runs Doppler RIO and IMU dead
//! reckoning, and the evaluation scores both against ground truth.

use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_odometry::offline::{run, Estimator, OfflineConfig, TimeOffsetMode};
use milliego_session::Session;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;

fn ate(
    session: &Session,
    estimator: Estimator,
) -> (f64, f64, milliego_odometry::offline::OfflineResult) {
    let cfg = OfflineConfig {
        estimator,
        ..OfflineConfig::default()
    };
    let r = run(session, &cfg).expect("offline run");
    let gt = Trajectory::from_tum(&session.groundtruth().unwrap().expect("ground truth"));
    let rep = evaluate(
        &gt,
        &Trajectory::from_tum(&r.trajectory),
        &Settings::default(),
    )
    .expect("evaluation");
    (rep.ate.rmse, rep.path_length, r)
}

#[test]
fn doppler_rio_beats_dead_reckoning_by_far_on_simulated_walks() {
    // (world, motion, seed, duration [s], at least this many times better than dead reckoning,
    // ATE at most this share of the path). The slow planar robot gives Doppler the least to work
    // with (its velocity is small against the Doppler noise).
    let cases = [
        (Family::Office, MotionKind::Handheld, 3, 20.0, 10.0, 0.03),
        (Family::Corridor, MotionKind::Robot, 5, 40.0, 2.0, 0.04),
    ];
    for (family, motion, seed, duration, margin, share) in cases {
        let dir = tempfile::tempdir().unwrap();
        let mut sc = Scenario::new(family, motion, seed);
        sc.duration_s = duration;
        simulate(&sc, dir.path(), &mut |_| {}).expect("simulate");
        let s = Session::open(dir.path()).unwrap();
        let (rio, path, r) = ate(&s, Estimator::Doppler);
        let (dr, _, _) = ate(&s, Estimator::ImuOnly);
        println!("{family:?}/{motion:?}/{seed}: path {path:.1} m, Doppler RIO ATE {rio:.3} m, IMU-only {dr:.2} m, ego ok {} of {}, gated {}", r.ego_ok, r.radar_frames, r.gated);
        assert!(
            !r.clock_unsynced,
            "indexed sessions put both streams on one clock"
        );
        assert_eq!(r.radar.bad + r.imu.bad, 0);
        assert!(
            r.ego_ok * 10 >= r.radar_frames * 8,
            "ego-velocity on at least 80% of frames"
        );
        assert!(
            rio < (share * path).max(0.25),
            "RIO ATE {rio:.3} m over {path:.1} m"
        );
        assert!(rio * margin < dr, "RIO {rio:.3} m vs IMU-only {dr:.2} m");
        // The clock fits recover the simulated drift (ppm) of each sensor relative to the host.
        let truth = s.meta.clock.expect("clock truth");
        let fit_ppm = |rate: f64| (1.0 / rate - 1.0) * 1e6;
        assert!((fit_ppm(r.radar_clock.unwrap().rate) - truth.radar_drift_ppm).abs() < 5.0);
        assert!((fit_ppm(r.imu_clock.unwrap().rate) - truth.imu_drift_ppm).abs() < 5.0);
    }
}

/// Simulates `sc` into a temporary directory (kept alive by the returned guard) and opens it.
fn simulated(sc: &Scenario) -> (tempfile::TempDir, Session) {
    let dir = tempfile::tempdir().unwrap();
    simulate(sc, dir.path(), &mut |_| {}).expect("simulate");
    let s = Session::open(dir.path()).unwrap();
    (dir, s)
}

/// Doppler RIO over `s` with rest detection on or off.
fn rio_run(s: &Session, rest: bool) -> milliego_odometry::offline::OfflineResult {
    let mut cfg = OfflineConfig::default();
    cfg.rest.enabled = rest;
    run(s, &cfg).expect("offline run")
}

/// Largest distance of the trajectory's positions from its first one \[m\] over `from..to` \[s\].
fn wander(r: &milliego_odometry::offline::OfflineResult, from: f64, to: f64) -> f64 {
    let inside: Vec<_> = r
        .trajectory
        .iter()
        .filter(|p| p.t >= from && p.t <= to)
        .collect();
    let Some(first) = inside.first() else {
        return f64::INFINITY;
    };
    inside
        .iter()
        .map(|p| {
            let d: [f64; 3] = std::array::from_fn(|k| p.p[k] - first.p[k]);
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_static_session_drifts_under_a_centimetre() {
    let mut sc = Scenario::new(Family::Office, MotionKind::Static, 21);
    sc.duration_s = 30.0;
    let (_dir, s) = simulated(&sc);
    let on = rio_run(&s, true);
    let off = rio_run(&s, false);
    let (d_on, d_off) = (wander(&on, 0.0, 1e9), wander(&off, 0.0, 1e9));
    println!(
        "static 30 s: drift {:.2} mm with rest updates ({} rest samples of {}, {} updates), {:.2} mm without",
        d_on * 1e3,
        on.rest_samples,
        on.imu_samples,
        on.rest_updates,
        d_off * 1e3
    );
    assert!(d_on < 0.01, "static session drifted {d_on:.4} m");
    // Rest is found after the first window (0.5 s) and a radar frame.
    assert!(on.rest_samples as f64 > 0.9 * on.imu_samples as f64);
    assert_eq!(off.rest_samples, 0, "rest detection off means off");
}

#[test]
fn rests_are_found_only_at_rest_and_hold_the_pose_there() {
    // Rest 8 s, walk, rest 6 s: the ends of the track must not drift, and the walk itself is never
    // taken for rest (the first sample at rest is in the first rest, the last in the last).
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 8);
    sc.duration_s = 40.0;
    sc.rest_start_s = 8.0;
    sc.rest_end_s = 6.0;
    let (_dir, s) = simulated(&sc);
    let on = rio_run(&s, true);
    let off = rio_run(&s, false);
    let gt = s.groundtruth().unwrap().expect("ground truth");
    let t0 = gt.first().unwrap().t;
    let end_rest = (t0 + 34.5, t0 + 39.5);
    let (a_on, a_off) = (ate_of(&s, &on.trajectory), ate_of(&s, &off.trajectory));
    let (w_on, w_off) = (
        wander(&on, end_rest.0, end_rest.1),
        wander(&off, end_rest.0, end_rest.1),
    );
    println!(
        "rest 8 s + walk + rest 6 s: ATE {a_on:.3} m with rest updates ({} rest samples), {a_off:.3} m without; \
         wander in the final rest {:.2} mm vs {:.2} mm",
        on.rest_samples,
        w_on * 1e3,
        w_off * 1e3
    );
    assert!(w_on < 0.01, "the final rest wandered {w_on:.4} m");
    // Rest samples: at most the two rests' IMU samples (200 Hz), at least most of them.
    let rest_max = (8.0 + 6.0) * 200.0;
    assert!(
        (on.rest_samples as f64) < rest_max && (on.rest_samples as f64) > 0.7 * rest_max,
        "{} rest samples for 14 s of rest",
        on.rest_samples
    );
    assert!(
        a_on <= a_off * 1.05 + 0.01,
        "rest updates made ATE worse: {a_on:.3} vs {a_off:.3} m"
    );
}

#[test]
fn a_robot_that_stops_under_coarse_doppler_comes_to_rest_even_after_a_refuted_rest() {
    // A corridor robot in 0.26 m/s Doppler steps stops for its last 6 s. Each frame then reads 0,
    // as it did at 0.1 m/s, and the filter, with a decimetre per second left over from the stop,
    // refutes the rest. The frames must then reach the filter (before, they were dropped as
    // "at rest" while the refuted rest applied nothing, and the robot drove on through its rest:
    // 0.51-0.92 m on these seeds, 0.72 m on average), and the rest must begin again once they
    // have brought the velocity to zero (0.12-0.32 m, 0.22 m on average, with both).
    let (mut refuted, mut sum) = (0, 0.0);
    for seed in [1, 4, 6] {
        let mut sc = Scenario::new(Family::Corridor, MotionKind::Robot, seed);
        sc.duration_s = 40.0;
        sc.rest_start_s = 3.0;
        sc.rest_end_s = 6.0;
        sc.doppler_step_mps = 0.26;
        let (_dir, s) = simulated(&sc);
        let r = rio_run(&s, true);
        let t0 = s.groundtruth().unwrap().expect("ground truth")[0].t;
        let w = wander(&r, t0 + 34.5, t0 + 39.5);
        println!(
            "seed {seed}: wander in the final rest {:.0} mm, {} rests refuted, {} rest samples",
            w * 1e3,
            r.rest_refuted,
            r.rest_samples
        );
        refuted += r.rest_refuted;
        sum += w;
        // Rest found again: beyond the 3 s start (600 samples at 200 Hz), at least half of the
        // final 6 s (without the retry: 630-700 samples in all).
        assert!(
            r.rest_samples > 600 + 600,
            "seed {seed}: {} rest samples, the final rest was not found again",
            r.rest_samples
        );
    }
    assert!(refuted > 0, "the runs exercise a refuted rest");
    let mean = sum / 3.0;
    assert!(
        mean < 0.4,
        "the robots moved {mean:.2} m on average in their final rest"
    );
}

#[test]
fn a_cruising_robot_is_never_taken_for_at_rest() {
    // Smooth planar motion at 0.2-0.6 m/s: the IMU is as still as at rest, the Doppler is not.
    let mut sc = Scenario::new(Family::Corridor, MotionKind::Robot, 5);
    sc.duration_s = 30.0;
    let (_dir, s) = simulated(&sc);
    let on = rio_run(&s, true);
    let off = rio_run(&s, false);
    println!("robot: {} rest samples", on.rest_samples);
    assert_eq!(on.rest_samples, 0);
    assert_eq!(on.trajectory, off.trajectory, "no rest, no change");
}

/// Largest height difference from the first pose \[m\].
fn height_wander(poses: &[milliego_session::TumPose]) -> f64 {
    let z0 = poses.first().map_or(0.0, |p| p.p[2]);
    poses
        .iter()
        .map(|p| (p.p[2] - z0).abs())
        .fold(0.0, f64::max)
}

fn ate_of(s: &Session, est: &[milliego_session::TumPose]) -> f64 {
    ate_and_path(s, est).0
}

/// ATE RMSE of `est` against the session's ground truth and the truth's path length \[m\].
fn ate_and_path(s: &Session, est: &[milliego_session::TumPose]) -> (f64, f64) {
    let gt = Trajectory::from_tum(&s.groundtruth().unwrap().expect("ground truth"));
    let rep = evaluate(&gt, &Trajectory::from_tum(est), &Settings::default()).expect("evaluation");
    (rep.ate.rmse, rep.path_length)
}

/// World heading error \[rad\] of `est` against the session's ground truth at each estimated
/// pose, after putting the estimate's first pose onto the truth's (the estimate starts at yaw 0).
fn heading_errors(s: &Session, est: &[milliego_session::TumPose]) -> Vec<f64> {
    use nalgebra::{Quaternion, UnitQuaternion};
    let gt = s.groundtruth().unwrap().expect("ground truth");
    let q = |p: &milliego_session::TumPose| {
        UnitQuaternion::from_quaternion(Quaternion::new(p.q[3], p.q[0], p.q[1], p.q[2]))
    };
    let at = |t: f64| {
        let i = gt.partition_point(|g| g.t < t).min(gt.len() - 1);
        q(&gt[i])
    };
    let align = at(est[0].t) * q(&est[0]).inverse();
    est.iter()
        .map(|p| {
            let d = align * q(p) * at(p.t).inverse();
            // Yaw of the residual rotation about the world vertical.
            let v = d * nalgebra::Vector3::x();
            v.y.atan2(v.x)
        })
        .collect()
}

/// Largest absolute heading error of `poses` \[deg\] ([`heading_errors`]).
fn worst(s: &Session, poses: &[milliego_session::TumPose]) -> f64 {
    heading_errors(s, poses)
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .to_degrees()
}

/// Doppler RIO with the defaults over `s`, with its worst heading error and the gyro alone's
/// (IMU dead reckoning) \[deg\].
fn headings_against_the_gyro(s: &Session) -> (milliego_odometry::offline::OfflineResult, f64, f64) {
    let rio = run(s, &OfflineConfig::default()).expect("offline run");
    let gyro = run(
        s,
        &OfflineConfig {
            estimator: Estimator::ImuOnly,
            ..OfflineConfig::default()
        },
    )
    .expect("offline run");
    let (h_rio, h_gyro) = (worst(s, &rio.trajectory), worst(s, &gyro.trajectory));
    (rio, h_rio, h_gyro)
}

#[test]
fn a_far_yawed_tilted_radar_never_makes_the_heading_worse_than_the_gyro() {
    // The rig that broke heading on real data: radar 1.1 m ahead of the IMU, yawed 30 deg,
    // tilted 25 deg up. Doppler RIO's heading must stay within 1 deg of the gyro alone's worst.
    for (motion, seed) in [(MotionKind::Robot, 3), (MotionKind::Handheld, 3)] {
        let mut sc = Scenario::new(Family::Office, motion, seed);
        sc.duration_s = 60.0;
        sc.radar_lever_m = Some([1.1, 0.0, 0.0]);
        sc.radar_yaw_deg = 30.0;
        sc.radar_tilt_deg = 25.0;
        let (_dir, s) = simulated(&sc);
        let (rio, h_rio, h_gyro) = headings_against_the_gyro(&s);
        let mut old = OfflineConfig::default();
        old.rio.radar_heading = true;
        let h_old = worst(&s, &run(&s, &old).expect("offline run").trajectory);
        // Points seen again (weighed by default) change which points vote, not what may
        // correct the heading: with every point weighing the same the bound holds too (it did
        // not hold with them weighed while the vertical velocity bound's gain could turn the
        // heading: 3.3 deg on the handheld).
        assert!(OfflineConfig::default().persist.enabled());
        let mut seen_again = OfflineConfig::default();
        seen_again.persist.window_s = 0.0;
        let h_seen = worst(&s, &run(&s, &seen_again).expect("offline run").trajectory);
        let path = ate(&s, Estimator::Doppler).1;
        println!(
            "{motion:?} mounted 1.1 m ahead, yawed 30, tilted 25: worst heading error Doppler RIO {h_rio:.2} deg (every point weighing the same: {h_seen:.2} deg; radar correcting heading: {h_old:.2} deg), gyro alone {h_gyro:.2} deg, ATE {:.3} m over {path:.1} m",
            ate_of(&s, &rio.trajectory)
        );
        assert!(
            h_rio <= h_gyro + 1.0,
            "{motion:?}: heading {h_rio:.2} deg vs gyro {h_gyro:.2} deg"
        );
        assert!(
            h_seen <= h_gyro + 1.0,
            "{motion:?}, every point weighing the same: heading {h_seen:.2} deg vs gyro {h_gyro:.2} deg"
        );
        // Position stays usable (the handheld radar keeps under 9 points a frame on this mount).
        assert!(ate_of(&s, &rio.trajectory) < 0.1 * path);
    }
}

#[test]
fn a_robot_starting_in_a_gentle_turn_unseen_by_the_radar_keeps_the_gyros_heading() {
    // This corridor robot starts at 0.56 m/s in a 0.045 rad/s turn (under the stillness test's
    // 0.05 rad/s), and its first frames hold 5 points each, none at zero Doppler, too few for a
    // velocity: nothing contradicts the rest the session is assumed to start in for 0.55 s. Its
    // rates must not become gyroscope bias (with the 0.5 s margin of a confirmed rest they did:
    // 1.7 deg/s of heading drift, 100 deg by the end; the gyro alone stays within 1 deg).
    let mut sc = Scenario::new(Family::Corridor, MotionKind::Robot, 3);
    sc.duration_s = 60.0;
    let (_dir, s) = simulated(&sc);
    let (rio, h_rio, h_gyro) = headings_against_the_gyro(&s);
    println!(
        "robot starting in a turn: worst heading error {h_rio:.2} deg, gyro alone {h_gyro:.2} deg, {} rest samples",
        rio.rest_samples
    );
    assert!(
        rio.rest_samples > 0,
        "the start is taken for rest (the case under test)"
    );
    assert!(
        h_rio <= h_gyro + 2.0,
        "heading {h_rio:.2} deg vs the gyro's {h_gyro:.2} deg"
    );
}

#[test]
fn leakage_and_coarse_doppler_do_not_let_the_vertical_velocity_run_away() {
    // A sparse outdoor drive-like walk: few real points beyond 1 m, a quarter of the points
    // zero-Doppler leakage within 1 m, Doppler in 0.49 m/s steps. Height stays bounded.
    let mut sc = Scenario::new(Family::Outdoor, MotionKind::Handheld, 4);
    sc.duration_s = 60.0;
    sc.near_field_share = 0.24;
    sc.doppler_step_mps = 0.49;
    let (_dir, s) = simulated(&sc);
    let mut cfg = OfflineConfig::default();
    cfg.ego.doppler_step = 0.49;
    cfg.doppler_step_from_cfg = false;
    cfg.ego.near_field_m = 1.0;
    let r = run(&s, &cfg).expect("offline run");
    let dz = height_wander(&r.trajectory);
    let gz = height_wander(&s.groundtruth().unwrap().expect("ground truth"));
    println!(
        "outdoor, leakage 24%, Doppler step 0.49 m/s: height wander {dz:.2} m (truth {gz:.2} m), {} vertical bounds, {} near-field points not voting, ego ok {} of {}",
        r.vertical_bounds, r.near_field_points, r.ego_ok, r.radar_frames
    );
    assert!(r.near_field_points > 0, "leakage is seen");
    assert!(dz < gz + 2.0, "height ran away: {dz:.2} m");
}

#[test]
fn a_barometer_carries_the_height_through_a_climb_the_radar_cannot_see() {
    // A 5 m climb with a consumer MEMS IMU: the radar's narrow elevation field barely sees
    // vertical motion, the barometer (MTData2 BaroPressure in the IMU stream) does.
    let mut sc = Scenario::new(Family::Atrium, MotionKind::Handheld, 5);
    sc.duration_s = 60.0;
    sc.height_change_m = 5.0;
    sc.baro_hz = 50.0;
    sc.imu_spec = milliego_sim::imu::ImuGrade::Mems.spec();
    let (_dir, s) = simulated(&sc);
    let gt = s.groundtruth().unwrap().expect("ground truth");
    let z_error = |r: &milliego_odometry::offline::OfflineResult| {
        let (e0, g0) = (r.trajectory[0].p[2], gt[0].p[2]);
        r.trajectory
            .iter()
            .map(|p| {
                let i = gt.partition_point(|g| g.t < p.t).min(gt.len() - 1);
                ((p.p[2] - e0) - (gt[i].p[2] - g0)).abs()
            })
            .fold(0.0, f64::max)
    };
    let with = run(&s, &OfflineConfig::default()).expect("offline run");
    let without = run(
        &s,
        &OfflineConfig {
            use_barometer: false,
            ..OfflineConfig::default()
        },
    )
    .expect("offline run");
    let (e_with, e_without) = (z_error(&with), z_error(&without));
    println!(
        "5 m climb: worst height error {e_with:.2} m with the barometer ({} of {} readings applied), {e_without:.2} m without",
        with.baro_updates, with.pressure_readings
    );
    assert_eq!(without.baro_updates, 0, "--no-barometer means none");
    assert!(with.pressure_readings > 2500, "50 Hz for 60 s");
    assert!(with.baro_updates * 10 > with.pressure_readings as u64 * 9);
    assert!(e_with < 0.5, "height error {e_with:.2} m with a barometer");
    assert!(e_without > 2.0 * e_with);
}

#[test]
fn the_radar_time_offset_is_estimated_where_the_stamps_are_not_trusted() {
    // Radar stamps 40 ms late (a host-stamped or bag-arrival-timed stream): the filter estimates
    // the offset from the Doppler updates. On handheld walks 40 ms (even 100 ms) of lateness
    // moves the ATE by less than seed-to-seed noise (over seeds 3-7 the estimate was better on
    // three, worse on two), so the ATE is only held to "no worse than not estimating".
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 3);
    sc.duration_s = 40.0;
    let (_dir, s) = simulated(&sc);
    let with = |shift: f64, mode: TimeOffsetMode| {
        let cfg = OfflineConfig {
            radar_time_shift_s: shift,
            time_offset: mode,
            ..OfflineConfig::default()
        };
        run(&s, &cfg).expect("offline run")
    };
    let auto = with(0.0, TimeOffsetMode::Auto);
    assert!(
        auto.time_offset.is_none(),
        "a simulated session's clocks are trusted"
    );
    let (o0, sd0, _) = with(0.0, TimeOffsetMode::Estimate(0.05))
        .time_offset
        .expect("estimated");
    let late = with(0.04, TimeOffsetMode::Off);
    let fixed = with(0.04, TimeOffsetMode::Estimate(0.05));
    let (o, sd, why) = fixed.time_offset.clone().expect("estimated");
    let (a_late, a_fixed, a_true) = (
        ate_of(&s, &late.trajectory),
        ate_of(&s, &fixed.trajectory),
        ate_of(&s, &auto.trajectory),
    );
    println!(
        "time offset: true stamps -> {:.1} +- {:.1} ms; stamps 40 ms late -> {:.1} +- {:.1} ms ({why}); ATE {a_fixed:.3} m estimated, {a_late:.3} m not, {a_true:.3} m with true stamps",
        o0 * 1e3,
        sd0 * 1e3,
        o * 1e3,
        sd * 1e3
    );
    assert!(o0.abs() < 0.01, "offset {o0} s where there is none");
    assert!((o + 0.04).abs() < 0.01, "offset {o} s, expected -0.04 s");
    assert!(sd < 0.01, "offset std {sd} s");
    assert!(a_fixed < a_late * 1.1 + 0.05, "{a_fixed} vs {a_late} m");
}

#[test]
fn a_ground_vehicle_constraint_keeps_a_car_on_its_track() {
    // A car outdoors (sparse returns): told it is a ground vehicle, the filter takes "no
    // sideways or vertical velocity" at each radar frame and ends closer to the truth.
    let mut sc = Scenario::new(Family::Outdoor, MotionKind::Vehicle, 2);
    sc.duration_s = 60.0;
    let (_dir, s) = simulated(&sc);
    let plain = run(&s, &OfflineConfig::default()).expect("offline run");
    let car = run(&s, &OfflineConfig::default().ground_vehicle()).expect("offline run");
    let (a_plain, a_car) = (ate_of(&s, &plain.trajectory), ate_of(&s, &car.trajectory));
    println!(
        "outdoor car: ATE {a_car:.2} m with the ground vehicle constraint ({} applied, {} gated), {a_plain:.2} m without",
        car.nonholonomic.0, car.nonholonomic.1
    );
    assert_eq!(plain.nonholonomic, (0, 0), "off unless asked");
    assert!(car.nonholonomic.0 > 1000);
    assert!(
        car.nonholonomic.1 * 20 < car.nonholonomic.0,
        "a car does not skid here"
    );
    assert!(a_car < a_plain, "{a_car:.2} vs {a_plain:.2} m");
}

#[test]
fn the_time_offset_uncertainty_is_consistent() {
    // NEES of the estimated radar time offset over walks, a robot and a head-worn rig, with true
    // and 40 ms late stamps: its reported deviation must cover its error (mean z^2 under the
    // chi-square(12)/12 99% bound, 2.18).
    let mut z2 = Vec::new();
    for (motion, seed) in [
        (MotionKind::Handheld, 1),
        (MotionKind::Handheld, 2),
        (MotionKind::Handheld, 4),
        (MotionKind::Robot, 1),
        (MotionKind::Headworn, 2),
        (MotionKind::Handheld, 6),
    ] {
        let mut sc = Scenario::new(Family::Office, motion, seed);
        sc.duration_s = 40.0;
        let (_dir, s) = simulated(&sc);
        for shift in [0.0, 0.04] {
            let cfg = OfflineConfig {
                radar_time_shift_s: shift,
                time_offset: TimeOffsetMode::Estimate(0.05),
                ..OfflineConfig::default()
            };
            let (o, sd, _) = run(&s, &cfg).unwrap().time_offset.expect("estimated");
            let z = (o + shift) / sd;
            println!(
                "{motion:?} seed {seed}, stamps {:.0} ms late: {:.1} +- {:.1} ms (z {z:.2})",
                shift * 1e3,
                o * 1e3,
                sd * 1e3
            );
            z2.push(z * z);
        }
    }
    let nees = z2.iter().sum::<f64>() / z2.len() as f64;
    println!("time offset NEES {nees:.2} over {} runs", z2.len());
    assert!(nees < 2.18, "time offset NEES {nees:.2}");
}

#[test]
fn near_field_leakage_is_read_from_the_points_and_only_where_there_is_some() {
    // A sixth of the points are leakage within 1 m at zero Doppler whatever the motion: they
    // pull each ego-velocity towards zero (the track comes out short). The runner finds them
    // against the filter's motion and leaves the near field out of the vote; without leakage
    // nothing is found and the run is the one with the test off, pose for pose.
    let (mut sum_found, mut sum_kept) = (0.0, 0.0);
    for (family, motion, seed) in [
        (Family::Corridor, MotionKind::Robot, 21),
        (Family::Office, MotionKind::Handheld, 22),
    ] {
        let mut sc = Scenario::new(family, motion, seed);
        sc.duration_s = 40.0;
        sc.near_field_share = 0.16;
        let (_dir, s) = simulated(&sc);
        let found = run(&s, &OfflineConfig::default()).expect("offline run");
        let mut off = OfflineConfig::default();
        off.ego.near_field_from_data = false;
        let kept = run(&s, &off).expect("offline run");
        let (range, learned) = found.near_field;
        let (tested, zero, leaks) = learned.expect("left to the data by default");
        let (a_found, a_kept) = (ate_of(&s, &found.trajectory), ate_of(&s, &kept.trajectory));
        println!(
            "{family:?}/{motion:?}/{seed}, 16% leakage: {zero} of {tested} tested near points at zero Doppler, near field {range} m, {} points not voting; ATE {a_found:.3} m against {a_kept:.3} m with every point voting",
            found.near_field_points
        );
        assert!(leaks && range == 1.0, "{:?}", found.near_field);
        assert!(found.near_field_points > 0);
        assert_eq!(kept.near_field, (0.0, None));
        assert_eq!(kept.near_field_points, 0);
        sum_found += a_found;
        sum_kept += a_kept;

        sc.near_field_share = 0.0;
        let (_dir, s) = simulated(&sc);
        let clean = run(&s, &OfflineConfig::default()).expect("offline run");
        let (range, learned) = clean.near_field;
        let (tested, zero, leaks) = learned.expect("left to the data by default");
        println!("  without leakage: {zero} of {tested} tested at zero Doppler");
        assert!(!leaks && range == 0.0, "{:?}", clean.near_field);
        assert!(tested > 0, "the test had points to judge");
        let off_run = run(&s, &off).expect("offline run");
        assert_eq!(clean.trajectory, off_run.trajectory);
    }
    assert!(
        sum_found < 0.8 * sum_kept,
        "{sum_found:.3} vs {sum_kept:.3} m over two sessions"
    );
}

#[test]
fn a_doppler_step_coarser_than_the_cfg_says_is_read_from_the_points() {
    // The radar reports Doppler in 0.42 m/s steps while its .cfg says 0.134 m/s bins (a
    // firmware that quantises coarser than its bins): a gate made for the .cfg's step rejects
    // most of the static world. The runner reads the step from the radial velocities: more
    // frames give a velocity, and the track is better over three walks (on one alone, the
    // spread from which points vote and which frames pass the gate is as large as the gain; with
    // points seen again weighed, the .cfg's step loses less than it did without).
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 3);
    sc.duration_s = 30.0;
    sc.doppler_step_mps = 0.42;
    let (mut sum_learned, mut sum_told) = (0.0, 0.0);
    for seed in 1..=3 {
        sc.seed = seed;
        let (_dir, s) = simulated(&sc);
        let learned = run(&s, &OfflineConfig::default()).expect("offline run");
        let mut cfg = OfflineConfig::default();
        cfg.ego.step_from_data = false;
        let told = run(&s, &cfg).expect("offline run");
        let (configured, seen) = learned.doppler_step;
        let (a_learned, a_told) = (
            ate_of(&s, &learned.trajectory),
            ate_of(&s, &told.trajectory),
        );
        println!(
            "office seed {seed}, Doppler in 0.42 m/s steps: .cfg step {configured:.3} m/s, seen {seen:?}; ego ok {} (step read) / {} (.cfg's) of {}; ATE {a_learned:.3} / {a_told:.3} m",
            learned.ego_ok, told.ego_ok, learned.radar_frames
        );
        assert!((configured - 0.134).abs() < 0.01, "{configured}");
        let seen = seen.expect("the step is seen");
        assert!((seen - 0.42).abs() < 1e-3, "{seen}");
        assert_eq!(told.doppler_step.1, None, "not read when turned off");
        assert!(learned.ego_ok > told.ego_ok, "seed {seed}");
        sum_learned += a_learned;
        sum_told += a_told;
    }
    assert!(
        sum_learned < sum_told,
        "{sum_learned:.3} vs {sum_told:.3} m over three walks"
    );
    sc.seed = 3;

    // Doppler on the .cfg's bins: the step read is the .cfg's.
    sc.doppler_step_mps = 0.0;
    let (_dir, s) = simulated(&sc);
    let r = run(&s, &OfflineConfig::default()).expect("offline run");
    let seen = r.doppler_step.1.expect("the bins are seen");
    assert!(
        (seen - r.doppler_step.0).abs() < 1e-3,
        "{:?}",
        r.doppler_step
    );
}

#[test]
fn lost_imu_samples_widen_the_velocity_so_the_barometer_holds_the_height() {
    // A headworn walk on a flat floor with a third of the IMU samples lost in bursts: across a
    // gap the integration draws the motion as a straight line, and a filter as sure of its
    // velocity after 0.2 s of missing samples as after one lets its vertical velocity go wrong
    // while the barometer's corrections go into the barometer bias (only their sum is seen).
    // The velocity variance grows with the missing time (`RioConfig::gap_accel_std`).
    for seed in [11, 12, 13] {
        let mut sc = Scenario::new(Family::StoreRoom, MotionKind::Headworn, seed);
        sc.duration_s = 60.0;
        sc.rest_start_s = 8.0;
        sc.imu_gap_share = 0.34;
        sc.baro_hz = 50.0;
        let (_dir, s) = simulated(&sc);
        let gz = height_wander(&s.groundtruth().unwrap().expect("ground truth"));
        let wander = |cfg: &OfflineConfig| {
            let r = run(&s, cfg).expect("offline run");
            (height_wander(&r.trajectory), r)
        };
        let (dz, r) = wander(&OfflineConfig::default());
        let mut off = OfflineConfig::default();
        off.rio.gap_accel_std = 0.0;
        let (dz_off, _) = wander(&off);
        println!(
            "seed {seed}: {} barometer readings, {} rejected, {} re-anchors; height wander {dz:.2} m ({dz_off:.2} m without the gap term; truth {gz:.2} m)",
            r.pressure_readings, r.baro_rejected, r.baro_reanchors
        );
        assert!(dz < gz + 0.5, "seed {seed}: height wandered {dz:.2} m");
    }
}

#[test]
fn a_robot_easing_into_a_turn_from_standstill_is_not_taken_for_gyro_bias() {
    // A robot that starts from standstill turning slowly: its first frames are at zero Doppler
    // and its IMU as still as at rest until the turn fills the stillness window, so the first
    // rest updates see the onset of the turn. Taken as gyroscope bias, that onset turns the
    // heading for the whole session (the radar cannot see heading): one validation session
    // drifted 1.1 deg/s. The zero-rate measurement waits until the rest has outlasted its rates
    // (`RestConfig::rate_margin_s`), so the heading is no worse than the gyro alone's.
    use milliego_sim::imu::ImuSpec;
    for seed in [1201, 11, 5] {
        let mut sc = Scenario::new(Family::Corridor, MotionKind::Robot, seed);
        sc.duration_s = 60.0;
        sc.rest_end_s = 5.3;
        sc.imu_spec = ImuSpec::mems();
        let (_dir, s) = simulated(&sc);
        // Mean heading error over the motion \[deg\] (the final rest's updates move the heading
        // in steps as the bias they learn explains what it did, so the rest is left out).
        let mean_error = |cfg: &OfflineConfig| {
            let r = run(&s, cfg).expect("offline run");
            let e = heading_errors(&s, &r.trajectory);
            let t_end = r.trajectory[0].t + sc.duration_s - sc.rest_end_s;
            let n = r.trajectory.iter().filter(|p| p.t < t_end).count();
            e[..n].iter().map(|x| x.abs()).sum::<f64>().to_degrees() / n as f64
        };
        let h_rio = mean_error(&OfflineConfig::default());
        let h_gyro = mean_error(&OfflineConfig {
            estimator: Estimator::ImuOnly,
            ..OfflineConfig::default()
        });
        let mut at_once = OfflineConfig::default();
        at_once.rest.rate_margin_s = 0.0;
        let h_at_once = mean_error(&at_once);
        println!(
            "seed {seed}: mean heading error {h_rio:.2} deg ({h_at_once:.2} deg taking the rates at once), gyro alone {h_gyro:.2} deg"
        );
        assert!(
            h_rio <= h_gyro + 2.0,
            "seed {seed}: heading error {h_rio:.2} deg vs gyro alone {h_gyro:.2} deg"
        );
    }
}

/// The outdoor handheld walk of split v2's training set with `seed`, simulated.
fn training_outdoor_walk(seed: u64) -> (tempfile::TempDir, Session) {
    use milliego_sim::split::{Set, SplitVersion};
    let e = SplitVersion::V2
        .entries(Set::Train)
        .into_iter()
        .find(|e| e.family == Family::Outdoor && e.motion == MotionKind::Handheld && e.seed == seed)
        .expect("an outdoor walk of the training set");
    simulated(&e.scenario())
}

#[test]
fn a_walk_the_radar_hardly_sees_does_not_run_away_horizontally() {
    // Two outdoor walks of split v2's training set with MEMS IMUs where the radar (tilted up,
    // sparse scene) gives no velocity for 10-30 s at a time: the IMU alone ran them away at up
    // to 10 m/s, 94 m and 9 m of ATE. The horizontal bound
    // (`RioConfig::horizontal_velocity_std`) keeps a lost filter at walking pace.
    for seed in [1102, 1100] {
        let (_dir, s) = training_outdoor_walk(seed);
        let path = ate(&s, Estimator::Doppler).1;
        let r = run(&s, &OfflineConfig::default()).expect("offline run");
        let mut off = OfflineConfig::default();
        off.rio.horizontal_velocity_std = f64::INFINITY;
        let r_off = run(&s, &off).expect("offline run");
        let (a, a_off) = (ate_of(&s, &r.trajectory), ate_of(&s, &r_off.trajectory));
        println!(
            "seed {seed}: {} of {} frames gave a velocity, {} horizontal bounds; ATE {a:.2} m ({a_off:.2} m without the bound) over {path:.1} m",
            r.ego_ok, r.radar_frames, r.horizontal_bounds
        );
        assert!(
            a < 0.25 * path,
            "seed {seed}: ATE {a:.2} m over {path:.1} m"
        );
    }
}

/// Horizontal speeds \[m/s\] of `poses` over consecutive 1 s intervals from `from` to `to` \[s\]
/// (the first pose at or after each second).
fn speeds_per_second(poses: &[milliego_session::TumPose], from: f64, to: f64) -> Vec<f64> {
    let at = |t: f64| poses.iter().find(|p| p.t >= t);
    let mut out = Vec::new();
    let mut t = from;
    while t + 1.0 <= to {
        if let (Some(a), Some(b)) = (at(t), at(t + 1.0)) {
            if b.t > a.t {
                out.push(((b.p[0] - a.p[0]).hypot(b.p[1] - a.p[1])) / (b.t - a.t));
            }
        }
        t += 1.0;
    }
    out
}

#[test]
fn a_walk_the_radar_loses_keeps_its_pace() {
    // An outdoor walk of split v2's training set (seed 1100) whose radar (sparse scene, a
    // handful of clutter points a frame) gives no velocity for 32 s from 23.6 s, until the
    // walker stops. The horizontal bound alone pulls a lost filter towards standing still; the
    // walking-pace bound (`RioConfig::pace_std`) holds the speed the radar last measured, so
    // the walk's speed over the stretch stays near the truth's.
    let (_dir, s) = training_outdoor_walk(1100);
    let truth = s.groundtruth().unwrap().expect("ground truth");
    let r = run(&s, &OfflineConfig::default()).expect("offline run");
    let mut off = OfflineConfig::default();
    off.rio.pace_std = f64::INFINITY;
    let r_off = run(&s, &off).expect("offline run");
    let u = r.unaided;
    assert!(
        u.length_s > 10.0,
        "the radar gives no velocity for {:.1} s at most",
        u.length_s
    );
    // The stretch from a second after the last aid.
    let (from, to) = (u.from_s + 1.0, u.from_s + u.length_s);
    let v_true = speeds_per_second(&truth, from, to);
    let error = |r: &milliego_odometry::offline::OfflineResult| {
        let v = speeds_per_second(&r.trajectory, from, to);
        let n = v.len().min(v_true.len()).max(1);
        v.iter()
            .zip(&v_true)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / n as f64
    };
    let (e_on, e_off) = (error(&r), error(&r_off));
    let pace_true = v_true.iter().sum::<f64>() / v_true.len().max(1) as f64;
    println!(
        "{:.1} s unaided from {:.1} s (true speed {pace_true:.2} m/s), {} pace bounds: speed error {e_on:.2} m/s ({e_off:.2} m/s without); ATE {:.2} m ({:.2} m without)",
        u.length_s,
        u.from_s,
        r.pace_bounds,
        ate_of(&s, &r.trajectory),
        ate_of(&s, &r_off.trajectory)
    );
    assert!(r.pace_bounds > 0, "the pace bound never applied");
    assert!(
        e_on < 0.5 && e_on < 0.6 * e_off,
        "speed error {e_on:.2} m/s ({e_off:.2} m/s without the pace bound)"
    );
}

#[test]
fn a_head_worn_walk_starting_in_motion_keeps_the_gyros_heading() {
    // No rest to measure the gyro bias: the radar sees the tilt, the levelling on the first
    // second of a walk is off by its mean acceleration, and a bias prior as wide as any MEMS
    // part's (0.01 rad/s) let the radar take that tilt error as horizontal gyro bias, which the
    // head's pitching then turned into heading drift the radar may not take back. A named MTi-1
    // starts from its turn-on bias (`XSENS_GYRO_TURN_ON_STD`).
    // Two walks where the wide prior broke the bound (the atrium walk: 12.3 deg against the
    // gyro's 0.9, ATE 3.9 m against 1.3 m).
    for (family, seed) in [(Family::Atrium, 6), (Family::StoreRoom, 7)] {
        let mut sc = Scenario::new(family, MotionKind::Headworn, seed);
        sc.duration_s = 60.0;
        assert_eq!(sc.rest_start_s, 0.0, "the walk starts in motion");
        let (_dir, s) = simulated(&sc);
        let (rio, h_rio, h_gyro) = headings_against_the_gyro(&s);
        let path = ate(&s, Estimator::Doppler).1;
        println!(
            "{family:?} head-worn walk {seed} from motion: worst heading error Doppler RIO {h_rio:.2} deg, gyro alone {h_gyro:.2} deg, ATE {:.3} m over {path:.1} m",
            ate_of(&s, &rio.trajectory)
        );
        assert!(
            h_rio <= h_gyro + 1.0,
            "{family:?} {seed}: heading {h_rio:.2} deg vs the gyro's {h_gyro:.2} deg"
        );
        assert!(ate_of(&s, &rio.trajectory) < 0.05 * path);
    }
}

#[test]
fn a_slow_robot_under_a_coarse_step_and_a_tilted_radar_keeps_its_track() {
    // A wheeled robot at 0.2-0.5 m/s whose radar, tilted 10 deg down, reports Doppler in
    // 0.36 m/s steps: its points round alike and the frames' velocities lean along the
    // direction the points do not spread in (forward against vertical). Told it is a ground
    // vehicle, the filter holds its sideways and vertical velocity to about a centimetre a
    // second, and the forward speed follows. (With the constraint's old 0.1 m/s, a third of the
    // robot's speed, these three ended 1.2-3.3% of their path off.)
    for seed in [3, 4, 5] {
        let mut sc = Scenario::new(Family::Office, MotionKind::Robot, seed);
        sc.duration_s = 40.0;
        sc.doppler_step_mps = 0.36;
        sc.radar_tilt_deg = -10.0;
        sc.radar_lever_m = Some([-0.37, -0.21, -0.07]);
        let (_dir, s) = simulated(&sc);
        let r = run(&s, &OfflineConfig::default().ground_vehicle()).expect("offline run");
        let (ate, path) = ate_and_path(&s, &r.trajectory);
        println!(
            "office robot {seed}: ATE {ate:.3} m over {path:.1} m ({:.2}%), constraint applied {} gated {}",
            100.0 * ate / path,
            r.nonholonomic.0,
            r.nonholonomic.1
        );
        assert!(ate < 0.01 * path, "ATE {ate:.3} m over {path:.1} m");
    }
}
