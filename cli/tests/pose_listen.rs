//! `milliego pose listen` over real loopback UDP: every datagram decoded, a corrupt one dropped
//! and counted, a sequence gap reported, the TUM file written.

use pose_link::{PoseMessage, MESSAGE_LEN};
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::process::{Command, Stdio};

#[test]
fn listen_decodes_datagrams_and_reports_drops_and_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let tum = dir.path().join("poses.tum");
    let mut child = Command::new(env!("CARGO_BIN_EXE_milliego"))
        .args([
            "pose",
            "listen",
            "udp://127.0.0.1:0",
            "--count",
            "3",
            "--seconds",
            "20",
            "--tum",
        ])
        .arg(&tum)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    err.read_line(&mut first).unwrap();
    let addr = first.trim().rsplit("udp://").next().unwrap().to_string();
    assert!(first.contains("listening on udp://127.0.0.1:"), "{first}");

    let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let send = |m: &PoseMessage, corrupt: bool| {
        let mut b = [0u8; MESSAGE_LEN];
        m.encode(&mut b).unwrap();
        if corrupt {
            b[40] ^= 1;
        }
        tx.send_to(&b, &addr).unwrap();
    };
    for (seq, corrupt) in [(1u32, false), (2, true), (3, false), (5, false)] {
        let m = PoseMessage {
            seq,
            measurement_time_ns: u64::from(seq) * 50_000_000,
            position: [f64::from(seq), 0.0, 0.0],
            ..PoseMessage::default()
        };
        send(&m, corrupt);
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    let lines: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        lines
            .iter()
            .map(|l| l["seq"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        vec![1, 3, 5]
    );
    assert!(rest.contains("CRC mismatch"), "{rest}");
    assert!(
        rest.contains("\"seq_gaps\":2") && rest.contains("\"seq_missing\":2"),
        "{rest}"
    );
    let tum_text = std::fs::read_to_string(&tum).unwrap();
    assert_eq!(tum_text.lines().count(), 3);
    assert!(
        tum_text
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("0.150000000 3 0 0 0 0 0 1"),
        "{tum_text}"
    );
}
