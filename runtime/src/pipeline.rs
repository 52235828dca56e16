//! The threads and their wiring: readers (or the offline feeder) -> synchroniser -> estimator
//! stage -> output, joined by [`DropOldest`] queues; the summary at the end.

pub use crate::error::{PortRole, RunError};
use crate::estimator::{build_run_estimators, Built, ClassicalConfig, EstimatorKind, ModelSource};
use crate::output::{Encoded, OutputSpec, Sink};
use crate::queue::{DropOldest, Pool};
use crate::reader::{
    radar_sink, read_loop, ImuDecoder, ImuItem, RadarDecoder, RadarItem, ReaderCtx, ReaderStats,
    SerialSource, Source,
};
use crate::stage::{PoseOut, Stage, StageConfig, StageCounters};
use crate::stats::Histogram;
use crate::summary::{
    ClockSummary, Clocks, Drops, FramesIn, FramesOut, LatencySummary, Plausibility, Ports,
    RunSummary, SyncSummary,
};
use crate::sync::{FeedOrder, SyncConfig, SyncCounters, SyncOut, Synchroniser};
use crate::view::{ViewEvent, ViewStatus, ViewTap};
use imu_driver::TimeWrap;
use milliego_session::streams::StreamReport;
use pose_link::Health;
use radar_driver::host::DecoderConfig;
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub mod hub;

/// Where sensor data comes from.
#[derive(Debug, Clone)]
pub enum Input {
    /// A recorded or simulated session, as fast as possible or at its original pace.
    Session {
        /// Session directory.
        dir: PathBuf,
        /// Keep the original pacing.
        realtime: bool,
    },
    /// Live ports (or pseudo-terminals of a replay).
    Devices(Devices),
}

/// Live ports.
#[derive(Debug, Clone, Default)]
pub struct Devices {
    /// Radar CLI port (for the `.cfg` upload).
    pub radar_cli: Option<String>,
    /// Radar data port.
    pub radar_data: Option<String>,
    /// Radar `.cfg` (uploaded, and read for the velocity resolution and frame period).
    pub radar_cfg: Option<PathBuf>,
    /// Radar data-port baud rate \[bit/s\].
    pub radar_baud: u32,
    /// IMU port.
    pub imu: Option<String>,
    /// IMU baud rate \[bit/s\].
    pub imu_baud: u32,
    /// SampleTimeFine wrap of the IMU.
    pub imu_wrap_day: bool,
    /// Configure the sensors before streaming (upload the `.cfg`, put the IMU in measurement).
    pub configure: bool,
    /// The sensor hub's link, `serial:DEV[@BAUD]`: both sensors on the hub's clock ([`hub`]).
    pub hub: Option<String>,
}

/// Settings of a run.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Estimator.
    pub estimator: EstimatorKind,
    /// Learned-model file.
    pub model: Option<PathBuf>,
    /// Threads for the learned model's matrix products (1: the estimator thread alone; see
    /// docs/runtime.md, "Model threads", for the measured scaling).
    pub model_threads: usize,
    /// Outputs.
    pub outputs: Vec<OutputSpec>,
    /// Publish IMU-propagated poses between radar-rate poses.
    pub imu_rate_output: bool,
    /// TUM outputs include the predicted poses.
    pub tum_predicted: bool,
    /// Classical estimators (extrinsics included; a session's replace them).
    pub classical: ClassicalConfig,
    /// Synchroniser.
    pub sync: SyncConfig,
    /// The IMU's noise preset for the filter; `None`: the one a session's IMU device names
    /// (`milliego_odometry::offline::imu_noise_of`), else `classical.rio` as given.
    pub imu_noise: Option<milliego_odometry::rio::ImuNoise>,
    /// Live devices: the IMU's part name (`[imu] device` in the configuration file,
    /// `run --imu-device`), whose preset the filter takes when `imu_noise` is none, as a
    /// session's device name picks one (`milliego_odometry::rio::ImuNoise::from_device`).
    /// Sessions name their own; this is not used for them.
    pub imu_device: Option<String>,
    /// Queue capacities: radar frames, IMU samples, synchronised events, poses.
    pub queues: [usize; 4],
    /// Stop after this long \[s\].
    pub duration_s: Option<f64>,
    /// Stop when no byte arrived for this long, once data has flowed \[s\].
    pub idle_exit_s: Option<f64>,
    /// First reopen backoff \[s\].
    pub reopen_backoff_s: f64,
    /// Sessions: align the clocks with the online synchroniser (from the recorded host
    /// stamps) instead of the whole-session fit.
    pub session_online_clock: bool,
    /// A live view's hand-off ([`crate::view`]): copies of frames, samples and poses, offered
    /// without waiting; what it cannot take is counted (`view_dropped`).
    pub view: Option<ViewTap>,
    /// Sessions at their original pace (`realtime`): how many times faster than recorded.
    pub session_speed: f64,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            estimator: EstimatorKind::Auto,
            model: None,
            model_threads: 1,
            outputs: Vec::new(),
            imu_rate_output: false,
            tum_predicted: false,
            classical: ClassicalConfig::default(),
            sync: SyncConfig::default(),
            imu_noise: None,
            imu_device: None,
            queues: [32, 512, 1024, 1024],
            duration_s: None,
            idle_exit_s: None,
            reopen_backoff_s: 0.05,
            session_online_clock: false,
            view: None,
            session_speed: 1.0,
        }
    }
}

/// Latency histograms of a run.
#[derive(Debug, Clone, Default)]
pub struct Latencies {
    /// Read of the last byte -> released by the synchroniser.
    pub sync: Histogram,
    /// Estimator stage compute time per event.
    pub estimate: Histogram,
    /// Estimator stage -> sent by the output stage.
    pub output: Histogram,
    /// Radar-rate poses: sensor byte read -> pose sent.
    pub end_to_end: Histogram,
    /// Predicted poses: IMU sample read -> pose sent.
    pub imu_to_pose: Histogram,
    /// Handing one item to the live view (copy and `try_send`).
    pub view_handoff: Histogram,
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Everything, as printed and written with `--summary-json`.
    pub report: RunSummary,
    /// Latencies.
    pub latency: Latencies,
    /// Poses sent (all kinds).
    pub poses_sent: u64,
    /// Radar-rate poses sent.
    pub radar_poses: u64,
    /// Drops of every queue and buffer.
    pub dropped_total: u64,
    /// Wall time \[s\].
    pub wall_s: f64,
}

struct Shared {
    radar_q: DropOldest<Box<RadarItem>>,
    imu_q: DropOldest<ImuItem>,
    ev_q: DropOldest<SyncOut>,
    pose_q: DropOldest<PoseOut>,
    pool: Pool<RadarItem>,
    stop: Arc<AtomicBool>,
    /// A session run: queues between stages wait instead of dropping.
    offline: bool,
    inputs_done: AtomicBool,
    sync_done: AtomicBool,
    stage_done: AtomicBool,
    sync_dropped: AtomicU64,
    epoch: Instant,
    last_data_ns: AtomicU64,
    /// Sessions: common-clock time up to which the feeder has pushed everything (f64 bits).
    watermark: AtomicU64,
    /// The live view's hand-off, when one is on.
    view: Option<ViewTap>,
}

impl Shared {
    fn now_ns(&self) -> u64 {
        self.epoch.elapsed().as_nanos() as u64
    }
    fn dropped(&self) -> u64 {
        self.radar_q.dropped()
            + self.imu_q.dropped()
            + self.ev_q.dropped()
            + self.pose_q.dropped()
            + self.sync_dropped.load(Ordering::Relaxed)
    }
}

fn recycle(sh: &Shared, ev: SyncOut) {
    if let SyncOut::Radar { item, .. } = ev {
        sh.pool.give(item);
    }
}

fn radar_derived(text: &str) -> Result<radar_driver::cfg::Derived, radar_driver::cfg::CfgError> {
    radar_driver::cfg::RadarConfig::parse(text)?.derive(None)
}

/// Reads and derives the radar `.cfg` at `path`.
fn read_radar_cfg(path: &std::path::Path) -> Result<radar_driver::cfg::Derived, RunError> {
    let text = std::fs::read_to_string(path).map_err(|error| RunError::RadarCfgRead {
        path: path.to_path_buf(),
        error,
    })?;
    radar_derived(&text).map_err(|error| RunError::RadarCfg {
        path: path.to_path_buf(),
        error,
    })
}

/// Everything a run needs, derived once from the input and the settings before any thread
/// starts: a missing device, a bad `.cfg` or an unusable model stops the run here, with one
/// message.
struct Plan {
    /// The settings, completed from the session or the `.cfg` (mounting, Doppler noise, clock).
    cfg: RunConfig,
    /// The session, for offline runs.
    session: Option<milliego_session::Session>,
    /// What the radar `.cfg` tells the live decoder (Doppler scale, frame period, plausibility).
    radar_decoding: DecoderConfig,
    /// The estimators.
    built: Built,
    /// The outputs, open.
    sinks: Vec<Sink>,
    /// The IMU noise the filter assumes and where it came from (for the summary).
    imu_noise: String,
}

impl Plan {
    fn derive(input: &Input, cfg: &RunConfig) -> Result<Plan, RunError> {
        let mut cfg = cfg.clone();
        let mut session = None;
        let mut radar_decoding = DecoderConfig::default();
        let imu_noise;
        let mut apply_cfg = |cfg: &mut RunConfig, d: &radar_driver::cfg::Derived| {
            cfg.classical.ego = cfg
                .classical
                .ego
                .with_velocity_resolution(d.velocity_resolution_mps);
            cfg.sync.radar_period_s = Some(d.frame_period_ms / 1e3);
            cfg.sync.half_chirps_s = d.active_frame_time_ms / 2e3;
            radar_decoding = DecoderConfig::from_derived(Some(d));
        };
        match input {
            Input::Session { dir, .. } => {
                let session_err = |error| RunError::Session {
                    dir: dir.clone(),
                    error,
                };
                let s = milliego_session::Session::open(dir).map_err(session_err)?;
                cfg.classical.mounting =
                    crate::estimator::Mounting::from_session(&s.meta.extrinsics);
                let (noise, why) = milliego_odometry::offline::imu_noise_of(&s, cfg.imu_noise);
                imu_noise = why;
                if let Some(n) = noise {
                    cfg.classical.rio = cfg.classical.rio.with_imu_noise(n);
                }
                if let Some(t) = s.radar_cfg().map_err(session_err)? {
                    // A session's .cfg only refines defaults (Doppler noise, frame period), so
                    // one that cannot be derived is reported and the defaults stay.
                    match radar_derived(&t) {
                        Ok(d) => apply_cfg(&mut cfg, &d),
                        Err(e) => tracing::warn!(
                            "session {}: radar .cfg not used ({e}); default radar settings",
                            dir.display()
                        ),
                    }
                }
                if let Some(r) = &s.meta.radar {
                    cfg.sync.radar_baud = r.baud;
                }
                if let Some(i) = &s.meta.imu {
                    cfg.sync.imu_baud = i.baud;
                }
                cfg.sync.radar_enabled = s.radar.is_some();
                cfg.sync.imu_enabled = s.imu.is_some();
                // Radar stamps the session cannot vouch for: the filter estimates the offset
                // (the offline runner's rule, `TimeOffsetMode::Auto`).
                if cfg.classical.rio.time_offset_std == 0.0
                    && milliego_odometry::offline::untrusted_radar_timing(&s).is_some()
                {
                    cfg.classical.rio.time_offset_std =
                        milliego_odometry::offline::TimeOffsetMode::DEFAULT_STD_S;
                }
                session = Some(s);
            }
            Input::Devices(d) => {
                if d.radar_data.is_none() && d.imu.is_none() && d.hub.is_none() {
                    return Err(RunError::NoSensor);
                }
                // A configured Xsens names itself once its port is open ([`Plan::name_imu`]).
                let (noise, why) = milliego_odometry::offline::imu_noise_for(
                    cfg.imu_device.as_deref(),
                    cfg.imu_noise,
                    "the live run names no IMU device (--imu-device, or [imu] device in \
                     --config; a configured Xsens names itself)",
                );
                imu_noise = why;
                if let Some(n) = noise {
                    cfg.classical.rio = cfg.classical.rio.with_imu_noise(n);
                }
                cfg.sync.radar_enabled = d.radar_data.is_some() || d.hub.is_some();
                cfg.sync.imu_enabled = d.imu.is_some() || d.hub.is_some();
                cfg.sync.radar_baud = d.radar_baud;
                cfg.sync.imu_baud = d.imu_baud;
                if let Some(p) = &d.radar_cfg {
                    apply_cfg(&mut cfg, &read_radar_cfg(p)?);
                }
            }
        }
        let built = Self::estimators(&cfg)?;
        if built.model_fallback {
            tracing::warn!("learned model unavailable: auto runs Doppler (MODEL_FALLBACK)");
        }
        let sinks = cfg
            .outputs
            .iter()
            .map(|o| Sink::open(o, cfg.tum_predicted).map_err(RunError::from))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Plan {
            cfg,
            session,
            radar_decoding,
            built,
            sinks,
            imu_noise,
        })
    }

    /// The run's estimators for `cfg`.
    fn estimators(cfg: &RunConfig) -> Result<Built, RunError> {
        let model = cfg.model.as_deref().map(|path| ModelSource {
            path,
            threads: cfg.model_threads,
        });
        Ok(build_run_estimators(cfg.estimator, &cfg.classical, model)?)
    }

    /// A live IMU that answered `product` (its product code) while being configured: the filter
    /// takes that part's preset, as from a session's device name, unless the run named the part
    /// or a preset itself (`asked`), which wins (a part that misreports, a board that relabels it).
    fn name_imu(&mut self, asked: &RunConfig, product: &str) -> Result<(), RunError> {
        if asked.imu_noise.is_some() || asked.imu_device.is_some() {
            return Ok(());
        }
        let (noise, why) = milliego_odometry::offline::imu_noise_for(Some(product), None, "");
        self.imu_noise = why;
        if let Some(n) = noise {
            // The plan took no preset for an unnamed part: this one applies to the defaults.
            self.cfg.classical.rio = self.cfg.classical.rio.with_imu_noise(n);
            self.built = Self::estimators(&self.cfg)?;
        }
        Ok(())
    }
}

/// Starts a named pipeline thread.
fn spawn_named<T: Send + 'static>(
    thread: &'static str,
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<std::thread::JoinHandle<T>, RunError> {
    std::thread::Builder::new()
        .name(thread.into())
        .spawn(f)
        .map_err(|error| RunError::Spawn { thread, error })
}

/// Counters the input threads keep for the summary.
#[derive(Debug, Default)]
struct InputCounters {
    radar: Arc<ReaderStats>,
    imu: Arc<ReaderStats>,
    /// Radar frames, IMU samples, barometer readings decoded, and barometer readings dropped
    /// (a later one came before an IMU sample could carry it).
    decoded: Arc<[AtomicU64; 4]>,
}

/// Runs the pipeline until the input ends, `stop` is set, or a limit is reached.
pub fn run(input: &Input, cfg: &RunConfig, stop: Arc<AtomicBool>) -> Result<Summary, RunError> {
    // The plan is checked before a device is touched (a bad model or setting stops the run here);
    // then a live Xsens the run configures names itself, and its product code picks the filter's
    // IMU preset, as a session's device name does.
    let mut plan = Plan::derive(input, cfg)?;
    let mut opened = None;
    if let Input::Devices(d) = input {
        let o = open_devices(d)?;
        if let Some(code) = &o.imu_product {
            plan.name_imu(cfg, code)?;
        }
        opened = Some((d, o));
    }
    let cfg = plan.cfg;
    let imu_noise = plan.imu_noise;
    let [qr, qi, qe, qp] = cfg.queues;
    let offline = plan.session.is_some();
    let sh = Arc::new(Shared {
        radar_q: DropOldest::new(qr),
        imu_q: DropOldest::new(qi),
        ev_q: DropOldest::new(qe),
        pose_q: DropOldest::new(qp),
        pool: Pool::new(qr + 64, qr + 32),
        stop: Arc::clone(&stop),
        offline,
        inputs_done: AtomicBool::new(false),
        sync_done: AtomicBool::new(false),
        stage_done: AtomicBool::new(false),
        sync_dropped: AtomicU64::new(0),
        epoch: Instant::now(),
        last_data_ns: AtomicU64::new(0),
        watermark: AtomicU64::new(f64::NEG_INFINITY.to_bits()),
        view: cfg.view.clone(),
    });
    if let Some(v) = &sh.view {
        v.offer(ViewEvent::Start {
            mounting: cfg.classical.mounting,
            estimator: cfg.estimator.name().into(),
            input: if offline { "session" } else { "devices" }.into(),
            clock: if offline && !cfg.session_online_clock {
                "session fit"
            } else {
                "online"
            }
            .into(),
        });
    }
    let counters = InputCounters::default();
    // The radar plausibility verdicts: the session decoder's report, or the live reader's counters.
    let mut session_radar_report = None;
    let mut input_threads = Vec::new();
    if let Some(s) = plan.session {
        let realtime = matches!(input, Input::Session { realtime: true, .. });
        let pace = realtime.then_some(cfg.session_speed);
        let (t, report) = start_session(&sh, &s, pace, cfg.session_online_clock, &counters)?;
        session_radar_report = Some(report);
        input_threads.push(t);
    } else if let Some((d, OpenDevices { radar, imu, .. })) = opened.take() {
        let backoff = Duration::from_secs_f64(cfg.reopen_backoff_s);
        if let Some(spec) = &d.hub {
            let wrap = if d.imu_wrap_day {
                TimeWrap::Day
            } else {
                TimeWrap::Pow32
            };
            let decoding = plan.radar_decoding;
            input_threads.push(hub::spawn(&sh, spec, decoding, wrap, backoff, &counters)?);
        }
        if let Some((port, src)) = radar {
            input_threads.push(spawn_radar_reader(
                &sh,
                port,
                src,
                plan.radar_decoding,
                backoff,
                &counters,
            )?);
        }
        if let Some((port, src)) = imu {
            let wrap = if d.imu_wrap_day {
                TimeWrap::Day
            } else {
                TimeWrap::Pow32
            };
            input_threads.push(spawn_imu_reader(&sh, port, src, wrap, backoff, &counters)?);
        }
    }
    let sync_cfg = SyncConfig {
        preview_imu: cfg.imu_rate_output,
        ..cfg.sync
    };
    let sync_thread = spawn_sync(&sh, sync_cfg, cfg.session_online_clock)?;
    let stage_cfg = StageConfig {
        imu_rate_output: cfg.imu_rate_output,
        mounting: cfg.classical.mounting,
    };
    let stage_thread = spawn_stage(&sh, stage_cfg, plan.built)?;
    let out_thread = spawn_output(&sh, plan.sinks)?;

    let started = Instant::now();
    supervise(&sh, &cfg, &stop, input_threads, started, &counters);
    sh.inputs_done.store(true, Ordering::Release);
    let (h_sync, sync_counters, clocks) = sync_thread
        .join()
        .map_err(|_| RunError::Panicked { thread: "sync" })?;
    let (h_est, stage_counters, stage_ends, mut view_handoff) = stage_thread
        .join()
        .map_err(|_| RunError::Panicked { thread: "estimate" })?;
    let out = out_thread
        .join()
        .map_err(|_| RunError::Panicked { thread: "output" })?;
    let wall_s = started.elapsed().as_secs_f64();
    view_handoff.merge(&out.view_handoff);
    let latency = Latencies {
        sync: h_sync,
        estimate: h_est,
        output: out.output.clone(),
        end_to_end: out.end_to_end.clone(),
        imu_to_pose: out.imu_to_pose.clone(),
        view_handoff,
    };
    let ends = RunEnds {
        estimator: cfg.estimator,
        offline,
        wall_s,
        sync: sync_counters,
        clocks,
        stage: stage_counters,
        radar_time_offset: stage_ends.radar_time_offset,
        doppler_step: stage_ends.doppler_step,
        learned: stage_ends.learned,
        filter: stage_ends.filter,
        imu_noise: &imu_noise,
        out: &out,
        radar_report: session_radar_report.as_ref(),
    };
    let report = run_summary(&ends, &sh, &counters, &latency);
    Ok(Summary {
        report,
        latency,
        poses_sent: u64::from(out.sent),
        radar_poses: out.radar_poses,
        dropped_total: sh.dropped(),
        wall_s,
    })
}

/// Decodes the session with the drivers' streaming decoders and starts the feeder thread, which
/// pushes the decoded streams on the session clock.
fn start_session(
    sh: &Arc<Shared>,
    s: &milliego_session::Session,
    realtime: Option<f64>,
    online_clock: bool,
    counters: &InputCounters,
) -> Result<(std::thread::JoinHandle<()>, StreamReport), RunError> {
    let session_err = |error| RunError::Session {
        dir: s.dir.clone(),
        error,
    };
    let (frames, radar_rep) = milliego_session::streams::radar_frames(s).map_err(session_err)?;
    let (imu, baro, _) = milliego_session::streams::imu_and_pressure(s).map_err(session_err)?;
    if imu.is_empty() && frames.is_empty() {
        return Err(RunError::EmptySession { dir: s.dir.clone() });
    }
    let clock =
        milliego_session::streams::SessionClock::fit(s, &frames, &imu).map_err(session_err)?;
    let sh2 = Arc::clone(sh);
    let dec = Arc::clone(&counters.decoded);
    let t = spawn_named("feeder", move || {
        let streams = SessionStreams {
            frames: &frames,
            imu: &imu,
            baro: &baro,
        };
        feed_session(&sh2, &streams, &clock, realtime, online_clock, &dec);
    })?;
    Ok((t, radar_rep))
}

/// An open port and how to reopen it.
type OpenPort = (Box<dyn Read + Send>, SerialSource);

/// The live ports, open.
struct OpenDevices {
    radar: Option<OpenPort>,
    imu: Option<OpenPort>,
    /// The IMU's product code (`ReqProductCode`), asked while configuring it.
    imu_product: Option<String>,
}

/// Opens (and, with `configure`, configures) the devices before any thread starts: a missing
/// device stops the run here. A configured IMU is asked its product code on the way.
fn open_devices(d: &Devices) -> Result<OpenDevices, RunError> {
    let mut radar_port = None;
    if let Some(p) = &d.radar_data {
        if d.configure {
            if let (Some(cli), Some(cfgp)) = (&d.radar_cli, &d.radar_cfg) {
                let text =
                    std::fs::read_to_string(cfgp).map_err(|error| RunError::RadarCfgRead {
                        path: cfgp.clone(),
                        error,
                    })?;
                let port =
                    radar_driver::host::cli_port::open_serial(cli, 115_200).map_err(|e| {
                        RunError::Port {
                            role: PortRole::RadarCli,
                            path: cli.clone(),
                            error: e.into(),
                        }
                    })?;
                let mut c = radar_driver::host::CliPort::new(port, Duration::from_secs(2));
                c.upload(&text).map_err(|error| RunError::RadarUpload {
                    port: cli.clone(),
                    error,
                })?;
            }
        }
        let mut src = SerialSource {
            path: p.clone(),
            baud: d.radar_baud,
        };
        let port = src.open().map_err(|error| RunError::Port {
            role: PortRole::RadarData,
            path: p.clone(),
            error,
        })?;
        radar_port = Some((port, src));
    }
    let mut imu_port = None;
    let mut imu_product = None;
    if let Some(p) = &d.imu {
        let mut src = SerialSource {
            path: p.clone(),
            baud: d.imu_baud,
        };
        let port: Box<dyn Read + Send> = if d.configure {
            let imu_err = |error| RunError::Imu {
                port: p.clone(),
                error,
            };
            let mut dev = imu_driver::host::Device::open(p, d.imu_baud).map_err(imu_err)?;
            dev.go_to_config().map_err(imu_err)?;
            let code = dev.product_code().map_err(imu_err)?;
            let code = code.trim_matches(|c: char| c == '\0' || c.is_whitespace());
            tracing::info!("IMU on {p}: product code {code:?}");
            imu_product = Some(code.to_string());
            dev.go_to_measurement().map_err(imu_err)?;
            Box::new(dev.into_reader().into_inner())
        } else {
            src.open().map_err(|error| RunError::Port {
                role: PortRole::Imu,
                path: p.clone(),
                error,
            })?
        };
        imu_port = Some((port, src));
    }
    Ok(OpenDevices {
        radar: radar_port,
        imu: imu_port,
        imu_product,
    })
}

fn reader_ctx(sh: &Shared, stats: &Arc<ReaderStats>, backoff: Duration) -> ReaderCtx {
    ReaderCtx {
        epoch: sh.epoch,
        stop: Arc::clone(&sh.stop),
        stats: Arc::clone(stats),
        backoff,
        max_backoff: Duration::from_secs(1),
    }
}

/// The radar reader thread: port -> [`RadarDecoder`] -> radar queue (drop-oldest).
fn spawn_radar_reader(
    sh: &Arc<Shared>,
    port: Box<dyn Read + Send>,
    mut src: SerialSource,
    decoding: DecoderConfig,
    backoff: Duration,
    counters: &InputCounters,
) -> Result<std::thread::JoinHandle<()>, RunError> {
    let sh2 = Arc::clone(sh);
    let ctx = reader_ctx(sh, &counters.radar, backoff);
    let dec = Arc::clone(&counters.decoded);
    let stats = Arc::clone(&counters.radar);
    spawn_named("radar", move || {
        let mut decoder = RadarDecoder::new(decoding);
        let mut sink = radar_sink(&sh2.radar_q, &sh2.pool);
        read_loop(&mut src, Some(port), &ctx, |b, host_s, ns, reopened| {
            if reopened {
                decoder.resync(&mut sink);
            }
            sh2.last_data_ns.store(ns, Ordering::Relaxed);
            decoder.feed(b, host_s, ns, &mut sink);
            decoder.publish(&stats);
            dec[0].store(decoder.frames(), Ordering::Relaxed);
        });
    })
}

/// The IMU reader thread: port -> [`ImuDecoder`] -> IMU queue (drop-oldest).
fn spawn_imu_reader(
    sh: &Arc<Shared>,
    port: Box<dyn Read + Send>,
    mut src: SerialSource,
    wrap: TimeWrap,
    backoff: Duration,
    counters: &InputCounters,
) -> Result<std::thread::JoinHandle<()>, RunError> {
    let sh2 = Arc::clone(sh);
    let ctx = reader_ctx(sh, &counters.imu, backoff);
    let dec = Arc::clone(&counters.decoded);
    spawn_named("imu", move || {
        let mut decoder = ImuDecoder::new(wrap);
        read_loop(&mut src, Some(port), &ctx, |b, host_s, ns, reopened| {
            if reopened {
                decoder.resync();
            }
            sh2.last_data_ns.store(ns, Ordering::Relaxed);
            decoder.feed(b, host_s, ns, |it| {
                sh2.imu_q.push(it);
            });
            dec[1].store(decoder.samples(), Ordering::Relaxed);
            dec[2].store(decoder.pressure(), Ordering::Relaxed);
            dec[3].store(decoder.pressure_dropped(), Ordering::Relaxed);
        });
    })
}

/// What the synchroniser thread hands back: its latency, counters and clock maps (JSON).
type SyncEnd = (Histogram, SyncCounters, Clocks);

/// The synchroniser thread: both queues -> time-ordered events. Live, events are released on the
/// host clock and a full event queue drops its oldest; offline, on the feeder's watermark, and
/// nothing is dropped.
fn spawn_sync(
    sh: &Arc<Shared>,
    sync_cfg: SyncConfig,
    session_online_clock: bool,
) -> Result<std::thread::JoinHandle<SyncEnd>, RunError> {
    let sh2 = Arc::clone(sh);
    spawn_named("sync", move || {
        let offline = sh2.offline;
        let mut sync = Synchroniser::new(sync_cfg);
        sync.offline_clock = offline && !session_online_clock;
        sync.data_time = offline;
        let mut hist = Histogram::default();
        // Offline: the feeder's order, rebuilt item by item (see `FeedOrder`; live, unused).
        let held = |capacity: usize| if offline { capacity } else { 0 };
        let mut feed = FeedOrder::new(held(sh2.imu_q.capacity()), held(sh2.radar_q.capacity()));
        loop {
            let done = sh2.inputs_done.load(Ordering::Acquire);
            let watermark = f64::from_bits(sh2.watermark.load(Ordering::Acquire));
            let mut any = false;
            // IMU first: a radar frame pushed before these samples is then visible below.
            // Bounded batches: a fast producer must not keep one drain going while the other
            // queue fills.
            for _ in 0..sh2.imu_q.len() {
                let Some(s) = sh2.imu_q.pop() else { break };
                if offline {
                    feed.push_imu(s);
                } else {
                    sync.push_imu(s);
                }
                any = true;
            }
            for _ in 0..sh2.radar_q.len() {
                let Some(r) = sh2.radar_q.pop() else { break };
                if offline {
                    feed.push_radar(r);
                } else {
                    sync.push_radar(r, |b| sh2.pool.give(b));
                }
                any = true;
            }
            let finished = done && sh2.imu_q.is_empty() && sh2.radar_q.is_empty();
            let mut emit = |ev: SyncOut| {
                let read_ns = match &ev {
                    SyncOut::Imu { read_ns, .. } => Some(*read_ns),
                    SyncOut::Radar { item, .. } => Some(item.read_ns),
                    SyncOut::Preview { .. } | SyncOut::Tick { .. } => None,
                };
                if let Some(r) = read_ns {
                    hist.record(sh2.now_ns().saturating_sub(r));
                }
                if offline {
                    sh2.ev_q.push_wait(ev);
                } else if let Some(old) = sh2.ev_q.push(ev) {
                    recycle(&sh2, old);
                }
            };
            if offline {
                // Once the feeder is done, everything it fed has been taken.
                let upto = if finished { f64::INFINITY } else { watermark };
                feed.release(upto, &mut sync, |b| sh2.pool.give(b), &mut emit);
            } else {
                sync.poll(sh2.epoch.elapsed().as_secs_f64(), &mut emit);
            }
            if finished && feed.is_empty() {
                sync.flush(|ev| sh2.ev_q.push_wait(ev));
                break;
            }
            sh2.sync_dropped
                .store(sync.counters.dropped, Ordering::Relaxed);
            if !any {
                std::thread::sleep(Duration::from_micros(200));
            }
        }
        sh2.sync_dropped
            .store(sync.counters.dropped, Ordering::Relaxed);
        sh2.sync_done.store(true, Ordering::Release);
        let clock = |c: &crate::sync::OnlineClock| {
            c.map().map(|(offset_s, rate)| ClockSummary {
                offset_s,
                rate,
                accepted: c.accepted,
                rejected_late: c.rejected_late,
            })
        };
        let clocks = Clocks {
            radar: clock(&sync.radar_clock),
            imu: clock(&sync.imu_clock),
            offline_fit: offline,
        };
        (hist, sync.counters, clocks)
    })
}

/// What the estimator stage hands back: its latency histogram, its counters, the radar time
/// offset its estimators estimated (estimate, deviation \[s\]) and its view hand-off times.
type StageEnd = (Histogram, StageCounters, StageEnds, Histogram);

/// The estimator thread: events -> poses (live, a full pose queue drops its oldest).
fn spawn_stage(
    sh: &Arc<Shared>,
    stage_cfg: StageConfig,
    built: Built,
) -> Result<std::thread::JoinHandle<StageEnd>, RunError> {
    let sh2 = Arc::clone(sh);
    spawn_named("estimate", move || {
        let mut stage = Stage::new(stage_cfg, built);
        let mut hist = Histogram::default();
        let mut handoff = Histogram::default();
        loop {
            let done = sh2.sync_done.load(Ordering::Acquire);
            let Some(ev) = sh2.ev_q.pop() else {
                if done && sh2.ev_q.is_empty() {
                    break;
                }
                std::thread::sleep(Duration::from_micros(200));
                continue;
            };
            let t0 = sh2.now_ns();
            // The view's copy of an IMU sample is offered after the event was processed.
            let imu = match (&sh2.view, &ev) {
                (Some(_), SyncOut::Imu { input, .. }) => Some((input.t, input.accel, input.gyro)),
                _ => None,
            };
            stage.process(
                ev,
                t0,
                |p| {
                    if sh2.offline {
                        sh2.pose_q.push_wait(p);
                    } else {
                        sh2.pose_q.push(p);
                    }
                },
                |b| {
                    // The frame's pose (if any) is queued by now: the view's copy costs the
                    // pose path nothing.
                    if let Some(v) = &sh2.view {
                        let h0 = sh2.now_ns();
                        v.offer(ViewEvent::Radar {
                            t: b.t.unwrap_or(b.host_s),
                            frame_number: b.frame_number,
                            points: b.points.clone(),
                            snr_db: b.snr_db.clone(),
                        });
                        handoff.record(sh2.now_ns().saturating_sub(h0));
                    }
                    sh2.pool.give(b)
                },
            );
            hist.record(sh2.now_ns().saturating_sub(t0));
            if let (Some(v), Some((t, accel, gyro))) = (&sh2.view, imu) {
                let h0 = sh2.now_ns();
                v.offer(ViewEvent::Imu { t, accel, gyro });
                handoff.record(sh2.now_ns().saturating_sub(h0));
            }
        }
        sh2.stage_done.store(true, Ordering::Release);
        let ends = StageEnds {
            radar_time_offset: stage.radar_time_offset(),
            doppler_step: stage.doppler_step(),
            learned: stage.learned(),
            filter: stage.filter(),
        };
        (hist, stage.counters, ends, handoff)
    })
}

/// What the output thread hands back.
#[derive(Debug, Default)]
struct OutputEnd {
    /// Estimator stage -> sent.
    output: Histogram,
    /// Radar-rate poses: sensor byte read -> sent.
    end_to_end: Histogram,
    /// Predicted poses: IMU sample read -> sent.
    imu_to_pose: Histogram,
    /// Poses sent (the next sequence number).
    sent: u32,
    send_errors: u64,
    radar_poses: u64,
    /// Handing poses to the live view.
    view_handoff: Histogram,
}

/// The output thread: poses -> sequence number, drop flags, host time -> every sink.
fn spawn_output(
    sh: &Arc<Shared>,
    mut sinks: Vec<Sink>,
) -> Result<std::thread::JoinHandle<OutputEnd>, RunError> {
    let sh2 = Arc::clone(sh);
    spawn_named("output", move || {
        let mut enc = Encoded::default();
        let mut end = OutputEnd::default();
        let mut last_dropped = 0u64;
        loop {
            let done = sh2.stage_done.load(Ordering::Acquire);
            let Some(mut p) = sh2.pose_q.pop() else {
                if done && sh2.pose_q.is_empty() {
                    break;
                }
                std::thread::sleep(Duration::from_micros(100));
                continue;
            };
            let dropped = sh2.dropped();
            if dropped > last_dropped {
                p.msg.health |= Health::FRAMES_DROPPED;
            }
            last_dropped = dropped;
            p.msg.seq = end.sent;
            end.sent = end.sent.wrapping_add(1);
            p.msg.dropped_total = dropped.min(u64::from(u32::MAX)) as u32;
            p.msg.host_time_ns = sh2.now_ns();
            enc.encode(&p.msg);
            for s in sinks.iter_mut() {
                if let Err(e) = s.send(&p.msg, p.t, &enc.bytes, &enc.serial[..enc.serial_len]) {
                    end.send_errors += 1;
                    if end.send_errors < 10 {
                        tracing::warn!(error = %e, "output failed");
                    }
                }
            }
            let sent = sh2.now_ns();
            end.output.record(sent.saturating_sub(p.emitted_ns));
            if p.msg.health.contains(Health::PREDICTED) {
                end.imu_to_pose.record(sent.saturating_sub(p.read_ns));
            } else {
                end.radar_poses += 1;
                end.end_to_end.record(sent.saturating_sub(p.read_ns));
            }
            // Sent and timed: the view's copy comes after.
            if let Some(v) = &sh2.view {
                let h0 = sh2.now_ns();
                v.offer(ViewEvent::Pose { t: p.t, msg: p.msg });
                end.view_handoff.record(sh2.now_ns().saturating_sub(h0));
            }
        }
        for s in sinks.iter_mut() {
            let _ = s.flush();
        }
        end
    })
}

/// Waits for the inputs to end, stopping them on `stop`, the duration limit or idle exit.
fn supervise(
    sh: &Shared,
    cfg: &RunConfig,
    stop: &AtomicBool,
    input_threads: Vec<std::thread::JoinHandle<()>>,
    started: Instant,
    counters: &InputCounters,
) {
    let mut last_status = Instant::now();
    while !input_threads.iter().all(|t| t.is_finished()) {
        if let Some(v) = &sh.view {
            if last_status.elapsed() >= Duration::from_millis(100) {
                last_status = Instant::now();
                v.offer(ViewEvent::Status(view_status(sh, counters, v)));
            }
        }
        let el = started.elapsed().as_secs_f64();
        let idle = cfg.idle_exit_s.is_some_and(|s| {
            let last = sh.last_data_ns.load(Ordering::Relaxed);
            last > 0 && sh.now_ns().saturating_sub(last) as f64 * 1e-9 > s
        });
        if stop.load(Ordering::Relaxed) || cfg.duration_s.is_some_and(|d| el > d) || idle {
            stop.store(true, Ordering::Relaxed);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    for t in input_threads {
        let _ = t.join();
    }
    if let Some(v) = &sh.view {
        v.offer(ViewEvent::Status(view_status(sh, counters, v)));
    }
}

/// The counters the live view shows.
fn view_status(sh: &Shared, c: &InputCounters, v: &ViewTap) -> ViewStatus {
    ViewStatus {
        radar_in: c.decoded[0].load(Ordering::Relaxed),
        imu_in: c.decoded[1].load(Ordering::Relaxed),
        queue_drops: [
            sh.radar_q.dropped(),
            sh.imu_q.dropped(),
            sh.ev_q.dropped(),
            sh.pose_q.dropped(),
            sh.sync_dropped.load(Ordering::Relaxed),
        ],
        view_dropped: v.dropped(),
    }
}

/// What the estimator stage knows at the end of a run beyond its counters.
struct StageEnds {
    radar_time_offset: Option<(f64, f64)>,
    doppler_step: Option<(f32, Option<f32>)>,
    learned: Option<crate::summary::LearnedSummary>,
    filter: Option<crate::summary::FilterSummary>,
}

/// What the stages reported at the end of a run.
struct RunEnds<'a> {
    estimator: EstimatorKind,
    offline: bool,
    wall_s: f64,
    sync: SyncCounters,
    clocks: Clocks,
    stage: StageCounters,
    radar_time_offset: Option<(f64, f64)>,
    doppler_step: Option<(f32, Option<f32>)>,
    learned: Option<crate::summary::LearnedSummary>,
    filter: Option<crate::summary::FilterSummary>,
    imu_noise: &'a str,
    out: &'a OutputEnd,
    radar_report: Option<&'a StreamReport>,
}

/// The radar plausibility verdicts: the session decoder's report, or the live reader's counters.
fn plausibility(report: Option<&StreamReport>, live: &ReaderStats) -> Plausibility {
    let load = |c: &AtomicU64| c.load(Ordering::Relaxed);
    match report {
        Some(r) => Plausibility::new(&r.implausible, r.reanchored, r.retracted, r.held),
        None => Plausibility::new(
            &live.implausible.each_ref().map(load),
            load(&live.reanchored),
            load(&live.retracted),
            load(&live.held),
        ),
    }
}

/// The run summary, as printed and written with `--summary-json`.
fn run_summary(e: &RunEnds<'_>, sh: &Shared, c: &InputCounters, latency: &Latencies) -> RunSummary {
    let load = |a: &AtomicU64| a.load(Ordering::Relaxed);
    let radar_in = load(&c.decoded[0]);
    let (sc, st) = (&e.sync, &e.stage);
    RunSummary {
        estimator: e.estimator.name().into(),
        input: if e.offline { "session" } else { "devices" }.into(),
        wall_s: e.wall_s,
        frames_in: FramesIn {
            radar: radar_in,
            imu: load(&c.decoded[1]),
            pressure: load(&c.decoded[2]),
        },
        barometer: if load(&c.decoded[2]) == 0 {
            "none: height from the radar and the IMU only".into()
        } else if matches!(
            e.estimator,
            EstimatorKind::Doppler | EstimatorKind::Fused | EstimatorKind::Auto
        ) {
            format!("{} readings aid the height", load(&c.decoded[2]))
        } else {
            format!(
                "{} readings, not used by this estimator",
                load(&c.decoded[2])
            )
        },
        radar_time_offset: match e.radar_time_offset {
            Some((o, sd)) => format!(
                "estimated: radar frames taken {:.1} ms after their stamps (+- {:.1} ms)",
                o * 1e3,
                sd * 1e3
            ),
            None => "not estimated: the radar stamps are trusted".into(),
        },
        doppler_step: match e.doppler_step {
            None => "not used by this estimator".into(),
            Some((configured, Some(seen))) => format!(
                "{seen:.4} m/s, read from the points' radial velocities (configured {configured:.4} m/s)"
            ),
            Some((configured, None)) => format!(
                "{configured:.4} m/s, configured (the points showed no step of their own)"
            ),
        },
        frames_out: FramesOut {
            poses_sent: u64::from(e.out.sent),
            radar_rate: e.out.radar_poses,
            predicted: st.predicted_poses,
            no_pose: st.no_pose,
            resets: st.resets,
            handovers: st.handovers,
            estimator_errors: st.errors,
            send_errors: e.out.send_errors,
        },
        drops: Drops {
            radar_queue: sh.radar_q.dropped(),
            imu_queue: sh.imu_q.dropped(),
            sync_buffers: sc.dropped,
            event_queue: sh.ev_q.dropped(),
            pose_queue: sh.pose_q.dropped(),
            pressure: load(&c.decoded[3]),
            total: sh.dropped() + load(&c.decoded[3]),
        },
        sync: SyncSummary {
            radar_released: sc.radar,
            imu_released: sc.imu,
            radar_late: sc.radar_late,
            radar_gaps: sc.radar_gaps,
            warmup_held: sc.warmup,
            imu_gaps: sc.imu_gaps,
            clocks: e.clocks,
        },
        ports: Ports {
            radar_reopens: load(&c.radar.reopens),
            imu_reopens: load(&c.imu.reopens),
            radar_bytes: load(&c.radar.bytes),
            imu_bytes: load(&c.imu.bytes),
        },
        latency: LatencySummary {
            sync: latency.sync.summary(),
            estimate: latency.estimate.summary(),
            output: latency.output.summary(),
            end_to_end: latency.end_to_end.summary(),
            imu_to_pose: latency.imu_to_pose.summary(),
            view_handoff: latency.view_handoff.summary(),
        },
        radar_plausibility: plausibility(e.radar_report, &c.radar),
        per_radar_frame_us: if radar_in > 0 {
            e.wall_s * 1e6 / radar_in as f64
        } else {
            0.0
        },
        view_dropped: sh.view.as_ref().map_or(0, ViewTap::dropped),
        view_client_dropped: 0,
        learned: e.learned.clone(),
        filter: e.filter,
        imu_noise: e.imu_noise.into(),
    }
}

/// Feeds a session's decoded streams in the offline runner's order (each radar frame before the
/// first IMU sample at or after its time), waiting when a queue is full (nothing is dropped).
/// A session's decoded streams.
struct SessionStreams<'a> {
    frames: &'a [milliego_session::streams::RadarFrame],
    imu: &'a [milliego_session::streams::ImuSample],
    baro: &'a [milliego_session::streams::PressureSample],
}

fn feed_session(
    sh: &Shared,
    streams: &SessionStreams<'_>,
    clock: &milliego_session::streams::SessionClock,
    realtime: Option<f64>,
    online_clock: bool,
    decoded: &[AtomicU64; 4],
) {
    let SessionStreams { frames, imu, baro } = *streams;
    let mut radar: Vec<(f64, usize)> = frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| Some((clock.radar_s(f)?, i)))
        .collect();
    radar.sort_by(|a, b| a.0.total_cmp(&b.0));
    let t_first = imu
        .first()
        .map(|s| clock.imu_s(s.sensor_s))
        .into_iter()
        .chain(radar.first().map(|r| r.0))
        .fold(f64::INFINITY, f64::min);
    let start = Instant::now();
    let pace = |t: f64| {
        if let Some(speed) = realtime {
            let speed = if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            };
            let due = Duration::from_secs_f64((t - t_first).max(0.0) / speed);
            let el = start.elapsed();
            if due > el {
                std::thread::sleep(due - el);
            }
        }
    };
    let push_radar = |tr: f64, i: usize| {
        let f = &frames[i];
        let mut it = sh.pool.take();
        it.host_s = f.host_s.unwrap_or(tr);
        it.read_ns = sh.now_ns();
        it.set_frame(f.sensor_s, f.frame_number, f.bytes, &f.cloud);
        it.t = (!online_clock).then_some(tr);
        it.fed_s = Some(tr);
        sh.radar_q.push_wait(it);
        decoded[0].fetch_add(1, Ordering::Relaxed);
        sh.watermark.store(tr.to_bits(), Ordering::Release);
    };
    let mut next = 0;
    let mut next_baro = 0;
    for s in imu {
        if sh.stop.load(Ordering::Relaxed) {
            return;
        }
        let t = clock.imu_s(s.sensor_s);
        // The barometer readings due at or before this sample: the latest rides with it (as the
        // live reader does), earlier ones are counted as dropped.
        let mut pressure = None;
        while next_baro < baro.len() && clock.imu_s(baro[next_baro].sensor_s) <= t {
            let b = &baro[next_baro];
            next_baro += 1;
            decoded[2].fetch_add(1, Ordering::Relaxed);
            if pressure.replace((b.sensor_s, b.pa)).is_some() {
                decoded[3].fetch_add(1, Ordering::Relaxed);
            }
        }
        while next < radar.len() && radar[next].0 <= t {
            pace(radar[next].0);
            push_radar(radar[next].0, radar[next].1);
            next += 1;
        }
        pace(t);
        let it = ImuItem {
            host_s: s.host_s.unwrap_or(t),
            read_ns: sh.now_ns(),
            sensor_s: s.sensor_s,
            accel: s.accel,
            gyro: s.gyro,
            bytes: s.bytes,
            t: (!online_clock).then_some(t),
            fed_s: Some(t),
            pressure,
        };
        sh.imu_q.push_wait(it);
        decoded[1].fetch_add(1, Ordering::Relaxed);
        sh.watermark.store(t.to_bits(), Ordering::Release);
    }
    for &(tr, i) in &radar[next..] {
        pace(tr);
        push_radar(tr, i);
    }
}
