//! `milliego eval`: trajectory error of an estimate against ground truth, as evo computes it.

use clap::{Args, ValueEnum};
use milliego_eval::{evaluate, Align, DeltaUnit, Report, Settings, Stats, Trajectory};
use serde_json::json;
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AlignArg {
    /// No alignment.
    None,
    /// Rotation + translation (Umeyama).
    Se3,
    /// Rotation + translation + scale (Umeyama).
    Sim3,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum UnitArg {
    /// Poses.
    F,
    /// Metres of path.
    M,
}

impl From<AlignArg> for Align {
    fn from(a: AlignArg) -> Align {
        match a {
            AlignArg::None => Align::None,
            AlignArg::Se3 => Align::Se3,
            AlignArg::Sim3 => Align::Sim3,
        }
    }
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Estimated trajectory (TUM: t tx ty tz qx qy qz qw).
    #[arg(long)]
    est: PathBuf,
    /// Ground truth (TUM).
    #[arg(long)]
    gt: PathBuf,
    /// Alignment of the estimate onto the ground truth.
    #[arg(long, value_enum, default_value_t = AlignArg::Se3)]
    align: AlignArg,
    /// Largest time difference for associating poses, in seconds.
    #[arg(long, default_value_t = 0.01)]
    max_diff: f64,
    /// Offset added to the estimate's timestamps, in seconds.
    #[arg(long, default_value_t = 0.0)]
    offset: f64,
    /// RPE delta.
    #[arg(long, default_value_t = 1.0)]
    delta: f64,
    /// RPE delta unit: f (poses) or m (metres of path).
    #[arg(long, value_enum, default_value_t = UnitArg::F)]
    delta_unit: UnitArg,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn stats_json(s: &Stats) -> serde_json::Value {
    json!({"rmse": s.rmse, "mean": s.mean, "median": s.median, "std": s.std, "min": s.min, "max": s.max, "sse": s.sse, "count": s.count})
}

pub fn run(a: EvalArgs) -> Result<()> {
    let load = |p: &PathBuf| -> Result<Trajectory> {
        Ok(Trajectory::from_tum(&milliego_session::read_tum(p)?))
    };
    let (gt, est) = (load(&a.gt)?, load(&a.est)?);
    let settings = Settings {
        align: a.align.into(),
        max_diff: a.max_diff,
        offset: a.offset,
        rpe_delta: a.delta,
        rpe_unit: if a.delta_unit == UnitArg::F {
            DeltaUnit::Frames
        } else {
            DeltaUnit::Meters
        },
    };
    let r: Report = evaluate(&gt, &est, &settings)
        .map_err(|e| format!("{} vs {}: {e}", a.est.display(), a.gt.display()))?;
    if a.json {
        let al = r.alignment;
        println!(
            "{}",
            json!({
                "est": a.est.display().to_string(), "gt": a.gt.display().to_string(),
                "matched": r.matched, "poses_est": r.poses.0, "poses_gt": r.poses.1,
                "align": format!("{:?}", a.align).to_lowercase(), "scale": al.scale,
                "rotation": [al.rotation.row(0).iter().collect::<Vec<_>>(), al.rotation.row(1).iter().collect::<Vec<_>>(), al.rotation.row(2).iter().collect::<Vec<_>>()],
                "translation": [al.translation.x, al.translation.y, al.translation.z],
                "ate_m": stats_json(&r.ate), "ate_2d_m": stats_json(&r.ate_2d),
                "rpe_m": stats_json(&r.rpe), "rpe_delta": a.delta, "rpe_unit": if a.delta_unit == UnitArg::F { "frames" } else { "m" },
                "path_length_m": r.path_length, "final_drift_pct": r.final_drift_pct, "ate_rmse_pct_of_path": r.ate_rmse_pct,
            })
        );
        return Ok(());
    }
    println!(
        "matched {} poses (estimate {}, ground truth {}), alignment {:?}, scale {:.6}",
        r.matched, r.poses.0, r.poses.1, a.align, r.alignment.scale
    );
    println!(
        "{:<10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "[m]", "rmse", "mean", "median", "std", "max"
    );
    for (name, s) in [("ATE 3D", r.ate), ("ATE 2D", r.ate_2d), ("RPE", r.rpe)] {
        println!(
            "{name:<10} {:>10.4} {:>10.4} {:>10.4} {:>10.4} {:>10.4}",
            s.rmse, s.mean, s.median, s.std, s.max
        );
    }
    println!(
        "path {:.2} m, final drift {:.2} % of path, ATE rmse {:.2} % of path",
        r.path_length, r.final_drift_pct, r.ate_rmse_pct
    );
    Ok(())
}
