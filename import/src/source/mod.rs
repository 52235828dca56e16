//! Recordings as a stream of serialised messages: ROS 1 bags ([`rosbag1`]), ROS 2 bag
//! directories with sqlite3 or MCAP storage ([`ros2`]), plain MCAP files ([`mcap`]) and
//! directories of CSV files ([`csv`]). Each
//! reader yields [`RawMessage`]s one at a time, holding at most one chunk in memory, and lists the
//! topics ([`TopicInfo`]) from the container's index when it has one.

pub mod csv;
pub mod mcap;
pub mod ros2;
pub mod rosbag1;

use crate::ros::Encoding;
use std::fmt;
use std::path::{Path, PathBuf};

/// One serialised message as the container stored it.
#[derive(Debug, Clone, Copy)]
pub struct RawMessage<'a> {
    /// Topic.
    pub topic: &'a str,
    /// Message type, normalised to `pkg/Type` ([`crate::ros::normalise_type`]).
    pub msg_type: &'a str,
    /// Time the recorder received it \[ns, the recording's clock\] (bag time / MCAP log time).
    pub log_time_ns: u64,
    /// Index of this message among its topic's messages in the order read (0-based).
    pub index: u64,
    /// The payload.
    pub data: &'a [u8],
    /// Its serialisation.
    pub encoding: Encoding,
}

/// A named metadata record: `(name, key -> value)`.
pub type MetadataRecord = (String, std::collections::BTreeMap<String, String>);

/// A topic of a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic.
    pub topic: String,
    /// Message type, normalised to `pkg/Type`.
    pub msg_type: String,
    /// Messages.
    pub count: u64,
    /// Log time of the first and last message \[ns\] (none when empty).
    pub span_ns: Option<(u64, u64)>,
}

impl TopicInfo {
    /// Mean message rate \[Hz\] over the topic's span (none with fewer than two messages).
    pub fn rate_hz(&self) -> Option<f64> {
        let (a, b) = self.span_ns?;
        (self.count > 1 && b > a).then(|| (self.count - 1) as f64 / ((b - a) as f64 * 1e-9))
    }
}

/// Why a recording could not be read. Every variant names the file; container errors name the
/// byte offset (or the record/row) where reading stopped.
#[derive(Debug)]
pub enum SourceError {
    /// The file or directory could not be opened or read.
    Io {
        /// File.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// Not a recording this crate reads (the first bytes or the layout say what it is not).
    UnknownFormat {
        /// File or directory.
        path: PathBuf,
        /// What was found.
        why: String,
    },
    /// The container is malformed or truncated.
    Corrupt {
        /// File.
        path: PathBuf,
        /// Byte offset (or, for sqlite, the row id) where the problem is.
        at: u64,
        /// What is wrong.
        why: String,
    },
    /// A feature of the container this reader does not support (e.g. a compression).
    Unsupported {
        /// File.
        path: PathBuf,
        /// What.
        what: String,
    },
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SourceError::Io { path, error } => write!(f, "{}: {error}", path.display()),
            SourceError::UnknownFormat { path, why } => {
                write!(f, "{}: not a ROS bag or MCAP file: {why}", path.display())
            }
            SourceError::Corrupt { path, at, why } => {
                write!(f, "{} at {at}: {why}", path.display())
            }
            SourceError::Unsupported { path, what } => {
                write!(f, "{}: unsupported: {what}", path.display())
            }
        }
    }
}

impl std::error::Error for SourceError {}

/// A recording: lists its topics and streams its messages.
pub trait Source {
    /// The file or directory.
    fn path(&self) -> &Path;

    /// The topics, with counts and time spans (from the index or summary when the container has
    /// one, else by reading it through).
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError>;

    /// The recording's metadata records, `(name, key -> value)` (MCAP metadata; empty for
    /// containers without any).
    fn metadata(&mut self) -> Result<Vec<MetadataRecord>, SourceError> {
        Ok(Vec::new())
    }

    /// Calls `f` on every message of the named topics (all topics when `topics` is empty), in the
    /// order stored (per topic that is log-time order for every container this crate reads).
    /// Stops at the first error `f` returns, or at a container error.
    fn for_each(
        &mut self,
        topics: &[&str],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), crate::ImportError>,
    ) -> Result<(), crate::ImportError>;
}

/// Opens `path` as whichever recording it is: a ROS 1 bag (`#ROSBAG V2.0` magic), a ROS 2 bag
/// directory (`metadata.yaml`), or an MCAP file (its magic).
pub fn open(path: &Path) -> Result<Box<dyn Source>, SourceError> {
    if path.is_dir() {
        if !path.join("metadata.yaml").is_file() && csv::is_csv_dir(path) {
            return Ok(Box::new(csv::CsvDir::open(path)?));
        }
        return Ok(Box::new(ros2::Ros2Bag::open(path)?));
    }
    let mut head = [0u8; 13];
    let n = {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|error| SourceError::Io {
            path: path.into(),
            error,
        })?;
        let mut n = 0;
        while n < head.len() {
            match f.read(&mut head[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(error) => {
                    return Err(SourceError::Io {
                        path: path.into(),
                        error,
                    })
                }
            }
        }
        n
    };
    let head = &head[..n];
    if head.starts_with(rosbag1::MAGIC) {
        Ok(Box::new(rosbag1::Bag1::open(path)?))
    } else if head.starts_with(mcap::MAGIC) {
        Ok(Box::new(mcap::McapFile::open(path)?))
    } else {
        Err(SourceError::UnknownFormat {
            path: path.into(),
            why: format!(
                "starts with {:02x?} (neither `#ROSBAG V2.0` nor the MCAP magic)",
                &head[..head.len().min(8)]
            ),
        })
    }
}
