//! `milliego run --estimator model` offline on a simulated held-out session: the learned model
//! (the shipped int8 file) through the runtime's window builder and composer gives a pose per
//! keyframe, far closer to ground truth than IMU dead reckoning on the same session, and the same
//! trajectory as `milliego score`'s offline model run (same preprocessing, same chain).

use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_session::{read_tum, Session};
use std::path::PathBuf;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn model(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../models/compact")
        .join(file)
}

fn run(
    session: &std::path::Path,
    estimator: &str,
    model_file: &str,
    out: &std::path::Path,
    extra: &[&str],
) {
    let o = Command::new(BIN)
        .args(["run", "--session"])
        .arg(session)
        .args(["--estimator", estimator, "--model"])
        .arg(model(model_file))
        .arg("--out")
        .arg(format!("tum:{}", out.display()))
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "milliego run failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn the_model_estimator_runs_offline_and_beats_imu_dead_reckoning() {
    let d = tempfile::tempdir().unwrap();
    let s = d.path().join("session");
    // Held-out family (household), unseen seed.
    let o = Command::new(BIN)
        .args([
            "sim",
            "--family",
            "household",
            "--motion",
            "handheld",
            "--seed",
            "977",
        ])
        .args(["--duration", "12", "-o"])
        .arg(&s)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let gt = Trajectory::from_tum(&Session::open(&s).unwrap().groundtruth().unwrap().unwrap());

    let model_tum = d.path().join("model.tum");
    run(&s, "model", "model-int8.onnx", &model_tum, &[]);
    let poses = read_tum(&model_tum).unwrap();
    // 12 s at 20 Hz, one pose per 5-frame keyframe window (the first keyframe is the origin).
    assert!(
        (40..=50).contains(&poses.len()),
        "{} model poses for 12 s of radar at 20 Hz with gap 5",
        poses.len()
    );
    let dt: Vec<f64> = poses.windows(2).map(|w| w[1].t - w[0].t).collect();
    assert!(
        dt.iter().all(|d| (0.2..0.3).contains(d)),
        "keyframe spacing {dt:?}"
    );

    let imu_tum = d.path().join("imu.tum");
    run(&s, "imu", "model-int8.onnx", &imu_tum, &[]);
    let ate = |p: &std::path::Path| {
        evaluate(
            &gt,
            &Trajectory::from_tum(&read_tum(p).unwrap()),
            &Settings::default(),
        )
        .unwrap()
        .ate
        .mean
    };
    let (m, i) = (ate(&model_tum), ate(&imu_tum));
    eprintln!("ATE mean: model int8 {m:.3} m, IMU dead reckoning {i:.3} m");
    assert!(m < i / 3.0, "model {m} m vs IMU-only {i} m");
    assert!(m < 2.0, "model ATE {m} m on a 12 s session");

    // The model's matrix products on two threads: the same trajectory, to the last digit.
    let two_tum = d.path().join("model-2-threads.tum");
    run(
        &s,
        "model",
        "model-int8.onnx",
        &two_tum,
        &["--threads", "2"],
    );
    assert_eq!(
        std::fs::read_to_string(&two_tum).unwrap(),
        std::fs::read_to_string(&model_tum).unwrap(),
        "--threads 2 changed the model's poses"
    );
}
