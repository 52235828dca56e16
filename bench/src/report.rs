//! Rows, the printed table, the JSON report and the machine it ran on.

use serde::Serialize;

/// Which way a row's ratio is good.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Better {
    /// Throughput: ratio = ours / peer, above 1 means we are faster.
    Higher,
    /// Latency, memory: ratio = ours / peer, below 1 means we are faster / smaller.
    Lower,
}

/// One measured figure beside its peer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// Row group (table section), e.g. `decoders` or `inference: paper-size graph`.
    pub group: String,
    /// What was measured, e.g. `radar framer+decoder`.
    pub name: String,
    /// Our value (`None`: not measured, printed `n/a`).
    pub value: Option<f64>,
    /// Unit of `value` and `peer_value`, e.g. `MB/s`, `ms`, `MB`.
    pub unit: String,
    /// What it is compared with.
    pub peer: String,
    /// The peer's value in the same unit.
    pub peer_value: Option<f64>,
    /// `value / peer_value`, see [`ratio`].
    pub ratio: Option<f64>,
    /// Which way the ratio is good.
    pub better: Better,
    /// Caveats (untrained weights, variant chosen, counts).
    pub notes: String,
}

impl Row {
    /// A row whose ratio is computed from the two values.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        group: &str,
        name: &str,
        value: Option<f64>,
        unit: &str,
        peer: &str,
        peer_value: Option<f64>,
        better: Better,
        notes: &str,
    ) -> Row {
        let r = match (value, peer_value) {
            (Some(a), Some(b)) => ratio(a, b),
            _ => None,
        };
        Row {
            group: group.into(),
            name: name.into(),
            value,
            unit: unit.into(),
            peer: peer.into(),
            peer_value,
            ratio: r,
            better,
            notes: notes.into(),
        }
    }

    /// A row with no figure, only a note (e.g. `n/a (milliego run not available)`).
    pub fn missing(group: &str, name: &str, notes: &str) -> Row {
        Row::new(group, name, None, "", "", None, Better::Lower, notes)
    }
}

/// `a / b` when both are finite and `b` is positive, else `None`.
pub fn ratio(a: f64, b: f64) -> Option<f64> {
    if a.is_finite() && b.is_finite() && b > 0.0 {
        Some(a / b)
    } else {
        None
    }
}

/// Median of `v` (the upper one of an even count); `None` when empty.
pub fn median(v: &[f64]) -> Option<f64> {
    percentile(v, 50.0)
}

/// Nearest-rank percentile `p` (0-100] of `v`; `None` when empty.
pub fn percentile(v: &[f64], p: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    if (p - 50.0).abs() < f64::EPSILON {
        return Some(s[s.len() / 2]);
    }
    let rank = ((p / 100.0) * s.len() as f64).ceil() as usize;
    Some(s[rank.clamp(1, s.len()) - 1])
}

fn num(v: Option<f64>) -> String {
    match v {
        None => "n/a".into(),
        Some(x) if x.abs() >= 100.0 => format!("{x:.0}"),
        Some(x) if x.abs() >= 10.0 => format!("{x:.1}"),
        Some(x) => format!("{x:.2}"),
    }
}

/// The table as printed: one section per group, columns name, value, peer, peer value, ratio, notes.
pub fn format_table(rows: &[Row]) -> String {
    let w = rows.iter().map(|r| r.name.len()).max().unwrap_or(4).max(4);
    let pw = rows.iter().map(|r| r.peer.len()).max().unwrap_or(4).max(4);
    let mut out = String::new();
    let mut group = None;
    for r in rows {
        if group != Some(&r.group) {
            out.push_str(&format!("\n== {} ==\n", r.group));
            out.push_str(&format!(
                "{:<w$}  {:>9} {:<5}  {:<pw$}  {:>9}  {:>6}  notes\n",
                "name", "value", "unit", "peer", "peer", "ratio"
            ));
            group = Some(&r.group);
        }
        let ratio = match (r.ratio, r.better) {
            (Some(x), Better::Higher) => format!("{x:.2}^"),
            (Some(x), Better::Lower) => format!("{x:.2}v"),
            (None, _) => "n/a".into(),
        };
        out.push_str(&format!(
            "{:<w$}  {:>9} {:<5}  {:<pw$}  {:>9}  {:>6}  {}\n",
            r.name,
            num(r.value),
            r.unit,
            r.peer,
            num(r.peer_value),
            ratio,
            r.notes
        ));
    }
    out.push_str(
        "\nratio = value / peer; ^ higher is better (throughput), v lower is better (latency, memory)\n",
    );
    out
}

/// Where the run happened.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Machine {
    /// `model name` from /proc/cpuinfo.
    pub cpu: String,
    /// Logical cores the OS reports.
    pub cores: usize,
    /// 1-minute load average at the start (other jobs on the machine).
    pub load_avg_1m: Option<f64>,
    /// UTC date and time of the run (`date -u` format).
    pub date: String,
}

impl Machine {
    /// Reads /proc/cpuinfo, /proc/loadavg and the clock.
    pub fn detect() -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split(':').nth(1))
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|| "unknown".into());
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let load_avg_1m = std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()));
        let date = std::process::Command::new("date")
            .args(["-u", "+%Y-%m-%dT%H:%M:%SZ"])
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_default();
        Machine {
            cpu,
            cores,
            load_avg_1m,
            date,
        }
    }
}

/// The whole report as written by `--json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Always `milliego-bench`.
    pub format: String,
    /// Format version of this JSON.
    pub version: u32,
    /// Whether `--quick` cut the repetitions.
    pub quick: bool,
    /// Where it ran.
    pub machine: Machine,
    /// Every row, in table order.
    pub rows: Vec<Row>,
}

impl Report {
    /// A report of `rows` measured on `machine`.
    pub fn new(machine: Machine, quick: bool, rows: Vec<Row>) -> Report {
        Report {
            format: "milliego-bench".into(),
            version: 1,
            quick,
            machine,
            rows,
        }
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}
