//! `milliego record`: configures the radar and the IMU, then records their data ports into a
//! session until Ctrl-C or a duration, with a progress line on stderr.

use clap::Args;
use milliego_hil::{ImuPort, Live, RadarPorts, RecordConfig};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

/// Record the radar and/or IMU ports into a new session directory.
#[derive(Debug, Args)]
pub struct RecordArgs {
    /// The new session directory (must not hold a session yet).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
    /// Radar CLI port (configuration; sensorStop at the end).
    #[arg(long)]
    radar_cli: Option<String>,
    /// Radar data port.
    #[arg(long)]
    radar_data: Option<String>,
    /// Radar chirp configuration to upload (saved as radar.cfg).
    #[arg(long)]
    radar_cfg: Option<PathBuf>,
    /// Radar data port rate, in bit/s.
    #[arg(long, default_value_t = 921_600)]
    radar_baud: u32,
    /// IMU port.
    #[arg(long)]
    imu: Option<String>,
    /// IMU port rate, in bit/s.
    #[arg(long, default_value_t = 115_200)]
    imu_baud: u32,
    /// IMU inertial output rate, in Hz.
    #[arg(long, default_value_t = 100)]
    imu_rate: u16,
    /// Stop after this long, in s (else at Ctrl-C).
    #[arg(long)]
    duration: Option<f64>,
    /// Record without configuring the sensors (and without sensorStop/GoToConfig at the end).
    #[arg(long)]
    no_config: bool,
    /// No progress line.
    #[arg(long)]
    quiet: bool,
}

pub fn run(a: RecordArgs) -> Result<(), Box<dyn std::error::Error>> {
    if a.radar_data.is_none() && a.imu.is_none() {
        return Err("nothing to record: give --radar-data and/or --imu".into());
    }
    let cfg_text = match &a.radar_cfg {
        Some(p) => Some(std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    // First Ctrl-C/SIGTERM: a flag the loops poll (clean shutdown); a second one exits at once.
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(sig, 130, stop.clone())?;
        signal_hook::flag::register(sig, stop.clone())?;
    }
    let duration =
        match a.duration {
            Some(d) if d > 0.0 => Some(Duration::try_from_secs_f64(d).map_err(|_| {
                format!("--duration {d}: must be a finite positive number of seconds")
            })?),
            Some(d) => {
                return Err(
                    format!("--duration {d}: must be a finite positive number of seconds").into(),
                )
            }
            None => None,
        };
    let cfg = RecordConfig {
        out: a.out,
        radar: a.radar_data.map(|data| RadarPorts {
            data,
            data_baud: a.radar_baud,
            cli: a.radar_cli,
            cfg: cfg_text,
        }),
        imu: a.imu.map(|path| ImuPort {
            path,
            baud: a.imu_baud,
            rate_hz: a.imu_rate,
        }),
        configure: !a.no_config,
        duration,
        progress: (!a.quiet).then_some(Duration::from_secs(1)),
        stop,
        ..RecordConfig::default()
    };
    let report = milliego_hil::record(&cfg, &Arc::new(Live::default()))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "recorded {:.1} s into {}",
        report.seconds,
        report.dir.display()
    );
    for s in &report.streams {
        eprintln!(
            "{} ({}): {} B read = {} B written in {} chunks; {} frames, {} bad, {} B skipped; queue full {}x (longest wait {:.1} ms)",
            s.stream.name(),
            s.port,
            s.bytes_read,
            s.bytes_written,
            s.chunks,
            s.frames_ok,
            s.frames_bad,
            s.bytes_skipped,
            s.queue_full,
            s.max_wait_ns as f64 * 1e-6
        );
    }
    Ok(())
}
