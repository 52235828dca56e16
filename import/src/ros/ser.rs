//! The two ROS serialisations, behind one reader so each message layout is written once
//! ([`super::msgs`]):
//!
//! - ROS 1: little-endian, packed (no alignment); a string is a `u32` byte count then the bytes
//!   (no NUL); `time` is `u32 sec, u32 nsec`.
//! - CDR (ROS 2, XCDR1): a 4-byte encapsulation header (`00 01` little-endian, `00 00` big-endian,
//!   then two option bytes); every primitive is aligned to its size counted from the end of that
//!   header; a string is a `u32` count that includes the terminating NUL, then the bytes and the NUL;
//!   `builtin_interfaces/Time` is `i32 sec, u32 nanosec`.
//!
//! Sequences are a `u32` element count in both. Every read is bounds-checked: a truncated or
//! malformed payload is an error naming the field and the byte offset, never a panic.

use std::fmt;

/// Which serialisation a payload uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1 (bags v2.0).
    Ros1,
    /// CDR with its encapsulation header (ROS 2 bags, MCAP `cdr` channels).
    Cdr,
}

/// Why a payload could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MsgError {
    /// The field being read, as a path (`header.frame_id`, `fields[2].name`).
    pub field: String,
    /// Byte offset in the payload where the read started.
    pub offset: usize,
    /// What is wrong.
    pub kind: MsgErrorKind,
}

/// What is wrong with a payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MsgErrorKind {
    /// The payload ends before the field does.
    Truncated {
        /// Bytes the field needs.
        need: usize,
        /// Bytes left.
        left: usize,
    },
    /// A CDR payload without a known encapsulation header.
    BadEncapsulation([u8; 2]),
    /// A string that is not UTF-8, or a CDR string without its NUL.
    BadString,
    /// A sequence or string longer than the payload could hold.
    TooLong {
        /// Elements (or bytes) claimed.
        len: u64,
    },
    /// A fixed-size field with a value outside its range (e.g. a `bool` that is not 0 or 1).
    BadValue(u64),
    /// Bytes left after the message (the payload is not this type).
    Trailing {
        /// Bytes left.
        left: usize,
    },
}

impl fmt::Display for MsgError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "field {} at byte {}: ", self.field, self.offset)?;
        match &self.kind {
            MsgErrorKind::Truncated { need, left } => {
                write!(f, "truncated (needs {need} B, {left} B left)")
            }
            MsgErrorKind::BadEncapsulation(b) => {
                write!(f, "unknown CDR encapsulation {:02x} {:02x}", b[0], b[1])
            }
            MsgErrorKind::BadString => f.write_str("not a valid string"),
            MsgErrorKind::TooLong { len } => write!(f, "length {len} exceeds the payload"),
            MsgErrorKind::BadValue(v) => write!(f, "invalid value {v}"),
            MsgErrorKind::Trailing { left } => {
                write!(f, "{left} B after the end of the message (wrong type?)")
            }
        }
    }
}

impl std::error::Error for MsgError {}

/// A reader over one serialised message.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    /// Where alignment is counted from (after the CDR header; 0 for ROS 1).
    origin: usize,
    enc: Encoding,
    big_endian: bool,
    /// The field path being read, for errors.
    path: Vec<String>,
}

impl<'a> Reader<'a> {
    /// A reader over `buf`; for CDR, checks and skips the encapsulation header.
    pub fn new(buf: &'a [u8], enc: Encoding) -> Result<Reader<'a>, MsgError> {
        let mut r = Reader {
            buf,
            pos: 0,
            origin: 0,
            enc,
            big_endian: false,
            path: Vec::new(),
        };
        if enc == Encoding::Cdr {
            let h = r.take("encapsulation", 4)?;
            r.big_endian = match [h[0], h[1]] {
                [0x00, 0x01] => false,
                [0x00, 0x00] => true,
                b => return Err(r.err_at(0, MsgErrorKind::BadEncapsulation(b))),
            };
            r.origin = 4;
        }
        Ok(r)
    }

    /// The serialisation.
    pub fn encoding(&self) -> Encoding {
        self.enc
    }

    /// Bytes read so far.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Reads `f` with `name` pushed on the field path.
    pub fn field<T>(
        &mut self,
        name: &str,
        f: impl FnOnce(&mut Self) -> Result<T, MsgError>,
    ) -> Result<T, MsgError> {
        self.path.push(name.to_string());
        let r = f(self);
        self.path.pop();
        r
    }

    /// Fails unless every byte was read (a CDR payload may end in up to 7 padding bytes; ROS 1
    /// none).
    pub fn finish(&self) -> Result<(), MsgError> {
        let left = self.buf.len() - self.pos;
        let allowed = if self.enc == Encoding::Cdr { 7 } else { 0 };
        if left > allowed {
            return Err(self.err_at(self.pos, MsgErrorKind::Trailing { left }));
        }
        Ok(())
    }

    fn err_at(&self, offset: usize, kind: MsgErrorKind) -> MsgError {
        MsgError {
            field: if self.path.is_empty() {
                "<message>".into()
            } else {
                self.path.join(".")
            },
            offset,
            kind,
        }
    }

    fn align(&mut self, n: usize) -> Result<(), MsgError> {
        if self.enc == Encoding::Cdr && n > 1 {
            let rel = self.pos - self.origin;
            let pad = (n - rel % n) % n;
            self.take("padding", pad)?;
        }
        Ok(())
    }

    fn take(&mut self, what: &str, n: usize) -> Result<&'a [u8], MsgError> {
        let left = self.buf.len() - self.pos;
        if n > left {
            let mut e = self.err_at(self.pos, MsgErrorKind::Truncated { need: n, left });
            if self.path.is_empty() {
                e.field = what.to_string();
            }
            return Err(e);
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], MsgError> {
        self.align(N)?;
        let s = self.take("value", N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }

    /// `uint8`.
    pub fn u8(&mut self) -> Result<u8, MsgError> {
        Ok(self.take("value", 1)?[0])
    }

    /// `bool` (0 or 1).
    pub fn bool(&mut self) -> Result<bool, MsgError> {
        let at = self.pos;
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(self.err_at(at, MsgErrorKind::BadValue(u64::from(v)))),
        }
    }

    /// `uint32`.
    pub fn u32(&mut self) -> Result<u32, MsgError> {
        Ok(u32::from_le_bytes(self.fixed()?))
    }

    /// `int32`.
    pub fn i32(&mut self) -> Result<i32, MsgError> {
        Ok(i32::from_le_bytes(self.fixed()?))
    }

    /// `float64`.
    pub fn f64(&mut self) -> Result<f64, MsgError> {
        Ok(f64::from_le_bytes(self.fixed()?))
    }

    /// `float64[N]`.
    pub fn f64_array<const N: usize>(&mut self) -> Result<[f64; N], MsgError> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64()?;
        }
        Ok(a)
    }

    /// A sequence length, checked against the bytes left (each element needs at least
    /// `min_elem` bytes).
    pub fn seq_len(&mut self, min_elem: usize) -> Result<usize, MsgError> {
        let at = self.pos;
        let n = self.u32()?;
        let left = self.buf.len() - self.pos;
        if (n as usize).saturating_mul(min_elem.max(1)) > left {
            return Err(self.err_at(at, MsgErrorKind::TooLong { len: u64::from(n) }));
        }
        Ok(n as usize)
    }

    /// `string`.
    pub fn string(&mut self) -> Result<String, MsgError> {
        let at = self.pos;
        let n = self.seq_len(1)?;
        let bytes = self.take("string", n)?;
        let text = match self.enc {
            Encoding::Ros1 => bytes,
            Encoding::Cdr => match bytes.split_last() {
                Some((0, s)) => s,
                // A zero count is tolerated (some writers emit it for the empty string).
                None => bytes,
                Some(_) => return Err(self.err_at(at, MsgErrorKind::BadString)),
            },
        };
        std::str::from_utf8(text)
            .map(str::to_string)
            .map_err(|_| self.err_at(at, MsgErrorKind::BadString))
    }

    /// `uint8[]`.
    pub fn bytes(&mut self) -> Result<&'a [u8], MsgError> {
        let n = self.seq_len(1)?;
        self.take("bytes", n)
    }

    /// A time stamp \[ns\]: ROS 1 `time` (`u32 sec, u32 nsec`) or ROS 2
    /// `builtin_interfaces/Time` (`i32 sec, u32 nanosec`).
    pub fn time_ns(&mut self) -> Result<i64, MsgError> {
        let sec = match self.enc {
            Encoding::Ros1 => i64::from(self.u32()?),
            Encoding::Cdr => i64::from(self.i32()?),
        };
        let at = self.pos;
        let nsec = self.u32()?;
        if nsec >= 1_000_000_000 {
            return Err(self.err_at(at, MsgErrorKind::BadValue(u64::from(nsec))));
        }
        Ok(sec * 1_000_000_000 + i64::from(nsec))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_aligns_from_the_end_of_the_header_and_strings_carry_a_nul() {
        // header, u8 7, pad 3, u32 string len 3 "ab\0", pad 5 -> f64 at rel 16
        let mut b = vec![0x00, 0x01, 0x00, 0x00, 7, 0, 0, 0];
        b.extend(3u32.to_le_bytes());
        b.extend(b"ab\0");
        b.extend([0u8; 5]);
        b.extend(1.5f64.to_le_bytes());
        let mut r = Reader::new(&b, Encoding::Cdr).unwrap();
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.string().unwrap(), "ab");
        assert_eq!(r.f64().unwrap(), 1.5);
        r.finish().unwrap();
    }

    #[test]
    fn cdr_big_endian() {
        let mut b = vec![0x00, 0x00, 0x00, 0x00];
        b.extend(0x0102_0304u32.to_be_bytes());
        let mut r = Reader::new(&b, Encoding::Cdr).unwrap();
        assert_eq!(r.u32().unwrap(), 0x0102_0304);
    }

    #[test]
    fn ros1_is_packed_and_strings_have_no_nul() {
        let mut b = vec![7u8];
        b.extend(2u32.to_le_bytes());
        b.extend(b"ab");
        b.extend(1.5f64.to_le_bytes());
        b.extend(3u32.to_le_bytes());
        b.extend(500u32.to_le_bytes());
        let mut r = Reader::new(&b, Encoding::Ros1).unwrap();
        assert_eq!(r.u8().unwrap(), 7);
        assert_eq!(r.string().unwrap(), "ab");
        assert_eq!(r.f64().unwrap(), 1.5);
        assert_eq!(r.time_ns().unwrap(), 3_000_000_500);
        r.finish().unwrap();
    }

    #[test]
    fn errors_name_the_field_and_offset() {
        let b = [0x00, 0x01, 0x00, 0x00, 9, 0, 0, 0];
        let mut r = Reader::new(&b, Encoding::Cdr).unwrap();
        let e = r
            .field("header", |r| r.field("frame_id", |r| r.string()))
            .unwrap_err();
        assert_eq!(e.field, "header.frame_id");
        assert_eq!(e.offset, 4);
        assert_eq!(e.kind, MsgErrorKind::TooLong { len: 9 });
        assert!(e.to_string().contains("header.frame_id at byte 4"), "{e}");
        let e = Reader::new(&[1, 2, 0, 0], Encoding::Cdr).unwrap_err();
        assert_eq!(e.kind, MsgErrorKind::BadEncapsulation([1, 2]));
        let e = Reader::new(&[0, 1], Encoding::Cdr).unwrap_err();
        assert!(matches!(
            e.kind,
            MsgErrorKind::Truncated { need: 4, left: 2 }
        ));
    }

    #[test]
    fn huge_sequence_counts_are_rejected_before_allocating() {
        let mut b = vec![0x00, 0x01, 0x00, 0x00];
        b.extend(u32::MAX.to_le_bytes());
        let mut r = Reader::new(&b, Encoding::Cdr).unwrap();
        assert!(matches!(
            r.seq_len(4).unwrap_err().kind,
            MsgErrorKind::TooLong { .. }
        ));
    }
}
