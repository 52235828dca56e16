//! `milliego run` on the HIL rig: a simulated session replayed into pseudo-terminals, the runtime
//! reading them as it would the sensors' UARTs and streaming poses over UDP to a socket here.

use milliego_eval::{evaluate, Settings, Trajectory};
use milliego_session::streams::{imu_samples, radar_frames, SessionClock};
use milliego_session::{Session, TumPose};
use pose_link::{Health, PoseMessage};
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn simulate(dir: &Path, seed: u64) {
    let st = Command::new(BIN)
        .args([
            "sim",
            "--family",
            "office",
            "--motion",
            "handheld",
            "--duration",
            "8",
        ])
        .args(["--seed", &seed.to_string(), "-o"])
        .arg(dir)
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
}

/// Starts the replay (1.5 s after the ptys exist, so the runtime sees the session from its
/// start) and returns it with the radar and IMU pty paths.
fn replay(dir: &Path, faults: &[&str]) -> (Child, String, String) {
    let mut child = Command::new(BIN)
        .arg("replay")
        .arg(dir)
        // Start once the runtime has opened both ptys (a fixed delay lost the first second of
        // data when a loaded machine started the runtime late), then a little more for it to
        // drop what waited in the driver.
        .args(["--wait-open", "--start-delay", "0.3", "--linger", "1"])
        .args(faults)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut path = |name: &str| {
        let l = lines.next().unwrap().unwrap();
        l.strip_prefix(&format!("{name}: "))
            .unwrap_or_else(|| panic!("replay printed {l:?}"))
            .to_string()
    };
    let (r, i) = (path("radar"), path("imu"));
    // Keep reading stdout (reopen notices) so the replay never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    (child, r, i)
}

/// The session's extrinsics as a runtime config file.
fn config(dir: &Path, s: &Session) -> std::path::PathBuf {
    let e = &s.meta.extrinsics;
    // Live devices name no IMU part: the rig's configuration names the session's, whose preset
    // (and gyro bias prior) the offline run takes from session.toml.
    let device = s.meta.imu.as_ref().and_then(|i| i.device.clone()).unwrap();
    let p = dir.join("runtime.toml");
    std::fs::write(
        &p,
        format!(
            "[imu]\ndevice = {device:?}\n\
             [extrinsics.radar]\nrotation_wxyz = {:?}\ntranslation_m = {:?}\n\
             [extrinsics.imu]\nrotation_wxyz = {:?}\ntranslation_m = {:?}\n",
            e.radar.rotation_wxyz, e.radar.translation_m, e.imu.rotation_wxyz, e.imu.translation_m
        ),
    )
    .unwrap();
    p
}

struct Online {
    msgs: Vec<PoseMessage>,
    summary: serde_json::Value,
}

fn run_online(dir: &Path, s: &Session, faults: &[&str]) -> Online {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let port = sock.local_addr().unwrap().port();
    let (mut rep, radar, imu) = replay(dir, faults);
    let summary = dir.join(format!("summary-{port}.json"));
    let imu_baud = s.meta.imu.as_ref().unwrap().baud.to_string();
    let mut run = Command::new(BIN)
        .args([
            "run",
            "--radar-data",
            &radar,
            "--imu",
            &imu,
            "--no-configure",
        ])
        .arg("--radar-cfg")
        .arg(dir.join("radar.cfg"))
        .args(["--imu-baud", &imu_baud, "--estimator", "doppler"])
        .arg("--config")
        .arg(config(dir, s))
        .args([
            "--out",
            &format!("udp://127.0.0.1:{port}"),
            "--idle-exit",
            "1.5",
        ])
        .arg("--summary-json")
        .arg(&summary)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut msgs = Vec::new();
    let mut buf = [0u8; 256];
    let deadline = Instant::now() + Duration::from_secs(40);
    loop {
        match sock.recv(&mut buf) {
            Ok(n) => msgs.push(PoseMessage::decode(&buf[..n]).expect("a valid pose message")),
            Err(_) => {
                if run.try_wait().unwrap().is_some() {
                    break;
                }
            }
        }
        assert!(Instant::now() < deadline, "the run did not end");
    }
    assert!(run.wait().unwrap().success());
    // The replay ends on its own once it has sent everything; if the run ended first, nobody
    // reads the ptys and the replay could block on a full one: stop it.
    let stop = Instant::now() + Duration::from_secs(10);
    while rep.try_wait().unwrap().is_none() && Instant::now() < stop {
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = rep.kill();
    let _ = rep.wait();
    let summary = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    Online { msgs, summary }
}

fn ate(s: &Session, t: &[TumPose]) -> f64 {
    let gt = Trajectory::from_tum(&s.groundtruth().unwrap().unwrap());
    evaluate(&gt, &Trajectory::from_tum(t), &Settings::default())
        .unwrap()
        .ate
        .rmse
}

/// Radar-rate poses on the session clock: the online IMU clock map (summary) against the
/// session's offline one gives the shift between the runtime's host clock and the session's.
fn on_session_clock(s: &Session, o: &Online) -> Vec<TumPose> {
    let (frames, _) = radar_frames(s).unwrap();
    let (imu, _) = imu_samples(s).unwrap();
    let off = SessionClock::fit(s, &frames, &imu).unwrap().imu.unwrap();
    let c = &o.summary["sync"]["clocks"]["imu"];
    let (on_off, on_rate) = (c["offset_s"].as_f64().unwrap(), c["rate"].as_f64().unwrap());
    let mid = imu[imu.len() / 2].sensor_s;
    let shift = off.host(mid) - (on_off + on_rate * mid);
    o.msgs
        .iter()
        .filter(|m| !m.health.contains(Health::PREDICTED))
        .map(|m| {
            let [w, x, y, z] = m.orientation.map(f64::from);
            TumPose {
                t: m.measurement_time_ns as f64 * 1e-9 + shift,
                p: m.position,
                q: [x, y, z, w],
            }
        })
        .collect()
}

fn offline_ate(dir: &Path, s: &Session) -> (usize, f64) {
    let tum = dir.join("offline.tum");
    let st = Command::new(BIN)
        .arg("run")
        .arg("--session")
        .arg(dir)
        .args(["--estimator", "doppler", "--out"])
        .arg(format!("tum:{}", tum.display()))
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    let t: Vec<TumPose> = std::fs::read_to_string(&tum)
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            TumPose {
                t: v[0],
                p: [v[1], v[2], v[3]],
                q: [v[4], v[5], v[6], v[7]],
            }
        })
        .collect();
    (t.len(), ate(s, &t))
}

#[test]
fn replayed_session_streams_a_pose_per_radar_frame_as_good_as_offline() {
    let d = tempfile::tempdir().unwrap();
    simulate(d.path(), 31);
    let s = Session::open(d.path()).unwrap();
    let o = run_online(d.path(), &s, &[]);
    assert!(!o.msgs.is_empty());
    // Sequence numbers contiguous from 0 (UDP on loopback loses nothing here).
    for (k, m) in o.msgs.iter().enumerate() {
        assert_eq!(m.seq as usize, k, "sequence gap");
    }
    let radar_rate: Vec<&PoseMessage> = o
        .msgs
        .iter()
        .filter(|m| !m.health.contains(Health::PREDICTED))
        .collect();
    // After the 1 s levelling window, one pose per radar frame (20 Hz): no gap in sensor time.
    for w in radar_rate.windows(2) {
        let dt = (w[1].measurement_time_ns - w[0].measurement_time_ns) as f64 * 1e-9;
        assert!((0.03..0.07).contains(&dt), "radar-rate poses {dt} s apart");
    }
    // The configuration's IMU part picked its preset, as the session's name does offline.
    let noise = o.summary["imu_noise"].as_str().unwrap();
    assert!(
        noise.starts_with("mti1, from the IMU device"),
        "live IMU noise: {noise}"
    );
    let (n_off, ate_off) = offline_ate(d.path(), &s);
    assert!(
        radar_rate.len() + 1 >= n_off,
        "{} online vs {n_off} offline",
        radar_rate.len()
    );
    // No sensor flagged missing while both stream.
    let missing = Health(Health::RADAR_MISSING.0 | Health::IMU_MISSING.0);
    let flagged: Vec<(usize, f64)> = radar_rate
        .iter()
        .enumerate()
        .filter(|(_, m)| m.health.0 & missing.0 != 0)
        .map(|(k, m)| (k, m.measurement_time_ns as f64 * 1e-9))
        .collect();
    // Only a frame after the IMU's last sample (the replay ended) may be flagged.
    assert!(
        flagged.iter().all(|&(k, _)| k + 2 >= radar_rate.len()),
        "flagged missing: {flagged:?} of {}",
        radar_rate.len()
    );
    assert!(
        o.msgs.iter().any(|m| m.health.contains(Health::PREDICTED)),
        "IMU-rate output is on"
    );
    // Predicted poses: the IMU propagation from one radar-rate pose lands near the next one.
    let predicted: Vec<&PoseMessage> = o
        .msgs
        .iter()
        .filter(|m| m.health.contains(Health::PREDICTED))
        .collect();
    let mut errs: Vec<f64> = radar_rate
        .iter()
        .filter_map(|r| {
            let p = predicted
                .iter()
                .min_by_key(|p| p.measurement_time_ns.abs_diff(r.measurement_time_ns))?;
            (p.measurement_time_ns.abs_diff(r.measurement_time_ns) < 3_000_000).then(|| {
                (0..3)
                    .map(|i| (p.position[i] - r.position[i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
        })
        .collect();
    errs.sort_by(f64::total_cmp);
    assert!(errs.len() > 100);
    let median = errs[errs.len() / 2];
    println!(
        "prediction vs next radar-rate pose: median {median:.4} m, max {:.4} m",
        errs[errs.len() - 1]
    );
    assert!(
        median < 0.03,
        "IMU-rate prediction off by {median} m (median)"
    );
    let ate_on = ate(&s, &on_session_clock(&s, &o));
    let lat = &o.summary["latency"];
    println!(
        "online ATE {ate_on:.4} m vs offline {ate_off:.4} m; {} messages ({} radar-rate); e2e p50 {} ms p99 {} ms; IMU->pose p50 {} ms p99 {} ms",
        o.msgs.len(),
        radar_rate.len(),
        lat["end_to_end"]["p50_ms"],
        lat["end_to_end"]["p99_ms"],
        lat["imu_to_pose"]["p50_ms"],
        lat["imu_to_pose"]["p99_ms"]
    );
    assert!(
        (ate_on - ate_off).abs() <= 0.05 * ate_off,
        "online ATE {ate_on} vs offline {ate_off}"
    );
}

#[test]
fn port_reopen_and_stalls_are_flagged_and_recovered_from() {
    let d = tempfile::tempdir().unwrap();
    simulate(d.path(), 32);
    let s = Session::open(d.path()).unwrap();
    let o = run_online(
        d.path(),
        &s,
        &[
            "--reopen",
            "radar@2.5",
            "--stall",
            "radar@3.5+1",
            "--stall",
            "imu@5.5+0.5",
        ],
    );
    assert!(o.summary["ports"]["radar_reopens"].as_u64().unwrap() >= 1);
    let t0 = o.msgs[0].measurement_time_ns;
    let rel = |m: &PoseMessage| (m.measurement_time_ns - t0) as f64 * 1e-9;
    // Each stall shows as a run of flagged poses, and the flag clears again afterwards.
    for (flag, name) in [
        (Health::RADAR_MISSING, "radar"),
        (Health::IMU_MISSING, "imu"),
    ] {
        let first = o.msgs.iter().position(|m| m.health.contains(flag));
        let first = first.unwrap_or_else(|| panic!("{name}: never flagged missing"));
        let flagged = o.msgs[first..]
            .iter()
            .take_while(|m| m.health.contains(flag))
            .count();
        let after = &o.msgs[first + flagged..];
        assert!(flagged >= 2, "{name}: flagged on {flagged} poses");
        assert!(
            after
                .iter()
                .filter(|m| !m.health.contains(Health::PREDICTED))
                .count()
                > 20,
            "{name}: radar-rate poses continue after the gap"
        );
        println!(
            "{name}: flagged from {:.2} s on {flagged} poses",
            rel(&o.msgs[first])
        );
    }
    // The stream itself never broke.
    for (k, m) in o.msgs.iter().enumerate() {
        assert_eq!(m.seq as usize, k);
    }
}
