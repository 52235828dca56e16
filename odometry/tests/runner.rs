//! The streaming classical runner on synthetic streams (a stationary rig looking at a static
//! scene): the health rule withdraws the prior after a run of rejected frames and the filter
//! re-anchors, both input orders (offline: a frame before the first IMU sample past it; runtime:
//! after it) give the same poses, and the same states where several frames fall in one IMU
//! interval, an IMU gap is bridged by radar dead reckoning, and sparse
//! frames of a turning rig give velocities with the points of the frames before them.

use milliego_odometry::rio::RioCounters;
use milliego_odometry::runner::{
    guided, ClassicalConfig, FrameInput, FramePose, Mounting, Runner, GUIDE_AFTER_UPDATES,
    MAX_REJECTED_IN_ROW, UNAIDED_AFTER_S,
};
use milliego_odometry::strapdown::{ImuSample, STANDARD_GRAVITY};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use radar_driver::tlv::Point;

const IMU_DT: f64 = 0.01;
const RADAR_DT: f64 = 0.1;
/// Radar frames fall between IMU samples.
const RADAR_OFFSET: f64 = 0.0037;

fn imu(k: usize) -> ImuSample {
    ImuSample {
        t: k as f64 * IMU_DT,
        accel: [0.0, 0.0, STANDARD_GRAVITY],
        gyro: [0.0; 3],
    }
}

/// A static scene seen by a radar moving at `v` (radar frame) \[m/s\]: `v_r = -d . v`.
fn scene(v: [f32; 3]) -> Vec<Point> {
    let mut pts = Vec::new();
    for az in -4i32..=4 {
        for el in -2..=2 {
            let (a, e) = (az as f32 * 0.25, el as f32 * 0.15);
            let d = [a.sin() * e.cos(), a.cos() * e.cos(), e.sin()];
            let r = 3.0 + (az + el).rem_euclid(4) as f32;
            pts.push(Point {
                x: d[0] * r,
                y: d[1] * r,
                z: d[2] * r,
                velocity: -(d[0] * v[0] + d[1] * v[1] + d[2] * v[2]),
            });
        }
    }
    pts
}

fn frame_t(n: usize) -> f64 {
    n as f64 * RADAR_DT + RADAR_OFFSET
}

/// Pushes frames `n..` (points from `points`) while they are at or before `t` \[s\].
fn push_frames_to(r: &mut Runner, n: &mut usize, t: f64, points: &impl Fn(usize) -> Vec<Point>) {
    while frame_t(*n) <= t {
        let pts = points(*n);
        r.push_radar(&FrameInput {
            t: frame_t(*n),
            id: *n as u64,
            points: &pts,
        });
        *n += 1;
    }
}

#[test]
fn the_health_rule() {
    assert!(!guided(GUIDE_AFTER_UPDATES - 1, 0));
    assert!(guided(GUIDE_AFTER_UPDATES, 0));
    assert!(guided(GUIDE_AFTER_UPDATES, MAX_REJECTED_IN_ROW - 1));
    assert!(!guided(GUIDE_AFTER_UPDATES, MAX_REJECTED_IN_ROW));
}

/// Feeds `seconds` of stationary IMU and radar frames (`points(n)` for frame n) in the runtime
/// order (a frame right after the first IMU sample past it); `check(n, runner)` after each frame.
fn feed(
    runner: &mut Runner,
    seconds: f64,
    points: impl Fn(usize) -> Vec<Point>,
    mut check: impl FnMut(usize, &Runner),
) -> Vec<FramePose> {
    let mut poses = Vec::new();
    let mut n = 0;
    for k in 0..(seconds / IMU_DT) as usize {
        let s = imu(k);
        runner.push_imu(s);
        while frame_t(n) <= s.t {
            let pts = points(n);
            runner.push_radar(&FrameInput {
                t: frame_t(n),
                id: n as u64,
                points: &pts,
            });
            check(n, runner);
            n += 1;
        }
        while let Some(p) = runner.pop_pose() {
            poses.push(p);
        }
    }
    poses
}

#[test]
fn rejected_frames_withdraw_the_prior_and_the_filter_re_anchors() {
    let mut r = Runner::new(&ClassicalConfig::default(), true);
    // 4 s at rest, then the radar insists on 3 m/s forward (far outside the filter's gate).
    let bad_from = 40;
    let mut guided_at_bad = None;
    let mut withdrawn_at = None;
    let mut regained_at = None;
    feed(
        &mut r,
        8.0,
        |n| {
            scene(if n < bad_from {
                [0.0; 3]
            } else {
                [0.0, 3.0, 0.0]
            })
        },
        |n, r| {
            if n + 1 == bad_from {
                guided_at_bad = Some(r.guiding());
            }
            if n >= bad_from && withdrawn_at.is_none() && !r.guiding() {
                withdrawn_at = Some(n);
                assert_eq!(r.rejected_in_row(), MAX_REJECTED_IN_ROW, "frame {n}");
            }
            if withdrawn_at.is_some() && regained_at.is_none() && r.guiding() {
                regained_at = Some(n);
            }
        },
    );
    assert_eq!(
        guided_at_bad,
        Some(true),
        "healthy after levelling and 10 updates"
    );
    let withdrawn_at = withdrawn_at.expect("the prior is withdrawn");
    assert_eq!(
        withdrawn_at,
        bad_from + MAX_REJECTED_IN_ROW as usize - 1,
        "withdrawn after {MAX_REJECTED_IN_ROW} rejected frames"
    );
    let c = r.filter_counters();
    assert!(c.reanchors >= 1, "{c:?}");
    assert!(
        regained_at.is_some(),
        "guided again once the filter re-anchored"
    );
    // The filter follows the radar after re-anchoring.
    let (_, _, v) = r.body_state().unwrap();
    assert!((v.norm() - 3.0).abs() < 0.3, "velocity {v:?}");
}

#[test]
fn offline_and_runtime_order_give_the_same_poses() {
    // Points seen again are weighed by default: the frames' points are placed with the state at
    // the sample before each frame in both orders, so their weights, and the poses, are the
    // same.
    assert!(ClassicalConfig::default().persist.enabled());
    same_poses_in_both_orders(&ClassicalConfig::default());
}

#[test]
fn offline_and_runtime_order_give_the_same_poses_with_every_point_weighing_the_same() {
    let mut cfg = ClassicalConfig::default();
    cfg.persist.window_s = 0.0;
    same_poses_in_both_orders(&cfg);
}

fn same_poses_in_both_orders(cfg: &ClassicalConfig) {
    let cfg = *cfg;
    let points = |n: usize| scene([0.0, 0.2 * (n as f32 * 0.1).sin(), 0.0]);
    let runtime = feed(&mut Runner::new(&cfg, true), 4.0, points, |_, _| {});
    // Offline order: each frame before the first sample at or past it.
    let mut r = Runner::new(&cfg, true);
    let mut offline = Vec::new();
    let mut n = 0;
    for k in 0..(4.0 / IMU_DT) as usize {
        let s = imu(k);
        push_frames_to(&mut r, &mut n, s.t, &points);
        r.push_imu(s);
        while let Some(p) = r.pop_pose() {
            offline.push(p);
        }
    }
    r.finish();
    // The runtime order has the frames up to the last sample; the offline order those before it.
    assert!(runtime.len() >= 35, "{} poses", runtime.len());
    assert_eq!(offline.len(), runtime.len());
    for (a, b) in offline.iter().zip(&runtime) {
        assert_eq!((a.id, a.t), (b.id, b.t));
        assert_eq!(a.body, b.body, "frame {}", a.id);
    }
    // Levelling frames come out when the filter starts, every later one once.
    assert_eq!(offline[0].id, 0);
    assert!(offline.windows(2).all(|w| w[1].id == w[0].id + 1));
}

#[test]
fn an_imu_gap_is_dead_reckoned_and_the_filter_re_anchors_after_it() {
    let mut r = Runner::new(&ClassicalConfig::default(), true);
    let v = [0.0, 0.5, 0.0];
    feed(&mut r, 3.0, |_| scene([0.0; 3]), |_, _| {});
    // The last sample is at 2.99 s: frame 30 (3.0037 s) is ahead of the IMU but within
    // `imu_gap_s`, so its pose waits for the next sample.
    let pts = scene(v);
    r.push_radar(&FrameInput {
        t: frame_t(30),
        id: 30,
        points: &pts,
    });
    assert_eq!(r.pop_pose(), None);
    let (t_before, before, _) = r.body_state().unwrap();
    // 1 s without IMU: frames at 10 Hz.
    let mut gap_poses = 0;
    for n in 31..41 {
        let pts = scene(v);
        r.push_radar(&FrameInput {
            t: frame_t(n),
            id: n as u64,
            points: &pts,
        });
        while let Some(p) = r.pop_pose() {
            assert_eq!(p.id, n as u64, "a dead-reckoned frame's pose at once");
            gap_poses += 1;
        }
    }
    assert_eq!(gap_poses, 10);
    assert_eq!(r.counters().dead_reckoned, 10);
    let (t_after, after, _) = r.body_state().unwrap();
    let moved = (after.translation.vector - before.translation.vector).norm();
    let expect = 0.5 * (t_after - t_before);
    assert!(
        (moved - expect).abs() < 0.05,
        "{moved} m, expected {expect}"
    );
    r.push_imu(imu(400));
    assert_eq!(r.counters().imu_restarts, 1);
    assert_eq!(
        r.filter_counters().updates,
        0,
        "a fresh filter after the gap"
    );
    let (_, restarted, _) = r.body_state().unwrap();
    assert_eq!(restarted.translation, after.translation, "the pose is kept");
}

/// When the rig of [`sparse_turning_walk`] starts to accelerate \[s\] (after levelling).
const T_ACCEL: f64 = 1.5;

/// A rig turning at a steady 1.5 rad/s while moving at a constant world velocity, its radar 0.3 m
/// from the IMU and yawed, seeing 4 static points per frame (too few alone: 5 needed). Returns
/// the runner after 6 s and the world velocity \[m/s\].
fn sparse_turning_walk(
    stack_window_s: f64,
    per_frame: usize,
    sigma: f32,
) -> (Runner, Vec<(f64, f64, f64)>) {
    let w = 1.5;
    let v0 = Vector3::new(1.0, 1.0, 0.0);
    let a_w = Vector3::new(0.8, -0.4, 0.0);
    let g = Vector3::new(0.0, 0.0, STANDARD_GRAVITY);
    let q_br = UnitQuaternion::from_euler_angles(0.05, -0.1, 0.4);
    let t_br = Vector3::new(0.3, 0.1, 0.05);
    let cfg = ClassicalConfig {
        mounting: Mounting {
            imu: Isometry3::identity(),
            radar: Isometry3::from_parts(Translation3::from(t_br), q_br),
        },
        stack_window_s,
        ego: milliego_odometry::ego_velocity::Config {
            sigma,
            ..Default::default()
        },
        ..ClassicalConfig::default()
    };
    // Static world points around the path, 1.5-9 m away, at several heights.
    let world: Vec<Vector3<f64>> = (0..97)
        .map(|i| {
            let a = i as f64 * 2.399;
            let r = 4.0 + (i % 7) as f64;
            Vector3::new(
                3.0 + r * a.cos(),
                1.5 + r * a.sin(),
                -1.0 + (i % 5) as f64 * 0.6,
            )
        })
        .collect();
    let frame = |n: usize| -> Vec<Point> {
        let t = frame_t(n);
        let q_wb = UnitQuaternion::from_euler_angles(0.0, 0.0, w * t);
        let omega = Vector3::new(0.0, 0.0, w);
        let ta = (t - T_ACCEL).max(0.0);
        let v_r = q_br.inverse() * (q_wb.inverse() * (v0 + a_w * ta) + omega.cross(&t_br));
        let p_r = v0 * t + a_w * (0.5 * ta * ta) + q_wb * t_br;
        (0..per_frame)
            .map(|k| {
                let p =
                    q_br.inverse() * (q_wb.inverse() * (world[(n * 4 + k) % world.len()] - p_r));
                let u = p / p.norm();
                Point {
                    x: p.x as f32,
                    y: p.y as f32,
                    z: p.z as f32,
                    velocity: -u.dot(&v_r) as f32,
                }
            })
            .collect()
    };
    let mut r = Runner::new(&cfg, true);
    let mut poses = Vec::new();
    let mut n = 0;
    for k in 0..(6.0 / IMU_DT) as usize {
        let t = k as f64 * IMU_DT;
        // The IMU at the body origin: specific force R^T (a + g), rate of turn about z.
        let a = if t > T_ACCEL { a_w } else { Vector3::zeros() };
        let f = UnitQuaternion::from_euler_angles(0.0, 0.0, w * t).inverse() * (a + g);
        let s = ImuSample {
            t,
            accel: [f.x, f.y, f.z],
            gyro: [0.0, 0.0, w],
        };
        r.push_imu(s);
        push_frames_to(&mut r, &mut n, s.t, &frame);
        while let Some(p) = r.pop_pose() {
            poses.push(p);
        }
    }
    let errors = poses
        .iter()
        .map(|p: &FramePose| {
            let v = v0 + a_w * (p.t - T_ACCEL).max(0.0);
            (p.t, (p.velocity_world - v).norm(), p.unaided_s)
        })
        .collect();
    (r, errors)
}

#[test]
fn sparse_frames_give_velocities_with_the_points_of_the_frames_before() {
    // Alone, no frame gives a velocity: the filter keeps the velocity it started with (zero).
    let (r, errors) = sparse_turning_walk(0.0, 4, 0.01);
    let c = *r.counters();
    assert_eq!((c.ego_ok, c.ego_stacked), (0, 0), "{c:?}");
    assert!(c.ego_too_few >= 55, "{c:?}");
    assert!(errors.iter().all(|&(_, e, _)| e > 1.0), "{errors:?}");

    // Kept for 0.25 s, the points of the frames before, carried through the turn (0.15-0.3 rad),
    // the lever arm and the acceleration, join each frame's and agree with its own within the
    // Doppler noise (0.01 m/s; inlier gate 0.03 m/s): every other frame gives a velocity.
    let (r, errors) = sparse_turning_walk(0.25, 4, 0.01);
    let c = *r.counters();
    assert_eq!(c.ego_ok, 0, "{c:?}");
    assert!(c.ego_stacked >= 25, "{c:?}");
    assert_eq!(r.filter_counters().gated, 0, "{:?}", r.filter_counters());
    for &(t, e, _) in errors.iter().filter(|(t, _, _)| *t > 2.0) {
        assert!(e < 0.12, "t {t:.2}: velocity error {e:.3} m/s");
    }
}

#[test]
fn each_pose_says_how_long_it_rested_on_the_imu_alone() {
    // No frame gives a velocity alone and the rig turns (never at rest): from its first pose on,
    // every pose rests on the IMU alone, and the longest stretch is the whole run.
    let (r, poses) = sparse_turning_walk(0.0, 4, 0.01);
    let t0 = poses[0].0;
    let t1 = poses[poses.len() - 1].0;
    for &(t, _, unaided) in &poses {
        assert!((unaided - (t - t0)).abs() < 1e-9, "t {t:.2}: {unaided} s");
    }
    let u = r.longest_unaided();
    assert!((u.from_s - t0).abs() < 1e-9, "{u:?}");
    assert!((u.length_s - (t1 - t0)).abs() < 1e-9, "{u:?}");
    let flagged = poses.iter().filter(|p| p.0 - t0 > UNAIDED_AFTER_S).count();
    assert_eq!(u.poses_unaided, flagged as u64, "{u:?}");
    assert!(flagged > 30, "{flagged} of {}", poses.len());

    // With the points of the frames before, every other frame gives a velocity: no pose rests
    // on the IMU alone for long once the first one came, and none is counted unaided.
    let (r, poses) = sparse_turning_walk(0.25, 4, 0.01);
    let first = poses.iter().position(|p| p.2 == 0.0 && p.0 > poses[0].0);
    let first = first.expect("a velocity was applied");
    for &(t, _, unaided) in &poses[first..] {
        assert!(
            unaided < 0.35,
            "t {t:.2}: {unaided} s since the last velocity"
        );
    }
    let u = r.longest_unaided();
    assert!(u.length_s < UNAIDED_AFTER_S, "{u:?}");
    assert_eq!(u.poses_unaided, 0, "{u:?}");
}

/// Runs `seconds` of a stationary IMU at 100 Hz that drops its samples from 0.5 to 0.8 s of
/// every second (3 radar frames fall in one IMU interval there), with frames `points(n)`, in the
/// offline order (`runtime` false: each frame before the first sample at or past it) or the
/// runtime order; returns the state after each sample and its frames (time, position,
/// velocity) and the filter's counters at the end.
/// Time \[s\], position \[m\] and velocity \[m/s\] of the filter.
type State = (f64, Vector3<f64>, Vector3<f64>);

fn gappy(
    runtime: bool,
    seconds: f64,
    points: &impl Fn(usize) -> Vec<Point>,
) -> (Vec<State>, RioCounters) {
    // As `milliego odometry` runs it: no radar-only dead reckoning (the runtime never needs it
    // here, its frames come behind the sample that ends the gap).
    let cfg = ClassicalConfig {
        imu_gap_s: f64::INFINITY,
        ..ClassicalConfig::default()
    };
    let mut r = Runner::new(&cfg, true);
    let mut states = Vec::new();
    let mut n = 0;
    for k in 0..(seconds / IMU_DT) as usize {
        let s = imu(k);
        if (0.5..0.8).contains(&(s.t % 1.0)) {
            continue;
        }
        if !runtime {
            push_frames_to(&mut r, &mut n, s.t, points);
        }
        r.push_imu(s);
        if runtime {
            push_frames_to(&mut r, &mut n, s.t, points);
        }
        while r.pop_pose().is_some() {}
        if let Some((t, b, v)) = r.body_state() {
            states.push((t, b.translation.vector, v));
        }
    }
    // Updates applied more than 50 ms after their frame: only the runtime order has them.
    let mut c = r.filter_counters();
    c.late = 0;
    (states, c)
}

#[test]
fn both_orders_agree_when_several_frames_fall_in_one_imu_interval() {
    // The radar says 3 m/s forward in bursts (frames 30-44, 60-67, 90-99): the filter gates it,
    // the prior is withdrawn after a run of rejections and the filter re-anchors; in the gaps
    // three frames come between two samples, and the run of rejections must be counted alike
    // in both orders (per sample, where the offline order applies their updates together).
    let points = |n: usize| {
        let bad = (30..45).contains(&n) || (60..68).contains(&n) || (90..100).contains(&n);
        scene(if bad { [0.0, 3.0, 0.0] } else { [0.0; 3] })
    };
    let (offline, c_off) = gappy(false, 12.0, &points);
    let (runtime, c_run) = gappy(true, 12.0, &points);
    assert!(c_off.reanchors > 0, "{c_off:?}");
    assert_eq!(c_off, c_run);
    assert_eq!(offline.len(), runtime.len());
    for (a, b) in offline.iter().zip(&runtime) {
        assert_eq!(a.0, b.0);
        assert!(
            (a.1 - b.1).norm() < 1e-9 && (a.2 - b.2).norm() < 1e-9,
            "at {} s: {a:?} {b:?}",
            a.0
        );
    }
}

#[test]
fn the_rounding_likelihood_goes_to_the_rigs_its_rule_names() {
    use milliego_odometry::runner::RoundingRule;
    let walk = ClassicalConfig::default();
    let mut car = ClassicalConfig::default();
    car.rio = car.rio.ground_vehicle();
    assert_eq!(walk.rounding_likelihood, RoundingRule::Never, "the default");
    for (rule, walk_too, car_too) in [
        (RoundingRule::Never, false, false),
        (RoundingRule::GroundVehicles, false, true),
        (RoundingRule::Always, true, true),
    ] {
        assert_eq!(rule.applies(&walk), walk_too, "{rule:?}, a walk");
        assert_eq!(rule.applies(&car), car_too, "{rule:?}, a car");
    }
    // By name, as `score --rounding` takes it.
    assert_eq!("vehicles".parse(), Ok(RoundingRule::GroundVehicles));
    assert_eq!("never".parse(), Ok(RoundingRule::Never));
    assert_eq!("always".parse(), Ok(RoundingRule::Always));
    assert!("sometimes"
        .parse::<RoundingRule>()
        .unwrap_err()
        .contains("\"sometimes\""));
    // Stated on the ego-velocity settings, it holds for every rig.
    let mut stated = walk;
    stated.ego.rounding_likelihood = true;
    assert!(RoundingRule::Never.applies(&stated));
}
