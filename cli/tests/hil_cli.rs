//! `milliego replay` and `milliego record` as a test engineer runs them: the replay prints one
//! `STREAM: PATH` line per pty on stdout, waits until they are opened, and streams the session;
//! `milliego record --no-config` on those paths writes the same bytes.
#![cfg(unix)]

use imu_driver::{DataId, MtData2Writer, Value};
use milliego_session::{Meta, Session, SessionWriter, Source, StreamKind};
use radar_driver::encode::FrameBuilder;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn session(dir: &Path) {
    let mut w = SessionWriter::create(dir, Meta::new(Source::Simulated)).unwrap();
    let mut radar = w.stream(StreamKind::Radar).unwrap();
    let mut imu = w.stream(StreamKind::Imu).unwrap();
    for n in 0..10u32 {
        let pts = [[1.0, 2.0, 0.0, 0.5]; 3];
        let f = FrameBuilder::oob(0x0303_0002, 0xA6843, n + 1)
            .points(&pts)
            .to_vec();
        radar.write_chunk(u64::from(n) * 50_000_000, &f).unwrap();
    }
    for n in 0..50u16 {
        let mut buf = [0u8; 64];
        let mut m = MtData2Writer::new(&mut buf);
        m.value(DataId(0x1020), &Value::PacketCounter(n)).unwrap();
        let len = m.finish(0xFF).unwrap();
        imu.write_chunk(u64::from(n) * 10_000_000, &buf[..len])
            .unwrap();
    }
    radar.finish().unwrap();
    imu.finish().unwrap();
    w.finish().unwrap();
}

fn drain(path: &str) -> std::thread::JoinHandle<Vec<u8>> {
    let mut port = serialport::new(path, 921_600)
        .timeout(Duration::from_millis(20))
        .open()
        .unwrap();
    std::thread::spawn(move || {
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            match port.read(&mut buf) {
                Ok(n) if n > 0 => out.extend_from_slice(&buf[..n]),
                Ok(_) => break,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(_) => break, // the replay closed the pty
            }
        }
        out
    })
}

#[test]
fn replay_prints_the_pty_paths_and_streams_the_session_into_them() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    session(&s);
    let mut child = Command::new(BIN)
        .args([
            "replay",
            s.to_str().unwrap(),
            "--speed",
            "4",
            "--wait-open",
            "--linger",
            "0.3",
        ])
        .args(["--garbage", "10:5", "--seed", "1"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let radar = lines.next().unwrap().unwrap();
    let imu = lines.next().unwrap().unwrap();
    let radar = radar.strip_prefix("radar: ").expect(&radar).to_string();
    let imu = imu.strip_prefix("imu: ").expect(&imu).to_string();
    let (r, i) = (drain(&radar), drain(&imu));
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let (r, i) = (r.join().unwrap(), i.join().unwrap());
    let sess = Session::open(&s).unwrap();
    let want_r = sess.radar.unwrap().read_all().unwrap();
    let want_i = sess.imu.unwrap().read_all().unwrap();
    // Garbage bursts were inserted between frames: the session's bytes are what is left once the
    // reported number of garbage bytes is taken out.
    let garbage = |name: &str| -> usize {
        let line = stderr.lines().rfind(|l| l.starts_with(name)).expect(name);
        let at = line.find(" garbage bursts (").unwrap() + " garbage bursts (".len();
        line[at..].split(' ').next().unwrap().parse().unwrap()
    };
    assert_eq!(r.len(), want_r.len() + garbage("radar:"), "{stderr}");
    assert_eq!(i.len(), want_i.len() + garbage("imu:"), "{stderr}");
    assert!(stderr.contains("replay done"), "{stderr}");
}

#[test]
fn record_writes_what_replay_sends() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    session(&s);
    let mut replay = Command::new(BIN)
        .args([
            "replay",
            s.to_str().unwrap(),
            "--fast",
            "--wait-open",
            "--linger",
            "0.5",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(replay.stdout.take().unwrap()).lines();
    let radar = lines.next().unwrap().unwrap()["radar: ".len()..].to_string();
    let imu = lines.next().unwrap().unwrap()["imu: ".len()..].to_string();
    let rec = dir.path().join("rec");
    let out = Command::new(BIN)
        .args([
            "record",
            "-o",
            rec.to_str().unwrap(),
            "--no-config",
            "--quiet",
        ])
        .args(["--radar-data", &radar, "--imu", &imu, "--duration", "3"])
        .output()
        .unwrap();
    assert!(replay.wait().unwrap().success());
    // The replay closes its ptys after lingering: the recorder reports the port that went away.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("read failed") && stderr.contains("/dev/"),
        "{stderr}"
    );
    let src = Session::open(&s).unwrap();
    assert!(
        std::fs::read(rec.join("radar.bin")).unwrap() == src.radar.unwrap().read_all().unwrap()
    );
    assert!(std::fs::read(rec.join("imu.bin")).unwrap() == src.imu.unwrap().read_all().unwrap());
}

#[test]
fn bad_options_name_themselves() {
    let out = Command::new(BIN)
        .args(["replay", "/nonexistent/session", "--fast"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("/nonexistent/session"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    session(&s);
    for (args, what) in [
        (vec!["--stall", "gps@1+1"], "gps"),
        (vec!["--garbage", "abc"], "--garbage"),
        (vec!["--drop", "1.5"], "--drop"),
        (vec!["--linger=-1"], "--linger"),
    ] {
        let out = Command::new(BIN)
            .args(["replay", s.to_str().unwrap()])
            .args(&args)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && e.contains(what), "{args:?}: {e}");
    }
    let out = Command::new(BIN)
        .args(["record", "-o", dir.path().join("r").to_str().unwrap()])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && e.contains("nothing to record"),
        "{e}"
    );
    // Through the hub: its spec, its exclusivity with the sensor ports, a missing device.
    let r = dir.path().join("h");
    for (args, what) in [
        (vec!["--hub", "/dev/ttyACM0", "--no-config"], "serial:DEV"),
        (vec!["--hub", "serial:/dev/x@fast", "--no-config"], "fast"),
        (vec!["--hub", "serial:/dev/x", "--imu", "/dev/y"], "--imu"),
        (
            vec!["--hub", "serial:/nonexistent/hub", "--no-config"],
            "/nonexistent/hub",
        ),
        (vec!["--hub", "serial:/nonexistent/hub"], "--radar-cli"),
    ] {
        let out = Command::new(BIN)
            .args(["record", "-o", r.to_str().unwrap()])
            .args(&args)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && e.contains(what), "{args:?}: {e}");
    }
}
