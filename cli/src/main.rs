//! `milliego`: one binary, one subcommand per job.
//!
//! Data flow: bytes -> frames -> samples -> windows -> model -> pose -> link. Each subcommand module
//! wires one stage of that flow to files, serial ports or sockets; the stages themselves live in
//! the library crates.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod dataset;
mod demo;
mod eval;
#[cfg(feature = "desk")]
mod import;
mod imu;
#[cfg(feature = "desk")]
mod mcap;
mod odometry;
mod output;
#[cfg(feature = "desk")]
mod plot;
mod pose;
mod radar;
mod record;
mod replay;
mod run;
mod score;
mod selftest;
mod sim;

#[derive(Debug, Parser)]
#[command(
    name = "milliego",
    version,
    about = "Radar-inertial egomotion: drivers, tools and runtime"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The end-to-end job on a generated default: simulate, decode, run the estimators, score them.
    Demo(demo::DemoArgs),
    /// TI mmWave radar: dump frames, upload a .cfg, show what a .cfg implies.
    #[command(subcommand)]
    Radar(radar::RadarCmd),
    /// Xsens MTi IMU: dump messages, configure a device.
    #[command(subcommand)]
    Imu(imu::ImuCmd),
    /// Training datasets for the learned model: sessions -> shards (docs/dataset.md).
    #[command(subcommand)]
    Dataset(dataset::DatasetCmd),
    /// Classical odometry over a session (Doppler radar-inertial or IMU-only), written as TUM.
    Odometry(odometry::OdometryArgs),
    /// Score every estimator on a set of the simulator's benchmark split (the paper's ATE table).
    Score(score::ScoreArgs),
    /// Trajectory error of an estimate against ground truth (ATE, RPE, drift), as evo computes it.
    Eval(eval::EvalArgs),
    /// Figures (PNG/SVG): trajectory coloured by error, error over time, ATE CDF, a radar frame.
    #[cfg(feature = "desk")]
    #[command(subcommand)]
    Plot(plot::PlotCmd),
    /// Pose link: listen to a pose stream (UDP or serial) and print or save it.
    #[command(subcommand)]
    Pose(pose::PoseCmd),
    /// Single-threaded self-check of decoders (and, later, the model) with digests that must match
    /// across architectures.
    Selftest(selftest::SelftestArgs),
    /// Simulate radar-inertial sessions with ground truth; the benchmark split.
    Sim(sim::SimArgs),
    /// Replay a session into pseudo-terminals or serial devices (the HIL rig).
    Replay(replay::ReplayArgs),
    /// The runtime: live ports (or a replay's ptys) or a session -> estimator -> poses over
    /// UDP, serial, TUM.
    Run(run::RunArgs),
    /// Watch a session live in Foxglove: replayed at its pace (or --speed) through the estimator,
    /// served over the Foxglove WebSocket protocol (docs/live-view.md).
    View(run::ViewArgs),
    /// Record the radar and IMU ports into a session.
    Record(record::RecordArgs),
    /// A session and estimated trajectories as MCAP with ROS 2 schemas (Foxglove, ros2 bag).
    #[cfg(feature = "desk")]
    ExportMcap(mcap::McapArgs),
    /// Recordings in: ROS 1 bags, ROS 2 bags (sqlite3 / MCAP), MCAP files -> a session.
    #[cfg(feature = "desk")]
    Import(import::ImportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Dataset(cmd) => dataset::run(cmd),
        Command::Run(a) => run::run(a),
        Command::View(a) => run::view(a),
        Command::Radar(cmd) => radar::run(cmd),
        Command::Imu(cmd) => imu::run(cmd),
        Command::Pose(cmd) => pose::run(cmd),
        Command::Eval(a) => eval::run(a),
        #[cfg(feature = "desk")]
        Command::Plot(cmd) => plot::run(cmd),
        Command::Score(a) => score::run(a),
        Command::Odometry(a) => odometry::run(a),
        Command::Selftest(a) => selftest::run(a),
        Command::Sim(args) => sim::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Record(args) => record::run(args),
        #[cfg(feature = "desk")]
        Command::ExportMcap(args) => mcap::run(args),
        #[cfg(feature = "desk")]
        Command::Import(args) => import::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("milliego: error: {e}");
            ExitCode::FAILURE
        }
    }
}
