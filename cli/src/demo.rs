//! `milliego demo`: the end-to-end job on a generated default, no hardware and no files needed:
//! simulate a radar-inertial session, decode both UART streams with the drivers, run Doppler
//! radar-inertial odometry, the learned milliEgo model (the shipped int8 file, with tract) alone and
//! fused into the Doppler filter (`milliego run`'s default), and IMU dead reckoning on it, and score
//! them against ground truth.

use clap::Args;
use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_odometry::offline::{run as run_offline, Estimator, OfflineConfig};
use milliego_session::{write_tum, Session};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Working directory for the session and the trajectories (default: a new temporary one).
    #[arg(long)]
    out: Option<PathBuf>,
    /// World family: corridor, office, atrium, store_room, household.
    #[arg(long, default_value = "office")]
    family: String,
    /// Motion: robot, handheld, headworn.
    #[arg(long, default_value = "handheld")]
    motion: String,
    /// Seed.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Length in seconds.
    #[arg(long, default_value_t = 30.0)]
    duration: f64,
    /// The learned model to run beside the classical estimators (skipped when the file is absent).
    #[arg(long, default_value = "models/compact/model-int8.onnx")]
    model: PathBuf,
}

/// Scores `est` against `gt` and prints one table row.
fn print_row(name: &str, gt: &Trajectory, est: &[milliego_session::TumPose]) -> Result<()> {
    let rep = evaluate(gt, &Trajectory::from_tum(est), &Settings::default())?;
    println!(
        "{name:<26} {:>8.3}m {:>8.3}m {:>8.3}m {:>8.3}m {:>10.2}",
        rep.ate.rmse, rep.ate.mean, rep.ate.max, rep.ate_2d.rmse, rep.final_drift_pct
    );
    Ok(())
}

pub fn run(a: DemoArgs) -> Result<()> {
    let family: Family = a
        .family
        .parse()
        .map_err(|e: String| format!("--family: {e}"))?;
    let motion: MotionKind = a
        .motion
        .parse()
        .map_err(|e: String| format!("--motion: {e}"))?;
    let out = match a.out {
        Some(d) => d,
        None => std::env::temp_dir().join(format!("milliego-demo-{}", std::process::id())),
    };
    let session_dir = out.join("session");
    let mut sc = Scenario::new(family, motion, a.seed);
    sc.duration_s = a.duration;
    eprintln!(
        "1/3 simulating {} s of {} / {} (seed {}) into {}",
        a.duration,
        a.family,
        a.motion,
        a.seed,
        session_dir.display()
    );
    let summary = simulate(&sc, &session_dir, &mut |_| {})?;
    eprintln!("    {summary:?}");
    let session = Session::open(&session_dir)?;
    let gt = Trajectory::from_tum(
        &session
            .groundtruth()?
            .ok_or("the simulated session has no ground truth")?,
    );
    println!(
        "{:<26} {:>9} {:>9} {:>9} {:>9} {:>10}",
        "estimator", "ATE rmse", "ATE mean", "ATE max", "ATE 2D", "drift %"
    );
    for (name, est, file) in [
        ("Doppler RIO (radar+IMU)", Estimator::Doppler, "doppler.tum"),
        ("IMU dead reckoning", Estimator::ImuOnly, "imu.tum"),
    ] {
        eprintln!("2/3 {name}: decoding the UART streams, fitting the clocks, filtering");
        let r = run_offline(
            &session,
            &OfflineConfig {
                estimator: est,
                ..OfflineConfig::default()
            },
        )?;
        let path = out.join(file);
        write_tum(&path, &r.trajectory)?;
        eprintln!(
            "3/3 {name}: scoring {} poses against ground truth ({})",
            r.trajectory.len(),
            path.display()
        );
        print_row(name, &gt, &r.trajectory)?;
    }
    if a.model.is_file() {
        let name = "milliEgo compact (model)";
        eprintln!("2/3 {name}: windows through the shared preprocessing, tract inference");
        let mut m =
            milliego_models::Model::load(&a.model, Some(&milliego_preprocess::Config::default()))?;
        let r = milliego_models::offline::run_session(&mut m, &session)?;
        let path = out.join("model.tum");
        write_tum(&path, &r.trajectory)?;
        print_row(name, &gt, &r.trajectory)?;
        let name = "fused (milliego run)";
        eprintln!(
            "2/3 {name}: the runtime's default, the model's motion inside the Doppler filter"
        );
        let (poses, _, _) = crate::score::run_runtime(
            &session_dir,
            milliego_runtime::estimator::EstimatorKind::Auto,
            &a.model,
            &milliego_odometry::runner::ClassicalConfig::default(),
            false,
        )?;
        write_tum(&out.join("auto.tum"), &poses)?;
        print_row(name, &gt, &poses)?;
    } else {
        eprintln!("skipped the learned model: {} not found", a.model.display());
    }
    println!("(ATE after SE(3) alignment over a {:.1} m path; `milliego eval --est {}/doppler.tum --gt {}/groundtruth.tum` for details)", gt.path_length(), out.display(), session_dir.display());
    Ok(())
}
