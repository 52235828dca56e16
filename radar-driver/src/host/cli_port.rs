//! The radar's CLI (configuration) port: upload a .cfg line by line and check every answer.
//!
//! The demo echoes each line, then answers `Done`, `Error <n>` or (for `%` comments) `Skipped`,
//! then prints the prompt `mmwDemo:/>`. `Ignored: ...` lines still end with `Done`.

use crate::cfg::{lines, CfgLine};
use std::fmt;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

/// CLI port baud rate \[bit/s\].
pub const CLI_BAUD: u32 = 115_200;

/// How the device answered one line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// `Done`.
    Done,
    /// `Skipped` (comments).
    Skipped,
    /// `Ignored: <why>` followed by `Done`.
    Ignored(String),
}

/// A failed exchange on the CLI port, naming the line.
#[derive(Debug)]
pub enum CliError {
    /// The port failed while sending or reading.
    Io {
        /// 1-based line of the .cfg (0 for lifecycle commands sent on their own).
        line_no: u32,
        /// The command.
        line: String,
        /// The I/O error.
        source: io::Error,
    },
    /// The device answered `Error <code>`.
    Rejected {
        /// 1-based line of the .cfg (0 for lifecycle commands sent on their own).
        line_no: u32,
        /// The command.
        line: String,
        /// The error code (-1 when the device printed none).
        code: i32,
        /// Everything the device printed for this line.
        transcript: String,
    },
    /// No `Done`/`Error`/`Skipped` within the timeout.
    Timeout {
        /// 1-based line of the .cfg (0 for lifecycle commands sent on their own).
        line_no: u32,
        /// The command.
        line: String,
        /// How long we waited.
        waited: Duration,
        /// Everything the device printed meanwhile.
        transcript: String,
    },
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Io { line_no, line, source } => write!(f, "cfg line {line_no} `{line}`: port error: {source}"),
            CliError::Rejected { line_no, line, code, transcript } => write!(
                f,
                "cfg line {line_no} `{line}`: device answered Error {code} (device said: {:?})",
                transcript.trim()
            ),
            CliError::Timeout { line_no, line, waited, transcript } => write!(
                f,
                "cfg line {line_no} `{line}`: no Done/Error after {} ms (device said: {:?}); wrong port, wrong baud, or the radar is not running the demo",
                waited.as_millis(),
                transcript.trim()
            ),
        }
    }
}

impl std::error::Error for CliError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            CliError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// What an upload did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UploadReport {
    /// Lines answered `Done`.
    pub done: u32,
    /// Lines answered `Skipped`.
    pub skipped: u32,
    /// Lines answered `Ignored: ...` (line number, device text).
    pub ignored: Vec<(u32, String)>,
}

/// The CLI port of a radar (any `Read + Write`: a serial port, or a pseudo-terminal in tests).
#[derive(Debug)]
pub struct CliPort<P> {
    port: P,
    timeout: Duration,
    pending: Vec<u8>,
}

impl<P: Read + Write> CliPort<P> {
    /// Wraps a port; each line waits at most `timeout` for its answer.
    pub fn new(port: P, timeout: Duration) -> Self {
        CliPort {
            port,
            timeout,
            pending: Vec::new(),
        }
    }

    /// Sends one command and waits for its answer.
    pub fn send(&mut self, line_no: u32, line: &str) -> Result<Reply, CliError> {
        let io_err = |source| CliError::Io {
            line_no,
            line: line.to_string(),
            source,
        };
        self.pending.clear();
        self.port.write_all(line.as_bytes()).map_err(io_err)?;
        self.port.write_all(b"\n").map_err(io_err)?;
        self.port.flush().map_err(io_err)?;
        let start = Instant::now();
        let mut transcript = String::new();
        let mut ignored: Option<String> = None;
        let mut chunk = [0u8; 256];
        loop {
            while let Some(pos) = self.pending.iter().position(|&b| b == b'\n' || b == b'\r') {
                let raw: Vec<u8> = self.pending.drain(..=pos).collect();
                let text = String::from_utf8_lossy(&raw);
                let text = text.trim().trim_start_matches("mmwDemo:/>").trim();
                if text.is_empty() || text == line.trim() {
                    continue;
                }
                transcript.push_str(text);
                transcript.push('\n');
                if text == "Done" {
                    return Ok(ignored.map_or(Reply::Done, Reply::Ignored));
                }
                if text == "Skipped" {
                    return Ok(Reply::Skipped);
                }
                if let Some(rest) = text.strip_prefix("Ignored:") {
                    ignored = Some(rest.trim().to_string());
                } else if let Some(rest) = text.strip_prefix("Error") {
                    let code = rest
                        .split_whitespace()
                        .next()
                        .and_then(|c| c.parse().ok())
                        .unwrap_or(-1);
                    return Err(CliError::Rejected {
                        line_no,
                        line: line.to_string(),
                        code,
                        transcript,
                    });
                }
            }
            let waited = start.elapsed();
            if waited >= self.timeout {
                return Err(CliError::Timeout {
                    line_no,
                    line: line.to_string(),
                    waited,
                    transcript,
                });
            }
            match self.port.read(&mut chunk) {
                Ok(0) => std::thread::sleep(Duration::from_millis(2)),
                Ok(n) => self.pending.extend_from_slice(&chunk[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_err(e)),
            }
        }
    }

    /// Uploads a .cfg: `sensorStop` and `flushCfg` first (sent even if the file lacks them),
    /// every line of the file in order (comments included; the device skips them), and
    /// `sensorStart` last (appended if the file lacks it). Stops at the first failing line.
    pub fn upload(&mut self, cfg_text: &str) -> Result<UploadReport, CliError> {
        let all: Vec<CfgLine<'_>> = lines(cfg_text).collect();
        let has = |cmd: &str| all.iter().any(|l| l.command() == cmd);
        let mut report = UploadReport::default();
        let mut note = |line_no: u32, r: Reply| match r {
            Reply::Done => report.done += 1,
            Reply::Skipped => report.skipped += 1,
            Reply::Ignored(why) => report.ignored.push((line_no, why)),
        };
        if !has("sensorStop") {
            note(0, self.send(0, "sensorStop")?);
        }
        if !has("flushCfg") {
            note(0, self.send(0, "flushCfg")?);
        }
        for l in &all {
            note(l.line_no, self.send(l.line_no, l.text)?);
        }
        if !has("sensorStart") {
            note(0, self.send(0, "sensorStart")?);
        }
        Ok(report)
    }

    /// Stops the sensor (`sensorStop`).
    pub fn stop(&mut self) -> Result<(), CliError> {
        self.send(0, "sensorStop").map(|_| ())
    }

    /// Restarts the sensor with the configuration already loaded (`sensorStart 0`).
    pub fn start(&mut self) -> Result<(), CliError> {
        self.send(0, "sensorStart 0").map(|_| ())
    }

    /// Gives the port back.
    pub fn into_inner(self) -> P {
        self.port
    }
}

/// Opens a serial port for the CLI (115200 8N1) or data port (the configured baud) with a
/// short read timeout, so readers can notice when to stop.
pub fn open_serial(
    path: &str,
    baud: u32,
) -> Result<Box<dyn serialport::SerialPort>, serialport::Error> {
    serialport::new(path, baud)
        .timeout(Duration::from_millis(50))
        .open()
}
