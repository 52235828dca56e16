//! Shared by the import tests: the Python that writes bags with independent writers (`rosbags`,
//! `mcap`).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A Python with `rosbags`, `mcap` and `mcap-ros2-support`: `MILLIEGO_ROS_PYTHON`, else
/// `python3`. `None` (after printing a skip line) when it lacks them, unless
/// `MILLIEGO_REQUIRE_ROS=1`, which turns the skip into a failure (CI sets it).
pub fn ros_python() -> Option<String> {
    let py = std::env::var("MILLIEGO_ROS_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import rosbags, mcap, mcap_ros2"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    let msg = format!(
        "skipped: rosbags / mcap / mcap-ros2-support not importable by {py} (set MILLIEGO_ROS_PYTHON)"
    );
    if std::env::var("MILLIEGO_REQUIRE_ROS").as_deref() == Ok("1") {
        panic!("{msg}, and MILLIEGO_REQUIRE_ROS=1");
    }
    println!("{msg}");
    None
}

/// A script in `import/tests/py/`.
pub fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/py")
        .join(name)
}

/// Runs `python script args...`; panics with its output when it fails.
pub fn run_py(py: &str, script_name: &str, args: &[&str]) -> String {
    let out = Command::new(py)
        .arg(script(script_name))
        .args(args)
        .output()
        .expect("python runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{script_name} {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}
