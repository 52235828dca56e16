//! Streaming Xbus framer over arbitrary chunks.

use crate::frame::{scan, FrameError, Scan, XbusFrame, FRAME_OVERHEAD, PREAMBLE};
use heapless::Vec;

/// One outcome of [`Framer::poll`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Poll<'a> {
    /// A frame with a valid checksum, released as soon as its checksum byte arrived.
    Frame(XbusFrame<'a>),
    /// `bytes` input bytes were given up on (counted in [`Counters::bytes_skipped`]); `error` says why.
    Dropped {
        /// Number of bytes discarded by this event.
        bytes: usize,
        /// Why they were discarded.
        error: FrameError,
    },
    /// All input was consumed (or buffered) without completing a frame.
    NeedMore,
}

/// [`Poll`] without the borrow: where the frame lies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Step {
    /// The frame is the last `len` bytes consumed from the input.
    Input(usize),
    /// The frame is the first `len` bytes of the framer's buffer.
    Buffer(usize),
    Dropped {
        bytes: usize,
        error: FrameError,
    },
    NeedMore,
}

/// Rejected candidate frames, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BadFrames {
    /// Candidates whose checksum did not match.
    pub checksum: u64,
    /// Candidates announcing a payload longer than the framer accepts.
    pub length: u64,
    /// A frame cut off by the end of the input ([`Framer::finish`]).
    pub truncated: u64,
}

impl BadFrames {
    /// All rejected candidates.
    pub fn total(&self) -> u64 {
        self.checksum + self.length + self.truncated
    }
}

impl Counters {
    /// Total rejected candidates (the same API as the radar framer's counters).
    pub fn frames_bad_total(&self) -> u64 {
        self.frames_bad.total()
    }

    /// `(reason, count)` of the rejected candidates, every reason listed.
    pub fn frames_bad_by_reason(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        let b = &self.frames_bad;
        [
            ("checksum", b.checksum),
            ("length", b.length),
            ("truncated", b.truncated),
        ]
        .into_iter()
    }
}

/// Running totals of a [`Framer`], readable at any time.
///
/// Invariant: `bytes_in == bytes in good frames + bytes_skipped + Framer::buffered()`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Bytes handed to the framer.
    pub bytes_in: u64,
    /// Frames released with a valid checksum.
    pub frames_ok: u64,
    /// Bytes of the good frames.
    pub frame_bytes: u64,
    /// Rejected candidate frames by reason.
    pub frames_bad: BadFrames,
    /// Bytes discarded (noise, rejected candidates, a truncated tail).
    pub bytes_skipped: u64,
    /// Times the framer lost sync and searched for the next preamble.
    pub resyncs: u64,
}

/// Streaming Xbus framer with a fixed buffer of `CAP` bytes (no allocation).
///
/// `CAP` is the largest whole frame the framer can hold; the largest accepted payload is
/// `CAP - 7` ([`frame_capacity`](crate::frame_capacity) computes `CAP` from a payload limit, since
/// stable Rust cannot do that arithmetic on a generic parameter). Use 2048 for live devices
/// (the LLD limit), 8185 for the official library's limit, 65535 for MT Manager `.mtb` logs. A limit
/// below the real frames makes the resync search find false frames inside big ones.
///
/// Feed any chunking (byte by byte up to megabytes) through [`poll`](Self::poll). Frames that lie
/// whole inside the input are returned without copying; only a frame that straddles chunks is
/// copied into the buffer. On a bad checksum or an impossible length the framer gives up ONE byte
/// and searches for the next preamble from there, so a corrupted frame never hides the good frame
/// behind it.
///
/// ```
/// use imu_driver::{Framer, Poll};
/// let mut framer = Framer::<64>::new();
/// let mut input: &[u8] = &[0x00, 0xFA, 0xFF, 0x31, 0x00, 0xD0];
/// assert!(matches!(framer.poll(&mut input), Poll::Dropped { bytes: 1, .. }));
/// match framer.poll(&mut input) {
///     Poll::Frame(f) => assert_eq!(f.mid(), 0x31),
///     other => panic!("{other:?}"),
/// }
/// assert_eq!(framer.poll(&mut input), Poll::NeedMore);
/// ```
#[derive(Debug)]
pub struct Framer<const CAP: usize> {
    buf: Vec<u8, CAP>,
    /// Bytes at the front of `buf` that form the frame released by the previous poll.
    released: usize,
    counters: Counters,
}

impl<const CAP: usize> Default for Framer<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> Framer<CAP> {
    /// An empty framer.
    pub const fn new() -> Self {
        Self {
            buf: Vec::new(),
            released: 0,
            counters: Counters {
                bytes_in: 0,
                frames_ok: 0,
                frame_bytes: 0,
                frames_bad: BadFrames {
                    checksum: 0,
                    length: 0,
                    truncated: 0,
                },
                bytes_skipped: 0,
                resyncs: 0,
            },
        }
    }

    /// The largest payload accepted, in bytes (`CAP - 7`).
    pub const fn max_payload(&self) -> usize {
        CAP.saturating_sub(FRAME_OVERHEAD)
    }

    /// Running totals.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Bytes held for a frame that is not complete yet.
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.released
    }

    /// Consumes from `input` what it needs and reports one outcome.
    ///
    /// Call again while it does not return [`Poll::NeedMore`]; `NeedMore` means `input` is empty
    /// (every byte is either in a frame, counted as dropped, or buffered for the next call). A
    /// returned frame borrows either `input` or the framer's buffer; the input slice itself is
    /// only borrowed for the call, so `while` loops over one chunk work as expected.
    pub fn poll<'a, 'b: 'a>(&'a mut self, input: &mut &'b [u8]) -> Poll<'a> {
        let before: &'b [u8] = input;
        match self.step(input) {
            Step::Input(len) => {
                let end = before.len() - input.len();
                Poll::Frame(XbusFrame::from_scanned(
                    before.get(end - len..end).unwrap_or_default(),
                ))
            }
            Step::Buffer(len) => Poll::Frame(self.buffered_frame(len)),
            Step::Dropped { bytes, error } => Poll::Dropped { bytes, error },
            Step::NeedMore => Poll::NeedMore,
        }
    }

    /// The frame [`Step::Buffer`] announced.
    pub(crate) fn buffered_frame(&self, len: usize) -> XbusFrame<'_> {
        XbusFrame::from_scanned(self.buf.get(..len).unwrap_or_default())
    }

    /// One step of [`poll`](Self::poll), reporting where a frame lies instead of borrowing it.
    pub(crate) fn step(&mut self, input: &mut &[u8]) -> Step {
        if self.released > 0 {
            self.drain_front(self.released);
            self.released = 0;
        }
        let max = self.max_payload();
        loop {
            if self.buf.is_empty() {
                return self.step_input(input, max);
            }
            if self.buf.first() != Some(&PREAMBLE) {
                // Left behind by a frame found inside a rejected candidate.
                let bytes = self
                    .buf
                    .iter()
                    .position(|&b| b == PREAMBLE)
                    .unwrap_or(self.buf.len());
                self.drain_front(bytes);
                self.counters.bytes_skipped += bytes as u64;
                self.counters.resyncs += 1;
                return Step::Dropped {
                    bytes,
                    error: FrameError::NoPreamble,
                };
            }
            let need = match scan(&self.buf, max) {
                Scan::Incomplete { need } if need > CAP => {
                    return self.reject_buffered(FrameError::LengthTooLarge { len: need, max })
                }
                Scan::Incomplete { need } => need,
                Scan::Complete { len } => return self.release(len),
                Scan::Invalid(error) => return self.reject_buffered(error),
            };
            if input.is_empty() {
                return Step::NeedMore;
            }
            let take = need.saturating_sub(self.buf.len()).min(input.len());
            let (head, tail) = input.split_at(take);
            // Cannot fail: `need <= CAP` was checked above.
            let _ = self.buf.extend_from_slice(head);
            self.counters.bytes_in += take as u64;
            *input = tail;
        }
    }

    /// Ends the input: like [`poll`](Self::poll) with no more bytes to come, so an incomplete
    /// candidate is rejected as [`FrameError::Truncated`] (giving up one byte, as for a bad
    /// checksum) and frames that lie inside it are still found. Call until it returns
    /// [`Poll::NeedMore`]; the framer is then empty and can take a new stream.
    pub fn poll_end(&mut self) -> Poll<'_> {
        match self.step_end() {
            Step::Buffer(len) => Poll::Frame(self.buffered_frame(len)),
            Step::Dropped { bytes, error } => Poll::Dropped { bytes, error },
            Step::Input(_) | Step::NeedMore => Poll::NeedMore,
        }
    }

    /// [`poll_end`](Self::poll_end) without the borrow.
    pub(crate) fn step_end(&mut self) -> Step {
        let mut none: &[u8] = &[];
        match self.step(&mut none) {
            Step::NeedMore if !self.buf.is_empty() => {
                let have = self.buf.len();
                let need = match scan(&self.buf, self.max_payload()) {
                    Scan::Incomplete { need } => need,
                    _ => have,
                };
                self.reject_buffered(FrameError::Truncated { have, need })
            }
            other => other,
        }
    }

    /// Ends the input, dropping whatever is buffered: reports a frame cut off by the end of the
    /// input, if any. [`poll_end`](Self::poll_end) also finds frames inside such a tail.
    pub fn finish(&mut self) -> Option<FrameError> {
        if self.released > 0 {
            self.drain_front(self.released);
            self.released = 0;
        }
        if self.buf.is_empty() {
            return None;
        }
        let have = self.buf.len();
        let need = match scan(&self.buf, self.max_payload()) {
            Scan::Incomplete { need } => need,
            _ => have,
        };
        self.counters.frames_bad.truncated += 1;
        self.counters.bytes_skipped += have as u64;
        self.buf.clear();
        Some(FrameError::Truncated { have, need })
    }

    /// Forgets any partial frame (e.g. after reopening a port) without counting it as bad.
    pub fn reset(&mut self) {
        self.counters.bytes_skipped += self.buffered() as u64;
        self.buf.clear();
        self.released = 0;
    }

    fn step_input(&mut self, input: &mut &[u8], max: usize) -> Step {
        let data: &[u8] = input;
        if data.is_empty() {
            return Step::NeedMore;
        }
        match data.iter().position(|&b| b == PREAMBLE) {
            Some(0) => {}
            found => {
                let bytes = found.unwrap_or(data.len());
                *input = data.get(bytes..).unwrap_or_default();
                self.counters.bytes_in += bytes as u64;
                self.counters.bytes_skipped += bytes as u64;
                self.counters.resyncs += 1;
                return Step::Dropped {
                    bytes,
                    error: FrameError::NoPreamble,
                };
            }
        }
        let scanned = match scan(data, max) {
            // Only a framer too small for a header (CAP < 6) gets here.
            Scan::Incomplete { need } if need > CAP => {
                Scan::Invalid(FrameError::LengthTooLarge { len: need, max })
            }
            other => other,
        };
        match scanned {
            Scan::Complete { len } => {
                *input = data.get(len..).unwrap_or_default();
                self.counters.bytes_in += len as u64;
                self.counters.frames_ok += 1;
                self.counters.frame_bytes += len as u64;
                Step::Input(len)
            }
            Scan::Invalid(error) => {
                *input = data.get(1..).unwrap_or_default();
                self.counters.bytes_in += 1;
                self.count_bad(&error);
                self.counters.bytes_skipped += 1;
                self.counters.resyncs += 1;
                Step::Dropped { bytes: 1, error }
            }
            Scan::Incomplete { .. } => {
                // All of `data` is shorter than the candidate, which fits in CAP (checked above).
                self.buf.clear();
                let _ = self.buf.extend_from_slice(data);
                *input = &[];
                self.counters.bytes_in += data.len() as u64;
                Step::NeedMore
            }
        }
    }

    fn release(&mut self, len: usize) -> Step {
        self.released = len;
        self.counters.frames_ok += 1;
        self.counters.frame_bytes += len as u64;
        Step::Buffer(len)
    }

    /// Gives up the first buffered byte and everything up to the next preamble in the buffer.
    fn reject_buffered(&mut self, error: FrameError) -> Step {
        self.count_bad(&error);
        let next = self
            .buf
            .iter()
            .skip(1)
            .position(|&b| b == PREAMBLE)
            .map_or(self.buf.len(), |p| p + 1);
        self.drain_front(next);
        self.counters.bytes_skipped += next as u64;
        self.counters.resyncs += 1;
        Step::Dropped { bytes: next, error }
    }

    fn count_bad(&mut self, error: &FrameError) {
        match error {
            FrameError::BadChecksum { .. } => self.counters.frames_bad.checksum += 1,
            FrameError::LengthTooLarge { .. } => self.counters.frames_bad.length += 1,
            FrameError::Truncated { .. } => self.counters.frames_bad.truncated += 1,
            FrameError::NoPreamble | FrameError::TrailingBytes { .. } => {}
        }
    }

    fn drain_front(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.buf.copy_within(n.., 0);
        self.buf.truncate(self.buf.len() - n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::checksum_sum;

    /// GoToConfigAck FA FF 31 00 D0 and a 3-byte FirmwareRev FA FF 13 03 01 02 03 E4.
    static ACK: [u8; 5] = [0xFA, 0xFF, 0x31, 0x00, 0xD0];
    static FW: [u8; 8] = [0xFA, 0xFF, 0x13, 0x03, 0x01, 0x02, 0x03, 0xE5];

    fn collect<const N: usize>(
        framer: &mut Framer<N>,
        mut input: &[u8],
        out: &mut std::vec::Vec<(u8, std::vec::Vec<u8>)>,
        errs: &mut std::vec::Vec<FrameError>,
    ) {
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => out.push((f.mid(), f.payload().to_vec())),
                Poll::Dropped { error, .. } => errs.push(error),
                Poll::NeedMore => break,
            }
        }
        assert!(input.is_empty());
    }

    type Outcome = (
        std::vec::Vec<(u8, std::vec::Vec<u8>)>,
        std::vec::Vec<FrameError>,
        Counters,
    );

    fn run_chunks(data: &[u8], chunk: usize) -> Outcome {
        let mut framer = Framer::<{ crate::frame_capacity(400) }>::new();
        let (mut out, mut errs) = (std::vec::Vec::new(), std::vec::Vec::new());
        for c in data.chunks(chunk.max(1)) {
            collect(&mut framer, c, &mut out, &mut errs);
        }
        if let Some(e) = framer.finish() {
            errs.push(e);
        }
        (out, errs, *framer.counters())
    }

    #[test]
    fn fw_fixture_is_valid() {
        assert_eq!(checksum_sum(&FW[1..]), 0);
        assert_eq!(checksum_sum(&ACK[1..]), 0);
    }

    #[test]
    fn empty_input_needs_more() {
        let mut framer = Framer::<16>::new();
        let mut input: &[u8] = &[];
        assert_eq!(framer.poll(&mut input), Poll::NeedMore);
        assert_eq!(framer.finish(), None);
        assert_eq!(*framer.counters(), Counters::default());
    }

    #[test]
    fn byte_by_byte_and_all_at_once_agree() {
        let data: std::vec::Vec<u8> = [&ACK[..], &FW[..], &ACK[..]].concat();
        for chunk in [1, 2, 3, 5, 7, data.len()] {
            let (out, errs, c) = run_chunks(&data, chunk);
            assert_eq!(
                out,
                vec![(0x31, vec![]), (0x13, vec![1, 2, 3]), (0x31, vec![])],
                "chunk {chunk}"
            );
            assert!(errs.is_empty());
            assert_eq!((c.frames_ok, c.bytes_in, c.bytes_skipped), (3, 18, 0));
        }
    }

    #[test]
    fn junk_prefix_is_dropped_then_frame_found() {
        let data = [&[0x00, 0x13, 0x37][..], &FW[..]].concat();
        let (out, errs, c) = run_chunks(&data, 64);
        assert_eq!(out, vec![(0x13, vec![1, 2, 3])]);
        assert_eq!(errs, vec![FrameError::NoPreamble]);
        assert_eq!((c.bytes_skipped, c.resyncs), (3, 1));
    }

    #[test]
    fn bad_checksum_then_good_frame_in_any_chunking() {
        let mut bad = FW;
        bad[5] ^= 0x40;
        let data = [&bad[..], &ACK[..]].concat();
        for chunk in 1..=data.len() {
            let (out, errs, c) = run_chunks(&data, chunk);
            assert_eq!(out, vec![(0x31, vec![])], "chunk {chunk}");
            assert_eq!(
                errs.first(),
                Some(&FrameError::BadChecksum {
                    mid: 0x13,
                    expected: 0xA5,
                    got: 0xE5
                })
            );
            assert_eq!(c.frames_bad.checksum, 1);
            assert_eq!(c.bytes_skipped, bad.len() as u64);
            assert_eq!(c.bytes_in, data.len() as u64);
        }
    }

    #[test]
    fn resync_advances_one_byte_so_a_frame_inside_a_bad_one_is_found() {
        // A corrupted LEN claims 10 bytes; the next frame starts inside the claimed range.
        let data = [&[0xFA, 0xFF, 0x36, 0x0A, 0x00][..], &FW[..], &[0u8; 8][..]].concat();
        for chunk in [1, 4, data.len()] {
            let (out, _, c) = run_chunks(&data, chunk);
            assert_eq!(out, vec![(0x13, vec![1, 2, 3])], "chunk {chunk}");
            assert_eq!(c.frames_bad.checksum, 1);
        }
    }

    #[test]
    fn impossible_length_is_rejected_with_evidence() {
        let data = [&[0xFA, 0xFF, 0x36, 0xFF, 0x10, 0x00][..], &ACK[..]].concat();
        let (out, errs, c) = run_chunks(&data, 2);
        assert_eq!(out, vec![(0x31, vec![])]);
        assert_eq!(
            errs[0],
            FrameError::LengthTooLarge {
                len: 0x1000,
                max: 400
            }
        );
        assert_eq!(c.frames_bad.length, 1);
    }

    #[test]
    fn frame_split_across_chunks_is_released_on_its_checksum_byte() {
        let mut framer = Framer::<64>::new();
        let mut a: &[u8] = &FW[..7];
        assert_eq!(framer.poll(&mut a), Poll::NeedMore);
        assert_eq!(framer.buffered(), 7);
        let mut b: &[u8] = &FW[7..];
        match framer.poll(&mut b) {
            Poll::Frame(f) => assert_eq!(f.as_bytes(), &FW[..]),
            other => panic!("{other:?}"),
        }
        assert_eq!(framer.buffered(), 0);
    }

    #[test]
    fn trailing_partial_frame_is_reported_truncated() {
        let data = [&ACK[..], &FW[..6]].concat();
        let (out, errs, c) = run_chunks(&data, 3);
        assert_eq!(out.len(), 1);
        assert_eq!(errs, vec![FrameError::Truncated { have: 6, need: 8 }]);
        assert_eq!((c.frames_bad.truncated, c.bytes_skipped), (1, 6));
    }

    #[test]
    fn counters_balance() {
        let mut bad = FW;
        bad[6] = 0;
        let data = [&[1, 2][..], &FW[..], &bad[..], &ACK[..], &[0xFA, 0xFF][..]].concat();
        for chunk in [1, 3, 100] {
            let (_, _, c) = run_chunks(&data, chunk);
            assert_eq!(c.bytes_in, data.len() as u64);
            assert_eq!(c.frame_bytes + c.bytes_skipped, c.bytes_in);
        }
    }

    fn big_frame(len: usize) -> std::vec::Vec<u8> {
        let payload: std::vec::Vec<u8> = (0..len).map(|i| (i % 251) as u8).collect();
        let mut out = vec![0u8; len + 7];
        let n = crate::encode_frame(&mut out, 0xFF, 0x36, &payload).unwrap();
        out.truncate(n);
        out
    }

    #[test]
    fn extended_frames_of_255_bytes_and_more_in_any_chunking() {
        for len in [254, 255, 256, 400] {
            let frame = big_frame(len);
            assert_eq!(frame.len(), if len < 255 { len + 5 } else { len + 7 });
            let data = [&frame[..], &ACK[..]].concat();
            for chunk in [1, 2, 6, 100, data.len()] {
                let (out, errs, _) = run_chunks(&data, chunk);
                assert!(errs.is_empty(), "len {len} chunk {chunk}: {errs:?}");
                assert_eq!(out.len(), 2);
                assert_eq!(out[0].1.len(), len);
            }
        }
    }

    #[test]
    fn payload_limit_is_the_callers_choice() {
        // An MT Manager .mtb log frame of 15,410 bytes.
        let frame = big_frame(15_410);
        let mut log = Framer::<{ crate::frame_capacity(65_535) }>::new();
        let mut input = &frame[..];
        assert!(matches!(log.poll(&mut input), Poll::Frame(f) if f.payload().len() == 15_410));
        let mut small = Framer::<{ crate::frame_capacity(2048) }>::new();
        let mut input = &frame[..];
        assert_eq!(
            small.poll(&mut input),
            Poll::Dropped {
                bytes: 1,
                error: FrameError::LengthTooLarge {
                    len: 15_410,
                    max: 2048
                }
            }
        );
    }

    #[test]
    fn poll_end_finds_frames_inside_a_truncated_candidate() {
        // A corrupted LEN claims 10 bytes but the input ends after a good frame inside them.
        let data = [&[0xFA, 0xFF, 0x36, 0x0A][..], &FW[..]].concat();
        for chunk in [1, 5, data.len()] {
            let mut framer = Framer::<64>::new();
            let (mut out, mut errs) = (std::vec::Vec::new(), std::vec::Vec::new());
            for c in data.chunks(chunk) {
                collect(&mut framer, c, &mut out, &mut errs);
            }
            assert!(out.is_empty(), "still waiting for the claimed 15 bytes");
            loop {
                match framer.poll_end() {
                    Poll::Frame(f) => out.push((f.mid(), f.payload().to_vec())),
                    Poll::Dropped { error, .. } => errs.push(error),
                    Poll::NeedMore => break,
                }
            }
            assert_eq!(out, vec![(0x13, vec![1, 2, 3])], "chunk {chunk}");
            assert_eq!(errs, vec![FrameError::Truncated { have: 12, need: 15 }]);
            let c = framer.counters();
            assert_eq!(
                (c.frames_bad.truncated, c.bytes_skipped, c.frame_bytes),
                (1, 4, 8)
            );
            assert_eq!(framer.buffered(), 0);
            assert_eq!(framer.finish(), None);
        }
    }

    #[test]
    fn degenerate_capacities_never_loop_or_lose_count() {
        let data = [
            &ACK[..],
            &[0xFA, 0xFF, 0x36, 0xFF, 0x00, 0x01, 0x00, 0xCB][..],
            &FW[..],
        ]
        .concat();
        fn drive<const N: usize>(data: &[u8]) -> Counters {
            let mut framer = Framer::<N>::new();
            for c in data.chunks(3) {
                let mut input = c;
                while framer.poll(&mut input) != Poll::NeedMore {}
            }
            while framer.poll_end() != Poll::NeedMore {}
            *framer.counters()
        }
        for c in [
            drive::<0>(&data),
            drive::<4>(&data),
            drive::<5>(&data),
            drive::<7>(&data),
        ] {
            assert_eq!(c.bytes_in, data.len() as u64);
            assert_eq!(c.frame_bytes + c.bytes_skipped, c.bytes_in);
        }
        assert_eq!(
            drive::<5>(&data).frames_ok,
            1,
            "the empty ack fits in 5 bytes"
        );
        assert_eq!(
            drive::<8>(&data).frames_ok,
            2,
            "and the 1-byte extended frame in 8"
        );
        assert_eq!(drive::<10>(&data).frames_ok, 3);
    }
}
