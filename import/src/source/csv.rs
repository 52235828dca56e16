//! Recordings as CSV files: a directory with any of these files, one header line naming the
//! columns (in any order; extra columns are ignored), then one row per sample, times in seconds
//! on one clock:
//!
//! | file | columns | topic it becomes |
//! |---|---|---|
//! | `radar.csv` | `t, frame, x, y, z, doppler[, snr]`, one row per point \[s, -, m, m/s, dB\] (ROS radar axes unless `--radar-axes session`; Doppler positive away); the points of a scan share `t` and `frame` | `/csv/radar` (`sensor_msgs/PointCloud2`) |
//! | `imu.csv` | `t, gx, gy, gz, ax, ay, az` \[s, rad/s, m/s^2\] | `/csv/imu` (`sensor_msgs/Imu`) |
//! | `pressure.csv` | `t, pa` \[s, Pa\] | `/csv/pressure` (`sensor_msgs/FluidPressure`) |
//! | `trigger.csv` | `t, seq` \[s, -\] (scan `frame` = trigger `seq`) | `/csv/trigger` (`std_msgs/Header`) |
//! | `groundtruth.csv` | `t, x, y, z, qx, qy, qz, qw` \[s, m\] | `/csv/groundtruth` (`geometry_msgs/PoseStamped`) |
//!
//! Rows become ROS 1 messages ([`crate::ros::ser::Encoding::Ros1`]), so CSV recordings go
//! through the same import path as bags; messages are yielded in time order across the files
//! (each file must be in time order), one row per file in memory.

use super::{RawMessage, Source, SourceError, TopicInfo};
use crate::ros::Encoding;
use crate::ImportError;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// One CSV stream: its file, topic, type and required columns.
struct Kind {
    file: &'static str,
    topic: &'static str,
    msg_type: &'static str,
    columns: &'static [&'static str],
    optional: &'static [&'static str],
}

const KINDS: [Kind; 5] = [
    Kind {
        file: "radar.csv",
        topic: "/csv/radar",
        msg_type: "sensor_msgs/PointCloud2",
        columns: &["t", "frame", "x", "y", "z", "doppler"],
        optional: &["snr"],
    },
    Kind {
        file: "imu.csv",
        topic: "/csv/imu",
        msg_type: "sensor_msgs/Imu",
        columns: &["t", "gx", "gy", "gz", "ax", "ay", "az"],
        optional: &[],
    },
    Kind {
        file: "pressure.csv",
        topic: "/csv/pressure",
        msg_type: "sensor_msgs/FluidPressure",
        columns: &["t", "pa"],
        optional: &[],
    },
    Kind {
        file: "trigger.csv",
        topic: "/csv/trigger",
        msg_type: "std_msgs/Header",
        columns: &["t", "seq"],
        optional: &[],
    },
    Kind {
        file: "groundtruth.csv",
        topic: "/csv/groundtruth",
        msg_type: "geometry_msgs/PoseStamped",
        columns: &["t", "x", "y", "z", "qx", "qy", "qz", "qw"],
        optional: &[],
    },
];

/// True when `dir` holds at least one of the CSV files this reader knows.
pub fn is_csv_dir(dir: &Path) -> bool {
    KINDS.iter().any(|k| dir.join(k.file).is_file())
}

/// A directory of CSV files.
#[derive(Debug)]
pub struct CsvDir {
    path: PathBuf,
}

/// One open file: its rows, parsed one at a time.
struct Rows {
    kind: usize,
    path: PathBuf,
    lines: std::io::Lines<BufReader<File>>,
    /// Column index of each required column, then of each optional one (`None` if absent).
    cols: Vec<Option<usize>>,
    line_no: usize,
    last_t: f64,
}

impl Rows {
    fn open(dir: &Path, kind: usize) -> Result<Option<Rows>, SourceError> {
        let k = &KINDS[kind];
        let path = dir.join(k.file);
        if !path.is_file() {
            return Ok(None);
        }
        let f = File::open(&path).map_err(|error| SourceError::Io {
            path: path.clone(),
            error,
        })?;
        let mut lines = BufReader::new(f).lines();
        let mut line_no = 0;
        let header = loop {
            line_no += 1;
            match lines.next() {
                Some(Ok(h)) if h.trim().is_empty() || h.trim_start().starts_with('#') => {}
                Some(Ok(h)) => break h,
                Some(Err(error)) => return Err(SourceError::Io { path, error }),
                None => {
                    return Err(SourceError::Corrupt {
                        path,
                        at: line_no,
                        why: "no header line".into(),
                    })
                }
            }
        };
        let names: Vec<String> = header
            .split(',')
            .map(|c| c.trim().to_ascii_lowercase())
            .collect();
        let mut cols = Vec::new();
        for c in k.columns {
            match names.iter().position(|n| n == c) {
                Some(i) => cols.push(Some(i)),
                None => {
                    return Err(SourceError::Corrupt {
                        path,
                        at: line_no,
                        why: format!(
                            "no column `{c}` in the header (needs {}; has {})",
                            k.columns.join(", "),
                            names.join(", ")
                        ),
                    })
                }
            }
        }
        for c in k.optional {
            cols.push(names.iter().position(|n| n == c));
        }
        Ok(Some(Rows {
            kind,
            path,
            lines,
            cols,
            line_no: line_no as usize,
            last_t: f64::NEG_INFINITY,
        }))
    }

    /// The next row's values (required columns, then optional ones as NaN when absent), or
    /// `None` at the end. Blank lines and `#` comments are skipped.
    fn next(&mut self) -> Result<Option<Vec<f64>>, SourceError> {
        loop {
            let Some(line) = self.lines.next() else {
                return Ok(None);
            };
            self.line_no += 1;
            let line = line.map_err(|error| SourceError::Io {
                path: self.path.clone(),
                error,
            })?;
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            let mut v = Vec::with_capacity(self.cols.len());
            for (j, c) in self.cols.iter().enumerate() {
                let Some(i) = *c else {
                    v.push(f64::NAN);
                    continue;
                };
                let name = KINDS[self.kind]
                    .columns
                    .iter()
                    .chain(KINDS[self.kind].optional)
                    .nth(j)
                    .copied()
                    .unwrap_or("?");
                let x = cells
                    .get(i)
                    .and_then(|s| s.parse::<f64>().ok())
                    .ok_or_else(|| SourceError::Corrupt {
                        path: self.path.clone(),
                        at: self.line_no as u64,
                        why: format!("line {}: column `{name}` is not a number", self.line_no),
                    })?;
                v.push(x);
            }
            if !(v[0].is_finite() && v[0] >= self.last_t) {
                return Err(SourceError::Corrupt {
                    path: self.path.clone(),
                    at: self.line_no as u64,
                    why: format!(
                        "line {}: time {} s is not finite or goes backwards (after {} s)",
                        self.line_no, v[0], self.last_t
                    ),
                });
            }
            self.last_t = v[0];
            return Ok(Some(v));
        }
    }
}

/// ROS 1 serialisation of the few messages rows become.
struct W(Vec<u8>);

impl W {
    fn u32(&mut self, v: u32) {
        self.0.extend(v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend(v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.0.extend(s.as_bytes());
    }
    fn header(&mut self, seq: u32, t_ns: i64, frame: &str) {
        self.u32(seq);
        self.u32((t_ns.div_euclid(1_000_000_000)).clamp(0, u32::MAX as i64) as u32);
        self.u32(t_ns.rem_euclid(1_000_000_000) as u32);
        self.string(frame);
    }
}

fn ns(t: f64) -> i64 {
    (t * 1e9).round() as i64
}

/// A scan's points as a PointCloud2 (float32 x y z doppler [snr]).
fn cloud(seq: u32, t: f64, pts: &[Vec<f64>], snr: bool) -> Vec<u8> {
    let names: &[&str] = if snr {
        &["x", "y", "z", "doppler", "snr"]
    } else {
        &["x", "y", "z", "doppler"]
    };
    let step = 4 * names.len() as u32;
    let mut w = W(Vec::new());
    w.header(seq, ns(t), "radar");
    w.u32(1);
    w.u32(pts.len() as u32);
    w.u32(names.len() as u32);
    for (i, n) in names.iter().enumerate() {
        w.string(n);
        w.u32(4 * i as u32);
        w.0.push(7); // FLOAT32
        w.u32(1);
    }
    w.0.push(0);
    w.u32(step);
    w.u32(step * pts.len() as u32);
    w.u32(step * pts.len() as u32);
    for p in pts {
        // Row: t frame x y z doppler snr.
        for v in &p[2..2 + names.len()] {
            w.0.extend((*v as f32).to_le_bytes());
        }
    }
    w.0.push(1);
    w.0
}

fn message(kind: usize, seq: u32, v: &[f64]) -> Vec<u8> {
    let mut w = W(Vec::new());
    let t = ns(v[0]);
    match kind {
        1 => {
            w.header(seq, t, "imu");
            for q in [0.0, 0.0, 0.0, 1.0] {
                w.f64(q);
            }
            for c in 0..9 {
                w.f64(if c == 0 { -1.0 } else { 0.0 });
            }
            for x in &v[1..4] {
                w.f64(*x);
            }
            for _ in 0..9 {
                w.f64(0.0);
            }
            for x in &v[4..7] {
                w.f64(*x);
            }
            for _ in 0..9 {
                w.f64(0.0);
            }
        }
        2 => {
            w.header(seq, t, "baro");
            w.f64(v[1]);
            w.f64(0.0);
        }
        3 => w.header(v[1] as u32, t, "trigger"),
        _ => {
            w.header(seq, t, "world");
            for x in &v[1..8] {
                w.f64(*x);
            }
        }
    }
    w.0
}

impl CsvDir {
    /// Opens a directory of CSV files (at least one of the known names).
    pub fn open(path: &Path) -> Result<CsvDir, SourceError> {
        if !is_csv_dir(path) {
            return Err(SourceError::UnknownFormat {
                path: path.into(),
                why: format!(
                    "a directory without metadata.yaml or any of {}",
                    KINDS.iter().map(|k| k.file).collect::<Vec<_>>().join(", ")
                ),
            });
        }
        Ok(CsvDir { path: path.into() })
    }

    /// Streams every message in time order across the files.
    fn stream(
        &self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        let mut files = Vec::new();
        for (k, kind) in KINDS.iter().enumerate() {
            if topics.is_empty() || topics.contains(&kind.topic) {
                if let Some(r) = Rows::open(&self.path, k)? {
                    files.push(r);
                }
            }
        }
        // The head row of each file; radar rows are gathered into whole scans first.
        let mut heads: Vec<Option<Vec<f64>>> = Vec::with_capacity(files.len());
        for r in &mut files {
            heads.push(r.next()?);
        }
        let mut index = vec![0u64; files.len()];
        loop {
            let Some(i) = (0..files.len())
                .filter(|&i| heads[i].is_some())
                .min_by(|&a, &b| {
                    let ta = heads[a].as_ref().map_or(f64::INFINITY, |v| v[0]);
                    let tb = heads[b].as_ref().map_or(f64::INFINITY, |v| v[0]);
                    ta.total_cmp(&tb)
                })
            else {
                return Ok(());
            };
            let Some(row) = heads[i].take() else {
                continue;
            };
            let kind = files[i].kind;
            let t_row = row[0];
            let data = if kind == 0 {
                let (t, frame) = (row[0], row[1]);
                let mut pts = vec![row];
                loop {
                    match files[i].next()? {
                        Some(r) if r[0] == t && r[1] == frame => pts.push(r),
                        next => {
                            heads[i] = next;
                            break;
                        }
                    }
                }
                let snr = pts.iter().all(|p| p[6].is_finite());
                cloud(frame as u32, t, &pts, snr)
            } else {
                let m = message(kind, index[i] as u32, &row);
                heads[i] = files[i].next()?;
                m
            };
            f(RawMessage {
                topic: KINDS[kind].topic,
                msg_type: KINDS[kind].msg_type,
                log_time_ns: ns(t_row).max(0) as u64,
                index: index[i],
                data: &data,
                encoding: Encoding::Ros1,
            })?;
            index[i] += 1;
        }
    }
}

impl Source for CsvDir {
    fn path(&self) -> &Path {
        &self.path
    }

    /// By reading the files through (CSV has no index).
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        let mut out: Vec<TopicInfo> = Vec::new();
        let r = self.stream(&[], &mut |m| {
            let t = m.log_time_ns;
            match out.iter_mut().find(|x| x.topic == m.topic) {
                Some(x) => {
                    x.count += 1;
                    x.span_ns = x.span_ns.map(|(a, b)| (a.min(t), b.max(t)));
                }
                None => out.push(TopicInfo {
                    topic: m.topic.into(),
                    msg_type: m.msg_type.into(),
                    count: 1,
                    span_ns: Some((t, t)),
                }),
            }
            Ok(())
        });
        match r {
            Ok(()) => Ok(out),
            Err(ImportError::Source(e)) => Err(e),
            Err(e) => Err(SourceError::Corrupt {
                path: self.path.clone(),
                at: 0,
                why: e.to_string(),
            }),
        }
    }

    fn for_each(
        &mut self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), ImportError>,
    ) -> Result<(), ImportError> {
        self.stream(topics, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::{Imu, PointCloud2, RosMsg};

    fn dir(files: &[(&str, &str)]) -> tempfile::TempDir {
        let d = tempfile::tempdir().unwrap();
        for (n, text) in files {
            std::fs::write(d.path().join(n), text).unwrap();
        }
        d
    }

    #[test]
    fn rows_become_messages_in_time_order_and_scans_group_their_points() {
        let d = dir(&[
            (
                "radar.csv",
                "t,frame,x,y,z,doppler\n0.10,7,1,2,3,-0.5\n0.10,7,4,5,6,0.25\n0.20,8,1,1,1,0\n",
            ),
            ("imu.csv", "# comment\nax,ay,az,gx,gy,gz,t\n0,0,9.81,0.1,0.2,0.3,0.05\n\n0,0,9.81,0,0,0,0.15\n"),
        ]);
        let mut src = super::super::open(d.path()).unwrap();
        let mut got = Vec::new();
        src.for_each(&[], &mut |m| {
            got.push((m.topic.to_string(), m.log_time_ns, m.data.to_vec()));
            Ok(())
        })
        .unwrap();
        let order: Vec<(&str, u64)> = got.iter().map(|g| (g.0.as_str(), g.1)).collect();
        assert_eq!(
            order,
            vec![
                ("/csv/imu", 50_000_000),
                ("/csv/radar", 100_000_000),
                ("/csv/imu", 150_000_000),
                ("/csv/radar", 200_000_000)
            ]
        );
        let c = PointCloud2::decode(&got[1].2, Encoding::Ros1).unwrap();
        assert_eq!((c.width, c.header.seq), (2, Some(7)));
        let l = crate::cloud::PointLayout::of(&c, None).unwrap();
        let mut pts = Vec::new();
        l.points(&c, |p| pts.push((p.xyz, p.doppler))).unwrap();
        assert_eq!(pts, vec![([1.0, 2.0, 3.0], -0.5), ([4.0, 5.0, 6.0], 0.25)]);
        let u = Imu::decode(&got[0].2, Encoding::Ros1).unwrap();
        assert_eq!(u.angular_velocity, [0.1, 0.2, 0.3]);
        assert_eq!(u.linear_acceleration, [0.0, 0.0, 9.81]);
        let t = src.topics().unwrap();
        assert_eq!(t.iter().map(|t| t.count).sum::<u64>(), 4);
    }

    #[test]
    fn bad_files_name_the_file_and_line() {
        let d = dir(&[("imu.csv", "t,gx,gy,gz,ax,ay\n")]);
        let e = super::super::open(d.path())
            .unwrap()
            .topics()
            .unwrap_err()
            .to_string();
        assert!(e.contains("imu.csv") && e.contains("no column `az`"), "{e}");
        let d = dir(&[("pressure.csv", "t,pa\n1.0,101325\n0.5,101300\n")]);
        let e = super::super::open(d.path())
            .unwrap()
            .topics()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("pressure.csv") && e.contains("line 3") && e.contains("backwards"),
            "{e}"
        );
        let d = dir(&[("pressure.csv", "t,pa\n1.0,abc\n")]);
        let e = super::super::open(d.path())
            .unwrap()
            .topics()
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2: column `pa` is not a number"), "{e}");
        let d = dir(&[("other.csv", "x\n")]);
        assert!(super::super::open(d.path()).is_err());
    }
}
