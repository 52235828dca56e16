//! `milliego record`: configures the radar and the IMU, then records their data ports (or both
//! through the sensor hub's link) into a session until Ctrl-C or a duration, with a progress line
//! on stderr.

use clap::Args;
use milliego_hil::{HubPort, ImuPort, Live, RadarPorts, RecordConfig};
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
    /// Both sensors through the sensor hub, serial:DEV or serial:DEV@BAUD (default 921600):
    /// each frame timed by the hub's clock at its last byte (docs/hub-link.md). --radar-cfg is
    /// saved (and uploaded over --radar-cli unless --no-config); the IMU is not configured.
    #[arg(long, value_name = "serial:DEV[@BAUD]", conflicts_with_all = ["radar_data", "imu"])]
    hub: Option<String>,
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
    if a.radar_data.is_none() && a.imu.is_none() && a.hub.is_none() {
        return Err("nothing to record: give --radar-data and/or --imu, or --hub".into());
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
    let hub = match &a.hub {
        Some(spec) => {
            let (path, baud) = milliego_runtime::pipeline::hub::parse_spec(spec)?;
            Some(HubPort {
                path,
                baud,
                radar_cli: a.radar_cli.clone(),
                radar_cfg: cfg_text.clone(),
            })
        }
        None => None,
    };
    let cfg = RecordConfig {
        out: a.out,
        hub,
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
    if let Some(h) = &report.hub {
        let health = h.health.map_or("no health message".to_string(), |x| {
            format!(
                "hub says: radar {} B received, {} frames forwarded, {} rejected, {} B skipped, {} B ring overflow; IMU {} B, {} forwarded, {} rejected, {} B skipped, {} B ring overflow; link {} sent, {} dropped",
                x.radar.rx_bytes, x.radar.frames_forwarded, x.radar.frames_bad, x.radar.bytes_skipped, x.radar.ring_overflow,
                x.imu.rx_bytes, x.imu.frames_forwarded, x.imu.frames_bad, x.imu.bytes_skipped, x.imu.ring_overflow,
                x.link_sent, x.link_dropped
            )
        });
        eprintln!(
            "hub link ({}): {} B, {} messages, {} bad frames ({} B dropped), {} lone delimiters, {} missing by sequence, {} restarts, {} stamps clamped; {health}",
            h.port, h.link_bytes, h.messages, h.bad_frames, h.bytes_dropped, h.empty_frames, h.seq_gaps, h.restarts, h.stamps_clamped
        );
    }
    Ok(())
}
