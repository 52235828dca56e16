//! `milliego radar ...`: dump frames from a capture or a live data port, upload a .cfg, and show
//! what a .cfg implies.

use crate::output::{self, Format};
use clap::{Args, Subcommand, ValueEnum};
use radar_driver::cfg::{RadarConfig, RfScale};
use radar_driver::clock::{cpu_clock_hz, CycleUnwrapper};
use radar_driver::error::FRAME_ERROR_NAMES;
use radar_driver::host::cli_port::{open_serial, CLI_BAUD};
use radar_driver::host::{CliPort, FrameReader, PointCloud, ReadEvent};
use radar_driver::{Layout, LayoutHint};
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Subcommand)]
pub enum RadarCmd {
    /// Decode frames from a capture file (.dat/.bin, raw data-UART bytes) or a live data port.
    Dump(DumpArgs),
    /// Upload a .cfg over the CLI port (sensorStop, flushCfg, the file, sensorStart).
    Config(ConfigArgs),
    /// Print what a .cfg implies: resolutions, limits, frame period, points-per-frame bound.
    Info(InfoArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LayoutArg {
    /// Detect per frame (people-counting headers by checksum, else out-of-box).
    Auto,
    /// Out-of-box demo, 40-byte header.
    Oob40,
    /// Out-of-box demo, 36-byte header (xWR14xx, SDK 1/2).
    Oob36,
    /// People counting, 48-byte header.
    Pc48,
    /// Older people counting, 52-byte header.
    Pc52,
}

impl LayoutArg {
    fn hint(self) -> LayoutHint {
        match self {
            LayoutArg::Auto => LayoutHint::Auto,
            LayoutArg::Oob40 => LayoutHint::Fixed(Layout::Oob40),
            LayoutArg::Oob36 => LayoutHint::Fixed(Layout::Oob36),
            LayoutArg::Pc48 => LayoutHint::Fixed(Layout::PeopleCounting48),
            LayoutArg::Pc52 => LayoutHint::Fixed(Layout::PeopleCounting52),
        }
    }
}

#[derive(Debug, Args)]
pub struct DumpArgs {
    /// Capture file of raw data-port bytes.
    #[arg(required_unless_present = "port", conflicts_with = "port")]
    file: Option<PathBuf>,
    /// Live data port (e.g. /dev/ttyACM1 or /dev/ttyUSB1).
    #[arg(long)]
    port: Option<String>,
    /// Data port baud rate [bit/s].
    #[arg(long, default_value_t = 921_600)]
    baud: u32,
    /// Output format, one record per frame (jsonl) or per point (csv).
    #[arg(long, value_enum, default_value_t = Format::Jsonl)]
    format: Format,
    /// Print only one JSON summary object (counts, errors, TLV types) at the end.
    #[arg(long)]
    summary: bool,
    /// Header layout.
    #[arg(long, value_enum, default_value_t = LayoutArg::Auto)]
    layout: LayoutArg,
    /// The .cfg the radar runs: scales SDK 1/2 Doppler indices to m/s and unwraps the sensor
    /// clock across long gaps.
    #[arg(long)]
    cfg: Option<PathBuf>,
    /// Stop after this many good frames.
    #[arg(long)]
    max_frames: Option<u64>,
    /// Read size in bytes (files only; a serial port delivers what it has).
    #[arg(long, default_value_t = 4096)]
    chunk: usize,
}

#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// The radar's CLI port (e.g. /dev/ttyACM0 or /dev/ttyUSB0).
    #[arg(long)]
    cli_port: String,
    /// The .cfg to upload.
    file: PathBuf,
    /// Time to wait for each line's Done/Error, in ms.
    #[arg(long, default_value_t = 2000)]
    timeout_ms: u64,
}

#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The .cfg to analyse.
    file: PathBuf,
    /// Device family (RF quantisation): 60 for xWR68xx/64xx, 77 for xWR14xx/16xx/18xx
    /// (default: from the start frequency).
    #[arg(long, value_parser = ["60", "77"])]
    ghz: Option<String>,
}

pub fn run(cmd: RadarCmd) -> Result<()> {
    match cmd {
        RadarCmd::Dump(a) => dump(a),
        RadarCmd::Config(a) => config(a),
        RadarCmd::Info(a) => info(a),
    }
}

fn read_cfg(path: &PathBuf) -> Result<RadarConfig> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    RadarConfig::parse(&text).map_err(|e| format!("{}: {e}", path.display()).into())
}

fn info(a: InfoArgs) -> Result<()> {
    let cfg = read_cfg(&a.file)?;
    let rf = a.ghz.as_deref().map(|g| {
        if g == "60" {
            RfScale::Ghz60
        } else {
            RfScale::Ghz77
        }
    });
    let d = cfg
        .derive(rf)
        .map_err(|e| format!("{}: {e}", a.file.display()))?;
    let v = json!({
        "file": a.file.display().to_string(),
        "rf_scale": d.rf_scale,
        "start_freq_ghz": d.start_freq_ghz,
        "slope_mhz_per_us": d.slope_mhz_us,
        "center_freq_ghz": d.center_freq_ghz,
        "sampled_bandwidth_mhz": d.sampled_bandwidth_mhz,
        "num_tx": d.num_tx,
        "num_rx": d.num_rx,
        "chirps_per_frame": d.chirps_per_frame,
        "num_range_bins": d.num_range_bins,
        "num_doppler_bins": d.num_doppler_bins,
        "range_resolution_m": d.range_resolution_m,
        "max_range_m": d.max_range_m,
        "velocity_resolution_m_per_s": d.velocity_resolution_mps,
        "max_velocity_m_per_s": d.max_velocity_mps,
        "frame_period_ms": d.frame_period_ms,
        "data_baud": d.data_baud,
        "uart_bytes_per_frame": d.uart_bytes_per_frame,
        "bytes_per_point": d.bytes_per_point,
        "max_points_per_frame": d.max_points_per_frame,
        "commands_not_modelled": cfg.other_commands,
    });
    println!("{}", serde_json::to_string_pretty(&v)?);
    Ok(())
}

fn config(a: ConfigArgs) -> Result<()> {
    let text =
        std::fs::read_to_string(&a.file).map_err(|e| format!("{}: {e}", a.file.display()))?;
    let port = open_serial(&a.cli_port, CLI_BAUD).map_err(|e| format!("{}: {e}", a.cli_port))?;
    let mut cli = CliPort::new(port, Duration::from_millis(a.timeout_ms));
    let report = cli.upload(&text)?;
    for (line_no, why) in &report.ignored {
        eprintln!("note: line {line_no} ignored by the device: {why}");
    }
    println!(
        "{}",
        json!({"uploaded": a.file.display().to_string(), "done": report.done, "skipped": report.skipped,
               "ignored": report.ignored.len()})
    );
    Ok(())
}

/// Running totals for `--summary` (and the stderr note after a dump).
#[derive(Default)]
struct Summary {
    points_total: u64,
    points_min: Option<usize>,
    points_max: usize,
    empty_points_tlv: u64,
    tlv_counts: BTreeMap<u32, u64>,
    tlv_errors: BTreeMap<u32, u64>,
    layouts: BTreeMap<&'static str, u64>,
    first_frame: Option<u32>,
    last_frame: Option<u32>,
    frame_gaps: u64,
    frames_missing: u64,
}

fn dump(a: DumpArgs) -> Result<()> {
    let velocity_res = match &a.cfg {
        Some(p) => {
            let d = read_cfg(p)?
                .derive(None)
                .map_err(|e| format!("{}: {e}", p.display()))?;
            Some((d.velocity_resolution_mps as f32, d.frame_period_ms / 1e3))
        }
        None => None,
    };
    let (src, name): (Box<dyn Read>, String) = match (&a.file, &a.port) {
        (Some(f), _) => (
            Box::new(std::fs::File::open(f).map_err(|e| format!("{}: {e}", f.display()))?),
            f.display().to_string(),
        ),
        (None, Some(p)) => (
            Box::new(open_serial(p, a.baud).map_err(|e| format!("{p}: {e}"))?),
            p.clone(),
        ),
        (None, None) => return Err("give a capture file or --port".into()),
    };
    let mut reader = FrameReader::new(src, a.layout.hint(), a.chunk);
    let mut out = output::stdout();
    let mut s = Summary::default();
    let mut clock: Option<CycleUnwrapper> = None;
    let start = Instant::now();
    let mut good = 0u64;
    let mut open = true;
    if !a.summary && a.format == Format::Csv {
        open = output::line(&mut out, "frame,subframe,cpu_cycles,sensor_time_s,host_time_s,point,x,y,z,velocity,snr_db,noise_db")?;
    }
    while open && a.max_frames.is_none_or(|m| good < m) {
        let ev = match reader.next_event() {
            Ok(Some(ev)) => ev,
            Ok(None) => break,
            // A port that goes away (cable pulled, replay rig closed) ends the dump; the summary
            // of what was read still follows.
            Err(e) if a.port.is_some() => {
                eprintln!("milliego: {name}: port closed: {e}");
                break;
            }
            Err(e) => return Err(e.into()),
        };
        let f = match ev {
            ReadEvent::Frame(f) => f,
            ReadEvent::Dropped { error, skipped, .. } => {
                if !a.summary {
                    eprintln!("milliego: {name}: dropped {skipped} B: {error}");
                }
                continue;
            }
            ReadEvent::Idle => continue,
        };
        good += 1;
        let frame = f.frame();
        let h = *frame.header();
        let cloud = PointCloud::from_frame(&frame, velocity_res.map(|v| v.0));
        let sensor_s = h.time_cpu_cycles.and_then(|c| {
            let u = clock.get_or_insert_with(|| {
                CycleUnwrapper::new(cpu_clock_hz(&h), velocity_res.map(|v| v.1))
            });
            u.push(h.frame_number, c).seconds
        });
        let host_s = f.host_time.duration_since(start).as_secs_f64();
        s.note(&h, &cloud);
        if a.summary {
            continue;
        }
        open = match a.format {
            Format::Jsonl => output::line(
                &mut out,
                &frame_json(&h, &cloud, sensor_s, host_s).to_string(),
            )?,
            Format::Csv => write_csv(&mut out, &h, &cloud, sensor_s, host_s)?,
        };
    }
    let c = *reader.counters();
    let mut bad = Map::new();
    for (i, n) in c.frames_bad.iter().enumerate() {
        if *n > 0 {
            bad.insert(FRAME_ERROR_NAMES[i].to_string(), json!(n));
        }
    }
    let summary = json!({
        "source": name,
        "frames_ok": c.frames_ok,
        "frames_bad": c.frames_bad_total(),
        "frames_bad_by_reason": bad,
        "bytes_in": c.bytes_in,
        "bytes_in_frames": c.bytes_ok,
        "bytes_skipped": c.bytes_skipped,
        "resyncs": c.resyncs,
        "points_total": s.points_total,
        "points_per_frame_min": s.points_min.unwrap_or(0),
        "points_per_frame_max": s.points_max,
        "frames_with_empty_points_tlv": s.empty_points_tlv,
        "tlv_counts": s.tlv_counts.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<Map<_, _>>(),
        "tlv_decode_errors": s.tlv_errors.iter().map(|(k, v)| (k.to_string(), json!(v))).collect::<Map<_, _>>(),
        "layouts": s.layouts,
        "frame_number_first": s.first_frame,
        "frame_number_last": s.last_frame,
        "frame_gaps": s.frame_gaps,
        "frames_missing": s.frames_missing,
    });
    if a.summary {
        output::line(&mut out, &summary.to_string())?;
    } else {
        eprintln!("milliego: {name}: {summary}");
    }
    match out.flush() {
        Err(e) if !output::is_broken_pipe(&e) => Err(e.into()),
        _ => Ok(()),
    }
}

impl Summary {
    fn note(&mut self, h: &radar_driver::Header, c: &PointCloud) {
        let n = c.points.len();
        self.points_total += n as u64;
        self.points_min = Some(self.points_min.map_or(n, |m| m.min(n)));
        self.points_max = self.points_max.max(n);
        self.empty_points_tlv += u64::from(c.empty_points_tlv);
        for t in &c.tlv_types {
            *self.tlv_counts.entry(*t).or_default() += 1;
        }
        for e in &c.tlv_errors {
            let radar_driver::TlvError::BadLength { ty, .. } = e else {
                continue;
            };
            *self.tlv_errors.entry(*ty).or_default() += 1;
        }
        *self.layouts.entry(h.layout.name()).or_default() += 1;
        if let Some(last) = self.last_frame {
            let step = h.frame_number.wrapping_sub(last);
            if step > 1 && step < u32::MAX / 2 {
                self.frame_gaps += 1;
                self.frames_missing += u64::from(step - 1);
            }
        }
        self.first_frame.get_or_insert(h.frame_number);
        self.last_frame = Some(h.frame_number);
    }
}

/// An f32 as the shortest decimal that reads back to it (85.2, not 85.20000457763672); NaN and
/// infinities (unknown values) as null.
fn num(v: f32) -> Value {
    if v.is_finite() {
        v.to_string()
            .parse::<f64>()
            .map_or(Value::Null, |d| json!(d))
    } else {
        Value::Null
    }
}

fn frame_json(
    h: &radar_driver::Header,
    c: &PointCloud,
    sensor_s: Option<f64>,
    host_s: f64,
) -> Value {
    let points: Vec<Value> = c
        .points
        .iter()
        .map(|p| json!([num(p.x), num(p.y), num(p.z), num(p.velocity)]))
        .collect();
    let mut o = Map::new();
    o.insert("frame".into(), json!(h.frame_number));
    o.insert("version".into(), json!(h.version.to_string()));
    o.insert("platform".into(), json!(format!("{:#x}", h.platform)));
    o.insert("layout".into(), json!(h.layout.name()));
    o.insert("subframe".into(), json!(h.subframe));
    o.insert("cpu_cycles".into(), json!(h.time_cpu_cycles));
    o.insert("sensor_time_s".into(), json!(sensor_s));
    o.insert("host_time_s".into(), json!(host_s));
    o.insert("points".into(), Value::Array(points));
    if let Some(snr) = &c.snr_db {
        o.insert(
            "snr".into(),
            Value::Array(snr.iter().map(|v| num(*v)).collect()),
        );
    }
    if let Some(noise) = &c.noise_db {
        o.insert(
            "noise".into(),
            Value::Array(noise.iter().map(|v| num(*v)).collect()),
        );
    }
    if !c.targets.is_empty() {
        let t: Vec<Value> = c
            .targets
            .iter()
            .map(|t| json!({"tid": t.tid, "position": t.position.map(num), "velocity": t.velocity.map(num)}))
            .collect();
        o.insert("targets".into(), Value::Array(t));
    }
    o.insert("tlv_types".into(), json!(c.tlv_types));
    if !c.tlv_errors.is_empty() {
        o.insert(
            "tlv_errors".into(),
            json!(c
                .tlv_errors
                .iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()),
        );
    }
    Value::Object(o)
}

fn write_csv(
    out: &mut impl Write,
    h: &radar_driver::Header,
    c: &PointCloud,
    sensor_s: Option<f64>,
    host_s: f64,
) -> std::io::Result<bool> {
    let opt = |v: Option<f32>| {
        v.filter(|v| v.is_finite())
            .map_or(String::new(), |v| v.to_string())
    };
    let head = format!(
        "{},{},{},{},{host_s}",
        h.frame_number,
        h.subframe.map_or(String::new(), |v| v.to_string()),
        h.time_cpu_cycles.map_or(String::new(), |v| v.to_string()),
        sensor_s.map_or(String::new(), |v| v.to_string()),
    );
    for (i, p) in c.points.iter().enumerate() {
        let snr = opt(c.snr_db.as_ref().and_then(|s| s.get(i).copied()));
        let noise = opt(c.noise_db.as_ref().and_then(|s| s.get(i).copied()));
        let line = format!(
            "{head},{i},{},{},{},{},{snr},{noise}",
            p.x,
            p.y,
            p.z,
            opt(Some(p.velocity))
        );
        if !output::line(out, &line)? {
            return Ok(false);
        }
    }
    Ok(true)
}
