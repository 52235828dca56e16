//! Helpers the CLI's integration tests share.

use std::path::Path;
use std::process::Command;

/// `milliego sim` of `family` / `motion` with `seed` for `duration` seconds into `dir`.
pub fn simulate(dir: &Path, family: &str, motion: &str, seed: u64, duration: f64) {
    let o = Command::new(env!("CARGO_BIN_EXE_milliego"))
        .args(["sim", "--family", family, "--motion", motion])
        .args([
            "--seed",
            &seed.to_string(),
            "--duration",
            &duration.to_string(),
        ])
        .arg("-o")
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "sim {family} {motion} {seed}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}
