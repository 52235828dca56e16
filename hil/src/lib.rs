//! The record/replay hardware-in-the-loop rig of the milliEgo stack.
//!
//! * [`schedule`]: when each byte of a session leaves the wire: from the timing index, or, for bare
//!   captures, from the sensor clocks (radar frame number x frame period or timeCpuCycles, IMU
//!   SampleTimeFine), every frame paced at the UART rate of its baud.
//! * [`fault`]: seeded, counted fault injection (corrupt, drop, garbage bursts, stalls, reopens).
//! * [`sink`]: where a replay writes: pseudo-terminals it creates, or real serial devices.
//! * [`mod@replay`]: plays a session's streams into sinks, radar and IMU on one time line.
//! * [`mod@record`]: reads the radar and IMU data ports on their own threads (or both through the
//!   sensor hub's link, on its clock) into a session, losing nothing (bytes read == bytes written
//!   is checked at exit).
//!
//! Spec of the rig and its CLI: `docs/hil.md`; of the session format: `docs/session.md`.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod fault;
pub mod record;
pub mod replay;
pub mod schedule;
pub mod sink;

pub use fault::{FaultCounts, FaultEvent, FaultKind, FaultPlan, Garbage, PortFault};
pub use record::{
    record, HubPort, HubRecord, ImuPort, Live, RadarPorts, RecordConfig, RecordReport, StreamRecord,
};
pub use replay::{replay, Notice, Pacing, ReplayOptions, ReplayReport, StreamReport};
pub use schedule::{Piece, StreamSchedule, Timing};
pub use sink::Sink;

pub use milliego_session::StreamKind;

use std::fmt;
use std::io;

/// An error of the rig, naming the stream, port or file concerned.
#[derive(Debug)]
pub enum HilError {
    /// The session could not be read.
    Session(milliego_session::SessionError),
    /// A port could not be opened, written or read.
    Port {
        /// Which stream.
        stream: StreamKind,
        /// The device path.
        path: String,
        /// What was being done ("open", "write", "read", "reopen", ...).
        action: &'static str,
        /// The operating system's error.
        source: io::Error,
    },
    /// A configuration step of a sensor failed.
    Config {
        /// Which stream.
        stream: StreamKind,
        /// What failed, with the driver's words.
        what: String,
    },
    /// An option is out of range or malformed.
    Invalid(String),
    /// The bytes read and written of a recording differ (a bug, never expected).
    Lost {
        /// Which stream.
        stream: StreamKind,
        /// Bytes read from the port \[B\].
        read: u64,
        /// Bytes written to the session \[B\].
        written: u64,
    },
}

impl fmt::Display for HilError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            HilError::Session(e) => write!(f, "{e}"),
            HilError::Port {
                stream,
                path,
                action,
                source,
            } => write!(
                f,
                "{} port {path}: {action} failed: {source}",
                stream.name()
            ),
            HilError::Config { stream, what } => {
                write!(f, "{} configuration failed: {what}", stream.name())
            }
            HilError::Invalid(m) => write!(f, "{m}"),
            HilError::Lost {
                stream,
                read,
                written,
            } => write!(
                f,
                "{}: {read} B read but {written} B written ({} B lost)",
                stream.name(),
                read.abs_diff(*written)
            ),
        }
    }
}

impl std::error::Error for HilError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            HilError::Session(e) => Some(e),
            HilError::Port { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<milliego_session::SessionError> for HilError {
    fn from(e: milliego_session::SessionError) -> Self {
        HilError::Session(e)
    }
}

/// Parses a stream name (`radar` or `imu`).
pub fn parse_stream(s: &str) -> Result<StreamKind, HilError> {
    match s {
        "radar" => Ok(StreamKind::Radar),
        "imu" => Ok(StreamKind::Imu),
        other => Err(HilError::Invalid(format!(
            "unknown stream {other:?} (expected radar or imu)"
        ))),
    }
}

/// Time `bytes` take on a UART at `baud` (8N1: 10 bits per byte) \[ns\].
pub fn uart_ns(bytes: u64, baud: u32) -> u64 {
    let ns = u128::from(bytes) * 10_000_000_000 / u128::from(baud.max(1));
    u64::try_from(ns).unwrap_or(u64::MAX)
}

/// True for I/O errors that only mean "nothing moved this time" on a serial port or pty with a
/// timeout (timed out, would block, interrupted): the loop retries instead of failing.
pub(crate) fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}
