//! Why a run could not start: one typed error that keeps what the drivers, the session reader,
//! the model loader and the outputs reported (the `.cfg` line, the port, the file), so a caller
//! can match on it and a person reads one message naming what and where.

use crate::estimator::BuildError;
use crate::output::SinkError;
use std::fmt;
use std::io;
use std::path::PathBuf;

/// Which serial port of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortRole {
    /// The radar's data (frame) port.
    RadarData,
    /// The radar's CLI (configuration) port.
    RadarCli,
    /// The IMU port.
    Imu,
}

impl fmt::Display for PortRole {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            PortRole::RadarData => "radar data port",
            PortRole::RadarCli => "radar CLI port",
            PortRole::Imu => "IMU port",
        })
    }
}

/// Why a run could not start (or, for [`RunError::Panicked`], why it ended early).
#[derive(Debug)]
pub enum RunError {
    /// Neither `--radar-data` nor `--imu` was given.
    NoSensor,
    /// The session could not be opened, or its streams could not be read.
    Session {
        /// Session directory.
        dir: PathBuf,
        /// What the session reader reported (file, offset, cause).
        error: milliego_session::SessionError,
    },
    /// The session has neither radar frames nor IMU samples.
    EmptySession {
        /// Session directory.
        dir: PathBuf,
    },
    /// The radar `.cfg` file could not be read.
    RadarCfgRead {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: io::Error,
    },
    /// The radar `.cfg` file cannot be used (the error names the line).
    RadarCfg {
        /// The file.
        path: PathBuf,
        /// The parser's error (line number and what is wrong).
        error: radar_driver::cfg::CfgError,
    },
    /// A serial port could not be opened.
    Port {
        /// Which port.
        role: PortRole,
        /// Device path.
        path: String,
        /// The operating system's error.
        error: io::Error,
    },
    /// Uploading the `.cfg` over the radar's CLI port failed (the error names the line).
    RadarUpload {
        /// CLI port.
        port: String,
        /// The driver's error.
        error: radar_driver::host::CliError,
    },
    /// The IMU could not be opened or put into measurement mode.
    Imu {
        /// IMU port.
        port: String,
        /// The driver's error (the step and what the device answered).
        error: imu_driver::host::DeviceError,
    },
    /// The estimator could not be built (no model, or a model that cannot be used).
    Estimator(BuildError),
    /// An output could not be opened.
    Output(SinkError),
    /// A pipeline thread could not be started.
    Spawn {
        /// Thread name.
        thread: &'static str,
        /// The operating system's error.
        error: io::Error,
    },
    /// A pipeline thread panicked (a bug: please report it with the input).
    Panicked {
        /// Thread name.
        thread: &'static str,
    },
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RunError::NoSensor => f.write_str("no sensor given: --radar-data and/or --imu"),
            RunError::Session { dir, error } => write!(f, "session {}: {error}", dir.display()),
            RunError::EmptySession { dir } => write!(
                f,
                "session {}: the session has neither radar frames nor IMU samples",
                dir.display()
            ),
            RunError::RadarCfgRead { path, error } => {
                write!(f, "radar .cfg {}: {error}", path.display())
            }
            RunError::RadarCfg { path, error } => {
                write!(f, "radar .cfg {}: {error}", path.display())
            }
            RunError::Port { role, path, error } => write!(f, "{role} {path}: {error}"),
            RunError::RadarUpload { port, error } => {
                write!(f, "radar configuration over {port}: {error}")
            }
            RunError::Imu { port, error } => write!(f, "IMU {port}: {error}"),
            RunError::Estimator(e) => write!(f, "{e}"),
            RunError::Output(e) => write!(f, "{e}"),
            RunError::Spawn { thread, error } => {
                write!(f, "cannot start the {thread} thread: {error}")
            }
            RunError::Panicked { thread } => write!(f, "the {thread} thread panicked"),
        }
    }
}

// Every variant's message already contains its cause, so `source` stays empty: a reporter that
// walks the chain would print each cause twice.
impl std::error::Error for RunError {}

impl From<BuildError> for RunError {
    fn from(e: BuildError) -> Self {
        RunError::Estimator(e)
    }
}

impl From<SinkError> for RunError {
    fn from(e: SinkError) -> Self {
        RunError::Output(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_what_and_where() {
        let e = RunError::Port {
            role: PortRole::RadarData,
            path: "/dev/ttyACM1".into(),
            error: io::Error::from(io::ErrorKind::NotFound),
        };
        assert_eq!(
            e.to_string(),
            "radar data port /dev/ttyACM1: entity not found"
        );
        let cfg = radar_driver::cfg::RadarConfig::parse("profileCfg 0 60\n")
            .and_then(|c| c.derive(None))
            .unwrap_err();
        let e = RunError::RadarCfg {
            path: "rig.cfg".into(),
            error: cfg,
        };
        let m = e.to_string();
        assert!(m.starts_with("radar .cfg rig.cfg: "), "{m}");
        assert!(m.contains(&cfg.to_string()), "{m}");
        assert!(matches!(
            RunError::from(BuildError::ModelUnavailable),
            RunError::Estimator(BuildError::ModelUnavailable)
        ));
    }
}
