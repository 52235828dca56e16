//! The threads and their wiring: readers (or the offline feeder) -> synchroniser -> estimator
//! stage -> output, joined by [`DropOldest`] queues; the summary at the end.

use crate::estimator::{build_run_estimators, ClassicalConfig, EstimatorKind};
use crate::output::{Encoded, OutputSpec, Sink};
use crate::queue::{DropOldest, Pool};
use crate::reader::{
    radar_sink, read_loop, ImuDecoder, ImuItem, RadarDecoder, RadarItem, ReaderCtx, ReaderStats,
    SerialSource, Source,
};
use crate::stage::{PoseOut, Stage, StageConfig};
use crate::stats::Histogram;
use crate::sync::{SyncConfig, SyncOut, Synchroniser};
use imu_driver::TimeWrap;
use pose_link::Health;
use radar_driver::host::DecoderConfig;
use serde_json::json;
use std::io::Read;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

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
}

/// Settings of a run.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Estimator.
    pub estimator: EstimatorKind,
    /// Learned-model file.
    pub model: Option<PathBuf>,
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
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            estimator: EstimatorKind::Auto,
            model: None,
            outputs: Vec::new(),
            imu_rate_output: false,
            tum_predicted: false,
            classical: ClassicalConfig::default(),
            sync: SyncConfig::default(),
            queues: [32, 512, 1024, 1024],
            duration_s: None,
            idle_exit_s: None,
            reopen_backoff_s: 0.05,
            session_online_clock: false,
        }
    }
}

/// Why a run could not start.
#[derive(Debug)]
pub struct RunError(pub String);

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RunError {}

fn err(s: impl Into<String>) -> RunError {
    RunError(s.into())
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
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Everything, as printed and written with `--summary-json`.
    pub json: serde_json::Value,
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
    inputs_done: AtomicBool,
    sync_done: AtomicBool,
    stage_done: AtomicBool,
    sync_dropped: AtomicU64,
    epoch: Instant,
    last_data_ns: AtomicU64,
    /// Sessions: common-clock time up to which the feeder has pushed everything (f64 bits).
    watermark: AtomicU64,
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

fn radar_derived(text: &str) -> Result<radar_driver::cfg::Derived, String> {
    radar_driver::cfg::RadarConfig::parse(text)
        .map_err(|e| format!("{e}"))?
        .derive(None)
        .map_err(|e| format!("{e}"))
}

/// Runs the pipeline until the input ends, `stop` is set, or a limit is reached.
pub fn run(input: &Input, cfg: &RunConfig, stop: Arc<AtomicBool>) -> Result<Summary, RunError> {
    let mut cfg = cfg.clone();
    // Everything that can fail at start-up fails here, with one message.
    let mut sinks = Vec::new();
    let mut session = None;
    // What the radar .cfg tells the live decoder (Doppler scale, frame period, plausibility).
    let mut radar_decoding = DecoderConfig::default();
    match input {
        Input::Session { dir, .. } => {
            let s = milliego_session::Session::open(dir)
                .map_err(|e| err(format!("session {}: {e}", dir.display())))?;
            cfg.classical.mounting = crate::estimator::Mounting::from_session(&s.meta.extrinsics);
            if let Some(d) = s
                .radar_cfg()
                .map_err(|e| err(e.to_string()))?
                .and_then(|t| radar_derived(&t).ok())
            {
                cfg.classical.ego.sigma = d.velocity_resolution_mps as f32 / 2.0;
                cfg.sync.radar_period_s = Some(d.frame_period_ms / 1e3);
                cfg.sync.half_chirps_s = d.active_frame_time_ms / 2e3;
            }
            if let Some(r) = &s.meta.radar {
                cfg.sync.radar_baud = r.baud;
            }
            if let Some(i) = &s.meta.imu {
                cfg.sync.imu_baud = i.baud;
            }
            cfg.sync.radar_enabled = s.radar.is_some();
            cfg.sync.imu_enabled = s.imu.is_some();
            session = Some(s);
        }
        Input::Devices(d) => {
            if d.radar_data.is_none() && d.imu.is_none() {
                return Err(err("no sensor given: --radar-data and/or --imu"));
            }
            cfg.sync.radar_enabled = d.radar_data.is_some();
            cfg.sync.imu_enabled = d.imu.is_some();
            cfg.sync.radar_baud = d.radar_baud;
            cfg.sync.imu_baud = d.imu_baud;
            if let Some(p) = &d.radar_cfg {
                let text = std::fs::read_to_string(p)
                    .map_err(|e| err(format!("radar .cfg {}: {e}", p.display())))?;
                let dv = radar_derived(&text)
                    .map_err(|e| err(format!("radar .cfg {}: {e}", p.display())))?;
                cfg.classical.ego.sigma = dv.velocity_resolution_mps as f32 / 2.0;
                cfg.sync.radar_period_s = Some(dv.frame_period_ms / 1e3);
                cfg.sync.half_chirps_s = dv.active_frame_time_ms / 2e3;
                radar_decoding = DecoderConfig::from_derived(Some(&dv));
            }
        }
    }
    let built = build_run_estimators(cfg.estimator, &cfg.classical, cfg.model.as_deref())
        .map_err(|e| err(e.to_string()))?;
    if built.model_fallback {
        tracing::warn!("learned model unavailable: auto runs Doppler (MODEL_FALLBACK)");
    }
    for o in &cfg.outputs {
        sinks.push(Sink::open(o, cfg.tum_predicted).map_err(err)?);
    }

    let [qr, qi, qe, qp] = cfg.queues;
    let sh = Arc::new(Shared {
        radar_q: DropOldest::new(qr),
        imu_q: DropOldest::new(qi),
        ev_q: DropOldest::new(qe),
        pose_q: DropOldest::new(qp),
        pool: Pool::new(qr + 64, qr + 32),
        stop: Arc::clone(&stop),
        inputs_done: AtomicBool::new(false),
        sync_done: AtomicBool::new(false),
        stage_done: AtomicBool::new(false),
        sync_dropped: AtomicU64::new(0),
        epoch: Instant::now(),
        last_data_ns: AtomicU64::new(0),
        watermark: AtomicU64::new(f64::NEG_INFINITY.to_bits()),
    });
    let offline = session.is_some();

    // Inputs.
    let mut input_threads = Vec::new();
    let radar_stats = Arc::new(ReaderStats::default());
    let imu_stats = Arc::new(ReaderStats::default());
    let decoded = Arc::new([AtomicU64::new(0), AtomicU64::new(0)]);
    // The radar plausibility verdicts: the session decoder's report, or the live reader's counters.
    let mut session_radar_report = None;
    if let Some(s) = session {
        let realtime = matches!(input, Input::Session { realtime: true, .. });
        let sh2 = Arc::clone(&sh);
        let dec = Arc::clone(&decoded);
        let (frames, radar_rep) =
            milliego_session::streams::radar_frames(&s).map_err(|e| err(e.to_string()))?;
        session_radar_report = Some(radar_rep);
        let (imu, _) =
            milliego_session::streams::imu_samples(&s).map_err(|e| err(e.to_string()))?;
        if imu.is_empty() && frames.is_empty() {
            return Err(err("the session has neither radar frames nor IMU samples"));
        }
        let clock = milliego_session::streams::SessionClock::fit(&s, &frames, &imu)
            .map_err(|e| err(e.to_string()))?;
        let online_clock = cfg.session_online_clock;
        input_threads.push(
            std::thread::Builder::new()
                .name("feeder".into())
                .spawn(move || {
                    feed_session(&sh2, &frames, &imu, &clock, realtime, online_clock, &dec);
                })
                .map_err(|e| err(e.to_string()))?,
        );
    } else if let Input::Devices(d) = input {
        // Open (and configure) everything before any thread starts: a missing device stops here.
        let mut radar_port = None;
        if let Some(p) = &d.radar_data {
            if d.configure {
                if let (Some(cli), Some(cfgp)) = (&d.radar_cli, &d.radar_cfg) {
                    let text = std::fs::read_to_string(cfgp)
                        .map_err(|e| err(format!("radar .cfg {}: {e}", cfgp.display())))?;
                    let port = radar_driver::host::cli_port::open_serial(cli, 115_200)
                        .map_err(|e| err(format!("radar CLI port {cli}: {e}")))?;
                    let mut c = radar_driver::host::CliPort::new(port, Duration::from_secs(2));
                    c.upload(&text)
                        .map_err(|e| err(format!("radar configuration over {cli}: {e}")))?;
                }
            }
            let mut src = SerialSource {
                path: p.clone(),
                baud: d.radar_baud,
            };
            radar_port = Some((
                src.open()
                    .map_err(|e| err(format!("radar data port {p}: {e}")))?,
                src,
            ));
        }
        let mut imu_port = None;
        if let Some(p) = &d.imu {
            let mut src = SerialSource {
                path: p.clone(),
                baud: d.imu_baud,
            };
            let port: Box<dyn Read + Send> = if d.configure {
                let mut dev = imu_driver::host::Device::open(p, d.imu_baud)
                    .map_err(|e| err(format!("IMU port {p}: {e}")))?;
                dev.go_to_measurement()
                    .map_err(|e| err(format!("IMU {p}: going to measurement: {e}")))?;
                Box::new(dev.into_reader().into_inner())
            } else {
                src.open().map_err(|e| err(format!("IMU port {p}: {e}")))?
            };
            imu_port = Some((port, src));
        }
        let backoff = Duration::from_secs_f64(cfg.reopen_backoff_s);
        if let Some((port, mut src)) = radar_port {
            let sh2 = Arc::clone(&sh);
            let ctx = ReaderCtx {
                epoch: sh.epoch,
                stop: Arc::clone(&stop),
                stats: Arc::clone(&radar_stats),
                backoff,
                max_backoff: Duration::from_secs(1),
            };
            let dec = Arc::clone(&decoded);
            let stats = Arc::clone(&radar_stats);
            input_threads.push(
                std::thread::Builder::new()
                    .name("radar".into())
                    .spawn(move || {
                        let mut decoder = RadarDecoder::new(radar_decoding);
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
                    .map_err(|e| err(e.to_string()))?,
            );
        }
        if let Some((port, mut src)) = imu_port {
            let sh2 = Arc::clone(&sh);
            let ctx = ReaderCtx {
                epoch: sh.epoch,
                stop: Arc::clone(&stop),
                stats: Arc::clone(&imu_stats),
                backoff,
                max_backoff: Duration::from_secs(1),
            };
            let wrap = if d.imu_wrap_day {
                TimeWrap::Day
            } else {
                TimeWrap::Pow32
            };
            let dec = Arc::clone(&decoded);
            input_threads.push(
                std::thread::Builder::new()
                    .name("imu".into())
                    .spawn(move || {
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
                        });
                    })
                    .map_err(|e| err(e.to_string()))?,
            );
        }
    }

    // Synchroniser.
    let sync_cfg = SyncConfig {
        preview_imu: cfg.imu_rate_output,
        ..cfg.sync
    };
    let session_online_clock = cfg.session_online_clock;
    let sh2 = Arc::clone(&sh);
    let sync_thread = std::thread::Builder::new().name("sync".into()).spawn(move || {
        let mut sync = Synchroniser::new(sync_cfg);
        sync.offline_clock = offline && !session_online_clock;
        sync.data_time = offline;
        let mut hist = Histogram::default();
        let mut data_now = f64::NEG_INFINITY;
        loop {
            let done = sh2.inputs_done.load(Ordering::Acquire);
            let watermark = f64::from_bits(sh2.watermark.load(Ordering::Acquire));
            let mut any = false;
            // IMU first: a radar frame pushed before these samples is then visible below.
            // Bounded batches: a fast producer must not keep one drain going while the other
            // queue fills.
            for _ in 0..sh2.imu_q.len() {
                let Some(s) = sh2.imu_q.pop() else { break };
                data_now = data_now.max(s.host_s);
                sync.push_imu(s);
                any = true;
            }
            for _ in 0..sh2.radar_q.len() {
                let Some(r) = sh2.radar_q.pop() else { break };
                data_now = data_now.max(r.host_s);
                sync.push_radar(r, |b| sh2.pool.give(b));
                any = true;
            }
            let now = if offline { watermark } else { sh2.epoch.elapsed().as_secs_f64() };
            let emit = |ev: SyncOut| {
                let read_ns = match &ev {
                    SyncOut::Imu { read_ns, .. } => Some(*read_ns),
                    SyncOut::Preview { .. } => None,
                    SyncOut::Radar { item, .. } => Some(item.read_ns),
                    SyncOut::Tick { .. } => None,
                };
                if let Some(r) = read_ns {
                    hist.record(sh2.now_ns().saturating_sub(r));
                }
                if offline {
                    let mut ev = ev;
                    while let Err(back) = sh2.ev_q.try_push(ev) {
                        ev = back;
                        std::thread::sleep(Duration::from_micros(50));
                    }
                } else if let Some(old) = sh2.ev_q.push(ev) {
                    recycle(&sh2, old);
                }
            };
            if now.is_finite() {
                sync.poll(now, emit);
            }
            if done && sh2.imu_q.is_empty() && sh2.radar_q.is_empty() {
                let emit = |ev: SyncOut| {
                    let mut ev = ev;
                    while let Err(back) = sh2.ev_q.try_push(ev) {
                        ev = back;
                        std::thread::sleep(Duration::from_micros(50));
                    }
                };
                sync.flush(emit);
                break;
            }
            sh2.sync_dropped
                .store(sync.counters.dropped, Ordering::Relaxed);
            if !any {
                std::thread::sleep(Duration::from_micros(200));
            }
        }
        sh2.sync_dropped.store(sync.counters.dropped, Ordering::Relaxed);
        sh2.sync_done.store(true, Ordering::Release);
        let clocks = json!({
            "radar": sync.radar_clock.map().map(|(o, r)| json!({"offset_s": o, "rate": r, "accepted": sync.radar_clock.accepted, "rejected_late": sync.radar_clock.rejected_late})),
            "imu": sync.imu_clock.map().map(|(o, r)| json!({"offset_s": o, "rate": r, "accepted": sync.imu_clock.accepted, "rejected_late": sync.imu_clock.rejected_late})),
            "offline_fit": offline,
        });
        (hist, sync.counters, clocks)
    }).map_err(|e| err(e.to_string()))?;

    // Estimator stage.
    let stage_cfg = StageConfig {
        imu_rate_output: cfg.imu_rate_output,
        mounting: cfg.classical.mounting,
    };
    let sh2 = Arc::clone(&sh);
    let stage_thread = std::thread::Builder::new()
        .name("estimate".into())
        .spawn(move || {
            let mut stage = Stage::new(stage_cfg, built);
            let mut hist = Histogram::default();
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
                stage.process(
                    ev,
                    t0,
                    |p| {
                        if offline {
                            let mut p = p;
                            while let Err(back) = sh2.pose_q.try_push(p) {
                                p = back;
                                std::thread::sleep(Duration::from_micros(50));
                            }
                        } else {
                            sh2.pose_q.push(p);
                        }
                    },
                    |b| sh2.pool.give(b),
                );
                hist.record(sh2.now_ns().saturating_sub(t0));
            }
            sh2.stage_done.store(true, Ordering::Release);
            (hist, stage.counters)
        })
        .map_err(|e| err(e.to_string()))?;

    // Output stage.
    let sh2 = Arc::clone(&sh);
    let out_thread = std::thread::Builder::new()
        .name("output".into())
        .spawn(move || {
            let mut enc = Encoded::default();
            let mut seq = 0u32;
            let mut last_dropped = 0u64;
            let (mut h_out, mut h_e2e, mut h_imu) = (
                Histogram::default(),
                Histogram::default(),
                Histogram::default(),
            );
            let mut send_errors = 0u64;
            let mut radar_poses = 0u64;
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
                p.msg.seq = seq;
                seq = seq.wrapping_add(1);
                p.msg.dropped_total = dropped.min(u64::from(u32::MAX)) as u32;
                p.msg.host_time_ns = sh2.now_ns();
                enc.encode(&p.msg);
                for s in sinks.iter_mut() {
                    if let Err(e) = s.send(&p.msg, p.t, &enc.bytes, &enc.serial[..enc.serial_len]) {
                        send_errors += 1;
                        if send_errors < 10 {
                            tracing::warn!(error = %e, "output failed");
                        }
                    }
                }
                let sent = sh2.now_ns();
                h_out.record(sent.saturating_sub(p.emitted_ns));
                if p.msg.health.contains(Health::PREDICTED) {
                    h_imu.record(sent.saturating_sub(p.read_ns));
                } else {
                    radar_poses += 1;
                    h_e2e.record(sent.saturating_sub(p.read_ns));
                }
            }
            for s in sinks.iter_mut() {
                let _ = s.flush();
            }
            (h_out, h_e2e, h_imu, seq, send_errors, radar_poses)
        })
        .map_err(|e| err(e.to_string()))?;

    // Supervise: limits, idle exit, end of inputs.
    let started = Instant::now();
    loop {
        let inputs_finished = input_threads.iter().all(|t| t.is_finished());
        if inputs_finished {
            break;
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
    sh.inputs_done.store(true, Ordering::Release);
    let (h_sync, sync_counters, clocks) = sync_thread
        .join()
        .map_err(|_| err("sync thread panicked"))?;
    let (h_est, stage_counters) = stage_thread
        .join()
        .map_err(|_| err("estimator thread panicked"))?;
    let (h_out, h_e2e, h_imu, sent, send_errors, radar_poses) = out_thread
        .join()
        .map_err(|_| err("output thread panicked"))?;
    let wall_s = started.elapsed().as_secs_f64();
    let dropped_total = sh.dropped();
    let latency = Latencies {
        sync: h_sync,
        estimate: h_est,
        output: h_out,
        end_to_end: h_e2e,
        imu_to_pose: h_imu,
    };
    let radar_in = decoded[0].load(Ordering::Relaxed);
    let plausibility = match &session_radar_report {
        Some(r) => json!({
            "rejected": r
                .implausible_by_reason()
                .map(|(n, c)| (n.to_string(), json!(c)))
                .collect::<serde_json::Map<String, serde_json::Value>>(),
            "rejected_total": r.implausible_total(),
            "reanchored": r.reanchored,
            "retracted": r.retracted,
            "held": r.held,
        }),
        None => {
            let by: serde_json::Map<String, serde_json::Value> =
                radar_driver::plausible::IMPLAUSIBLE_NAMES
                    .iter()
                    .zip(&radar_stats.implausible)
                    .map(|(n, c)| ((*n).to_string(), json!(c.load(Ordering::Relaxed))))
                    .collect();
            let total: u64 = radar_stats
                .implausible
                .iter()
                .map(|c| c.load(Ordering::Relaxed))
                .sum();
            json!({
                "rejected": by,
                "rejected_total": total,
                "reanchored": radar_stats.reanchored.load(Ordering::Relaxed),
                "retracted": radar_stats.retracted.load(Ordering::Relaxed),
                "held": radar_stats.held.load(Ordering::Relaxed),
            })
        }
    };
    let json = json!({
        "estimator": cfg.estimator.name(),
        "input": if offline { "session" } else { "devices" },
        "wall_s": wall_s,
        "frames_in": {"radar": radar_in, "imu": decoded[1].load(Ordering::Relaxed)},
        "frames_out": {"poses_sent": sent, "radar_rate": radar_poses, "predicted": stage_counters.predicted_poses,
                        "no_pose": stage_counters.no_pose, "resets": stage_counters.resets, "handovers": stage_counters.handovers, "estimator_errors": stage_counters.errors,
                        "send_errors": send_errors},
        "drops": {"radar_queue": sh.radar_q.dropped(), "imu_queue": sh.imu_q.dropped(), "sync_buffers": sync_counters.dropped,
                  "event_queue": sh.ev_q.dropped(), "pose_queue": sh.pose_q.dropped(), "total": dropped_total},
        "sync": {"radar_released": sync_counters.radar, "imu_released": sync_counters.imu, "radar_late": sync_counters.radar_late,
                 "radar_gaps": sync_counters.radar_gaps, "warmup_held": sync_counters.warmup, "imu_gaps": sync_counters.imu_gaps, "clocks": clocks},
        "ports": {"radar_reopens": radar_stats.reopens.load(Ordering::Relaxed), "imu_reopens": imu_stats.reopens.load(Ordering::Relaxed),
                  "radar_bytes": radar_stats.bytes.load(Ordering::Relaxed), "imu_bytes": imu_stats.bytes.load(Ordering::Relaxed)},
        "latency": {"sync": latency.sync.to_json(), "estimate": latency.estimate.to_json(), "output": latency.output.to_json(),
                    "end_to_end": latency.end_to_end.to_json(), "imu_to_pose": latency.imu_to_pose.to_json()},
        "radar_plausibility": plausibility,
        "per_radar_frame_us": if radar_in > 0 { wall_s * 1e6 / radar_in as f64 } else { 0.0 },
    });
    Ok(Summary {
        json,
        latency,
        poses_sent: u64::from(sent),
        radar_poses,
        dropped_total,
        wall_s,
    })
}

/// Feeds a session's decoded streams in the offline runner's order (each radar frame before the
/// first IMU sample at or after its time), waiting when a queue is full (nothing is dropped).
fn feed_session(
    sh: &Shared,
    frames: &[milliego_session::streams::RadarFrame],
    imu: &[milliego_session::streams::ImuSample],
    clock: &milliego_session::streams::SessionClock,
    realtime: bool,
    online_clock: bool,
    decoded: &[AtomicU64; 2],
) {
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
        if realtime {
            let due = Duration::from_secs_f64((t - t_first).max(0.0));
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
        it.sensor_s = f.sensor_s;
        it.frame_number = f.frame_number;
        it.bytes = f.bytes;
        it.processing_s = f
            .cloud
            .stats
            .map_or(0.0, |s| f64::from(s.inter_frame_processing_time_us) * 1e-6);
        it.t = (!online_clock).then_some(tr);
        it.points.clear();
        it.points.extend_from_slice(&f.cloud.points);
        while let Err(back) = sh.radar_q.try_push(it) {
            it = back;
            std::thread::sleep(Duration::from_micros(50));
        }
        decoded[0].fetch_add(1, Ordering::Relaxed);
        sh.watermark.store(tr.to_bits(), Ordering::Release);
    };
    let mut next = 0;
    for s in imu {
        if sh.stop.load(Ordering::Relaxed) {
            return;
        }
        let t = clock.imu_s(s.sensor_s);
        while next < radar.len() && radar[next].0 <= t {
            pace(radar[next].0);
            push_radar(radar[next].0, radar[next].1);
            next += 1;
        }
        pace(t);
        let mut it = ImuItem {
            host_s: s.host_s.unwrap_or(t),
            read_ns: sh.now_ns(),
            sensor_s: s.sensor_s,
            accel: s.accel,
            gyro: s.gyro,
            bytes: s.bytes,
            t: (!online_clock).then_some(t),
        };
        while let Err(back) = sh.imu_q.try_push(it) {
            it = back;
            std::thread::sleep(Duration::from_micros(50));
        }
        decoded[1].fetch_add(1, Ordering::Relaxed);
        sh.watermark.store(t.to_bits(), Ordering::Release);
    }
    for &(tr, i) in &radar[next..] {
        pace(tr);
        push_radar(tr, i);
    }
}
