//! `milliego export-mcap`: a session and estimated trajectories as an MCAP file with ROS 2 schemas
//! (Foxglove, `ros2 bag play`); topics, frames and the time base are in docs/mcap.md.

use clap::Args;
use milliego_mcap::{export, topic_name, ExportOptions, Trajectory};
use milliego_session::{read_tum, Session};
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Args)]
pub struct McapArgs {
    /// Session directory (or bare captures); its ground truth, if any, becomes /groundtruth/*.
    session: PathBuf,
    /// Estimated trajectory (TUM, session host clock, e.g. from `milliego odometry`); repeatable,
    /// each becomes `/STEM/pose` and `/STEM/odom` (STEM: the file name without extension).
    #[arg(long = "poses", value_name = "EST.tum")]
    poses: Vec<PathBuf>,
    /// Output MCAP file.
    #[arg(short, long)]
    out: PathBuf,
    /// Store the chunks uncompressed (default: zstd).
    #[arg(long)]
    no_compress: bool,
}

pub fn run(a: McapArgs) -> Result<()> {
    let session = Session::open(&a.session)?;
    let mut estimates = Vec::new();
    for p in &a.poses {
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        estimates.push(Trajectory {
            name: topic_name(stem),
            poses: read_tum(p)?,
        });
    }
    let opts = ExportOptions {
        compress: !a.no_compress,
        ..ExportOptions::default()
    };
    let s = export(&session, &estimates, &a.out, &opts)
        .map_err(|e| format!("{} -> {}: {e}", a.session.display(), a.out.display()))?;
    println!(
        "{:<24} {:<32} {:>9} {:>12}",
        "topic", "type", "messages", "bytes"
    );
    for t in &s.topics {
        println!(
            "{:<24} {:<32} {:>9} {:>12}",
            t.topic, t.ros_type, t.messages, t.bytes
        );
    }
    let span = s
        .log_time_range_ns
        .map_or(0.0, |(a, b)| (b - a) as f64 * 1e-9);
    println!(
        "{}: {} messages over {span:.3} s, {} B ({})",
        s.path.display(),
        s.messages(),
        s.file_bytes,
        if a.no_compress {
            "uncompressed"
        } else {
            "zstd"
        }
    );
    println!(
        "radar: {} frames, {} rejected by the framer, {} without a time (not exported); imu: {} messages, {} rejected, {} not samples",
        s.radar.ok, s.radar.bad, s.radar_untimed, s.imu.ok, s.imu.bad, s.imu.not_samples
    );
    if s.clock_unsynced {
        println!("warning: no timing index for a stream: its sensor clock was taken to start at session time 0");
    }
    if s.time_offset_ns > 0 {
        println!(
            "note: log times are session time + {:.6} s (data measured before the session start)",
            s.time_offset_ns as f64 * 1e-9
        );
    }
    Ok(())
}
