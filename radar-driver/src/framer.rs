//! The streaming framer: bytes in arbitrary chunks -> checked frames.
//!
//! Rules (each one answers a failure of other parsers):
//! * A frame is released as soon as its totalPacketLen bytes are in; the framer never waits for
//!   the next magic word.
//! * Before that, if the next frame's magic appears inside the claimed length, the frame is
//!   reported [`FrameError::Truncated`] at once and the next frame is framed from its magic.
//! * Any other failure drops only the 8 magic bytes and searches again.
//! * totalPacketLen is bounded by the buffer (and an optional lower maximum).
//! * Every byte is accounted for: `bytes_in == bytes_in_good_frames + bytes_skipped + buffered()`.
//!
//! The buffer is a `heapless::Vec<u8, N>`: no allocation, so the same code runs on a
//! microcontroller. When the buffer is empty and a whole frame sits in the input chunk, the frame
//! is a view into the input (no copy).

use crate::error::{FrameError, FRAME_ERROR_KINDS};
use crate::frame::{
    detect, find_magic_or_prefix, read_u32, Detect, Frame, Layout, LayoutHint, MAGIC,
};

/// Default buffer size for host use \[B\]: larger than any frame that fits a 10 fps UART budget.
pub const DEFAULT_MAX_FRAME: usize = 64 * 1024;

/// What one [`Framer::poll`] call produced.
#[derive(Debug)]
pub enum Poll<'a> {
    /// A checked frame. It borrows the framer: drop it before polling again.
    Frame(Frame<'a>),
    /// A candidate frame was rejected and `skipped` bytes were dropped because of it.
    Dropped {
        /// Why.
        error: FrameError,
        /// Bytes dropped for it (the magic, or the truncated frame's bytes) \[B\].
        skipped: usize,
    },
    /// The input is used up: feed more bytes.
    NeedMore,
}

/// Counters since the framer was created. Nothing is dropped without being counted here.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Bytes consumed from the input \[B\].
    pub bytes_in: u64,
    /// Frames released.
    pub frames_ok: u64,
    /// Bytes in released frames \[B\].
    pub bytes_ok: u64,
    /// Rejected candidates, indexed by [`FrameError::kind_index`].
    pub frames_bad: [u64; FRAME_ERROR_KINDS],
    /// Bytes not part of any released frame: junk between frames, dropped magics, truncated
    /// frames \[B\].
    pub bytes_skipped: u64,
    /// Times the framer had to search for a magic word where a frame should have started
    /// (junk before a frame, or after a rejected candidate).
    pub resyncs: u64,
}

impl Counters {
    /// Total rejected candidates.
    pub fn frames_bad_total(&self) -> u64 {
        self.frames_bad.iter().sum()
    }

    /// `(reason, count)` of the rejected candidates, every reason listed (the same API as the
    /// Xbus framer's counters).
    pub fn frames_bad_by_reason(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        crate::error::FRAME_ERROR_NAMES
            .iter()
            .copied()
            .zip(self.frames_bad.iter().copied())
    }
}

/// What follows a released frame.
enum TailCheck {
    /// A magic word, junk, or nothing suspicious.
    Normal,
    /// Could be the rest of a magic word begun inside the frame: wait for more.
    NeedMore,
    /// The frame ended this many bytes into the next magic word.
    Overlap(usize),
}

/// Result of looking at a window that may start with a frame.
enum Step {
    /// `n` bytes at the start hold no magic (not even a prefix of one).
    Skip(usize),
    /// The window starts with a candidate that needs at least this many bytes.
    NeedMore(usize),
    /// The window starts with a good frame of this layout and length.
    Frame(Layout, usize),
    /// The candidate is bad; drop this many bytes.
    Drop(FrameError, usize),
}

/// Streaming framer with an `N`-byte buffer (the largest frame it can hold).
#[derive(Debug)]
pub struct Framer<const N: usize> {
    buf: heapless::Vec<u8, N>,
    /// Length of the frame handed out from `buf` by the last poll; removed at the next poll.
    release: usize,
    /// Window inspection state (scan offset, layout hint, length bound).
    scan: Scanner,
    last_layout: Option<Layout>,
    /// True when the last thing seen was a good frame (junk after it is a new loss of sync).
    in_sync: bool,
    /// The last 7 bytes of the frame released last, and its length: if what follows it is the
    /// rest of a magic word that began inside it, that frame was short on the wire.
    tail: [u8; 7],
    last_len: usize,
    check_tail: bool,
    counters: Counters,
}

impl<const N: usize> Default for Framer<N> {
    fn default() -> Self {
        Self::new(LayoutHint::Auto)
    }
}

impl<const N: usize> Framer<N> {
    /// A framer for frames of the given layout (or [`LayoutHint::Auto`]).
    pub fn new(hint: LayoutHint) -> Self {
        Framer {
            buf: heapless::Vec::new(),
            release: 0,
            scan: Scanner {
                scanned: 0,
                hint,
                max_len: N,
                magic: memchr::memmem::Finder::new(&MAGIC),
            },
            last_layout: None,
            in_sync: true,
            tail: [0; 7],
            last_len: 0,
            check_tail: false,
            counters: Counters::default(),
        }
    }

    /// Lowers the largest accepted totalPacketLen below the buffer size \[B\] (for example to the
    /// bound a .cfg implies).
    pub fn with_max_len(mut self, max_len: usize) -> Self {
        self.scan.max_len = max_len.min(N);
        self
    }

    /// Counters so far.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Bytes held for an incomplete candidate \[B\].
    pub fn buffered(&self) -> usize {
        self.buf.len() - self.release
    }

    /// Whether the frame released last may still be taken back: its last bytes are the start of
    /// a magic word, and the bytes that will show whether the next frame's magic continues them
    /// ([`FrameError::OverlapsNextFrame`]) have not been polled yet. False for almost every frame
    /// (a frame whose last byte is not one of the magic's first seven bytes is final at once), so
    /// a consumer that must never publish a retracted frame holds only these few frames until
    /// the next poll settles them.
    pub fn may_retract(&self) -> bool {
        self.check_tail && matches!(self.tail_check(&[]), TailCheck::NeedMore)
    }

    /// The layout of the last good frame (auto mode), or the fixed layout.
    pub fn last_layout(&self) -> Option<Layout> {
        match self.scan.hint {
            LayoutHint::Fixed(l) => Some(l),
            LayoutHint::Auto => self.last_layout,
        }
    }

    /// Consumes bytes from `input` (advancing it) until a frame is complete, a candidate is
    /// rejected, or the input is used up.
    ///
    /// ```
    /// use radar_driver::{Framer, Poll, encode::FrameBuilder};
    /// let mut bytes = [0u8; 96];
    /// let n = FrameBuilder::oob(0x0303_0002, 0xA6843, 1).write(&mut bytes).unwrap();
    /// let mut framer: Framer<1024> = Framer::default();
    /// let mut input = &bytes[..n];
    /// match framer.poll(&mut input) {
    ///     Poll::Frame(f) => assert_eq!(f.header().frame_number, 1),
    ///     other => panic!("{other:?}"),
    /// }
    /// assert!(matches!(framer.poll(&mut input), Poll::NeedMore));
    /// ```
    pub fn poll<'r, 'i: 'r>(&'r mut self, input: &mut &'i [u8]) -> Poll<'r> {
        if self.release > 0 {
            let n = self.release;
            self.buf_drain(n);
            self.release = 0;
        }
        loop {
            if self.check_tail {
                let from_buf = !self.buf.is_empty();
                let w: &[u8] = if from_buf { &self.buf } else { input };
                if w.is_empty() {
                    return Poll::NeedMore;
                }
                match self.tail_check(w) {
                    TailCheck::Normal => self.check_tail = false,
                    TailCheck::NeedMore if from_buf => match input.split_first() {
                        Some((&b, rest)) => {
                            let _ = self.buf.push(b);
                            *input = rest;
                            self.consumed(1);
                            continue;
                        }
                        None => return Poll::NeedMore,
                    },
                    TailCheck::NeedMore => {
                        if input.is_empty() {
                            return Poll::NeedMore;
                        }
                        let n = input.len().min(N);
                        let _ = self.buf.extend_from_slice(&input[..n]);
                        *input = &input[n..];
                        self.consumed(n);
                        continue;
                    }
                    TailCheck::Overlap(k) => return self.retract(k),
                }
            }
            if self.buf.is_empty() {
                let window: &'i [u8] = input;
                if window.is_empty() {
                    return Poll::NeedMore;
                }
                match self.scan.step(window) {
                    Step::Skip(n) => {
                        *input = &window[n..];
                        self.consumed(n);
                        self.skip(n);
                    }
                    Step::Frame(layout, len) => {
                        *input = &window[len..];
                        self.consumed(len);
                        self.good(layout, len);
                        self.keep_tail(&window[..len]);
                        return Poll::Frame(Frame::trusted(&window[..len], layout));
                    }
                    Step::Drop(error, n) => {
                        *input = &window[n..];
                        self.consumed(n);
                        return self.dropped(error, n);
                    }
                    Step::NeedMore(_) => {
                        // The whole window is an incomplete candidate shorter than N: keep it.
                        let keep = window.len().min(N);
                        let _ = self.buf.extend_from_slice(&window[..keep]);
                        *input = &window[keep..];
                        self.consumed(keep);
                        if input.is_empty() {
                            return Poll::NeedMore;
                        }
                    }
                }
            } else {
                let step = self.scan.step(&self.buf);
                match step {
                    Step::Skip(n) => {
                        self.buf_drain(n);
                        self.skip(n);
                    }
                    Step::Frame(layout, len) => {
                        self.release = len;
                        self.good(layout, len);
                        let mut t = [0u8; 7];
                        let from = len.saturating_sub(7);
                        t[7 - (len - from)..].copy_from_slice(&self.buf[from..len]);
                        self.tail = t;
                        return Poll::Frame(Frame::trusted(&self.buf[..len], layout));
                    }
                    Step::Drop(error, n) => {
                        self.buf_drain(n);
                        return self.dropped(error, n);
                    }
                    Step::NeedMore(need) => {
                        if input.is_empty() {
                            return Poll::NeedMore;
                        }
                        let want = need.saturating_sub(self.buf.len()).max(1);
                        let room = N - self.buf.len();
                        let take = want.min(input.len()).min(room);
                        if take == 0 {
                            // Cannot happen: need <= max_len <= N. Drop the candidate rather than spin.
                            let n = self.buf.len().min(MAGIC.len());
                            self.buf_drain(n);
                            return self.dropped(
                                FrameError::LengthTooLarge {
                                    len: need as u32,
                                    max: self.scan.max_len as u32,
                                },
                                n,
                            );
                        }
                        let _ = self.buf.extend_from_slice(&input[..take]);
                        *input = &input[take..];
                        self.consumed(take);
                    }
                }
            }
        }
    }

    /// Ends the stream: an incomplete candidate still buffered is reported as truncated (or, if
    /// it is only part of a magic word, counted as skipped). Returns the drop, if any.
    pub fn finish(&mut self) -> Option<(FrameError, usize)> {
        if self.release > 0 {
            let n = self.release;
            self.buf_drain(n);
            self.release = 0;
        }
        let n = self.buf.len();
        if n == 0 {
            return None;
        }
        let error = if n >= 16 {
            let claimed = self.candidate_len().unwrap_or(0);
            FrameError::Truncated {
                claimed,
                got: n as u32,
            }
        } else {
            FrameError::BufferTooShort { need: 16, have: n }
        };
        self.buf.clear();
        self.scan.scanned = 0;
        if let Poll::Dropped { error, skipped } = self.dropped(error, n) {
            return Some((error, skipped));
        }
        None
    }

    fn candidate_len(&self) -> Option<u32> {
        let l = self.last_layout().unwrap_or(Layout::Oob40);
        l.claimed_len(&self.buf)
    }

    fn buf_drain(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.buf.copy_within(n.., 0);
        self.buf.truncate(self.buf.len() - n);
        self.scan.scanned = 0;
    }

    fn consumed(&mut self, n: usize) {
        self.counters.bytes_in += n as u64;
    }

    fn skip(&mut self, n: usize) {
        if n == 0 {
            return;
        }
        self.counters.bytes_skipped += n as u64;
        if self.in_sync {
            self.counters.resyncs += 1;
            self.in_sync = false;
        }
    }

    fn good(&mut self, layout: Layout, len: usize) {
        self.counters.frames_ok += 1;
        self.counters.bytes_ok += len as u64;
        self.last_layout = Some(layout);
        self.in_sync = true;
        self.last_len = len;
        self.check_tail = true;
    }

    fn keep_tail(&mut self, frame: &[u8]) {
        let from = frame.len().saturating_sub(7);
        let n = frame.len() - from;
        self.tail = [0; 7];
        self.tail[7 - n..].copy_from_slice(&frame[from..]);
    }

    /// Whether the bytes after the last released frame continue a magic word begun inside it.
    fn tail_check(&self, w: &[u8]) -> TailCheck {
        if w.first() == Some(&MAGIC[0]) {
            return TailCheck::Normal;
        }
        let tail = &self.tail[7 - self.last_len.min(7)..];
        for k in (1..=tail.len()).rev() {
            if tail[tail.len() - k..] != MAGIC[..k] {
                continue;
            }
            let rest = &MAGIC[k..];
            let n = rest.len().min(w.len());
            if w[..n] == rest[..n] {
                return if n == rest.len() {
                    TailCheck::Overlap(k)
                } else {
                    TailCheck::NeedMore
                };
            }
        }
        TailCheck::Normal
    }

    /// Takes back the last released frame: it ended `k` bytes into the next magic word.
    fn retract<'r>(&mut self, k: usize) -> Poll<'r> {
        self.check_tail = false;
        let len = self.last_len;
        self.counters.frames_ok -= 1;
        self.counters.bytes_ok -= len as u64;
        // The k magic bytes go back in front of what follows, for the next frame.
        let mut restored: heapless::Vec<u8, N> = heapless::Vec::new();
        let _ = restored.extend_from_slice(&MAGIC[..k]);
        let keep = (N - k).min(self.buf.len());
        let _ = restored.extend_from_slice(&self.buf[..keep]);
        self.buf = restored;
        self.scan.scanned = 0;
        self.dropped(
            FrameError::OverlapsNextFrame {
                overlap: k as u32,
                len: len as u32,
            },
            len - k,
        )
    }

    fn dropped<'r>(&mut self, error: FrameError, skipped: usize) -> Poll<'r> {
        self.counters.frames_bad[error.kind_index()] += 1;
        self.counters.bytes_skipped += skipped as u64;
        if self.in_sync {
            self.counters.resyncs += 1;
        }
        self.in_sync = false;
        Poll::Dropped { error, skipped }
    }
}

/// The part of the framer that looks at a window; kept apart from the buffer so the buffer can
/// be looked at in place.
#[derive(Debug)]
struct Scanner {
    /// Offset in the current candidate up to which the inner-magic scan has run.
    scanned: usize,
    hint: LayoutHint,
    max_len: usize,
    /// The magic-word searcher, built once (building one per search costs more than searching
    /// a frame).
    magic: memchr::memmem::Finder<'static>,
}

impl Scanner {
    /// Looks at a window that starts wherever the previous candidate ended.
    fn step(&mut self, w: &[u8]) -> Step {
        match find_magic_or_prefix(w, |h| self.magic.find(h)) {
            None => return Step::Skip(w.len()),
            Some(0) => {}
            Some(i) => return Step::Skip(i),
        }
        if w.len() < MAGIC.len() {
            return Step::NeedMore(MAGIC.len());
        }
        match self.hint {
            LayoutHint::Fixed(l) => self.step_as(w, LayoutHint::Fixed(l)),
            LayoutHint::Auto => {
                // A people-counting header is recognised by its checksum; if the frame then does
                // not hold together as one (a 1-in-65536 coincidence for an out-of-box header),
                // it is read as the out-of-box frame it then is.
                let scanned = self.scanned;
                match self.step_as(w, LayoutHint::Auto) {
                    Step::Drop(e, n)
                        if !matches!(e, FrameError::Truncated { .. }) && w.len() >= 20 =>
                    {
                        self.scanned = scanned;
                        let oob = LayoutHint::Fixed(oob_layout_of(w));
                        match self.step_as(w, oob) {
                            s @ Step::Frame(..) => s,
                            _ => Step::Drop(e, n),
                        }
                    }
                    s => s,
                }
            }
        }
    }

    fn step_as(&mut self, w: &[u8], hint: LayoutHint) -> Step {
        let (layout, claimed) = match detect(w, hint) {
            Detect::NeedMore(n) => return self.need_more_or_truncated(w, n, None),
            Detect::Bad(e) => return Step::Drop(e, MAGIC.len()),
            Detect::Found(l, len) => (l, len),
        };
        let total = claimed as usize;
        if total > self.max_len {
            return Step::Drop(
                FrameError::LengthTooLarge {
                    len: claimed,
                    max: self.max_len as u32,
                },
                MAGIC.len(),
            );
        }
        if w.len() < total {
            return self.need_more_or_truncated(w, total, Some(claimed));
        }
        if let Some(k) = self.inner_magic(&w[..total]) {
            self.scanned = 0;
            return Step::Drop(
                FrameError::Truncated {
                    claimed,
                    got: k as u32,
                },
                k,
            );
        }
        self.scanned = 0;
        match Frame::new_checked(&w[..total], layout) {
            Ok(_) => Step::Frame(layout, total),
            Err(e) => Step::Drop(e, MAGIC.len()),
        }
    }

    fn need_more_or_truncated(&mut self, w: &[u8], need: usize, claimed: Option<u32>) -> Step {
        if let Some(k) = self.inner_magic(w) {
            self.scanned = 0;
            let claimed = claimed.unwrap_or(need as u32);
            return Step::Drop(
                FrameError::Truncated {
                    claimed,
                    got: k as u32,
                },
                k,
            );
        }
        Step::NeedMore(need)
    }

    /// Offset of a magic word after the candidate's own, scanning only bytes not scanned before.
    fn inner_magic(&mut self, w: &[u8]) -> Option<usize> {
        let from = self.scanned.saturating_sub(MAGIC.len() - 1).max(1);
        let found = w
            .get(from..)
            .and_then(|h| self.magic.find(h))
            .map(|k| k + from);
        self.scanned = w.len();
        found
    }
}

/// The out-of-box layout a candidate header would have.
fn oob_layout_of(w: &[u8]) -> Layout {
    let v = read_u32(w, 8..12).unwrap_or(0);
    let p = read_u32(w, 16..20).unwrap_or(0);
    Layout::oob_for(v, p)
}
