//! `milliego score --json`: every estimator's per-session figures come with the set's summary,
//! in the order of `session_names`, and the summary (mean, max, median, sessions worse than
//! Doppler RIO's) is made of them.

use std::process::{Command, Output};

/// `milliego score --json --no-model` over the first two sessions of split v1's validation set
/// (simulated into `work`), with `extra` arguments.
fn score_two(work: &std::path::Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_milliego"))
        .args([
            "score",
            "--set",
            "val",
            "--limit",
            "2",
            "--no-model",
            "--json",
        ])
        .arg("--work")
        .arg(work)
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn score_json_reports_every_session_of_every_estimator() {
    let work = tempfile::tempdir().unwrap();
    let o = score_two(work.path(), &[]);
    assert!(
        o.status.success(),
        "score: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    let names = v["session_names"].as_array().expect("session_names");
    assert_eq!(names.len(), 2);
    assert!(names
        .iter()
        .all(|n| n.as_str().is_some_and(|s| !s.is_empty())));
    let rows = v["estimators"].as_object().expect("estimators");
    assert!(rows.contains_key("Doppler RIO"), "{:?}", rows.keys());
    for (name, row) in rows {
        let each = row["per_session"].as_array().expect("per_session");
        assert_eq!(each.len(), names.len(), "{name}");
        assert_eq!(row["sessions"].as_u64(), Some(names.len() as u64));
        let ate: Vec<f64> = each
            .iter()
            .map(|s| s["ate_3d_mean_m"].as_f64().expect("finite ATE"))
            .collect();
        let mean = ate.iter().sum::<f64>() / ate.len() as f64;
        let max = ate.iter().cloned().fold(f64::MIN, f64::max);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + b.abs());
        assert!(
            close(row["ate_3d_mean_m"].as_f64().unwrap(), mean),
            "{name}: {row}"
        );
        assert!(
            close(row["ate_3d_max_m"].as_f64().unwrap(), max),
            "{name}: {row}"
        );
        let mut sorted = ate.clone();
        sorted.sort_by(f64::total_cmp);
        let median = (sorted[0] + sorted[1]) / 2.0;
        assert!(
            close(row["ate_3d_median_m"].as_f64().unwrap(), median),
            "{name}: {row}"
        );
        // Session by session against Doppler RIO's; the baseline row itself has none.
        let worse = &row["sessions_worse_than_doppler"];
        if name == "Doppler RIO" {
            assert!(worse.is_null(), "{row}");
        } else {
            let base = &rows["Doppler RIO"]["per_session"];
            let expect = each
                .iter()
                .zip(base.as_array().unwrap())
                .filter(|(s, b)| {
                    s["ate_3d_mean_m"].as_f64().unwrap()
                        > 1.1 * b["ate_3d_mean_m"].as_f64().unwrap()
                })
                .count();
            assert_eq!(worse.as_u64(), Some(expect as u64), "{name}: {row}");
        }
        for s in each {
            assert!(s["ate_2d_mean_m"].as_f64().is_some_and(f64::is_finite));
            assert!(s["drift_pct"].as_f64().is_some());
        }
    }
}

#[test]
fn score_declares_the_robots_ground_vehicles_unless_told_cars_only() {
    // The first two sessions of split v1's validation set: a corridor robot and a handheld walk.
    let work = tempfile::tempdir().unwrap();
    let score = |rule: Option<&str>| match rule {
        Some(r) => score_two(work.path(), &["--ground-vehicles", r]),
        None => score_two(work.path(), &[]),
    };
    let parse = |o: &Output| -> serde_json::Value {
        assert!(
            o.status.success(),
            "score: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        serde_json::from_slice(&o.stdout).expect("one JSON object")
    };
    let (default, cars) = (parse(&score(None)), parse(&score(Some("cars"))));
    assert_eq!(default["ground_vehicles"], "cars-and-robots");
    assert_eq!(cars["ground_vehicles"], "cars");
    let names = default["session_names"].as_array().unwrap();
    assert!(names[0].as_str().unwrap().contains("robot"), "{names:?}");
    assert!(names[1].as_str().unwrap().contains("handheld"), "{names:?}");
    let ate = |v: &serde_json::Value, k: usize| {
        v["estimators"]["Doppler RIO"]["per_session"][k]["ate_3d_mean_m"]
            .as_f64()
            .unwrap()
    };
    // The robot runs with the constraint by default only; the walk is never constrained.
    assert_ne!(ate(&default, 0), ate(&cars, 0));
    assert_eq!(ate(&default, 1), ate(&cars, 1));
    let bad = score(Some("boats"));
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--ground-vehicles boats"), "{err}");
}

#[test]
fn score_refuses_a_learned_switch_that_is_neither_on_nor_off_by_name() {
    let work = tempfile::tempdir().unwrap();
    for flag in ["--learned-noise", "--learned-offset", "--learned-scale"] {
        let o = score_two(work.path(), &[flag, "maybe"]);
        assert!(!o.status.success(), "{flag} maybe was taken");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(flag) && err.contains("\"maybe\""),
            "{flag}: {err}"
        );
    }
}

#[test]
fn score_rows_keeps_the_rows_asked_for_and_doppler() {
    let work = tempfile::tempdir().unwrap();
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../models/compact/model-int8.onnx"
    );
    let keys = |extra: &[&str]| -> Vec<String> {
        let o = Command::new(env!("CARGO_BIN_EXE_milliego"))
            .args(["score", "--set", "val", "--limit", "1", "--json"])
            .arg("--work")
            .arg(work.path())
            .args(extra)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "score {extra:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
        let mut k: Vec<String> = v["estimators"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        k.sort();
        k
    };
    // Without --rows every classical row; with it, Doppler RIO and the rows named.
    assert_eq!(keys(&["--no-model"]), ["Doppler RIO", "IMU dead reckoning"]);
    assert_eq!(keys(&["--no-model", "--rows", "auto"]), ["Doppler RIO"]);
    assert_eq!(
        keys(&["--model", model, "--rows", "auto,zeroed"]),
        [
            "Doppler RIO",
            "auto (compact int8)",
            "milliEgo compact int8, radar zeroed"
        ]
    );
    let bad = score_two(work.path(), &["--rows", "auto,doppler"]);
    assert!(!bad.status.success(), "--rows doppler was taken");
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("--rows: \"doppler\""), "{err}");
}
