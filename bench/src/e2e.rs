//! The "end-to-end (milliego run)" row group: filled from a shell command that prints a JSON
//! summary, once the `milliego run` subcommand exists.

use crate::report::{Better, Row};
use std::path::Path;
use std::process::{Command, Stdio};

/// Group name of these rows.
pub const GROUP: &str = "end-to-end (milliego run)";

/// Whether `milliego run --help` exits 0 with the binary at `milliego`.
pub fn run_available(milliego: &Path) -> bool {
    Command::new(milliego)
        .args(["run", "--help"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Rows from a JSON summary object: every numeric field becomes a row (`value` in the unit the
/// field name ends with, e.g. `windows_per_s`, `latency_ms`), with no peer.
pub fn rows_from_summary(summary: &serde_json::Value) -> Vec<Row> {
    let Some(obj) = summary.as_object() else {
        return vec![Row::missing(
            GROUP,
            "summary",
            "n/a (summary is not a JSON object)",
        )];
    };
    obj.iter()
        .filter_map(|(k, v)| {
            let x = v.as_f64()?;
            let unit = k
                .rsplit('_')
                .next()
                .filter(|u| *u != k.as_str())
                .unwrap_or("");
            Some(Row::new(
                GROUP,
                k,
                Some(x),
                unit,
                "",
                None,
                Better::Lower,
                "",
            ))
        })
        .collect()
}

/// Runs `cmd` with `sh -c` when `milliego run` exists and turns the last stdout line (a JSON
/// object) into rows; otherwise one row `n/a (milliego run not available)`.
pub fn rows(milliego: &Path, cmd: Option<&str>) -> Vec<Row> {
    if !run_available(milliego) {
        return vec![Row::missing(
            GROUP,
            "milliego run",
            "n/a (milliego run not available)",
        )];
    }
    let Some(cmd) = cmd else {
        return vec![Row::missing(
            GROUP,
            "milliego run",
            "n/a (no --e2e command given)",
        )];
    };
    let out = match Command::new("sh").args(["-c", cmd]).output() {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            return vec![Row::missing(
                GROUP,
                "milliego run",
                &format!("failed ({})", o.status),
            )]
        }
        Err(e) => {
            return vec![Row::missing(
                GROUP,
                "milliego run",
                &format!("failed ({e})"),
            )]
        }
    };
    let text = String::from_utf8_lossy(&out.stdout);
    match serde_json::from_str(text.lines().last().unwrap_or_default()) {
        Ok(v) => rows_from_summary(&v),
        Err(e) => vec![Row::missing(
            GROUP,
            "milliego run",
            &format!("bad JSON summary ({e})"),
        )],
    }
}
