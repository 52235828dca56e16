//! The IMU stream: decodes with the real framer, its clock maps to host time through the
//! recorded truth, its noise has the configured Allan deviation, and integrating it follows the
//! ground truth.

mod common;

use common::{decode_imu, imu_truth, Gt, Sim};
use milliego_sim::imu::{ImuSpec, GRAVITY, MESSAGE_LEN, STATUS_WORD};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{sensor_pose, IMU_LATENCY_S, IMU_START_S};
use milliego_sim::world::Family;
use nalgebra::{UnitQuaternion, Vector3};
use std::sync::OnceLock;

const DURATION_S: f64 = 20.0;

fn walking() -> &'static Sim {
    static S: OnceLock<Sim> = OnceLock::new();
    S.get_or_init(|| common::simulate(Family::StoreRoom, MotionKind::Handheld, 5, DURATION_S))
}

fn host_of(s: &Sim, stf: u32) -> f64 {
    let c = s.session.meta.clock.unwrap();
    (f64::from(stf) * 1e-4 - c.imu_offset_s) / (1.0 + c.imu_drift_ppm * 1e-6)
}

#[test]
fn stream_decodes_with_contiguous_counters_and_clock_truth() {
    for s in [
        walking(),
        &common::simulate_with(Family::Atrium, MotionKind::Robot, 2, |s| {
            s.duration_s = 10.0;
            s.imu_hz = 400.0;
        }),
        &common::simulate_with(Family::Household, MotionKind::Headworn, 9, |s| {
            s.duration_s = 10.0;
            s.imu_hz = 100.0;
            s.imu_baud = 115_200;
        }),
    ] {
        let (msgs, bad) = decode_imu(&s.session);
        assert_eq!(bad, 0, "bad frames or other messages");
        let hz = s.scenario.imu_hz;
        let implied = (s.scenario.duration_s - IMU_START_S) * hz;
        assert!(
            (msgs.len() as f64 - implied).abs() <= 2.0,
            "{} samples, implied {implied}",
            msgs.len()
        );
        assert_eq!(msgs.len() as u64, s.summary.imu_samples);
        let baud = f64::from(s.session.meta.imu.as_ref().unwrap().baud);
        let on_wire = MESSAGE_LEN as f64 * 10.0 / baud;
        for w in msgs.windows(2) {
            assert_eq!(
                w[1].counter,
                w[0].counter.wrapping_add(1),
                "PacketCounter skips"
            );
            let ticks = w[1].stf - w[0].stf;
            assert!(
                (f64::from(ticks) - 1e4 / hz).abs() <= 1.0,
                "SampleTimeFine step {ticks}"
            );
        }
        for m in &msgs {
            assert_eq!(m.status, STATUS_WORD);
            // Sample instant (sensor clock -> host via the truth) + latency + bytes on the wire
            // <= the read that completed it <= that + USB latency (1 ms) + rounding.
            let late = m.host_ns as f64 * 1e-9 - (host_of(s, m.stf) + IMU_LATENCY_S + on_wire);
            assert!(
                (-2e-5..1.1e-3).contains(&late),
                "sample {}: {late} s",
                m.counter
            );
        }
    }
}

/// Overlapping Allan deviation at `m` samples of `x`.
fn adev(x: &[f64], m: usize, dt: f64) -> f64 {
    let mut c = vec![0.0; x.len() + 1];
    for (i, v) in x.iter().enumerate() {
        c[i + 1] = c[i] + v * dt;
    }
    let tau = m as f64 * dt;
    let n = x.len() + 1;
    let mut s = 0.0;
    let mut k = 0;
    for i in 0..n - 2 * m {
        let d = c[i + 2 * m] - 2.0 * c[i + m] + c[i];
        s += d * d;
        k += 1;
    }
    (s / (2.0 * tau * tau * k as f64)).sqrt()
}

#[test]
fn allan_deviation_at_one_second_matches_the_configuration() {
    let s = common::simulate_with(Family::Office, MotionKind::Static, 21, |s| {
        s.duration_s = 300.0;
        s.radar_hz = 10.0;
    });
    let (msgs, bad) = decode_imu(&s.session);
    assert_eq!(bad, 0);
    let spec = ImuSpec::mti1();
    let hz = s.scenario.imu_hz;
    let m = hz as usize; // tau = 1 s
    for (name, get, want) in [
        ("gyro", 0, spec.gyro.allan_deviation(1.0)),
        ("accel", 1, spec.accel.allan_deviation(1.0)),
    ] {
        for axis in 0..3 {
            let x: Vec<f64> = msgs
                .iter()
                .map(|s| if get == 0 { s.gyr[axis] } else { s.acc[axis] })
                .collect();
            let got = adev(&x, m, 1.0 / hz);
            eprintln!("{name} axis {axis}: Allan deviation at 1 s {got:.3e}, configured {want:.3e} ({:+.1} %)", (got / want - 1.0) * 100.0);
            assert!(
                (got / want - 1.0).abs() < 0.2,
                "{name} axis {axis}: {got} vs {want}"
            );
        }
    }
    // At rest the accelerometer reads gravity.
    let mean = msgs.iter().map(|m| m.acc).sum::<Vector3<f64>>() / msgs.len() as f64;
    assert!((mean.norm() - GRAVITY).abs() < 0.1, "|f| = {}", mean.norm());
}

#[test]
fn one_second_of_imu_integration_follows_the_ground_truth() {
    let s = walking();
    let (msgs, _) = decode_imu(&s.session);
    let biases = imu_truth(&s.path());
    assert_eq!(biases.len(), msgs.len());
    let gt = Gt::load(&s.session);
    let (t_bi, q_bi) = sensor_pose(&s.session.meta.extrinsics.imu);
    let spec = ImuSpec::mti1();
    let g = Vector3::new(0.0, 0.0, -GRAVITY);
    let hz = s.scenario.imu_hz;
    let n = hz as usize; // 1 s
                         // Budget (T = 1 s): white accelerometer noise N_a T^1.5 / sqrt(3) and the gyro noise's
                         // attitude error seen through gravity g N_g T^2.5 / sqrt(20); 4 sigma plus 1 mm for the
                         // ground truth's interpolation.
    let sp = ((spec.accel.white / 3f64.sqrt()).powi(2)
        + (GRAVITY * spec.gyro.white / 20f64.sqrt()).powi(2))
    .sqrt();
    let pos_budget = 5.0 * sp + 1e-3;
    let att_budget = 5.0 * spec.gyro.white + 2e-5;
    let mut worst = (0.0f64, 0.0f64);
    let mut naive_worst = 0.0f64;
    let mut start = 0;
    while start + n < msgs.len() {
        let t0 = host_of(s, msgs[start].stf);
        let mut q = gt.q(t0) * q_bi;
        let mut v = gt.v(t0, &t_bi);
        let mut p = gt.p(t0, &t_bi);
        let mut v_naive = v;
        let mut p_naive = p;
        let mut q_naive = q;
        for k in start..start + n {
            let (a, b) = (&msgs[k], &msgs[k + 1]);
            let dt = host_of(s, b.stf) - host_of(s, a.stf);
            let (ba, bg) = (biases[k].1, biases[k].2);
            let (ba2, bg2) = (biases[k + 1].1, biases[k + 1].2);
            // Trapezoid in the world frame, midpoint rotation.
            let q1 =
                q * UnitQuaternion::from_scaled_axis(((a.gyr - bg) + (b.gyr - bg2)) * 0.5 * dt);
            let acc0 = q * (a.acc - ba) + g;
            let acc1 = q1 * (b.acc - ba2) + g;
            p += v * dt + (2.0 * acc0 + acc1) / 6.0 * dt * dt;
            v += (acc0 + acc1) * 0.5 * dt;
            q = q1;
            // The same without removing the biases (must do worse over the session).
            let qn1 = q_naive * UnitQuaternion::from_scaled_axis((a.gyr + b.gyr) * 0.5 * dt);
            let an0 = q_naive * a.acc + g;
            let an1 = qn1 * b.acc + g;
            p_naive += v_naive * dt + (2.0 * an0 + an1) / 6.0 * dt * dt;
            v_naive += (an0 + an1) * 0.5 * dt;
            q_naive = qn1;
        }
        let t1 = host_of(s, msgs[start + n].stf);
        let dp = (p - gt.p(t1, &t_bi)).norm();
        let dq = (q.inverse() * (gt.q(t1) * q_bi)).angle();
        if std::env::var_os("SIM_DEBUG").is_some() {
            eprintln!("t0 {t0:.2} dp {dp:.4} dq {dq:.5}");
        }
        worst = (worst.0.max(dp), worst.1.max(dq));
        naive_worst = naive_worst.max((p_naive - gt.p(t1, &t_bi)).norm());
        let _ = q_naive;
        start += n / 2;
    }
    eprintln!(
        "1 s integration: worst position error {:.2} mm (budget {:.2} mm), attitude {:.4} deg (budget {:.4} deg); with the biases left in {:.1} mm",
        worst.0 * 1e3,
        pos_budget * 1e3,
        worst.1.to_degrees(),
        att_budget.to_degrees(),
        naive_worst * 1e3
    );
    assert!(
        worst.0 < pos_budget,
        "position error {} m > {pos_budget} m",
        worst.0
    );
    assert!(
        worst.1 < att_budget,
        "attitude error {} rad > {att_budget} rad",
        worst.1
    );
    assert!(naive_worst > worst.0, "the biases made no difference");
}
