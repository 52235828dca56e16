//! A CDR serializer (XCDR1, little-endian, plain `CDR_LE` encapsulation), as ROS 2 writes message
//! payloads: a 4-byte encapsulation header `00 01 00 00`, then the fields in declaration order,
//! each primitive aligned to its own size relative to the first byte AFTER the header. Strings are
//! a `uint32` length counting the terminating NUL, the bytes, the NUL; sequences a `uint32` element
//! count and the elements; fixed arrays just the elements; nested messages just their fields.

/// Why a value cannot be written: CDR lengths are `uint32`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CdrError {
    /// A string or sequence longer than `u32::MAX` elements.
    TooLong {
        /// What was being written.
        what: &'static str,
        /// Its length \[elements\].
        len: usize,
    },
}

impl std::fmt::Display for CdrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CdrError::TooLong { what, len } => {
                write!(
                    f,
                    "{what} of {len} elements does not fit a CDR uint32 length"
                )
            }
        }
    }
}

impl std::error::Error for CdrError {}

/// The encapsulation header of little-endian plain CDR (representation id `CDR_LE`, options 0).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Builds one CDR payload.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        CdrWriter::new()
    }
}

impl CdrWriter {
    /// A payload holding only the encapsulation header.
    pub fn new() -> CdrWriter {
        CdrWriter {
            buf: CDR_LE_HEADER.to_vec(),
        }
    }

    /// The payload, header included.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    /// Bytes written after the header \[B\].
    pub fn body_len(&self) -> usize {
        self.buf.len() - CDR_LE_HEADER.len()
    }

    /// Pads with zeros to a multiple of `n` bytes from the start of the body.
    fn align(&mut self, n: usize) {
        while !self.body_len().is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    /// `uint8` / `byte` / `char`.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// `bool` (one byte, 0 or 1).
    pub fn bool(&mut self, v: bool) {
        self.buf.push(u8::from(v));
    }

    /// `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `float32`.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// Fixed-size `float64[N]` (no length prefix).
    pub fn f64_array(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }

    /// The `uint32` length of a sequence of `len` elements.
    pub fn seq_len(&mut self, what: &'static str, len: usize) -> Result<(), CdrError> {
        let n = u32::try_from(len).map_err(|_| CdrError::TooLong { what, len })?;
        self.u32(n);
        Ok(())
    }

    /// `string`: length including the NUL, bytes, NUL.
    pub fn string(&mut self, v: &str) -> Result<(), CdrError> {
        self.seq_len("string", v.len() + 1)?;
        self.buf.extend_from_slice(v.as_bytes());
        self.buf.push(0);
        Ok(())
    }

    /// `uint8[]`: count, bytes.
    pub fn bytes(&mut self, v: &[u8]) -> Result<(), CdrError> {
        self.seq_len("uint8[]", v.len())?;
        self.buf.extend_from_slice(v);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_only() {
        assert_eq!(CdrWriter::new().into_bytes(), [0, 1, 0, 0]);
    }

    #[test]
    fn float64_after_string_is_aligned_from_the_body_start() {
        // string "ab" (len 3 incl. NUL) takes body bytes 0..7; the float64 starts at 8.
        let mut w = CdrWriter::new();
        w.string("ab").unwrap();
        w.f64(1.0);
        let want: Vec<u8> = [
            &[0, 1, 0, 0][..],
            &[3, 0, 0, 0, b'a', b'b', 0],
            &[0],
            &1.0f64.to_le_bytes(),
        ]
        .concat();
        assert_eq!(w.into_bytes(), want);
    }

    #[test]
    fn empty_string_is_a_nul() {
        let mut w = CdrWriter::new();
        w.string("").unwrap();
        w.u8(7);
        w.u32(0x0403_0201);
        assert_eq!(
            w.into_bytes(),
            [0, 1, 0, 0, 1, 0, 0, 0, 0, 7, 0, 0, 1, 2, 3, 4]
        );
    }

    #[test]
    fn sequences_and_fixed_arrays() {
        let mut w = CdrWriter::new();
        // bool at 0, pad to 4, count 4..8, bytes 8..11.
        w.bool(true);
        w.bytes(&[9, 8, 7]).unwrap();
        w.f64_array(&[-1.0, 2.5]);
        let want: Vec<u8> = [
            &[0, 1, 0, 0][..],
            &[1, 0, 0, 0],
            &[3, 0, 0, 0, 9, 8, 7],
            // body 11: pad to 16 for the float64
            &[0, 0, 0, 0, 0],
            &(-1.0f64).to_le_bytes(),
            &2.5f64.to_le_bytes(),
        ]
        .concat();
        assert_eq!(w.into_bytes(), want);
    }

    #[test]
    fn signed_and_float32() {
        let mut w = CdrWriter::new();
        w.u8(1);
        w.i32(-2);
        w.f32(0.5);
        assert_eq!(
            w.into_bytes(),
            [0, 1, 0, 0, 1, 0, 0, 0, 0xfe, 0xff, 0xff, 0xff, 0, 0, 0, 0x3f]
        );
    }
}
