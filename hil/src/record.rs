//! Records the radar and IMU data ports into a session.
//!
//! ```text
//! radar data port --read thread--\                                 /-> radar.bin + radar.idx
//!                                 +--bounded channel--> writer ---+
//! IMU port --------read thread---/      (chunks)      (decodes    \-> imu.bin + imu.idx
//!                                                       live)
//! ```
//!
//! Through the sensor hub (`RecordConfig::hub`, docs/hub-link.md) one port carries both sensors:
//! each forwarded radar frame and IMU message becomes one chunk of its stream, timed by the hub's
//! clock at the frame's last byte (one clock for both sensors, mapped onto session time by one
//! offset, fixed at the first message), and the link's damage is counted ([`HubRecord`]).
//!
//! Each read is stamped with the host time since the session start, on one monotonic anchor
//! shared by both readers, and written unchanged with [`StreamWriter::write_chunk`]. A full channel
//! blocks its reader (counted as a queue-full event) for at most [`RecordConfig::max_block`]; past
//! that the recording fails loudly, never drops. At exit, bytes read == bytes written is checked
//! per stream. Radar and IMU frames are decoded on the writer side for the progress line.

use crate::{HilError, StreamKind};
use crossbeam_channel::{bounded, RecvTimeoutError, SendTimeoutError, Sender, TrySendError};
use hub_link::{Deframer, Event, LinkClock, Message, FRAME_MAX};
use imu_driver::host::{Device, Plan};
use imu_driver::{DataId, LogFramer, OutputSetting};
use milliego_session::{Meta, SessionWriter, Source, StreamWriter};
use radar_driver::host::CliPort;
use radar_driver::{Framer, DEFAULT_MAX_FRAME};
use serialport::SerialPort;
use std::io::{self, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

/// The radar's ports.
#[derive(Debug, Clone, PartialEq)]
pub struct RadarPorts {
    /// Data port device.
    pub data: String,
    /// Data port baud rate \[bit/s\].
    pub data_baud: u32,
    /// CLI port device (needed to configure and to send sensorStop at the end).
    pub cli: Option<String>,
    /// The .cfg text to upload (also saved as the session's `radar.cfg`).
    pub cfg: Option<String>,
}

/// The IMU's port.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuPort {
    /// Device.
    pub path: String,
    /// Baud rate \[bit/s\].
    pub baud: u32,
    /// Inertial output rate to configure \[Hz\].
    pub rate_hz: u16,
}

/// The sensor hub's link port: radar frames and IMU messages, verbatim, with the hub's timestamps.
#[derive(Debug, Clone, PartialEq)]
pub struct HubPort {
    /// Device.
    pub path: String,
    /// Baud rate \[bit/s\].
    pub baud: u32,
    /// Radar CLI port: the hub forwards the radar's data port only, so the .cfg upload and
    /// sensorStop go to the radar directly.
    pub radar_cli: Option<String>,
    /// The radar's .cfg (saved as the session's `radar.cfg`; uploaded when configuring).
    pub radar_cfg: Option<String>,
}

/// What to record.
#[derive(Debug, Clone)]
pub struct RecordConfig {
    /// The new session directory.
    pub out: PathBuf,
    /// The radar, if recorded.
    pub radar: Option<RadarPorts>,
    /// The IMU, if recorded.
    pub imu: Option<ImuPort>,
    /// Both sensors through the sensor hub instead (excludes `radar` and `imu`). The IMU cannot
    /// be configured through the hub; configuring uploads the radar's .cfg over its CLI port.
    pub hub: Option<HubPort>,
    /// Configure the sensors first (radar .cfg upload, IMU output configuration); at the end
    /// sensorStop / GoToConfig.
    pub configure: bool,
    /// Stop after this long (else at [`RecordConfig::stop`]).
    pub duration: Option<Duration>,
    /// Chunks the channel holds before a reader blocks.
    pub queue_chunks: usize,
    /// Longest a reader may block on a full channel before the recording fails.
    pub max_block: Duration,
    /// Read timeout of the data ports: bounds how late a reader notices a stop.
    pub read_timeout: Duration,
    /// Progress line on stderr every this long (None: quiet).
    pub progress: Option<Duration>,
    /// Set to stop (Ctrl-C).
    pub stop: Arc<AtomicBool>,
}

impl Default for RecordConfig {
    fn default() -> Self {
        RecordConfig {
            out: PathBuf::from("session"),
            radar: None,
            imu: None,
            hub: None,
            configure: true,
            duration: None,
            queue_chunks: 1024,
            max_block: Duration::from_secs(2),
            read_timeout: Duration::from_millis(50),
            progress: None,
            stop: Arc::new(AtomicBool::new(false)),
        }
    }
}

/// Live counters of one stream, readable while recording.
#[derive(Debug, Default)]
pub struct LiveStream {
    /// Bytes read from the port \[B\].
    pub bytes_read: AtomicU64,
    /// Bytes written to the session \[B\].
    pub bytes_written: AtomicU64,
    /// Reads that returned data.
    pub chunks: AtomicU64,
    /// Times a reader found the channel full and had to wait.
    pub queue_full: AtomicU64,
    /// Frames decoded (radar frames, Xbus messages).
    pub frames_ok: AtomicU64,
    /// Candidates the decoder rejected.
    pub frames_bad: AtomicU64,
    /// Bytes the decoder skipped \[B\].
    pub bytes_skipped: AtomicU64,
    /// Longest a reader waited on a full channel \[ns\].
    pub max_wait_ns: AtomicU64,
}

/// Live counters of a recording (share it with a thread that watches).
#[derive(Debug, Default)]
pub struct Live {
    /// The radar stream.
    pub radar: LiveStream,
    /// The IMU stream.
    pub imu: LiveStream,
}

impl Live {
    /// The counters of one stream.
    pub fn stream(&self, kind: StreamKind) -> &LiveStream {
        match kind {
            StreamKind::Radar => &self.radar,
            StreamKind::Imu => &self.imu,
        }
    }
}

/// The outcome of one stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamRecord {
    /// Which stream.
    pub stream: StreamKind,
    /// The port recorded.
    pub port: String,
    /// Bytes read \[B\].
    pub bytes_read: u64,
    /// Bytes written \[B\] (equal to `bytes_read`, checked).
    pub bytes_written: u64,
    /// Reads that returned data (= index records).
    pub chunks: u64,
    /// Times the reader waited on a full channel.
    pub queue_full: u64,
    /// Longest such wait \[ns\].
    pub max_wait_ns: u64,
    /// Frames decoded.
    pub frames_ok: u64,
    /// Candidates rejected by the decoder.
    pub frames_bad: u64,
    /// Bytes the decoder skipped \[B\].
    pub bytes_skipped: u64,
}

/// What came over the hub's link.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HubRecord {
    /// The link port.
    pub port: String,
    /// Bytes read from the link \[B\].
    pub link_bytes: u64,
    /// Messages decoded (radar, IMU, health).
    pub messages: u64,
    /// Link frames that failed COBS, CRC or message checks (their bytes are in `bytes_dropped`).
    pub bad_frames: u64,
    /// Bytes of those frames and of partial ones \[B\].
    pub bytes_dropped: u64,
    /// Lone delimiters (0x00 with no frame before it: a sender's flush, or a frame's first byte
    /// damaged into a delimiter, whose other bytes are then in `bytes_dropped`) \[B\].
    pub empty_frames: u64,
    /// Messages missing by the link's sequence numbers (dropped by the hub for backpressure, or
    /// destroyed on the way).
    pub seq_gaps: u64,
    /// Times the hub restarted (sequence back to 0); each re-anchors its clock.
    pub restarts: u64,
    /// Frames whose hub time went back within a stream (written at the previous time).
    pub stamps_clamped: u64,
    /// The hub's last health message (its own counters: UART bytes, framer rejects, drops).
    pub health: Option<hub_link::Health>,
}

/// What a recording did.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordReport {
    /// The session directory.
    pub dir: PathBuf,
    /// Per recorded stream.
    pub streams: Vec<StreamRecord>,
    /// Recording time \[s\].
    pub seconds: f64,
    /// Shutdown steps that failed (sensorStop, GoToConfig): reported, not fatal.
    pub warnings: Vec<String>,
    /// The hub's link, when recorded through the hub.
    pub hub: Option<HubRecord>,
}

enum Msg {
    Chunk {
        kind: StreamKind,
        host_ns: u64,
        bytes: Vec<u8>,
    },
}

struct ReaderEnd<P> {
    port: P,
    error: Option<HilError>,
    hub: Option<HubRecord>,
}

/// Configures the sensors (unless told not to), records until the duration, a stop request or a
/// port error, shuts the sensors down, and writes the session. The session is written even when a
/// port fails (with what was read until then), and the error is returned after that.
pub fn record(cfg: &RecordConfig, live: &Arc<Live>) -> Result<RecordReport, HilError> {
    if cfg.radar.is_none() && cfg.imu.is_none() && cfg.hub.is_none() {
        return Err(HilError::Invalid(
            "nothing to record: give the radar data port and/or the IMU port, or the hub's".into(),
        ));
    }
    if cfg.hub.is_some() && (cfg.radar.is_some() || cfg.imu.is_some()) {
        return Err(HilError::Invalid(
            "the hub's link carries both sensors: give it or the sensors' own data ports, not both"
                .into(),
        ));
    }
    if cfg.configure {
        if let Some(r) = &cfg.radar {
            if r.cli.is_none() || r.cfg.is_none() {
                return Err(HilError::Invalid(
                    "configuring the radar needs --radar-cli and --radar-cfg (or use --no-config)"
                        .into(),
                ));
            }
        }
        if let Some(h) = &cfg.hub {
            if h.radar_cli.is_none() || h.radar_cfg.is_none() {
                return Err(HilError::Invalid(
                    "configuring the radar behind the hub needs --radar-cli and --radar-cfg (the hub forwards its data port only; the IMU cannot be configured through the hub); or use --no-config"
                        .into(),
                ));
            }
        }
    }
    let mut writer = SessionWriter::create(&cfg.out, Meta::new(Source::Recorded))?;
    let mut warnings = Vec::new();
    if let Some(h) = &cfg.hub {
        if let Some(text) = &h.radar_cfg {
            writer.radar_cfg(text)?;
        }
        let port = format!("hub {}", h.path);
        writer
            .meta_mut()
            .radar
            .get_or_insert_with(Default::default)
            .port = Some(port.clone());
        writer
            .meta_mut()
            .imu
            .get_or_insert_with(Default::default)
            .port = Some(port);
        writer.meta_mut().description = format!(
            "recorded through the sensor hub on {}: each index record is one frame, timed by the hub's clock at its last byte (docs/hub-link.md)",
            h.path
        );
    }
    if let Some(r) = &cfg.radar {
        if let Some(text) = &r.cfg {
            writer.radar_cfg(text)?;
        }
        let m = writer.meta_mut().radar.get_or_insert_with(Default::default);
        m.baud = r.data_baud;
        m.port = Some(r.data.clone());
    }
    if let Some(m) = &cfg.imu {
        let im = writer.meta_mut().imu.get_or_insert_with(Default::default);
        im.baud = m.baud;
        im.port = Some(m.path.clone());
        if cfg.configure {
            im.rate_hz = Some(f64::from(m.rate_hz));
        }
    }

    // The writer first, then each reader as soon as its port is ready: the radar's before its
    // sensorStart, the IMU's right after its configuration, so the kernel's buffer never has to
    // hold a stream while the other sensor is being configured. Session time starts here.
    let anchor = Instant::now();
    let (tx, rx) = bounded::<Msg>(cfg.queue_chunks.max(1));
    let halt = Arc::new(AtomicBool::new(false));
    let failed = Arc::new(AtomicBool::new(false));
    let mut files = Vec::new();
    if cfg.radar.is_some() || cfg.hub.is_some() {
        files.push((StreamKind::Radar, writer.stream(StreamKind::Radar)?));
    }
    if cfg.imu.is_some() || cfg.hub.is_some() {
        files.push((StreamKind::Imu, writer.stream(StreamKind::Imu)?));
    }
    let wlive = live.clone();
    let progress = cfg.progress;
    let writer_thread = thread::Builder::new()
        .name("record-writer".into())
        .spawn(move || write_loop(rx, files, &wlive, progress, anchor))
        .map_err(|e| HilError::Invalid(format!("cannot start the writer thread: {e}")))?;
    let spawn = |kind: StreamKind, path: String, port: Box<dyn SerialPort>| {
        let (tx, live, halt, failed) = (tx.clone(), live.clone(), halt.clone(), failed.clone());
        let max_block = cfg.max_block;
        thread::Builder::new()
            .name(format!("record-{}", kind.name()))
            .spawn(move || {
                read_loop(
                    kind, path, port, tx, &live, &halt, &failed, anchor, max_block,
                )
            })
            .map_err(|e| HilError::Invalid(format!("cannot start a reader thread: {e}")))
    };
    let mut readers = Vec::new();
    let mut cli = None;
    let setup = (|| -> Result<(), HilError> {
        if let Some(h) = &cfg.hub {
            let port = open(StreamKind::Radar, &h.path, h.baud, cfg.read_timeout)?;
            let (tx, live, halt, failed) = (tx.clone(), live.clone(), halt.clone(), failed.clone());
            let (path, max_block) = (h.path.clone(), cfg.max_block);
            let t = thread::Builder::new()
                .name("record-hub".into())
                .spawn(move || {
                    hub_read_loop(path, port, tx, &live, &halt, &failed, anchor, max_block)
                })
                .map_err(|e| HilError::Invalid(format!("cannot start the hub reader: {e}")))?;
            readers.push((StreamKind::Radar, t));
        }
        if let Some(r) = &cfg.radar {
            let port = open(StreamKind::Radar, &r.data, r.data_baud, cfg.read_timeout)?;
            readers.push((
                StreamKind::Radar,
                spawn(StreamKind::Radar, r.data.clone(), port)?,
            ));
        }
        if let Some(m) = &cfg.imu {
            let mut port = open(StreamKind::Imu, &m.path, m.baud, cfg.read_timeout)?;
            if cfg.configure {
                let mut dev = Device::new(port);
                let report = dev
                    .configure(&imu_plan(m.rate_hz))
                    .map_err(|e| HilError::Config {
                        stream: StreamKind::Imu,
                        what: format!("{}: {e}", m.path),
                    })?;
                writer
                    .meta_mut()
                    .imu
                    .get_or_insert_with(Default::default)
                    .device = Some(report.product_code.trim().to_string());
                port = dev.into_reader().into_inner();
            }
            readers.push((
                StreamKind::Imu,
                spawn(StreamKind::Imu, m.path.clone(), port)?,
            ));
        }
        let radar_cli = match (&cfg.radar, &cfg.hub) {
            (Some(r), _) => r.cli.as_ref().zip(r.cfg.as_ref()),
            (None, Some(h)) => h.radar_cli.as_ref().zip(h.radar_cfg.as_ref()),
            (None, None) => None,
        };
        if let (true, Some((cli_path, text))) = (cfg.configure, radar_cli) {
            let port = open(
                StreamKind::Radar,
                cli_path,
                115_200,
                Duration::from_millis(50),
            )?;
            let mut c = CliPort::new(port, Duration::from_secs(2));
            let uploaded = c.upload(text);
            // sensorStop at the end even when a later line failed after sensorStart.
            cli = Some(c);
            uploaded.map_err(|e| HilError::Config {
                stream: StreamKind::Radar,
                what: format!("{cli_path}: {e}"),
            })?;
        }
        Ok(())
    })();
    drop(tx);

    if setup.is_ok() {
        while !cfg.stop.load(Ordering::SeqCst)
            && !failed.load(Ordering::SeqCst)
            && cfg.duration.is_none_or(|d| anchor.elapsed() < d)
        {
            thread::sleep(Duration::from_millis(20));
        }
    }
    halt.store(true, Ordering::SeqCst);

    let mut first_err = None;
    let mut ends = Vec::new();
    let mut hub = None;
    for (kind, h) in readers {
        match h.join() {
            Ok(mut end) => {
                if let Some(e) = end.error.take() {
                    first_err.get_or_insert(e);
                }
                hub = hub.or(end.hub.take());
                ends.push((kind, end));
            }
            Err(_) => {
                first_err.get_or_insert(HilError::Invalid(format!(
                    "the {} reader thread panicked",
                    kind.name()
                )));
            }
        }
    }
    let written = match writer_thread.join() {
        Ok(r) => r,
        Err(_) => Err(HilError::Invalid("the writer thread panicked".into())),
    };
    let seconds = anchor.elapsed().as_secs_f64();

    // Shut the sensors down (best effort: the recording is already safe).
    if let Some(mut c) = cli {
        if let Err(e) = c.stop() {
            warnings.push(format!("radar CLI: sensorStop failed: {e}"));
        }
    }
    if cfg.configure && cfg.imu.is_some() {
        if let Some((_, end)) = ends.into_iter().find(|(k, _)| *k == StreamKind::Imu) {
            let mut dev = Device::new(end.port);
            if let Err(e) = dev.go_to_config() {
                warnings.push(format!("IMU: GoToConfig failed: {e}"));
            }
        }
    }

    let written = written?;
    // A failed setup leaves the data files but no session.toml: not a session.
    setup?;
    let dir = writer.finish()?;
    if let Some(e) = first_err {
        return Err(e);
    }
    let mut out = Vec::new();
    for (kind, bytes_written) in written {
        let l = live.stream(kind);
        let bytes_read = l.bytes_read.load(Ordering::SeqCst);
        if bytes_read != bytes_written {
            return Err(HilError::Lost {
                stream: kind,
                read: bytes_read,
                written: bytes_written,
            });
        }
        out.push(StreamRecord {
            stream: kind,
            port: match (kind, &cfg.hub) {
                (_, Some(h)) => Some(format!("hub {}", h.path)),
                (StreamKind::Radar, None) => cfg.radar.as_ref().map(|r| r.data.clone()),
                (StreamKind::Imu, None) => cfg.imu.as_ref().map(|m| m.path.clone()),
            }
            .unwrap_or_default(),
            bytes_read,
            bytes_written,
            chunks: l.chunks.load(Ordering::SeqCst),
            queue_full: l.queue_full.load(Ordering::SeqCst),
            max_wait_ns: l.max_wait_ns.load(Ordering::SeqCst),
            frames_ok: l.frames_ok.load(Ordering::SeqCst),
            frames_bad: l.frames_bad.load(Ordering::SeqCst),
            bytes_skipped: l.bytes_skipped.load(Ordering::SeqCst),
        });
    }
    Ok(RecordReport {
        dir,
        streams: out,
        seconds,
        warnings,
        hub,
    })
}

/// The IMU outputs recorded: PacketCounter and SampleTimeFine with every message, acceleration,
/// rate of turn and the status word at `rate_hz`.
pub fn imu_plan(rate_hz: u16) -> Plan {
    let s = |id: u16, rate_hz: u16| OutputSetting {
        id: DataId(id),
        rate_hz,
    };
    Plan {
        outputs: vec![
            s(0x1020, OutputSetting::MAX_RATE),
            s(0x1060, OutputSetting::MAX_RATE),
            s(0x4020, rate_hz),
            s(0x8020, rate_hz),
            s(0xE020, rate_hz),
        ],
        baudrate: None,
        measure: true,
    }
}

fn open(
    stream: StreamKind,
    path: &str,
    baud: u32,
    timeout: Duration,
) -> Result<Box<dyn SerialPort>, HilError> {
    serialport::new(path, baud)
        .timeout(timeout)
        .open()
        .map_err(|e| HilError::Port {
            stream,
            path: path.to_string(),
            action: "open",
            source: e.into(),
        })
}

/// One read of a port: `Some(n)` bytes, `None` for a timeout or an interruption (try again), or
/// the error to report, with a hint naming `what` (the device or the hub) as the likely cause.
fn read_port<P: io::Read>(port: &mut P, buf: &mut [u8], what: &str) -> io::Result<Option<usize>> {
    match port.read(buf) {
        Ok(0) => Err(io::Error::new(
            io::ErrorKind::UnexpectedEof,
            format!("the port reported end of file ({what} gone?)"),
        )),
        Ok(n) => Ok(Some(n)),
        Err(e) if crate::is_transient(&e) => Ok(None),
        Err(e) => Err(io::Error::new(
            e.kind(),
            format!("{e} ({what} unplugged, or the other end closed?)"),
        )),
    }
}

#[allow(clippy::too_many_arguments)]
fn read_loop<P: io::Read>(
    kind: StreamKind,
    path: String,
    mut port: P,
    tx: Sender<Msg>,
    live: &Live,
    stop: &AtomicBool,
    failed: &AtomicBool,
    anchor: Instant,
    max_block: Duration,
) -> ReaderEnd<P> {
    let l = live.stream(kind);
    let mut buf = vec![0u8; 1 << 16];
    let fail = |action: &'static str, source: io::Error| {
        failed.store(true, Ordering::SeqCst);
        Some(HilError::Port {
            stream: kind,
            path: path.clone(),
            action,
            source,
        })
    };
    let mut error = None;
    while !stop.load(Ordering::Relaxed) {
        let n = match read_port(&mut port, &mut buf, "device") {
            Ok(Some(n)) => n,
            Ok(None) => continue,
            Err(e) => {
                error = fail("read", e);
                break;
            }
        };
        let host_ns = u64::try_from(anchor.elapsed().as_nanos()).unwrap_or(u64::MAX);
        l.bytes_read.fetch_add(n as u64, Ordering::SeqCst);
        l.chunks.fetch_add(1, Ordering::Relaxed);
        let msg = Msg::Chunk {
            kind,
            host_ns,
            bytes: buf[..n].to_vec(),
        };
        if let Err((action, source)) = send(&tx, msg, l, max_block, n) {
            error = fail(action, source);
            break;
        }
    }
    ReaderEnd {
        port,
        error,
        hub: None,
    }
}

/// Hands a chunk to the writer: at once, or after waiting at most `max_block` on a full queue
/// (counted); past that, or with the writer gone, the failure to report (`n` bytes unwritten).
fn send(
    tx: &Sender<Msg>,
    msg: Msg,
    l: &LiveStream,
    max_block: Duration,
    n: usize,
) -> Result<(), (&'static str, io::Error)> {
    let gone = || {
        (
            "queue",
            io::Error::other(format!("the writer stopped; {n} B read but not written")),
        )
    };
    match tx.try_send(msg) {
        Ok(()) => Ok(()),
        Err(TrySendError::Full(msg)) => {
            l.queue_full.fetch_add(1, Ordering::Relaxed);
            let t = Instant::now();
            let r = tx.send_timeout(msg, max_block);
            let waited = u64::try_from(t.elapsed().as_nanos()).unwrap_or(u64::MAX);
            l.max_wait_ns.fetch_max(waited, Ordering::Relaxed);
            match r {
                Ok(()) => Ok(()),
                Err(SendTimeoutError::Timeout(_)) => Err((
                    "queue (the writer fell behind)",
                    io::Error::new(
                        io::ErrorKind::TimedOut,
                        format!(
                            "the queue to the writer stayed full for {max_block:?}; {n} B read but not written"
                        ),
                    ),
                )),
                Err(SendTimeoutError::Disconnected(_)) => Err(gone()),
            }
        }
        Err(TrySendError::Disconnected(_)) => Err(gone()),
    }
}

/// The hub's link port -> one chunk per forwarded frame, on the hub's clock.
#[allow(clippy::too_many_arguments)]
fn hub_read_loop<P: io::Read>(
    path: String,
    mut port: P,
    tx: Sender<Msg>,
    live: &Live,
    stop: &AtomicBool,
    failed: &AtomicBool,
    anchor: Instant,
    max_block: Duration,
) -> ReaderEnd<P> {
    let mut buf = vec![0u8; 1 << 16];
    let mut deframer: Box<Deframer<FRAME_MAX>> = Box::default();
    let mut rec = HubRecord {
        port: path.clone(),
        ..HubRecord::default()
    };
    // The hub's clock on session time; the last time written per stream [ns].
    let mut clock = LinkClock::default();
    let mut last = [0u64; 2];
    let fail = |action: &'static str, source: io::Error| {
        failed.store(true, Ordering::SeqCst);
        Some(HilError::Port {
            stream: StreamKind::Radar,
            path: format!("{path} (hub link)"),
            action,
            source,
        })
    };
    let mut error = None;
    'read: while !stop.load(Ordering::Relaxed) {
        let n = match read_port(&mut port, &mut buf, "hub") {
            Ok(Some(n)) => n,
            Ok(None) => continue,
            Err(e) => {
                error = fail("read", e);
                break;
            }
        };
        let host_ns = u64::try_from(anchor.elapsed().as_nanos()).unwrap_or(u64::MAX);
        rec.link_bytes += n as u64;
        let mut input = &buf[..n];
        loop {
            let m = match deframer.poll(&mut input) {
                Event::Message(m) => m,
                Event::BadFrame(_) => continue,
                Event::NeedMore => break,
            };
            let at = clock.observe(m.header(), host_ns).t_ns;
            let (kind, bytes) = match m {
                Message::Radar { bytes, .. } => (StreamKind::Radar, bytes),
                Message::Imu { bytes, .. } => (StreamKind::Imu, bytes),
                Message::Health { health, .. } => {
                    rec.health = Some(health);
                    continue;
                }
            };
            let i = usize::from(kind == StreamKind::Imu);
            if at < last[i] {
                rec.stamps_clamped += 1;
            }
            last[i] = last[i].max(at);
            let l = live.stream(kind);
            l.bytes_read.fetch_add(bytes.len() as u64, Ordering::SeqCst);
            l.chunks.fetch_add(1, Ordering::Relaxed);
            let msg = Msg::Chunk {
                kind,
                host_ns: last[i],
                bytes: bytes.to_vec(),
            };
            if let Err((action, source)) = send(&tx, msg, l, max_block, bytes.len()) {
                error = fail(action, source);
                break 'read;
            }
        }
    }
    let c = deframer.counters();
    rec.seq_gaps = clock.seq_gaps;
    rec.restarts = clock.restarts;
    rec.messages = c.messages_ok;
    rec.bad_frames = c.frames_bad_cobs + c.frames_bad_message + c.frames_overflow;
    rec.bytes_dropped = c.bytes_dropped;
    rec.empty_frames = c.empty_frames;
    ReaderEnd {
        port,
        error,
        hub: Some(rec),
    }
}

/// Per-stream decoder for the live counters.
enum Decoder {
    Radar(Box<Framer<DEFAULT_MAX_FRAME>>),
    Imu(Box<LogFramer>),
}

impl Decoder {
    fn feed(&mut self, bytes: &[u8], l: &LiveStream) {
        let mut input = bytes;
        match self {
            Decoder::Radar(f) => {
                while !matches!(f.poll(&mut input), radar_driver::Poll::NeedMore) {}
                let c = f.counters();
                l.frames_ok.store(c.frames_ok, Ordering::Relaxed);
                l.frames_bad.store(c.frames_bad_total(), Ordering::Relaxed);
                l.bytes_skipped.store(c.bytes_skipped, Ordering::Relaxed);
            }
            Decoder::Imu(f) => {
                while !matches!(f.poll(&mut input), imu_driver::Poll::NeedMore) {}
                let c = f.counters();
                l.frames_ok.store(c.frames_ok, Ordering::Relaxed);
                l.frames_bad.store(c.frames_bad.total(), Ordering::Relaxed);
                l.bytes_skipped.store(c.bytes_skipped, Ordering::Relaxed);
            }
        }
    }
}

type Written = Vec<(StreamKind, u64)>;

fn write_loop(
    rx: crossbeam_channel::Receiver<Msg>,
    files: Vec<(StreamKind, StreamWriter)>,
    live: &Live,
    progress: Option<Duration>,
    anchor: Instant,
) -> Result<Written, HilError> {
    let mut outs: Vec<(StreamKind, StreamWriter, Decoder)> = files
        .into_iter()
        .map(|(k, w)| {
            let d = match k {
                StreamKind::Radar => Decoder::Radar(Box::default()),
                StreamKind::Imu => Decoder::Imu(Box::default()),
            };
            (k, w, d)
        })
        .collect();
    let mut last_progress = Instant::now();
    let mut last_counts = [(0u64, 0u64); 2];
    loop {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Msg::Chunk {
                kind,
                host_ns,
                bytes,
            }) => {
                if let Some((_, w, d)) = outs.iter_mut().find(|o| o.0 == kind) {
                    w.write_chunk(host_ns, &bytes)?;
                    let l = live.stream(kind);
                    l.bytes_written.store(w.written(), Ordering::SeqCst);
                    d.feed(&bytes, l);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if let Some(every) = progress {
            if last_progress.elapsed() >= every {
                let dt = last_progress.elapsed().as_secs_f64();
                last_progress = Instant::now();
                print_progress(live, &outs, anchor, dt, &mut last_counts);
            }
        }
    }
    let mut out = Vec::new();
    for (k, w, _) in outs {
        let n = w.finish()?;
        live.stream(k).bytes_written.store(n, Ordering::SeqCst);
        out.push((k, n));
    }
    Ok(out)
}

fn print_progress(
    live: &Live,
    outs: &[(StreamKind, StreamWriter, Decoder)],
    anchor: Instant,
    dt: f64,
    last: &mut [(u64, u64); 2],
) {
    let mut line = format!("rec {:7.1} s", anchor.elapsed().as_secs_f64());
    for (k, _, _) in outs {
        let l = live.stream(*k);
        let i = usize::from(*k == StreamKind::Imu);
        let bytes = l.bytes_written.load(Ordering::Relaxed);
        let frames = l.frames_ok.load(Ordering::Relaxed);
        let (b0, f0) = last[i];
        last[i] = (bytes, frames);
        line.push_str(&format!(
            " | {} {} B {:.1} kB/s {} {} {:.1}/s bad {} skipped {} B queue-full {}",
            k.name(),
            bytes,
            (bytes - b0) as f64 / dt / 1000.0,
            frames,
            if *k == StreamKind::Radar {
                "frames"
            } else {
                "msgs"
            },
            (frames - f0) as f64 / dt,
            l.frames_bad.load(Ordering::Relaxed),
            l.bytes_skipped.load(Ordering::Relaxed),
            l.queue_full.load(Ordering::Relaxed),
        ));
    }
    let mut err = io::stderr().lock();
    let _ = writeln!(err, "{line}");
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A port that yields `chunks` reads of 100 bytes, then times out.
    struct Chunks(usize);

    impl io::Read for Chunks {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.0 == 0 {
                thread::sleep(Duration::from_millis(5));
                return Err(io::ErrorKind::TimedOut.into());
            }
            self.0 -= 1;
            buf[..100].fill(0x55);
            Ok(100)
        }
    }

    fn reader(
        chunks: usize,
        queue: usize,
        max_block: Duration,
    ) -> (
        crossbeam_channel::Receiver<Msg>,
        Arc<Live>,
        Arc<AtomicBool>,
        thread::JoinHandle<ReaderEnd<Chunks>>,
    ) {
        let (tx, rx) = bounded(queue);
        let live = Arc::new(Live::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (l, s) = (live.clone(), stop.clone());
        let h = thread::spawn(move || {
            let failed = AtomicBool::new(false);
            read_loop(
                StreamKind::Imu,
                "fake".into(),
                Chunks(chunks),
                tx,
                &l,
                &s,
                &failed,
                Instant::now(),
                max_block,
            )
        });
        (rx, live, stop, h)
    }

    #[test]
    fn a_slow_writer_blocks_the_reader_counted_and_loses_nothing() {
        let (rx, live, stop, h) = reader(20, 1, Duration::from_secs(5));
        let mut got = 0u64;
        while got < 2000 {
            thread::sleep(Duration::from_millis(3));
            match rx.recv_timeout(Duration::from_secs(5)) {
                Ok(Msg::Chunk { bytes, .. }) => got += bytes.len() as u64,
                Err(e) => panic!("{e}"),
            }
        }
        stop.store(true, Ordering::SeqCst);
        let end = h.join().unwrap();
        assert!(end.error.is_none());
        assert_eq!(live.imu.bytes_read.load(Ordering::SeqCst), 2000);
        assert!(live.imu.queue_full.load(Ordering::SeqCst) > 0);
        assert!(live.imu.max_wait_ns.load(Ordering::SeqCst) > 0);
    }

    #[test]
    fn a_stuck_writer_fails_the_recording_loudly() {
        let (rx, live, _stop, h) = reader(5, 1, Duration::from_millis(100));
        let end = h.join().unwrap();
        let e = end.error.expect("an error").to_string();
        assert!(
            e.contains("stayed full") && e.contains("100 B read but not written"),
            "{e}"
        );
        assert_eq!(live.imu.bytes_read.load(Ordering::SeqCst), 200);
        drop(rx);
    }
}
