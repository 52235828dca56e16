//! The committed C header is what cbindgen makes of the current source (`gen-header`). Needs
//! cbindgen on PATH (`cargo install --locked cbindgen`); without it the test says it skipped.

use std::path::Path;
use std::process::Command;

#[test]
fn committed_header_is_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = Command::new("cbindgen")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        println!(
            "skipped: cbindgen not on PATH, include/pose_link.h not checked \
             (cargo install --locked cbindgen)"
        );
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let fresh = tmp.path().join("pose_link.h");
    let out = Command::new("cbindgen")
        .current_dir(dir)
        .args([
            "--config",
            "cbindgen.toml",
            "--crate",
            "pose-link-c",
            "--quiet",
        ])
        .arg("--output")
        .arg(&fresh)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cbindgen failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let fresh = std::fs::read_to_string(&fresh).unwrap();
    let committed = std::fs::read_to_string(dir.join("include/pose_link.h")).unwrap();
    assert!(
        fresh == committed,
        "include/pose_link.h is out of date: run pose-link-c/gen-header and commit it\n\
         first difference at line {}",
        fresh
            .lines()
            .zip(committed.lines())
            .position(|(a, b)| a != b)
            .map_or(fresh.lines().count().min(committed.lines().count()), |i| i)
            + 1
    );
}
