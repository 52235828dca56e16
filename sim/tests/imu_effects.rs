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

#[test]
fn barometer_reads_the_true_height_through_the_standard_atmosphere() {
    use milliego_sim::imu::{standard_altitude, standard_pressure, BARO_NOISE_PA};
    let s = common::simulate_with(Family::Office, MotionKind::Handheld, 6, |s| {
        s.duration_s = 30.0;
        s.baro_hz = 50.0;
    });
    assert!(s.session.meta.description.contains("barometer 50 Hz"));
    let (all, baro) = common::decode_imu_all(&s.session);
    let (imu, bad) = decode_imu(&s.session);
    assert_eq!(bad, 0);
    assert_eq!(all.len(), imu.len() + baro.len());
    // One PacketCounter sequence over IMU and pressure messages, as the device sends them.
    for w in all.windows(2) {
        assert_eq!(w[1].0, w[0].0.wrapping_add(1), "counter skips");
        assert!(w[1].1 >= w[0].1, "sample time goes back");
    }
    let rate = (baro.len() - 1) as f64 / (f64::from(baro.last().unwrap().stf - baro[0].stf) * 1e-4);
    assert!((rate - 50.0).abs() < 0.01, "{rate} Hz");
    // The start altitude from the truth file's header; the bias per row.
    let text = std::fs::read_to_string(s.path().join("baro_truth.csv")).unwrap();
    let h0: f64 = text
        .lines()
        .find_map(|l| l.split("start altitude ").nth(1))
        .and_then(|r| r.split(' ').next())
        .unwrap()
        .parse()
        .unwrap();
    let bias: Vec<f64> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(',').nth(3).unwrap().parse().unwrap())
        .collect();
    assert_eq!(bias.len(), baro.len());
    let gt = common::Gt::load(&s.session);
    let (t_bi, _) = milliego_sim::scenario::sensor_pose(&s.session.meta.extrinsics.imu);
    let clk = s.session.meta.clock.unwrap();
    let (mut res_pa, mut res_m) = (Vec::new(), Vec::new());
    for (m, b) in baro.iter().zip(&bias) {
        let th = (f64::from(m.stf) * 1e-4 - clk.imu_offset_s) / (1.0 + clk.imu_drift_ppm * 1e-6);
        let z = gt.p(th, &t_bi).z;
        res_pa.push(f64::from(m.pa) - b - standard_pressure(h0 + z));
        res_m.push(standard_altitude(f64::from(m.pa) - b) - h0 - z);
    }
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let mean = res_pa.iter().sum::<f64>() / res_pa.len() as f64;
    let expect = (BARO_NOISE_PA.powi(2) + 1.0 / 12.0).sqrt();
    eprintln!(
        "{} pressure samples, h0 {h0:.1} m: residual mean {mean:.3} Pa, rms {:.3} Pa (expected {expect:.3}), height rms {:.3} m",
        baro.len(),
        rms(&res_pa),
        rms(&res_m)
    );
    assert!(mean.abs() < 0.2, "mean {mean} Pa");
    assert!(
        (rms(&res_pa) / expect - 1.0).abs() < 0.15,
        "rms {} Pa",
        rms(&res_pa)
    );
    assert!(rms(&res_m) < 0.15, "height rms {} m", rms(&res_m));
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 1);
    sc.baro_hz = 200.0;
    assert!(sc
        .validate()
        .unwrap_err()
        .to_string()
        .contains("barometer rate"));
    sc.baro_hz = 100.0;
    sc.imu_hz = 370.0;
    sc.imu_baud = 230_400;
    assert!(sc.validate().is_err());
    sc.baro_hz = 0.0;
    assert!(sc.validate().is_ok());
    sc.baro_hz = 100.0;
    assert!(sc
        .validate()
        .unwrap_err()
        .to_string()
        .contains("barometer at 100 Hz"));
}
