//! Where a replay writes: a pseudo-terminal pair the rig creates (the system under test opens the
//! slave path like a device) or a real serial device (a USB-serial adapter wired to a board).

use crate::{HilError, StreamKind};
use serialport::{SerialPort, TTYPort};
use std::io::{self, Write};
use std::path::Path;
use std::thread;
use std::time::{Duration, Instant};

/// How long one write may be refused before the caller is told (nobody reading a pty?).
pub const BLOCKED_NOTICE: Duration = Duration::from_secs(1);

/// Write timeout of a sink's port: bounds how late a blocked write notices a stop request.
const WRITE_TIMEOUT: Duration = Duration::from_millis(100);

enum Port {
    /// The master side, and our own handle on the slave (kept open so the pair survives the
    /// system under test closing and reopening it).
    Pty { master: TTYPort, _slave: TTYPort },
    Device {
        port: Box<dyn SerialPort>,
        baud: u32,
    },
}

/// One output port of a replay.
pub struct Sink {
    stream: StreamKind,
    path: String,
    /// `None` only while a reopen has the port closed.
    port: Option<Port>,
    /// Bytes the system under test wrote back (read and discarded) \[B\].
    pub(crate) bytes_back: u64,
}

impl std::fmt::Debug for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sink")
            .field("stream", &self.stream)
            .field("path", &self.path)
            .field("pty", &self.is_pty())
            .finish()
    }
}

impl Sink {
    /// A new pseudo-terminal pair (raw mode); the system under test opens [`Sink::path`].
    pub fn pty(stream: StreamKind) -> Result<Sink, HilError> {
        let (master, slave, path) = new_pair(stream)?;
        Ok(Sink {
            stream,
            path,
            port: Some(Port::Pty {
                master,
                _slave: slave,
            }),
            bytes_back: 0,
        })
    }

    /// A serial device at `baud` (8N1, no flow control).
    pub fn device(stream: StreamKind, path: &str, baud: u32) -> Result<Sink, HilError> {
        let port = open_device(stream, path, baud)?;
        Ok(Sink {
            stream,
            path: path.to_string(),
            port: Some(Port::Device { port, baud }),
            bytes_back: 0,
        })
    }

    /// Which stream this sink carries.
    pub fn stream(&self) -> StreamKind {
        self.stream
    }

    /// The device path a system under test opens (pty slave) or the device written to.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// True for a pseudo-terminal the rig created.
    pub fn is_pty(&self) -> bool {
        matches!(self.port, Some(Port::Pty { .. }))
    }

    /// Processes other than the rig's own handle that hold the pty slave open (Linux: counted in
    /// `/proc/*/fd`; our own process counts beyond the handle the rig keeps). 0 for devices.
    pub fn slave_openers(&self) -> usize {
        if !self.is_pty() {
            return 0;
        }
        count_open(Path::new(&self.path)).saturating_sub(1)
    }

    /// Waits until someone opened the pty slave, up to `timeout` (`None`: until `stop`); true when
    /// it was opened (always true for devices).
    pub fn wait_open(&self, timeout: Option<Duration>, stop: &dyn Fn() -> bool) -> bool {
        let deadline = timeout.and_then(|t| Instant::now().checked_add(t));
        while self.is_pty() && self.slave_openers() == 0 {
            if deadline.is_some_and(|d| Instant::now() >= d) || stop() {
                return false;
            }
            thread::sleep(Duration::from_millis(20));
        }
        true
    }

    /// Writes all of `bytes`, retrying while the port is full (a reader that is slow or absent),
    /// until `stop` says so; `on_blocked` is called once when this call has been blocked for
    /// [`BLOCKED_NOTICE`]. Returns the time spent blocked.
    pub(crate) fn write_all(
        &mut self,
        bytes: &[u8],
        stop: &dyn Fn() -> bool,
        on_blocked: &mut dyn FnMut(&str),
    ) -> Result<Duration, HilError> {
        let mut rest = bytes;
        let mut blocked = Duration::ZERO;
        let mut told = false;
        while !rest.is_empty() {
            let t = Instant::now();
            let r = match &mut self.port {
                Some(Port::Pty { master, .. }) => master.write(rest),
                Some(Port::Device { port, .. }) => port.write(rest),
                None => Err(io::Error::new(
                    io::ErrorKind::NotConnected,
                    "the port is closed",
                )),
            };
            match r {
                Ok(0) => {
                    return Err(self.err(
                        "write",
                        io::Error::new(io::ErrorKind::WriteZero, "the port accepted no bytes"),
                    ))
                }
                Ok(n) => rest = &rest[n..],
                Err(e) if crate::is_transient(&e) => {
                    blocked += t.elapsed();
                    if !told && blocked >= BLOCKED_NOTICE {
                        told = true;
                        on_blocked(&self.path);
                    }
                    if stop() {
                        return Ok(blocked);
                    }
                }
                Err(e) => return Err(self.err("write", e)),
            }
        }
        Ok(blocked)
    }

    /// Reads and discards what the system under test wrote back (a pty's buffer would otherwise
    /// fill and block it).
    pub(crate) fn drain_input(&mut self) {
        let mut buf = [0u8; 1024];
        let port: &mut dyn SerialPort = match &mut self.port {
            Some(Port::Pty { master, .. }) => master,
            Some(Port::Device { port, .. }) => port.as_mut(),
            None => return,
        };
        while port.bytes_to_read().map(|n| n > 0).unwrap_or(false) {
            match port.read(&mut buf) {
                Ok(n) if n > 0 => self.bytes_back += n as u64,
                _ => break,
            }
        }
    }

    /// Closes the port and opens it again after `gap`. A pty gets a new pair: the kernel hands
    /// out the lowest free pty number, so the path stays the same when the system under test closed
    /// its end during the gap, and changes otherwise (see [`Sink::path`] afterwards). A device is
    /// reopened at the same path, retrying for up to 2 s (a USB adapter re-enumerating).
    pub(crate) fn reopen(&mut self, gap: Duration) -> Result<(), HilError> {
        let pty = self.is_pty();
        let baud = match &self.port {
            Some(Port::Device { baud, .. }) => *baud,
            _ => 0,
        };
        self.port = None;
        thread::sleep(gap);
        if pty {
            let (master, slave, path) = new_pair(self.stream)?;
            self.port = Some(Port::Pty {
                master,
                _slave: slave,
            });
            self.path = path;
            return Ok(());
        }
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            match open_device(self.stream, &self.path, baud) {
                Ok(port) => {
                    self.port = Some(Port::Device { port, baud });
                    return Ok(());
                }
                Err(e) if Instant::now() >= deadline => return Err(e),
                Err(_) => thread::sleep(Duration::from_millis(50)),
            }
        }
    }

    fn err(&self, action: &'static str, source: io::Error) -> HilError {
        HilError::Port {
            stream: self.stream,
            path: self.path.clone(),
            action,
            source,
        }
    }
}

fn new_pair(stream: StreamKind) -> Result<(TTYPort, TTYPort, String), HilError> {
    let e = |source: io::Error| HilError::Port {
        stream,
        path: "/dev/ptmx".into(),
        action: "create a pseudo-terminal",
        source,
    };
    let (mut master, slave) = TTYPort::pair().map_err(|x| e(x.into()))?;
    master.set_timeout(WRITE_TIMEOUT).map_err(|x| e(x.into()))?;
    let path = slave
        .name()
        .ok_or_else(|| e(io::Error::other("the slave has no path")))?;
    Ok((master, slave, path))
}

fn open_device(stream: StreamKind, path: &str, baud: u32) -> Result<Box<dyn SerialPort>, HilError> {
    serialport::new(path, baud)
        .timeout(WRITE_TIMEOUT)
        .open()
        .map_err(|source| HilError::Port {
            stream,
            path: path.to_string(),
            action: "open",
            source: source.into(),
        })
}

/// How many open file descriptors of all processes point at `path` (Linux `/proc`; 0 where it
/// cannot be read).
fn count_open(path: &Path) -> usize {
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return 0;
    };
    let mut n = 0;
    for p in procs.flatten() {
        let Ok(fds) = std::fs::read_dir(p.path().join("fd")) else {
            continue;
        };
        for fd in fds.flatten() {
            if std::fs::read_link(fd.path()).is_ok_and(|t| t == path) {
                n += 1;
            }
        }
    }
    n
}
