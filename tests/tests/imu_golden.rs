//! Golden parity: every value an independent decoder printed for the real Xsens captures
//! (`output.golden`) is reproduced from the matching `output.bin`, and the SetOutputConfiguration
//! acks decode to `outputconfig.golden`. The goldens are read at run time; nothing is copied here.

use imu_driver::mtdata2::GnssPvt;
use imu_driver::{
    message::OutputConfiguration, DataId, LogFramer, Message, Poll, Precision, Value,
};
use std::fs;
use std::path::{Path, PathBuf};

/// Float values in the five goldens (README: "10,169 values over the five captures").
const GOLDEN_FLOAT_VALUES: usize = 10_169;

fn capture_dirs() -> Option<Vec<PathBuf>> {
    let root = milliego_tests::captures_dir("xsens")?;
    let mut dirs: Vec<PathBuf> = fs::read_dir(&root)
        .expect("read captures dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("output.bin").is_file())
        .collect();
    dirs.sort();
    Some(dirs)
}

/// One golden message: items as (name, value lines).
type GoldenMessage = Vec<(String, Vec<String>)>;

fn parse_golden(text: &str) -> Vec<GoldenMessage> {
    let mut messages = Vec::new();
    let mut current: GoldenMessage = Vec::new();
    for line in text.lines() {
        if line.is_empty() {
            if !current.is_empty() {
                messages.push(std::mem::take(&mut current));
            }
        } else if let Some(value) = line.strip_prefix("  ") {
            current
                .last_mut()
                .expect("value before any item name")
                .1
                .push(value.to_string());
        } else {
            let name = line.strip_suffix(':').expect("item name ends with ':'");
            current.push((name.to_string(), Vec::new()));
        }
    }
    if !current.is_empty() {
        messages.push(current);
    }
    messages
}

/// Decoded MTData2 payloads of a capture, in order.
fn decode_frames(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut framer = LogFramer::new();
    let mut input = bytes;
    let mut out = Vec::new();
    loop {
        match framer.poll(&mut input) {
            Poll::Frame(f) => {
                assert_eq!((f.bid(), f.mid()), (0xFF, 0x36));
                out.push(f.payload().to_vec());
            }
            Poll::Dropped { bytes, error } => panic!("capture has {bytes} bad bytes: {error}"),
            Poll::NeedMore => break,
        }
    }
    assert_eq!(framer.finish(), None);
    out
}

/// Compares a decoded float with the golden text: exactly in the stored precision (Float32
/// values as f32, fixed point and Float64 as f64: both are exact in an f64).
fn float_matches(golden: &str, ours: f64, p: Precision) -> bool {
    match p {
        Precision::Float32 => golden.parse::<f32>().ok() == Some(ours as f32),
        _ => golden.parse::<f64>().ok() == Some(ours),
    }
}

fn float_labels(id: DataId, n: usize) -> Vec<&'static str> {
    match (id.kind().name(), n) {
        (_, 1) => vec![""],
        ("LatLon", 2) => vec!["Lat", "Lon"],
        (_, 3) if id.kind().name() != "RotationMatrix" => vec!["X", "Y", "Z"],
        (_, 4) => vec!["Q0", "Q1", "Q2", "Q3"],
        (_, 9) => vec!["A", "B", "C", "D", "E", "F", "G", "H", "I"],
        other => panic!("no labels for {other:?}"),
    }
}

fn pvt_lines(p: &GnssPvt) -> Vec<String> {
    let fields: [(&str, i64); 35] = [
        ("ITOW", p.itow.into()),
        ("Year", p.year.into()),
        ("Month", p.month.into()),
        ("Day", p.day.into()),
        ("Hour", p.hour.into()),
        ("Min", p.min.into()),
        ("Sec", p.sec.into()),
        ("Valid", p.valid.into()),
        ("TAcc", p.t_acc.into()),
        ("Nano", p.nano.into()),
        ("FixType", p.fix_type.into()),
        ("Flags", p.flags.into()),
        ("NumSV", p.num_sv.into()),
        ("Reserved1", p.reserved1.into()),
        ("Lon", p.lon.into()),
        ("Lat", p.lat.into()),
        ("Height", p.height.into()),
        ("HMSL", p.hmsl.into()),
        ("HAcc", p.h_acc.into()),
        ("VAcc", p.v_acc.into()),
        ("VelN", p.vel_n.into()),
        ("VelE", p.vel_e.into()),
        ("VelD", p.vel_d.into()),
        ("GSpeed", p.g_speed.into()),
        ("HeadMot", p.head_mot.into()),
        ("SAcc", p.s_acc.into()),
        ("HeadAcc", p.head_acc.into()),
        ("HeadVeh", p.head_veh.into()),
        ("GDOP", p.gdop.into()),
        ("PDOP", p.pdop.into()),
        ("TDOP", p.tdop.into()),
        ("VDOP", p.vdop.into()),
        ("HDOP", p.hdop.into()),
        ("NDOP", p.ndop.into()),
        ("EDOP", p.edop.into()),
    ];
    fields.iter().map(|(k, v)| format!("{k}:{v}")).collect()
}

#[derive(Default, Debug)]
struct Tally {
    floats: usize,
    others: usize,
    golden_lines: usize,
    messages: usize,
}

/// Checks one decoded item against its golden entry; returns a description of the first mismatch.
fn check_item(
    id: DataId,
    value: &Value<'_>,
    golden: &[String],
    tally: &mut Tally,
) -> Result<(), String> {
    let floats = value.floats();
    if !floats.is_empty() {
        let labels = float_labels(id, floats.len());
        if golden.len() != floats.len() {
            return Err(format!(
                "{} values, golden has {}",
                floats.len(),
                golden.len()
            ));
        }
        for ((label, ours), g) in labels.iter().zip(floats).zip(golden) {
            let text = if label.is_empty() {
                g.as_str()
            } else {
                g.strip_prefix(label)
                    .and_then(|r| r.strip_prefix(':'))
                    .ok_or(format!("golden {g:?} lacks label {label}"))?
            };
            if !float_matches(text, *ours, id.precision()) {
                return Err(format!("{label}: ours {ours:e}, golden {text}"));
            }
            tally.floats += 1;
        }
        return Ok(());
    }
    let ours: Vec<String> = match value {
        Value::PacketCounter(v) => vec![v.to_string()],
        Value::SampleTimeFine(v) | Value::SampleTimeCoarse(v) | Value::BaroPressure(v) => {
            vec![v.to_string()]
        }
        Value::UtcTime(t) => vec![t.to_string()],
        Value::StatusWord(s) => vec![format!("{s:032b}")],
        Value::StatusByte(s) => vec![format!("{s:08b}")],
        Value::GnssPvtData(p) => pvt_lines(p),
        Value::GnssSatInfo(s) => vec![
            format!("ITOW:{}", s.itow),
            format!("NumSVS:{}", s.num_svs),
            format!("Res1:{}", s.reserved[0]),
            format!("Res2:{}", s.reserved[1]),
            format!("Res3:{}", s.reserved[2]),
        ],
        other => return Err(format!("no golden form for {other:?}")),
    };
    if ours != golden {
        return Err(format!("ours {ours:?}, golden {golden:?}"));
    }
    tally.others += ours.len();
    Ok(())
}

fn check_capture(dir: &Path, tally: &mut Tally) {
    let bin = fs::read(dir.join("output.bin")).expect("output.bin");
    let golden = parse_golden(&fs::read_to_string(dir.join("output.golden")).expect("golden"));
    tally.golden_lines += golden
        .iter()
        .flatten()
        .map(|(_, values)| values.len())
        .sum::<usize>();
    let payloads = decode_frames(&bin);
    assert_eq!(
        payloads.len(),
        golden.len(),
        "{}: message count",
        dir.display()
    );
    for (m, (payload, gmsg)) in payloads.iter().zip(&golden).enumerate() {
        let Ok(Message::MtData2(data)) = Message::decode_payload(0x36, payload) else {
            panic!("not MTData2")
        };
        let items: Vec<_> = data.items().map(|i| i.expect("item")).collect();
        let names: Vec<String> = items.iter().map(|i| i.id.to_string()).collect();
        let gnames: Vec<&String> = gmsg.iter().map(|(n, _)| n).collect();
        assert_eq!(
            names.iter().collect::<Vec<_>>(),
            gnames,
            "{} message {m}: item names",
            dir.display()
        );
        for (item, (name, gvalues)) in items.iter().zip(gmsg) {
            let value = item.value().expect("value");
            if let Err(e) = check_item(item.id, &value, gvalues, tally) {
                panic!("{} message {m} item {name}: {e}", dir.display());
            }
        }
        tally.messages += 1;
    }
}

#[test]
fn every_golden_value_is_reproduced() {
    let Some(dirs) = capture_dirs() else { return };
    let mut tally = Tally::default();
    for dir in &dirs {
        check_capture(dir, &mut tally);
    }
    println!("{tally:?} over {} captures", dirs.len());
    assert_eq!(tally.messages, 500);
    assert_eq!(tally.floats, GOLDEN_FLOAT_VALUES, "float values compared");
    assert_eq!(
        tally.floats + tally.others,
        tally.golden_lines,
        "every golden line compared"
    );
}

fn rate_text(rate: u16) -> String {
    if rate == 0xFFFF {
        "Max".to_string()
    } else {
        format!("{rate} Hz")
    }
}

#[test]
fn output_configuration_acks_decode_to_their_goldens() {
    let Some(dirs) = capture_dirs() else { return };
    let mut checked = 0;
    for dir in &dirs {
        let payload = fs::read(dir.join("outputconfig.bin")).expect("outputconfig.bin");
        let golden = fs::read_to_string(dir.join("outputconfig.golden")).expect("golden");
        let expected: Vec<String> = golden.lines().map(str::to_string).collect();
        // The capture holds the ack's payload; frame it the way the device sends it (MID 0xC1)
        // and decode it through the framer and the message layer.
        let mut frame = vec![0u8; payload.len() + 7];
        let n = imu_driver::encode_frame(&mut frame, 0xFF, 0xC1, &payload).unwrap();
        let mut framer = imu_driver::DeviceFramer::new();
        let mut input = &frame[..n];
        let Poll::Frame(f) = framer.poll(&mut input) else {
            panic!("no frame")
        };
        let Ok(Message::OutputConfiguration(config)) = Message::decode(&f) else {
            panic!("not an OutputConfiguration")
        };
        assert_eq!(config, OutputConfiguration::new_checked(&payload).unwrap());
        let mut ours = Vec::new();
        for s in config.settings() {
            ours.push(format!("{}:", s.id));
            ours.push(format!("  {}", rate_text(s.rate_hz)));
        }
        assert_eq!(ours, expected, "{}", dir.display());
        checked += config.len();
    }
    assert_eq!(dirs.len(), 5);
    assert!(checked >= 5 * 13, "{checked} settings over the five acks");
}
