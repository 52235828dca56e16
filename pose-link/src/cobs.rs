//! Consistent Overhead Byte Stuffing: frames a message so that 0x00 never appears inside it, and
//! a 0x00 delimiter ends it. Overhead: 1 byte per started 254 bytes.

use core::fmt;

/// Largest encoded size of `n` bytes (without the delimiter) \[B\].
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Why COBS bytes do not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CobsError {
    /// A 0x00 inside an encoded frame (at this offset).
    ZeroByte {
        /// Offset in the frame \[B\].
        at: usize,
    },
    /// A code byte points past the end of the frame.
    Overrun {
        /// Offset of the code byte \[B\].
        at: usize,
        /// The code.
        code: u8,
    },
    /// The output buffer is too small \[B\].
    BufferTooSmall {
        /// Bytes the output needed at least \[B\].
        need: usize,
    },
}

impl fmt::Display for CobsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::ZeroByte { at } => write!(f, "COBS frame holds a 0x00 at offset {at}"),
            Self::Overrun { at, code } => {
                write!(f, "COBS code {code} at offset {at} runs past the frame end")
            }
            Self::BufferTooSmall { need } => {
                write!(f, "COBS output buffer too small: need at least {need} B")
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CobsError {}

/// Encodes `src` into `dst` (no delimiter); returns the encoded length.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Result<usize, CobsError> {
    let need = max_encoded_len(src.len());
    if dst.len() < need {
        return Err(CobsError::BufferTooSmall { need });
    }
    let mut code_at = 0;
    let mut out = 1;
    let mut code = 1u8;
    for &b in src {
        if b == 0 {
            dst[code_at] = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            dst[out] = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                dst[code_at] = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    Ok(out)
}

/// COBS encoder that takes one byte at a time and emits encoded bytes as soon as a block is
/// complete (at most 254 bytes are held): no frame-sized buffer. The output equals [`encode`]'s
/// for the same input; [`StreamEncoder::finish`] also writes the 0x00 delimiter.
#[derive(Debug, Clone)]
pub struct StreamEncoder {
    block: [u8; 254],
    n: usize,
}

impl Default for StreamEncoder {
    fn default() -> Self {
        Self::new()
    }
}

impl StreamEncoder {
    /// An encoder at the start of a frame.
    pub const fn new() -> Self {
        StreamEncoder {
            block: [0; 254],
            n: 0,
        }
    }

    fn flush(&mut self, code: u8, out: &mut impl FnMut(u8)) -> usize {
        out(code);
        for &b in &self.block[..self.n] {
            out(b);
        }
        let w = self.n + 1;
        self.n = 0;
        w
    }

    /// Adds one byte; returns the bytes written to `out`.
    #[inline]
    pub fn push(&mut self, b: u8, out: &mut impl FnMut(u8)) -> usize {
        if b == 0 {
            return self.flush(self.n as u8 + 1, out);
        }
        self.block[self.n] = b;
        self.n += 1;
        if self.n == 254 {
            return self.flush(0xFF, out);
        }
        0
    }

    /// Ends the frame: the last block and the 0x00 delimiter; returns the bytes written.
    pub fn finish(&mut self, out: &mut impl FnMut(u8)) -> usize {
        let w = self.flush(self.n as u8 + 1, out);
        out(0);
        w + 1
    }
}

/// Splits a byte stream at its 0x00 delimiters into COBS frames of at most `N` encoded bytes:
/// the part of a link's deframer that does not depend on its messages (the pose link's and the
/// hub link's deframers both decode what this releases).
#[derive(Debug)]
pub struct Splitter<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: usize,
    /// Bytes consumed \[B\].
    pub bytes_in: u64,
    /// Empty frames (consecutive delimiters), skipped.
    pub empty_frames: u64,
}

/// What one [`Splitter::poll`] released.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split<'a> {
    /// A delimited frame, still COBS-encoded, without its delimiter.
    Frame {
        /// The encoded bytes.
        cobs: &'a [u8],
        /// Its bytes on the wire, delimiter included \[B\].
        wire: usize,
    },
    /// A frame longer than the buffer before its delimiter: all its bytes are gone.
    Overflow {
        /// Its bytes on the wire, delimiter included \[B\].
        dropped: usize,
    },
    /// The input is used up.
    NeedMore,
}

impl<const N: usize> Default for Splitter<N> {
    fn default() -> Self {
        Splitter {
            buf: [0; N],
            len: 0,
            overflow: 0,
            bytes_in: 0,
            empty_frames: 0,
        }
    }
}

impl<const N: usize> Splitter<N> {
    /// Bytes held for an unfinished frame \[B\].
    pub fn buffered(&self) -> usize {
        self.len + self.overflow
    }

    /// Forgets an unfinished frame; returns its bytes \[B\].
    pub fn resync(&mut self) -> usize {
        let dropped = self.buffered();
        self.len = 0;
        self.overflow = 0;
        dropped
    }

    /// Consumes bytes from `input` (advancing it) up to the next delimiter that ends a frame.
    pub fn poll(&mut self, input: &mut &[u8]) -> Split<'_> {
        while let Some((&b, rest)) = input.split_first() {
            *input = rest;
            self.bytes_in += 1;
            if b != 0 {
                if self.len < N {
                    self.buf[self.len] = b;
                    self.len += 1;
                } else {
                    self.overflow += 1;
                }
                continue;
            }
            let wire = self.len + self.overflow + 1;
            let len = core::mem::take(&mut self.len);
            if core::mem::take(&mut self.overflow) > 0 {
                return Split::Overflow { dropped: wire };
            }
            if len == 0 {
                self.empty_frames += 1;
                continue;
            }
            return Split::Frame {
                cobs: &self.buf[..len],
                wire,
            };
        }
        Split::NeedMore
    }
}

/// Decodes one frame `src` (without its delimiter) into `dst`; returns the decoded length.
pub fn decode(src: &[u8], dst: &mut [u8]) -> Result<usize, CobsError> {
    let mut i = 0;
    let mut out = 0;
    while i < src.len() {
        let code = src[i];
        if code == 0 {
            return Err(CobsError::ZeroByte { at: i });
        }
        let end = i + usize::from(code);
        if end > src.len() {
            return Err(CobsError::Overrun { at: i, code });
        }
        for (k, &b) in src[i + 1..end].iter().enumerate() {
            if b == 0 {
                return Err(CobsError::ZeroByte { at: i + 1 + k });
            }
            *dst.get_mut(out)
                .ok_or(CobsError::BufferTooSmall { need: out + 1 })? = b;
            out += 1;
        }
        i = end;
        if code != 0xFF && i < src.len() {
            *dst.get_mut(out)
                .ok_or(CobsError::BufferTooSmall { need: out + 1 })? = 0;
            out += 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round(src: &[u8]) {
        let mut enc = [0u8; 1024];
        let n = encode(src, &mut enc).unwrap();
        assert!(!enc[..n].contains(&0));
        assert!(n <= max_encoded_len(src.len()));
        let mut dec = [0u8; 1024];
        let m = decode(&enc[..n], &mut dec).unwrap();
        assert_eq!(&dec[..m], src);
    }

    #[test]
    fn known_vectors() {
        let mut enc = [0u8; 16];
        let n = encode(&[0x11, 0x22, 0x00, 0x33], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = encode(&[0x00], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x01, 0x01]);
        let n = encode(&[], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x01]);
    }

    #[test]
    fn round_trips_including_254_runs() {
        round(&[]);
        round(&[0, 0, 0]);
        let long: [u8; 600] = core::array::from_fn(|i| (i % 255) as u8 + 1);
        round(&long);
        round(&long[..254]);
        round(&long[..253]);
        let mut mixed = long;
        mixed[300] = 0;
        round(&mixed);
    }

    #[test]
    fn stream_encoder_matches_encode() {
        let long: [u8; 800] =
            core::array::from_fn(|i| if i % 97 == 5 { 0 } else { (i % 255) as u8 + 1 });
        for n in [0, 1, 2, 253, 254, 255, 507, 508, 509, 800] {
            for src in [&long[..n], &[0u8; 800][..n]] {
                let mut want = [0u8; 1024];
                let m = encode(src, &mut want).unwrap();
                let mut got = [0u8; 1024];
                let mut k = 0;
                let mut e = StreamEncoder::new();
                let mut w = 0;
                for &b in src {
                    w += e.push(b, &mut |x| {
                        got[k] = x;
                        k += 1
                    });
                }
                w += e.finish(&mut |x| {
                    got[k] = x;
                    k += 1
                });
                assert_eq!(w, k);
                assert_eq!(&got[..k - 1], &want[..m], "n = {n}");
                assert_eq!(got[k - 1], 0);
            }
        }
    }

    #[test]
    fn malformed_frames_are_named() {
        let mut d = [0u8; 8];
        assert_eq!(
            decode(&[0x05, 1, 2], &mut d),
            Err(CobsError::Overrun { at: 0, code: 5 })
        );
        assert_eq!(
            decode(&[0x03, 1, 0], &mut d),
            Err(CobsError::ZeroByte { at: 2 })
        );
        assert_eq!(
            decode(&[0x09, 1, 2, 3, 4, 5, 6, 7, 8], &mut [0u8; 4]),
            Err(CobsError::BufferTooSmall { need: 5 })
        );
    }
}
