//! `milliego score`: every estimator on a set of the simulator's benchmark split, one table (ATE
//! 3D/2D mean, std, max as in the paper's tables, and drift as % of path). The learned model's
//! columns join this table when the model lands; today it scores the classical estimators.

use clap::Args;
use milliego_eval::{evaluate, Settings, Stats, Trajectory};
use milliego_odometry::offline::{run as run_offline, Estimator, OfflineConfig};
use milliego_session::Session;
use milliego_sim::scenario::run as simulate;
use milliego_sim::split::{benchmark, Set};
use serde_json::json;
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Per session: ATE 3D mean, ATE 2D mean \[m\], final drift \[% of path\].
type SessionScore = (f64, f64, f64);

#[derive(Debug, Args)]
pub struct ScoreArgs {
    /// Benchmark set: train, val or test (held out: unseen family and seeds).
    #[arg(long, default_value = "test")]
    set: String,
    /// Where the simulated sessions go (reused when already there).
    #[arg(long)]
    work: Option<PathBuf>,
    /// Score only the first N sessions of the set.
    #[arg(long)]
    limit: Option<usize>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

pub fn run(a: ScoreArgs) -> Result<()> {
    let set: Set = a.set.parse()?;
    let work = a
        .work
        .unwrap_or_else(|| std::env::temp_dir().join("milliego-benchmark"));
    let entries: Vec<_> = benchmark()
        .into_iter()
        .filter(|e| e.set == set)
        .take(a.limit.unwrap_or(usize::MAX))
        .collect();
    let estimators = [("imu", Estimator::ImuOnly), ("doppler", Estimator::Doppler)];
    let mut per: Vec<(String, Vec<SessionScore>)> = estimators
        .iter()
        .map(|(n, _)| (n.to_string(), Vec::new()))
        .collect();
    for (i, e) in entries.iter().enumerate() {
        let dir = work.join(set.name()).join(e.dir_name());
        if !dir.join("session.toml").is_file() {
            eprintln!("[{}/{}] simulating {}", i + 1, entries.len(), dir.display());
            simulate(&e.scenario(), &dir, &mut |_| {})?;
        }
        let s = Session::open(&dir)?;
        let gt = Trajectory::from_tum(&s.groundtruth()?.ok_or("no ground truth")?);
        for ((_, est), (_, out)) in estimators.iter().zip(per.iter_mut()) {
            let r = run_offline(
                &s,
                &OfflineConfig {
                    estimator: *est,
                    ..OfflineConfig::default()
                },
            )?;
            let rep = evaluate(
                &gt,
                &Trajectory::from_tum(&r.trajectory),
                &Settings::default(),
            )?;
            out.push((rep.ate.mean, rep.ate_2d.mean, rep.final_drift_pct));
        }
    }
    let summarise = |v: &[SessionScore]| {
        let pick = |f: fn(&SessionScore) -> f64| Stats::of(&v.iter().map(f).collect::<Vec<_>>());
        (pick(|x| x.0), pick(|x| x.1), pick(|x| x.2))
    };
    if a.json {
        let rows: serde_json::Map<String, serde_json::Value> = per
            .iter()
            .map(|(n, v)| {
                let (a3, a2, d) = summarise(v);
                (n.clone(), json!({"ate_3d_mean_m": a3.mean, "ate_3d_std_m": a3.std, "ate_3d_max_m": a3.max,
                    "ate_2d_mean_m": a2.mean, "ate_2d_std_m": a2.std, "ate_2d_max_m": a2.max, "drift_pct_mean": d.mean, "sessions": v.len()}))
            })
            .collect();
        println!("{}", json!({"set": set.name(), "estimators": rows}));
        return Ok(());
    }
    println!(
        "{} sessions of the '{}' set (per-session ATE means, then over sessions)",
        entries.len(),
        set.name()
    );
    println!(
        "{:<22} {:>22} {:>22} {:>10}",
        "estimator", "ATE 3D mean/std/max", "ATE 2D mean/std/max", "drift %"
    );
    for (n, v) in &per {
        let (a3, a2, d) = summarise(v);
        let name = if n == "imu" {
            "IMU dead reckoning"
        } else {
            "Doppler RIO"
        };
        println!(
            "{name:<22} {:>7.2}/{:>6.2}/{:>7.2} {:>7.2}/{:>6.2}/{:>7.2} {:>10.2}",
            a3.mean, a3.std, a3.max, a2.mean, a2.std, a2.max, d.mean
        );
    }
    println!("(milliEgo fp32/int8 columns: pending the model, issue 5)");
    Ok(())
}
