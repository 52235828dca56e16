//! Sensor readers: bytes from a port (any [`std::io::Read`]) through the drivers' framers into
//! time-stamped items (sensor clock and host time of the read that completed the message). A port
//! that fails or disappears is reopened with backoff; readers never block on later stages.

use crate::queue::{DropOldest, Pool};
use imu_driver::{Checker, LogFramer, Message, TimeWrap};
use radar_driver::clock::{cpu_clock_hz, CycleUnwrapper};
use radar_driver::host::{Point, PointCloud};
use radar_driver::plausible::{CheckCounters, Checker as RadarChecker, Limits, IMPLAUSIBLE_KINDS};
use radar_driver::{FrameError, Framer, Poll, DEFAULT_MAX_FRAME};
use std::io::{self, Read};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Points a recycled frame holds without growing (larger frames grow it once).
pub const POINTS_RESERVED: usize = 512;

/// A decoded radar frame on its way through the pipeline (boxes are recycled through a [`Pool`]).
#[derive(Debug, Clone)]
pub struct RadarItem {
    /// Host time of the read that completed the frame \[s since the pipeline epoch\].
    pub host_s: f64,
    /// Host time of that read \[ns since the pipeline epoch\] (latency reference).
    pub read_ns: u64,
    /// Unwrapped sensor time \[s\], when the header has a cycle counter.
    pub sensor_s: Option<f64>,
    /// Frame counter.
    pub frame_number: u32,
    /// Frame length on the wire \[B\].
    pub bytes: usize,
    /// Processing time the frame reports (stats TLV) \[s\].
    pub processing_s: f64,
    /// Measurement time on the common clock \[s\], once known (offline feeders set it).
    pub t: Option<f64>,
    /// Points.
    pub points: Vec<Point>,
}

impl Default for RadarItem {
    fn default() -> Self {
        RadarItem {
            host_s: 0.0,
            read_ns: 0,
            sensor_s: None,
            frame_number: 0,
            bytes: 0,
            processing_s: 0.0,
            t: None,
            points: Vec::with_capacity(POINTS_RESERVED),
        }
    }
}

/// A decoded IMU sample.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ImuItem {
    /// Host time of the read that completed the message \[s since the pipeline epoch\].
    pub host_s: f64,
    /// Host time of that read \[ns since the pipeline epoch\].
    pub read_ns: u64,
    /// Unwrapped SampleTimeFine \[s\].
    pub sensor_s: f64,
    /// Specific force \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn \[rad/s\].
    pub gyro: [f64; 3],
    /// Message length on the wire \[B\].
    pub bytes: usize,
    /// Time on the common clock \[s\], once known (offline feeders set it).
    pub t: Option<f64>,
}

/// Radar framer, plausibility checker and decoder, reusing its buffers.
///
/// Each released frame goes through the [`RadarChecker`] before it is decoded and emitted (as in the
/// offline [`milliego_session::streams::radar_frames`], with the same limits the same frames are
/// rejected). A frame the framer retracts after it was emitted
/// ([`FrameError::OverlapsNextFrame`]) cannot be taken back from the pipeline here (that would
/// need the next frame's first bytes: a frame of latency), but the checker and the sensor clock
/// forget it, so the frames after it are judged and stamped as offline.
pub struct RadarDecoder {
    framer: Box<Framer<DEFAULT_MAX_FRAME>>,
    checker: RadarChecker,
    clock: Option<CycleUnwrapper>,
    clock_before: Option<CycleUnwrapper>,
    period_s: Option<f64>,
    vres: Option<f32>,
    cloud: PointCloud,
    /// Frames decoded (plausible ones: rejected frames are in [`RadarDecoder::plausibility`]).
    pub frames: u64,
    /// Emitted frames the framer retracted afterwards (they lost bytes on the wire).
    pub retracted_after_emit: u64,
    last_emitted: bool,
}

impl std::fmt::Debug for RadarDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RadarDecoder")
            .field("frames", &self.frames)
            .finish()
    }
}

impl RadarDecoder {
    /// A decoder; `vres` scales SDK 1/2 Doppler indices \[m/s\], `period_s` helps unwrap the
    /// cycle counter \[s\] (both from the `.cfg`).
    pub fn new(vres: Option<f32>, period_s: Option<f64>) -> Self {
        let mut cloud = PointCloud::default();
        cloud.points.reserve(1024);
        cloud.tlv_types.reserve(16);
        RadarDecoder {
            framer: Box::default(),
            checker: RadarChecker::default(),
            clock: None,
            clock_before: None,
            period_s,
            vres,
            cloud,
            frames: 0,
            retracted_after_emit: 0,
            last_emitted: false,
        }
    }

    /// Holds frames to `limits` (from the `.cfg`: [`Limits::from_derived`]) instead of the
    /// defaults.
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.checker = RadarChecker::new(limits);
        self
    }

    /// Bad frames and skipped bytes so far.
    pub fn counters(&self) -> &radar_driver::Counters {
        self.framer.counters()
    }

    /// Plausibility verdicts so far (rejections by reason, re-anchors, retractions).
    pub fn plausibility(&self) -> &CheckCounters {
        self.checker.counters()
    }

    /// Copies the plausibility counters into the reader's shared counters.
    pub fn publish(&self, stats: &ReaderStats) {
        let c = self.checker.counters();
        for (a, v) in stats.implausible.iter().zip(c.rejected) {
            a.store(v, Ordering::Relaxed);
        }
        stats.reanchored.store(c.reanchored, Ordering::Relaxed);
        stats
            .retracted_after_emit
            .store(self.retracted_after_emit, Ordering::Relaxed);
    }

    /// Feeds bytes read at `host_s` / `read_ns`; `emit` gets each frame, filled into `item`
    /// (which it must hand on or give back).
    pub fn feed(
        &mut self,
        mut input: &[u8],
        host_s: f64,
        read_ns: u64,
        mut emit: impl FnMut(&mut dyn FnMut(&mut RadarItem)),
    ) {
        loop {
            match self.framer.poll(&mut input) {
                Poll::Frame(f) => {
                    self.last_emitted = false;
                    if !self.checker.check(&f).is_accept() {
                        continue;
                    }
                    let h = *f.header();
                    let period = self.period_s;
                    self.clock_before = self.clock;
                    let sensor_s = h.time_cpu_cycles.and_then(|c| {
                        self.clock
                            .get_or_insert_with(|| CycleUnwrapper::new(cpu_clock_hz(&h), period))
                            .push(h.frame_number, c)
                            .seconds
                    });
                    self.cloud.decode_into(&f, self.vres);
                    self.frames += 1;
                    let bytes = f.as_bytes().len();
                    let cloud = &self.cloud;
                    emit(&mut |it: &mut RadarItem| {
                        it.host_s = host_s;
                        it.read_ns = read_ns;
                        it.sensor_s = sensor_s;
                        it.frame_number = h.frame_number;
                        it.bytes = bytes;
                        it.processing_s = cloud
                            .stats
                            .map_or(0.0, |s| f64::from(s.inter_frame_processing_time_us) * 1e-6);
                        it.t = None;
                        it.points.clear();
                        it.points.extend_from_slice(&cloud.points);
                    });
                    self.last_emitted = true;
                }
                Poll::Dropped {
                    error: FrameError::OverlapsNextFrame { .. },
                    ..
                } => {
                    self.checker.retract();
                    if self.last_emitted {
                        self.clock = self.clock_before;
                        self.retracted_after_emit += 1;
                    }
                    self.last_emitted = false;
                }
                Poll::Dropped { .. } => self.last_emitted = false,
                Poll::NeedMore => break,
            }
        }
    }

    /// Forgets a partial frame (after the port was reopened).
    pub fn resync(&mut self) {
        self.framer.finish();
    }
}

/// Xbus framer and MTData2 decoder.
pub struct ImuDecoder {
    framer: Box<LogFramer>,
    checker: Checker,
    /// Samples decoded.
    pub samples: u64,
    /// Messages without acceleration, rate of turn and SampleTimeFine.
    pub not_samples: u64,
}

impl std::fmt::Debug for ImuDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImuDecoder")
            .field("samples", &self.samples)
            .finish()
    }
}

impl ImuDecoder {
    /// A decoder for a device whose SampleTimeFine wraps as `wrap`.
    pub fn new(wrap: TimeWrap) -> Self {
        ImuDecoder {
            framer: Box::new(LogFramer::new()),
            checker: Checker::new(wrap),
            samples: 0,
            not_samples: 0,
        }
    }

    /// Feeds bytes; `emit` gets each sample.
    pub fn feed(
        &mut self,
        mut input: &[u8],
        host_s: f64,
        read_ns: u64,
        mut emit: impl FnMut(ImuItem),
    ) {
        loop {
            match self.framer.poll(&mut input) {
                imu_driver::Poll::Frame(f) => {
                    let Ok(Message::MtData2(d)) = Message::decode(&f) else {
                        self.not_samples += 1;
                        continue;
                    };
                    let s = d.sample();
                    let checked = self.checker.check(&s);
                    match (s.acceleration, s.rate_of_turn, checked.time_ticks) {
                        (Some(accel), Some(gyro), Some(ticks)) => {
                            self.samples += 1;
                            emit(ImuItem {
                                host_s,
                                read_ns,
                                sensor_s: ticks as f64 * 1e-4,
                                accel,
                                gyro,
                                bytes: f.as_bytes().len(),
                                t: None,
                            })
                        }
                        _ => self.not_samples += 1,
                    }
                }
                imu_driver::Poll::Dropped { .. } => {}
                imu_driver::Poll::NeedMore => break,
            }
        }
    }

    /// Forgets a partial message (after the port was reopened).
    pub fn resync(&mut self) {
        self.framer.finish();
    }
}

/// Something a reader can (re)open.
pub trait Source: Send {
    /// Name for logs.
    fn name(&self) -> String;
    /// Opens the port.
    fn open(&mut self) -> io::Result<Box<dyn Read + Send>>;
}

/// A serial port (or pseudo-terminal) by path.
#[derive(Debug, Clone)]
pub struct SerialSource {
    /// Device path.
    pub path: String,
    /// Baud rate \[bit/s\].
    pub baud: u32,
}

impl Source for SerialSource {
    fn name(&self) -> String {
        self.path.clone()
    }
    fn open(&mut self) -> io::Result<Box<dyn Read + Send>> {
        let p = serialport::new(&self.path, self.baud)
            .timeout(Duration::from_millis(20))
            .open()
            .map_err(io::Error::from)?;
        // Bytes that waited in the driver before we opened carry no usable host time: a
        // backlog read in one burst would look like a second of data arriving at once.
        let _ = p.clear(serialport::ClearBuffer::Input);
        Ok(Box::new(p))
    }
}

/// Counters a reader shares with the rest of the pipeline.
#[derive(Debug, Default)]
pub struct ReaderStats {
    /// Bytes read \[B\].
    pub bytes: AtomicU64,
    /// Reads that returned data.
    pub reads: AtomicU64,
    /// Times the port was reopened.
    pub reopens: AtomicU64,
    /// True while the port is open.
    pub connected: AtomicBool,
    /// Radar frames rejected as implausible, by [`radar_driver::plausible::Implausible::kind_index`].
    pub implausible: [AtomicU64; IMPLAUSIBLE_KINDS],
    /// Radar frames that confirmed a sensor restart or frame-number jump.
    pub reanchored: AtomicU64,
    /// Radar frames emitted and then retracted by the framer (they lost bytes on the wire).
    pub retracted_after_emit: AtomicU64,
}

/// What a reader thread needs.
pub struct ReaderCtx {
    /// Pipeline epoch (host times are measured from it).
    pub epoch: Instant,
    /// Set to stop.
    pub stop: Arc<AtomicBool>,
    /// Counters.
    pub stats: Arc<ReaderStats>,
    /// First backoff after a failure; doubles up to `max_backoff`.
    pub backoff: Duration,
    /// Longest backoff.
    pub max_backoff: Duration,
}

impl std::fmt::Debug for ReaderCtx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReaderCtx").finish()
    }
}

/// Reads `port` (already open, or None to open it first) until `stop`, handing each chunk to
/// `feed(bytes, host_s, read_ns)`; reopens the port with backoff when it fails or ends.
pub fn read_loop(
    src: &mut dyn Source,
    mut port: Option<Box<dyn Read + Send>>,
    ctx: &ReaderCtx,
    mut feed: impl FnMut(&[u8], f64, u64, bool),
) {
    let mut buf = vec![0u8; 4096];
    let mut backoff = ctx.backoff;
    let mut reopened = false;
    while !ctx.stop.load(Ordering::Relaxed) {
        let Some(p) = port.as_mut() else {
            match src.open() {
                Ok(p) => {
                    tracing::warn!(port = %src.name(), "port reopened");
                    ctx.stats.reopens.fetch_add(1, Ordering::Relaxed);
                    ctx.stats.connected.store(true, Ordering::Relaxed);
                    port = Some(p);
                    backoff = ctx.backoff;
                    reopened = true;
                }
                Err(e) => {
                    tracing::debug!(port = %src.name(), error = %e, "reopen failed");
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(ctx.max_backoff);
                }
            }
            continue;
        };
        match p.read(&mut buf) {
            Ok(0) => {
                // End of file or a hung-up pty: reopen.
                tracing::warn!(port = %src.name(), "port closed; reopening");
                port = None;
                ctx.stats.connected.store(false, Ordering::Relaxed);
                std::thread::sleep(backoff);
            }
            Ok(n) => {
                let now = ctx.epoch.elapsed();
                ctx.stats.bytes.fetch_add(n as u64, Ordering::Relaxed);
                ctx.stats.reads.fetch_add(1, Ordering::Relaxed);
                feed(
                    &buf[..n],
                    now.as_secs_f64(),
                    now.as_nanos() as u64,
                    reopened,
                );
                reopened = false;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                        | io::ErrorKind::WouldBlock
                ) => {}
            Err(e) => {
                tracing::warn!(port = %src.name(), error = %e, "port failed; reopening");
                port = None;
                ctx.stats.connected.store(false, Ordering::Relaxed);
                std::thread::sleep(backoff);
            }
        }
    }
}

/// Pushes a radar frame from the decoder into the queue, recycling boxes through `pool`.
pub fn radar_sink<'a>(
    q: &'a DropOldest<Box<RadarItem>>,
    pool: &'a Pool<RadarItem>,
) -> impl FnMut(&mut dyn FnMut(&mut RadarItem)) + 'a {
    move |fill| {
        let mut it = pool.take();
        fill(&mut it);
        if let Some(old) = q.push(it) {
            pool.give(old);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use radar_driver::encode::FrameBuilder;

    /// Frames 1..=12: 4 with a corrupted number, 7 with a NaN point, 9 (number 20, in the
    /// window) one byte short so the framer retracts it after release.
    fn stream() -> Vec<u8> {
        let pts = [[1.0, 2.0, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
        let nan = [[1.0, f32::NAN, 0.0, 0.5], [0.5, 3.0, 0.1, -0.2]];
        let mut bytes = Vec::new();
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
            }
            bytes.extend(f);
        }
        bytes
    }

    #[test]
    fn the_live_decoder_rejects_counts_and_forgets_retracted_frames() {
        let bytes = stream();
        for chunk in [1usize, 7, 100, 4096] {
            let mut dec = RadarDecoder::new(None, None).with_limits(Limits::default());
            let mut seen = Vec::new();
            for c in bytes.chunks(chunk) {
                dec.feed(c, 0.0, 0, |fill| {
                    let mut it = RadarItem::default();
                    fill(&mut it);
                    seen.push(it.frame_number);
                });
            }
            // 20 was emitted before the framer could know it was short; 10 still follows 8.
            assert_eq!(
                seen,
                [1, 2, 3, 5, 6, 8, 20, 10, 11, 12],
                "chunks of {chunk}"
            );
            let p = dec.plausibility();
            assert_eq!(p.rejected_total(), 2);
            assert_eq!(p.rejected[0], 1, "frame_number");
            assert_eq!(p.rejected[7], 1, "non_finite");
            assert_eq!(
                (p.retracted, dec.retracted_after_emit, dec.frames),
                (1, 1, 10)
            );
            let stats = ReaderStats::default();
            dec.publish(&stats);
            assert_eq!(stats.implausible[0].load(Ordering::Relaxed), 1);
            assert_eq!(stats.retracted_after_emit.load(Ordering::Relaxed), 1);
        }
    }
}
