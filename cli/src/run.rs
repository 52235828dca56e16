//! `milliego run`: the online runtime (live ports or a replay's pseudo-terminals) or an offline run
//! over a session, streaming poses to UDP, serial and TUM outputs. See docs/runtime.md.

use clap::{Args, ValueEnum};
use milliego_live_view::{LiveView, ViewOptions, DEFAULT_ADDR};
use milliego_runtime::config::FileConfig;
use milliego_runtime::estimator::EstimatorKind;
use milliego_runtime::output::OutputSpec;
use milliego_runtime::pipeline::{run as run_pipeline, Devices, Input, RunConfig};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EstimatorArg {
    /// The learned milliEgo model alone (the paper's network).
    Model,
    /// Doppler radar-inertial odometry.
    Doppler,
    /// IMU dead reckoning.
    Imu,
    /// Doppler with the model's relative motion as a gated measurement (every one within the
    /// gate applied).
    Fused,
    /// With a model: fused until its learned measurements fail the online consistency check,
    /// then Doppler (a hand-over); without one: Doppler (flagged model_fallback).
    Auto,
}

#[derive(Debug, Default, Args)]
pub struct RunArgs {
    /// Offline: a session directory (as fast as possible; --realtime for its original pace).
    #[arg(long, conflicts_with_all = ["radar_data", "imu"])]
    session: Option<PathBuf>,
    /// Offline: keep the session's original pacing.
    #[arg(long, requires = "session")]
    realtime: bool,
    /// Radar CLI port (the .cfg is uploaded there unless --no-configure).
    #[arg(long)]
    radar_cli: Option<String>,
    /// Radar data port.
    #[arg(long)]
    radar_data: Option<String>,
    /// Radar .cfg (uploaded; also gives the velocity resolution and frame period).
    #[arg(long)]
    radar_cfg: Option<PathBuf>,
    /// Radar data-port baud rate.
    #[arg(long)]
    radar_baud: Option<u32>,
    /// IMU port.
    #[arg(long)]
    imu: Option<String>,
    /// IMU baud rate.
    #[arg(long)]
    imu_baud: Option<u32>,
    /// The sensor hub's link, serial:DEV or serial:DEV@BAUD (default 921600): radar and IMU
    /// through the hub, on its clock (docs/hub-link.md). --radar-cfg gives the radar settings.
    #[arg(long, value_name = "serial:DEV[@BAUD]", conflicts_with_all = ["session", "radar_data", "imu"])]
    hub: Option<String>,
    /// Do not configure the sensors (replayed ports, or sensors already streaming).
    #[arg(long)]
    no_configure: bool,
    /// Estimator, model, outputs, summary, logging (shared with `view`).
    #[command(flatten)]
    pipe: PipelineArgs,
    /// Configuration file (TOML); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// IMU-rate predicted poses between radar-rate poses: on or off (default: on for live
    /// ports, off for sessions).
    #[arg(long)]
    imu_rate_output: Option<bool>,
    /// TUM outputs also get the predicted poses.
    #[arg(long)]
    tum_predicted: bool,
    /// The rig is a ground vehicle: the Doppler filter holds the body frame's lateral and
    /// vertical velocity at zero, within 0.01 m/s at standstill and 0.02 of the forward speed
    /// in motion (as `odometry --vehicle`).
    #[arg(long)]
    vehicle: bool,
    /// The IMU's noise preset for the filter: mti1 (Xsens MTi-1 series), mti600 (MTi-600
    /// series) or mems (BMI088/ICM class). Default: the one the session's IMU device names,
    /// else the MTi-1's noise with a gyro bias prior wide enough for any part (docs/odometry.md,
    /// "IMU noise", "Gyro bias prior").
    #[arg(long, value_name = "PRESET")]
    imu_noise: Option<milliego_odometry::rio::ImuNoise>,
    /// Live devices: the IMU's part name (e.g. MTi-1, MTi-630, BMI088), which picks its noise
    /// preset and gyro bias prior as a session's device name does; overrides `[imu] device` in
    /// --config. Sessions name their own IMU.
    #[arg(long, value_name = "NAME", conflicts_with = "session")]
    imu_device: Option<String>,
    /// Radar updates may correct heading (as `odometry --radar-heading`; docs/odometry.md).
    #[arg(long)]
    radar_heading: bool,
    /// How far back a radar point counts as seen again \[s\]: points seen in the frames before
    /// weigh more in the ego-velocity consensus (as `odometry --persist-window`; default 0.125,
    /// chosen on the validation sets, docs/odometry.md "Points seen again"; 0: off).
    /// The summary's `filter` block counts the points seen again.
    #[arg(long, value_name = "SECONDS")]
    persist_window: Option<f64>,
    /// Radar updates over which the filter adapts the scale of the radar velocity covariance
    /// (as `odometry --radar-noise-window`; default 300; 0: off, the covariance as the
    /// ego-velocity stage states it; docs/odometry.md "Radar noise adaptation"). The summary's
    /// `filter.radar_noise_scale` gives the scale it ended with.
    #[arg(long, value_name = "N")]
    radar_noise_window: Option<f64>,
    /// Correlation time of the rounding a coarse Doppler step leaves shared by a frame's points,
    /// kept as a filter state \[s\] (as `odometry --radar-error-time`; default 2; 0: off).
    #[arg(long, value_name = "SECONDS")]
    radar_error_time: Option<f64>,
    /// Stop after this many seconds.
    #[arg(long)]
    duration: Option<f64>,
    /// Stop when no sensor byte arrived for this many seconds (once data has flowed).
    #[arg(long)]
    idle_exit: Option<f64>,
    /// Sessions: align the clocks with the online synchroniser instead of the whole-session fit.
    #[arg(long, requires = "session")]
    online_clock: bool,
    /// Serve a live Foxglove view (WebSocket, foxglove.websocket.v1) on HOST:PORT; without a
    /// value on 127.0.0.1:8765 (loopback). Another host is reachable from the network: anyone
    /// who can connect sees the data (docs/live-view.md).
    #[arg(long, value_name = "HOST:PORT", num_args = 0..=1, default_missing_value = DEFAULT_ADDR)]
    foxglove: Option<String>,
    /// With --foxglove: wait up to this many seconds for a client to subscribe before starting.
    #[arg(long, value_name = "S", requires = "foxglove")]
    foxglove_wait: Option<f64>,
    /// With --foxglove: channel messages queued per client before that client's oldest is
    /// dropped and counted (`view_client_dropped`; default 4096).
    #[arg(long, value_name = "N", requires = "foxglove")]
    foxglove_backlog: Option<usize>,
    /// `milliego view`: pace multiplier of the session.
    #[arg(skip)]
    speed: Option<f64>,
    /// `milliego view`: wait for a client without a limit.
    #[arg(skip)]
    wait_forever: bool,
}

/// `milliego view`: a session replayed at its pace through the estimator, shown live.
#[derive(Debug, Args)]
pub struct ViewArgs {
    /// Session directory (recorded, simulated or imported).
    session: PathBuf,
    /// Pace: 1 is the recorded pace, 2 twice as fast.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Where the Foxglove WebSocket server listens (loopback by default; another host is
    /// reachable from the network).
    #[arg(long, value_name = "HOST:PORT", default_value = DEFAULT_ADDR)]
    foxglove: String,
    /// Wait at most this many seconds for a client to subscribe (default: until one does;
    /// Ctrl-C stops); 0 starts at once.
    #[arg(long, value_name = "S")]
    wait: Option<f64>,
    /// Channel messages queued per client before that client's oldest is dropped and counted
    /// (`view_client_dropped`; default 4096).
    #[arg(long, value_name = "N")]
    backlog: Option<usize>,
    /// Estimator, model, outputs, summary, logging (as for `run`).
    #[command(flatten)]
    pipe: PipelineArgs,
}

/// The flags `run` and `view` share: what estimates, where poses and the summary go, logging.
#[derive(Debug, Default, Args)]
pub struct PipelineArgs {
    /// Estimator.
    #[arg(long, value_enum)]
    estimator: Option<EstimatorArg>,
    /// Learned-model file.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Threads for the learned model's matrix products (default 1: the shipped compact model is
    /// slower on 2; larger graphs gain about 1.2x on 2, docs/runtime.md "Model threads").
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=64))]
    threads: Option<u16>,
    /// Output: udp://HOST:PORT, serial:DEV or serial:DEV@BAUD, tum:FILE (repeatable).
    #[arg(long = "out")]
    out: Vec<String>,
    /// Write the summary as JSON to this file.
    #[arg(long)]
    summary_json: Option<PathBuf>,
    /// More logging (-v info, -vv debug); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count)]
    verbose: u8,
}

/// `milliego view`: `run --session DIR --realtime --foxglove ADDR`, at `--speed`.
pub fn view(a: ViewArgs) -> Result<()> {
    if !(a.speed.is_finite() && a.speed > 0.0) {
        return Err(format!("--speed {}: expected a positive number", a.speed).into());
    }
    run(RunArgs {
        session: Some(a.session),
        realtime: true,
        pipe: a.pipe,
        foxglove: Some(a.foxglove),
        foxglove_wait: a.wait,
        foxglove_backlog: a.backlog,
        wait_forever: a.wait.is_none(),
        speed: Some(a.speed),
        ..RunArgs::default()
    })
}

/// Starts the live view of `--foxglove`, its tap in `cfg`.
fn start_view(a: &RunArgs, addr: &str, cfg: &mut RunConfig) -> Result<LiveView> {
    let mut o = ViewOptions::parse_addr(addr)?;
    o.session = a.session.clone();
    if let Some(b) = a.foxglove_backlog {
        o.backlog = b.max(1);
    }
    if !o.is_loopback() {
        eprintln!(
            "warning: the live view listens on {addr}, reachable from other machines: anyone who \
             can connect sees the poses and sensor data (no authentication, no TLS)"
        );
    }
    let (view, tap) = LiveView::start(&o)?;
    eprintln!(
        "live view: ws://{} (Foxglove: Open connection -> Foxglove WebSocket; layout docs/foxglove-layout.json)",
        view.addr()
    );
    cfg.view = Some(tap);
    Ok(view)
}

fn init_logging(verbose: u8) {
    use tracing_subscriber::EnvFilter;
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    use std::io::IsTerminal;
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .try_init();
}

pub fn run(a: RunArgs) -> Result<()> {
    init_logging(a.pipe.verbose);
    let file = match &a.config {
        Some(p) => FileConfig::load(p)?,
        None => FileConfig::default(),
    };
    let mut cfg = RunConfig {
        estimator: match a.pipe.estimator {
            Some(EstimatorArg::Model) => EstimatorKind::Model,
            Some(EstimatorArg::Doppler) => EstimatorKind::Doppler,
            Some(EstimatorArg::Imu) => EstimatorKind::Imu,
            Some(EstimatorArg::Fused) => EstimatorKind::Fused,
            Some(EstimatorArg::Auto) => EstimatorKind::Auto,
            None => file.estimator.unwrap_or(EstimatorKind::Auto),
        },
        ..RunConfig::default()
    };
    // Default: the shipped int8 model, when run from the repository.
    cfg.model = a.pipe.model.clone().or(file.model.clone()).or_else(|| {
        let p = PathBuf::from("models/compact/model-int8.onnx");
        p.is_file().then_some(p)
    });
    cfg.model_threads = a
        .pipe
        .threads
        .map(usize::from)
        .or(file.model_threads)
        .unwrap_or(1);
    cfg.outputs = if a.pipe.out.is_empty() {
        file.outputs()?
    } else {
        a.pipe
            .out
            .iter()
            .map(|o| o.parse::<OutputSpec>())
            .collect::<std::result::Result<_, _>>()?
    };
    let radar_data = a.radar_data.clone().or(file.radar.data.clone());
    let imu = a.imu.clone().or(file.imu.port.clone());
    let offline = a.session.is_some();
    if !offline && radar_data.is_none() && imu.is_none() && a.hub.is_none() {
        return Err(
            "give --session DIR, --hub serial:DEV, or --radar-data and/or --imu (or a --config naming them)".into(),
        );
    }
    cfg.imu_rate_output = a
        .imu_rate_output
        .or(file.imu_rate_output)
        .unwrap_or(!offline);
    cfg.tum_predicted = a.tum_predicted || file.tum_predicted.unwrap_or(false);
    cfg.duration_s = a.duration;
    cfg.session_online_clock = a.online_clock;
    cfg.idle_exit_s = a.idle_exit;
    if let Some(s) = file.sync.stall_periods {
        cfg.sync.stall_periods = s;
    }
    if let Some(s) = file.sync.max_hold_s {
        cfg.sync.max_hold_s = s;
    }
    if let Some(w) = file.sync.clock_window {
        cfg.sync.clock.window = w;
    }
    if let Some(l) = file.sync.late_s {
        cfg.sync.clock.late_s = l;
    }
    let q = &file.queues;
    for (slot, v) in cfg
        .queues
        .iter_mut()
        .zip([q.radar, q.imu, q.events, q.poses])
    {
        if let Some(v) = v {
            *slot = v;
        }
    }
    let place = |p: &milliego_runtime::config::Placement| {
        let [w, x, y, z] = p.rotation_wxyz;
        nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::from(nalgebra::Vector3::from(p.translation_m)),
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
        )
    };
    if a.vehicle {
        cfg.classical.rio = cfg.classical.rio.ground_vehicle();
    }
    cfg.imu_noise = a.imu_noise;
    cfg.imu_device = a.imu_device.clone().or(file.imu.device.clone());
    cfg.classical.rio.radar_heading = a.radar_heading;
    if let Some(w) = a.persist_window {
        cfg.classical.persist.window_s = w.max(0.0);
    }
    if let Some(n) = a.radar_noise_window {
        cfg.classical.rio.radar_noise_window = n.max(0.0);
    }
    if let Some(t) = a.radar_error_time {
        cfg.classical.rio = cfg.classical.rio.with_radar_error_time(t);
    }
    if let Some(p) = &file.extrinsics.radar {
        cfg.classical.mounting.radar = place(p);
    }
    if let Some(p) = &file.extrinsics.imu {
        cfg.classical.mounting.imu = place(p);
    }
    let input = match &a.session {
        Some(dir) => Input::Session {
            dir: dir.clone(),
            realtime: a.realtime,
        },
        None => Input::Devices(Devices {
            radar_cli: a.radar_cli.clone().or(file.radar.cli.clone()),
            radar_data,
            radar_cfg: a.radar_cfg.clone().or(file.radar.cfg.clone()),
            radar_baud: a.radar_baud.or(file.radar.baud).unwrap_or(921_600),
            imu,
            imu_baud: a.imu_baud.or(file.imu.baud).unwrap_or(115_200),
            imu_wrap_day: file.imu.wrap.as_deref() == Some("day"),
            configure: !a.no_configure,
            hub: a.hub.clone(),
        }),
    };
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // A second Ctrl-C exits at once (status 130).
        signal_hook::flag::register_conditional_shutdown(sig, 130, Arc::clone(&stop))?;
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    if let Some(s) = a.speed {
        cfg.session_speed = s;
    }
    let view = match &a.foxglove {
        Some(addr) => Some(start_view(&a, addr, &mut cfg)?),
        None => None,
    };
    if let Some(v) = &view {
        let limit = a.foxglove_wait.map(|s| Duration::from_secs_f64(s.max(0.0)));
        if a.wait_forever || limit.is_some_and(|l| !l.is_zero()) {
            eprintln!("live view: waiting for a client to subscribe");
            if !v.wait_for_subscriber(if a.wait_forever { None } else { limit }, &stop) {
                eprintln!("live view: no client subscribed; starting anyway");
            }
        }
    }
    let summary = run_pipeline(&input, &cfg, stop);
    // The run is over: the view publishes what it still holds, then stops.
    cfg.view = None;
    let view = view.map(|v| v.finish(Duration::from_millis(500)));
    let mut summary = summary?;
    if let Some(v) = view {
        summary.report.view_client_dropped = v.client_dropped;
    }
    let text = serde_json::to_string_pretty(&summary.report)?;
    eprintln!("{text}");
    if let Some(p) = a.pipe.summary_json.as_ref().or(file.summary_json.as_ref()) {
        std::fs::write(p, &text).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}
