//! Learned relative motions as measurements of the classical filter
//! (`milliego_odometry::learned`), end to end on simulated sessions: motions taken from the
//! ground truth stand in for a perfect network, reversed ones for a network out of its domain.
//! What the network itself adds is scored by `milliego score` (docs/model.md, "Fusion").

use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_odometry::learned::{LearnedConfig, RelativeMotion, NOISE_RHO_MAX};
use milliego_odometry::offline::{run, run_with_motions, Estimator, OfflineConfig, OfflineResult};
use milliego_odometry::rio::ImuNoise;
use milliego_session::{Session, TumPose};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use nalgebra::{UnitQuaternion, Vector3};

fn simulated(
    family: Family,
    motion: MotionKind,
    seed: u64,
    s: f64,
) -> (tempfile::TempDir, Session) {
    simulated_from(family, motion, seed, s, 0.0)
}

/// [`simulated`] with `rest_s` at rest before the motion.
fn simulated_from(
    family: Family,
    motion: MotionKind,
    seed: u64,
    s: f64,
    rest_s: f64,
) -> (tempfile::TempDir, Session) {
    let dir = tempfile::tempdir().unwrap();
    let mut sc = Scenario::new(family, motion, seed);
    sc.duration_s = s;
    sc.rest_start_s = rest_s;
    simulate(&sc, dir.path(), &mut |_| {}).expect("simulate");
    let session = Session::open(dir.path()).unwrap();
    (dir, session)
}

/// A simulated session, its Doppler RIO run (default settings) and that run's pose times (where
/// the learned motions are anchored).
fn walk(
    family: Family,
    motion: MotionKind,
    seed: u64,
    s: f64,
) -> (tempfile::TempDir, Session, OfflineResult, Vec<f64>) {
    let (dir, session) = simulated(family, motion, seed, s);
    let doppler = run(&session, &OfflineConfig::default()).unwrap();
    let times = doppler.trajectory.iter().map(|p| p.t).collect();
    (dir, session, doppler, times)
}

fn ate(s: &Session, r: &OfflineResult) -> f64 {
    let gt = Trajectory::from_tum(&s.groundtruth().unwrap().expect("ground truth"));
    evaluate(
        &gt,
        &Trajectory::from_tum(&r.trajectory),
        &Settings::default(),
    )
    .expect("evaluation")
    .ate
    .mean
}

/// The ground-truth pose at `t` (position interpolated, rotation of the nearer sample).
fn gt_at(gt: &[TumPose], t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let i = gt.partition_point(|p| p.t < t).clamp(1, gt.len() - 1);
    let (a, b) = (&gt[i - 1], &gt[i]);
    let w = ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
    let p = Vector3::from(a.p) * (1.0 - w) + Vector3::from(b.p) * w;
    let n = if w < 0.5 { a } else { b };
    let [x, y, z, qw] = n.q;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(qw, x, y, z));
    (p, q)
}

/// Motions between every 5th pose of `times` from the ground truth, their translation times
/// `scale`.
fn motions(s: &Session, times: &[f64], scale: f64) -> Vec<RelativeMotion> {
    let gt = s.groundtruth().unwrap().expect("ground truth");
    times
        .iter()
        .step_by(5)
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| {
            let (p0, q0) = gt_at(&gt, *w[0]);
            let (p1, _) = gt_at(&gt, *w[1]);
            let d = q0.inverse() * (p1 - p0) * scale;
            RelativeMotion {
                t_from: *w[0],
                t_to: *w[1],
                translation: d.into(),
                translation_std: None,
            }
        })
        .collect()
}

/// A lasting error's run applied most of its `n` motions one at a time (within the gate), and
/// right motions left the stated deviation about as it is.
fn within_gate_and_right_stays(lasting: &OfflineResult, n: usize, right: &OfflineResult) {
    assert!(
        lasting.learned.applied as usize > n / 2,
        "within the gate: {:?}",
        lasting.learned
    );
    assert!(
        right.learned_noise_factor < 2.0,
        "right motions: factor {}",
        right.learned_noise_factor
    );
}

/// A MEMS part's filter (it leans on the network more than an Xsens preset's) on `s`: Doppler
/// alone, with `right` motions, and with `lasting` ones with their deviation widened by what the
/// radar measured (the default) and not; each run with its ATE \[m\].
struct LastingError {
    doppler: (OfflineResult, f64),
    right: (OfflineResult, f64),
    widened: (OfflineResult, f64),
    plain: (OfflineResult, f64),
}

fn lasting_error_runs(
    s: &Session,
    right: &[RelativeMotion],
    lasting: &[RelativeMotion],
) -> LastingError {
    let widened = LearnedConfig::default();
    assert!(widened.adapt_noise, "on by default");
    let plain = LearnedConfig {
        adapt_noise: false,
        ..widened
    };
    let scored = |m: &[RelativeMotion], learned| {
        let r = with_mems(s, Estimator::Doppler, m, learned);
        let a = ate(s, &r);
        (r, a)
    };
    let runs = LastingError {
        doppler: scored(&[], widened),
        right: scored(right, widened),
        widened: scored(lasting, widened),
        plain: scored(lasting, plain),
    };
    println!(
        "{} radar updates, {} motions; ATE: Doppler {:.3} m, right motions {:.3} m (factor {:.2}), lasting error widened {:.3} m (factor {:.2}), not {:.3} m",
        runs.doppler.0.updates,
        right.len(),
        runs.doppler.1,
        runs.right.1,
        runs.right.0.learned_noise_factor,
        runs.widened.1,
        runs.widened.0.learned_noise_factor,
        runs.plain.1
    );
    within_gate_and_right_stays(&runs.widened.0, lasting.len(), &runs.right.0);
    runs
}

/// `m` with a steady velocity error `v` \[m/s, body frame at `from`\] added to every motion.
fn off_by(m: &[RelativeMotion], v: Vector3<f64>) -> Vec<RelativeMotion> {
    m.iter()
        .map(|r| RelativeMotion {
            translation: (Vector3::from(r.translation) + v * (r.t_to - r.t_from)).into(),
            ..*r
        })
        .collect()
}

fn with(
    s: &Session,
    est: Estimator,
    m: &[RelativeMotion],
    learned: LearnedConfig,
) -> OfflineResult {
    with_imu(s, est, None, m, learned)
}

/// [`with`] for a filter told the IMU is a consumer MEMS part (its noise, and a gyro bias prior
/// as wide as any part's): it leans on the network more than an Xsens preset's filter does.
fn with_mems(
    s: &Session,
    est: Estimator,
    m: &[RelativeMotion],
    learned: LearnedConfig,
) -> OfflineResult {
    with_imu(s, est, Some(ImuNoise::Mems), m, learned)
}

fn with_imu(
    s: &Session,
    est: Estimator,
    imu_noise: Option<ImuNoise>,
    m: &[RelativeMotion],
    learned: LearnedConfig,
) -> OfflineResult {
    let cfg = OfflineConfig {
        estimator: est,
        imu_noise,
        ..OfflineConfig::default()
    };
    run_with_motions(s, &cfg, m, learned).expect("offline run")
}

#[test]
fn right_motions_carry_an_imu_without_radar_and_do_not_hurt_doppler() {
    let (_d, s, doppler, times) = walk(Family::Office, MotionKind::Handheld, 3, 60.0);
    let m = motions(&s, &times, 1.0);
    let learned = LearnedConfig::default();
    let imu = with(&s, Estimator::ImuOnly, &[], learned);
    let imu_m = with(&s, Estimator::ImuOnly, &m, learned);
    let dop_m = with(&s, Estimator::Doppler, &m, learned);
    let (a_imu, a_imu_m, a_dop, a_dop_m) = (
        ate(&s, &imu),
        ate(&s, &imu_m),
        ate(&s, &doppler),
        ate(&s, &dop_m),
    );
    println!(
        "ATE: IMU {a_imu:.2} m, IMU + motions {a_imu_m:.3} m, Doppler {a_dop:.3} m, Doppler + motions {a_dop_m:.3} m; {:?}",
        dop_m.learned
    );
    assert_eq!(imu.learned.applied, 0);
    assert!(
        imu_m.learned.applied as usize > m.len() / 2,
        "{:?}",
        imu_m.learned
    );
    assert!(a_imu_m * 4.0 < a_imu, "motions alone bound the IMU's drift");
    assert!(
        a_dop_m <= a_dop * 1.05,
        "right motions must not make Doppler worse"
    );
    let nis = dop_m.learned.nis_mean().unwrap();
    assert!(
        nis < 3.0,
        "right motions are within their stated deviation (NIS {nis:.2})"
    );
    assert_eq!(dop_m.learned.switched_off, 0);
}

#[test]
fn reversed_motions_fail_the_online_check_and_stop() {
    let (_d, s, doppler, times) = walk(Family::Corridor, MotionKind::Handheld, 5, 60.0);
    // A network fed the wrong axis convention (a rig mounted backwards): every motion reversed.
    // (Twice the distance passes the check: the deviation grows with the distance, and with
    // Doppler outweighing them such motions cost nothing here.)
    let m = motions(&s, &times, -1.0);
    let checked = LearnedConfig::default();
    let on = with(&s, Estimator::Doppler, &m, checked);
    // The default widens the deviation by the error measured where the radar covers the motion
    // (`adapt_noise`); the check is judged without it too.
    let plain = LearnedConfig {
        adapt_noise: false,
        ..checked
    };
    let unchecked = |c: LearnedConfig| {
        with(
            &s,
            Estimator::Doppler,
            &m,
            LearnedConfig {
                monitor: false,
                ..c
            },
        )
    };
    let (on_plain, off_plain, off_widened) = (
        with(&s, Estimator::Doppler, &m, plain),
        unchecked(plain),
        unchecked(checked),
    );
    // (Unchecked, the widened ones cost about what they cost without widening here: Doppler
    // outweighs them either way.)
    let a = |r: &OfflineResult| ate(&s, r);
    let (a_dop, a_on) = (ate(&s, &doppler), a(&on));
    println!(
        "ATE: Doppler {a_dop:.3} m, with reversed motions checked {a_on:.3} m ({:?}); without widening: checked {:.3} m, unchecked {:.3} m ({:?}); widened, unchecked {:.3} m",
        on.learned,
        a(&on_plain),
        a(&off_plain),
        off_plain.learned,
        a(&off_widened)
    );
    assert_eq!(on.learned.switched_off, 1, "{:?}", on.learned);
    assert!(on.learned.suspended > 0, "{:?}", on.learned);
    assert_eq!(on_plain.learned.switched_off, 1, "{:?}", on_plain.learned);
    for off in [&off_plain, &off_widened] {
        assert_eq!(off.learned.switched_off + off.learned.suspended, 0);
    }
    assert!(
        off_plain.learned.nis_mean().unwrap() > 4.0,
        "the bias shows in the innovations"
    );
    assert!(
        a_on <= a_dop * 1.1,
        "Doppler {a_dop:.3} m, checked {a_on:.3} m"
    );
    assert!(
        a(&on_plain) < a(&off_plain),
        "the check alone: checked {:.3} m, unchecked {:.3} m",
        a(&on_plain),
        a(&off_plain)
    );
}

#[test]
fn a_network_error_that_lasts_widens_the_deviation_once_the_radar_has_measured_it() {
    // Where the radar covers the motion, the network's error against the filter is measured:
    // right motions leave the stated deviation as it is; a lasting sideways error (0.8 m/s along
    // the body's y axis, across the walk, within the gate one measurement at a time) reads as
    // errors correlated from one interval to the next on that axis, and the deviation is widened
    // by their variance times what the correlation gives (an error along the walk would read as
    // one of scale, which the scale calibration takes off).
    let (_d, s, _, times) = walk(Family::Office, MotionKind::Handheld, 3, 20.0);
    let right = motions(&s, &times, 1.0);
    let lasting = off_by(&right, Vector3::new(0.0, 0.8, 0.0));
    // On a MEMS part's filter, which leans on the network more (an Xsens preset's filter knows
    // this walk's motion well enough that the error costs it 0.057 against 0.048 m unwidened).
    let LastingError {
        doppler: (_, a_dop),
        widened: (r_on, a_on),
        plain: (r_off, a_off),
        ..
    } = lasting_error_runs(&s, &right, &lasting);
    // The error is about the stated deviation on its axis (0.2 m per 0.25 s interval), and
    // correlated up to the clamp: a factor of several, at most the clamp's.
    let full = (1.0 + NOISE_RHO_MAX) / (1.0 - NOISE_RHO_MAX);
    assert!(
        (4.0..=2.0 * full).contains(&r_on.learned_noise_factor),
        "lasting error: factor {}",
        r_on.learned_noise_factor
    );
    assert_eq!(r_off.learned_noise_factor, 1.0);
    assert!(
        a_on < 0.5 * a_off,
        "widened {a_on:.3} m, not {a_off:.3} m (Doppler {a_dop:.3} m)"
    );
}

#[test]
fn a_cars_filter_measures_the_network_where_the_radar_does_not_cover() {
    // A car in a sparse outdoor scene: few of its intervals have the radar updates a covered
    // one needs, but its filter knows its velocity from the ground vehicle constraint and the
    // IMU its rest measured. There the network's lasting error (1.5 m/s sideways, within the
    // gate one measurement at a time at the car's deviation) is measured against the filter and
    // the deviation widened; with covered intervals only it is trusted as stated.
    let (_d, s) = simulated_from(Family::Outdoor, MotionKind::Vehicle, 4, 30.0, 3.0);
    let cfg = OfflineConfig::default().ground_vehicle();
    let doppler = run(&s, &cfg).unwrap();
    let times: Vec<f64> = doppler.trajectory.iter().map(|p| p.t).collect();
    let right = motions(&s, &times, 1.0);
    let lasting = off_by(&right, Vector3::new(0.0, 1.5, 0.0));
    let known = LearnedConfig::default();
    assert!(known.known_share > 0.0, "on by default");
    let covered_only = LearnedConfig {
        known_share: 0.0,
        ..known
    };
    let car = |m: &[RelativeMotion], learned| run_with_motions(&s, &cfg, m, learned).unwrap();
    let (r_right, r_on, r_off) = (
        car(&right, known),
        car(&lasting, known),
        car(&lasting, covered_only),
    );
    let (a_dop, a_right, a_on, a_off) = (
        ate(&s, &doppler),
        ate(&s, &r_right),
        ate(&s, &r_on),
        ate(&s, &r_off),
    );
    println!(
        "car: {} radar updates; ATE: Doppler {a_dop:.3} m, right motions {a_right:.3} m (factor {:.2}), lasting error, known intervals calibrate {a_on:.3} m (factor {:.2}), covered only {a_off:.3} m (factor {:.2}); learned {:?}",
        doppler.updates,
        r_right.learned_noise_factor,
        r_on.learned_noise_factor,
        r_off.learned_noise_factor,
        r_on.learned
    );
    within_gate_and_right_stays(&r_on, lasting.len(), &r_right);
    assert!(
        r_off.learned_noise_factor < 2.0,
        "covered intervals only: the radar measured little, factor {}",
        r_off.learned_noise_factor
    );
    assert!(
        r_on.learned_noise_factor > 4.0,
        "known intervals: factor {}",
        r_on.learned_noise_factor
    );
    assert!(
        a_on < 0.5 * a_off,
        "known intervals calibrate {a_on:.3} m, covered only {a_off:.3} m (Doppler {a_dop:.3} m)"
    );
}

#[test]
fn reversed_motions_fail_the_online_check_with_the_offset_calibration_on_too() {
    // Calibrated, reversed motions on a steady walk read as a steady offset of twice the
    // velocity and agree with the filter once it is taken off; the check judges them before.
    let (_d, s, _, times) = walk(Family::Corridor, MotionKind::Handheld, 5, 20.0);
    let m = motions(&s, &times, -1.0);
    let on = LearnedConfig {
        calibrate_offset: true,
        ..LearnedConfig::default()
    };
    let r = with(&s, Estimator::Doppler, &m, on);
    println!("reversed, offset calibrated: {:?}", r.learned);
    assert_eq!(r.learned.switched_off, 1, "{:?}", r.learned);
    assert!(r.learned.suspended > 0, "{:?}", r.learned);
}

#[test]
fn at_rest_motions_are_not_applied_and_the_rig_does_not_move() {
    let (_d, s, _, times) = walk(Family::Office, MotionKind::Static, 21, 12.0);
    // A network that "walks" at rest (what the simulation-trained one did on a real rig):
    // 5 cm forward per keyframe.
    let m: Vec<RelativeMotion> = times
        .iter()
        .step_by(5)
        .collect::<Vec<_>>()
        .windows(2)
        .map(|w| RelativeMotion {
            t_from: *w[0],
            t_to: *w[1],
            translation: [0.05, 0.0, 0.0],
            translation_std: None,
        })
        .collect();
    let r = with(&s, Estimator::Doppler, &m, LearnedConfig::default());
    let first = r.trajectory.first().unwrap().p;
    let wander = r
        .trajectory
        .iter()
        .map(|p| (Vector3::from(p.p) - Vector3::from(first)).norm())
        .fold(0.0, f64::max);
    println!(
        "static {:.1} s: wander {:.2} mm, {:?}",
        times.last().unwrap() - times[0],
        wander * 1e3,
        r.learned
    );
    assert!(
        r.learned.at_rest as usize * 10 >= m.len() * 8,
        "{:?}",
        r.learned
    );
    assert!(wander < 0.01, "moved {wander:.4} m at rest");
}

#[test]
fn a_network_that_says_where_it_is_unsure_is_trusted_less_there() {
    // Every other motion 2.5x too long, and the network says so through a large predicted
    // deviation (1 m against 1 cm): weighing its own deviation in, the filter follows the right
    // motions; without it, it averages the wrong ones in.
    let (_d, s, _, times) = walk(Family::Office, MotionKind::Handheld, 3, 20.0);
    let right = motions(&s, &times, 1.0);
    let mixed: Vec<RelativeMotion> = right
        .iter()
        .enumerate()
        .map(|(i, r)| {
            if i % 2 == 0 {
                RelativeMotion {
                    translation: r.translation.map(|x| x * 2.5),
                    translation_std: Some([1.0; 3]),
                    ..*r
                }
            } else {
                RelativeMotion {
                    translation_std: Some([0.01; 3]),
                    ..*r
                }
            }
        })
        .collect();
    let base = LearnedConfig {
        monitor: false,
        ..LearnedConfig::default()
    };
    let right_only: Vec<RelativeMotion> = mixed.iter().skip(1).step_by(2).copied().collect();
    let blind = ate(&s, &with(&s, Estimator::ImuOnly, &mixed, base));
    let aware = ate(
        &s,
        &with(
            &s,
            Estimator::ImuOnly,
            &mixed,
            LearnedConfig {
                predicted_std: 1.0,
                ..base
            },
        ),
    );
    let reference = ate(&s, &with(&s, Estimator::ImuOnly, &right_only, base));
    println!("ATE: blind to the deviation {blind:.3} m, weighing it {aware:.3} m, right motions only {reference:.3} m");
    assert!(
        aware < 0.5 * blind,
        "the predicted deviation must take the wrong motions' weight away"
    );
    assert!(
        aware - reference < 0.1 * (blind - reference),
        "weighing the deviation must take it at least 90% of the way to having only the right motions"
    );
}

#[test]
fn a_steady_offset_of_the_network_is_measured_where_the_radar_sees_the_motion() {
    // A network whose every motion carries the same velocity error (0.4 m/s along the body's x
    // axis, forward: on a walk the scale calibration takes part of it): with the offset
    // calibration the filter takes it off, without it the filter is pulled by every
    // measurement.
    let (_d, s, _, times) = walk(Family::Office, MotionKind::Handheld, 3, 20.0);
    let m = off_by(&motions(&s, &times, 1.0), Vector3::new(0.4, 0.0, 0.0));
    let on = LearnedConfig {
        calibrate_offset: true,
        ..LearnedConfig::default()
    };
    let off = LearnedConfig {
        calibrate_offset: false,
        ..on
    };
    // On a MEMS part's filter: with an Xsens preset's gyro prior this walk's filter knows its
    // motion well enough that the offset no longer pulls it measurably (0.047 m either way).
    let (r_on, r_off, doppler) = (
        with_mems(&s, Estimator::Doppler, &m, on),
        with_mems(&s, Estimator::Doppler, &m, off),
        with_mems(&s, Estimator::Doppler, &[], on),
    );
    let (a_dop, a_on, a_off) = (ate(&s, &doppler), ate(&s, &r_on), ate(&s, &r_off));
    println!("ATE: Doppler {a_dop:.3} m, offset calibrated {a_on:.3} m, not {a_off:.3} m");
    assert!(
        r_on.learned.applied as usize > m.len() / 2,
        "{:?}",
        r_on.learned
    );
    assert!(a_on < a_off, "{a_on:.3} vs {a_off:.3} m");
    assert!(
        a_on <= a_dop * 1.1 + 0.02,
        "{a_on:.3} vs Doppler {a_dop:.3} m"
    );
}

#[test]
fn a_sparse_scenes_radar_measures_the_networks_lasting_error_too() {
    // Outdoor walks: the radar gives a velocity in a sixth to a quarter of the frames, so a
    // keyframe interval (5 frames) rarely holds 4 of them; intervals with 2 count as covered
    // (`SCALE_COVERS`), so the network's lasting error (0.8 m/s sideways) is measured there
    // too and its deviation widened. Counting only intervals with 4, the factor stayed at 1.0-1.06
    // on these walks and the filter trusted the error as stated.
    for seed in [1, 2, 3] {
        let (_d, s, _, times) = walk(Family::Outdoor, MotionKind::Handheld, seed, 30.0);
        let right = motions(&s, &times, 1.0);
        let lasting = off_by(&right, Vector3::new(0.0, 0.8, 0.0));
        println!("seed {seed}:");
        let LastingError {
            doppler: (doppler, a_dop),
            widened: (r_on, a_on),
            plain: (_, a_off),
            ..
        } = lasting_error_runs(&s, &right, &lasting);
        assert!(
            (doppler.updates as usize) < 2 * right.len(),
            "seed {seed}: a sparse scene ({} radar updates over {} intervals)",
            doppler.updates,
            right.len()
        );
        assert!(
            r_on.learned_noise_factor > 3.0,
            "seed {seed}: lasting error: factor {}",
            r_on.learned_noise_factor
        );
        assert!(
            a_on <= a_off,
            "seed {seed}: widened {a_on:.3} m, not {a_off:.3} m (Doppler {a_dop:.3} m)"
        );
    }
}
