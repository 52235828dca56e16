//! Recordings in: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage), MCAP files and CSV become
//! milliEgo sessions (docs/session.md), so every command (`odometry`, `run`, `eval`, `replay`,
//! `dataset build`) works on real recordings.
//!
//! The data flow: container ([`source`]) -> serialised messages -> decoded ROS messages ([`ros`])
//! -> re-timed, re-framed sensor samples -> a session on disk.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod ros;
pub mod source;

use std::fmt;

/// Why an import failed. Every variant names the file, and where it applies the topic, the
/// message index and the field.
#[derive(Debug)]
pub enum ImportError {
    /// The container could not be read.
    Source(source::SourceError),
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImportError::Source(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ImportError {}

impl From<source::SourceError> for ImportError {
    fn from(e: source::SourceError) -> Self {
        ImportError::Source(e)
    }
}
