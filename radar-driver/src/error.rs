//! Error types. Every variant carries the evidence needed to find the bad bytes.

use core::fmt;

/// Why a candidate frame (a magic word and what follows it) was rejected.
///
/// The framer drops only the 8 magic bytes after any of these (or, for [`FrameError::Truncated`],
/// the bytes before the next magic) and searches again, so the next good frame is always found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// The buffer handed to [`crate::Frame::new_checked`] is shorter than the header or the claimed length.
    BufferTooShort {
        /// Bytes needed \[B\].
        need: usize,
        /// Bytes available \[B\].
        have: usize,
    },
    /// The buffer does not start with the 8-byte magic word.
    BadMagic,
    /// totalPacketLen is smaller than the header of this layout.
    LengthTooSmall {
        /// Claimed total length \[B\].
        len: u32,
        /// Header length of the layout \[B\].
        min: u32,
    },
    /// totalPacketLen exceeds the framer's bound (its buffer, or the configured maximum).
    LengthTooLarge {
        /// Claimed total length \[B\].
        len: u32,
        /// The bound \[B\].
        max: u32,
    },
    /// The people-counting header checksum does not fold to 0xFFFF.
    BadChecksum {
        /// The folded one's-complement sum over the header (0xFFFF when valid).
        folded: u16,
    },
    /// A TLV header (8 bytes) does not fit in what remains of the frame.
    TlvHeaderOverrun {
        /// TLV index within the frame (0-based).
        index: u32,
        /// Offset of the TLV header from the frame start \[B\].
        offset: u32,
        /// Bytes left in the frame at that offset \[B\].
        room: u32,
    },
    /// A TLV's length does not fit in what remains of the frame (or, where the length includes the
    /// TLV header, is smaller than that header).
    BadTlvLength {
        /// TLV index within the frame (0-based).
        index: u32,
        /// TLV type.
        ty: u32,
        /// Length field as sent \[B\].
        len: u32,
        /// Bytes left in the frame after the TLV header \[B\].
        room: u32,
    },
    /// A layout without padding (people counting) has bytes after its last TLV.
    TrailingBytes {
        /// Bytes after the last TLV \[B\].
        len: u32,
    },
    /// The frame released just before ended inside the next frame's magic word: it lost `overlap`
    /// bytes on the wire (a dropped byte that no checksum catches), so its content is shifted and
    /// must be discarded. The next frame is framed from the recovered magic.
    OverlapsNextFrame {
        /// Bytes of the next magic the previous frame had taken in (1..=7).
        overlap: u32,
        /// Length of the retracted frame \[B\].
        len: u32,
    },
    /// The next frame's magic word appeared inside this frame's claimed length: the frame was cut
    /// short on the wire (or by the tool that saved it).
    Truncated {
        /// Claimed total length \[B\].
        claimed: u32,
        /// Bytes present before the next magic (or the end of the stream) \[B\].
        got: u32,
    },
}

/// Number of distinct [`FrameError`] kinds, for per-reason counters.
pub const FRAME_ERROR_KINDS: usize = 10;

impl FrameError {
    /// Stable index of this error's kind (0..[`FRAME_ERROR_KINDS`]).
    pub fn kind_index(&self) -> usize {
        match self {
            Self::BufferTooShort { .. } => 0,
            Self::BadMagic => 1,
            Self::LengthTooSmall { .. } => 2,
            Self::LengthTooLarge { .. } => 3,
            Self::BadChecksum { .. } => 4,
            Self::TlvHeaderOverrun { .. } => 5,
            Self::BadTlvLength { .. } => 6,
            Self::TrailingBytes { .. } => 7,
            Self::Truncated { .. } => 8,
            Self::OverlapsNextFrame { .. } => 9,
        }
    }

    /// Stable snake_case name of this error's kind (used in summaries and counters).
    pub fn kind_name(&self) -> &'static str {
        FRAME_ERROR_NAMES[self.kind_index()]
    }
}

/// Names of the error kinds, indexed by [`FrameError::kind_index`].
pub const FRAME_ERROR_NAMES: [&str; FRAME_ERROR_KINDS] = [
    "buffer_too_short",
    "bad_magic",
    "length_too_small",
    "length_too_large",
    "bad_checksum",
    "tlv_header_overrun",
    "bad_tlv_length",
    "trailing_bytes",
    "truncated",
    "overlaps_next_frame",
];

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooShort { need, have } => {
                write!(f, "buffer too short: need {need} B, have {have} B")
            }
            Self::BadMagic => write!(f, "frame does not start with the magic word 02 01 04 03 06 05 08 07"),
            Self::LengthTooSmall { len, min } => {
                write!(f, "totalPacketLen {len} B is smaller than the {min} B header")
            }
            Self::LengthTooLarge { len, max } => {
                write!(f, "totalPacketLen {len} B exceeds the bound of {max} B")
            }
            Self::BadChecksum { folded } => {
                write!(f, "header checksum folds to {folded:#06x}, expected 0xffff")
            }
            Self::TlvHeaderOverrun { index, offset, room } => write!(
                f,
                "TLV #{index} header at offset {offset} needs 8 B but only {room} B remain in the frame"
            ),
            Self::BadTlvLength { index, ty, len, room } => write!(
                f,
                "TLV #{index} (type {ty}) claims {len} B but only {room} B remain in the frame"
            ),
            Self::TrailingBytes { len } => {
                write!(f, "{len} B after the last TLV in a layout without padding")
            }
            Self::OverlapsNextFrame { overlap, len } => write!(
                f,
                "the previous frame ({len} B) ended {overlap} B into the next frame's magic: it lost bytes on the wire, discard it"
            ),
            Self::Truncated { claimed, got } => write!(
                f,
                "frame truncated: header claims {claimed} B, next magic (or end of stream) after {got} B"
            ),
        }
    }
}

/// What a TLV payload's length had to be for its type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expected {
    /// Exactly this many bytes.
    Exactly(u32),
    /// A multiple of this many bytes.
    MultipleOf(u32),
    /// A fixed prefix, then a multiple of the element size.
    PrefixThenMultipleOf {
        /// Prefix length \[B\].
        prefix: u32,
        /// Element size \[B\].
        elem: u32,
    },
    /// A power-of-two count of u16 bins (range/noise profiles, range-Doppler heatmap).
    PowerOfTwoU16s,
    /// The length implied by the payload's own count field.
    FromCount {
        /// Declared element count.
        count: u32,
        /// Payload length implied by that count \[B\].
        implied: u32,
    },
}

/// Why a TLV payload could not be decoded as its type. The raw payload stays available.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TlvError {
    /// The payload length does not fit the type's layout.
    BadLength {
        /// TLV type.
        ty: u32,
        /// Payload length \[B\].
        len: u32,
        /// What the type requires.
        expected: Expected,
    },
    /// The SDK 1/2 point descriptor carries a Q format that cannot be right (over 15 fractional bits).
    BadQFormat {
        /// The xyzQFormat field.
        q: u16,
    },
}

impl fmt::Display for Expected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Exactly(n) => write!(f, "exactly {n} B"),
            Self::MultipleOf(n) => write!(f, "a multiple of {n} B"),
            Self::PrefixThenMultipleOf { prefix, elem } => {
                write!(f, "{prefix} B then a multiple of {elem} B")
            }
            Self::PowerOfTwoU16s => write!(f, "a power-of-two number of u16 bins"),
            Self::FromCount { count, implied } => {
                write!(f, "{implied} B for the {count} elements it declares")
            }
        }
    }
}

impl fmt::Display for TlvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BadLength { ty, len, expected } => {
                write!(f, "TLV type {ty}: payload of {len} B, expected {expected}")
            }
            Self::BadQFormat { q } => {
                write!(f, "point descriptor Q format {q} is out of range (0..=15)")
            }
        }
    }
}

impl core::error::Error for FrameError {}
impl core::error::Error for TlvError {}
