//! `milliego sim ...`: simulate radar-inertial sessions with ground truth, and the benchmark
//! split.
//!
//! ```text
//! milliego sim --family office --motion handheld --seed 7 --duration 30 -o DIR
//! milliego sim split
//! milliego sim benchmark --set test -o DIR
//! ```

use crate::output;
use clap::{Args, Subcommand};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{self, Scenario, Summary};
use milliego_sim::split::{self, Set};
use milliego_sim::world::Family;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::str::FromStr;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// `milliego sim`: one session from the options, or a subcommand.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SimArgs {
    #[command(subcommand)]
    cmd: Option<SimCmd>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Debug, Subcommand)]
enum SimCmd {
    /// Print the benchmark split: which (family, motion, seed) train, validate and test.
    Split,
    /// Write every session of one set of the benchmark under DIR/SET/FAMILY-MOTION-SEED.
    Benchmark(BenchArgs),
}

#[derive(Debug, Args)]
struct RunArgs {
    /// World family: corridor, office, atrium, store_room, household.
    #[arg(long, default_value = "office", value_parser = parse::<Family>)]
    family: Family,
    /// Motion: robot, handheld, headworn, static.
    #[arg(long, default_value = "handheld", value_parser = parse::<MotionKind>)]
    motion: MotionKind,
    /// Seed of the world, the trajectory, the clocks and all noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Length [s].
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    duration: f64,
    /// Output session directory (must not hold a session yet).
    #[arg(short = 'o', long = "out")]
    out: Option<PathBuf>,
    /// Radar frame rate [Hz] (10-30).
    #[arg(long, default_value_t = 20.0)]
    radar_hz: f64,
    /// IMU output rate [Hz] (100-400).
    #[arg(long, default_value_t = 200.0)]
    imu_hz: f64,
    /// IMU UART rate [bit/s].
    #[arg(long, default_value_t = 921_600)]
    imu_baud: u32,
}

#[derive(Debug, Args)]
struct BenchArgs {
    /// Which set: train, val or test.
    #[arg(long, value_parser = parse::<Set>)]
    set: Set,
    /// Root directory of the benchmark.
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

fn parse<T: FromStr<Err = String>>(s: &str) -> std::result::Result<T, String> {
    s.parse()
}

/// Runs `milliego sim`.
pub fn run(args: SimArgs) -> Result<()> {
    match args.cmd {
        Some(SimCmd::Split) => print_split(),
        Some(SimCmd::Benchmark(b)) => benchmark(&b),
        None => {
            let r = args.run;
            let out = r
                .out
                .ok_or("milliego sim needs an output directory: -o DIR")?;
            let mut sc = Scenario::new(r.family, r.motion, r.seed);
            sc.duration_s = r.duration;
            sc.radar_hz = r.radar_hz;
            sc.imu_hz = r.imu_hz;
            sc.imu_baud = r.imu_baud;
            let s = simulate(&sc, &out, "")?;
            println!("{}", summary_line(&out, &s));
            Ok(())
        }
    }
}

fn simulate(sc: &Scenario, out: &Path, tag: &str) -> Result<Summary> {
    sc.validate()?;
    let mut last = -1;
    let mut err = std::io::stderr();
    let s = scenario::run(sc, out, &mut |f| {
        let pct = (f * 100.0) as i32;
        if pct / 5 != last / 5 {
            last = pct;
            let _ = write!(err, "\r{tag}simulating {}: {pct:3} %", out.display());
            let _ = err.flush();
        }
    })
    .map_err(|e| format!("{}: {e}", out.display()))?;
    eprintln!();
    Ok(s)
}

fn summary_line(out: &Path, s: &Summary) -> String {
    format!(
        "{}: {} radar frames, {:.1} points per frame ({}..{}), outlier share {:.3}, {} IMU samples, {} + {} B",
        out.display(),
        s.frames,
        s.points_mean(),
        s.points_min,
        s.points_max,
        s.outlier_share(),
        s.imu_samples,
        s.radar_bytes,
        s.imu_bytes
    )
}

fn print_split() -> Result<()> {
    let mut out = output::stdout();
    let mut lines = vec![
        "# milliEgo simulator benchmark split (docs/simulator.md)".to_string(),
        format!(
            "# held-out family: {}; train seeds {:?}, val seeds {:?}, test seeds {:?}; {} s each",
            split::HELD_OUT_FAMILY,
            split::TRAIN_SEEDS,
            split::VAL_SEEDS,
            split::TEST_SEEDS,
            split::DURATION_S
        ),
        "set,family,motion,seed,duration_s".to_string(),
    ];
    lines.extend(split::benchmark().iter().map(|e| {
        format!(
            "{},{},{},{},{}",
            e.set, e.family, e.motion, e.seed, e.duration_s
        )
    }));
    for l in &lines {
        if !output::line(&mut out, l)? {
            return Ok(());
        }
    }
    match out.flush() {
        Err(e) if output::is_broken_pipe(&e) => Ok(()),
        r => Ok(r?),
    }
}

fn benchmark(b: &BenchArgs) -> Result<()> {
    let entries = split::entries(b.set);
    let n = entries.len();
    for (i, e) in entries.iter().enumerate() {
        let out = b.out.join(e.dir_name());
        let s = simulate(&e.scenario(), &out, &format!("[{}/{n}] ", i + 1))?;
        println!("{}", summary_line(&out, &s));
    }
    Ok(())
}
