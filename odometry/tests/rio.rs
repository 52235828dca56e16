//! Radar-inertial odometry on a synthetic walk with known ground truth: the filter follows the
//! trajectory, beats IMU dead reckoning by a wide margin, estimates the accelerometer bias, and its
//! velocity covariance is consistent with its errors.

use milliego_odometry::rio::{RadarMount, Rio, RioConfig, VelocityMeasurement};
use milliego_odometry::strapdown::{ImuSample, NavState, Strapdown, STANDARD_GRAVITY};
use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Ground truth: a 3 m circle at 0.3 rad/s with a 2 Hz, 5 cm bob, facing along the motion, with
/// gentle roll and pitch.
fn truth(t: f64) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let (r, w) = (3.0, 0.3);
    let p = Vector3::new(
        r * (w * t).cos(),
        r * (w * t).sin(),
        0.05 * (2.0 * std::f64::consts::PI * 2.0 * t).sin(),
    );
    let q = UnitQuaternion::from_euler_angles(
        0.05 * (1.1 * t).sin(),
        0.04 * (0.7 * t).sin(),
        w * t + std::f64::consts::FRAC_PI_2,
    );
    (p, q)
}

fn derivatives(t: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let h = 1e-4;
    let (p0, _) = truth(t - h);
    let (p1, q1) = truth(t);
    let (p2, _) = truth(t + h);
    let v = (p2 - p0) / (2.0 * h);
    let a = (p2 - 2.0 * p1 + p0) / (h * h);
    let (_, qa) = truth(t - h);
    let (_, qb) = truth(t + h);
    let w_body = (qa.inverse() * qb).scaled_axis() / (2.0 * h);
    let _ = q1;
    (v, a, w_body)
}

struct Noise {
    rng: ChaCha8Rng,
}

impl Noise {
    fn gauss(&mut self, s: f64) -> f64 {
        let u1: f64 = self.rng.gen_range(1e-12..1.0);
        let u2: f64 = self.rng.gen_range(0.0..1.0);
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos() * s
    }
    fn vec(&mut self, s: f64) -> Vector3<f64> {
        Vector3::new(self.gauss(s), self.gauss(s), self.gauss(s))
    }
}

/// One run of the synthetic walk: the filter, the dead-reckoning end error \[m\], the path \[m\]
/// and the mean velocity NEES after 5 s.
struct Walk {
    rio: Rio,
    accel_bias: Vector3<f64>,
    rio_err: f64,
    dr_err: f64,
    path: f64,
    nees: f64,
    frames: usize,
}

/// The 60 s walk with radar velocities of noise `radar_sigma` \[m/s\] per axis, stated to the
/// filter as `stated_sigma`.
fn walk(cfg: RioConfig, radar_sigma: f64, stated_sigma: f64) -> Walk {
    let (imu_hz, radar_hz, duration) = (200.0, 20.0, 60.0);
    let accel_bias = Vector3::new(0.05, -0.03, 0.02);
    let gyro_bias = Vector3::new(0.002, -0.001, 0.0005);
    let mount = RadarMount {
        rotation: UnitQuaternion::from_euler_angles(0.0, 0.0, 10f64.to_radians()),
        translation: Vector3::new(0.05, 0.1, 0.02),
    };
    let mut noise = Noise {
        rng: ChaCha8Rng::seed_from_u64(42),
    };
    let g = Vector3::new(0.0, 0.0, -STANDARD_GRAVITY);

    let (p0, q0) = truth(0.0);
    let (v0, _, _) = derivatives(0.0);
    let start = NavState {
        t: 0.0,
        q: q0,
        v: Vector3::zeros(),
        p: p0,
    }; // velocity unknown at start
    let mut rio = Rio::new(cfg, mount, start);
    let mut dr = Strapdown::new(NavState { v: v0, ..start }, STANDARD_GRAVITY); // dead reckoning, true start
    let n = (duration * imu_hz) as usize;
    let every = (imu_hz / radar_hz) as usize;
    let (mut nees_sum, mut nees_n) = (0.0, 0);
    let mut path = 0.0;
    let mut last_p = p0;
    for i in 0..=n {
        let t = i as f64 / imu_hz;
        let (v, a, w) = derivatives(t);
        let (p, q) = truth(t);
        path += (p - last_p).norm();
        last_p = p;
        let f = q.inverse() * (a - g);
        let sa = cfg.accel_noise * imu_hz.sqrt();
        let sg = cfg.gyro_noise * imu_hz.sqrt();
        let s = ImuSample {
            t,
            accel: (f + accel_bias + noise.vec(sa)).into(),
            gyro: (w + gyro_bias + noise.vec(sg)).into(),
        };
        rio.push_imu(s);
        dr.push(s);
        if i % every == 0 && i > 0 {
            let vr = mount.rotation.inverse() * (q.inverse() * v + w.cross(&mount.translation))
                + noise.vec(radar_sigma);
            let c = stated_sigma * stated_sigma;
            rio.push_velocity(VelocityMeasurement {
                t,
                carried: false,
                velocity: vr.into(),
                covariance: [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, c]],
                shared_covariance: [[0.0; 3]; 3],
                doppler_step: 0.0,
            });
            if t > 5.0 {
                let e = rio.state().v - v;
                let pv = rio.covariance().fixed_view::<3, 3>(3, 3).into_owned();
                nees_sum += (e.transpose() * pv.try_inverse().unwrap() * e)[(0, 0)];
                nees_n += 1;
            }
        }
    }
    let (p_end, _) = truth(duration);
    Walk {
        rio_err: (rio.state().p - p_end).norm(),
        dr_err: (dr.state().p - p_end).norm(),
        rio,
        accel_bias,
        path,
        nees: nees_sum / f64::from(nees_n),
        frames: n / every,
    }
}

#[test]
fn follows_a_walk_and_beats_dead_reckoning() {
    let Walk {
        rio,
        accel_bias,
        rio_err,
        dr_err,
        path,
        nees: mean_nees,
        frames,
    } = walk(RioConfig::default(), 0.03, 0.03);
    let c = rio.counters();
    assert_eq!((c.updates + c.gated) as usize, frames, "{c:?}");
    assert!(c.gated <= 2, "{c:?}");
    assert!(
        rio_err < 0.02 * path,
        "RIO drift {rio_err:.2} m over {path:.1} m"
    );
    assert!(
        rio_err * 20.0 < dr_err,
        "RIO {rio_err:.2} m vs dead reckoning {dr_err:.2} m"
    );
    let (ba, _) = rio.biases();
    assert!(
        (ba - accel_bias).norm() < 0.6 * accel_bias.norm(),
        "accel bias estimate {ba:?} vs {accel_bias:?}"
    );
    println!(
        "path {path:.1} m: RIO end error {rio_err:.3} m, dead reckoning {dr_err:.1} m, accel bias error {:.4} m/s^2, velocity NEES {mean_nees:.2}, radar noise scale {:.3}, {c:?}",
        (ba - accel_bias).norm(),
        rio.radar_noise_scale()
    );
    assert!((0.3..9.0).contains(&mean_nees), "velocity NEES {mean_nees}");
    // The stated noise is right: the scale stays near 1.
    assert!(rio.radar_noise_scale() < 1.3, "{}", rio.radar_noise_scale());
}

#[test]
fn a_radar_noisier_than_stated_is_found_and_its_covariance_scaled() {
    // Noise 0.06 m/s stated as 0.02: the covariance is 9x too small.
    let cfg = RioConfig::default();
    let fixed = walk(
        RioConfig {
            radar_noise_window: 0.0,
            ..cfg
        },
        0.06,
        0.02,
    );
    let adapted = walk(cfg, 0.06, 0.02);
    // The same radar stated right.
    let right = walk(
        RioConfig {
            radar_noise_window: 0.0,
            ..cfg
        },
        0.06,
        0.06,
    );
    let scale = adapted.rio.radar_noise_scale();
    println!(
        "noise scale {scale:.2} (9 is right); velocity NEES {:.2} as stated, {:.2} adapted, {:.2} stated right; end error {:.3} / {:.3} / {:.3} m",
        fixed.nees, adapted.nees, right.nees, fixed.rio_err, adapted.rio_err, right.rio_err
    );
    assert_eq!(fixed.rio.radar_noise_scale(), 1.0);
    assert!((6.0..10.0).contains(&scale), "noise scale {scale}");
    // Over-confident as stated (41 against 4.9 when stated right); once scaled, within twice
    // the filter stated right (7.5).
    assert!(
        fixed.nees > 4.0 * right.nees,
        "velocity NEES as stated {} against {}",
        fixed.nees,
        right.nees
    );
    assert!(
        adapted.nees < 2.0 * right.nees,
        "velocity NEES adapted {} against {}",
        adapted.nees,
        right.nees
    );
}

#[test]
fn a_radar_quieter_than_stated_keeps_its_stated_covariance() {
    // The stated covariance is a floor: a scale below 1 was measured and made the simulated
    // sessions worse (docs/odometry.md, "Radar noise adaptation").
    let w = walk(RioConfig::default(), 0.01, 0.03);
    assert_eq!(w.rio.radar_noise_scale(), 1.0);
    let free = walk(
        RioConfig {
            radar_noise_scale_bounds: [0.01, 10.0],
            ..RioConfig::default()
        },
        0.01,
        0.03,
    );
    let s = free.rio.radar_noise_scale();
    assert!((0.05..0.3).contains(&s), "noise scale {s} (1/9 is right)");
}

#[test]
fn outlying_velocity_measurements_are_gated() {
    let mut rio = Rio::new(
        RioConfig::default(),
        RadarMount::default(),
        NavState::at_rest(0.0),
    );
    for i in 0..=200 {
        let t = i as f64 * 0.005;
        rio.push_imu(ImuSample {
            t,
            accel: [0.0, 0.0, STANDARD_GRAVITY],
            gyro: [0.0; 3],
        });
        if i % 10 == 0 && i > 0 {
            let v = if i == 100 { [25.0, 0.0, 0.0] } else { [0.0; 3] };
            rio.push_velocity(VelocityMeasurement {
                t,
                carried: false,
                velocity: v,
                covariance: [[1e-3, 0.0, 0.0], [0.0, 1e-3, 0.0], [0.0, 0.0, 1e-3]],
                shared_covariance: [[0.0; 3]; 3],
                doppler_step: 0.0,
            });
        }
    }
    assert_eq!(rio.counters().gated, 1);
    assert_eq!(rio.counters().updates, 19);
    assert!(rio.state().v.norm() < 0.05);
}

#[test]
fn levelling_recovers_roll_and_pitch() {
    let q = UnitQuaternion::from_euler_angles(0.1, -0.2, 0.0);
    let f = q.inverse() * Vector3::new(0.0, 0.0, STANDARD_GRAVITY);
    let rio = Rio::levelled(RioConfig::default(), RadarMount::default(), 0.0, f.into());
    let (r, p, y) = rio.state().q.euler_angles();
    assert!(
        (r - 0.1).abs() < 1e-9 && (p + 0.2).abs() < 1e-9 && y.abs() < 1e-9,
        "{r} {p} {y}"
    );
}

/// A filter standing still, levelled, fed 100 Hz samples and 50 Hz barometric heights from
/// `height(t)` up to `until` \[s\].
fn standing_with_barometer(height: impl Fn(f64) -> f64, until: f64) -> Rio {
    let g = [0.0, 0.0, STANDARD_GRAVITY];
    let mut rio = Rio::levelled(RioConfig::default(), RadarMount::default(), 0.0, g);
    let mut k = 0u32;
    loop {
        let t = f64::from(k) * 0.01;
        if t > until {
            return rio;
        }
        if k.is_multiple_of(2) {
            rio.push_height(t, height(t));
        }
        rio.push_imu(ImuSample {
            t,
            accel: g,
            gyro: [0.0; 3],
        });
        k += 1;
    }
}

#[test]
fn a_barometer_rejected_for_a_second_re_anchors_the_height() {
    // The barometric height steps 3 m at 10 s (as it does when the filter's own height has run
    // 3 m away): every reading then fails the gate of a filter sure of its height. After a
    // second of rejections the filter takes the barometer's height again.
    let step = |t: f64| if t < 10.0 { 0.0 } else { 3.0 };
    let rio = standing_with_barometer(step, 10.9);
    let c = *rio.counters();
    assert_eq!(c.baro_reanchors, 0);
    assert!(c.baro_rejected >= 40, "{c:?}");
    assert!(rio.state().p.z.abs() < 0.1, "{}", rio.state().p.z);
    let rio = standing_with_barometer(step, 12.0);
    let c = *rio.counters();
    assert_eq!(c.baro_reanchors, 1, "{c:?}");
    assert!(c.baro_rejected < 60, "{c:?}");
    assert!((rio.state().p.z - 3.0).abs() < 0.3, "{}", rio.state().p.z);
    // A reading off once in a while never re-anchors.
    let rio = standing_with_barometer(
        |t| {
            if ((t * 50.0).round() as u32).is_multiple_of(25) {
                3.0
            } else {
                0.0
            }
        },
        30.0,
    );
    let c = *rio.counters();
    assert_eq!(c.baro_reanchors, 0, "{c:?}");
    assert!(c.baro_rejected > 0 && rio.state().p.z.abs() < 0.1, "{c:?}");
}

/// A filter that accelerated forward at 8 m/s^2 for 2 s without radar (its yaw error now correlated with
/// its position error), given a zero-velocity and a position-hold update: the largest rotation
/// either update applied about the world vertical \[rad\], and the largest in all \[rad\].
fn rest_after_acceleration(radar_heading: bool) -> (f64, f64) {
    let cfg = RioConfig {
        radar_heading,
        // Yaw, not tilt, uncertain: the lateral position error is mostly heading.
        init_gyro_bias_std: 0.05,
        init_tilt_std: 0.002,
        ..RioConfig::default()
    };
    let g = [0.0, 0.0, STANDARD_GRAVITY];
    let mut rio = Rio::levelled(cfg, RadarMount::default(), 0.0, g);
    for k in 0..=400 {
        rio.push_imu(ImuSample {
            t: f64::from(k) * 0.005,
            accel: [8.0, 0.0, STANDARD_GRAVITY],
            gyro: [0.0, 0.0, 0.02],
        });
    }
    let p = rio.covariance();
    assert!(
        p[(1, 8)].abs() > 1e-6,
        "no position-yaw correlation to test with: {}",
        p[(1, 8)]
    );
    // Each update on its own copy of the filter.
    let turn = |update: &dyn Fn(&mut Rio)| {
        let mut r = rio.clone();
        update(&mut r);
        (r.state().q * rio.state().q.inverse()).scaled_axis()
    };
    let a = turn(&|r| r.zero_velocity(0.01));
    // Held 0.5 m to the left of where the filter is: across the motion, where yaw shows.
    let b = turn(&|r| {
        let anchor = r.state().p + Vector3::new(0.0, 0.5, 0.0);
        r.hold_position(anchor, 0.01)
    });
    (
        if a.z.abs() > b.z.abs() { a.z } else { b.z },
        a.norm().max(b.norm()),
    )
}

#[test]
fn rest_updates_leave_the_heading_to_the_gyro() {
    // A world velocity or position cannot observe heading: a rest taken in motion (a false
    // rest) must not turn it through the velocity-yaw correlation.
    let (about_vertical, all) = rest_after_acceleration(false);
    println!("kept: {about_vertical:.2e} rad about the vertical of {all:.2e} rad");
    assert!(
        all > 1e-3,
        "the rest corrected the attitude by only {all:.2e} rad"
    );
    assert!(
        about_vertical.abs() < 1e-9,
        "heading moved {about_vertical:.3e} rad"
    );
    // With the radar allowed to correct heading, rests may too (the correlation is real).
    let (about_vertical, all) = rest_after_acceleration(true);
    println!("free: {about_vertical:.2e} rad about the vertical of {all:.2e} rad");
    assert!(
        about_vertical.abs() > 5e-3,
        "heading moved only {about_vertical:.3e} rad"
    );
}

/// A slow rig under coarse Doppler: it cruises at 0.2 m/s and every frame reads 0 (all its
/// points round to 0 under 0.46 m/s steps), stated with the rounding the frame's points share.
/// Returns the filter's speed after `secs` \[s\].
fn cruise_reading_zero(cfg: RioConfig, secs: f64) -> f64 {
    let cfg = RioConfig {
        // The filter knows its velocity, attitude and IMU biases when the zeros begin (as after
        // a rest and a radar that saw the start of the motion).
        init_velocity_std: 0.02,
        init_tilt_std: 0.002,
        init_accel_bias_std: 0.005,
        init_gyro_bias_std: 5e-4,
        ..cfg
    };
    let start = NavState {
        v: Vector3::new(0.2, 0.0, 0.0),
        ..NavState::at_rest(0.0)
    };
    let mut rio = Rio::new(cfg, RadarMount::default(), start);
    let (shared, white) = (0.03, 0.002);
    let diag = |s: f64| [[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]];
    for i in 0..=(secs * 100.0).round() as usize {
        let t = i as f64 * 0.01;
        rio.push_imu(ImuSample {
            t,
            accel: [0.0, 0.0, STANDARD_GRAVITY],
            gyro: [0.0; 3],
        });
        if i % 5 == 0 && i > 0 {
            rio.push_velocity(VelocityMeasurement {
                t,
                carried: false,
                velocity: [0.0; 3],
                covariance: diag(shared + white),
                shared_covariance: diag(shared),
                doppler_step: 0.46,
            });
        }
    }
    assert_eq!(
        rio.counters().gated,
        0,
        "the zeros are within their covariance"
    );
    rio.state().v.norm()
}

#[test]
fn a_rounding_the_frames_share_does_not_pin_a_slow_rig_to_zero() {
    // Twenty identical readings a second are about one reading of the rounding per correlation
    // time (2 s), not twenty: as a state the shared error takes the repeats, and the IMU keeps
    // the speed over that time.
    let tau = RioConfig::default().radar_error_time_s;
    let kept = cruise_reading_zero(RioConfig::default(), tau);
    assert!(
        kept > 0.17,
        "speed {kept} m/s after {tau} s of zeros (truth 0.2)"
    );
    // Taken as fresh noise each frame, the same readings pin the filter to zero.
    let white = cruise_reading_zero(
        RioConfig {
            radar_error_state: false,
            ..RioConfig::default()
        },
        tau,
    );
    assert!(
        white < 0.1,
        "speed {white} m/s with the rounding taken as white"
    );
}

/// A straight walk at `speed` \[m/s\] along x with a 2 Hz, 3 cm step bob, whose radar gives
/// velocities for the first 10 s and none for the next 20 s, while the accelerometer's x bias
/// steps by 0.08 m/s^2 at 10 s (what a small tilt error or a warming MEMS part does): returns
/// the horizontal speed error \[m/s\] at the end and the walking-pace bounds applied.
fn walk_the_radar_loses(cfg: RioConfig, speed: f64) -> (f64, u64) {
    let imu_hz = 200.0;
    let mount = RadarMount {
        rotation: UnitQuaternion::identity(),
        translation: Vector3::zeros(),
    };
    let g = Vector3::new(0.0, 0.0, -STANDARD_GRAVITY);
    let bob = |t: f64| 0.03 * (2.0 * std::f64::consts::PI * 2.0 * t).sin();
    let mut noise = Noise {
        rng: ChaCha8Rng::seed_from_u64(7),
    };
    let start = NavState {
        t: 0.0,
        q: UnitQuaternion::identity(),
        v: Vector3::new(speed, 0.0, 0.0),
        p: Vector3::zeros(),
    };
    let mut rio = Rio::new(cfg, mount, start);
    let n = (30.0 * imu_hz) as usize;
    for i in 0..=n {
        let t = i as f64 / imu_hz;
        let w2 = (2.0 * std::f64::consts::PI * 2.0).powi(2);
        let a = Vector3::new(0.0, 0.0, -w2 * bob(t));
        let bias = if t >= 10.0 {
            Vector3::new(0.08, 0.0, 0.0)
        } else {
            Vector3::zeros()
        };
        let sa = cfg.accel_noise * imu_hz.sqrt();
        let sg = cfg.gyro_noise * imu_hz.sqrt();
        rio.push_imu(ImuSample {
            t,
            accel: (a - g + bias + noise.vec(sa)).into(),
            gyro: noise.vec(sg).into(),
        });
        if i % 10 == 0 && i > 0 {
            if t < 10.0 {
                let v = Vector3::new(
                    speed,
                    0.0,
                    2.0 * std::f64::consts::PI
                        * 2.0
                        * 0.03
                        * (2.0 * std::f64::consts::PI * 2.0 * t).cos(),
                );
                let c = 0.05 * 0.05;
                rio.push_velocity(VelocityMeasurement {
                    t,
                    carried: false,
                    velocity: (v + noise.vec(0.05)).into(),
                    covariance: [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, c]],
                    shared_covariance: [[0.0; 3]; 3],
                    doppler_step: 0.0,
                });
            } else {
                rio.push_frame_without_velocity(t);
            }
        }
    }
    let v = rio.state().v;
    ((v.x.hypot(v.y) - speed).abs(), rio.counters().pace_bounds)
}

#[test]
fn a_walk_the_radar_stops_seeing_keeps_its_pace() {
    // Without the walking-pace bound the IMU carries the bias step into the speed (1.6 m/s over
    // 20 s); with it, the filter holds the pace it walked at when the radar last saw it.
    let cfg = RioConfig::default();
    let (e_on, bounds) = walk_the_radar_loses(cfg, 1.3);
    let off = RioConfig {
        pace_std: f64::INFINITY,
        ..cfg
    };
    let (e_off, none) = walk_the_radar_loses(off, 1.3);
    println!("speed error after 20 s without radar: {e_on:.3} m/s with the pace bound ({bounds} applied), {e_off:.3} m/s without");
    assert_eq!(none, 0);
    assert!(bounds > 0);
    // The filter admits it has lost its speed only once its own variance passes the bound's, so
    // the pace holds the speed within about two of the bound's deviations, not one.
    assert!(
        e_on < 0.5 && e_on < 0.25 * e_off,
        "{e_on:.3} vs {e_off:.3} m/s"
    );
}

/// A ground vehicle cruising straight at `speed` \[m/s\] with its velocity `slip` \[rad\] off its
/// forward axis (a tyre's slip angle, or a vehicle frame misaligned by it), its radar at the IMU
/// measuring that velocity with 0.05 m/s noise at 10 Hz for 10 s: returns the ground vehicle
/// constraint's (applications, gated) and the filter's sideways velocity error \[m/s\] at the end.
fn cruise_with_slip(cfg: RioConfig, speed: f64, slip: f64) -> (u64, u64, f64) {
    let imu_hz = 200.0;
    let truth = Vector3::new(speed * slip.cos(), speed * slip.sin(), 0.0);
    let start = NavState {
        v: truth,
        ..NavState::at_rest(0.0)
    };
    let mut rio = Rio::new(cfg, RadarMount::default(), start);
    let mut noise = Noise {
        rng: ChaCha8Rng::seed_from_u64(11),
    };
    let c = 0.05 * 0.05;
    for i in 0..=(10.0 * imu_hz) as usize {
        let t = i as f64 / imu_hz;
        rio.push_imu(ImuSample {
            t,
            accel: (Vector3::new(0.0, 0.0, STANDARD_GRAVITY)
                + noise.vec(cfg.accel_noise * imu_hz.sqrt()))
            .into(),
            gyro: noise.vec(cfg.gyro_noise * imu_hz.sqrt()).into(),
        });
        if i % 20 == 0 && i > 0 {
            rio.push_velocity(VelocityMeasurement {
                t,
                carried: false,
                velocity: (truth + noise.vec(0.05)).into(),
                covariance: [[c, 0.0, 0.0], [0.0, c, 0.0], [0.0, 0.0, c]],
                shared_covariance: [[0.0; 3]; 3],
                doppler_step: 0.0,
            });
        }
    }
    let k = rio.counters();
    (
        k.nonholonomic_updates,
        k.nonholonomic_gated,
        (rio.state().v.y - truth.y).abs(),
    )
}

#[test]
fn a_ground_vehicles_constraint_widens_with_its_speed() {
    let car = RioConfig::default().ground_vehicle();
    // A car at 10 m/s slipping by a degree moves 0.17 m/s sideways: inside the constraint's
    // deviation at that speed, so the constraint is never gated and most of the radar's
    // sideways velocity stands.
    let slip = 1f64.to_radians();
    let (applied, gated, error) = cruise_with_slip(car, 10.0, slip);
    println!("car at 10 m/s, 1 deg slip: constraint applied {applied}, gated {gated}, sideways error {error:.3} m/s");
    assert_eq!(gated, 0);
    assert!(applied >= 100);
    assert!(error < 0.08, "sideways velocity {error:.3} m/s off of 0.17");
    // Held to its standstill deviation at every speed, the constraint pulls that slip away.
    let stiff = RioConfig {
        nonholonomic_angle: 0.0,
        ..car
    };
    let (_, _, pulled) = cruise_with_slip(stiff, 10.0, slip);
    println!("the same with the standstill deviation at any speed: sideways error {pulled:.3} m/s");
    assert!(pulled > 1.5 * error, "{pulled:.3} against {error:.3} m/s");
}
