//! `milliego odometry`'s filter options reach the filter: a coarse-Doppler robot session run with
//! the defaults, with the shared rounding state's correlation time stated as its default, and with
//! the state off.

use std::path::Path;
use std::process::Command;

mod common;

/// `milliego odometry` on `session` into `out` with `extra` options; the trajectory's text.
fn odometry(session: &Path, out: &Path, extra: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_milliego"))
        .arg("odometry")
        .arg("--session")
        .arg(session)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "odometry {extra:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read_to_string(out).unwrap()
}

#[test]
fn the_radar_error_time_reaches_the_filter() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    common::simulate_with(
        &session,
        "corridor",
        "robot",
        5,
        20.0,
        &["--rest-start", "3", "--doppler-step", "0.46"],
    );
    let default = odometry(&session, &dir.path().join("default.tum"), &[]);
    let stated = odometry(
        &session,
        &dir.path().join("stated.tum"),
        &["--radar-error-time", "2"],
    );
    let off = odometry(
        &session,
        &dir.path().join("off.tum"),
        &["--radar-error-time", "0"],
    );
    assert!(
        default.lines().count() > 300,
        "{} poses",
        default.lines().count()
    );
    assert_eq!(default, stated, "the default is a 2 s correlation time");
    assert_ne!(default, off, "turning the state off changes the trajectory");
}
