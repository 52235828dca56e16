//! Helpers the CLI's integration tests share.

// Each test binary compiles this module and uses some of it.
#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// `milliego sim` of `family` / `motion` with `seed` for `duration` seconds into `dir`.
pub fn simulate(dir: &Path, family: &str, motion: &str, seed: u64, duration: f64) {
    simulate_with(dir, family, motion, seed, duration, &[]);
}

/// [`simulate`] with `extra` options for `milliego sim` (rests, a coarse Doppler step, a mount).
pub fn simulate_with(
    dir: &Path,
    family: &str,
    motion: &str,
    seed: u64,
    duration: f64,
    extra: &[&str],
) {
    let o = Command::new(env!("CARGO_BIN_EXE_milliego"))
        .args(["sim", "--family", family, "--motion", motion])
        .args([
            "--seed",
            &seed.to_string(),
            "--duration",
            &duration.to_string(),
        ])
        .args(extra)
        .arg("-o")
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "sim {family} {motion} {seed} {extra:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}
