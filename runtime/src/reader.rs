//! Sensor readers: bytes from a port (any [`std::io::Read`]) through the drivers' framers into
//! time-stamped items (sensor clock and host time of the read that completed the message). A port
//! that fails or disappears is reopened with backoff; readers never block on later stages.

use crate::queue::{DropOldest, Pool};
use imu_driver::host::ImuDecodeReport;
use imu_driver::TimeWrap;
use radar_driver::host::{DecodeReport, Decoded, Decoder, DecoderConfig, Point, PointCloud};
use radar_driver::plausible::{CheckCounters, IMPLAUSIBLE_KINDS};
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
    /// Offline feeders: the frame's place in the feed, a time on the common clock \[s\] (see
    /// [`crate::sync::FeedOrder`]); `None` for live reads.
    pub fed_s: Option<f64>,
    /// Points.
    pub points: Vec<Point>,
    /// SNR per point \[dB\], when the frame carries side info (else empty).
    pub snr_db: Vec<f32>,
}

impl RadarItem {
    /// Sets what the frame itself says (sensor time, number, length, processing time, points),
    /// reusing the point buffer; host times and `t` are the caller's.
    pub fn set_frame(
        &mut self,
        sensor_s: Option<f64>,
        frame_number: u32,
        bytes: usize,
        cloud: &PointCloud,
    ) {
        self.sensor_s = sensor_s;
        self.frame_number = frame_number;
        self.bytes = bytes;
        self.processing_s = cloud
            .stats
            .map_or(0.0, |s| f64::from(s.inter_frame_processing_time_us) * 1e-6);
        self.points.clear();
        self.points.extend_from_slice(&cloud.points);
        self.snr_db.clear();
        if let Some(snr) = &cloud.snr_db {
            self.snr_db.extend_from_slice(snr);
        }
    }
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
            fed_s: None,
            points: Vec::with_capacity(POINTS_RESERVED),
            snr_db: Vec::with_capacity(POINTS_RESERVED),
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
    /// Offline feeders: the sample's place in the feed, a time on the common clock \[s\] (see
    /// [`crate::sync::FeedOrder`]); `None` for live reads.
    pub fed_s: Option<f64>,
    /// The barometer reading that came since the previous sample, if any: its SampleTimeFine
    /// \[s\] and pressure \[Pa\] (the estimator takes it just before this sample).
    pub pressure: Option<(f64, f64)>,
}

/// The live radar decoder: the drivers' streaming [`Decoder`] (framer, plausibility checker,
/// sensor clock, retraction), the same that decodes sessions offline, filling recycled
/// [`RadarItem`]s. The same bytes give the same frames as offline however the port chunks them;
/// a frame that might still be retracted (its last bytes begin a magic word) is held until the
/// bytes after it arrive, so no frame is published that the offline run drops.
pub struct RadarDecoder {
    inner: Decoder<(f64, u64)>,
}

impl std::fmt::Debug for RadarDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RadarDecoder")
            .field("frames", &self.frames())
            .finish()
    }
}

impl RadarDecoder {
    /// A decoder with the settings the radar's `.cfg` implies ([`DecoderConfig::from_derived`]).
    pub fn new(cfg: DecoderConfig) -> Self {
        RadarDecoder {
            inner: Decoder::new(cfg),
        }
    }

    /// Frames published (plausible and final).
    pub fn frames(&self) -> u64 {
        self.inner.report().published
    }

    /// Everything decoding counted so far (framer, plausibility, held frames).
    pub fn report(&self) -> DecodeReport {
        self.inner.report()
    }

    /// Bad frames and skipped bytes so far.
    pub fn counters(&self) -> &radar_driver::Counters {
        self.inner.framer_counters()
    }

    /// Plausibility verdicts so far (rejections by reason, re-anchors, retractions).
    pub fn plausibility(&self) -> &CheckCounters {
        self.inner.plausibility()
    }

    /// Copies the plausibility counters into the reader's shared counters.
    pub fn publish(&self, stats: &ReaderStats) {
        let r = self.inner.report();
        for (a, v) in stats.implausible.iter().zip(r.plausibility.rejected) {
            a.store(v, Ordering::Relaxed);
        }
        stats
            .reanchored
            .store(r.plausibility.reanchored, Ordering::Relaxed);
        stats
            .retracted
            .store(r.plausibility.retracted, Ordering::Relaxed);
        stats.held.store(r.held, Ordering::Relaxed);
    }

    /// Feeds bytes read at `host_s` / `read_ns`; `emit` gets each frame, filled into `item`
    /// (which it must hand on or give back). A frame is stamped with the read that completed it.
    pub fn feed(
        &mut self,
        input: &[u8],
        host_s: f64,
        read_ns: u64,
        mut emit: impl FnMut(&mut dyn FnMut(&mut RadarItem)),
    ) {
        self.inner
            .feed(input, (host_s, read_ns), |f| emit(&mut |it| fill(it, f)));
    }

    /// Ends a stretch of the stream (the port was reopened): a held frame is published, a
    /// partial one counted as dropped.
    pub fn resync(&mut self, mut emit: impl FnMut(&mut dyn FnMut(&mut RadarItem))) {
        self.inner.finish(|f| emit(&mut |it| fill(it, f)));
    }
}

fn fill(it: &mut RadarItem, f: &Decoded<'_, (f64, u64)>) {
    (it.host_s, it.read_ns) = f.stamp;
    it.set_frame(f.sensor_s, f.frame_number, f.bytes, f.cloud);
    it.t = None;
    it.fed_s = None;
}

/// The live IMU decoder: the drivers' streaming [`imu_driver::host::Decoder`], the same that
/// decodes sessions offline, producing [`ImuItem`]s.
pub struct ImuDecoder {
    inner: imu_driver::host::Decoder,
    /// A barometer reading waiting for the next sample: SampleTimeFine \[s\], pressure \[Pa\].
    held: Option<(f64, f64)>,
    pressure_dropped: u64,
}

impl std::fmt::Debug for ImuDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImuDecoder")
            .field("samples", &self.samples())
            .finish()
    }
}

impl ImuDecoder {
    /// A decoder for a device whose SampleTimeFine wraps as `wrap`.
    pub fn new(wrap: TimeWrap) -> Self {
        ImuDecoder {
            inner: imu_driver::host::Decoder::new(wrap),
            held: None,
            pressure_dropped: 0,
        }
    }

    /// Samples decoded.
    pub fn samples(&self) -> u64 {
        self.inner.report().samples
    }

    /// Everything decoding counted so far.
    pub fn report(&self) -> ImuDecodeReport {
        self.inner.report()
    }

    /// Feeds bytes; `emit` gets each sample, with the barometer reading that came since the
    /// previous one attached (a second reading before the next sample replaces the first, which
    /// is counted in [`ImuDecoder::pressure_dropped`]).
    pub fn feed(&mut self, input: &[u8], host_s: f64, read_ns: u64, mut emit: impl FnMut(ImuItem)) {
        let held = core::cell::Cell::new(self.held);
        let dropped = core::cell::Cell::new(0u64);
        self.inner.feed_with_pressure(
            input,
            (host_s, read_ns),
            |s| {
                emit(ImuItem {
                    host_s: s.stamp.0,
                    read_ns: s.stamp.1,
                    sensor_s: s.sensor_s,
                    accel: s.accel,
                    gyro: s.gyro,
                    bytes: s.bytes,
                    t: None,
                    fed_s: None,
                    pressure: held.take(),
                })
            },
            |p| {
                if held.replace(Some((p.sensor_s, p.pa))).is_some() {
                    dropped.set(dropped.get() + 1);
                }
            },
        );
        self.held = held.get();
        self.pressure_dropped += dropped.get();
    }

    /// Barometer readings decoded.
    pub fn pressure(&self) -> u64 {
        self.inner.report().pressure
    }

    /// Barometer readings replaced by a later one before an IMU sample could carry them.
    pub fn pressure_dropped(&self) -> u64 {
        self.pressure_dropped
    }

    /// Forgets a partial message (after the port was reopened).
    pub fn resync(&mut self) {
        self.inner.finish();
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
    /// Radar frames the framer retracted (they lost bytes on the wire); never published.
    pub retracted: AtomicU64,
    /// Radar frames held for the bytes after them (their last bytes began a magic word).
    pub held: AtomicU64,
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
    fn the_live_decoder_rejects_counts_and_never_publishes_retracted_frames() {
        let bytes = stream();
        for chunk in [1usize, 7, 100, 4096] {
            let mut dec = RadarDecoder::new(DecoderConfig::default());
            let mut seen = Vec::new();
            for c in bytes.chunks(chunk) {
                dec.feed(c, 0.0, 0, |fill| {
                    let mut it = RadarItem::default();
                    fill(&mut it);
                    seen.push(it.frame_number);
                });
            }
            // 20 lost a byte: it is held until the next magic shows it short, then dropped.
            assert_eq!(seen, [1, 2, 3, 5, 6, 8, 10, 11, 12], "chunks of {chunk}");
            let p = dec.plausibility();
            assert_eq!(p.rejected_total(), 2);
            assert_eq!(p.rejected[0], 1, "frame_number");
            assert_eq!(p.rejected[7], 1, "non_finite");
            assert_eq!((p.retracted, dec.report().held, dec.frames()), (1, 1, 9));
            let stats = ReaderStats::default();
            dec.publish(&stats);
            assert_eq!(stats.implausible[0].load(Ordering::Relaxed), 1);
            assert_eq!(stats.retracted.load(Ordering::Relaxed), 1);
        }
    }
}
