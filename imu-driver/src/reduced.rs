//! Reduced Xbus for the MTi-1 series over I2C/SPI (MTSSP): messages without preamble and bus
//! id, checksummed as if the bus id were 0xFF, moved through opcode-addressed pipes.

use crate::encode::EncodeError;
use crate::frame::{
    checksum_sum, FrameError, EXTENDED_LEN, MAX_EXTENDED_PAYLOAD, MAX_STANDARD_PAYLOAD,
};
use core::fmt;

/// MTSSP opcodes (the first byte of every I2C/SPI transfer).
pub mod opcode {
    /// Read protocol information.
    pub const PROTOCOL_INFO: u8 = 0x01;
    /// Write the protocol configuration.
    pub const CONFIGURE_PROTOCOL: u8 = 0x02;
    /// Write a reduced message to the device.
    pub const CONTROL_PIPE: u8 = 0x03;
    /// Read the sizes waiting in the notification and measurement pipes.
    pub const PIPE_STATUS: u8 = 0x04;
    /// Read one message from the notification pipe (acks, errors, replies).
    pub const NOTIFICATION_PIPE: u8 = 0x05;
    /// Read one message from the measurement pipe (MTData2).
    pub const MEASUREMENT_PIPE: u8 = 0x06;
}

/// The bus id the checksum assumes.
const IMPLIED_BID: u8 = 0xFF;

/// A checked reduced message `MID LEN [EXT_HI EXT_LO] DATA CS`, borrowed.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct ReducedFrame<'a> {
    raw: &'a [u8],
    header: u8,
}

impl<'a> ReducedFrame<'a> {
    /// Checks that `raw` starts with one reduced message and returns it with the bytes after it
    /// (a pipe read may be longer than its message).
    pub fn parse(raw: &'a [u8]) -> Result<(Self, &'a [u8]), FrameError> {
        let (len, header) = match raw {
            [_, EXTENDED_LEN, hi, lo, ..] => (usize::from(u16::from_be_bytes([*hi, *lo])), 4),
            [_, EXTENDED_LEN, ..] => {
                return Err(FrameError::Truncated {
                    have: raw.len(),
                    need: 4,
                })
            }
            [_, len, ..] => (usize::from(*len), 2),
            _ => {
                return Err(FrameError::Truncated {
                    have: raw.len(),
                    need: 2,
                })
            }
        };
        let total = header + len + 1;
        let (frame, rest) = raw.split_at_checked(total).ok_or(FrameError::Truncated {
            have: raw.len(),
            need: total,
        })?;
        let sum = checksum_sum(frame).wrapping_add(IMPLIED_BID);
        if sum != 0 {
            let got = frame.last().copied().unwrap_or(0);
            return Err(FrameError::BadChecksum {
                mid: frame.first().copied().unwrap_or(0),
                expected: got.wrapping_sub(sum),
                got,
            });
        }
        Ok((
            Self {
                raw: frame,
                header: header as u8,
            },
            rest,
        ))
    }

    /// Message identifier.
    pub fn mid(&self) -> u8 {
        self.raw.first().copied().unwrap_or(0)
    }

    /// The payload bytes.
    pub fn payload(&self) -> &'a [u8] {
        let end = self.raw.len().saturating_sub(1);
        self.raw
            .get(usize::from(self.header)..end)
            .unwrap_or_default()
    }

    /// The message as received.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.raw
    }
}

impl fmt::Debug for ReducedFrame<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ReducedFrame")
            .field("mid", &format_args!("0x{:02X}", self.mid()))
            .field("payload_len", &self.payload().len())
            .finish()
    }
}

/// Encodes a control-pipe write: `0x03 MID LEN [EXT] DATA CS`. Returns its length.
pub fn encode_control(out: &mut [u8], mid: u8, payload: &[u8]) -> Result<usize, EncodeError> {
    let len = payload.len();
    if len > MAX_EXTENDED_PAYLOAD {
        return Err(EncodeError::PayloadTooLarge { len });
    }
    let (header, h): ([u8; 5], usize) = if len <= MAX_STANDARD_PAYLOAD {
        ([opcode::CONTROL_PIPE, mid, len as u8, 0, 0], 3)
    } else {
        let [hi, lo] = (len as u16).to_be_bytes();
        ([opcode::CONTROL_PIPE, mid, EXTENDED_LEN, hi, lo], 5)
    };
    let need = h + len + 1;
    let have = out.len();
    let frame = out
        .get_mut(..need)
        .ok_or(EncodeError::BufferTooSmall { need, have })?;
    let (head, body) = frame.split_at_mut(h);
    head.copy_from_slice(header.get(..h).unwrap_or_default());
    let (data, cs) = body.split_at_mut(len);
    data.copy_from_slice(payload);
    let sum = checksum_sum(head.get(1..).unwrap_or_default())
        .wrapping_add(checksum_sum(payload))
        .wrapping_add(IMPLIED_BID);
    if let Some(c) = cs.first_mut() {
        *c = sum.wrapping_neg();
    }
    Ok(need)
}

/// The reply to [`opcode::PIPE_STATUS`]: bytes waiting in each pipe (two little-endian u16).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PipeStatus {
    /// Size of the next notification message \[bytes\].
    pub notification_size: u16,
    /// Size of the next measurement message \[bytes\].
    pub measurement_size: u16,
}

impl PipeStatus {
    /// Decodes the 4 status bytes.
    pub fn parse(b: [u8; 4]) -> Self {
        let [n0, n1, m0, m1] = b;
        Self {
            notification_size: u16::from_le_bytes([n0, n1]),
            measurement_size: u16::from_le_bytes([m0, m1]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode::encode_frame;

    #[test]
    fn reduced_form_is_the_full_frame_without_preamble_and_bid() {
        // Full frame FA FF 31 00 D0 -> reduced 31 00 D0 (same checksum).
        let (f, rest) = ReducedFrame::parse(&[0x31, 0x00, 0xD0, 0xEE]).unwrap();
        assert_eq!((f.mid(), f.payload(), rest), (0x31, &[][..], &[0xEE][..]));
        for len in [0usize, 3, 254, 255, 300] {
            let payload: std::vec::Vec<u8> = (0..len).map(|i| i as u8).collect();
            let mut full = vec![0u8; len + 7];
            let n = encode_frame(&mut full, 0xFF, 0x36, &payload).unwrap();
            let mut ctl = vec![0u8; len + 6];
            let m = encode_control(&mut ctl, 0x36, &payload).unwrap();
            assert_eq!(ctl[0], opcode::CONTROL_PIPE);
            assert_eq!(&ctl[1..m], &full[2..n], "len {len}");
            let (f, rest) = ReducedFrame::parse(&ctl[1..m]).unwrap();
            assert_eq!((f.mid(), f.payload(), rest.len()), (0x36, &payload[..], 0));
        }
    }

    #[test]
    fn reduced_errors_carry_evidence() {
        assert_eq!(
            ReducedFrame::parse(&[0x31, 0x00, 0xD1]),
            Err(FrameError::BadChecksum {
                mid: 0x31,
                expected: 0xD0,
                got: 0xD1
            })
        );
        assert_eq!(
            ReducedFrame::parse(&[0x36, 0x05, 1, 2]),
            Err(FrameError::Truncated { have: 4, need: 8 })
        );
        assert!(ReducedFrame::parse(&[]).is_err());
        assert_eq!(
            encode_control(&mut [0u8; 3], 0x30, &[]),
            Err(EncodeError::BufferTooSmall { need: 4, have: 3 })
        );
    }

    #[test]
    fn pipe_status_is_little_endian() {
        assert_eq!(
            PipeStatus::parse([0x05, 0x00, 0x2C, 0x01]),
            PipeStatus {
                notification_size: 5,
                measurement_size: 300
            }
        );
    }
}
