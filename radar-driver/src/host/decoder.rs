//! The one streaming bytes -> point clouds decoder: framer, plausibility checker, sensor clock
//! and retraction, fed in chunks as they arrive. Sessions run it in batch over a recorded stream,
//! the runtime's reader live over a port; both publish the same frames from the same bytes,
//! however the bytes are chunked.
//!
//! A frame is published once it is final: the framer released it, the plausibility
//! [`Checker`] accepted it, and the framer can no longer take it back. The framer takes a frame
//! back ([`FrameError::OverlapsNextFrame`]) when it lost bytes on the wire and so ended inside the
//! next frame's magic word; that can only be seen in the bytes after it. Only a frame whose last
//! bytes are the start of a magic word can be taken back ([`Framer::may_retract`]); such a frame
//! is held until the next bytes settle it (a frame period of latency, live), every other frame is
//! published as soon as its last byte is in.
//!
//! Nothing is dropped silently: [`Decoder::report`] counts every byte and frame the framer or
//! the checker rejected, by reason.
//!
//! ```
//! use radar_driver::encode::FrameBuilder;
//! use radar_driver::host::decoder::{Decoder, DecoderConfig};
//! let mut bytes = Vec::new();
//! for n in 1..=3 {
//!     bytes.extend(FrameBuilder::oob(0x0303_0002, 0xA6843, n).points(&[[1.0, 2.0, 0.0, 0.5]]).to_vec());
//! }
//! let mut dec = Decoder::new(DecoderConfig::default());
//! let mut numbers = Vec::new();
//! for (i, chunk) in bytes.chunks(50).enumerate() {
//!     dec.feed(chunk, i, |f| numbers.push((f.frame_number, f.cloud.points.len())));
//! }
//! dec.finish(|f| numbers.push((f.frame_number, f.cloud.points.len())));
//! assert_eq!(numbers, [(1, 1), (2, 1), (3, 1)]);
//! assert_eq!(dec.report().published, 3);
//! ```

use super::cloud::PointCloud;
use crate::cfg::Derived;
use crate::clock::{cpu_clock_hz, CycleUnwrapper};
use crate::error::FrameError;
use crate::framer::{Counters, Framer, Poll, DEFAULT_MAX_FRAME};
use crate::plausible::{CheckCounters, Checker, Limits};
use alloc::boxed::Box;

/// What the decoder needs from the radar's `.cfg` (all optional: without a `.cfg` the defaults
/// hold).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DecoderConfig {
    /// Doppler bin size, to scale SDK 1/2 Doppler indices \[m/s\].
    pub velocity_resolution_mps: Option<f32>,
    /// Frame period, to unwrap the cycle counter \[s\].
    pub frame_period_s: Option<f64>,
    /// What the plausibility checker holds frames to.
    pub limits: Limits,
}

impl DecoderConfig {
    /// The settings a parsed `.cfg` implies ([`crate::cfg::RadarConfig::derive`]); the defaults
    /// without one.
    pub fn from_derived(derived: Option<&Derived>) -> Self {
        derived.map_or_else(DecoderConfig::default, |d| DecoderConfig {
            velocity_resolution_mps: Some(d.velocity_resolution_mps as f32),
            frame_period_s: Some(d.frame_period_ms / 1e3),
            limits: Limits::from_derived(d),
        })
    }
}

/// One published frame. `stamp` is what the caller passed with the chunk that completed the
/// frame (a host time, a chunk index...).
#[derive(Debug, Clone, Copy)]
pub struct Decoded<'a, S> {
    /// The caller's stamp of the chunk that held the frame's last byte.
    pub stamp: S,
    /// Sensor time from the unwrapped cycle counter \[s since the first frame\], when the header
    /// has one.
    pub sensor_s: Option<f64>,
    /// Frame counter.
    pub frame_number: u32,
    /// Frame length on the wire \[B\].
    pub bytes: usize,
    /// Points, side info, targets.
    pub cloud: &'a PointCloud,
}

/// What decoding found so far. Every frame the framer released is either published, rejected as
/// implausible, retracted, or still held.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecodeReport {
    /// Framer counters (bytes in, skipped, frames rejected by reason).
    pub framer: Counters,
    /// Plausibility verdicts (rejections by reason, re-anchors, retractions).
    pub plausibility: CheckCounters,
    /// Frames published.
    pub published: u64,
    /// Frames held back until the bytes after them arrived (their last bytes began a magic
    /// word); most were published a poll later, the rest retracted.
    pub held: u64,
}

/// A frame decoded and accepted but not yet final.
#[derive(Debug)]
struct Slot<S> {
    stamp: Option<S>,
    sensor_s: Option<f64>,
    frame_number: u32,
    bytes: usize,
    /// The sensor clock before this frame: a retraction takes the clock back with the frame.
    clock_before: Option<CycleUnwrapper>,
}

/// The streaming radar decoder (see the [module docs](self)). Buffers are reused: once they have
/// grown to the largest frame, decoding allocates nothing.
pub struct Decoder<S: Copy = ()> {
    framer: Box<Framer<DEFAULT_MAX_FRAME>>,
    checker: Checker,
    clock: Option<CycleUnwrapper>,
    cfg: DecoderConfig,
    cloud: PointCloud,
    pending: Slot<S>,
    published: u64,
    held: u64,
}

impl<S: Copy> core::fmt::Debug for Decoder<S> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Decoder")
            .field("cfg", &self.cfg)
            .field("published", &self.published)
            .field("pending", &self.pending.stamp.is_some())
            .finish()
    }
}

impl<S: Copy> Decoder<S> {
    /// A decoder with the given settings.
    pub fn new(cfg: DecoderConfig) -> Self {
        let mut cloud = PointCloud::default();
        cloud.points.reserve(1024);
        cloud.tlv_types.reserve(16);
        Decoder {
            framer: Box::default(),
            checker: Checker::new(cfg.limits),
            clock: None,
            cfg,
            cloud,
            pending: Slot {
                stamp: None,
                sensor_s: None,
                frame_number: 0,
                bytes: 0,
                clock_before: None,
            },
            published: 0,
            held: 0,
        }
    }

    /// The settings in force.
    pub fn config(&self) -> &DecoderConfig {
        &self.cfg
    }

    /// Counters so far.
    pub fn report(&self) -> DecodeReport {
        DecodeReport {
            framer: *self.framer.counters(),
            plausibility: *self.checker.counters(),
            published: self.published,
            held: self.held,
        }
    }

    /// Framer counters so far.
    pub fn framer_counters(&self) -> &Counters {
        self.framer.counters()
    }

    /// Plausibility verdicts so far.
    pub fn plausibility(&self) -> &CheckCounters {
        self.checker.counters()
    }

    /// True while a frame is held for the bytes after it.
    pub fn holding(&self) -> bool {
        self.pending.stamp.is_some()
    }

    /// Feeds the next chunk of the stream, received at `stamp`; `publish` gets each frame as it
    /// becomes final, in stream order.
    pub fn feed(&mut self, mut input: &[u8], stamp: S, mut publish: impl FnMut(&Decoded<'_, S>)) {
        loop {
            let polled = self.framer.poll(&mut input);
            let done = matches!(polled, Poll::NeedMore);
            match polled {
                Poll::Frame(f) => {
                    // The framer settled a held frame before it released this one: it is final.
                    flush(
                        &mut self.pending,
                        &self.cloud,
                        &mut self.published,
                        &mut publish,
                    );
                    if !self.checker.check(&f).is_accept() {
                        continue;
                    }
                    let h = *f.header();
                    let clock_before = self.clock;
                    let period = self.cfg.frame_period_s;
                    let sensor_s = h.time_cpu_cycles.and_then(|c| {
                        self.clock
                            .get_or_insert_with(|| CycleUnwrapper::new(cpu_clock_hz(&h), period))
                            .push(h.frame_number, c)
                            .seconds
                    });
                    self.cloud.decode_into(&f, self.cfg.velocity_resolution_mps);
                    self.pending = Slot {
                        stamp: Some(stamp),
                        sensor_s,
                        frame_number: h.frame_number,
                        bytes: f.as_bytes().len(),
                        clock_before,
                    };
                    if self.framer.may_retract() {
                        self.held += 1;
                    }
                }
                // The frame released last lost bytes on the wire: take it back, and with it its
                // effect on the continuity anchor and the clock. Only a held frame can be here
                // (a published one could not be retracted any more).
                Poll::Dropped {
                    error: FrameError::OverlapsNextFrame { .. },
                    ..
                } => {
                    self.checker.retract();
                    if self.pending.stamp.take().is_some() {
                        self.clock = self.pending.clock_before;
                    }
                }
                Poll::Dropped { .. } | Poll::NeedMore => {}
            }
            if !self.framer.may_retract() {
                self.flush(&mut publish);
            }
            if done {
                break;
            }
        }
    }

    /// Ends the stream (or a stretch of it, before a port is reopened): a held frame is published
    /// (no bytes will settle it), a partial frame is counted as dropped.
    pub fn finish(&mut self, mut publish: impl FnMut(&Decoded<'_, S>)) {
        self.flush(&mut publish);
        self.framer.finish();
    }

    fn flush(&mut self, publish: &mut impl FnMut(&Decoded<'_, S>)) {
        flush(&mut self.pending, &self.cloud, &mut self.published, publish);
    }
}

/// Publishes the pending frame, if any (the fields apart, so the framer can stay borrowed).
fn flush<S: Copy>(
    pending: &mut Slot<S>,
    cloud: &PointCloud,
    published: &mut u64,
    publish: &mut impl FnMut(&Decoded<'_, S>),
) {
    let Some(stamp) = pending.stamp.take() else {
        return;
    };
    *published += 1;
    publish(&Decoded {
        stamp,
        sensor_s: pending.sensor_s,
        frame_number: pending.frame_number,
        bytes: pending.bytes,
        cloud,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode::FrameBuilder;

    /// Frames 1..=12: 4 with a corrupted number, 7 with a NaN point, 9 (number 20, in the
    /// window) one byte short and ending in a magic byte so the framer retracts it.
    fn stream() -> (Vec<u8>, usize) {
        let pts = [[1.0, 2.0, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
        let nan = [[1.0, f32::NAN, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
        let mut bytes = Vec::new();
        let mut end_of_9 = 0;
        for n in 1..=12u32 {
            let number = match n {
                4 => 1004,
                9 => 20,
                _ => n,
            };
            let p: &[[f32; 4]] = if n == 7 { &nan } else { &pts };
            let mut f = FrameBuilder::oob(0x0303_0002, 0xA6843, number)
                .points(p)
                .to_vec();
            if n == 9 {
                f.pop();
                end_of_9 = bytes.len() + f.len();
            }
            bytes.extend(f);
        }
        (bytes, end_of_9)
    }

    fn decode(bytes: &[u8], chunk: usize) -> (Vec<(u32, usize)>, DecodeReport) {
        let mut dec = Decoder::new(DecoderConfig::default());
        let mut seen = Vec::new();
        for (i, c) in bytes.chunks(chunk).enumerate() {
            dec.feed(c, i, |f| seen.push((f.frame_number, f.stamp)));
        }
        dec.finish(|f| seen.push((f.frame_number, f.stamp)));
        (seen, dec.report())
    }

    #[test]
    fn a_retracted_frame_is_never_published_however_the_bytes_are_chunked() {
        let (bytes, _) = stream();
        for chunk in [1usize, 7, 100, 4096] {
            let (seen, rep) = decode(&bytes, chunk);
            let numbers: Vec<u32> = seen.iter().map(|s| s.0).collect();
            assert_eq!(numbers, [1, 2, 3, 5, 6, 8, 10, 11, 12], "chunks of {chunk}");
            let p = rep.plausibility;
            assert_eq!(p.rejected_total(), 2);
            assert_eq!(p.rejected[0], 1, "frame_number");
            assert_eq!(p.rejected[7], 1, "non_finite");
            assert_eq!((p.retracted, rep.published, rep.held), (1, 9, 1));
            assert_eq!(rep.framer.frames_ok, p.accepted + p.rejected_total());
        }
    }

    #[test]
    fn frames_are_published_with_the_stamp_of_the_chunk_of_their_last_byte() {
        let (bytes, _) = stream();
        let one = FrameBuilder::oob(0x0303_0002, 0xA6843, 1)
            .points(&[[1.0, 2.0, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]])
            .to_vec()
            .len();
        let (seen, _) = decode(&bytes, 7);
        // Frame 1 ends at byte `one`: in chunk (one - 1) / 7. No wait for the next frame.
        assert_eq!(seen[0], (1, (one - 1) / 7));
    }

    #[test]
    fn a_held_frame_waits_only_for_the_bytes_that_settle_it() {
        let (bytes, end_of_9) = stream();
        // Feed up to the end of the short frame 9: it is released, looks like it might end in
        // the next magic, and is held; the next byte settles it (a magic: it is retracted).
        let mut dec: Decoder<()> = Decoder::new(DecoderConfig::default());
        let mut seen = Vec::new();
        dec.feed(&bytes[..end_of_9 + 1], (), |f| seen.push(f.frame_number));
        assert_eq!(seen.last(), Some(&8));
        dec.feed(&bytes[end_of_9 + 1..], (), |f| seen.push(f.frame_number));
        assert_eq!(seen, [1, 2, 3, 5, 6, 8, 10, 11, 12]);
        // At the end of a stream, a held frame is published: nothing will take it back.
        let mut dec: Decoder<()> = Decoder::new(DecoderConfig::default());
        let mut last = Vec::new();
        dec.feed(&bytes[..end_of_9 + 1], (), |f| last.push(f.frame_number));
        assert!(dec.holding());
        dec.finish(|f| last.push(f.frame_number));
        assert_eq!(last.last(), Some(&20));
    }
}
