//! `milliego imu ...`: dump Xsens MTi messages from a capture, an `.mtb` log or a live port, and
//! configure a device.

use crate::output::{self, Format};
use clap::{Args, Subcommand, ValueEnum};
use imu_driver::host::serialport::{self, SerialPort};
use imu_driver::host::{Device, Event, Plan, Reader};
use imu_driver::mtdata2::{GnssPvt, Layout};
use imu_driver::time::{Checked, MessageKind, TICKS_PER_SECOND};
use imu_driver::{
    frame_capacity, mid, Baudrate, Checker, CoordinateFrame, Counters, DataId, DataKind, Message,
    OutputSetting, Precision, TimeWrap, Value, XbusFrame,
};
use serde_json::{json, Map, Value as Json};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Xsens MTi IMU commands.
#[derive(Debug, Subcommand)]
pub enum ImuCmd {
    /// Decode a raw capture, an MT Manager .mtb log or a live port into JSONL or CSV.
    Dump(DumpArgs),
    /// Configure a device's outputs (and optionally its baud rate), then start measuring.
    Config(ConfigArgs),
}

/// Arguments of `imu dump`.
#[derive(Debug, Args)]
pub struct DumpArgs {
    /// Raw capture or .mtb log (back-to-back Xbus frames).
    #[arg(required_unless_present = "port", conflicts_with = "port")]
    file: Option<PathBuf>,
    /// Serial port of a live device instead of a file.
    #[arg(long)]
    port: Option<String>,
    /// Baud rate of --port.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Record format.
    #[arg(long, value_enum, default_value_t = Format::Jsonl)]
    format: Format,
    /// Print only statistics: frames ok/bad, bytes skipped, counts per MID and data id, rates.
    #[arg(long)]
    summary: bool,
    /// Where SampleTimeFine wraps: pow32 (MTi-1/600 series) or day (MTi-10/100 series).
    #[arg(long, value_enum, default_value_t = Wrap::Pow32)]
    wrap: Wrap,
    /// Stop after this many messages (a port otherwise runs until interrupted).
    #[arg(long)]
    count: Option<u64>,
}

/// SampleTimeFine wrap choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Wrap {
    /// 2^32 ticks.
    Pow32,
    /// One day (864,000,000 ticks).
    Day,
}

/// Arguments of `imu config`.
#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// Serial port of the device.
    #[arg(long)]
    port: String,
    /// Current baud rate of the device.
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Output rate of the data outputs, in Hz (time, counter and status come with every message).
    #[arg(long, default_value_t = 100)]
    rate: u16,
    /// Outputs, comma separated, by snake_case name (acceleration, rate_of_turn, quaternion, ...).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "packet_counter,sample_time_fine,status_word,acceleration,rate_of_turn"
    )]
    outputs: Vec<String>,
    /// Precision of float outputs.
    #[arg(long, value_enum, default_value_t = PrecisionArg::Float32)]
    precision: PrecisionArg,
    /// Coordinate frame of orientation and velocity outputs.
    #[arg(long, value_enum, default_value_t = FrameArg::Enu)]
    frame: FrameArg,
    /// Switch the device (and this port) to a new baud rate.
    #[arg(long)]
    new_baud: Option<u32>,
    /// Stay in config mode at the end.
    #[arg(long)]
    no_measure: bool,
    /// Timeout of each step, in ms.
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
}

/// Float precision choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// IEEE single.
    Float32,
    /// Fixed point 12.20.
    Fp1220,
    /// Fixed point 16.32.
    Fp1632,
    /// IEEE double.
    Float64,
}

/// Coordinate frame choice.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FrameArg {
    /// East-North-Up.
    Enu,
    /// North-East-Down.
    Ned,
    /// North-West-Up.
    Nwu,
}

pub fn run(cmd: ImuCmd) -> Result<(), Box<dyn std::error::Error>> {
    match cmd {
        ImuCmd::Dump(args) => dump(&args),
        ImuCmd::Config(args) => config(&args),
    }
}

fn dump(args: &DumpArgs) -> Result<(), Box<dyn std::error::Error>> {
    if let Some(path) = &args.port {
        let port = serialport::new(path, args.baud)
            .timeout(Duration::from_millis(100))
            .open()?;
        let reader: Reader<Box<dyn SerialPort>> = Reader::new(port);
        dump_from(reader, args, true)
    } else {
        let path = args.file.as_ref().ok_or("give a file or --port")?;
        let file = File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
        // .mtb logs hold frames up to ~15 KB: accept every length the format allows.
        let reader: Reader<File, { frame_capacity(65_535) }> = Reader::new(file);
        dump_from(reader, args, false)
    }
}

/// Running statistics for `--summary`.
#[derive(Default)]
struct Summary {
    per_mid: BTreeMap<u8, u64>,
    per_id: BTreeMap<u16, u64>,
    item_errors: u64,
    message_errors: u64,
    /// Per message kind: last unwrapped SampleTimeFine, steps between messages (ticks), count.
    times: BTreeMap<&'static str, (u64, Vec<u64>, u64)>,
}

fn kind_name(k: MessageKind) -> &'static str {
    match k {
        MessageKind::Inertial => "inertial",
        MessageKind::GnssPvt => "gnss_pvt",
        MessageKind::GnssSatInfo => "gnss_sat_info",
        MessageKind::HighRate => "high_rate",
    }
}

fn dump_from<R: Read, const CAP: usize>(
    mut reader: Reader<R, CAP>,
    args: &DumpArgs,
    live: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let wrap = match args.wrap {
        Wrap::Pow32 => TimeWrap::Pow32,
        Wrap::Day => TimeWrap::Day,
    };
    let mut checker = Checker::new(wrap);
    let mut summary = Summary::default();
    let mut out = output::stdout();
    let started = Instant::now();
    let mut messages = 0u64;
    if !args.summary && args.format == Format::Csv && !output::line(&mut out, CSV_HEADER)? {
        return Ok(());
    }
    loop {
        if args.count.is_some_and(|n| messages >= n) {
            break;
        }
        let event = match reader.next_event() {
            Ok(Some(e)) => e,
            Ok(None) => break,
            Err(e) if live && e.kind() == io::ErrorKind::TimedOut => continue,
            // A port that goes away (cable pulled, replay rig closed) ends the dump; the summary
            // of what was read still follows.
            Err(e) if live => {
                eprintln!("milliego: port closed: {e}");
                break;
            }
            Err(e) => return Err(e.into()),
        };
        let Event::Frame { frame, at } = event else {
            continue;
        };
        messages += 1;
        let host_s = live.then(|| at.duration_since(started).as_secs_f64());
        let record = Record::new(&frame, &mut checker, &mut summary);
        if args.summary {
            continue;
        }
        let text = match args.format {
            Format::Jsonl => Some(record.json(host_s).to_string()),
            Format::Csv => record.csv(),
        };
        if let Some(text) = text {
            if !output::line(&mut out, &text)? {
                return Ok(());
            }
        }
    }
    if args.summary {
        print_summary(&mut out, reader.counters(), &checker, &summary)?;
    }
    match out.flush() {
        Err(e) if !output::is_broken_pipe(&e) => Err(e.into()),
        _ => Ok(()),
    }
}

/// One decoded message and its checks.
struct Record<'a> {
    frame: XbusFrame<'a>,
    message: Result<Message<'a>, imu_driver::MessageError>,
    checked: Option<Checked>,
}

impl<'a> Record<'a> {
    fn new(frame: &XbusFrame<'a>, checker: &mut Checker, summary: &mut Summary) -> Self {
        *summary.per_mid.entry(frame.mid()).or_default() += 1;
        let message = Message::decode(frame);
        let mut checked = None;
        match &message {
            Ok(Message::MtData2(m)) => {
                for item in m.items() {
                    match item {
                        Ok(i) => *summary.per_id.entry(i.id.0).or_default() += 1,
                        Err(_) => summary.item_errors += 1,
                    }
                }
                let c = checker.check(&m.sample());
                if let Some(t) = c.time_ticks {
                    let e = summary
                        .times
                        .entry(kind_name(c.kind))
                        .or_insert((t, Vec::new(), 0));
                    if e.2 > 0 && t > e.0 {
                        e.1.push(t - e.0);
                    }
                    e.0 = t;
                    e.2 += 1;
                }
                checked = Some(c);
            }
            Ok(_) => {}
            Err(_) => summary.message_errors += 1,
        }
        Self {
            frame: *frame,
            message,
            checked,
        }
    }

    fn json(&self, host_s: Option<f64>) -> Json {
        let mut o = Map::new();
        o.insert("mid".into(), json!(self.frame.mid()));
        o.insert("bus_id".into(), json!(self.frame.bid()));
        if let Some(name) = mid::name(self.frame.mid()) {
            o.insert("msg".into(), json!(name));
        }
        if let Some(t) = host_s {
            o.insert("host_time_s".into(), json!(t));
        }
        match &self.message {
            Ok(Message::MtData2(m)) => {
                for item in m.items() {
                    match item.and_then(|i| i.value().map(|v| (i.id, v))) {
                        Ok((id, v)) => {
                            let key = match id.kind() {
                                DataKind::Unknown => format!("0x{:04X}", id.0),
                                k => k.snake_name().to_string(),
                            };
                            o.insert(key, value_json(&v));
                        }
                        Err(e) => {
                            if let Some(list) = o
                                .entry("errors")
                                .or_insert_with(|| json!([]))
                                .as_array_mut()
                            {
                                list.push(json!(e.to_string()));
                            }
                        }
                    }
                }
                if let Some(c) = &self.checked {
                    if let Some(t) = c.time_ticks {
                        o.insert("time_s".into(), json!(t as f64 / TICKS_PER_SECOND as f64));
                    }
                    if !c.flags.is_clean() {
                        o.insert("flags".into(), json!(c.flags.names().collect::<Vec<_>>()));
                    }
                }
            }
            Ok(Message::Error { code, detail }) => {
                o.insert("error_code".into(), json!(code.as_u8()));
                o.insert("error".into(), json!(code.text()));
                o.insert("detail".into(), json!(hex(detail)));
            }
            Ok(Message::Warning { code, detail }) => {
                o.insert("warning_code".into(), json!(code));
                o.insert("detail".into(), json!(String::from_utf8_lossy(detail)));
            }
            Ok(Message::DeviceId(id)) => {
                o.insert("device_id".into(), json!(format!("{id:08X}")));
            }
            Ok(Message::ProductCode(p)) => {
                o.insert("product_code".into(), json!(String::from_utf8_lossy(p)));
            }
            Ok(Message::FirmwareRev(f)) => {
                o.insert("firmware".into(), json!(f.to_string()));
            }
            Ok(Message::Configuration(c)) => {
                o.insert("output_mode".into(), json!(c.output_mode));
                o.insert("output_settings".into(), json!(c.output_settings));
                o.insert("sampling_period".into(), json!(c.sampling_period));
            }
            Ok(Message::OutputConfiguration(c)) => {
                let list: Vec<Json> = c
                    .settings()
                    .map(|s| json!({"id": format!("0x{:04X}", s.id.0), "name": s.id.to_string(), "rate_hz": s.rate_hz}))
                    .collect();
                o.insert("outputs".into(), Json::Array(list));
            }
            Ok(Message::Baudrate(Some(code))) => {
                o.insert(
                    "baudrate".into(),
                    json!(Baudrate::from_code(*code).map(Baudrate::bps)),
                );
            }
            Ok(Message::MtData(p)) | Ok(Message::Other { payload: p, .. }) => {
                o.insert("payload".into(), json!(hex(p)));
            }
            Ok(_) => {}
            Err(e) => {
                o.insert("decode_error".into(), json!(e.to_string()));
                o.insert("payload".into(), json!(hex(self.frame.payload())));
            }
        }
        Json::Object(o)
    }

    /// A CSV row for MTData2 messages (other messages have no row).
    fn csv(&self) -> Option<String> {
        let Ok(Message::MtData2(m)) = &self.message else {
            return None;
        };
        let s = m.sample();
        let mut cols: Vec<String> = vec![
            self.frame.mid().to_string(),
            self.frame.bid().to_string(),
            opt(s.packet_counter),
            opt(s.sample_time_fine),
            opt(self
                .checked
                .and_then(|c| c.time_ticks)
                .map(|t| t as f64 / TICKS_PER_SECOND as f64)),
        ];
        for v in [
            s.acceleration,
            s.rate_of_turn,
            s.magnetic_field,
            s.euler_angles,
        ] {
            push_floats(&mut cols, v.as_ref().map(|a| &a[..]), 3);
        }
        push_floats(&mut cols, s.quaternion.as_ref().map(|a| &a[..]), 4);
        cols.push(opt(s.status));
        cols.push(
            self.checked
                .map(|c| c.flags.names().collect::<Vec<_>>().join("|"))
                .unwrap_or_default(),
        );
        Some(cols.join(","))
    }
}

const CSV_HEADER: &str = "mid,bus_id,packet_counter,sample_time_fine,time_s,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,mag_x,mag_y,mag_z,roll,pitch,yaw,q0,q1,q2,q3,status,flags";

fn opt<T: ToString>(v: Option<T>) -> String {
    v.map(|v| v.to_string()).unwrap_or_default()
}

fn push_floats(cols: &mut Vec<String>, v: Option<&[f64]>, n: usize) {
    for i in 0..n {
        cols.push(opt(v.and_then(|v| v.get(i))));
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

fn pvt_json(p: &GnssPvt) -> Json {
    json!({
        "itow_ms": p.itow, "year": p.year, "month": p.month, "day": p.day, "hour": p.hour,
        "min": p.min, "sec": p.sec, "valid": p.valid, "t_acc_ns": p.t_acc, "nano": p.nano,
        "fix_type": p.fix_type, "flags": p.flags, "num_sv": p.num_sv,
        "lat_deg": f64::from(p.lat) * 1e-7, "lon_deg": f64::from(p.lon) * 1e-7,
        "height_mm": p.height, "hmsl_mm": p.hmsl, "h_acc_mm": p.h_acc, "v_acc_mm": p.v_acc,
        "vel_ned_mm_s": [p.vel_n, p.vel_e, p.vel_d], "g_speed_mm_s": p.g_speed,
        "head_mot": p.head_mot, "s_acc": p.s_acc, "head_acc": p.head_acc, "head_veh": p.head_veh,
        "dop": {"g": p.gdop, "p": p.pdop, "t": p.tdop, "v": p.vdop, "h": p.hdop, "n": p.ndop, "e": p.edop},
    })
}

fn value_json(v: &Value<'_>) -> Json {
    match v {
        Value::Temperature(x) | Value::AltitudeEllipsoid(x) => json!(x),
        Value::UtcTime(t) => json!(t.to_string()),
        Value::PacketCounter(c) => json!(c),
        Value::SampleTimeFine(t)
        | Value::SampleTimeCoarse(t)
        | Value::BaroPressure(t)
        | Value::StatusWord(t) => json!(t),
        Value::StatusByte(s) => json!(s),
        Value::Rssi(r) => json!(r),
        Value::GnssPvtData(p) => pvt_json(p),
        Value::GnssSatInfo(s) => json!({
            "itow_ms": s.itow,
            "num_svs": s.num_svs,
            "satellites": s.satellites().map(|sat| json!({
                "gnss_id": sat.gnss_id, "sv_id": sat.sv_id, "cno": sat.cno, "flags": sat.flags
            })).collect::<Vec<_>>(),
        }),
        Value::Unknown(d) => json!(hex(d)),
        other => json!(other.floats()),
    }
}

fn print_summary(
    out: &mut impl Write,
    c: &Counters,
    checker: &Checker,
    s: &Summary,
) -> io::Result<()> {
    let mut lines = vec![
        format!("bytes in:          {}", c.bytes_in),
        format!("frames ok:         {}", c.frames_ok),
        format!(
            "frames bad:        {} (checksum {}, length {}, truncated {})",
            c.frames_bad.total(),
            c.frames_bad.checksum,
            c.frames_bad.length,
            c.frames_bad.truncated
        ),
        format!("bytes skipped:     {}", c.bytes_skipped),
        format!("resyncs:           {}", c.resyncs),
    ];
    let ct = checker.counters();
    lines.push(format!(
        "packet counter:    {} in sequence, {} gaps ({} missing), {} out of order",
        ct.in_sequence, ct.gaps, ct.missing, ct.out_of_order
    ));
    lines.push(format!("flagged messages:  {}", checker.flagged));
    lines.push(format!(
        "decode errors:     {} items, {} messages",
        s.item_errors, s.message_errors
    ));
    lines.push("messages per MID:".into());
    for (m, n) in &s.per_mid {
        lines.push(format!(
            "  0x{m:02X} {:<22} {n}",
            mid::name(*m).unwrap_or("?")
        ));
    }
    lines.push("items per data id:".into());
    for (id, n) in &s.per_id {
        lines.push(format!("  0x{id:04X} {:<34} {n}", DataId(*id).to_string()));
    }
    lines.push("rate implied by SampleTimeFine (median step):".into());
    for (kind, (_, steps, n)) in &s.times {
        let mut steps = steps.clone();
        steps.sort_unstable();
        let rate = match steps.get(steps.len() / 2) {
            Some(&median) if median > 0 => format!(
                "{:.2} Hz (median step {:.1} ms)",
                TICKS_PER_SECOND as f64 / median as f64,
                median as f64 / 10.0
            ),
            _ => "n/a".to_string(),
        };
        lines.push(format!("  {kind:<14} {rate}, {n} messages"));
    }
    for l in lines {
        if !output::line(out, &l)? {
            break;
        }
    }
    Ok(())
}

fn output_id(name: &str, p: Precision, frame: CoordinateFrame) -> Result<DataId, String> {
    let kind = DataKind::ALL
        .iter()
        .copied()
        .find(|k| k.snake_name() == name)
        .ok_or_else(|| {
            let known: Vec<&str> = DataKind::ALL.iter().map(|k| k.snake_name()).collect();
            format!("unknown output {name:?}; known: {}", known.join(", "))
        })?;
    DataId::of(kind, p)
        .map(|id| id.in_frame(frame))
        .ok_or_else(|| format!("no id for {name}"))
}

fn config(args: &ConfigArgs) -> Result<(), Box<dyn std::error::Error>> {
    let p = match args.precision {
        PrecisionArg::Float32 => Precision::Float32,
        PrecisionArg::Fp1220 => Precision::Fp1220,
        PrecisionArg::Fp1632 => Precision::Fp1632,
        PrecisionArg::Float64 => Precision::Float64,
    };
    let frame = match args.frame {
        FrameArg::Enu => CoordinateFrame::Enu,
        FrameArg::Ned => CoordinateFrame::Ned,
        FrameArg::Nwu => CoordinateFrame::Nwu,
    };
    let mut outputs = Vec::new();
    for name in &args.outputs {
        let id = output_id(name.trim(), p, frame)?;
        // Time, counter and status describe each message: ask for them at "max".
        let every_message = matches!(id.kind().layout(), Layout::Fixed(n) if n <= 12)
            && id.kind() != DataKind::BaroPressure;
        let rate_hz = if every_message {
            OutputSetting::MAX_RATE
        } else {
            args.rate
        };
        outputs.push(OutputSetting { id, rate_hz });
    }
    let baudrate = match args.new_baud {
        Some(bps) => Some(Baudrate::from_bps(bps).ok_or(format!("no device baud code for {bps}"))?),
        None => None,
    };
    let mut device =
        Device::open(&args.port, args.baud)?.with_timeout(Duration::from_millis(args.timeout_ms));
    let report = device.configure(&Plan {
        outputs,
        baudrate,
        measure: !args.no_measure,
    })?;
    let mut out = output::stdout();
    let mut lines = vec![
        format!("device id:     {:08X}", report.device_id),
        format!("product code:  {}", report.product_code),
        format!("firmware:      {}", report.firmware),
    ];
    if let Some(o) = &report.outputs {
        lines.push("outputs in force:".into());
        for s in &o.actual {
            let rate = if s.is_max_rate() {
                "max".to_string()
            } else {
                format!("{} Hz", s.rate_hz)
            };
            lines.push(format!("  {:<40} {rate}", s.id.to_string()));
        }
        for d in &o.differences {
            lines.push(format!("warning: {d}"));
        }
    }
    if let Some(b) = report.baudrate {
        lines.push(format!("baud rate:     {}", b.bps()));
    }
    lines.push(format!(
        "mode:          {}",
        if args.no_measure {
            "config"
        } else {
            "measurement"
        }
    ));
    for l in lines {
        if !output::line(&mut out, &l)? {
            break;
        }
    }
    out.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use imu_driver::{MtData2Writer, XbusFrame};

    #[test]
    fn output_names_map_to_ids_in_precision_and_frame() {
        let id = output_id("acceleration", Precision::Fp1220, CoordinateFrame::Ned).unwrap();
        assert_eq!(
            id,
            DataId(0x4021),
            "frame bits only on orientation/velocity"
        );
        let id = output_id("quaternion", Precision::Float64, CoordinateFrame::Ned).unwrap();
        assert_eq!(id, DataId(0x2017));
        let id = output_id("packet_counter", Precision::Float64, CoordinateFrame::Ned).unwrap();
        assert_eq!(id, DataId(0x1020), "no format bits on fixed layouts");
        let err = output_id("accel", Precision::Float32, CoordinateFrame::Enu).unwrap_err();
        assert!(err.contains("rate_of_turn"), "{err}");
    }

    #[test]
    fn mtdata2_records_as_json_and_csv() {
        let mut buf = [0u8; 128];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(DataId(0x1020), &Value::PacketCounter(7)).unwrap();
        w.value(DataId(0x1060), &Value::SampleTimeFine(12_345))
            .unwrap();
        w.value(DataId(0x4020), &Value::Acceleration([0.5, -1.0, 9.75]))
            .unwrap();
        w.item(DataId(0x9990), &[0xAB]).unwrap();
        let n = w.finish(0xFF).unwrap();
        let frame = XbusFrame::new_checked(&buf[..n]).unwrap();
        let mut checker = Checker::new(TimeWrap::Pow32);
        let mut summary = Summary::default();
        let r = Record::new(&frame, &mut checker, &mut summary);
        let j = r.json(None);
        assert_eq!(j["mid"], 0x36);
        assert_eq!(j["bus_id"], 0xFF);
        assert_eq!(j["msg"], "MTData2");
        assert_eq!(j["packet_counter"], 7);
        assert_eq!(j["sample_time_fine"], 12_345);
        assert_eq!(j["acceleration"], json!([0.5, -1.0, 9.75]));
        assert_eq!(j["0x9990"], "AB");
        assert_eq!(j["time_s"], 1.2345);
        let row = r.csv().unwrap();
        assert_eq!(row.split(',').count(), CSV_HEADER.split(',').count());
        assert!(
            row.starts_with("54,255,7,12345,1.2345,0.5,-1,9.75,"),
            "{row}"
        );
        assert_eq!(summary.per_id.get(&0x4020), Some(&1));
        assert_eq!(summary.per_mid.get(&0x36), Some(&1));
    }

    #[test]
    fn error_replies_as_json() {
        let mut buf = [0u8; 16];
        let n = imu_driver::encode_frame(&mut buf, 0xFF, mid::ERROR, &[0x04]).unwrap();
        let frame = XbusFrame::new_checked(&buf[..n]).unwrap();
        let r = Record::new(
            &frame,
            &mut Checker::new(TimeWrap::Pow32),
            &mut Summary::default(),
        );
        let j = r.json(None);
        assert_eq!(
            (j["error_code"].clone(), j["error"].clone()),
            (json!(4), json!("invalid message"))
        );
        assert_eq!(r.csv(), None);
    }
}
