//! A framer over `std::io::Read` that stamps frames with host monotonic time.

use crate::frame::{frame_capacity, FrameError, XbusFrame};
use crate::framer::{Counters, Framer, Step};
use std::io::{self, Read};
use std::time::Instant;

/// What [`Reader::next_event`] reports.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// A checked frame.
    Frame {
        /// The frame, borrowed from the reader.
        frame: XbusFrame<'a>,
        /// Host monotonic time at which the `read()` that delivered the frame's last byte
        /// returned.
        at: Instant,
    },
    /// Bytes the framer gave up on.
    Dropped {
        /// How many.
        bytes: usize,
        /// Why.
        error: FrameError,
    },
}

/// Reads Xbus frames from any byte source (a serial port, a file, a pipe, a pty).
///
/// Each `read()` is stamped when it returns; frames completed by that chunk carry that stamp.
/// `CAP` is the framer's buffer (see [`Framer`]); the default accepts 2048-byte payloads, use
/// `Reader::<_, { frame_capacity(65535) }>` for `.mtb` logs.
#[derive(Debug)]
pub struct Reader<R, const CAP: usize = { frame_capacity(2048) }> {
    inner: R,
    framer: Framer<CAP>,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    stamp: Instant,
    reads: u64,
    eof: bool,
}

impl<R: Read, const CAP: usize> Reader<R, CAP> {
    /// A reader with a 64 KiB read buffer.
    pub fn new(inner: R) -> Self {
        Self::with_read_size(inner, 1 << 16)
    }

    /// A reader whose `read()` calls ask for at most `size` bytes (at least 1).
    pub fn with_read_size(inner: R, size: usize) -> Self {
        Self {
            inner,
            framer: Framer::new(),
            buf: vec![0; size.max(1)],
            start: 0,
            end: 0,
            stamp: Instant::now(),
            reads: 0,
            eof: false,
        }
    }

    /// The framer's counters.
    pub fn counters(&self) -> &Counters {
        self.framer.counters()
    }

    /// Successful `read()` calls so far.
    pub fn reads(&self) -> u64 {
        self.reads
    }

    /// The byte source (e.g. to write requests to a port).
    pub fn get_mut(&mut self) -> &mut R {
        &mut self.inner
    }

    /// The byte source.
    pub fn get_ref(&self) -> &R {
        &self.inner
    }

    /// Gives the byte source back.
    pub fn into_inner(self) -> R {
        self.inner
    }

    /// Forgets buffered bytes and any partial frame (after a baud-rate change).
    pub fn discard(&mut self) {
        self.start = 0;
        self.end = 0;
        self.framer.reset();
    }

    /// The next frame or dropped-bytes event; `Ok(None)` at end of input (a trailing partial
    /// frame is reported as [`FrameError::Truncated`] first, see [`Framer::poll_end`]).
    ///
    /// Errors of the source are returned as they are (a serial port's `TimedOut` included) and the
    /// reader stays usable; `Interrupted` is retried.
    pub fn next_event(&mut self) -> io::Result<Option<Event<'_>>> {
        loop {
            let pending = self.buf.get(self.start..self.end).unwrap_or_default();
            let mut input = pending;
            let step = self.framer.step(&mut input);
            self.start += pending.len() - input.len();
            match step {
                Step::Input(len) => {
                    let frame = self
                        .buf
                        .get(self.start - len..self.start)
                        .unwrap_or_default();
                    return Ok(Some(Event::Frame {
                        frame: XbusFrame::from_scanned(frame),
                        at: self.stamp,
                    }));
                }
                Step::Buffer(len) => {
                    return Ok(Some(Event::Frame {
                        frame: self.framer.buffered_frame(len),
                        at: self.stamp,
                    }))
                }
                Step::Dropped { bytes, error } => return Ok(Some(Event::Dropped { bytes, error })),
                Step::NeedMore => {}
            }
            if self.eof {
                return Ok(match self.framer.step_end() {
                    Step::Buffer(len) => Some(Event::Frame {
                        frame: self.framer.buffered_frame(len),
                        at: self.stamp,
                    }),
                    Step::Dropped { bytes, error } => Some(Event::Dropped { bytes, error }),
                    Step::Input(_) | Step::NeedMore => None,
                });
            }
            self.start = 0;
            self.end = 0;
            match self.inner.read(&mut self.buf) {
                Ok(0) => self.eof = true,
                Ok(n) => {
                    self.stamp = Instant::now();
                    self.end = n;
                    self.reads += 1;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// Hands out its chunks one `read()` at a time, sleeping before each.
    struct Chunked(Vec<Vec<u8>>);

    impl Read for Chunked {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            if self.0.is_empty() {
                return Ok(0);
            }
            std::thread::sleep(Duration::from_millis(5));
            let c = self.0.remove(0);
            out[..c.len()].copy_from_slice(&c);
            Ok(c.len())
        }
    }

    #[test]
    fn frames_carry_the_stamp_of_the_read_with_their_last_byte() {
        let ack = [0xFA, 0xFF, 0x31, 0x00, 0xD0];
        // Frame 1 whole in read 1; frame 2 split over reads 1 and 2; then a truncated frame.
        let chunks = vec![
            [&ack[..], &ack[..2]].concat(),
            ack[2..].to_vec(),
            vec![0xFA, 0xFF],
        ];
        let t0 = Instant::now();
        let mut r: Reader<_> = Reader::new(Chunked(chunks));
        let mut stamps = Vec::new();
        let mut dropped = Vec::new();
        while let Some(ev) = r.next_event().unwrap() {
            match ev {
                Event::Frame { frame, at } => {
                    assert_eq!(frame.mid(), 0x31);
                    stamps.push(at);
                }
                Event::Dropped { bytes, error } => dropped.push((bytes, error)),
            }
        }
        assert_eq!(stamps.len(), 2);
        assert!(stamps[0] > t0);
        assert!(
            stamps[1] >= stamps[0] + Duration::from_millis(5),
            "second frame completed by the second read"
        );
        assert_eq!(
            dropped,
            vec![(2, FrameError::Truncated { have: 2, need: 4 })]
        );
        assert_eq!(r.reads(), 3);
    }
}
