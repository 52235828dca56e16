//! A simulated session exported to MCAP and read back: with the `mcap` crate's reader (counts per
//! topic, monotonic log times, seekable summary), and with the Python `mcap` + `mcap-ros2-support`
//! packages through scripts/check-mcap.py, which decodes every message with its ROS 2 schema.
//! The Python check needs `MILLIEGO_MCAP_PYTHON` (else `python3`) with both packages; without
//! them it prints a skip line, and fails instead when `MILLIEGO_REQUIRE_MCAP=1` (CI sets it).

use mcap::{MessageStream, Summary};
use milliego_mcap::{export, ExportOptions, ExportSummary, Trajectory};
use milliego_session::streams::{imu_samples, radar_frames};
use milliego_session::{Session, TumPose};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn session(dir: &Path) -> Session {
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 11);
    sc.duration_s = 3.0;
    simulate(&sc, dir, &mut |_| {}).expect("simulate");
    Session::open(dir).expect("open the simulated session")
}

/// The ground truth moved 1 m along x: a stand-in for an estimate.
fn estimate(gt: &[TumPose]) -> Vec<TumPose> {
    gt.iter()
        .map(|p| TumPose {
            p: [p.p[0] + 1.0, p.p[1], p.p[2]],
            ..*p
        })
        .collect()
}

fn counts_and_times(bytes: &[u8]) -> (BTreeMap<String, u64>, Vec<u64>) {
    let mut counts = BTreeMap::new();
    let mut times = Vec::new();
    for m in MessageStream::new(bytes).expect("MCAP magic and records") {
        let m = m.expect("a readable message");
        *counts.entry(m.channel.topic.clone()).or_insert(0) += 1;
        assert_eq!(m.channel.message_encoding, "cdr");
        let schema = m
            .channel
            .schema
            .as_ref()
            .expect("every channel has a schema");
        assert_eq!(schema.encoding, "ros2msg");
        assert_eq!(&m.data[..4], &[0, 1, 0, 0], "CDR_LE encapsulation");
        assert_eq!(m.log_time, m.publish_time);
        times.push(m.log_time);
    }
    (counts, times)
}

struct Fixture {
    _dir: tempfile::TempDir,
    session: Session,
    gt: Vec<TumPose>,
    est: Vec<TumPose>,
    out: PathBuf,
}

fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let session = session(&dir.path().join("session"));
    let gt = session.groundtruth().unwrap().expect("ground truth");
    let est = estimate(&gt);
    let out = dir.path().join("out.mcap");
    Fixture {
        _dir: dir,
        session,
        gt,
        est,
        out,
    }
}

fn run_export(f: &Fixture, compress: bool) -> ExportSummary {
    let opts = ExportOptions {
        compress,
        chunk_size: 64 * 1024,
    };
    let est = [Trajectory {
        name: "doppler".into(),
        poses: f.est.clone(),
    }];
    export(&f.session, &est, &f.out, &opts).expect("export")
}

#[test]
fn export_reads_back_with_the_mcap_crate() {
    let f = fixture();
    let (frames, _) = radar_frames(&f.session).unwrap();
    let (imu, _) = imu_samples(&f.session).unwrap();
    assert!(frames.len() > 20 && imu.len() > 200);
    for compress in [true, false] {
        let s = run_export(&f, compress);
        assert_eq!(s.radar_untimed, 0);
        assert!(!s.clock_unsynced);
        let bytes = std::fs::read(&f.out).unwrap();
        assert_eq!(s.file_bytes, bytes.len() as u64);
        let (counts, times) = counts_and_times(&bytes);
        let want: BTreeMap<String, u64> = [
            ("/tf_static", 1),
            ("/radar/points", frames.len()),
            ("/imu/data", imu.len()),
            ("/groundtruth/pose", f.gt.len()),
            ("/groundtruth/odom", f.gt.len()),
            ("/doppler/pose", f.est.len()),
            ("/doppler/odom", f.est.len()),
        ]
        .into_iter()
        .map(|(t, n)| (t.to_string(), n as u64))
        .collect();
        assert_eq!(counts, want, "messages per topic (compress {compress})");
        let summed: BTreeMap<String, u64> = s
            .topics
            .iter()
            .map(|t| (t.topic.clone(), t.messages))
            .collect();
        assert_eq!(summed, want, "the summary counts what was written");
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "log times in order");
        assert_eq!(
            s.log_time_range_ns,
            Some((times[0], *times.last().unwrap()))
        );
        // Seekable: a summary with statistics, chunk indexes and message indexes.
        let summary = Summary::read(&bytes).unwrap().expect("summary section");
        let stats = summary.stats.as_ref().expect("statistics");
        assert_eq!(stats.message_count, want.values().sum::<u64>());
        assert!(summary.chunk_indexes.len() > 1, "several chunks");
        assert!(summary
            .chunk_indexes
            .iter()
            .all(|c| !c.message_index_offsets.is_empty()));
        assert_eq!(
            summary.chunk_indexes[0].compression,
            if compress { "zstd" } else { "" }
        );
        assert_eq!(summary.schemas.len(), 5, "one schema per message type");
    }
}

#[test]
fn bad_trajectory_names_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let s = session(&dir.path().join("s"));
    let out = dir.path().join("x.mcap");
    for name in ["groundtruth", "a-b", "1x"] {
        let e = export(
            &s,
            &[Trajectory {
                name: name.into(),
                poses: Vec::new(),
            }],
            &out,
            &ExportOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains(name), "{e}");
    }
}

fn python() -> Option<String> {
    let py = std::env::var("MILLIEGO_MCAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import mcap.reader, mcap_ros2.decoder"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    if std::env::var("MILLIEGO_REQUIRE_MCAP").is_ok_and(|v| v == "1") {
        panic!("MILLIEGO_REQUIRE_MCAP=1 but {py} cannot import mcap and mcap_ros2");
    }
    println!("skipped: mcap / mcap-ros2-support not importable by {py} (set MILLIEGO_MCAP_PYTHON to a python with both installed)");
    None
}

#[test]
fn python_ros2_decoder_reads_every_message() {
    let Some(py) = python() else {
        return;
    };
    let f = fixture();
    let (frames, _) = radar_frames(&f.session).unwrap();
    let (imu, _) = imu_samples(&f.session).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/check-mcap.py");
    for compress in [true, false] {
        let s = run_export(&f, compress);
        let counts: BTreeMap<String, u64> = s
            .topics
            .iter()
            .map(|t| (t.topic.clone(), t.messages))
            .collect();
        let cloud = &frames[0].cloud.points;
        let e = f.est[0];
        let mut expect = json!({
            "counts": counts,
            "first_cloud_points": cloud.len(),
            "first_imu_angular_velocity": imu[0].gyro,
            "first_pose": {"topic": "/doppler/pose", "position": e.p, "orientation": e.q},
            "tol": 1e-12,
        });
        if let Some(p) = cloud.first() {
            expect["first_cloud_x"] = json!(p.x);
        }
        let expect = expect.to_string();
        let expect_path = f.out.with_extension("json");
        std::fs::write(&expect_path, expect).unwrap();
        let o = Command::new(&py)
            .arg(&script)
            .arg(&f.out)
            .arg(&expect_path)
            .output()
            .expect("run check-mcap.py");
        println!("{}", String::from_utf8_lossy(&o.stdout));
        assert!(
            o.status.success(),
            "check-mcap.py (compress {compress}) failed:\n{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
    }
}
