//! `milliego import` on the recordings users have, written by an independent writer (Python
//! `rosbags`) from a simulated session with known truth: a ROS 1 bag in ti_mmwave_rospkg style
//! (zero scan stamps, scans arriving 100-130 ms late, a hardware trigger topic), a ROS 2 bag
//! (sqlite3), the MCAP `export-mcap` wrote, and the CSV layout of docs/import.md. On every imported session `milliego odometry`
//! must reproduce the original session's accuracy (ATE within 5%).
//!
//! Needs a Python with `rosbags`, `mcap` and `mcap-ros2-support` (`MILLIEGO_ROS_PYTHON`; a skip
//! line otherwise, a failure with `MILLIEGO_REQUIRE_ROS=1`).

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

fn milliego(args: &[&str]) -> String {
    let out = Command::new(BIN).args(args).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "milliego {args:?} failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn ros_python() -> Option<String> {
    let py = std::env::var("MILLIEGO_ROS_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import rosbags, mcap, mcap_ros2, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        let msg = format!("skipped: rosbags / mcap / mcap-ros2-support / numpy not importable by {py} (set MILLIEGO_ROS_PYTHON)");
        assert!(
            std::env::var("MILLIEGO_REQUIRE_ROS").as_deref() != Ok("1"),
            "{msg}"
        );
        println!("{msg}");
        return None;
    }
    Some(py)
}

/// A simulated session of `family` and `motion` at `out`.
fn sim(family: &str, motion: &str, seed: u32, duration_s: u32, out: &str) {
    let (seed, duration) = (seed.to_string(), duration_s.to_string());
    milliego(&[
        "sim",
        "--family",
        family,
        "--motion",
        motion,
        "--seed",
        &seed,
        "--duration",
        &duration,
        "-o",
        out,
    ]);
}

/// ATE RMSE [m] of `milliego odometry` on a session against the session's ground truth.
fn ate(session: &Path, work: &Path, name: &str) -> f64 {
    let est = work.join(format!("{name}.tum"));
    let s = session.to_str().unwrap();
    milliego(&["odometry", "--session", s, "-o", est.to_str().unwrap()]);
    let gt = session.join("groundtruth.tum");
    let j: serde_json::Value = serde_json::from_str(&milliego(&[
        "eval",
        "--est",
        est.to_str().unwrap(),
        "--gt",
        gt.to_str().unwrap(),
        "--json",
    ]))
    .unwrap();
    j["ate_m"]["rmse"].as_f64().unwrap()
}

#[test]
fn imported_bags_reproduce_the_original_accuracy() {
    let Some(py) = ros_python() else { return };
    let d = tempfile::tempdir().unwrap();
    let w = d.path();
    let p = |n: &str| -> PathBuf { w.join(n) };
    let s = |x: &PathBuf| x.to_str().unwrap().to_string();
    let orig = p("orig");
    sim("office", "handheld", 11, 20, &s(&orig));
    milliego(&["export-mcap", &s(&orig), "-o", &s(&p("s.mcap"))]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../import/tests/py/bags_from_mcap.py");
    let out = Command::new(&py)
        .arg(&script)
        .args([
            s(&p("s.mcap")),
            s(&p("bags")),
            "--compression".into(),
            "lz4".into(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let a0 = ate(&orig, w, "orig");
    let bags = p("bags");
    let cases: [(&str, Vec<String>); 4] = [
        // The export's own MCAP: its metadata says the points are in TI axes.
        (
            "mcap",
            vec![
                s(&p("s.mcap")),
                "--calib".into(),
                s(&bags.join("rig_session.toml")),
            ],
        ),
        (
            "ros2",
            vec![
                s(&bags.join("ros2_db3")),
                "--calib".into(),
                s(&bags.join("rig.toml")),
            ],
        ),
        (
            "ti",
            vec![
                s(&bags.join("ti.bag")),
                "--calib".into(),
                s(&bags.join("rig.toml")),
            ],
        ),
        (
            "csv",
            vec![
                s(&bags.join("csv")),
                "--calib".into(),
                s(&bags.join("rig.toml")),
            ],
        ),
    ];
    // The chirp configuration the rig ran, as a ti_mmwave_rospkg user has it.
    let cfg = s(&orig.join("radar.cfg"));
    // A ROS bag names no IMU part: its user names it at the import (the simulated MTi-1, whose
    // preset and gyro bias prior the original session's name picks). The export's MCAP names its own.
    let part = "MTi-1 (simulated)";
    for (name, args) in cases {
        let dir = p(&format!("imported-{name}"));
        let mut a: Vec<&str> = vec!["import", "--radar-cfg", &cfg];
        if name != "mcap" {
            a.extend(["--imu-device", part]);
        }
        a.extend(args.iter().map(String::as_str));
        a.extend(["-o", dir.to_str().unwrap()]);
        let report = milliego(&a);
        println!("{name}:\n{report}");
        if name == "ti" {
            assert!(
                report.contains("trigger /radar/trigger, by sequence number"),
                "{report}"
            );
        }
        // Every scan at its true time (the trigger re-timing), every point and IMU value as
        // simulated (axes converted there and back).
        assert_same_streams(&orig, &dir, name);
        let meta = milliego_session::Session::open(&dir).unwrap().meta;
        assert_eq!(meta.imu.unwrap().device.as_deref(), Some(part), "{name}");
        let ai = ate(&dir, w, name);
        println!("{name}: ATE {ai:.4} m, original {a0:.4} m");
        assert!(
            (ai - a0).abs() <= 0.05 * a0,
            "{name}: ATE {ai} m vs {a0} m on the original session"
        );
    }
}

/// Radar frames (relative time [s], points) and IMU samples (relative time [s], accel, gyro) of a
/// session, on its own clock.
#[allow(clippy::type_complexity)]
fn streams(dir: &Path) -> (Vec<(f64, Vec<[f32; 4]>)>, Vec<(f64, [f64; 3], [f64; 3])>) {
    use milliego_session::streams::{imu_samples, radar_frames, SessionClock};
    let s = milliego_session::Session::open(dir).unwrap();
    let (frames, _) = radar_frames(&s).unwrap();
    let (imu, _) = imu_samples(&s).unwrap();
    let c = SessionClock::fit(&s, &frames, &imu).unwrap();
    let radar: Vec<(f64, Vec<[f32; 4]>)> = frames
        .iter()
        .map(|f| {
            (
                c.radar_s(f).unwrap(),
                f.cloud
                    .points
                    .iter()
                    .map(|p| [p.x, p.y, p.z, p.velocity])
                    .collect(),
            )
        })
        .collect();
    let imu: Vec<(f64, [f64; 3], [f64; 3])> = imu
        .iter()
        .map(|i| (c.imu_s(i.sensor_s), i.accel, i.gyro))
        .collect();
    let t0 = radar[0].0;
    (
        radar.into_iter().map(|(t, p)| (t - t0, p)).collect(),
        imu.into_iter().map(|(t, a, g)| (t - t0, a, g)).collect(),
    )
}

/// import(export(S)) == S for what both hold: every radar point exactly, every IMU value
/// exactly, radar times to 1 us and IMU times to the 100 us SampleTimeFine grid.
#[test]
fn import_of_the_export_is_the_session() {
    let d = tempfile::tempdir().unwrap();
    let w = d.path();
    let orig = w.join("orig");
    let o = orig.to_str().unwrap();
    sim("corridor", "robot", 3, 8, o);
    let mcap = w.join("s.mcap");
    milliego(&["export-mcap", o, "-o", mcap.to_str().unwrap()]);
    let back = w.join("back");
    // No --radar-axes: the export's metadata says its points are in TI axes.
    milliego(&[
        "import",
        mcap.to_str().unwrap(),
        "-o",
        back.to_str().unwrap(),
    ]);
    assert_same_streams(&orig, &back, "export");
}

/// The radar frames and IMU samples of `b` are those of `a`: points and IMU values exactly, radar
/// times to 1 us, IMU times to the 100 us SampleTimeFine grid.
fn assert_same_streams(a: &Path, b: &Path, name: &str) {
    let (r0, i0) = streams(a);
    let (r1, i1) = streams(b);
    assert_eq!(r0.len(), r1.len(), "{name}: radar frames");
    for (k, (a, b)) in r0.iter().zip(&r1).enumerate() {
        assert!(
            (a.0 - b.0).abs() < 1e-6,
            "{name}: frame {k}: {} s vs {} s",
            a.0,
            b.0
        );
        assert_eq!(a.1, b.1, "{name}: frame {k} points");
    }
    assert_eq!(i0.len(), i1.len(), "{name}: IMU samples");
    for (k, (a, b)) in i0.iter().zip(&i1).enumerate() {
        assert!(
            (a.0 - b.0).abs() <= 1e-4,
            "{name}: sample {k}: {} s vs {} s",
            a.0,
            b.0
        );
        assert_eq!((a.1, a.2), (b.1, b.2), "{name}: sample {k} values");
    }
}

/// Reads a pty the replay opened until it closes (or 20 s pass).
#[cfg(unix)]
fn drain(path: &str) -> std::thread::JoinHandle<Vec<u8>> {
    use std::io::Read;
    let mut port = serialport::new(path, 921_600)
        .timeout(std::time::Duration::from_millis(20))
        .open()
        .unwrap();
    std::thread::spawn(move || {
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        let start = std::time::Instant::now();
        while start.elapsed() < std::time::Duration::from_secs(20) {
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

/// Every command a user runs on a session works on an imported one: `odometry` and `run
/// --session` (same trajectory), `eval`, `plot`, `dataset build`, `export-mcap` (whose import
/// is the same session again) and `replay` into ptys (the session's bytes, in order).
#[test]
#[cfg(unix)]
fn every_command_works_on_an_imported_session() {
    use std::io::BufRead;
    let d = tempfile::tempdir().unwrap();
    let w = d.path();
    let p = |n: &str| -> String { w.join(n).to_str().unwrap().to_string() };
    sim("office", "handheld", 5, 10, &p("orig"));
    milliego(&["export-mcap", &p("orig"), "-o", &p("s.mcap")]);
    milliego(&["import", &p("s.mcap"), "-o", &p("imp")]);
    let imp = w.join("imp");
    // Bad input at the command line: a non-zero exit and the error on stderr, naming it.
    for (args, want) in [
        (
            vec![
                "import",
                &p("s.mcap"),
                "--imu-topic",
                "/nope",
                "-o",
                &p("x"),
            ][..]
                .to_vec(),
            "imu topic: topic /nope is not in the recording",
        ),
        (
            vec!["import", &p("missing.bag"), "-o", &p("x")],
            "missing.bag",
        ),
        (
            vec!["import", &p("orig/session.toml"), "-o", &p("x")],
            "session.toml",
        ),
    ] {
        let out = Command::new(BIN).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(want),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
    let meta = std::fs::read_to_string(imp.join("session.toml")).unwrap();
    assert!(
        meta.contains("[import]"),
        "an imported session says so:\n{meta}"
    );

    // The export carried the extrinsics (/tf_static) and the .cfg (its `milliego` metadata).
    let (m0, m1) = (
        milliego_session::Session::open(w.join("orig"))
            .unwrap()
            .meta,
        milliego_session::Session::open(&imp).unwrap().meta,
    );
    assert_eq!(
        m0.extrinsics, m1.extrinsics,
        "extrinsics through /tf_static"
    );
    // The parts' names through the metadata: the IMU's picks the filter's noise preset.
    let device = |m: &milliego_session::Meta| {
        (
            m.radar.as_ref().and_then(|r| r.device.clone()),
            m.imu.as_ref().and_then(|i| i.device.clone()),
        )
    };
    assert!(device(&m0).1.is_some());
    assert_eq!(
        device(&m0),
        device(&m1),
        "device names through the metadata"
    );
    assert!(
        imp.join("radar.cfg").is_file(),
        "the .cfg through the metadata"
    );

    // odometry and run --session on the imported session are as accurate as on the original.
    let ate_of = |est: &str, session: &str| -> f64 {
        let gt = w.join(session).join("groundtruth.tum");
        let j: serde_json::Value = serde_json::from_str(&milliego(&[
            "eval",
            "--est",
            &p(est),
            "--gt",
            gt.to_str().unwrap(),
            "--json",
        ]))
        .unwrap();
        j["ate_m"]["rmse"].as_f64().unwrap()
    };
    for session in ["orig", "imp"] {
        milliego(&[
            "odometry",
            "--session",
            &p(session),
            "-o",
            &p(&format!("odo-{session}.tum")),
        ]);
        milliego(&[
            "run",
            "--session",
            &p(session),
            "--estimator",
            "doppler",
            "--out",
            &format!("tum:{}", p(&format!("run-{session}.tum"))),
        ]);
    }
    for tool in ["odo", "run"] {
        let (a0, a1) = (
            ate_of(&format!("{tool}-orig.tum"), "orig"),
            ate_of(&format!("{tool}-imp.tum"), "imp"),
        );
        println!("{tool}: ATE {a1:.4} m imported, {a0:.4} m original");
        assert!(
            a1.is_finite() && (a1 - a0).abs() <= 0.05 * a0,
            "{tool}: {a1} m vs {a0} m"
        );
    }
    let gt = imp.join("groundtruth.tum");

    milliego(&[
        "plot",
        "trajectory",
        "--est",
        &p("odo-imp.tum"),
        "--gt",
        gt.to_str().unwrap(),
        "--out",
        &p("fig"),
    ]);
    assert!(
        std::fs::metadata(w.join("fig/trajectory.png"))
            .unwrap()
            .len()
            > 1000
    );
    milliego(&["plot", "radar", &p("imp"), "-o", &p("frame.png")]);
    assert!(std::fs::metadata(w.join("frame.png")).unwrap().len() > 1000);

    // Training data from the imported session: the same windows as from the original.
    let windows = |session: &str, out: &str| -> u64 {
        milliego(&["dataset", "build", &p(session), "-o", &p(out), "--quiet"]);
        let m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(w.join(out).join("manifest.json")).unwrap(),
        )
        .unwrap();
        m["windows"].as_u64().unwrap()
    };
    let n = windows("imp", "ds-imp");
    assert!(n > 20, "{n} windows");
    assert_eq!(
        n,
        windows("orig", "ds-orig"),
        "windows from the imported and the original session"
    );

    // export-mcap of the imported session imports to the same streams again.
    milliego(&["export-mcap", &p("imp"), "-o", &p("again.mcap")]);
    milliego(&["import", &p("again.mcap"), "-o", &p("again")]);
    assert_same_streams(&imp, &w.join("again"), "import(export(import))");

    // replay into ptys: the session's radar and IMU bytes come out, in order.
    let mut child = Command::new(BIN)
        .args([
            "replay",
            &p("imp"),
            "--fast",
            "--wait-open",
            "--linger",
            "0.5",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let mut port = |name: &str| -> String {
        let l = lines.next().unwrap().unwrap();
        l.strip_prefix(&format!("{name}: ")).expect(&l).to_string()
    };
    let (radar, imu) = (port("radar"), port("imu"));
    let (r, i) = (drain(&radar), drain(&imu));
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let s = milliego_session::Session::open(&imp).unwrap();
    assert!(
        r.join().unwrap() == s.radar.unwrap().read_all().unwrap(),
        "radar bytes"
    );
    assert!(
        i.join().unwrap() == s.imu.unwrap().read_all().unwrap(),
        "IMU bytes"
    );
}
