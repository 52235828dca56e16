//! `milliego run` stops at start-up with one clear message when it cannot run.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn fails_with(args: &[&str], want: &str) {
    let out = Command::new(BIN).arg("run").args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} succeeded");
    assert!(err.contains(want), "{args:?}: {err}");
    assert_eq!(err.matches("error:").count(), 1, "one message: {err}");
}

#[test]
fn start_up_errors_are_one_clear_message() {
    let d = tempfile::tempdir().unwrap();
    let dev = d.path().join("no-such-tty");
    let dev = dev.to_str().unwrap();
    fails_with(
        &[
            "--radar-data",
            dev,
            "--imu",
            dev,
            "--no-configure",
            "--estimator",
            "doppler",
        ],
        "radar data port",
    );
    // Tests run in cli/, where the default models/compact/model-int8.onnx does not exist.
    fails_with(
        &["--imu", dev, "--no-configure", "--estimator", "model"],
        "needs a model file",
    );
    let junk = d.path().join("junk.onnx");
    std::fs::write(&junk, b"not onnx").unwrap();
    let junk = junk.to_str().unwrap();
    for kind in ["model", "auto"] {
        fails_with(
            &[
                "--imu",
                dev,
                "--no-configure",
                "--estimator",
                kind,
                "--model",
                junk,
            ],
            "cannot load the model",
        );
    }
    let bad = d.path().join("bad.toml");
    std::fs::write(&bad, "estimatr = \"doppler\"\n").unwrap();
    fails_with(
        &["--imu", dev, "--config", bad.to_str().unwrap()],
        "unknown field `estimatr`",
    );
    fails_with(&["--imu", dev, "--threads", "0"], "--threads");
    std::fs::write(&bad, "model_threads = 65\n").unwrap();
    fails_with(
        &["--imu", dev, "--config", bad.to_str().unwrap()],
        "model_threads: 65",
    );
    std::fs::write(&bad, "[sync]\nstall_periods = 0\n").unwrap();
    fails_with(
        &["--imu", dev, "--config", bad.to_str().unwrap()],
        "sync.stall_periods",
    );
    fails_with(
        &["--session", d.path().join("nope").to_str().unwrap()],
        "nope",
    );
    fails_with(&["--imu", dev, "--out", "udp://nohost"], "udp://HOST:PORT");
}
