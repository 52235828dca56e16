//! Classical odometry end to end on simulated sessions: the simulator writes a session, the
//! offline runner decodes both streams, fits the clocks and runs Doppler RIO and IMU dead
//! reckoning, and the evaluation scores both against ground truth.

use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_odometry::offline::{run, Estimator, OfflineConfig};
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
