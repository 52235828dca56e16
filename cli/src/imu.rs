//! `milliego imu ...` (being written on its own branch).

use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum ImuCmd {}

pub fn run(cmd: ImuCmd) -> Result<(), Box<dyn std::error::Error>> {
    match cmd {}
}
