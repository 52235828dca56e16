//! `milliego dataset build`: sessions -> training shards (format: docs/dataset.md), through the
//! same preprocessing the runtime runs.

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use milliego_preprocess::dataset::{build, Progress};
use milliego_preprocess::Config;
use milliego_sim::scenario::run as simulate;
use milliego_sim::split::{Set, SplitVersion};
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Subcommand)]
pub enum DatasetCmd {
    /// Build a training dataset from session directories (or a simulator benchmark set).
    Build(BuildArgs),
}

#[derive(Debug, Args)]
pub struct BuildArgs {
    /// Session directories (each needs radar, IMU and ground truth).
    sessions: Vec<PathBuf>,
    /// Output directory (manifest.json and one shard per session).
    #[arg(short, long)]
    out: PathBuf,
    /// Add every session of this simulator benchmark set: train, val or test (simulated into
    /// --work when missing).
    #[arg(long)]
    set: Option<String>,
    /// Benchmark split version of --set: v1 or v2 (docs/simulator.md).
    #[arg(long, default_value = "v1")]
    split: String,
    /// Where benchmark sessions live or are simulated.
    #[arg(long)]
    work: Option<PathBuf>,
    /// Radar frames between the two frames of a window.
    #[arg(long, default_value_t = Config::default().gap)]
    gap: u32,
    /// Maximum range mapped into the depth image, metres.
    #[arg(long, default_value_t = Config::default().max_range_m)]
    max_range: f64,
    /// No progress bar.
    #[arg(long, short)]
    quiet: bool,
}

fn bar(len: u64, quiet: bool, what: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template(&format!(
            "{what} {{bar:30}} {{pos}}/{{len}} [{{elapsed_precise}} < {{eta}}] {{msg}}"
        ))
        .expect("valid template"),
    );
    b
}

pub fn run(cmd: DatasetCmd) -> Result<()> {
    let DatasetCmd::Build(a) = cmd;
    let mut sessions = a.sessions.clone();
    if let Some(set) = &a.set {
        let set: Set = set.parse()?;
        let version: SplitVersion = a.split.parse()?;
        let work = a
            .work
            .clone()
            .unwrap_or_else(|| std::env::temp_dir().join("milliego-benchmark"));
        let entries = version.entries(set);
        let sim = bar(entries.len() as u64, a.quiet, "simulating");
        for e in &entries {
            let dir = e.work_dir(&work);
            if !dir.join("session.toml").is_file() {
                sim.set_message(e.dir_name());
                simulate(&e.scenario(), &dir, &mut |_| {})?;
            }
            let found = milliego_session::Session::open(&dir)?.meta.description;
            if !e.is_session(&found) {
                return Err(crate::score::stale(&dir, &found, e).into());
            }
            sim.inc(1);
            sessions.push(dir);
        }
        sim.finish_and_clear();
    }
    if sessions.is_empty() {
        return Err("give session directories or --set train|val|test".into());
    }
    let pre = Config {
        gap: a.gap,
        max_range_m: a.max_range,
        ..Config::default()
    };
    let pb = bar(sessions.len() as u64, a.quiet, "building");
    let m = build(&sessions, &a.out, &pre, &mut |p| match p {
        Progress::Start(_, _, dir) => pb.set_message(dir.display().to_string()),
        Progress::Done(_, e) => {
            pb.inc(1);
            let s = &e.skipped;
            let dropped = s.no_prev_frame + s.imu_not_covered + s.imu_gap + s.no_ground_truth;
            if dropped > 0 || s.radar_frames_bad > 0 || s.imu_messages_bad > 0 {
                pb.println(format!(
                    "{}: {} windows; skipped: {:?}",
                    e.session, e.windows, e.skipped
                ));
            }
        }
    })?;
    pb.finish_and_clear();
    let skipped = m.shards.iter().fold([0u64; 4], |mut acc, e| {
        acc[0] += e.skipped.no_prev_frame;
        acc[1] += e.skipped.imu_not_covered + e.skipped.imu_gap;
        acc[2] += e.skipped.no_ground_truth;
        acc[3] += e.skipped.points_out_of_view + e.skipped.points_out_of_range;
        acc
    });
    println!(
        "{}: {} sessions, {} frames, {} windows (without a window: {} first-gap or missing \
         partner frames, {} IMU not covered; {} without ground truth; {} points outside the \
         image); norm min {:.4} max {:.4} mean {:.5}",
        a.out.display(),
        m.shards.len(),
        m.frames,
        m.windows,
        skipped[0],
        skipped[1],
        skipped[2],
        skipped[3],
        m.norm.min,
        m.norm.max,
        m.norm.mean
    );
    Ok(())
}
