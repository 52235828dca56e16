//! The session: one on-disk format for recorded and simulated radar-inertial data.
//!
//! A session is a directory (spec: `docs/session.md`):
//!
//! ```text
//! session.toml      metadata, sensors, extrinsics, clock truth (simulated sessions)
//! radar.bin         radar data-port bytes exactly as read (a TI .dat is one)
//! radar.idx         timing index: host time per read chunk (optional)
//! radar.cfg         the chirp configuration the radar ran (optional)
//! imu.bin           IMU port bytes exactly as read (an Xsens .mtb or raw dump is one)
//! imu.idx           timing index (optional)
//! groundtruth.tum   body trajectory, TUM format, host time base (optional)
//! ```
//!
//! [`Session::open`] also opens a bare TI `.dat` / Xsens log, or a directory of them without
//! `session.toml`; streams without an index then get their timing from the sensor clocks.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod index;
mod meta;
pub mod streams;
mod tum;

pub use index::{read_index, IndexEntry, IndexWriter, INDEX_MAGIC};
pub use meta::{
    ClockTruth, Extrinsic, Extrinsics, GroundTruthMeta, ImportMeta, ImportedStream, ImuMeta, Meta,
    RadarMeta, Source, FORMAT, VERSION,
};
pub use tum::{read_tum, write_tum, TumPose};

use std::fmt;
use std::fs::{self, File};
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Which sensor a stream comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StreamKind {
    /// TI mmWave data UART.
    Radar,
    /// Xsens MTi serial port.
    Imu,
}

impl StreamKind {
    /// `radar` or `imu`: the file stem in a session directory.
    pub fn name(self) -> &'static str {
        match self {
            StreamKind::Radar => "radar",
            StreamKind::Imu => "imu",
        }
    }
}

/// A session error, naming the file and what is wrong with it.
#[derive(Debug)]
pub struct SessionError {
    /// The file or directory concerned.
    pub path: PathBuf,
    /// What is wrong.
    pub kind: ErrorKind,
}

/// What is wrong with a session.
#[derive(Debug)]
pub enum ErrorKind {
    /// The file system said no.
    Io(io::Error),
    /// `session.toml` does not parse or has the wrong format/version.
    Meta(String),
    /// The timing index is malformed.
    Index(String),
    /// The ground-truth trajectory is malformed (1-based line).
    GroundTruth {
        /// Line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// A bare file is neither a radar nor an IMU stream.
    UnknownStream,
    /// The directory holds no stream at all.
    Empty,
    /// Refusing to overwrite an existing session.
    Exists,
}

impl fmt::Display for SessionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = self.path.display();
        match &self.kind {
            ErrorKind::Io(e) => write!(f, "{p}: {e}"),
            ErrorKind::Meta(m) => write!(f, "{p}: {m}"),
            ErrorKind::Index(m) => write!(f, "{p}: bad timing index: {m}"),
            ErrorKind::GroundTruth { line, what } => write!(f, "{p}:{line}: bad ground-truth line: {what}"),
            ErrorKind::UnknownStream => write!(
                f,
                "{p}: neither a TI radar stream (no magic 02 01 04 03 06 05 08 07) nor an Xsens stream (no valid Xbus frame) in the first 64 KiB"
            ),
            ErrorKind::Empty => write!(f, "{p}: no radar.bin, imu.bin, .dat, .bin or .mtb stream in this directory"),
            ErrorKind::Exists => write!(f, "{p}: a session already exists here (choose a new directory)"),
        }
    }
}

impl std::error::Error for SessionError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match &self.kind {
            ErrorKind::Io(e) => Some(e),
            _ => None,
        }
    }
}

pub(crate) fn err(path: &Path, kind: ErrorKind) -> SessionError {
    SessionError {
        path: path.to_path_buf(),
        kind,
    }
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(io::Error) -> SessionError + '_ {
    move |e| err(path, ErrorKind::Io(e))
}

/// One byte stream of a session.
#[derive(Debug, Clone)]
pub struct Stream {
    /// Which sensor.
    pub kind: StreamKind,
    /// The raw bytes file.
    pub data: PathBuf,
    /// Host time per read chunk, if the session was recorded with an index.
    pub index: Option<Vec<IndexEntry>>,
    /// Length of the data file \[B\].
    pub len: u64,
}

/// A chunk of a stream as it was read, with its host time when the session has an index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chunk {
    /// Host monotonic time when the read returned \[ns since session start\]; `None` without index.
    pub host_ns: Option<u64>,
    /// Byte range in the data file.
    pub start: u64,
    /// End of the range (exclusive).
    pub end: u64,
}

impl Stream {
    /// All bytes of the stream.
    pub fn read_all(&self) -> Result<Vec<u8>, SessionError> {
        fs::read(&self.data).map_err(io_err(&self.data))
    }

    /// The stream as read chunks: from the index when there is one (any unindexed tail becomes one
    /// chunk without time), else one chunk without time.
    pub fn chunks(&self) -> Vec<Chunk> {
        let mut out = Vec::new();
        let mut start = 0;
        for e in self.index.iter().flatten() {
            out.push(Chunk {
                host_ns: Some(e.host_ns),
                start,
                end: e.end,
            });
            start = e.end;
        }
        if start < self.len {
            out.push(Chunk {
                host_ns: None,
                start,
                end: self.len,
            });
        }
        out
    }
}

/// An opened session.
#[derive(Debug, Clone)]
pub struct Session {
    /// Directory (or, for a bare file, its parent).
    pub dir: PathBuf,
    /// Metadata (defaults for a session without `session.toml`).
    pub meta: Meta,
    /// The radar stream, if any.
    pub radar: Option<Stream>,
    /// The IMU stream, if any.
    pub imu: Option<Stream>,
}

/// File name of the metadata.
pub const META_FILE: &str = "session.toml";

impl Session {
    /// Opens a session directory, a directory of bare captures, or a single bare capture file.
    pub fn open(path: impl AsRef<Path>) -> Result<Session, SessionError> {
        let path = path.as_ref();
        let md = fs::metadata(path).map_err(io_err(path))?;
        if md.is_file() {
            let kind = sniff_file(path)?.ok_or_else(|| err(path, ErrorKind::UnknownStream))?;
            let stream = bare_stream(kind, path)?;
            let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
            let mut s = Session {
                dir,
                meta: Meta::imported(),
                radar: None,
                imu: None,
            };
            match kind {
                StreamKind::Radar => s.radar = Some(stream),
                StreamKind::Imu => s.imu = Some(stream),
            }
            return Ok(s);
        }
        let meta_path = path.join(META_FILE);
        if meta_path.is_file() {
            let meta = Meta::read(&meta_path)?;
            let radar = meta
                .radar
                .as_ref()
                .map(|r| open_stream(path, StreamKind::Radar, &r.data, r.index.as_deref()))
                .transpose()?;
            let imu = meta
                .imu
                .as_ref()
                .map(|r| open_stream(path, StreamKind::Imu, &r.data, r.index.as_deref()))
                .transpose()?;
            if radar.is_none() && imu.is_none() {
                return Err(err(path, ErrorKind::Empty));
            }
            return Ok(Session {
                dir: path.to_path_buf(),
                meta,
                radar,
                imu,
            });
        }
        // A directory of bare captures: radar.bin / imu.bin by name, else sniff *.dat/*.bin/*.mtb.
        let mut s = Session {
            dir: path.to_path_buf(),
            meta: Meta::imported(),
            radar: None,
            imu: None,
        };
        let mut entries: Vec<PathBuf> = fs::read_dir(path)
            .map_err(io_err(path))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                matches!(
                    p.extension().and_then(|e| e.to_str()),
                    Some("dat" | "bin" | "mtb")
                )
            })
            .collect();
        entries.sort();
        for p in entries {
            let Some(kind) = sniff_file(&p)? else {
                continue;
            };
            let slot = match kind {
                StreamKind::Radar => &mut s.radar,
                StreamKind::Imu => &mut s.imu,
            };
            if slot.is_none() {
                let idx = p.with_extension("idx");
                *slot = Some(if idx.is_file() {
                    open_stream_paths(kind, &p, Some(&idx))?
                } else {
                    bare_stream(kind, &p)?
                });
            }
        }
        if s.radar.is_none() && s.imu.is_none() {
            return Err(err(path, ErrorKind::Empty));
        }
        if path.join("radar.cfg").is_file() {
            s.meta.radar.get_or_insert_with(RadarMeta::default).cfg = Some("radar.cfg".into());
        }
        Ok(s)
    }

    /// The radar .cfg text, when the session has one.
    pub fn radar_cfg(&self) -> Result<Option<String>, SessionError> {
        let Some(name) = self.meta.radar.as_ref().and_then(|r| r.cfg.as_ref()) else {
            return Ok(None);
        };
        let p = self.dir.join(name);
        fs::read_to_string(&p).map(Some).map_err(io_err(&p))
    }

    /// The ground-truth trajectory, when the session has one.
    pub fn groundtruth(&self) -> Result<Option<Vec<TumPose>>, SessionError> {
        let name = match self.meta.groundtruth.as_ref() {
            Some(g) => PathBuf::from(&g.file),
            None if self.dir.join("groundtruth.tum").is_file() => PathBuf::from("groundtruth.tum"),
            None => return Ok(None),
        };
        read_tum(&self.dir.join(name)).map(Some)
    }
}

fn bare_stream(kind: StreamKind, data: &Path) -> Result<Stream, SessionError> {
    let len = fs::metadata(data).map_err(io_err(data))?.len();
    Ok(Stream {
        kind,
        data: data.to_path_buf(),
        index: None,
        len,
    })
}

fn open_stream(
    dir: &Path,
    kind: StreamKind,
    data: &str,
    index: Option<&str>,
) -> Result<Stream, SessionError> {
    let idx = index.map(|i| dir.join(i));
    open_stream_paths(kind, &dir.join(data), idx.as_deref())
}

fn open_stream_paths(
    kind: StreamKind,
    data: &Path,
    index: Option<&Path>,
) -> Result<Stream, SessionError> {
    let mut s = bare_stream(kind, data)?;
    if let Some(ip) = index {
        let entries = read_index(ip)?;
        if let Some(last) = entries.last() {
            if last.end > s.len {
                return Err(err(
                    ip,
                    ErrorKind::Index(format!(
                        "indexes {} B but {} holds {} B",
                        last.end,
                        data.display(),
                        s.len
                    )),
                ));
            }
        }
        s.index = Some(entries);
    }
    Ok(s)
}

/// Which sensor a file's bytes come from, judged on its first 64 KiB.
pub fn sniff_file(path: &Path) -> Result<Option<StreamKind>, SessionError> {
    let mut head = Vec::with_capacity(1 << 16);
    File::open(path)
        .map_err(io_err(path))?
        .take(1 << 16)
        .read_to_end(&mut head)
        .map_err(io_err(path))?;
    Ok(sniff(&head))
}

/// Which sensor a byte stream comes from: the TI magic word, or a valid Xbus frame
/// (`FA`, bus id, message id, length, payload, checksum summing to 0).
pub fn sniff(head: &[u8]) -> Option<StreamKind> {
    if radar_driver::frame::find_magic(head).is_some() {
        return Some(StreamKind::Radar);
    }
    let mut i = 0;
    while let Some(p) = head[i..].iter().position(|&b| b == 0xFA) {
        let s = i + p;
        if let Some(&len) = head.get(s + 3) {
            let n = usize::from(len);
            if len != 0xFF {
                if let Some(frame) = head.get(s + 1..s + 5 + n) {
                    if frame.iter().fold(0u8, |a, b| a.wrapping_add(*b)) == 0 {
                        return Some(StreamKind::Imu);
                    }
                }
            }
        }
        i = s + 1;
    }
    None
}

/// Writes a new session directory.
#[derive(Debug)]
pub struct SessionWriter {
    dir: PathBuf,
    meta: Meta,
}

impl SessionWriter {
    /// Creates `dir` (which must not already hold a session) for a session described by `meta`.
    pub fn create(dir: impl AsRef<Path>, meta: Meta) -> Result<SessionWriter, SessionError> {
        let dir = dir.as_ref();
        if dir.join(META_FILE).exists() {
            return Err(err(dir, ErrorKind::Exists));
        }
        fs::create_dir_all(dir).map_err(io_err(dir))?;
        Ok(SessionWriter {
            dir: dir.to_path_buf(),
            meta,
        })
    }

    /// The session directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The metadata that [`SessionWriter::finish`] will write (edit it before finishing).
    pub fn meta_mut(&mut self) -> &mut Meta {
        &mut self.meta
    }

    /// Opens the data and index files of a stream (`radar.bin` + `radar.idx`, `imu.bin` + `imu.idx`)
    /// and records them in the metadata.
    pub fn stream(&mut self, kind: StreamKind) -> Result<StreamWriter, SessionError> {
        let data = format!("{}.bin", kind.name());
        let index = format!("{}.idx", kind.name());
        match kind {
            StreamKind::Radar => {
                let r = self.meta.radar.get_or_insert_with(RadarMeta::default);
                r.data = data.clone();
                r.index = Some(index.clone());
            }
            StreamKind::Imu => {
                let m = self.meta.imu.get_or_insert_with(ImuMeta::default);
                m.data = data.clone();
                m.index = Some(index.clone());
            }
        }
        StreamWriter::create(&self.dir.join(data), &self.dir.join(index))
    }

    /// Writes the radar .cfg as `radar.cfg`.
    pub fn radar_cfg(&mut self, text: &str) -> Result<(), SessionError> {
        let p = self.dir.join("radar.cfg");
        fs::write(&p, text).map_err(io_err(&p))?;
        self.meta.radar.get_or_insert_with(RadarMeta::default).cfg = Some("radar.cfg".into());
        Ok(())
    }

    /// Writes the ground truth as `groundtruth.tum`.
    pub fn groundtruth(&mut self, poses: &[TumPose]) -> Result<(), SessionError> {
        let p = self.dir.join("groundtruth.tum");
        write_tum(&p, poses)?;
        let g = self
            .meta
            .groundtruth
            .get_or_insert_with(GroundTruthMeta::default);
        g.file = "groundtruth.tum".into();
        Ok(())
    }

    /// Writes `session.toml` (last, so a directory with it is a complete session).
    pub fn finish(self) -> Result<PathBuf, SessionError> {
        self.meta.write(&self.dir.join(META_FILE))?;
        Ok(self.dir)
    }
}

/// Appends read chunks to a stream's data and index files.
#[derive(Debug)]
pub struct StreamWriter {
    data: BufWriter<File>,
    data_path: PathBuf,
    index: IndexWriter,
    written: u64,
}

impl StreamWriter {
    /// Creates the data and index files.
    pub fn create(data: &Path, index: &Path) -> Result<StreamWriter, SessionError> {
        let f = File::create(data).map_err(io_err(data))?;
        Ok(StreamWriter {
            data: BufWriter::with_capacity(1 << 16, f),
            data_path: data.to_path_buf(),
            index: IndexWriter::create(index)?,
            written: 0,
        })
    }

    /// Appends one chunk as it was read, with the host time its read returned [ns since session
    /// start]. Empty chunks are ignored.
    pub fn write_chunk(&mut self, host_ns: u64, bytes: &[u8]) -> Result<(), SessionError> {
        if bytes.is_empty() {
            return Ok(());
        }
        self.data
            .write_all(bytes)
            .map_err(io_err(&self.data_path))?;
        self.written += bytes.len() as u64;
        self.index.push(IndexEntry {
            host_ns,
            end: self.written,
        })
    }

    /// Bytes written so far \[B\].
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Flushes both files to disk; returns the bytes written.
    pub fn finish(mut self) -> Result<u64, SessionError> {
        self.data.flush().map_err(io_err(&self.data_path))?;
        self.data
            .get_ref()
            .sync_all()
            .map_err(io_err(&self.data_path))?;
        self.index.finish()?;
        Ok(self.written)
    }
}
