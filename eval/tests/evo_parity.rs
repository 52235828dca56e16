//! Figures equal evo's on the same files (to 1e-6), for every alignment and both RPE delta units.
//! Needs a Python with `evo` (`MILLIEGO_EVO_PYTHON`, else `python3`); prints a skip line when
//! absent, and fails instead when `MILLIEGO_REQUIRE_EVO=1` (CI installs evo and sets it).

use milliego_eval::{evaluate, Align, DeltaUnit, Settings, Stats, Trajectory};
use milliego_session::{read_tum, write_tum, TumPose};
use nalgebra::{UnitQuaternion, Vector3};
use std::process::Command;

fn python() -> Option<String> {
    let py = std::env::var("MILLIEGO_EVO_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import evo.core.metrics"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    if std::env::var_os("MILLIEGO_REQUIRE_EVO").is_some() {
        panic!("MILLIEGO_REQUIRE_EVO is set but {py} cannot import evo");
    }
    println!("skipped: evo not importable by {py} (set MILLIEGO_EVO_PYTHON to a python with evo installed)");
    None
}

/// A reference walk and an estimate of it: rotated, shifted, scaled, drifting, noisy, with jittered
/// and missing timestamps.
fn trajectories() -> (Vec<TumPose>, Vec<TumPose>) {
    let mut gt = Vec::new();
    let mut est = Vec::new();
    let tf = UnitQuaternion::from_euler_angles(0.1, -0.05, 0.7);
    let shift = Vector3::new(2.0, -1.0, 0.3);
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    for i in 0..600 {
        let t = 100.0 + i as f64 * 0.05;
        let s = i as f64 * 0.05;
        let p = Vector3::new(
            4.0 * (0.2 * s).cos(),
            3.0 * (0.3 * s).sin(),
            0.1 * (1.3 * s).sin(),
        );
        let q = UnitQuaternion::from_euler_angles(0.05 * (0.9 * s).sin(), 0.03 * s.cos(), 0.25 * s);
        gt.push(TumPose {
            t,
            p: p.into(),
            q: [q.i, q.j, q.k, q.w],
        });
        if i % 7 == 3 {
            continue; // missing estimate poses
        }
        let drift = Vector3::new(0.002 * s, -0.001 * s, 0.0);
        let noise = Vector3::new(rnd(), rnd(), rnd()) * 0.02;
        let pe = tf * ((p + drift + noise) * 0.9) + shift;
        let qe =
            tf * q * UnitQuaternion::from_euler_angles(rnd() * 0.01, rnd() * 0.01, rnd() * 0.02);
        est.push(TumPose {
            t: t + rnd() * 0.008,
            p: pe.into(),
            q: [qe.i, qe.j, qe.k, qe.w],
        });
    }
    (gt, est)
}

const SCRIPT: &str = r#"
import json, sys, copy
from evo.core import sync, metrics
from evo.tools import file_interface
gt = file_interface.read_tum_trajectory_file(sys.argv[1])
est = file_interface.read_tum_trajectory_file(sys.argv[2])
out = {}
for align in ("none", "se3", "sim3"):
    for key, unit, delta in (("f1", "f", 1), ("f10", "f", 10), ("m1", "m", 1.0)):
        r, e = sync.associate_trajectories(gt, est, max_diff=0.01)
        e = copy.deepcopy(e)
        if align != "none":
            e.align(r, correct_scale=(align == "sim3"))
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((r, e))
        u = metrics.Unit.frames if unit == "f" else metrics.Unit.meters
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta, u, all_pairs=False)
        rpe.process_data((r, e))
        out[f"{align}/{key}"] = {"ape": ape.get_all_statistics(), "rpe": rpe.get_all_statistics(), "n": r.num_poses}
print(json.dumps(out))
"#;

fn close(ours: &Stats, evo: &serde_json::Value, what: &str) {
    for (name, v) in [
        ("rmse", ours.rmse),
        ("mean", ours.mean),
        ("median", ours.median),
        ("std", ours.std),
        ("min", ours.min),
        ("max", ours.max),
        ("sse", ours.sse),
    ] {
        let e = evo[name]
            .as_f64()
            .unwrap_or_else(|| panic!("{what}: evo has no {name}"));
        assert!((v - e).abs() <= 1e-6, "{what} {name}: ours {v}, evo {e}");
    }
}

#[test]
fn figures_equal_evo() {
    let Some(py) = python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (gt, est) = trajectories();
    let (g, e) = (dir.path().join("gt.tum"), dir.path().join("est.tum"));
    write_tum(&g, &gt).unwrap();
    write_tum(&e, &est).unwrap();
    let out = Command::new(&py)
        .args(["-c", SCRIPT])
        .arg(&g)
        .arg(&e)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "evo failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let evo: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Read back what evo read (the TUM text), not the in-memory values.
    let (rt, et) = (
        Trajectory::from_tum(&read_tum(&g).unwrap()),
        Trajectory::from_tum(&read_tum(&e).unwrap()),
    );
    for (align, a) in [
        ("none", Align::None),
        ("se3", Align::Se3),
        ("sim3", Align::Sim3),
    ] {
        for (key, delta, unit) in [
            ("f1", 1.0, DeltaUnit::Frames),
            ("f10", 10.0, DeltaUnit::Frames),
            ("m1", 1.0, DeltaUnit::Meters),
        ] {
            let s = Settings {
                align: a,
                rpe_delta: delta,
                rpe_unit: unit,
                ..Settings::default()
            };
            let rep = evaluate(&rt, &et, &s).unwrap();
            let k = format!("{align}/{key}");
            let v = &evo[&k];
            assert_eq!(
                rep.matched as u64,
                v["n"].as_u64().unwrap(),
                "{k}: matched poses"
            );
            close(&rep.ate, &v["ape"], &format!("{k} APE"));
            close(&rep.rpe, &v["rpe"], &format!("{k} RPE"));
        }
    }
}
