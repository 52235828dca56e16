//! `milliego radar ...` (being written).

use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum RadarCmd {}

pub fn run(cmd: RadarCmd) -> Result<(), Box<dyn std::error::Error>> {
    match cmd {}
}
