//! `record` through the sensor hub: a fake hub on a pseudo-terminal sends radar frames and IMU
//! messages in the hub-link format (docs/hub-link.md), in odd chunks at host times unrelated to
//! its stamps, with a corrupted message, a sequence gap and health. The session gets each
//! sensor's forwarded bytes unchanged, one index record per frame on the hub's clock, and the
//! report counts the link's damage.
#![cfg(unix)]

mod common;

use common::{imu_msg, radar_frame};
use hub_link::{encode_serial, Header, Health, Kind, PortHealth};
use milliego_hil::{record, HubPort, Live, RecordConfig, StreamKind};
use milliego_session::Session;
use serialport::{SerialPort, TTYPort};
use std::io::Write;
use std::sync::Arc;
use std::thread;
use std::time::Duration;

fn message(kind: Kind, seq: u32, t_ns: u64, body: &[u8]) -> Vec<u8> {
    let h = Header {
        seq,
        t_ns,
        ..Header::default()
    };
    let mut w = Vec::new();
    encode_serial(kind, &h, &[body], &mut |b| w.push(b));
    w
}

fn health_body(frames: u32) -> Vec<u8> {
    let h = Health {
        timer_hz: 50_000_000,
        radar: PortHealth {
            frames_forwarded: frames,
            ..PortHealth::default()
        },
        ..Health::default()
    };
    h.to_bytes().to_vec()
}

#[test]
fn recording_through_the_hub_keeps_each_frame_on_the_hub_clock_and_counts_the_damage() {
    let (mut master, slave) = TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(2)).unwrap();
    let path = slave.name().unwrap();

    // The hub's output: every 50 ms of hub time a radar frame, and IMU messages every 10 ms.
    // Hub time starts at 7 s (its boot was long ago).
    let mut wire = Vec::new();
    let (mut radar_sent, mut imu_sent) = (Vec::new(), Vec::new());
    let (mut radar_t, mut imu_t) = (Vec::new(), Vec::new());
    let mut seq = 0u32;
    let t0 = 7_000_000_000u64;
    for k in 0..40u32 {
        let t = t0 + u64::from(k) * 10_000_000 + 1_234;
        if k % 5 == 0 {
            let f = radar_frame(k / 5 + 1);
            wire.push(message(Kind::Radar, seq, t, &f));
            radar_sent.extend_from_slice(&f);
            radar_t.push(t);
        } else if k == 13 {
            // Corrupted on the way: the link's CRC rejects it; its sequence number is missing.
            let mut m = message(Kind::Imu, seq, t, &imu_msg(k as u16));
            let mid = m.len() / 2;
            m[mid] = if m[mid] == 0xFF { 0x7F } else { m[mid] + 1 };
            wire.push(m);
        } else if k == 27 {
            // Dropped by the hub for backpressure: only the gap in the sequence shows it.
        } else {
            let m = imu_msg(k as u16);
            wire.push(message(Kind::Imu, seq, t, &m));
            imu_sent.extend_from_slice(&m);
            imu_t.push(t);
        }
        seq += 1;
        if k == 20 {
            wire.push(message(Kind::Health, seq, t + 5, &health_body(5)));
            seq += 1;
        }
    }
    wire.push(message(
        Kind::Health,
        seq,
        t0 + 500_000_000,
        &health_body(8),
    ));

    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("rec");
    let cfg = RecordConfig {
        out: out.clone(),
        hub: Some(HubPort {
            path,
            baud: 921_600,
            radar_cli: None,
            radar_cfg: Some("frameCfg 0 0 16 0 50 1 0\n".into()),
        }),
        configure: false,
        duration: Some(Duration::from_millis(1500)),
        ..RecordConfig::default()
    };
    let rec = thread::spawn(move || record(&cfg, &Arc::new(Live::default())));
    // The host reads the link in pieces that have nothing to do with the hub's stamps: 37-byte
    // writes with pauses that do not follow hub time.
    thread::sleep(Duration::from_millis(200));
    // A lone delimiter after the first message (a sender's flush): counted, nothing else.
    let mut bytes: Vec<u8> = wire[0].clone();
    bytes.push(0);
    bytes.extend(wire[1..].concat());
    for (i, c) in bytes.chunks(37).enumerate() {
        master.write_all(c).unwrap();
        if i % 9 == 0 {
            thread::sleep(Duration::from_millis(15));
        }
    }
    let report = rec.join().unwrap().unwrap();

    // Each sensor's bytes unchanged, less the damaged and dropped messages.
    assert_eq!(std::fs::read(out.join("radar.bin")).unwrap(), radar_sent);
    assert_eq!(std::fs::read(out.join("imu.bin")).unwrap(), imu_sent);
    // One index record per frame, at the hub's times (relative to the first message, exact to
    // the nanosecond).
    let s = Session::open(&out).unwrap();
    let times = |kind: StreamKind| -> Vec<u64> {
        let st = match kind {
            StreamKind::Radar => s.radar.as_ref().unwrap(),
            StreamKind::Imu => s.imu.as_ref().unwrap(),
        };
        st.chunks().iter().map(|c| c.host_ns.unwrap()).collect()
    };
    let (rt, it) = (times(StreamKind::Radar), times(StreamKind::Imu));
    assert_eq!(rt.len(), radar_t.len());
    assert_eq!(it.len(), imu_t.len());
    let base = rt[0];
    let rel = |v: &[u64]| -> Vec<i64> { v.iter().map(|&t| t as i64 - base as i64).collect() };
    let want = |v: &[u64]| -> Vec<i64> { v.iter().map(|&t| (t - radar_t[0]) as i64).collect() };
    assert_eq!(rel(&rt), want(&radar_t));
    assert_eq!(rel(&it), want(&imu_t));
    // The radar .cfg was kept; the ports say the hub.
    assert_eq!(
        s.radar_cfg().unwrap().as_deref(),
        Some("frameCfg 0 0 16 0 50 1 0\n")
    );
    assert!(
        s.meta.description.contains("sensor hub"),
        "{}",
        s.meta.description
    );

    let h = report.hub.expect("a hub record");
    assert_eq!(h.link_bytes, bytes.len() as u64);
    assert_eq!(h.bad_frames, 1, "the corrupted message");
    assert_eq!(h.empty_frames, 1, "the flush");
    assert_eq!(h.seq_gaps, 2, "the corrupted and the dropped message");
    assert_eq!(h.restarts, 0);
    assert_eq!(h.stamps_clamped, 0);
    assert_eq!(h.messages as usize, wire.len() - 1);
    assert_eq!(h.health.map(|x| x.radar.frames_forwarded), Some(8));
    for st in &report.streams {
        assert_eq!(st.bytes_read, st.bytes_written);
        assert_eq!(st.frames_bad, 0, "{:?}", st.stream);
        assert!(st.port.starts_with("hub "), "{}", st.port);
    }
}

#[test]
fn the_hub_excludes_the_sensor_ports_and_configuring_needs_the_radar_cli() {
    let hub = HubPort {
        path: "/dev/null-hub".into(),
        baud: 921_600,
        radar_cli: None,
        radar_cfg: None,
    };
    let dir = tempfile::tempdir().unwrap();
    let both = RecordConfig {
        out: dir.path().join("a"),
        hub: Some(hub.clone()),
        imu: Some(milliego_hil::ImuPort {
            path: "/dev/null".into(),
            baud: 115_200,
            rate_hz: 100,
        }),
        configure: false,
        ..RecordConfig::default()
    };
    let e = record(&both, &Arc::new(Live::default())).unwrap_err();
    assert!(e.to_string().contains("not both"), "{e}");
    let configure = RecordConfig {
        out: dir.path().join("b"),
        hub: Some(hub),
        configure: true,
        ..RecordConfig::default()
    };
    let e = record(&configure, &Arc::new(Live::default())).unwrap_err();
    assert!(e.to_string().contains("--radar-cli"), "{e}");
    assert!(!dir.path().join("a").exists() && !dir.path().join("b").exists());
}
