//! The Xbus frame: a zero-copy, checked view of `FA BID MID LEN [EXT_HI EXT_LO] DATA... CS`.

use core::fmt;

/// The preamble byte that starts every frame.
pub const PREAMBLE: u8 = 0xFA;
/// The LEN value announcing that a 2-byte big-endian length follows.
pub const EXTENDED_LEN: u8 = 0xFF;
/// The largest payload that fits the standard (1-byte) length field; 255 and more use the extended form.
pub const MAX_STANDARD_PAYLOAD: usize = 254;
/// The largest payload the extended length field can announce.
pub const MAX_EXTENDED_PAYLOAD: usize = 0xFFFF;
/// Bytes a frame adds around its payload in the worst case (preamble, BID, MID, LEN, two extended
/// length bytes, checksum).
pub const FRAME_OVERHEAD: usize = 7;

/// Buffer size a [`Framer`](crate::Framer) needs to accept payloads of up to `max_payload` bytes.
///
/// ```
/// use imu_driver::{frame_capacity, Framer};
/// let framer = Framer::<{ frame_capacity(2048) }>::new();
/// assert_eq!(framer.max_payload(), 2048);
/// ```
pub const fn frame_capacity(max_payload: usize) -> usize {
    max_payload + FRAME_OVERHEAD
}

/// Why bytes did not form a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// Bytes before a preamble (line noise, a partial frame at the start of a capture).
    NoPreamble,
    /// The checksum byte does not make the sum of BID..CS zero modulo 256.
    BadChecksum {
        /// Message id of the rejected candidate frame.
        mid: u8,
        /// The checksum byte the frame should have carried.
        expected: u8,
        /// The checksum byte it carried.
        got: u8,
    },
    /// The announced payload length exceeds the framer's (or the caller's) limit.
    LengthTooLarge {
        /// Announced payload length in bytes.
        len: usize,
        /// The largest accepted payload length in bytes.
        max: usize,
    },
    /// The input ended inside a frame.
    Truncated {
        /// Bytes of the frame present.
        have: usize,
        /// Bytes the frame needs (a lower bound while the header is incomplete).
        need: usize,
    },
    /// [`XbusFrame::new_checked`] was given more bytes than one frame.
    TrailingBytes {
        /// Length of the frame at the start of the slice.
        frame: usize,
        /// Length of the slice.
        have: usize,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NoPreamble => write!(f, "bytes before a preamble (0xFA)"),
            Self::BadChecksum { mid, expected, got } => write!(
                f,
                "bad checksum in frame with MID 0x{mid:02X}: expected 0x{expected:02X}, got 0x{got:02X}"
            ),
            Self::LengthTooLarge { len, max } => {
                write!(f, "announced payload length {len} exceeds the limit {max}")
            }
            Self::Truncated { have, need } => {
                write!(f, "truncated frame: {have} of {need} bytes")
            }
            Self::TrailingBytes { frame, have } => {
                write!(f, "{have} bytes given for a {frame}-byte frame")
            }
        }
    }
}

impl core::error::Error for FrameError {}

/// What the bytes at the start of a slice (starting with the preamble) amount to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scan {
    /// More bytes are needed; `need` is the total known so far (header or whole frame).
    Incomplete { need: usize },
    /// A valid frame of `len` bytes starts the slice.
    Complete { len: usize },
    /// The candidate is invalid.
    Invalid(FrameError),
}

/// Scans a candidate frame at the start of `bytes` (which must start with [`PREAMBLE`]).
#[inline]
pub(crate) fn scan(bytes: &[u8], max_payload: usize) -> Scan {
    let (len, header) = match bytes {
        [_, _, _, EXTENDED_LEN, hi, lo, ..] => (usize::from(u16::from_be_bytes([*hi, *lo])), 6),
        [_, _, _, EXTENDED_LEN, ..] => return Scan::Incomplete { need: 6 },
        [_, _, _, len, ..] => (usize::from(*len), 4),
        _ => return Scan::Incomplete { need: 4 },
    };
    if len > max_payload {
        return Scan::Invalid(FrameError::LengthTooLarge {
            len,
            max: max_payload,
        });
    }
    let total = header + len + 1;
    let Some(frame) = bytes.get(..total) else {
        return Scan::Incomplete { need: total };
    };
    let sum = checksum_sum(frame.get(1..).unwrap_or_default());
    if sum == 0 {
        Scan::Complete { len: total }
    } else {
        let got = frame.last().copied().unwrap_or(0);
        Scan::Invalid(FrameError::BadChecksum {
            mid: frame.get(2).copied().unwrap_or(0),
            expected: got.wrapping_sub(sum),
            got,
        })
    }
}

/// Sum modulo 256 of `bytes`.
#[inline]
pub(crate) fn checksum_sum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |acc, b| acc.wrapping_add(*b))
}

/// A complete Xbus frame with a verified checksum, borrowed from the bytes it arrived in.
///
/// Constructed only by [`XbusFrame::new_checked`] or by the [`Framer`](crate::Framer); once built, no
/// accessor panics.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct XbusFrame<'a> {
    raw: &'a [u8],
    header: u8,
}

impl<'a> XbusFrame<'a> {
    /// Checks that `raw` is exactly one frame (preamble, a length within `MAX_EXTENDED_PAYLOAD`, a
    /// valid checksum) and returns its view.
    pub fn new_checked(raw: &'a [u8]) -> Result<Self, FrameError> {
        if raw.first() != Some(&PREAMBLE) {
            return Err(FrameError::NoPreamble);
        }
        match scan(raw, MAX_EXTENDED_PAYLOAD) {
            Scan::Complete { len } if len == raw.len() => Ok(Self::from_scanned(raw)),
            Scan::Complete { len } => Err(FrameError::TrailingBytes {
                frame: len,
                have: raw.len(),
            }),
            Scan::Incomplete { need } => Err(FrameError::Truncated {
                have: raw.len(),
                need,
            }),
            Scan::Invalid(e) => Err(e),
        }
    }

    /// Builds the view over bytes that [`scan`] reported complete with exactly this length.
    #[inline]
    pub(crate) fn from_scanned(raw: &'a [u8]) -> Self {
        let header = if raw.get(3) == Some(&EXTENDED_LEN) {
            6
        } else {
            4
        };
        Self { raw, header }
    }

    /// Bus identifier (0xFF: master / a standalone device; 0x01..: devices on a bus).
    #[inline]
    pub fn bid(&self) -> u8 {
        self.raw.get(1).copied().unwrap_or(0)
    }

    /// Message identifier (see [`mid`](crate::mid)).
    #[inline]
    pub fn mid(&self) -> u8 {
        self.raw.get(2).copied().unwrap_or(0)
    }

    /// The payload (DATA) bytes.
    #[inline]
    pub fn payload(&self) -> &'a [u8] {
        let end = self.raw.len().saturating_sub(1);
        self.raw
            .get(usize::from(self.header)..end)
            .unwrap_or_default()
    }

    /// The checksum byte.
    #[inline]
    pub fn checksum(&self) -> u8 {
        self.raw.last().copied().unwrap_or(0)
    }

    /// True when the frame uses the extended (3-byte) length field.
    #[inline]
    pub fn is_extended(&self) -> bool {
        self.header == 6
    }

    /// The whole frame as received, preamble to checksum.
    #[inline]
    pub fn as_bytes(&self) -> &'a [u8] {
        self.raw
    }
}

impl fmt::Debug for XbusFrame<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("XbusFrame")
            .field("bid", &format_args!("0x{:02X}", self.bid()))
            .field("mid", &format_args!("0x{:02X}", self.mid()))
            .field("payload_len", &self.payload().len())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// GoToConfig as sent by the host: FA FF 30 00 D1.
    static GO_TO_CONFIG: [u8; 5] = [0xFA, 0xFF, 0x30, 0x00, 0xD1];

    #[test]
    fn checked_view_of_a_standard_frame() {
        let f = XbusFrame::new_checked(&GO_TO_CONFIG).unwrap();
        assert_eq!(
            (f.bid(), f.mid(), f.payload(), f.checksum()),
            (0xFF, 0x30, &[][..], 0xD1)
        );
        assert!(!f.is_extended());
    }

    #[test]
    fn checked_view_rejects_bad_input_with_evidence() {
        let mut bad = GO_TO_CONFIG;
        bad[4] = 0xD2;
        assert_eq!(
            XbusFrame::new_checked(&bad),
            Err(FrameError::BadChecksum {
                mid: 0x30,
                expected: 0xD1,
                got: 0xD2
            })
        );
        assert_eq!(
            XbusFrame::new_checked(&GO_TO_CONFIG[..3]),
            Err(FrameError::Truncated { have: 3, need: 4 })
        );
        assert_eq!(
            XbusFrame::new_checked(&GO_TO_CONFIG[1..]),
            Err(FrameError::NoPreamble)
        );
        let mut long = [0u8; 6];
        long[..5].copy_from_slice(&GO_TO_CONFIG);
        assert_eq!(
            XbusFrame::new_checked(&long),
            Err(FrameError::TrailingBytes { frame: 5, have: 6 })
        );
        assert_eq!(XbusFrame::new_checked(&[]), Err(FrameError::NoPreamble));
    }

    fn extended(len: u16, fill: u8) -> [u8; 6 + 300 + 1] {
        let mut raw = [fill; 6 + 300 + 1];
        let [hi, lo] = len.to_be_bytes();
        raw[..6].copy_from_slice(&[0xFA, 0xFF, 0x36, 0xFF, hi, lo]);
        let end = 6 + usize::from(len);
        raw[end] = checksum_sum(&raw[1..end]).wrapping_neg();
        raw
    }

    #[test]
    fn extended_length_frames_with_255_and_more_bytes() {
        let raw = extended(255, 0x01);
        let f = XbusFrame::new_checked(&raw[..6 + 255 + 1]).unwrap();
        assert!(f.is_extended());
        assert_eq!(f.payload(), &[0x01; 255][..]);
        let raw = extended(300, 0x5A);
        let f = XbusFrame::new_checked(&raw).unwrap();
        assert_eq!(f.payload().len(), 300);
    }

    #[test]
    fn extended_length_bytes_are_part_of_the_checksum() {
        // A driver that sums the decoded 16-bit length (0x012C -> 0x2C) instead of both length bytes
        // (0x01 + 0x2C) computes a checksum one lower and rejects this valid frame; we must accept
        // ours and reject theirs.
        let mut raw = extended(300, 0x5A);
        let good = raw[306];
        raw[306] = good.wrapping_add(1);
        assert_eq!(
            XbusFrame::new_checked(&raw),
            Err(FrameError::BadChecksum {
                mid: 0x36,
                expected: good,
                got: good.wrapping_add(1)
            })
        );
    }
}
