//! Soak: `milliego run --session` with every estimator (the model as fp32 and int8, fused,
//! Doppler, IMU, and the default `auto`) over generated sessions of every family and motion, unseen seeds
//! among them the ones that once crashed the default path (tract's AMX over-read,
//! docs/amx-overread.md). Every run must exit 0 (a crash is a failed run, never a skip), give a
//! pose per expected radar frame, account for every frame, and write only finite values.
//!
//! `MILLIEGO_SOAK_DURATION` (seconds per session, default 8) lengthens the sessions for a longer
//! soak by hand.

use milliego_session::{read_tum, Session};
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::simulate;

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

/// (family, motion, seed): all five families, the three moving rigs, seeds of the benchmark's
/// held-out range and the five sessions that crashed `auto` before the AMX guard.
const SESSIONS: [(&str, &str, u64); 14] = [
    ("atrium", "handheld", 7103),
    ("store_room", "robot", 7104),
    ("office", "handheld", 8202),
    ("atrium", "robot", 8203),
    ("atrium", "headworn", 8207),
    ("corridor", "handheld", 7101),
    ("corridor", "robot", 7102),
    ("household", "headworn", 7105),
    ("office", "robot", 8201),
    ("store_room", "handheld", 8204),
    ("household", "handheld", 8205),
    ("corridor", "headworn", 8206),
    ("office", "headworn", 8208),
    ("household", "robot", 8209),
];

fn model(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../models/compact")
        .join(file)
}

/// One run; its summary JSON. Panics (the test fails) on any non-zero exit, a signal included.
fn run(session: &Path, estimator: &str, model_file: Option<&str>, out: &Path) -> serde_json::Value {
    let summary = out.with_extension("json");
    let mut cmd = Command::new(BIN);
    // From the repository root, as a user runs it: `auto` then finds the shipped int8 model.
    cmd.current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join(".."))
        .args(["run", "--session"])
        .arg(session)
        .args(["--estimator", estimator])
        .arg("--out")
        .arg(format!("tum:{}", out.display()))
        .arg("--summary-json")
        .arg(&summary);
    if let Some(m) = model_file {
        cmd.arg("--model").arg(model(m));
    }
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "milliego run --estimator {estimator} {:?} on {}: {} (a crash is a failure)\n{}",
        model_file,
        session.display(),
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap()
}

#[test]
fn every_estimator_runs_every_session_to_the_end() {
    let duration: f64 = std::env::var("MILLIEGO_SOAK_DURATION")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8.0);
    let d = tempfile::tempdir().unwrap();
    let runs: [(&str, Option<&str>); 6] = [
        ("auto", None),
        ("fused", Some("model-int8.onnx")),
        ("model", Some("model-int8.onnx")),
        ("model", Some("model.onnx")),
        ("doppler", None),
        ("imu", None),
    ];
    let mut total = 0;
    let mut handovers = 0;
    for (family, motion, seed) in SESSIONS {
        let s = d.path().join(format!("{family}-{motion}-{seed}"));
        simulate(&s, family, motion, seed, duration);
        let frames = milliego_session::streams::radar_frames(&Session::open(&s).unwrap())
            .unwrap()
            .0
            .len() as u64;
        // `auto`'s poses when it never handed over: then it ran the fused estimator throughout.
        let mut auto_fused = None;
        for (estimator, file) in runs {
            let tag = format!(
                "{family} {motion} {seed} {estimator} {}",
                file.unwrap_or("default")
            );
            let out = s.join(format!(
                "{estimator}-{}.tum",
                file.unwrap_or("default").replace('.', "_")
            ));
            let j = run(&s, estimator, file, &out);
            let fo = &j["frames_out"];
            let radar_in = j["frames_in"]["radar"].as_u64().unwrap();
            let radar_rate = fo["radar_rate"].as_u64().unwrap();
            let no_pose = fo["no_pose"].as_u64().unwrap();
            assert_eq!(radar_in, frames, "{tag}: every decoded frame fed");
            assert_eq!(j["drops"]["total"].as_u64(), Some(0), "{tag}: {j}");
            // Every radar frame either gave a pose or is counted as giving none.
            assert_eq!(radar_rate + no_pose, radar_in, "{tag}: {fo}");
            // A pose per expected frame: per frame after the 1 s levelling for the filters (fused
            // and auto included), per 5-frame keyframe window for the model (20 Hz radar).
            let expected = match estimator {
                "model" => (frames.saturating_sub(10)) / 5,
                _ => frames.saturating_sub(25),
            };
            assert!(
                radar_rate >= expected,
                "{tag}: {radar_rate} poses for {frames} frames (expected at least {expected})"
            );
            assert_eq!(fo["resets"].as_u64(), Some(1), "{tag}: one origin only");
            // `auto` runs the fused estimator with the shipped int8 model and hands over to
            // Doppler only when the learned measurements fail the online check (runs come in
            // that order).
            let h = fo["handovers"].as_u64().unwrap();
            handovers += h;
            let poses = read_tum(&out).unwrap();
            let learned = &j["learned"];
            match (estimator, file) {
                ("auto", _) => {
                    assert_eq!(learned["switched_off"].as_bool(), Some(h > 0), "{tag}: {j}");
                    assert!(learned["model_windows"].as_u64() > Some(0), "{tag}: {j}");
                    if h == 0 {
                        auto_fused = Some(poses.clone());
                    }
                }
                ("fused", _) => {
                    assert_eq!(h, 0, "{tag}: fused hands over to nothing");
                    assert_eq!(learned["switched_off"].as_bool(), Some(false), "{tag}: {j}");
                    if let Some(a) = &auto_fused {
                        assert_eq!(a, &poses, "{tag}: auto ran the fused estimator");
                    }
                }
                _ => assert_eq!(h, 0, "{tag}: hand-over in a fixed estimator"),
            }
            assert_eq!(poses.len() as u64, radar_rate, "{tag}");
            assert!(
                poses
                    .iter()
                    .all(|p| p.t.is_finite() && p.p.iter().chain(&p.q).all(|v| v.is_finite())),
                "{tag}: non-finite pose"
            );
            total += 1;
        }
    }
    println!(
        "{total} runs over {} sessions of {duration} s: all exited 0 ({handovers} hand-overs in auto)",
        SESSIONS.len()
    );
}
