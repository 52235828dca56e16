//! The version-1 message: a 16-byte header, a body, a CRC-32C (spec: `docs/hub-link.md`).

use crate::cobs::StreamEncoder;
use crate::Crc32c;
use core::fmt;

/// Protocol version this crate writes and reads.
pub const VERSION: u8 = 1;
/// Header length \[B\]: kind, version, flags (u16), link sequence number (u32), hub time (u64 ns).
pub const HEADER_LEN: usize = 16;
/// Trailer length \[B\]: CRC-32C (little-endian) over header and body.
pub const CRC_LEN: usize = 4;
/// Largest body the link carries \[B\] (a radar frame up to 16 KiB).
pub const MAX_BODY: usize = 16 * 1024;

/// Message kinds (header byte 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Kind {
    /// A radar data-UART frame, verbatim (magic word to its totalPacketLen).
    Radar = 1,
    /// An Xsens Xbus message, verbatim (preamble to checksum).
    Imu = 2,
    /// The hub's counters and clock ([`Health`]).
    Health = 3,
}

impl Kind {
    /// The kind of a header byte.
    pub fn from_u8(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Radar),
            2 => Some(Kind::Imu),
            3 => Some(Kind::Health),
            _ => None,
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Radar => "radar",
            Kind::Imu => "imu",
            Kind::Health => "health",
        }
    }
}

/// The header of every message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Header {
    /// Flags (version 1: 0 on the wire; receivers ignore unknown bits).
    pub flags: u16,
    /// Link sequence number: +1 per message the hub produced, whether sent or dropped for
    /// backpressure (a gap counts lost messages).
    pub seq: u32,
    /// Hub time \[ns since hub boot\]: for radar and IMU messages the time the sensor's last byte
    /// arrived; for health the time it was written.
    pub t_ns: u64,
}

/// Counters of one sensor UART (all wrap at 2^32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PortHealth {
    /// Bytes the UART received \[B\].
    pub rx_bytes: u32,
    /// Bytes lost because the receive ring was full \[B\].
    pub ring_overflow: u32,
    /// Highest fill of the receive ring \[B\].
    pub ring_high_water: u32,
    /// UART receive errors (overrun, framing, parity, break).
    pub uart_errors: u32,
    /// Frames the framer released.
    pub frames_ok: u32,
    /// Candidates the framer rejected (all reasons).
    pub frames_bad: u32,
    /// Bytes the framer skipped (junk, rejected candidates) \[B\].
    pub bytes_skipped: u32,
    /// Times the framer searched for sync.
    pub resyncs: u32,
    /// Frames handed to the link (sent or dropped for backpressure).
    pub frames_forwarded: u32,
    /// Radar only: frames released then retracted (they overlapped the next frame's magic).
    pub frames_retracted: u32,
}

/// Periodic health message body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Health {
    /// Frequency of the timer behind the hub clock \[Hz\].
    pub timer_hz: u32,
    /// Radar UART.
    pub radar: PortHealth,
    /// IMU UART.
    pub imu: PortHealth,
    /// Messages put on the link.
    pub link_sent: u32,
    /// Messages dropped because the link's transmit ring was full (backpressure).
    pub link_dropped: u32,
    /// Bytes of those messages (encoded) \[B\].
    pub link_dropped_bytes: u32,
    /// Highest fill of the transmit ring \[B\].
    pub link_high_water: u32,
    /// Receive-interrupt timestamps merged because the stamp ring was full (those bytes carry a
    /// later stamp).
    pub stamps_merged: u32,
    /// Worst receive-interrupt time per byte \[cycles of `isr_clock`\].
    pub isr_max_per_byte: u32,
    /// What `isr_max_per_byte` counts: 0 not measured, 1 DWT CYCCNT core cycles, 2 SysTick
    /// ticks.
    pub isr_clock: u32,
    /// Receive ring sizes, radar and IMU, and the transmit ring size \[B\].
    pub capacities: [u32; 3],
}

/// Health body length in version 1 \[B\] (31 little-endian u32). Longer bodies are accepted
/// (fields appended by a later minor revision are ignored).
pub const HEALTH_LEN: usize = 31 * 4;

impl Health {
    fn words(&self) -> [u32; 31] {
        let p = |h: &PortHealth| {
            [
                h.rx_bytes,
                h.ring_overflow,
                h.ring_high_water,
                h.uart_errors,
                h.frames_ok,
                h.frames_bad,
                h.bytes_skipped,
                h.resyncs,
                h.frames_forwarded,
                h.frames_retracted,
            ]
        };
        let (r, i) = (p(&self.radar), p(&self.imu));
        let mut w = [0u32; 31];
        w[0] = self.timer_hz;
        w[1..11].copy_from_slice(&r);
        w[11..21].copy_from_slice(&i);
        w[21] = self.link_sent;
        w[22] = self.link_dropped;
        w[23] = self.link_dropped_bytes;
        w[24] = self.link_high_water;
        w[25] = self.stamps_merged;
        w[26] = self.isr_max_per_byte;
        w[27] = self.isr_clock;
        w[28..31].copy_from_slice(&self.capacities);
        w
    }

    /// The body bytes.
    pub fn to_bytes(&self) -> [u8; HEALTH_LEN] {
        let mut out = [0u8; HEALTH_LEN];
        for (c, w) in out.chunks_exact_mut(4).zip(self.words()) {
            c.copy_from_slice(&w.to_le_bytes());
        }
        out
    }

    /// Reads a body (at least [`HEALTH_LEN`] bytes).
    pub fn from_bytes(b: &[u8]) -> Option<Health> {
        if b.len() < HEALTH_LEN {
            return None;
        }
        let mut w = [0u32; 31];
        for (x, c) in w.iter_mut().zip(b.chunks_exact(4)) {
            *x = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
        let p = |s: &[u32]| PortHealth {
            rx_bytes: s[0],
            ring_overflow: s[1],
            ring_high_water: s[2],
            uart_errors: s[3],
            frames_ok: s[4],
            frames_bad: s[5],
            bytes_skipped: s[6],
            resyncs: s[7],
            frames_forwarded: s[8],
            frames_retracted: s[9],
        };
        Some(Health {
            timer_hz: w[0],
            radar: p(&w[1..11]),
            imu: p(&w[11..21]),
            link_sent: w[21],
            link_dropped: w[22],
            link_dropped_bytes: w[23],
            link_high_water: w[24],
            stamps_merged: w[25],
            isr_max_per_byte: w[26],
            isr_clock: w[27],
            capacities: [w[28], w[29], w[30]],
        })
    }
}

/// A decoded message; sensor bytes borrow the decode buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message<'a> {
    /// A radar frame.
    Radar {
        /// Header.
        header: Header,
        /// The frame as it came off the radar's UART.
        bytes: &'a [u8],
    },
    /// An IMU message.
    Imu {
        /// Header.
        header: Header,
        /// The Xbus message as it came off the IMU's UART.
        bytes: &'a [u8],
    },
    /// Health.
    Health {
        /// Header.
        header: Header,
        /// Counters.
        health: Health,
    },
}

impl<'a> Message<'a> {
    /// The header.
    pub fn header(&self) -> &Header {
        match self {
            Message::Radar { header, .. }
            | Message::Imu { header, .. }
            | Message::Health { header, .. } => header,
        }
    }

    /// The kind.
    pub fn kind(&self) -> Kind {
        match self {
            Message::Radar { .. } => Kind::Radar,
            Message::Imu { .. } => Kind::Imu,
            Message::Health { .. } => Kind::Health,
        }
    }

    /// Checks and decodes one message (COBS already removed).
    pub fn decode(buf: &'a [u8]) -> Result<Message<'a>, DecodeError> {
        if buf.len() < HEADER_LEN + CRC_LEN {
            return Err(DecodeError::TooShort { len: buf.len() });
        }
        let (data, crc) = buf.split_at(buf.len() - CRC_LEN);
        let want = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
        let got = crate::crc32c(data);
        if got != want {
            return Err(DecodeError::Crc { want, got });
        }
        if data[1] != VERSION {
            return Err(DecodeError::Version { version: data[1] });
        }
        let header = Header {
            flags: u16::from_le_bytes([data[2], data[3]]),
            seq: u32::from_le_bytes([data[4], data[5], data[6], data[7]]),
            t_ns: u64::from_le_bytes([
                data[8], data[9], data[10], data[11], data[12], data[13], data[14], data[15],
            ]),
        };
        let body = &data[HEADER_LEN..];
        match Kind::from_u8(data[0]) {
            Some(Kind::Radar) => Ok(Message::Radar {
                header,
                bytes: body,
            }),
            Some(Kind::Imu) => Ok(Message::Imu {
                header,
                bytes: body,
            }),
            Some(Kind::Health) => Health::from_bytes(body)
                .map(|health| Message::Health { header, health })
                .ok_or(DecodeError::HealthTooShort { len: body.len() }),
            None => Err(DecodeError::Kind { kind: data[0] }),
        }
    }

    /// Encodes the message for the serial link (COBS, then the 0x00 delimiter), byte by byte
    /// into `out`; returns the bytes written.
    pub fn encode_serial(&self, out: &mut impl FnMut(u8)) -> usize {
        let hb;
        let body: &[u8] = match self {
            Message::Radar { bytes, .. } | Message::Imu { bytes, .. } => bytes,
            Message::Health { health, .. } => {
                hb = health.to_bytes();
                &hb
            }
        };
        encode_serial(self.kind(), self.header(), &[body], out)
    }
}

/// Bytes of the raw message for a body of `body_len` bytes \[B\].
pub const fn message_len(body_len: usize) -> usize {
    HEADER_LEN + body_len + CRC_LEN
}

/// Largest serial frame (COBS and delimiter) for a body of `body_len` bytes \[B\].
pub const fn serial_len_max(body_len: usize) -> usize {
    crate::cobs::max_encoded_len(message_len(body_len)) + 1
}

/// Encodes a message whose body is the concatenation of `body` parts, COBS-stuffed and
/// delimited, byte by byte into `out` (no buffer beyond COBS's 254-byte block); returns the bytes
/// written. The firmware writes straight into its transmit ring with this.
pub fn encode_serial(
    kind: Kind,
    header: &Header,
    body: &[&[u8]],
    out: &mut impl FnMut(u8),
) -> usize {
    let mut enc = StreamEncoder::new();
    let mut crc = Crc32c::default();
    let mut n = 0usize;
    let mut put = |b: u8, enc: &mut StreamEncoder, crc: &mut Crc32c| {
        crc.byte(b);
        n += enc.push(b, out);
    };
    let mut h = [0u8; HEADER_LEN];
    h[0] = kind as u8;
    h[1] = VERSION;
    h[2..4].copy_from_slice(&header.flags.to_le_bytes());
    h[4..8].copy_from_slice(&header.seq.to_le_bytes());
    h[8..16].copy_from_slice(&header.t_ns.to_le_bytes());
    for &b in &h {
        put(b, &mut enc, &mut crc);
    }
    for part in body {
        for &b in *part {
            put(b, &mut enc, &mut crc);
        }
    }
    let c = crc.finish().to_le_bytes();
    for b in c {
        n += enc.push(b, out);
    }
    n + enc.finish(out)
}

/// Why a message does not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DecodeError {
    /// Shorter than header plus CRC.
    TooShort {
        /// Bytes \[B\].
        len: usize,
    },
    /// CRC mismatch.
    Crc {
        /// CRC in the message.
        want: u32,
        /// CRC computed.
        got: u32,
    },
    /// A version this decoder does not read.
    Version {
        /// The version byte.
        version: u8,
    },
    /// An unknown kind byte.
    Kind {
        /// The kind byte.
        kind: u8,
    },
    /// A health body shorter than [`HEALTH_LEN`].
    HealthTooShort {
        /// Body bytes \[B\].
        len: usize,
    },
}

impl DecodeError {
    /// Stable snake_case name (counters, summaries).
    pub fn kind_name(&self) -> &'static str {
        match self {
            DecodeError::TooShort { .. } => "too_short",
            DecodeError::Crc { .. } => "bad_crc",
            DecodeError::Version { .. } => "bad_version",
            DecodeError::Kind { .. } => "bad_kind",
            DecodeError::HealthTooShort { .. } => "health_too_short",
        }
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecodeError::TooShort { len } => write!(f, "message of {len} B is shorter than 20 B"),
            DecodeError::Crc { want, got } => {
                write!(
                    f,
                    "CRC-32C mismatch: message says {want:#010x}, computed {got:#010x}"
                )
            }
            DecodeError::Version { version } => write!(f, "unsupported version {version}"),
            DecodeError::Kind { kind } => write!(f, "unknown message kind {kind}"),
            DecodeError::HealthTooShort { len } => {
                write!(f, "health body of {len} B, need {HEALTH_LEN}")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}
