//! Serial stream -> hub messages: COBS frames delimited by 0x00.

use crate::cobs::{self, CobsError};
use crate::message::{DecodeError, Message};

/// What one [`Deframer::poll`] produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event<'a> {
    /// A good message (borrows the deframer).
    Message(Message<'a>),
    /// A frame was dropped (its bytes are counted in [`DeframerCounters::bytes_dropped`]).
    BadFrame(FrameError),
    /// The input is used up.
    NeedMore,
}

/// Why a serial frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// COBS did not decode.
    Cobs(CobsError),
    /// COBS decoded, the message did not.
    Message(DecodeError),
    /// The frame grew beyond the buffer before its delimiter.
    Overflow {
        /// Bytes discarded up to the delimiter \[B\].
        dropped: usize,
    },
}

impl FrameError {
    /// Stable snake_case name of the error kind (for counters and summaries).
    pub fn kind_name(&self) -> &'static str {
        match self {
            FrameError::Cobs(_) => "bad_cobs",
            FrameError::Message(e) => e.kind_name(),
            FrameError::Overflow { .. } => "overflow",
        }
    }
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::Cobs(e) => write!(f, "{e}"),
            FrameError::Message(e) => write!(f, "{e}"),
            FrameError::Overflow { dropped } => {
                write!(f, "frame longer than the buffer: {dropped} B dropped")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Counters since the deframer was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DeframerCounters {
    /// Bytes consumed \[B\].
    pub bytes_in: u64,
    /// Messages decoded.
    pub messages_ok: u64,
    /// Frames that failed COBS decoding.
    pub frames_bad_cobs: u64,
    /// Frames whose message failed to decode (CRC, version, kind, length).
    pub frames_bad_message: u64,
    /// Frames longer than the buffer.
    pub frames_overflow: u64,
    /// Bytes of dropped frames (delimiters included) \[B\].
    pub bytes_dropped: u64,
    /// Empty frames (consecutive delimiters), ignored.
    pub empty_frames: u64,
}

/// Accumulates a byte stream and releases a message at each 0x00 delimiter. `N` bounds one
/// encoded frame: [`crate::serial_len_max`]`(largest body)` (the host uses [`crate::FRAME_MAX`]).
#[derive(Debug)]
pub struct Deframer<const N: usize> {
    split: cobs::Splitter<N>,
    msg: [u8; N],
    counters: DeframerCounters,
}

impl<const N: usize> Default for Deframer<N> {
    fn default() -> Self {
        Deframer {
            split: cobs::Splitter::default(),
            msg: [0; N],
            counters: DeframerCounters::default(),
        }
    }
}

impl<const N: usize> Deframer<N> {
    /// Counters so far.
    pub fn counters(&self) -> &DeframerCounters {
        &self.counters
    }

    /// Bytes held for an unfinished frame \[B\].
    pub fn buffered(&self) -> usize {
        self.split.buffered()
    }

    /// Forgets an unfinished frame (the stream was interrupted, e.g. the port was reopened): its
    /// bytes are counted in [`DeframerCounters::bytes_dropped`]; the counters are kept. Returns
    /// the bytes dropped \[B\].
    pub fn resync(&mut self) -> usize {
        let dropped = self.split.resync();
        self.counters.bytes_dropped += dropped as u64;
        dropped
    }

    /// Consumes bytes from `input` (advancing it) up to the next complete frame.
    pub fn poll(&mut self, input: &mut &[u8]) -> Event<'_> {
        let (bytes, wire) = match self.split.poll(input) {
            cobs::Split::Frame { cobs, wire } => (cobs, wire),
            cobs::Split::NeedMore => {
                self.sync();
                return Event::NeedMore;
            }
            cobs::Split::Overflow { dropped } => {
                self.sync();
                self.counters.frames_overflow += 1;
                self.counters.bytes_dropped += dropped as u64;
                return Event::BadFrame(FrameError::Overflow { dropped });
            }
        };
        let decoded = cobs::decode(bytes, &mut self.msg);
        self.sync();
        let c = &mut self.counters;
        let err = match decoded {
            Err(e) => {
                c.frames_bad_cobs += 1;
                FrameError::Cobs(e)
            }
            Ok(n) => match Message::decode(&self.msg[..n]) {
                Ok(m) => {
                    c.messages_ok += 1;
                    return Event::Message(m);
                }
                Err(e) => {
                    c.frames_bad_message += 1;
                    FrameError::Message(e)
                }
            },
        };
        c.bytes_dropped += wire as u64;
        Event::BadFrame(err)
    }

    /// The splitter's counts into the counters.
    fn sync(&mut self) {
        self.counters.bytes_in = self.split.bytes_in;
        self.counters.empty_frames = self.split.empty_frames;
    }
}
