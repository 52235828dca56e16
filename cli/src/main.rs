//! `milliego`: one binary, one subcommand per job.
//!
//! Data flow: bytes -> frames -> samples -> windows -> model -> pose -> link. Each subcommand module
//! wires one stage of that flow to files, serial ports or sockets; the stages themselves live in
//! the library crates.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

mod imu;
mod output;
mod radar;
mod record;
mod replay;

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
    /// TI mmWave radar: dump frames, upload a .cfg, show what a .cfg implies.
    #[command(subcommand)]
    Radar(radar::RadarCmd),
    /// Xsens MTi IMU: dump messages, configure a device.
    #[command(subcommand)]
    Imu(imu::ImuCmd),
    /// Replay a session into pseudo-terminals or serial devices (the HIL rig).
    Replay(replay::ReplayArgs),
    /// Record the radar and IMU ports into a session.
    Record(record::RecordArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Radar(cmd) => radar::run(cmd),
        Command::Imu(cmd) => imu::run(cmd),
        Command::Replay(args) => replay::run(args),
        Command::Record(args) => record::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("milliego: error: {e}");
            ExitCode::FAILURE
        }
    }
}
