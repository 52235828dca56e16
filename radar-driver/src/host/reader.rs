//! A reader that turns any byte source (file, serial port, pseudo-terminal) into frames stamped
//! with the host monotonic time of their last byte.

use crate::error::FrameError;
use crate::frame::{Frame, Header, Layout, LayoutHint};
use crate::framer::{Counters, Framer, Poll, DEFAULT_MAX_FRAME};
use std::collections::VecDeque;
use std::io::{self, Read};
use std::time::Instant;

/// A frame copied out of the framer, with its host receive time.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedFrame {
    bytes: Vec<u8>,
    layout: Layout,
    /// Host monotonic time when the read that delivered the frame's last byte returned.
    pub host_time: Instant,
}

impl OwnedFrame {
    /// The checked view of this frame.
    pub fn frame(&self) -> Frame<'_> {
        Frame::trusted(&self.bytes, self.layout)
    }
    /// The decoded header.
    pub fn header(&self) -> Header {
        *self.frame().header()
    }
    /// The frame bytes as received.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }
}

/// What the reader produced.
#[derive(Debug, Clone, PartialEq)]
pub enum ReadEvent {
    /// A good frame.
    Frame(OwnedFrame),
    /// A candidate frame was rejected; `skipped` bytes were dropped.
    Dropped {
        /// Why.
        error: FrameError,
        /// Bytes dropped \[B\].
        skipped: usize,
        /// When the read that revealed it returned.
        host_time: Instant,
    },
    /// The source timed out without data (serial ports with a read timeout); poll again.
    Idle,
}

/// Reads a byte source in chunks and frames it.
#[derive(Debug)]
pub struct FrameReader<R> {
    src: R,
    framer: Box<Framer<DEFAULT_MAX_FRAME>>,
    chunk: Vec<u8>,
    queue: VecDeque<ReadEvent>,
    eof: bool,
}

impl<R: Read> FrameReader<R> {
    /// A reader with the given layout hint, reading up to `chunk_size` bytes per read.
    pub fn new(src: R, hint: LayoutHint, chunk_size: usize) -> Self {
        FrameReader {
            src,
            framer: Box::new(Framer::new(hint)),
            chunk: vec![0; chunk_size.max(1)],
            queue: VecDeque::new(),
            eof: false,
        }
    }

    /// Framer counters so far.
    pub fn counters(&self) -> &Counters {
        self.framer.counters()
    }

    /// The underlying source.
    pub fn get_ref(&self) -> &R {
        &self.src
    }

    /// The next event; `Ok(None)` once the source has ended and everything was reported.
    pub fn next_event(&mut self) -> io::Result<Option<ReadEvent>> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Ok(Some(e));
            }
            if self.eof {
                return Ok(None);
            }
            let n = match self.src.read(&mut self.chunk) {
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) =>
                {
                    return Ok(Some(ReadEvent::Idle));
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            let host_time = Instant::now();
            if n == 0 {
                self.eof = true;
                if let Some((error, skipped)) = self.framer.finish() {
                    self.queue.push_back(ReadEvent::Dropped {
                        error,
                        skipped,
                        host_time,
                    });
                }
                continue;
            }
            let mut input = &self.chunk[..n];
            loop {
                match self.framer.poll(&mut input) {
                    Poll::Frame(f) => self.queue.push_back(ReadEvent::Frame(OwnedFrame {
                        bytes: f.as_bytes().to_vec(),
                        layout: f.layout(),
                        host_time,
                    })),
                    Poll::Dropped { error, skipped } => self.queue.push_back(ReadEvent::Dropped {
                        error,
                        skipped,
                        host_time,
                    }),
                    Poll::NeedMore => break,
                }
            }
        }
    }
}
