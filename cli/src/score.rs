//! `milliego score`: every estimator on a set of the simulator's benchmark split, one table (ATE
//! 3D/2D mean, std, max as in the paper's tables, and drift as % of path): IMU-only dead
//! reckoning, Doppler radar-inertial odometry, the learned model (each `--model` file, fp32 or
//! int8, run with tract exactly as the runtime runs it), and per model the fused estimator and
//! `auto` (run by the runtime itself, `milliego run --session` as fast as it goes).

use clap::Args;
use milliego_eval::{evaluate, Settings, Stats, Trajectory};
use milliego_models::offline::run_session;
use milliego_models::Model;
use milliego_odometry::learned::LearnedConfig;
use milliego_odometry::offline::{run as run_offline, Estimator, OfflineConfig};
use milliego_odometry::runner::{ClassicalConfig, RoundingRule};
use milliego_runtime::estimator::EstimatorKind;
use milliego_runtime::output::OutputSpec;
use milliego_runtime::pipeline::{run as run_pipeline, Input, RunConfig};
use milliego_runtime::summary::LearnedSummary;
use milliego_session::Session;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::run as simulate;
use milliego_sim::split::{Set, SplitVersion};
use serde_json::json;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Per session: ATE 3D mean, ATE 2D mean \[m\], final drift \[% of path\].
type SessionScore = (f64, f64, f64);

/// The row every other is compared with, session by session.
const BASELINE: &str = "Doppler RIO";

/// A session counts as worse than [`BASELINE`]'s when its mean 3D ATE exceeds the baseline's by
/// more than this factor (issue 19's bar for `milliego run`'s default: never more than 10% worse).
const WORSE_FACTOR: f64 = 1.1;

/// Sessions of `v` whose mean 3D ATE exceeds `base`'s on the same session (same order) by more
/// than [`WORSE_FACTOR`].
fn sessions_worse(v: &[SessionScore], base: &[SessionScore]) -> usize {
    v.iter()
        .zip(base)
        .filter(|(x, b)| x.0 > WORSE_FACTOR * b.0)
        .count()
}

#[derive(Debug, Args)]
pub struct ScoreArgs {
    /// Benchmark set: train, val or test (held out: unseen family and seeds).
    #[arg(long, default_value = "test")]
    set: String,
    /// Benchmark split version: v1 (benign rigs, indoor) or v2 (outdoor too, each session's rig
    /// drawn from its seed: rests, IMU grades/rates/gaps, radar mounts, ...; docs/simulator.md).
    #[arg(long, default_value = "v1")]
    split: String,
    /// Where the simulated sessions go (reused when already there).
    #[arg(long)]
    work: Option<PathBuf>,
    /// Score only the first N sessions of the set.
    #[arg(long)]
    limit: Option<usize>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
    /// Learned models to score (ONNX from milliego_models.export / quantize); repeatable. Rows
    /// are named by config and precision, and by the file too where two models share those.
    /// Default: models/compact/model.onnx and model-int8.onnx when present.
    #[arg(long)]
    model: Vec<PathBuf>,
    /// Score only the classical estimators.
    #[arg(long)]
    no_model: bool,
    /// Leave out the fused and auto rows (the model alone only).
    #[arg(long)]
    no_fused: bool,
    /// Score only these rows, comma-separated: `imu` (dead reckoning), `model` (each model
    /// alone), `zeroed` (each model with its radar input zeroed), `fused`, `auto`. Doppler RIO
    /// is always scored: every row is compared with it. Default: all. Each model row runs the
    /// network over every session, so tuning the fusion with `--rows auto` takes a quarter of
    /// the time.
    #[arg(long, value_delimiter = ',', value_name = "ROW,...")]
    rows: Vec<String>,
    /// The learned measurements' absolute deviation per axis and keyframe interval \[m\]
    /// (default: the shipped setting, docs/model.md "Fusion").
    #[arg(long, value_name = "M")]
    learned_base_std: Option<f64>,
    /// The learned measurements' deviation per metre moved (default: the shipped setting).
    #[arg(long, value_name = "K")]
    learned_scale_std: Option<f64>,
    /// Weight of a model's own predicted deviation (uncertainty head) in the learned
    /// measurements' deviation (default: the shipped setting; 0: not used)
    #[arg(long, value_name = "W")]
    learned_predicted_std: Option<f64>,
    /// `auto`'s online check: the largest mean NIS over its window (default: the shipped
    /// setting).
    #[arg(long, value_name = "X")]
    learned_nis_max: Option<f64>,
    /// `auto`'s online check: the largest share of its window beyond the gate.
    #[arg(long, value_name = "F")]
    learned_gated_max: Option<f64>,
    /// `auto`'s online check: measurements it looks back over.
    #[arg(long, value_name = "N")]
    learned_window: Option<usize>,
    /// Skip a learned measurement when this many radar updates were applied over its interval
    /// (0: never).
    #[arg(long, value_name = "N")]
    learned_doppler_covers: Option<u64>,
    /// Calibrate the network's scale online against the filter where the radar covers an
    /// interval: on or off (default: the shipped setting).
    #[arg(long, value_name = "on|off")]
    learned_scale: Option<String>,
    /// Calibrate the network's velocity offset online against the filter where the radar covers
    /// an interval: on or off (default: the shipped setting, docs/model.md "Fusion").
    #[arg(long, value_name = "on|off")]
    learned_offset: Option<String>,
    /// Widen the learned measurements' deviation by the network's error measured online where
    /// the radar covers an interval (its excess variance and its correlation between
    /// consecutive intervals): on or off (default: the shipped setting, docs/model.md "Fusion").
    #[arg(long, value_name = "on|off")]
    learned_noise: Option<String>,
    /// For ground vehicles, intervals the radar did not cover calibrate too where the filter's
    /// velocity deviation times the interval is at most this share of the network's stated
    /// deviation (default: the shipped setting, docs/model.md "Fusion"; 0: covered intervals
    /// only).
    #[arg(long, value_name = "S")]
    learned_known: Option<f64>,
    /// How far back a radar point counts as seen again in the ego-velocity consensus \[s\]
    /// (default: the shipped setting, 0.125, chosen on the validation sets; 0: off;
    /// docs/odometry.md "Points seen again")
    #[arg(long, value_name = "S")]
    persist_window: Option<f64>,
    /// How long a radar frame that gives no velocity alone is kept for the next ones \[s\]
    /// (default: the shipped setting, docs/odometry.md; 0: off).
    #[arg(long, value_name = "S")]
    stack_window: Option<f64>,
    /// Radar updates over which the filter adapts the scale of the radar velocity covariance
    /// (default: the shipped setting, 300; 0: off; docs/odometry.md "Radar noise adaptation").
    #[arg(long, value_name = "N")]
    radar_noise_window: Option<f64>,
    /// Correlation time of the shared rounding state \[s\] (default: the shipped setting, 2; 0:
    /// off; docs/odometry.md "The rounding a frame's points share is a state").
    #[arg(long, value_name = "SECONDS")]
    radar_error_time: Option<f64>,
    /// Which rigs' ego-velocities take the likelihood of the rounded Doppler readings: never,
    /// vehicles (the rigs declared ground vehicles) or always (default: the shipped setting;
    /// docs/odometry.md "A slow robot under a coarse Doppler step").
    #[arg(long, value_name = "never|vehicles|always")]
    rounding: Option<String>,
    /// Let the radar updates correct the heading and the gyro bias about the vertical (default:
    /// off, the heading from the gyro; docs/odometry.md "Heading comes from the gyro").
    #[arg(long)]
    radar_heading: bool,
    /// The rigs declared ground vehicles, as their operator would (`odometry --vehicle`: the body
    /// neither slides sideways nor lifts off): `cars-and-robots` (the split's cars and its
    /// wheeled robots, which are planar and head along their path) or `cars` (the protocol
    /// before 2026-12-06; docs/odometry.md "Ground vehicles").
    #[arg(
        long,
        value_name = "cars|cars-and-robots",
        default_value = "cars-and-robots"
    )]
    ground_vehicles: String,
}

/// Whether a session of `motion` runs with the ground vehicle constraint under the score's
/// `--ground-vehicles` `rule`.
fn declared_ground_vehicle(rule: &str, motion: MotionKind) -> Result<bool> {
    match rule {
        "cars" => Ok(motion == MotionKind::Vehicle),
        "cars-and-robots" => Ok(matches!(motion, MotionKind::Vehicle | MotionKind::Robot)),
        other => Err(format!("--ground-vehicles {other}: expected cars or cars-and-robots").into()),
    }
}

/// One column of the table.
enum Column {
    Classical(Estimator),
    Model(Box<Model>),
    /// The runtime with this estimator and model file.
    Runtime(EstimatorKind, PathBuf),
}

/// Runs the runtime over the session in `dir` with `kind` and `model` (as fast as it goes) and
/// returns its radar-rate poses, the learned measurements' report and the hand-overs.
pub(crate) fn run_runtime(
    dir: &std::path::Path,
    kind: EstimatorKind,
    model: &std::path::Path,
    classical: &ClassicalConfig,
    vehicle: bool,
) -> Result<(Vec<milliego_session::TumPose>, Option<LearnedSummary>, u64)> {
    let tum = std::env::temp_dir().join(format!(
        "milliego-score-{}-{}.tum",
        std::process::id(),
        kind.name()
    ));
    let mut cfg = RunConfig {
        estimator: kind,
        model: Some(model.to_path_buf()),
        outputs: vec![OutputSpec::Tum(tum.clone())],
        ..RunConfig::default()
    };
    cfg.classical = ClassicalConfig {
        mounting: cfg.classical.mounting,
        ..*classical
    };
    if vehicle {
        cfg.classical.rio = cfg.classical.rio.ground_vehicle();
    }
    let input = Input::Session {
        dir: dir.to_path_buf(),
        realtime: false,
    };
    let s = run_pipeline(&input, &cfg, Arc::new(AtomicBool::new(false)))?;
    let poses = milliego_session::read_tum(&tum);
    let _ = std::fs::remove_file(&tum);
    Ok((poses?, s.report.learned, s.report.frames_out.handovers))
}

/// One label per model: its metadata's `config precision`, with the file's path after it where two
/// models would otherwise share a label (two retrained compact int8 files, say), so that no row of the
/// table or key of `--json` stands for two models. The same file given twice is an error.
fn unique_labels(paths: &[PathBuf], labels: &[String]) -> Result<Vec<String>> {
    let mut out = Vec::with_capacity(labels.len());
    for (i, (path, label)) in paths.iter().zip(labels).enumerate() {
        if paths[..i].contains(path) {
            return Err(format!("--model {} is given twice", path.display()).into());
        }
        let shared = labels.iter().filter(|l| *l == label).count() > 1;
        out.push(if shared {
            format!("{label} [{}]", path.display())
        } else {
            label.clone()
        });
    }
    Ok(out)
}

fn default_models() -> Vec<PathBuf> {
    [
        "models/compact/model.onnx",
        "models/compact/model-int8.onnx",
    ]
    .iter()
    .map(PathBuf::from)
    .filter(|p| p.is_file())
    .collect()
}

/// The error for a work directory that holds another scenario than the split's entry.
pub(crate) fn stale(dir: &std::path::Path, found: &str, e: &milliego_sim::split::Entry) -> String {
    format!(
        "{} holds another scenario ({found:?}, expected {:?}); remove it or give another --work",
        dir.display(),
        e.scenario().description()
    )
}

/// The rows `--rows` names, checked: `None` for all.
fn chosen_rows(rows: &[String]) -> Result<Option<Vec<&'static str>>> {
    const ROWS: [&str; 5] = ["imu", "model", "zeroed", "fused", "auto"];
    if rows.is_empty() {
        return Ok(None);
    }
    rows.iter()
        .map(|r| {
            let r = r.trim();
            ROWS.iter().find(|k| **k == r).copied().ok_or_else(|| {
                format!("--rows: {r:?} is none of imu, model, zeroed, fused, auto").into()
            })
        })
        .collect::<Result<Vec<_>>>()
        .map(Some)
}

pub fn run(a: ScoreArgs) -> Result<()> {
    let set: Set = a.set.parse()?;
    let version: SplitVersion = a.split.parse()?;
    let rows = chosen_rows(&a.rows)?;
    let wants = |row: &str| rows.as_ref().is_none_or(|r| r.contains(&row));
    // Checked before anything is simulated or run.
    declared_ground_vehicle(&a.ground_vehicles, MotionKind::Vehicle)?;
    let work = a
        .work
        .unwrap_or_else(|| std::env::temp_dir().join("milliego-benchmark"));
    let entries: Vec<_> = version
        .entries(set)
        .into_iter()
        .take(a.limit.unwrap_or(usize::MAX))
        .collect();
    let mut estimators: Vec<(String, Column)> = Vec::new();
    if wants("imu") {
        estimators.push((
            "IMU dead reckoning".into(),
            Column::Classical(Estimator::ImuOnly),
        ));
    }
    estimators.push((BASELINE.into(), Column::Classical(Estimator::Doppler)));
    let models = if a.no_model {
        Vec::new()
    } else if a.model.is_empty() {
        default_models()
    } else {
        a.model.clone()
    };
    let mut loaded = Vec::new();
    for path in &models {
        let m = Model::load(path, Some(&milliego_preprocess::Config::default()))?;
        let label = format!(
            "{} {}{}",
            m.meta().config,
            m.meta().precision,
            if m.meta().trained { "" } else { " (UNTRAINED)" }
        );
        loaded.push((m, label));
    }
    let labels = unique_labels(
        &models,
        &loaded.iter().map(|(_, l)| l.clone()).collect::<Vec<_>>(),
    )?;
    for ((path, (m, _)), label) in models.iter().zip(loaded).zip(labels) {
        let name = format!("milliEgo {label}");
        let runtime = !a.no_fused;
        if wants("model") {
            estimators.push((name.clone(), Column::Model(Box::new(m))));
        }
        if wants("zeroed") {
            // The same network with its radar input zeroed: what the radar adds to it.
            let mut ablated = Model::load(path, Some(&milliego_preprocess::Config::default()))?;
            ablated.set_radar_zeroed(true);
            estimators.push((
                format!("{name}, radar zeroed"),
                Column::Model(Box::new(ablated)),
            ));
        }
        if runtime && wants("fused") {
            estimators.push((
                format!("fused ({label})"),
                Column::Runtime(EstimatorKind::Fused, path.clone()),
            ));
        }
        if runtime && wants("auto") {
            estimators.push((
                format!("auto ({label})"),
                Column::Runtime(EstimatorKind::Auto, path.clone()),
            ));
        }
    }
    let mut learned = LearnedConfig::default();
    if let Some(b) = a.learned_base_std {
        learned.base_std_m = b;
    }
    if let Some(k) = a.learned_scale_std {
        learned.scale_std = k;
    }
    if let Some(w) = a.learned_predicted_std {
        learned.predicted_std = w;
    }
    if let Some(x) = a.learned_nis_max {
        learned.nis_max = x;
    }
    if let Some(f) = a.learned_gated_max {
        learned.gated_max = f;
    }
    if let Some(v) = &a.learned_scale {
        learned.calibrate_scale = match v.as_str() {
            "on" => true,
            "off" => false,
            o => return Err(format!("--learned-scale: {o:?} is neither on nor off").into()),
        };
    }
    if let Some(v) = &a.learned_offset {
        learned.calibrate_offset = match v.as_str() {
            "on" => true,
            "off" => false,
            o => return Err(format!("--learned-offset: {o:?} is neither on nor off").into()),
        };
    }
    if let Some(v) = &a.learned_noise {
        learned.adapt_noise = match v.as_str() {
            "on" => true,
            "off" => false,
            o => return Err(format!("--learned-noise: {o:?} is neither on nor off").into()),
        };
    }
    if let Some(k) = a.learned_known {
        if !(k.is_finite() && k >= 0.0) {
            return Err(format!("--learned-known: {k} is not a share of 0 or more").into());
        }
        learned.known_share = k;
    }
    if let Some(n) = a.learned_doppler_covers {
        learned.doppler_covers = n;
    }
    if let Some(n) = a.learned_window {
        learned.window = n.max(1);
    }
    let mut classical = ClassicalConfig {
        learned,
        ..ClassicalConfig::default()
    };
    if let Some(w) = a.stack_window {
        classical.stack_window_s = w.max(0.0);
    }
    if let Some(w) = a.persist_window {
        classical.persist.window_s = w.max(0.0);
    }
    classical.rio.radar_heading |= a.radar_heading;
    if let Some(r) = &a.rounding {
        classical.rounding_likelihood = r
            .parse::<RoundingRule>()
            .map_err(|e| format!("--rounding: {e}"))?;
    }
    if let Some(n) = a.radar_noise_window {
        classical.rio.radar_noise_window = n.max(0.0);
    }
    if let Some(t) = a.radar_error_time {
        classical.rio = classical.rio.with_radar_error_time(t);
    }
    // Per runtime column: learned measurements applied, evaluated, NIS sum; sessions handed over.
    let mut learned_use: Vec<(u64, u64, f64, usize)> = vec![(0, 0, 0.0, 0); estimators.len()];
    let mut per: Vec<(String, Vec<SessionScore>)> = estimators
        .iter()
        .map(|(n, _)| (n.clone(), Vec::new()))
        .collect();
    // Progress on stderr (drawn only on a terminal).
    let bar = indicatif::ProgressBar::new(entries.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "scoring {bar:30} {pos}/{len} [{elapsed_precise} < {eta}] {msg}",
        )
        .expect("valid template"),
    );
    for e in &entries {
        let dir = e.work_dir(&work);
        bar.set_message(e.dir_name());
        if !dir.join("session.toml").is_file() {
            bar.println(format!("simulating {}", dir.display()));
            simulate(&e.scenario(), &dir, &mut |_| {})?;
        }
        let s = Session::open(&dir)?;
        if !e.is_session(&s.meta.description) {
            return Err(stale(&dir, &s.meta.description, e).into());
        }
        let gt = Trajectory::from_tum(&s.groundtruth()?.ok_or("no ground truth")?);
        let vehicle = declared_ground_vehicle(&a.ground_vehicles, e.scenario().motion)?;
        for (k, ((_, est), (_, out))) in estimators.iter_mut().zip(per.iter_mut()).enumerate() {
            let trajectory = match est {
                Column::Classical(est) => {
                    let mut cfg = OfflineConfig {
                        estimator: *est,
                        stack_window_s: classical.stack_window_s,
                        persist: classical.persist,
                        rounding_likelihood: classical.rounding_likelihood,
                        ..OfflineConfig::default()
                    };
                    // The filter's settings as the runtime columns get them.
                    cfg.rio = classical.rio;
                    // What the rig's operator knows and says (`odometry --vehicle`): a car.
                    let cfg = if vehicle { cfg.ground_vehicle() } else { cfg };
                    run_offline(&s, &cfg)?.trajectory
                }
                Column::Model(m) => run_session(m, &s)?.trajectory,
                Column::Runtime(kind, path) => {
                    let (poses, rep, handovers) =
                        run_runtime(&dir, *kind, path, &classical, vehicle)?;
                    learned_use[k].3 += usize::from(handovers > 0);
                    if let Some(r) = rep {
                        let n = r.applied + r.gated + r.suspended;
                        let u = &mut learned_use[k];
                        u.0 += r.applied;
                        u.1 += n;
                        u.2 += r.nis_mean.unwrap_or(0.0) * n as f64;
                    }
                    poses
                }
            };
            let rep = evaluate(
                &gt,
                &Trajectory::from_tum(&trajectory),
                &Settings::default(),
            )?;
            out.push((rep.ate.mean, rep.ate_2d.mean, rep.final_drift_pct));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let summarise = |v: &[SessionScore]| {
        let pick = |f: fn(&SessionScore) -> f64| Stats::of(&v.iter().map(f).collect::<Vec<_>>());
        (pick(|x| x.0), pick(|x| x.1), pick(|x| x.2))
    };
    let base: &[SessionScore] = per
        .iter()
        .find(|(n, _)| n == BASELINE)
        .map_or(&[], |(_, v)| v.as_slice());
    // Sessions worse than the baseline, for every other row.
    let worse = |n: &str, v: &[SessionScore]| (n != BASELINE).then(|| sessions_worse(v, base));
    if a.json {
        let rows: serde_json::Map<String, serde_json::Value> = per
            .iter()
            .map(|(n, v)| {
                let (a3, a2, d) = summarise(v);
                let each: Vec<_> = v
                    .iter()
                    .map(|x| json!({"ate_3d_mean_m": x.0, "ate_2d_mean_m": x.1, "drift_pct": x.2}))
                    .collect();
                (n.clone(), json!({"ate_3d_mean_m": a3.mean, "ate_3d_std_m": a3.std, "ate_3d_max_m": a3.max,
                    "ate_3d_median_m": a3.median, "sessions_worse_than_doppler": worse(n, v),
                    "ate_2d_mean_m": a2.mean, "ate_2d_std_m": a2.std, "ate_2d_max_m": a2.max, "drift_pct_mean": d.mean, "sessions": v.len(),
                    "per_session": each}))
            })
            .collect();
        println!(
            "{}",
            json!({"set": set.name(), "split": version.name(), "ground_vehicles": a.ground_vehicles, "estimators": rows,
                "session_names": entries.iter().map(|e| e.dir_name()).collect::<Vec<_>>()})
        );
        return Ok(());
    }
    // Version 1 keeps the header it always had.
    let of_split = match version {
        SplitVersion::V1 => String::new(),
        v => format!(" of split {v}"),
    };
    println!(
        "{} sessions of the '{}' set{of_split} (per-session ATE means, then over sessions; declared ground vehicles: {})",
        entries.len(),
        set.name(),
        a.ground_vehicles
    );
    // Wide enough for the longest name (models told apart by their file have long ones).
    let w = per.iter().map(|(n, _)| n.len()).max().unwrap_or(0).max(36);
    println!(
        "{:<w$} {:>22} {:>22} {:>10} {:>10} {:>12}",
        "estimator",
        "ATE 3D mean/std/max",
        "ATE 2D mean/std/max",
        "drift %",
        "3D median",
        "> 1.1x RIO"
    );
    for (name, v) in &per {
        let (a3, a2, d) = summarise(v);
        let worse =
            worse(name, v).map_or_else(|| "-".to_string(), |k| format!("{k} of {}", v.len()));
        println!(
            "{name:<w$} {:>7.2}/{:>6.2}/{:>7.2} {:>7.2}/{:>6.2}/{:>7.2} {:>10.2} {:>10.2} {worse:>12}",
            a3.mean, a3.std, a3.max, a2.mean, a2.std, a2.max, d.mean, a3.median
        );
    }
    println!(
        "(> 1.1x RIO: sessions where the row's mean 3D ATE is more than {WORSE_FACTOR} times {BASELINE}'s)"
    );
    for ((name, v), (applied, n, nis, handed)) in per.iter().zip(&learned_use) {
        if *n > 0 {
            println!(
                "{name}: learned measurements applied {applied} of {n} evaluated, mean NIS {:.2} (3 when their deviation is right); handed over to Doppler in {handed} of {} sessions",
                nis / *n as f64,
                v.len()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{chosen_rows, sessions_worse, unique_labels};
    use std::path::PathBuf;

    #[test]
    fn sessions_worse_than_the_baseline_by_more_than_ten_percent() {
        let base = [(1.0, 0.0, 0.0), (0.5, 0.0, 0.0), (0.8, 0.0, 0.0)];
        // 1.09x, 1.2x, 0.625x: only the second is more than 10% worse.
        let row = [(1.09, 9.0, 9.0), (0.6, 0.0, 0.0), (0.5, 0.0, 0.0)];
        assert_eq!(sessions_worse(&row, &base), 1);
        assert_eq!(
            sessions_worse(&base, &base),
            0,
            "the baseline against itself"
        );
        // Session by session, not by the mean: the same values in another order.
        let shuffled = [(0.5, 0.0, 0.0), (0.6, 0.0, 0.0), (1.09, 0.0, 0.0)];
        assert_eq!(sessions_worse(&shuffled, &base), 2);
    }

    #[test]
    fn models_that_share_a_label_are_told_apart_by_their_file() {
        let paths: Vec<PathBuf> = [
            "models/compact/model-int8.onnx",
            "retrained/int8.onnx",
            "models/compact/model.onnx",
        ]
        .iter()
        .map(PathBuf::from)
        .collect();
        let labels = ["compact int8", "compact int8", "compact fp32"].map(String::from);
        assert_eq!(
            unique_labels(&paths, &labels).unwrap(),
            [
                "compact int8 [models/compact/model-int8.onnx]",
                "compact int8 [retrained/int8.onnx]",
                "compact fp32",
            ]
        );
    }

    #[test]
    fn rows_are_checked_by_name() {
        assert_eq!(chosen_rows(&[]).unwrap(), None, "no --rows: every row");
        let given = ["auto", " fused"].map(String::from);
        assert_eq!(chosen_rows(&given).unwrap(), Some(vec!["auto", "fused"]));
        let e = chosen_rows(&["doppler".to_string()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("--rows: \"doppler\" is none of"), "{e}");
    }

    #[test]
    fn the_same_model_twice_is_an_error() {
        let paths = vec![PathBuf::from("a.onnx"), PathBuf::from("a.onnx")];
        let labels = ["compact int8", "compact int8"].map(String::from);
        let e = unique_labels(&paths, &labels).unwrap_err().to_string();
        assert!(e.contains("a.onnx is given twice"), "{e}");
    }
}
