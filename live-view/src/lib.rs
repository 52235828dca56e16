//! The live view of `milliego run --foxglove` and `milliego view`: one thread takes what the
//! runtime offers on its view channel ([`milliego_runtime::view`]) and publishes it with the
//! official Foxglove SDK's WebSocket server. Clients may ask for the published protocol's
//! subprotocol `foxglove.websocket.v1` (Lichtblick, Foxglove's spec) or the SDK's
//! `foxglove.sdk.v1`; a small front translates the first (`front.rs`).
//!
//! Channels (docs/live-view.md):
//!
//! | topic | schema | encoding |
//! |---|---|---|
//! | `/radar/points` | `foxglove.PointCloud` (x, y, z, doppler, snr; frame `radar`) | protobuf |
//! | `/pose` | `foxglove.PoseInFrame` (frame `world`) | protobuf |
//! | `/trajectory` | `foxglove.PosesInFrame` (radar-rate poses so far) | protobuf |
//! | `/tf` | `foxglove.FrameTransforms` (world -> body -> radar / imu) | protobuf |
//! | `/imu` | `milliego.Imu` ([`IMU_SCHEMA`]) | JSON |
//! | `/velocity` | `milliego.Velocity` ([`VELOCITY_SCHEMA`]) | JSON |
//! | `/health` | `milliego.Health` ([`HEALTH_SCHEMA`]) | JSON |
//! | `/ground_truth/pose`, `/ground_truth/trajectory` | as `/pose`, `/trajectory` (sessions with ground truth) | protobuf |
//!
//! The server never blocks the runtime: the runtime's hand-off drops and counts what this thread
//! cannot take, and the front keeps a bounded backlog of channel messages per client (the oldest
//! dropped and counted, [`ViewCounters::client_dropped`], for a client that does not read).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod front;
mod gt;
mod publish;

use crossbeam_channel::{Receiver, RecvTimeoutError};
use foxglove::{Context, WebSocketServer, WebSocketServerHandle};
use milliego_runtime::view::{ViewEvent, ViewTap, DEFAULT_VIEW_CAPACITY};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use front::LEGACY_SUBPROTOCOL;
pub use publish::{HEALTH_SCHEMA, IMU_SCHEMA, VELOCITY_SCHEMA};

/// Every topic the view may advertise (the ground-truth ones only for sessions that have it).
pub const TOPICS: &[&str] = &[
    "/radar/points",
    "/pose",
    "/trajectory",
    "/tf",
    "/imu",
    "/velocity",
    "/health",
    "/ground_truth/pose",
    "/ground_truth/trajectory",
];

/// Where the view listens when `--foxglove` names no address: loopback only.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// Channel messages queued per client before that client's oldest is dropped.
pub const DEFAULT_BACKLOG: usize = 4096;
/// The SDK's own per-client queue: it feeds the front's reader, which never waits for a
/// client, so it does not fill; drops happen (and are counted) in the front.
const SDK_BACKLOG: usize = 4 * DEFAULT_BACKLOG;

/// Settings of a live view.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Host to bind (loopback by default; anything else is the user's explicit choice).
    pub host: String,
    /// TCP port (0: any free port).
    pub port: u16,
    /// The session being run, for its ground truth.
    pub session: Option<PathBuf>,
    /// Items the runtime's hand-off holds before it drops (and counts).
    pub capacity: usize,
    /// Messages the SDK queues per client.
    pub backlog: usize,
}

impl ViewOptions {
    /// Options for `HOST:PORT` (or a bare `PORT`, on loopback).
    pub fn parse_addr(addr: &str) -> Result<ViewOptions, ViewError> {
        let bad = || ViewError::Address {
            addr: addr.to_string(),
        };
        let (host, port) = match addr.rsplit_once(':') {
            Some((h, p)) => (h.trim_start_matches('[').trim_end_matches(']'), p),
            None => ("127.0.0.1", addr),
        };
        if host.is_empty() {
            return Err(bad());
        }
        let port = port.parse::<u16>().map_err(|_| bad())?;
        Ok(ViewOptions {
            host: host.to_string(),
            port,
            session: None,
            capacity: DEFAULT_VIEW_CAPACITY,
            backlog: DEFAULT_BACKLOG,
        })
    }

    /// True when the host is a loopback address (or `localhost`).
    pub fn is_loopback(&self) -> bool {
        self.host == "localhost"
            || self
                .host
                .parse::<std::net::IpAddr>()
                .is_ok_and(|ip| ip.is_loopback())
    }
}

/// Why a view could not start.
#[derive(Debug)]
pub enum ViewError {
    /// `--foxglove` is not `HOST:PORT` or `PORT`.
    Address {
        /// What was given.
        addr: String,
    },
    /// The address could not be bound.
    Bind {
        /// `HOST:PORT`.
        addr: String,
        /// The OS error.
        error: std::io::Error,
    },
    /// The server could not start.
    Start {
        /// `HOST:PORT`.
        addr: String,
        /// The SDK's error.
        error: foxglove::FoxgloveError,
    },
    /// The session's ground truth could not be read.
    GroundTruth {
        /// Session directory.
        dir: PathBuf,
        /// The session reader's error.
        error: milliego_session::SessionError,
    },
    /// The view thread could not be started.
    Spawn(std::io::Error),
}

impl std::fmt::Display for ViewError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ViewError::Address { addr } => {
                write!(f, "--foxglove {addr:?}: expected HOST:PORT or PORT")
            }
            ViewError::Bind { addr, error } => {
                write!(f, "live view on {addr}: cannot listen: {error}")
            }
            ViewError::Start { addr, error } => {
                write!(f, "live view on {addr}: cannot start the server: {error}")
            }
            ViewError::GroundTruth { dir, error } => {
                write!(f, "live view: ground truth of {}: {error}", dir.display())
            }
            ViewError::Spawn(e) => write!(f, "live view: cannot start its thread: {e}"),
        }
    }
}

impl std::error::Error for ViewError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ViewError::Start { error, .. } => Some(error),
            ViewError::Bind { error, .. } => Some(error),
            ViewError::GroundTruth { error, .. } => Some(error),
            ViewError::Spawn(e) => Some(e),
            ViewError::Address { .. } => None,
        }
    }
}

/// What the view thread published.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ViewCounters {
    /// Radar frames.
    pub radar: u64,
    /// IMU samples.
    pub imu: u64,
    /// Poses.
    pub poses: u64,
    /// Health messages.
    pub health: u64,
    /// Channel messages dropped for clients that read too slowly (all clients together).
    pub client_dropped: u64,
    /// Client connections served.
    pub clients: u64,
}

/// A running live view.
pub struct LiveView {
    handle: Option<WebSocketServerHandle>,
    front: Option<front::Front>,
    /// The SDK context the channels live in (dropping it closes them).
    _ctx: Arc<Context>,
    thread: Option<JoinHandle<ViewCounters>>,
    finishing: Arc<AtomicBool>,
    publisher_channels: Vec<Arc<foxglove::RawChannel>>,
    addr: String,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.addr)
            .finish()
    }
}

impl LiveView {
    /// Starts the server and the view thread; the tap goes into the run's configuration.
    pub fn start(opts: &ViewOptions) -> Result<(LiveView, ViewTap), ViewError> {
        let gt = match &opts.session {
            Some(dir) => gt::GroundTruth::load(dir)?,
            None => None,
        };
        let ctx = Context::new();
        let publisher = publish::Publisher::new(&ctx, gt);
        let channels = publisher.channels();
        let want = format!("{}:{}", opts.host, opts.port);
        // The SDK's server on a loopback port; clients reach it through the front.
        let handle = WebSocketServer::new()
            .name("milliego")
            .context(&ctx)
            .bind("127.0.0.1", 0)
            .message_backlog_size(SDK_BACKLOG.max(opts.backlog))
            .start_blocking()
            .map_err(|error| ViewError::Start {
                addr: want.clone(),
                error,
            })?;
        let backend = SocketAddr::from(([127, 0, 0, 1], handle.port()));
        let front =
            front::Front::start(&opts.host, opts.port, backend, opts.backlog).map_err(|error| {
                ViewError::Bind {
                    addr: want.clone(),
                    error,
                }
            })?;
        let addr = match front.addr() {
            SocketAddr::V6(a) => format!("[{}]:{}", a.ip(), a.port()),
            SocketAddr::V4(a) => a.to_string(),
        };
        let (tap, rx) = ViewTap::new(opts.capacity);
        let finishing = Arc::new(AtomicBool::new(false));
        let fin = Arc::clone(&finishing);
        let thread = std::thread::Builder::new()
            .name("view".into())
            .spawn(move || view_loop(publisher, &rx, &fin))
            .map_err(ViewError::Spawn)?;
        Ok((
            LiveView {
                handle: Some(handle),
                front: Some(front),
                _ctx: ctx,
                thread: Some(thread),
                finishing,
                publisher_channels: channels,
                addr,
            },
            tap,
        ))
    }

    /// `HOST:PORT` the server listens on (the port the OS chose for port 0).
    pub fn addr(&self) -> &str {
        &self.addr
    }

    /// The port clients connect to.
    pub fn port(&self) -> u16 {
        self.front.as_ref().map_or(0, |f| f.addr().port())
    }

    /// Waits until a client has subscribed to a channel (and 200 ms more, so the rest of its
    /// subscriptions settle), `timeout` passes (None: no limit) or `stop` is set; true when a
    /// client subscribed.
    pub fn wait_for_subscriber(&self, timeout: Option<Duration>, stop: &AtomicBool) -> bool {
        let started = Instant::now();
        loop {
            if self.publisher_channels.iter().any(|c| c.has_sinks()) {
                std::thread::sleep(Duration::from_millis(200));
                return true;
            }
            if stop.load(Ordering::Relaxed) || timeout.is_some_and(|t| started.elapsed() >= t) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Publishes what is still queued (the final trajectory too), keeps serving for `linger` so
    /// clients receive it, then stops the server.
    pub fn finish(mut self, linger: Duration) -> ViewCounters {
        self.finishing.store(true, Ordering::Release);
        let mut counters = self
            .thread
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        std::thread::sleep(linger);
        if let Some(h) = self.handle.take() {
            h.stop().wait_blocking();
        }
        if let Some(f) = self.front.take() {
            counters.client_dropped = f.counters().dropped.load(Ordering::Relaxed);
            counters.clients = f.counters().clients.load(Ordering::Relaxed);
        }
        counters
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.finishing.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            h.stop().wait_blocking();
        }
    }
}

fn view_loop(
    mut publisher: publish::Publisher,
    rx: &Receiver<ViewEvent>,
    finishing: &AtomicBool,
) -> ViewCounters {
    loop {
        match rx.recv_timeout(Duration::from_millis(20)) {
            Ok(ev) => publisher.handle(ev),
            Err(RecvTimeoutError::Timeout) => {
                if finishing.load(Ordering::Acquire) && rx.is_empty() {
                    break;
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    publisher.finish();
    publisher.counters
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_default_to_loopback() {
        let o = ViewOptions::parse_addr("8765").unwrap();
        assert_eq!((o.host.as_str(), o.port), ("127.0.0.1", 8765));
        assert!(o.is_loopback());
        let o = ViewOptions::parse_addr("0.0.0.0:9000").unwrap();
        assert_eq!((o.host.as_str(), o.port), ("0.0.0.0", 9000));
        assert!(!o.is_loopback());
        assert!(ViewOptions::parse_addr("[::1]:1").unwrap().is_loopback());
        assert!(ViewOptions::parse_addr("localhost:x").is_err());
        assert!(ViewOptions::parse_addr(":1").is_err());
    }
}
