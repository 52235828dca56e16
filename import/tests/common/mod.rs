//! Shared by the import tests: the Python that writes bags with independent writers (`rosbags`,
//! `mcap`).

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// A Python with `rosbags`, `mcap` and `mcap-ros2-support`: `MILLIEGO_ROS_PYTHON`, else
/// `python3`. `None` (after printing a skip line) when it lacks them, unless
/// `MILLIEGO_REQUIRE_ROS=1`, which turns the skip into a failure (CI sets it).
pub fn ros_python() -> Option<String> {
    let py = std::env::var("MILLIEGO_ROS_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&py)
        .args(["-c", "import rosbags, mcap, mcap_ros2"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    let msg = format!(
        "skipped: rosbags / mcap / mcap-ros2-support not importable by {py} (set MILLIEGO_ROS_PYTHON)"
    );
    if std::env::var("MILLIEGO_REQUIRE_ROS").as_deref() == Ok("1") {
        panic!("{msg}, and MILLIEGO_REQUIRE_ROS=1");
    }
    println!("{msg}");
    None
}

/// A script in `import/tests/py/`.
pub fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/py")
        .join(name)
}

/// Runs `python script args...`; panics with its output when it fails.
pub fn run_py(py: &str, script_name: &str, args: &[&str]) -> String {
    let out = Command::new(py)
        .arg(script(script_name))
        .args(args)
        .output()
        .expect("python runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{script_name} {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

// ROS 1 bags by hand (format 2.0), for what no writer produces: unindexed, damaged, odd.

/// A record: header fields (each `u32 len, name=value`), then `u32 len` and the data.
pub fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
    let mut header = Vec::new();
    for (name, value) in fields {
        header.extend(((name.len() + 1 + value.len()) as u32).to_le_bytes());
        header.extend(name.as_bytes());
        header.push(b'=');
        header.extend(*value);
    }
    let mut r = (header.len() as u32).to_le_bytes().to_vec();
    r.extend(header);
    r.extend((data.len() as u32).to_le_bytes());
    r.extend(data);
    r
}

/// A bag by hand: magic, a bag header (unindexed, padded to 4096 B), then `records`.
pub fn hand_bag(dir: &Path, name: &str, records: &[Vec<u8>]) -> PathBuf {
    let head = record(
        &[
            ("op", &[0x03]),
            ("index_pos", &0u64.to_le_bytes()),
            ("conn_count", &0u32.to_le_bytes()),
            ("chunk_count", &0u32.to_le_bytes()),
        ],
        &[],
    );
    let mut bytes = milliego_import::source::rosbag1::MAGIC.to_vec();
    let pad = 4096 - (head.len() - 4);
    bytes.extend(&head[..head.len() - 4]);
    bytes.extend((pad as u32).to_le_bytes());
    bytes.extend(vec![b' '; pad]);
    for r in records {
        bytes.extend(r);
    }
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

pub fn connection(conn: u32, topic: &str, msg_type: &str) -> Vec<u8> {
    let mut data = Vec::new();
    for (k, v) in [("topic", topic), ("type", msg_type), ("md5sum", "*")] {
        data.extend(((k.len() + 1 + v.len()) as u32).to_le_bytes());
        data.extend(format!("{k}={v}").as_bytes());
    }
    record(
        &[
            ("op", &[0x07]),
            ("conn", &conn.to_le_bytes()),
            ("topic", topic.as_bytes()),
        ],
        &data,
    )
}

pub fn message(conn: u32, sec: u32, nsec: u32, data: &[u8]) -> Vec<u8> {
    let mut time = sec.to_le_bytes().to_vec();
    time.extend(nsec.to_le_bytes());
    record(
        &[
            ("op", &[0x02]),
            ("conn", &conn.to_le_bytes()),
            ("time", &time),
        ],
        data,
    )
}

pub fn chunk(compression: &str, records: &[Vec<u8>]) -> Vec<u8> {
    let data = records.concat();
    let size = (data.len() as u32).to_le_bytes();
    record(
        &[
            ("op", &[0x05]),
            ("compression", compression.as_bytes()),
            ("size", &size),
        ],
        &data,
    )
}
