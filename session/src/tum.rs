//! TUM trajectories: one pose per line, `t tx ty tz qx qy qz qw` (t \[s\], position \[m\], unit
//! quaternion with the scalar last); `#` comments.

use crate::{err, io_err, ErrorKind, SessionError};
use std::io::Write;
use std::path::Path;

/// One pose of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TumPose {
    /// Time \[s\] (session host clock for ground truth).
    pub t: f64,
    /// Position \[m\].
    pub p: [f64; 3],
    /// Orientation as a unit quaternion (x, y, z, w).
    pub q: [f64; 4],
}

/// Reads a TUM file; every line must have 8 finite numbers and a unit quaternion (|q| within 1e-3).
pub fn read_tum(path: &Path) -> Result<Vec<TumPose>, SessionError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let bad = |what: String| err(path, ErrorKind::GroundTruth { line: i + 1, what });
        let v: Vec<f64> = l
            .split_whitespace()
            .map(|t| t.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad(format!("not all numbers: {l:?}")))?;
        if v.len() != 8 {
            return Err(bad(format!(
                "{} fields, expected 8 (t tx ty tz qx qy qz qw)",
                v.len()
            )));
        }
        let q = [v[4], v[5], v[6], v[7]];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (n - 1.0).abs() > 1e-3 {
            return Err(bad(format!("quaternion norm {n}, expected 1")));
        }
        if let Some(prev) = out.last().map(|p: &TumPose| p.t) {
            if v[0] < prev {
                return Err(bad(format!("time {} goes back from {prev}", v[0])));
            }
        }
        out.push(TumPose {
            t: v[0],
            p: [v[1], v[2], v[3]],
            q,
        });
    }
    Ok(out)
}

/// Writes a TUM file with full precision.
pub fn write_tum(path: &Path, poses: &[TumPose]) -> Result<(), SessionError> {
    let mut s = String::with_capacity(poses.len() * 96);
    s.push_str("# t[s] tx ty tz[m] qx qy qz qw\n");
    for p in poses {
        s.push_str(&format!(
            "{:.9} {} {} {} {} {} {} {}\n",
            p.t, p.p[0], p.p[1], p.p[2], p.q[0], p.q[1], p.q[2], p.q[3]
        ));
    }
    let mut f = std::fs::File::create(path).map_err(io_err(path))?;
    f.write_all(s.as_bytes()).map_err(io_err(path))
}
