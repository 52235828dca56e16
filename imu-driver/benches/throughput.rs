//! Decoder throughput on the shared Xsens captures, side by side with the `xsens-mti` crate
//! decoding the same bytes in the same run.
//!
//! `cargo bench -p imu-driver --bench throughput` (skips with a line when the captures are absent).

use imu_driver::{frame_capacity, Framer, Message, Poll, Value};
use std::hint::black_box;
use std::time::{Duration, Instant};
use xsens_mti::prelude as x;

/// Totals one decoding pass produces (compared between passes and printed).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct Pass {
    messages: u64,
    items: u64,
    values: u64,
    errors: u64,
    sum: f64,
}

type Big = Framer<{ frame_capacity(65_535) }>;

fn ours_frames(data: &[u8]) -> Pass {
    let mut framer = Big::new();
    let mut input = data;
    let mut p = Pass::default();
    loop {
        match framer.poll(&mut input) {
            Poll::Frame(f) => {
                p.messages += 1;
                p.sum += f64::from(f.checksum());
            }
            Poll::Dropped { .. } => p.errors += 1,
            Poll::NeedMore => break,
        }
    }
    p
}

fn ours_values(framer: &mut Big, chunk: &[u8], p: &mut Pass) {
    let mut input = chunk;
    loop {
        match framer.poll(&mut input) {
            Poll::Frame(f) => {
                p.messages += 1;
                if let Ok(Message::MtData2(m)) = Message::decode(&f) {
                    for item in m.items() {
                        p.items += 1;
                        match item.and_then(|i| i.value()) {
                            Ok(v) => {
                                p.values += 1;
                                p.sum += match v {
                                    Value::PacketCounter(c) => f64::from(c),
                                    Value::SampleTimeFine(t) => f64::from(t),
                                    other => other.floats().iter().sum(),
                                };
                            }
                            Err(_) => p.errors += 1,
                        }
                    }
                }
            }
            Poll::Dropped { .. } => p.errors += 1,
            Poll::NeedMore => break,
        }
    }
}

fn ours_full(data: &[u8], chunk: usize) -> Pass {
    let mut framer = Big::new();
    let mut p = Pass::default();
    for c in data.chunks(chunk) {
        ours_values(&mut framer, c, &mut p);
    }
    p
}

fn theirs_frames(data: &[u8], buf: &mut [u8]) -> Pass {
    let mut dec = x::Decoder::new(buf).expect("decoder buffer");
    let mut p = Pass::default();
    for &b in data {
        match dec.decode(b) {
            Ok(Some(f)) => {
                p.messages += 1;
                p.sum += f64::from(f.checksum().unwrap_or(0));
            }
            Ok(None) => {}
            Err(_) => p.errors += 1,
        }
    }
    p
}

/// Decodes the values `xsens-mti` has types for (Float32, Float64 and the raw fixed-point words).
fn theirs_item(pkt: &xsens_mti::wire::MTData2Packet<&[u8]>, p: &mut Pass) -> Result<(), ()> {
    use x::{DataType as T, Precision as P};
    let d = pkt.payload();
    let id = pkt.data_id();
    macro_rules! vec3 {
        ($t:ident, $a:ident, $b:ident, $c:ident) => {
            match id.precision() {
                P::Float32 => x::$t::<f32>::from_be_slice(d).map(|v| f64::from(v.$a + v.$b + v.$c)),
                P::Float64 => x::$t::<f64>::from_be_slice(d).map(|v| v.$a + v.$b + v.$c),
                P::Fp1220 => x::$t::<u32>::from_be_slice(d).map(|v| f64::from(v.$a ^ v.$b ^ v.$c)),
                _ => x::$t::<u64>::from_be_slice(d).map(|v| (v.$a ^ v.$b ^ v.$c) as f64),
            }
        };
    }
    let v = match id.data_type() {
        T::PacketCounter => x::PacketCounter::from_be_slice(d).map(|v| f64::from(v.0)),
        T::SampleTimeFine => x::SampleTimeFine::from_be_slice(d).map(|v| f64::from(v.0)),
        T::SampleTimeCoarse => x::SampleTimeCoarse::from_be_slice(d).map(|v| f64::from(v.0)),
        T::UtcTime => x::UtcTime::from_be_slice(d).map(|v| f64::from(v.ns)),
        T::StatusWord => x::StatusWord::from_be_slice(d).map(|v| f64::from(v.self_test())),
        T::Acceleration => vec3!(Acceleration, x, y, z),
        T::RateOfTurn => vec3!(RateOfTurn, x, y, z),
        T::MagneticField => vec3!(MagneticField, x, y, z),
        T::EulerAngles => vec3!(EulerAngles, roll, pitch, yaw),
        T::VelocityXYZ => vec3!(VelocityXYZ, x, y, z),
        T::PositionEcef => match id.precision() {
            P::Float32 => {
                x::PositionEcef::<f32>::from_be_slice(d).map(|v| f64::from(v.x + v.y + v.z))
            }
            P::Float64 => x::PositionEcef::<f64>::from_be_slice(d).map(|v| v.x + v.y + v.z),
            _ => return Err(()),
        },
        T::AltitudeEllipsoid => match id.precision() {
            P::Float32 => x::AltitudeEllipsoid::<f32>::from_be_slice(d).map(|v| f64::from(v.0)),
            P::Float64 => x::AltitudeEllipsoid::<f64>::from_be_slice(d).map(|v| v.0),
            P::Fp1220 => x::AltitudeEllipsoid::<u32>::from_be_slice(d).map(|v| f64::from(v.0)),
            _ => x::AltitudeEllipsoid::<u64>::from_be_slice(d).map(|v| v.0 as f64),
        },
        T::LatLon => match id.precision() {
            P::Float32 => x::LatLon::<f32>::from_be_slice(d).map(|v| f64::from(v.lat + v.lon)),
            P::Float64 => x::LatLon::<f64>::from_be_slice(d).map(|v| v.lat + v.lon),
            P::Fp1220 => x::LatLon::<u32>::from_be_slice(d).map(|v| f64::from(v.lat ^ v.lon)),
            _ => x::LatLon::<u64>::from_be_slice(d).map(|v| (v.lat ^ v.lon) as f64),
        },
        _ => return Err(()),
    };
    match v {
        Ok(v) => {
            p.values += 1;
            p.sum += v;
            Ok(())
        }
        Err(_) => Err(()),
    }
}

fn theirs_full(data: &[u8], buf: &mut [u8]) -> Pass {
    let mut dec = x::Decoder::new(buf).expect("decoder buffer");
    let mut p = Pass::default();
    for &b in data {
        match dec.decode(b) {
            Ok(Some(f)) => {
                p.messages += 1;
                if f.message_id() == <x::MTData2 as x::MessageExt>::MSG_ID {
                    if let Ok(m) = <x::MTData2 as x::MessageDecode>::decode(&f) {
                        for pkt in m {
                            p.items += 1;
                            match pkt {
                                Ok(pkt) => {
                                    if theirs_item(&pkt, &mut p).is_err() {
                                        p.errors += 1;
                                    }
                                }
                                Err(_) => p.errors += 1,
                            }
                        }
                    }
                }
            }
            Ok(None) => {}
            Err(_) => p.errors += 1,
        }
    }
    p
}

/// Runs `f` repeatedly for at least `min` (and 5 passes); returns (one pass's result, seconds per pass).
fn measure(min: Duration, mut f: impl FnMut() -> Pass) -> (Pass, f64) {
    let first = black_box(f());
    let start = Instant::now();
    let mut passes = 0u32;
    while passes < 5 || start.elapsed() < min {
        let p = black_box(f());
        assert_eq!(p.messages, first.messages);
        passes += 1;
    }
    (first, start.elapsed().as_secs_f64() / f64::from(passes))
}

fn main() {
    let Some(dir) = milliego_tests::captures_dir("xsens") else {
        return;
    };
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("captures dir")
        .filter_map(|e| e.ok().map(|e| e.path().join("output.bin")))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    let data: Vec<u8> = files
        .iter()
        .flat_map(|f| std::fs::read(f).expect("capture"))
        .collect();
    let min = Duration::from_millis(
        std::env::var("BENCH_MS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1000),
    );
    println!(
        "xsens decoder throughput: {} captures, {} bytes per pass, >= {} ms per row",
        files.len(),
        data.len(),
        min.as_millis()
    );
    let mut buf = vec![0u8; 65_542];
    let rows: Vec<(&str, (Pass, f64))> = vec![
        (
            "imu-driver  frames (whole buffer)",
            measure(min, || ours_frames(&data)),
        ),
        (
            "xsens-mti   frames (byte by byte)",
            measure(min, || theirs_frames(&data, &mut buf)),
        ),
        (
            "imu-driver  frames+items (whole)",
            measure(min, || ours_full(&data, data.len())),
        ),
        (
            "imu-driver  frames+items (64 B reads)",
            measure(min, || ours_full(&data, 64)),
        ),
        (
            "xsens-mti   frames+items",
            measure(min, || theirs_full(&data, &mut buf)),
        ),
    ];
    println!(
        "{:<40} {:>10} {:>13} {:>9} {:>8} {:>7} {:>7}",
        "decoder", "MB/s", "messages/s", "messages", "items", "values", "errors"
    );
    for (name, (p, secs)) in &rows {
        println!(
            "{name:<40} {:>10.1} {:>13.0} {:>9} {:>8} {:>7} {:>7}",
            data.len() as f64 / secs / 1e6,
            p.messages as f64 / secs,
            p.messages,
            p.items,
            p.values,
            p.errors
        );
    }
    let secs = |i: usize| rows[i].1 .1;
    println!(
        "ratio imu-driver / xsens-mti: frames {:.1}x, frames+items {:.1}x (64 B reads: {:.1}x)",
        secs(1) / secs(0),
        secs(4) / secs(2),
        secs(4) / secs(3)
    );
    println!(
        "note: xsens-mti has no types for Temperature, Quaternion, RotationMatrix, DeltaV, DeltaQ, \
         FreeAcceleration, GNSS or StatusByte (counted as errors); it returns fixed-point values \
         as raw words and reads Fp16.32 as 8-byte words (the wire has 6), so those items fail"
    );
}
