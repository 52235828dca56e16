//! The live Foxglove view (`milliego view`, `run --foxglove`) seen by an independent client:
//! `scripts/foxglove-client.py` (Python `websockets` + `foxglove-schemas-protobuf`) connects over
//! loopback with the `foxglove.websocket.v1` subprotocol, subscribes to every advertised channel
//! and decodes every message. Its values are checked against the session and the TUM file the
//! same run wrote. A client that subscribes and then stops reading must not slow the pose stream
//! (UDP to a loopback socket this test reads).
//!
//! Needs a Python with `websockets` and `foxglove-schemas-protobuf` (`MILLIEGO_EVO_PYTHON`, the
//! evo venv CI sets up; a skip line otherwise, a failure with `MILLIEGO_REQUIRE_EVO=1`).

use milliego_session::{read_tum, Session};
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn client_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/foxglove-client.py")
}

fn python() -> Option<String> {
    let py = std::env::var("MILLIEGO_EVO_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import websockets, foxglove_schemas_protobuf"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        let msg = format!(
            "skipped: websockets / foxglove-schemas-protobuf not importable by {py} (set MILLIEGO_EVO_PYTHON)"
        );
        assert!(
            std::env::var("MILLIEGO_REQUIRE_EVO").as_deref() != Ok("1"),
            "{msg}"
        );
        println!("{msg}");
        return None;
    }
    Some(py)
}

fn sim(dir: &Path, seconds: &str) {
    let out = Command::new(BIN)
        .args([
            "sim",
            "--family",
            "office",
            "--motion",
            "handheld",
            "--seed",
            "5",
            "--duration",
            seconds,
            "-o",
        ])
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "sim: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Starts `milliego args...` and returns it with the live view's `ws://` URL from its stderr
/// (the rest of stderr is collected in a thread).
fn start_view(args: &[&str]) -> (Child, String, std::thread::JoinHandle<String>) {
    let mut child = Command::new(BIN)
        .args(args)
        // The SDK reports a client's full queue at info level.
        .env("RUST_LOG", "warn,foxglove=info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    let url = loop {
        let mut line = String::new();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "milliego ended before its view started:\n{seen}"
        );
        seen.push_str(&line);
        if let Some(rest) = line.strip_prefix("live view: ws://") {
            break format!("ws://{}", rest.split_whitespace().next().unwrap());
        }
    };
    let rest = std::thread::spawn(move || {
        let mut s = seen;
        std::io::Read::read_to_string(&mut err, &mut s).unwrap();
        s
    });
    (child, url, rest)
}

fn client(py: &str, url: &str, out: &Path, extra: &[&str]) -> Child {
    Command::new(py)
        .arg(client_script())
        .arg(url)
        .arg("-o")
        .arg(out)
        .args(extra)
        .spawn()
        .unwrap()
}

fn json_file(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn an_independent_client_decodes_every_channel_and_matches_the_session() {
    let Some(py) = python() else { return };
    let d = tempfile::tempdir().unwrap();
    let session = d.path().join("s");
    sim(&session, "6");
    let tum = d.path().join("run.tum");
    let summary = d.path().join("summary.json");
    let seen = d.path().join("client.json");
    let s = session.to_str().unwrap();
    let (child, url, stderr) = start_view(&[
        "view",
        s,
        "--speed",
        "3",
        "--foxglove",
        "127.0.0.1:0",
        "--wait",
        "30",
        "--estimator",
        "doppler",
        "--out",
        &format!("tum:{}", tum.display()),
        "--summary-json",
        summary.to_str().unwrap(),
    ]);
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");
    let mut c = client(&py, &url, &seen, &["--seconds", "60"]);
    let out = child.wait_with_output().unwrap();
    let err = stderr.join().unwrap();
    assert!(out.status.success(), "milliego view failed:\n{err}");
    assert!(c.wait().unwrap().success(), "client failed");
    let j = json_file(&seen);
    let sum = json_file(&summary);
    assert_eq!(j["errors"], serde_json::json!([]), "client errors");

    // Channels: well-known schemas in protobuf, the custom ones in JSON with a JSON schema.
    let ch = &j["channels"];
    for (topic, schema, enc) in [
        ("/radar/points", "foxglove.PointCloud", "protobuf"),
        ("/pose", "foxglove.PoseInFrame", "protobuf"),
        ("/trajectory", "foxglove.PosesInFrame", "protobuf"),
        ("/tf", "foxglove.FrameTransforms", "protobuf"),
        ("/ground_truth/pose", "foxglove.PoseInFrame", "protobuf"),
        (
            "/ground_truth/trajectory",
            "foxglove.PosesInFrame",
            "protobuf",
        ),
        ("/imu", "milliego.Imu", "json"),
        ("/velocity", "milliego.Velocity", "json"),
        ("/health", "milliego.Health", "json"),
    ] {
        assert_eq!(ch[topic]["schemaName"], schema, "{topic}: {ch}");
        assert_eq!(ch[topic]["encoding"], enc, "{topic}");
        assert!(
            j["counts"][topic].as_u64().unwrap_or(0) > 0,
            "{topic}: no message"
        );
    }
    assert_eq!(sum["view_dropped"], 0, "{sum}");
    // A client that reads lost nothing either (every message is checked below).
    assert_eq!(sum["view_client_dropped"], 0, "{sum}");

    // Radar: one cloud per session frame, the same points in the same order.
    let sess = Session::open(&session).unwrap();
    let (frames, _) = milliego_session::streams::radar_frames(&sess).unwrap();
    let radar = j["radar"].as_array().unwrap();
    assert_eq!(radar.len(), frames.len(), "one cloud per frame");
    assert_eq!(sum["frames_in"]["radar"], frames.len() as u64);
    for (r, f) in radar.iter().zip(&frames) {
        assert_eq!(
            r["n"],
            f.cloud.points.len() as u64,
            "points of frame {}",
            f.frame_number
        );
        assert_eq!(r["frame"], "radar");
        assert_eq!(
            r["fields"],
            serde_json::json!(["x", "y", "z", "doppler", "snr"])
        );
        if let (Some(p), Some(first)) = (f.cloud.points.first(), r["first"].as_array()) {
            let got: Vec<f64> = first
                .iter()
                .map(|v| v.as_f64().unwrap_or(f64::NAN))
                .collect();
            let want = [p.x, p.y, p.z, p.velocity].map(f64::from);
            for k in 0..4 {
                assert!(
                    close(got[k], want[k], 1e-6),
                    "frame {}: {got:?} vs {want:?}",
                    f.frame_number
                );
            }
            if let Some(snr) = f.cloud.snr_db.as_ref().and_then(|s| s.first()) {
                assert!(close(got[4], f64::from(*snr), 1e-6));
            }
        }
    }

    // Poses: the TUM file of the same run, pose for pose.
    let est = read_tum(&tum).unwrap();
    let poses = j["pose"].as_array().unwrap();
    assert!(est.len() > 50, "{} poses", est.len());
    assert_eq!(poses.len(), est.len(), "one /pose per TUM line");
    assert_eq!(sum["frames_out"]["poses_sent"], est.len() as u64);
    for (p, e) in poses.iter().zip(&est) {
        assert!(close(p["t"].as_f64().unwrap(), e.t, 2e-9), "{p} vs {e:?}");
        for k in 0..3 {
            assert!(
                close(p["p"][k].as_f64().unwrap(), e.p[k], 1e-5),
                "{p} vs {e:?}"
            );
        }
        for k in 0..4 {
            assert!(
                close(p["q"][k].as_f64().unwrap(), e.q[k], 1e-6),
                "{p} vs {e:?}"
            );
        }
        assert_eq!(p["frame"], "world");
    }
    // The trajectory's last message holds every radar-rate pose.
    let traj = j["trajectory_last"]["poses"].as_array().unwrap();
    assert_eq!(traj.len(), est.len());
    let (last, e) = (traj.last().unwrap(), est.last().unwrap());
    for k in 0..3 {
        assert!(close(last[k].as_f64().unwrap(), e.p[k], 1e-5));
    }
    // Transforms: world -> body (the last pose), body -> radar / imu (the session's extrinsics).
    let tf = j["tf_last"].as_array().unwrap();
    let find = |child: &str| tf.iter().find(|t| t["child"] == child).unwrap();
    assert_eq!(find("body")["parent"], "world");
    for k in 0..3 {
        assert!(close(find("body")["t"][k].as_f64().unwrap(), e.p[k], 1e-5));
        let want = sess.meta.extrinsics.radar.translation_m[k];
        assert!(close(find("radar")["t"][k].as_f64().unwrap(), want, 1e-9));
        let want = sess.meta.extrinsics.imu.translation_m[k];
        assert!(close(find("imu")["t"][k].as_f64().unwrap(), want, 1e-9));
    }
    assert_eq!(find("radar")["parent"], "body");
    // IMU: every ordered sample.
    assert_eq!(j["imu"]["n"], sum["sync"]["imu_released"], "{sum}");
    assert!(j["imu"]["first"]["accel"]["z"].as_f64().unwrap().abs() > 5.0);
    assert_eq!(j["velocity_n"].as_u64().unwrap(), est.len() as u64 - 1);
    // Health: the estimator, the drop counters, the final count of poses.
    let h = &j["health_last"];
    assert_eq!(h["estimator"], "doppler");
    assert_eq!(h["active_estimator"], "doppler");
    assert_eq!(h["poses"], est.len() as u64);
    assert_eq!(h["view_dropped"], 0);
    assert_eq!(h["clock"]["mode"], "session fit");
    assert_eq!(h["drops"]["pose_queue"], 0);
    // Ground truth, aligned at the first pose.
    let gt = j["gt_pose"].as_array().unwrap();
    assert!(gt.len() + 2 >= est.len(), "{} ground-truth poses", gt.len());
    for k in 0..3 {
        assert!(close(
            gt[0]["p"][k].as_f64().unwrap(),
            poses[0]["p"][k].as_f64().unwrap(),
            1e-6
        ));
    }
    println!(
        "live view: {} clouds, {} poses, {} IMU samples, {} health messages decoded",
        radar.len(),
        poses.len(),
        j["imu"]["n"],
        j["health_n"]
    );
}

#[test]
fn a_client_that_stops_reading_does_not_slow_the_pose_stream() {
    let Some(py) = python() else { return };
    let d = tempfile::tempdir().unwrap();
    let session = d.path().join("s");
    sim(&session, "5");
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let udp = format!("udp://{}", rx.local_addr().unwrap());
    let summary = d.path().join("summary.json");
    let seen = d.path().join("client.json");
    let (mut child, url, stderr) = start_view(&[
        "view",
        session.to_str().unwrap(),
        "--foxglove",
        "127.0.0.1:0",
        "--wait",
        "30",
        // A short per-client queue: the stalled client's overflows within the session.
        "--backlog",
        "64",
        "--estimator",
        "doppler",
        "--out",
        &udp,
        "--summary-json",
        summary.to_str().unwrap(),
    ]);
    let mut c = client(&py, &url, &seen, &["--stall", "--seconds", "12"]);
    // Every pose, with its arrival time.
    let mut arrivals = Vec::new();
    let mut buf = [0u8; 256];
    let started = Instant::now();
    loop {
        match rx.recv(&mut buf) {
            Ok(n) => {
                let m = pose_link::PoseMessage::decode(&buf[..n]).unwrap();
                arrivals.push((Instant::now(), m.seq));
            }
            Err(_) => {
                if child.try_wait().unwrap().is_some()
                    || started.elapsed() > Duration::from_secs(60)
                {
                    break;
                }
            }
        }
    }
    let status = child.wait().unwrap();
    let err = stderr.join().unwrap();
    assert!(status.success(), "milliego view failed:\n{err}");
    let _ = c.kill();
    let _ = c.wait();
    let sum = json_file(&summary);
    let sent = sum["frames_out"]["poses_sent"].as_u64().unwrap();
    assert!(sent > 50, "{sum}");
    assert_eq!(arrivals.len() as u64, sent, "every pose arrived over UDP");
    for (i, (_, seq)) in arrivals.iter().enumerate() {
        assert_eq!(u64::from(*seq), i as u64, "in order, none lost");
    }
    // The rate is the radar's (20 Hz at the recorded pace): no stretch without poses.
    let gaps: Vec<f64> = arrivals
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).as_secs_f64())
        .collect();
    let max_gap = gaps.iter().copied().fold(0.0, f64::max);
    let span = (arrivals.last().unwrap().0 - arrivals[0].0).as_secs_f64();
    let rate = (arrivals.len() - 1) as f64 / span;
    println!(
        "stalled client: {} poses at {rate:.1} Hz, longest gap {:.1} ms, view_dropped {}, view_client_dropped {}",
        arrivals.len(),
        max_gap * 1e3,
        sum["view_dropped"],
        sum["view_client_dropped"]
    );
    // Bounds with room for a loaded CI machine; a pose path waiting on the stalled client would
    // stop the stream for good.
    assert!((17.0..23.0).contains(&rate), "rate {rate:.1} Hz");
    assert!(
        max_gap < 0.5,
        "a {:.0} ms gap in the pose stream",
        max_gap * 1e3
    );
    // The summary reports what the view's own hand-off dropped, and what the stalled client
    // lost: with 64 messages queued for it and 64 KiB of socket buffer, most of the session's
    // clouds, poses and IMU samples (thousands of messages) never reached it.
    assert!(sum["view_dropped"].is_u64(), "{sum}");
    let lost = sum["view_client_dropped"].as_u64().unwrap();
    let imu = sum["frames_in"]["imu"].as_u64().unwrap();
    assert!(
        lost > imu / 2,
        "the stalled client lost {lost} messages of a session with {imu} IMU samples: {sum}"
    );
    assert!(
        !err.contains("outbox for client"),
        "the SDK's own queue overflowed: the front did not drain it\n{err}"
    );
}
