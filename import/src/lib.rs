//! Recordings in: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage), MCAP files and CSV become
//! milliEgo sessions (docs/session.md), so every command (`odometry`, `run`, `eval`, `replay`,
//! `dataset build`) works on real recordings.
//!
//! The data flow: container ([`source`]) -> serialised messages -> decoded ROS messages ([`ros`])
//! -> re-timed, re-framed sensor samples -> a session on disk.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod calib;
pub mod cloud;
pub mod ros;
pub mod source;
pub mod tf;
pub mod wire;
pub mod writer;

pub use writer::{import, list, ImportOptions, ImportReport};

use std::fmt;
use std::path::PathBuf;

/// Why an import failed. Every variant names the file, and where it applies the topic, the
/// message index and the field.
#[derive(Debug)]
pub enum ImportError {
    /// The container could not be read.
    Source(source::SourceError),
    /// A message could not be decoded as its type.
    Message {
        /// Where.
        at: Box<At>,
        /// Its type.
        msg_type: String,
        /// The field and byte offset.
        error: ros::MsgError,
    },
    /// A radar scan's point layout cannot be used.
    Layout {
        /// Where.
        at: Box<At>,
        /// What is wrong with the fields.
        error: cloud::LayoutError,
    },
    /// A stream's topic is missing, ambiguous or of the wrong type.
    Topic {
        /// `radar`, `imu`, `pressure`, `trigger` or `groundtruth`.
        stream: &'static str,
        /// What is wrong, with the topics the recording has.
        why: String,
    },
    /// A message is in a frame the calibration does not describe.
    Frame {
        /// Where.
        at: Box<At>,
        /// Its `header.frame_id`.
        frame_id: String,
        /// The frame the calibration names.
        expected: String,
    },
    /// The calibration file cannot be used.
    Calib(calib::CalibError),
    /// The radar `.cfg` cannot be used (the error names the line).
    RadarCfg(radar_driver::cfg::CfgError),
    /// No sensor message could be timed.
    Empty,
    /// Writing the session failed.
    Session(milliego_session::SessionError),
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImportError::Source(e) => write!(f, "{e}"),
            ImportError::Message {
                at,
                msg_type,
                error,
            } => write!(f, "{at} ({msg_type}): {error}"),
            ImportError::Layout { at, error } => write!(f, "{at}: {error}"),
            ImportError::Topic { stream, why } => write!(f, "{stream} topic: {why}"),
            ImportError::Frame {
                at,
                frame_id,
                expected,
            } => write!(
                f,
                "{at}: field header.frame_id is {frame_id:?}, the calibration describes \
                 {expected:?}"
            ),
            ImportError::Calib(e) => write!(f, "{e}"),
            ImportError::RadarCfg(e) => write!(f, "radar .cfg: {e}"),
            ImportError::Empty => f.write_str("no radar scan or IMU sample could be timed"),
            ImportError::Session(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ImportError {}

/// Where in a recording: the file, the topic and the message's index in its topic.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct At {
    /// Recording.
    pub source: PathBuf,
    /// Topic.
    pub topic: String,
    /// Index of the message in its topic (0-based).
    pub index: u64,
}

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} message {}",
            self.source.display(),
            self.topic,
            self.index
        )
    }
}

impl From<source::SourceError> for ImportError {
    fn from(e: source::SourceError) -> Self {
        ImportError::Source(e)
    }
}
