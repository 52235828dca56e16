//! Import throughput and memory on bags written by the independent `rosbags` writer, side by
//! side with the `rosbags` reader (Python) reading and deserialising the same files in the same
//! run.
//!
//! Run: `cargo bench -p milliego-import --bench throughput` (Python with `rosbags` and numpy:
//! `$MILLIEGO_ROS_PYTHON`, else the CI venv `~/.cache/milliego-evo`, else `python3`; the
//! recording lasts `$MILLIEGO_IMPORT_BENCH_SECONDS`, default 120 s).
//!
//! Ours is the whole `milliego import` (read, decode, re-time, re-encode, write the session);
//! the peer only reads and deserialises. MB/s counts the recording's bytes on disk; times are
//! medians of interleaved rounds, so a noisy shared machine affects both sides alike. The peak
//! resident memory of this process (VmHWM, which includes the benchmark itself) shows that the
//! import holds one chunk, not the recording.

use milliego_import::{import, ImportOptions};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const ROUNDS: usize = 3;

fn python() -> Option<PathBuf> {
    let home = std::env::var_os("HOME").map(PathBuf::from);
    let candidates = std::env::var_os("MILLIEGO_ROS_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .chain(home.map(|h| h.join(".cache/milliego-evo/bin/python")))
        .chain([PathBuf::from("python3")]);
    for p in candidates {
        let ok = Command::new(&p)
            .args(["-c", "import rosbags.highlevel, numpy"])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok {
            return Some(p);
        }
    }
    None
}

fn size(path: &Path) -> u64 {
    if path.is_dir() {
        std::fs::read_dir(path)
            .map(|d| d.flatten().map(|e| size(&e.path())).sum())
            .unwrap_or(0)
    } else {
        std::fs::metadata(path).map_or(0, |m| m.len())
    }
}

/// Peak resident set of this process so far [bytes] (VmHWM).
fn peak_rss() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The peer's read time [s] and message count.
fn peer(py: &Path, script: &Path, rec: &Path) -> Result<(f64, u64), String> {
    let out = Command::new(py)
        .arg(script)
        .arg(rec)
        .output()
        .map_err(|e| format!("{}: {e}", py.display()))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).map_err(|e| format!("peer output: {e}"))?;
    Ok((
        v["seconds"].as_f64().unwrap_or(f64::NAN),
        v["messages"].as_u64().unwrap_or(0),
    ))
}

fn main() {
    let Some(py) = python() else {
        println!(
            "skipped: no Python with rosbags and numpy (set MILLIEGO_ROS_PYTHON); \
             `pip install rosbags numpy` provides one"
        );
        return;
    };
    let seconds: u32 = std::env::var("MILLIEGO_IMPORT_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(120);
    let here = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches");
    let work = Path::new(env!("CARGO_TARGET_TMPDIR")).join("import-bench");
    let _ = std::fs::remove_dir_all(&work);
    let t = Instant::now();
    let made = Command::new(&py)
        .arg(here.join("make_bags.py"))
        .arg(&work)
        .arg(seconds.to_string())
        .output()
        .expect("run make_bags.py");
    assert!(
        made.status.success(),
        "make_bags.py failed:\n{}",
        String::from_utf8_lossy(&made.stderr)
    );
    println!(
        "{seconds} s rig recording (20 Hz radar scans of 256 points, 400 Hz IMU, trigger, \
         100 Hz ground truth) written by rosbags in {:.1} s; peer: {}",
        t.elapsed().as_secs_f64(),
        py.display()
    );
    let rss0 = peak_rss();
    println!(
        "\n{:<14} {:>9} {:>10} {:>10} {:>7} {:>10} {:>14}",
        "recording", "MB", "ours MB/s", "peer MB/s", "ratio", "messages", "peak RSS MB"
    );
    for (name, rec) in [
        ("ros1 none", work.join("none.bag")),
        ("ros1 lz4", work.join("lz4.bag")),
        ("ros2 sqlite3", work.join("ros2")),
    ] {
        let mb = size(&rec) as f64 / 1e6;
        let (mut ours, mut theirs) = (Vec::new(), Vec::new());
        let mut read = 0;
        let mut peer_msgs = 0;
        for r in 0..ROUNDS {
            let out = work.join(format!("session-{r}"));
            let _ = std::fs::remove_dir_all(&out);
            let t = Instant::now();
            let report = match import(std::slice::from_ref(&rec), &out, &ImportOptions::default()) {
                Ok(r) => r,
                Err(e) => panic!("import {}: {e}", rec.display()),
            };
            ours.push(t.elapsed().as_secs_f64());
            read = report.streams.iter().map(|s| s.messages).sum::<u64>();
            let _ = std::fs::remove_dir_all(&out);
            match peer(&py, &here.join("peer_read.py"), &rec) {
                Ok((s, n)) => {
                    theirs.push(s);
                    peer_msgs = n;
                }
                Err(e) => println!("peer failed on {}: {e}", rec.display()),
            }
        }
        let ours_mbs = mb / median(ours);
        let (peer_mbs, ratio) = if theirs.is_empty() {
            (f64::NAN, f64::NAN)
        } else {
            let p = mb / median(theirs);
            (p, ours_mbs / p)
        };
        let rss = peak_rss().map_or("n/a".into(), |b| format!("{:.1}", b as f64 / 1e6));
        println!(
            "{name:<14} {mb:>9.1} {ours_mbs:>10.1} {peer_mbs:>10.1} {ratio:>7.2} {:>10} {rss:>14}",
            format!("{read}/{peer_msgs}")
        );
    }
    if let Some(r0) = rss0 {
        println!(
            "\npeak RSS before the first import: {:.1} MB (messages: ours read / peer read; \
             ours reads the four topics, the peer every message)",
            r0 as f64 / 1e6
        );
    }
}
