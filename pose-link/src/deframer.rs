//! Serial stream -> pose messages: COBS frames delimited by 0x00.

use crate::cobs::{self, CobsError};
use crate::message::{DecodeError, PoseMessage, MESSAGE_LEN};

/// What one [`Deframer::poll`] produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A good message.
    Message(PoseMessage),
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
    /// Frames whose message failed to decode (CRC, type, version, length).
    pub frames_bad_message: u64,
    /// Frames longer than the buffer.
    pub frames_overflow: u64,
    /// Bytes of dropped frames (delimiters included) \[B\].
    pub bytes_dropped: u64,
    /// Empty frames (consecutive delimiters), ignored \[B\].
    pub empty_frames: u64,
}

/// Accumulates a byte stream and releases a message at each 0x00 delimiter. `N` bounds one
/// encoded frame (at least [`cobs::max_encoded_len`]`(`[`MESSAGE_LEN`]`)` for version 1).
#[derive(Debug)]
pub struct Deframer<const N: usize> {
    split: cobs::Splitter<N>,
    counters: DeframerCounters,
}

impl<const N: usize> Default for Deframer<N> {
    fn default() -> Self {
        Deframer {
            split: cobs::Splitter::default(),
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

    /// Consumes bytes from `input` (advancing it) up to the next complete frame.
    pub fn poll(&mut self, input: &mut &[u8]) -> Event {
        let c = &mut self.counters;
        let ev = match self.split.poll(input) {
            cobs::Split::NeedMore => Event::NeedMore,
            cobs::Split::Overflow { dropped } => {
                c.frames_overflow += 1;
                c.bytes_dropped += dropped as u64;
                Event::BadFrame(FrameError::Overflow { dropped })
            }
            cobs::Split::Frame { cobs: bytes, wire } => {
                let mut msg = [0u8; N];
                let ev = match cobs::decode(bytes, &mut msg) {
                    Err(e) => {
                        c.frames_bad_cobs += 1;
                        Event::BadFrame(FrameError::Cobs(e))
                    }
                    Ok(n) => match PoseMessage::decode(&msg[..n]) {
                        Ok(m) => {
                            c.messages_ok += 1;
                            Event::Message(m)
                        }
                        Err(e) => {
                            c.frames_bad_message += 1;
                            Event::BadFrame(FrameError::Message(e))
                        }
                    },
                };
                if matches!(ev, Event::BadFrame(_)) {
                    c.bytes_dropped += wire as u64;
                }
                ev
            }
        };
        c.bytes_in = self.split.bytes_in;
        c.empty_frames = self.split.empty_frames;
        ev
    }
}

/// Encodes a message for the serial link: COBS plus the 0x00 delimiter. Returns the length.
pub fn encode_serial(m: &PoseMessage, out: &mut [u8]) -> Result<usize, CobsError> {
    let mut raw = [0u8; MESSAGE_LEN];
    m.encode(&mut raw)
        .map_err(|_| CobsError::BufferTooSmall { need: MESSAGE_LEN })?;
    let n = cobs::encode(&raw, out)?;
    *out.get_mut(n)
        .ok_or(CobsError::BufferTooSmall { need: n + 1 })? = 0;
    Ok(n + 1)
}
