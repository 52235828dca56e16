//! The server's front door: the Foxglove SDK 0.30 negotiates only `foxglove.sdk.v1` and
//! `foxglove.sdk.v1.1`, while Lichtblick and clients written against the published protocol
//! spec ask for `foxglove.websocket.v1`, whose messages are the same as `foxglove.sdk.v1`'s
//! (inline schemas in `advertise`, the same binary opcodes). The front listens on the user's
//! address, rewrites that one request header to `foxglove.sdk.v1` (and the answer back), and then
//! copies bytes both ways between the client and the SDK's server on a loopback port. A client
//! that offers `foxglove.sdk.*` goes through unchanged.
//!
//! Towards the client the front is also where a slow client loses data, so that it is counted:
//! one thread per client reads the SDK's WebSocket frames as fast as they come into a queue of
//! whole messages, another writes them to the client. When the queue holds `backlog` message-data
//! messages (the protocol's binary opcode 0x01: a channel's message), the oldest of them is dropped
//! and counted ([`FrontCounters`]); everything else (advertisements, server info, pings, close) is
//! never dropped. The SDK's own per-client queue therefore never fills.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// The subprotocol of the published Foxglove WebSocket protocol.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The SDK's name for the same protocol.
const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// Longest HTTP head accepted \[B\].
const HEAD_MAX: usize = 16 * 1024;
/// Send buffer towards a client \[B\]: small, so a client that reads slowly makes the front's
/// queue drop its oldest messages (fresh data for a live view) instead of megabytes of stale data
/// waiting in the kernel.
const SOCKET_BUFFER: usize = 64 * 1024;
/// Longest WebSocket frame accepted from the SDK \[B\] (a point cloud is tens of kB).
const FRAME_MAX: u64 = 64 * 1024 * 1024;
/// The Foxglove protocol's binary opcode of a channel message (`MessageData`).
const MESSAGE_DATA: u8 = 0x01;

/// What the front dropped, all clients together.
#[derive(Debug, Default)]
pub struct FrontCounters {
    /// Channel messages dropped because a client read too slowly.
    pub dropped: AtomicU64,
    /// Clients served so far.
    pub clients: AtomicU64,
}

/// A running front.
#[derive(Debug)]
pub struct Front {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    counters: Arc<FrontCounters>,
}

impl Front {
    /// Listens on `host:port` and forwards every connection to `backend`, queueing at most
    /// `backlog` channel messages per client.
    pub fn start(host: &str, port: u16, backend: SocketAddr, backlog: usize) -> io::Result<Front> {
        let listener = TcpListener::bind((host, port))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let counters = Arc::new(FrontCounters::default());
        let c2 = Arc::clone(&counters);
        let backlog = backlog.max(1);
        let thread = std::thread::Builder::new()
            .name("view-front".into())
            .spawn(move || accept_loop(&listener, backend, backlog, &c2, &stop2))?;
        Ok(Front {
            addr,
            stop,
            thread: Some(thread),
            counters,
        })
    }

    /// The address clients connect to.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// What was dropped so far.
    pub fn counters(&self) -> &FrontCounters {
        &self.counters
    }
}

impl Drop for Front {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn accept_loop(
    listener: &TcpListener,
    backend: SocketAddr,
    backlog: usize,
    counters: &Arc<FrontCounters>,
    stop: &AtomicBool,
) {
    while !stop.load(Ordering::Acquire) {
        match listener.accept() {
            Ok((client, peer)) => {
                counters.clients.fetch_add(1, Ordering::Relaxed);
                let counters = Arc::clone(counters);
                let spawned = std::thread::Builder::new()
                    .name("view-client".into())
                    .spawn(move || {
                        if let Err(e) = serve(client, backend, backlog, &counters) {
                            tracing::debug!(%peer, error = %e, "live view client ended");
                        }
                    });
                if let Err(e) = spawned {
                    tracing::warn!(error = %e, "live view: cannot serve a client");
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => {
                tracing::warn!(error = %e, "live view: accept failed");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

/// Reads an HTTP head (up to and including the blank line); returns it and any bytes after it.
fn read_head(s: &mut TcpStream) -> io::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let head = String::from_utf8(buf)
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "HTTP head not UTF-8"))?;
            return Ok((head, rest));
        }
        if buf.len() > HEAD_MAX {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "HTTP head too long",
            ));
        }
        let n = s.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// Rewrites the `Sec-WebSocket-Protocol` header(s) of `head` with `f` (given the offered or
/// chosen tokens); other lines stay as they are.
fn rewrite_protocol(head: &str, mut f: impl FnMut(&[&str]) -> Option<String>) -> String {
    let mut out = String::with_capacity(head.len() + 16);
    for line in head.split_inclusive("\r\n") {
        let replaced = line.split_once(':').and_then(|(name, value)| {
            if !name.trim().eq_ignore_ascii_case("sec-websocket-protocol") {
                return None;
            }
            let tokens: Vec<&str> = value.trim().split(',').map(str::trim).collect();
            f(&tokens).map(|v| format!("Sec-WebSocket-Protocol: {v}\r\n"))
        });
        out.push_str(replaced.as_deref().unwrap_or(line));
    }
    out
}

/// The request head for the SDK, and whether the client asked for the legacy name only.
pub fn translate_request(head: &str) -> (String, bool) {
    let mut offered = Vec::new();
    let _ = rewrite_protocol(head, |t| {
        offered.extend(t.iter().map(|s| s.to_string()));
        None
    });
    let legacy = offered.iter().any(|t| t == LEGACY_SUBPROTOCOL)
        && !offered.iter().any(|t| t.starts_with("foxglove.sdk."));
    if !legacy {
        return (head.to_string(), false);
    }
    (
        rewrite_protocol(head, |_| Some(SDK_SUBPROTOCOL.into())),
        true,
    )
}

/// The SDK's answer with the legacy name put back.
pub fn translate_response(head: &str) -> String {
    rewrite_protocol(head, |t| {
        (t == [SDK_SUBPROTOCOL]).then(|| LEGACY_SUBPROTOCOL.to_string())
    })
}

fn serve(
    mut client: TcpStream,
    backend: SocketAddr,
    backlog: usize,
    counters: &Arc<FrontCounters>,
) -> io::Result<()> {
    client.set_nonblocking(false)?;
    client.set_nodelay(true)?;
    client.set_read_timeout(Some(Duration::from_secs(10)))?;
    let (head, rest) = read_head(&mut client)?;
    client.set_read_timeout(None)?;
    let (head, legacy) = translate_request(&head);
    let mut server = TcpStream::connect(backend)?;
    server.set_nodelay(true)?;
    socket2::SockRef::from(&client).set_send_buffer_size(SOCKET_BUFFER)?;
    server.write_all(head.as_bytes())?;
    server.write_all(&rest)?;
    let (answer, rest) = read_head(&mut server)?;
    let answer = if legacy {
        translate_response(&answer)
    } else {
        answer
    };
    client.write_all(answer.as_bytes())?;
    // What came after the answer's head (the first frames, maybe part of one) is the start of
    // the stream the reader below parses.
    // Then bytes both ways until either side closes.
    let (mut c2, mut s2) = (client.try_clone()?, server.try_clone()?);
    let up = std::thread::Builder::new()
        .name("view-client-up".into())
        .spawn(move || {
            let _ = io::copy(&mut c2, &mut s2);
            let _ = s2.shutdown(Shutdown::Write);
        })?;
    // Down: a reader that never waits for the client fills the queue, this thread empties it.
    let outbox = Arc::new(Outbox::new(backlog));
    let (ob, counters) = (Arc::clone(&outbox), Arc::clone(counters));
    let mut s3 = server.try_clone()?;
    let down = std::thread::Builder::new()
        .name("view-client-down".into())
        .spawn(move || {
            if let Err(e) = read_messages(&mut s3, rest, &ob, &counters.dropped) {
                tracing::debug!(error = %e, "live view: the server's stream ended");
            }
            ob.close();
        })?;
    while let Some(bytes) = outbox.pop() {
        if client.write_all(&bytes).is_err() {
            break;
        }
    }
    let _ = client.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
    let _ = up.join();
    let _ = down.join();
    Ok(())
}

/// One WebSocket message (all its frames, as received) or one control frame.
#[derive(Debug)]
struct Unit {
    bytes: Vec<u8>,
    /// A channel message: may be dropped for a slow client.
    droppable: bool,
}

#[derive(Debug, Default)]
struct Queue {
    units: VecDeque<Unit>,
    /// Droppable units in `units`.
    droppable: usize,
    closed: bool,
}

/// The per-client queue between the reader of the SDK's stream and the writer to the client.
#[derive(Debug)]
struct Outbox {
    q: Mutex<Queue>,
    ready: Condvar,
    backlog: usize,
}

impl Outbox {
    fn new(backlog: usize) -> Outbox {
        Outbox {
            q: Mutex::new(Queue::default()),
            ready: Condvar::new(),
            backlog,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.q
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Queues `u`; when `backlog` channel messages are already queued, the oldest of them is
    /// dropped and counted in `dropped`.
    fn push(&self, u: Unit, dropped: &AtomicU64) {
        let mut q = self.lock();
        if u.droppable {
            if q.droppable >= self.backlog {
                if let Some(i) = q.units.iter().position(|x| x.droppable) {
                    q.units.remove(i);
                    q.droppable -= 1;
                    dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
            q.droppable += 1;
        }
        q.units.push_back(u);
        drop(q);
        self.ready.notify_one();
    }

    /// The next unit's bytes; None once the reader closed the queue and it is empty.
    fn pop(&self) -> Option<Vec<u8>> {
        let mut q = self.lock();
        loop {
            if let Some(u) = q.units.pop_front() {
                if u.droppable {
                    q.droppable -= 1;
                }
                return Some(u.bytes);
            }
            if q.closed {
                return None;
            }
            q = self
                .ready
                .wait(q)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }

    fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_all();
    }
}

/// A WebSocket frame's header: (header length, payload length, FIN, opcode, masked), or None
/// while `b` is too short to tell (RFC 6455 section 5.2).
fn frame_header(b: &[u8]) -> Option<(usize, u64, bool, u8, bool)> {
    let (&b0, &b1) = (b.first()?, b.get(1)?);
    let masked = b1 & 0x80 != 0;
    let (mut hdr, len) = match b1 & 0x7f {
        126 => (4, u64::from(u16::from_be_bytes([*b.get(2)?, *b.get(3)?]))),
        127 => {
            let x: [u8; 8] = b.get(2..10)?.try_into().ok()?;
            (10, u64::from_be_bytes(x))
        }
        n => (2, u64::from(n)),
    };
    if masked {
        hdr += 4;
    }
    Some((hdr, len, b0 & 0x80 != 0, b0 & 0x0f, masked))
}

/// Reads the SDK's frames (`start`, then what `server` sends) into `outbox`, whole messages at
/// a time, until the stream ends.
fn read_messages(
    server: &mut TcpStream,
    start: Vec<u8>,
    outbox: &Outbox,
    dropped: &AtomicU64,
) -> io::Result<()> {
    let mut buf = start;
    let mut chunk = vec![0u8; 64 * 1024];
    // The message being assembled from fragments.
    let mut cur: Option<Unit> = None;
    loop {
        let mut at = 0;
        while let Some((hdr, len, fin, opcode, masked)) = frame_header(&buf[at..]) {
            if len > FRAME_MAX {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("a {len} B WebSocket frame from the server (limit {FRAME_MAX} B)"),
                ));
            }
            let total = hdr + len as usize;
            if buf.len() - at < total {
                break;
            }
            let frame = &buf[at..at + total];
            at += total;
            if opcode >= 0x8 {
                // Control frames (close, ping, pong) go out on their own, never dropped.
                outbox.push(
                    Unit {
                        bytes: frame.to_vec(),
                        droppable: false,
                    },
                    dropped,
                );
                continue;
            }
            match (opcode, cur.as_mut()) {
                (0, Some(u)) => u.bytes.extend_from_slice(frame),
                _ => {
                    if let Some(u) = cur.take() {
                        outbox.push(u, dropped);
                    }
                    let first = frame
                        .get(hdr)
                        .map(|&b| if masked { b ^ frame[hdr - 4] } else { b });
                    cur = Some(Unit {
                        bytes: frame.to_vec(),
                        droppable: opcode == 0x2 && first == Some(MESSAGE_DATA),
                    });
                }
            }
            if fin {
                if let Some(u) = cur.take() {
                    outbox.push(u, dropped);
                }
            }
        }
        buf.drain(..at);
        let n = server.read(&mut chunk)?;
        if n == 0 {
            if let Some(u) = cur.take() {
                outbox.push(u, dropped);
            }
            return Ok(());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An unmasked server frame.
    fn frame(fin: bool, opcode: u8, payload: &[u8]) -> Vec<u8> {
        let mut f = vec![(u8::from(fin) << 7) | opcode];
        match payload.len() {
            n if n < 126 => f.push(n as u8),
            n if n <= 0xffff => {
                f.push(126);
                f.extend_from_slice(&(n as u16).to_be_bytes());
            }
            n => {
                f.push(127);
                f.extend_from_slice(&(n as u64).to_be_bytes());
            }
        }
        f.extend_from_slice(payload);
        f
    }

    /// Runs `read_messages` over `bytes` sent in `chunk`-byte writes; the units queued.
    fn read_all(bytes: &[u8], chunk: usize, backlog: usize) -> (Vec<Unit>, u64) {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let mut w = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (mut r, _) = l.accept().unwrap();
        // The first bytes arrive with the handshake's answer, cut mid-frame; the rest in `chunk`s.
        let cut = bytes.len().min(5);
        let data = bytes[cut..].to_vec();
        let writer = std::thread::spawn(move || {
            for c in data.chunks(chunk) {
                w.write_all(c).unwrap();
            }
        });
        let ob = Outbox::new(backlog);
        let dropped = AtomicU64::new(0);
        read_messages(&mut r, bytes[..cut].to_vec(), &ob, &dropped).unwrap();
        writer.join().unwrap();
        let units = std::mem::take(&mut ob.lock().units).into_iter().collect();
        (units, dropped.load(Ordering::Relaxed))
    }

    #[test]
    fn messages_are_reassembled_and_only_channel_messages_are_dropped() {
        let mut wire = Vec::new();
        wire.extend(frame(true, 0x1, br#"{"op":"advertise"}"#));
        // Channel messages (binary, opcode 0x01), one of 70 kB (64-bit length) and one in
        // three fragments with a ping between them.
        for i in 0..5u8 {
            wire.extend(frame(true, 0x2, &[MESSAGE_DATA, i, 0, 0, 0]));
        }
        let big = [MESSAGE_DATA; 70_000];
        wire.extend(frame(true, 0x2, &big));
        wire.extend(frame(false, 0x2, &[MESSAGE_DATA, 9]));
        wire.extend(frame(false, 0x0, &[1, 2, 3]));
        wire.extend(frame(true, 0x9, b"ping"));
        wire.extend(frame(true, 0x0, &[4]));
        // A binary message of another kind (0x02: time) is never dropped.
        wire.extend(frame(true, 0x2, &[0x02, 0, 0, 0, 0, 0, 0, 0, 0]));
        wire.extend(frame(true, 0x8, &[0x03, 0xe8]));
        for chunk in [1, 7, 4096] {
            let (units, dropped) = read_all(&wire, chunk, 3);
            // 7 channel messages, 3 kept: the oldest 4 dropped.
            assert_eq!(dropped, 4, "chunk {chunk}");
            let kept: Vec<_> = units.iter().filter(|u| u.droppable).collect();
            assert_eq!(kept.len(), 3);
            assert_eq!(kept[0].bytes, frame(true, 0x2, &[MESSAGE_DATA, 4, 0, 0, 0]));
            assert_eq!(kept[1].bytes.len(), 10 + 70_000);
            let fragmented = [
                frame(false, 0x2, &[MESSAGE_DATA, 9]),
                frame(false, 0x0, &[1, 2, 3]),
                frame(true, 0x0, &[4]),
            ]
            .concat();
            assert_eq!(kept[2].bytes, fragmented);
            // Nothing else was dropped, and the order is the stream's.
            let others: Vec<u8> = units
                .iter()
                .filter(|u| !u.droppable)
                .map(|u| u.bytes[0] & 0x0f)
                .collect();
            assert_eq!(others, [0x1, 0x9, 0x2, 0x8], "chunk {chunk}");
        }
        // With room for all, nothing is dropped and the bytes are the stream's (the ping ahead
        // of the fragmented message it interrupted).
        let (units, dropped) = read_all(&wire, 100, 100);
        assert_eq!(dropped, 0);
        assert_eq!(
            units.iter().map(|u| u.bytes.len()).sum::<usize>(),
            wire.len()
        );
    }

    #[test]
    fn an_oversized_frame_ends_the_stream_with_an_error() {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let mut w = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (mut r, _) = l.accept().unwrap();
        let mut f = vec![0x82, 127];
        f.extend_from_slice(&(FRAME_MAX + 1).to_be_bytes());
        w.write_all(&f).unwrap();
        let e = read_messages(&mut r, Vec::new(), &Outbox::new(4), &AtomicU64::new(0)).unwrap_err();
        assert!(e.to_string().contains("WebSocket frame"), "{e}");
    }

    #[test]
    fn the_legacy_subprotocol_is_translated_both_ways() {
        let req =
            "GET / HTTP/1.1\r\nHost: x\r\nsec-websocket-protocol: foxglove.websocket.v1\r\n\r\n";
        let (r, legacy) = translate_request(req);
        assert!(legacy);
        assert!(
            r.contains("Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n"),
            "{r}"
        );
        assert!(r.starts_with("GET / HTTP/1.1\r\nHost: x\r\n") && r.ends_with("\r\n\r\n"));
        let res =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert!(
            translate_response(res).contains("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n")
        );
        // A client that speaks the SDK's names goes through unchanged.
        let req = "GET / HTTP/1.1\r\nSec-WebSocket-Protocol: foxglove.sdk.v1.1, foxglove.websocket.v1\r\n\r\n";
        assert_eq!(translate_request(req), (req.to_string(), false));
    }
}
