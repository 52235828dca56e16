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
    milliego(&[
        "sim",
        "--family",
        "office",
        "--motion",
        "handheld",
        "--seed",
        "11",
        "--duration",
        "20",
        "-o",
        &s(&orig),
    ]);
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
    for (name, args) in cases {
        let dir = p(&format!("imported-{name}"));
        let mut a: Vec<&str> = vec!["import", "--radar-cfg", &cfg];
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
    milliego(&[
        "sim",
        "--family",
        "corridor",
        "--motion",
        "robot",
        "--seed",
        "3",
        "--duration",
        "8",
        "-o",
        o,
    ]);
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
