//! `milliego replay`: the HIL rig. Plays a session into pseudo-terminals it creates (printing the
//! paths a system under test opens) or into serial devices, with the original pacing, faster, or
//! as fast as possible, and optional seeded faults.

use clap::Args;
use milliego_hil::fault::{parse_garbage, parse_reopen, parse_stall};
use milliego_hil::{schedule, FaultPlan, Notice, Pacing, ReplayOptions, Sink, StreamKind};
use milliego_session::Session;
use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Replay a session into pseudo-terminals or serial devices.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// Session directory, or a bare TI .dat / Xsens log, or a directory of them.
    session: PathBuf,
    /// Pace: N times the original speed (1 = original).
    #[arg(long, default_value_t = 1.0, conflicts_with = "fast")]
    speed: f64,
    /// As fast as the ports take the bytes.
    #[arg(long)]
    fast: bool,
    /// Create pseudo-terminals and print their paths (the default without --radar-dev/--imu-dev).
    #[arg(long, conflicts_with_all = ["radar_dev", "imu_dev"])]
    pty: bool,
    /// Serial device for the radar stream (e.g. a USB-serial adapter wired to the board's UART).
    #[arg(long)]
    radar_dev: Option<String>,
    /// Serial device for the IMU stream.
    #[arg(long)]
    imu_dev: Option<String>,
    /// Radar UART rate, in bit/s (default: the session's, else 921600).
    #[arg(long)]
    baud_radar: Option<u32>,
    /// IMU UART rate, in bit/s (default: the session's, else 115200).
    #[arg(long)]
    baud_imu: Option<u32>,
    /// Fraction of bytes to corrupt (XOR with a random non-zero value).
    #[arg(long, default_value_t = 0.0)]
    corrupt: f64,
    /// Fraction of bytes to drop.
    #[arg(long, default_value_t = 0.0)]
    drop: f64,
    /// Garbage bursts RATE:LEN (bursts per second of session time, bytes per burst), inserted
    /// between frames, never containing a sync byte.
    #[arg(long, value_name = "RATE:LEN")]
    garbage: Option<String>,
    /// Stall a stream: STREAM@T+D stops it at T seconds for D seconds (repeatable).
    #[arg(long, value_name = "STREAM@T+D")]
    stall: Vec<String>,
    /// Close and reopen a port at T seconds: STREAM@T (repeatable).
    #[arg(long, value_name = "STREAM@T")]
    reopen: Vec<String>,
    /// Seed of the fault generators.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Repeat the session until Ctrl-C.
    #[arg(long = "loop")]
    repeat: bool,
    /// Start only once every pty has been opened by someone (Linux: seen in /proc/*/fd).
    #[arg(long)]
    wait_open: bool,
    /// Start only after Enter is pressed.
    #[arg(long)]
    wait_enter: bool,
    /// Wait this long before starting, in s.
    #[arg(long, default_value_t = 0.0)]
    start_delay: f64,
    /// Keep the ptys open this long after the last byte, so readers get everything, in s.
    #[arg(long, default_value_t = 1.0)]
    linger: f64,
}

pub fn run(a: ReplayArgs) -> Result<(), Box<dyn std::error::Error>> {
    let session = Session::open(&a.session)?;
    let mut schedules = schedule::build(&session, a.baud_radar, a.baud_imu)?;
    let pacing = if a.fast {
        Pacing::Fast
    } else if a.speed == 1.0 {
        Pacing::Original
    } else {
        Pacing::Speed(a.speed)
    };
    let mut faults = FaultPlan {
        corrupt: a.corrupt,
        drop: a.drop,
        garbage: a.garbage.as_deref().map(parse_garbage).transpose()?,
        seed: a.seed,
        ..FaultPlan::default()
    };
    for s in &a.stall {
        faults.stalls.push(parse_stall(s)?);
    }
    for s in &a.reopen {
        faults.reopens.push(parse_reopen(s)?);
    }
    faults.validate()?;
    seconds("--start-delay", a.start_delay)?;
    seconds("--linger", a.linger)?;

    let stop = Arc::new(AtomicBool::new(false));
    // First Ctrl-C/SIGTERM: a flag the loops poll (clean shutdown); a second one exits at once.
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register_conditional_shutdown(sig, 130, stop.clone())?;
        signal_hook::flag::register(sig, stop.clone())?;
    }

    let devices = a.radar_dev.is_some() || a.imu_dev.is_some();
    let mut sinks = Vec::new();
    schedules.retain(|s| {
        !devices
            || match s.kind {
                StreamKind::Radar => a.radar_dev.is_some(),
                StreamKind::Imu => a.imu_dev.is_some(),
            }
    });
    if schedules.is_empty() {
        return Err("nothing to replay: the session has no stream for the devices given".into());
    }
    let mut out = std::io::stdout().lock();
    for s in &schedules {
        let sink = match (devices, s.kind) {
            (false, k) => Sink::pty(k)?,
            (true, StreamKind::Radar) => {
                Sink::device(s.kind, a.radar_dev.as_deref().unwrap_or_default(), s.baud)?
            }
            (true, StreamKind::Imu) => {
                Sink::device(s.kind, a.imu_dev.as_deref().unwrap_or_default(), s.baud)?
            }
        };
        writeln!(out, "{}: {}", s.kind.name(), sink.path())?;
        eprintln!(
            "{}: {} B, {} pieces over {:.3} s, timing from {:?}, {} bit/s",
            s.kind.name(),
            s.data.len(),
            s.pieces.len(),
            s.end_ns() as f64 * 1e-9,
            s.timing,
            s.baud
        );
        sinks.push(sink);
    }
    out.flush()?;
    drop(out);

    let stopped = || stop.load(Ordering::SeqCst);
    if a.wait_open {
        for s in &sinks {
            eprintln!("waiting for {} to be opened ...", s.path());
            if !s.wait_open(None, &stopped) {
                return Err("stopped before the ports were opened".into());
            }
        }
    }
    if a.wait_enter {
        eprintln!("press Enter to start");
        let mut line = String::new();
        std::io::stdin().lock().read_line(&mut line)?;
        if stopped() {
            return Err("stopped before the start".into());
        }
    }
    wait(seconds("--start-delay", a.start_delay)?, &stopped);

    let (tx, rx) = crossbeam_channel::unbounded();
    let printer = std::thread::spawn(move || {
        for n in rx {
            match n {
                Notice::Reopened { stream, path } => {
                    println!("{}: {path} (reopened)", stream.name());
                }
                Notice::Blocked { stream, path } => eprintln!(
                    "{}: {path} takes no bytes (is anything reading it?)",
                    stream.name()
                ),
            }
        }
    });
    let opts = ReplayOptions {
        pacing,
        faults,
        passes: if a.repeat { 0 } else { 1 },
        stop: stop.clone(),
        notify: Some(tx),
        ..ReplayOptions::default()
    };
    // Progress on stderr (drawn only on a terminal): replay time against the session's length.
    let total_s = schedules.iter().map(|s| s.end_ns()).max().unwrap_or(0) as f64 * 1e-9;
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let ticker = {
        let done = done.clone();
        let speed = a.speed.max(1e-6);
        std::thread::spawn(move || {
            let bar = indicatif::ProgressBar::new((total_s * 10.0) as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template("replay {bar:30} {msg}")
                    .expect("valid template"),
            );
            let t0 = std::time::Instant::now();
            while !done.load(Ordering::SeqCst) {
                let t = (t0.elapsed().as_secs_f64() * speed).min(total_s);
                bar.set_position((t * 10.0) as u64);
                bar.set_message(format!("{t:.1} / {total_s:.1} s"));
                std::thread::sleep(std::time::Duration::from_millis(200));
            }
            bar.finish_and_clear();
        })
    };
    let result = milliego_hil::replay(schedules, sinks, &opts);
    done.store(true, Ordering::SeqCst);
    let _ = ticker.join();
    let (report, sinks) = result?;
    drop(opts);
    let _ = printer.join();
    if sinks.iter().any(Sink::is_pty) {
        wait(seconds("--linger", a.linger)?, &stopped);
    }
    drop(sinks);
    eprintln!(
        "replay {} after {:.3} s",
        if report.stopped { "stopped" } else { "done" },
        report.wall_ns as f64 * 1e-9
    );
    for r in &report.streams {
        let f = r.faults;
        eprintln!(
            "{}: {} -> {} B in {} writes over {} pass(es); late max {:.3} ms mean {:.3} ms; blocked {:.3} s; \
             faults: {} corrupted, {} dropped, {} garbage bursts ({} B), {} stalls, {} reopens",
            r.stream.name(),
            r.bytes_session,
            r.bytes_written,
            r.writes,
            r.passes,
            r.late_max_ns as f64 * 1e-6,
            r.late_mean_ns as f64 * 1e-6,
            r.blocked_ns as f64 * 1e-9,
            f.corrupted,
            f.dropped,
            f.garbage_bursts,
            f.garbage_bytes,
            f.stalls,
            f.reopens
        );
    }
    Ok(())
}

/// A duration option \[s\]: finite and >= 0.
fn seconds(name: &str, s: f64) -> Result<Duration, String> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| format!("{name} {s}: must be a finite number of seconds >= 0"))
}

/// Sleeps `d` unless stopped first.
fn wait(d: Duration, stopped: &dyn Fn() -> bool) {
    let start = Instant::now();
    while start.elapsed() < d && !stopped() {
        std::thread::sleep(Duration::from_millis(20).min(d));
    }
}
