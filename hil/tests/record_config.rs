//! `record` with configuration, against scripted fake sensors on pseudo-terminals: the radar's
//! .cfg is uploaded over its CLI port and `sensorStop` sent at the end; the IMU gets its output
//! configuration, measurement mode, and GoToConfig at the end; the data the fakes stream is
//! recorded unchanged.
#![cfg(unix)]

mod common;

use common::{imu_msg, radar_frame};
use imu_driver::message::mid;
use imu_driver::{encode_frame, DeviceFramer, Poll};
use milliego_hil::{record, ImuPort, Live, RadarPorts, RecordConfig, StreamKind};
use milliego_session::Session;
use serialport::{SerialPort, TTYPort};
use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

fn pair() -> (TTYPort, TTYPort, String) {
    let (mut master, slave) = TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(2)).unwrap();
    let path = slave.name().unwrap();
    (master, slave, path)
}

/// A radar: answers every CLI line with Done; streams a frame every 20 ms on the data port between
/// sensorStart and sensorStop. Returns the lines seen and the data bytes sent.
fn fake_radar(
    mut cli: TTYPort,
    mut data: TTYPort,
    stop: Arc<AtomicBool>,
) -> thread::JoinHandle<(Vec<String>, Vec<u8>)> {
    thread::spawn(move || {
        let mut lines = Vec::new();
        let mut sent = Vec::new();
        let mut line = Vec::new();
        let mut streaming = false;
        let mut n = 1;
        let mut next = Instant::now();
        let mut b = [0u8; 256];
        while !stop.load(Ordering::Relaxed) {
            if streaming && Instant::now() >= next {
                let f = radar_frame(n);
                n += 1;
                data.write_all(&f).unwrap();
                sent.extend_from_slice(&f);
                next += Duration::from_millis(20);
            }
            let k = match cli.read(&mut b) {
                Ok(k) => k,
                Err(e) if e.kind() == ErrorKind::TimedOut => continue,
                Err(_) => break,
            };
            for &c in &b[..k] {
                if c != b'\n' {
                    line.push(c);
                    continue;
                }
                let text = String::from_utf8_lossy(&line).trim().to_string();
                line.clear();
                let _ = write!(cli, "{text}\r\nDone\r\nmmwDemo:/>");
                if text.starts_with("sensorStart") {
                    streaming = true;
                    next = Instant::now();
                }
                if text == "sensorStop" {
                    streaming = false;
                }
                lines.push(text);
            }
        }
        thread::sleep(Duration::from_millis(100));
        (lines, sent)
    })
}

/// An MTi: acks the configuration steps, streams MTData2 every 10 ms in measurement mode.
/// Returns the MIDs received and the MTData2 bytes sent.
fn fake_imu(mut port: TTYPort, stop: Arc<AtomicBool>) -> thread::JoinHandle<(Vec<u8>, Vec<u8>)> {
    thread::spawn(move || {
        let mut framer = DeviceFramer::new();
        let mut mids = Vec::new();
        let mut sent = Vec::new();
        let mut streaming = false;
        let mut counter = 0u16;
        let mut next = Instant::now();
        let mut buf = [0u8; 512];
        let send = |port: &mut TTYPort, m: u8, payload: &[u8]| {
            let mut out = vec![0u8; payload.len() + 7];
            let n = encode_frame(&mut out, 0xFF, m, payload).unwrap();
            port.write_all(&out[..n]).unwrap();
        };
        while !stop.load(Ordering::Relaxed) {
            if streaming && Instant::now() >= next {
                let m = imu_msg(counter);
                counter = counter.wrapping_add(1);
                port.write_all(&m).unwrap();
                sent.extend_from_slice(&m);
                next += Duration::from_millis(10);
            }
            let n = match port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == ErrorKind::TimedOut => continue,
                Err(_) => break,
            };
            let mut input = &buf[..n];
            let mut got = Vec::new();
            loop {
                match framer.poll(&mut input) {
                    Poll::Frame(f) => got.push((f.mid(), f.payload().to_vec())),
                    Poll::Dropped { .. } => {}
                    Poll::NeedMore => break,
                }
            }
            for (m, payload) in got {
                mids.push(m);
                match m {
                    mid::GO_TO_CONFIG => {
                        streaming = false;
                        send(&mut port, mid::GO_TO_CONFIG_ACK, &[]);
                    }
                    mid::REQ_DID => send(&mut port, mid::DEVICE_ID, &[0x03, 0x70, 0x12, 0x34]),
                    mid::REQ_PRODUCT_CODE => send(&mut port, mid::PRODUCT_CODE, b"MTi-3-8A7G6 "),
                    mid::REQ_FW_REV => send(
                        &mut port,
                        mid::FIRMWARE_REV,
                        &[1, 8, 2, 0, 0, 0, 7, 0, 0, 0, 9],
                    ),
                    mid::SET_OUTPUT_CONFIGURATION => {
                        send(&mut port, mid::OUTPUT_CONFIGURATION, &payload)
                    }
                    mid::GO_TO_MEASUREMENT => {
                        send(&mut port, mid::GO_TO_MEASUREMENT_ACK, &[]);
                        streaming = true;
                        // The first message comes a little after the ack, as on a device.
                        next = Instant::now() + Duration::from_millis(30);
                    }
                    _ => {}
                }
            }
        }
        thread::sleep(Duration::from_millis(100));
        (mids, sent)
    })
}

#[test]
fn record_configures_both_sensors_records_their_bytes_and_stops_them() {
    let (cli_m, _cli_s, cli_path) = pair();
    let (data_m, _data_s, data_path) = pair();
    let (imu_m, _imu_s, imu_path) = pair();
    let stop_fakes = Arc::new(AtomicBool::new(false));
    let radar = fake_radar(cli_m, data_m, stop_fakes.clone());
    let imu = fake_imu(imu_m, stop_fakes.clone());
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rec");
    let cfg_text = "sensorStop\nflushCfg\nframeCfg 0 0 16 0 20 1 0\nsensorStart\n";
    let cfg = RecordConfig {
        out: out.clone(),
        radar: Some(RadarPorts {
            data: data_path,
            data_baud: 921_600,
            cli: Some(cli_path),
            cfg: Some(cfg_text.into()),
        }),
        imu: Some(ImuPort {
            path: imu_path,
            baud: 115_200,
            rate_hz: 100,
        }),
        configure: true,
        duration: Some(Duration::from_millis(1000)),
        ..RecordConfig::default()
    };
    let report = record(&cfg, &Arc::new(Live::default())).unwrap();
    assert!(report.warnings.is_empty(), "{:?}", report.warnings);
    thread::sleep(Duration::from_millis(100));
    stop_fakes.store(true, Ordering::Relaxed);
    let (lines, radar_sent) = radar.join().unwrap();
    let (mids, imu_sent) = imu.join().unwrap();

    // The radar got the file and, at the end, sensorStop.
    assert_eq!(
        &lines[..4],
        &[
            "sensorStop",
            "flushCfg",
            "frameCfg 0 0 16 0 20 1 0",
            "sensorStart"
        ]
    );
    assert_eq!(lines.last().map(String::as_str), Some("sensorStop"));
    // The IMU was configured, measured, and sent back to config mode.
    let pos = |m: u8| mids.iter().position(|&x| x == m);
    assert!(pos(mid::SET_OUTPUT_CONFIGURATION) < pos(mid::GO_TO_MEASUREMENT));
    assert_eq!(mids.last(), Some(&mid::GO_TO_CONFIG));

    // Recorded bytes: the radar's data port was open before sensorStart, so everything sent up to
    // the end of recording is there, unchanged; the IMU's messages after configuration likewise.
    let rec_radar = std::fs::read(out.join("radar.bin")).unwrap();
    assert!(rec_radar.len() >= 10 * 96, "{} B", rec_radar.len());
    assert!(radar_sent.starts_with(&rec_radar));
    let rec_imu = std::fs::read(out.join("imu.bin")).unwrap();
    assert!(rec_imu.len() >= 20 * 40, "{} B", rec_imu.len());
    assert!(imu_sent.starts_with(&rec_imu));
    let r = report
        .streams
        .iter()
        .find(|s| s.stream == StreamKind::Radar)
        .unwrap();
    assert_eq!(r.frames_bad, 0);
    assert_eq!(r.bytes_skipped, 0);
    let i = report
        .streams
        .iter()
        .find(|s| s.stream == StreamKind::Imu)
        .unwrap();
    assert_eq!(i.frames_bad, 0);
    assert_eq!(i.bytes_skipped, 0);

    let s = Session::open(&out).unwrap();
    assert_eq!(s.radar_cfg().unwrap().as_deref(), Some(cfg_text));
    assert_eq!(
        s.meta.imu.as_ref().unwrap().device.as_deref(),
        Some("MTi-3-8A7G6")
    );
    assert_eq!(s.meta.imu.as_ref().unwrap().rate_hz, Some(100.0));
}

#[test]
fn a_silent_imu_fails_the_setup_naming_its_port_and_writes_no_session() {
    let (_imu_m, _imu_s, imu_path) = pair(); // nobody answers on the master side
    let (data_m, _data_s, data_path) = pair();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rec");
    let cfg = RecordConfig {
        out: out.clone(),
        radar: Some(RadarPorts {
            data: data_path,
            data_baud: 921_600,
            cli: Some("/dev/null".into()),
            cfg: Some("sensorStart\n".into()),
        }),
        imu: Some(ImuPort {
            path: imu_path.clone(),
            baud: 115_200,
            rate_hz: 100,
        }),
        configure: true,
        duration: Some(Duration::from_secs(5)),
        ..RecordConfig::default()
    };
    let t = Instant::now();
    let e = record(&cfg, &Arc::new(Live::default())).unwrap_err();
    let m = e.to_string();
    assert!(
        m.starts_with("imu configuration failed") && m.contains(&imu_path),
        "{m}"
    );
    assert!(
        t.elapsed() < Duration::from_secs(4),
        "gave up after {:?}",
        t.elapsed()
    );
    assert!(!out.join("session.toml").exists());
    drop(data_m);
}

#[test]
fn configuring_the_radar_needs_its_cli_port_and_cfg() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = RecordConfig {
        out: dir.path().join("rec"),
        radar: Some(RadarPorts {
            data: "/dev/null".into(),
            data_baud: 921_600,
            cli: None,
            cfg: None,
        }),
        configure: true,
        ..RecordConfig::default()
    };
    let e = record(&cfg, &Arc::new(Live::default())).unwrap_err();
    assert!(e.to_string().contains("--radar-cli"), "{e}");
}
