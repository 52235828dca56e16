//! The cheap parts of the report: ratio math, percentiles, table text and JSON shape (no timing).

use milliego_bench::report::{median, percentile};
use milliego_bench::{e2e, format_table, ratio, Better, Machine, Report, Row};

fn rows() -> Vec<Row> {
    vec![
        Row::new(
            "decoders",
            "radar",
            Some(200.0),
            "MB/s",
            "mmwave-tlv",
            Some(50.0),
            Better::Higher,
            "4 captures",
        ),
        Row::new(
            "inference",
            "tract int8 median",
            Some(8.8),
            "ms",
            "ORT best int8",
            Some(3.0),
            Better::Lower,
            "",
        ),
        Row::missing(
            e2e::GROUP,
            "milliego run",
            "n/a (milliego run not available)",
        ),
    ]
}

#[test]
fn ratio_math() {
    assert_eq!(ratio(6.0, 3.0), Some(2.0));
    assert_eq!(ratio(1.0, 0.0), None);
    assert_eq!(ratio(f64::NAN, 1.0), None);
    let r = rows();
    assert_eq!(r[0].ratio, Some(4.0));
    assert!((r[1].ratio.unwrap() - 8.8 / 3.0).abs() < 1e-12);
    assert_eq!(r[2].ratio, None);
}

#[test]
fn percentiles() {
    let v: Vec<f64> = (1..=100).rev().map(f64::from).collect();
    assert_eq!(median(&v), Some(51.0));
    assert_eq!(percentile(&v, 99.0), Some(99.0));
    assert_eq!(percentile(&v, 100.0), Some(100.0));
    assert_eq!(percentile(&[3.0], 99.0), Some(3.0));
    assert_eq!(median(&[]), None);
}

#[test]
fn table_text() {
    let t = format_table(&rows());
    assert!(t.contains("== decoders =="));
    assert!(t.contains("== end-to-end (milliego run) =="));
    assert!(t.contains("n/a (milliego run not available)"));
    assert!(t.contains("4.00^"), "{t}");
    assert!(t.contains("2.93v"), "{t}");
}

#[test]
fn json_shape() {
    let m = Machine {
        cpu: "cpu".into(),
        cores: 2,
        load_avg_1m: Some(1.5),
        date: "2026-01-01T00:00:00Z".into(),
    };
    let j: serde_json::Value =
        serde_json::from_str(&Report::new(m, true, rows()).to_json()).unwrap();
    assert_eq!(j["format"], "milliego-bench");
    assert_eq!(j["quick"], true);
    assert_eq!(j["machine"]["cores"], 2);
    let r = j["rows"].as_array().unwrap();
    assert_eq!(r.len(), 3);
    for key in [
        "group",
        "name",
        "value",
        "unit",
        "peer",
        "peer_value",
        "ratio",
        "better",
        "notes",
    ] {
        assert!(r[0].get(key).is_some(), "row lacks {key}");
    }
    assert_eq!(r[0]["ratio"], 4.0);
    assert_eq!(r[0]["better"], "higher");
    assert!(r[2]["value"].is_null());
}

#[test]
fn e2e_summary_rows_and_missing_binary() {
    let v = serde_json::json!({"windows_per_s": 12.5, "latency_ms": 80.0, "name": "x"});
    let r = e2e::rows_from_summary(&v);
    assert_eq!(r.len(), 2);
    assert!(r.iter().any(|r| r.name == "latency_ms" && r.unit == "ms"));
    let r = e2e::rows(std::path::Path::new("/nonexistent/milliego"), Some("true"));
    assert_eq!(r[0].notes, "n/a (milliego run not available)");
}
