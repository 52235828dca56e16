//! The server's front door: the Foxglove SDK 0.30 negotiates only `foxglove.sdk.v1` and
//! `foxglove.sdk.v1.1`, while Lichtblick and clients written against the published protocol
//! spec ask for `foxglove.websocket.v1`, whose messages are the same as `foxglove.sdk.v1`'s
//! (inline schemas in `advertise`, the same binary opcodes). The front listens on the user's
//! address, rewrites that one request header to `foxglove.sdk.v1` (and the answer back), and then
//! copies bytes both ways between the client and the SDK's server on a loopback port. A client
//! that offers `foxglove.sdk.*` goes through unchanged.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The subprotocol of the published Foxglove WebSocket protocol.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The SDK's name for the same protocol.
const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// Longest HTTP head accepted \[B\].
const HEAD_MAX: usize = 16 * 1024;
/// Socket buffers between the SDK and a client \[B\]: small, so a client that reads slowly makes
/// the SDK's per-client queue drop its oldest messages (fresh data for a live view) instead of
/// megabytes of stale data waiting in the kernel.
const SOCKET_BUFFER: usize = 64 * 1024;

/// A running front.
#[derive(Debug)]
pub struct Front {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Front {
    /// Listens on `host:port` and forwards every connection to `backend`.
    pub fn start(host: &str, port: u16, backend: SocketAddr) -> io::Result<Front> {
        let listener = TcpListener::bind((host, port))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("view-front".into())
            .spawn(move || accept_loop(&listener, backend, &stop2))?;
        Ok(Front {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// The address clients connect to.
    pub fn addr(&self) -> SocketAddr {
        self.addr
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

fn accept_loop(listener: &TcpListener, backend: SocketAddr, stop: &AtomicBool) {
    while !stop.load(Ordering::Acquire) {
        match listener.accept() {
            Ok((client, peer)) => {
                let spawned = std::thread::Builder::new()
                    .name("view-client".into())
                    .spawn(move || {
                        if let Err(e) = serve(client, backend) {
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

fn serve(mut client: TcpStream, backend: SocketAddr) -> io::Result<()> {
    client.set_nonblocking(false)?;
    client.set_nodelay(true)?;
    client.set_read_timeout(Some(Duration::from_secs(10)))?;
    let (head, rest) = read_head(&mut client)?;
    client.set_read_timeout(None)?;
    let (head, legacy) = translate_request(&head);
    let mut server = TcpStream::connect(backend)?;
    server.set_nodelay(true)?;
    socket2::SockRef::from(&server).set_recv_buffer_size(SOCKET_BUFFER)?;
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
    client.write_all(&rest)?;
    // Then bytes both ways until either side closes.
    let (mut c2, mut s2) = (client.try_clone()?, server.try_clone()?);
    let up = std::thread::Builder::new()
        .name("view-client-up".into())
        .spawn(move || {
            let _ = io::copy(&mut c2, &mut s2);
            let _ = s2.shutdown(Shutdown::Write);
        })?;
    let _ = io::copy(&mut server, &mut client);
    let _ = client.shutdown(Shutdown::Both);
    let _ = server.shutdown(Shutdown::Both);
    let _ = up.join();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
