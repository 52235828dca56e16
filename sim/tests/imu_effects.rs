//! IMU failure modes and grades: bursts of dropped messages, other noise grades, low rates.

mod common;

use common::{decode_imu, imu_truth};
use milliego_sim::imu::{ImuGrade, ImuSpec};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::Scenario;
use milliego_sim::world::Family;

#[test]
fn gaps_drop_messages_in_bursts_and_counters_jump() {
    // The real case: an MTi-G-710 at 100 Hz delivering 68 Hz.
    let s = common::simulate_with(Family::Office, MotionKind::Handheld, 3, |s| {
        s.duration_s = 60.0;
        s.imu_hz = 100.0;
        s.imu_gap_share = 0.32;
    });
    let (msgs, bad) = decode_imu(&s.session);
    assert_eq!(bad, 0);
    assert_eq!(msgs.len() as u64, s.summary.imu_samples);
    assert_eq!(imu_truth(&s.path()).len(), msgs.len());
    let span = f64::from(msgs.last().unwrap().stf - msgs[0].stf) * 1e-4;
    let rate = (msgs.len() - 1) as f64 / span;
    let (mut bursts, mut dropped) = (0usize, 0usize);
    for w in msgs.windows(2) {
        let dc = w[1].counter.wrapping_sub(w[0].counter);
        assert!(dc >= 1);
        // SampleTimeFine jumps with the counter: 100 ticks per sample at 100 Hz.
        assert_eq!(w[1].stf - w[0].stf, u32::from(dc) * 100);
        if dc > 1 {
            bursts += 1;
            dropped += usize::from(dc - 1);
        }
    }
    let mean_burst = dropped as f64 / bursts as f64;
    eprintln!("effective rate {rate:.1} Hz, {bursts} gaps of {mean_burst:.2} samples on average");
    assert!((rate - 68.0).abs() < 4.0, "effective rate {rate} Hz");
    assert!(
        mean_burst > 3.0 && mean_burst < 8.0,
        "mean burst {mean_burst} samples"
    );
    assert!(s.session.meta.description.contains("dropped in bursts"));
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 1);
    sc.imu_gap_share = 0.9;
    assert!(sc
        .validate()
        .unwrap_err()
        .to_string()
        .contains("IMU gap share"));
}

/// Standard deviation of each gyro and accelerometer axis over a static session (the truth is
/// constant; over 10 s the bias hardly moves, so this is the white noise at the sample rate).
fn static_noise(grade: ImuGrade) -> (f64, f64, String) {
    let s = common::simulate_with(Family::Office, MotionKind::Static, 4, |s| {
        s.duration_s = 10.0;
        s.imu_spec = grade.spec();
    });
    let (msgs, bad) = decode_imu(&s.session);
    assert_eq!(bad, 0);
    let n = msgs.len() as f64;
    let sd = |f: &dyn Fn(usize) -> f64| {
        let m = (0..msgs.len()).map(f).sum::<f64>() / n;
        ((0..msgs.len()).map(|i| (f(i) - m).powi(2)).sum::<f64>() / n).sqrt()
    };
    let g = (0..3).map(|k| sd(&|i| msgs[i].gyr[k])).sum::<f64>() / 3.0;
    let a = (0..3).map(|k| sd(&|i| msgs[i].acc[k])).sum::<f64>() / 3.0;
    let device = s.session.meta.imu.as_ref().unwrap().device.clone().unwrap();
    (g, a, device)
}

#[test]
fn grades_have_their_noise_and_name() {
    let dt_sqrt = (200.0f64).sqrt();
    for grade in ImuGrade::ALL {
        let spec = grade.spec();
        let (g, a, device) = static_noise(grade);
        let (ge, ae) = (spec.gyro.white * dt_sqrt, spec.accel.white * dt_sqrt);
        eprintln!(
            "{grade}: gyro {g:.3e} rad/s (white {ge:.3e}), accel {a:.3e} m/s^2 (white {ae:.3e}), {device}"
        );
        assert!((g / ge - 1.0).abs() < 0.1, "{grade} gyro {g} vs {ge}");
        assert!((a / ae - 1.0).abs() < 0.1, "{grade} accel {a} vs {ae}");
        assert_eq!(device, grade.device());
        assert_eq!(grade.name().parse::<ImuGrade>().unwrap(), grade);
        assert_eq!(ImuGrade::of(&spec), Some(grade));
    }
    assert!("adis".parse::<ImuGrade>().is_err());
    // The ordering the presets stand for.
    let (a, b, c) = (ImuSpec::mti600(), ImuSpec::mti1(), ImuSpec::mems());
    assert!(a.accel.white < b.accel.white && b.accel.white < c.accel.white);
    assert!(a.gyro.bias_sigma < b.gyro.bias_sigma && b.gyro.bias_sigma < c.gyro.bias_sigma);
    assert!(a.accel.bias_sigma < b.accel.bias_sigma && b.accel.bias_sigma < c.accel.bias_sigma);
    assert!(b.gyro.turn_on < c.gyro.turn_on && b.accel.turn_on < c.accel.turn_on);
    assert!(b.gyro.white < c.gyro.white);
}

#[test]
fn fifty_hertz_streams_decode() {
    let s = common::simulate_with(Family::Corridor, MotionKind::Robot, 2, |s| {
        s.duration_s = 5.0;
        s.imu_hz = 50.0;
    });
    let (msgs, bad) = decode_imu(&s.session);
    assert_eq!(bad, 0);
    assert!((msgs.len() as f64 - (5.0 - 0.05) * 50.0).abs() <= 2.0);
    for w in msgs.windows(2) {
        assert_eq!(w[1].counter, w[0].counter.wrapping_add(1));
        assert_eq!(w[1].stf - w[0].stf, 200);
    }
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 1);
    sc.imu_hz = 40.0;
    assert!(sc.validate().unwrap_err().to_string().contains("50-400 Hz"));
}
