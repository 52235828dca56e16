//! A session's streams decoded and time-stamped: radar point clouds and IMU samples, each with the
//! host time of the chunk that completed it (when the session has an index) and its sensor time.
//! This is what offline runs, dataset export and evaluation read; nothing is dropped silently:
//! [`StreamReport`] counts what the framers rejected and, for radar frames, what the plausibility
//! checker ([`radar_driver::plausible`]) rejected, by reason. The decoding is the drivers'
//! streaming decoders ([`radar_driver::host::Decoder`], [`imu_driver::host::Decoder`]), the same
//! the runtime's readers run live, fed the recorded chunks.

use crate::{Session, SessionError};
use imu_driver::host::Decoder as ImuDecoder;
use imu_driver::TimeWrap;
use radar_driver::cfg::RadarConfig;
use radar_driver::host::{Decoded, Decoder, DecoderConfig, PointCloud};
use radar_driver::plausible::{IMPLAUSIBLE_KINDS, IMPLAUSIBLE_NAMES};

/// A decoded radar frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RadarFrame {
    /// Host time of the chunk that completed the frame \[s since session start\], if indexed.
    pub host_s: Option<f64>,
    /// Sensor time from the unwrapped cycle counter \[s since the first frame\], if the header has
    /// one.
    pub sensor_s: Option<f64>,
    /// Frame counter.
    pub frame_number: u32,
    /// Frame length on the wire \[B\].
    pub bytes: usize,
    /// Points, side info, targets.
    pub cloud: PointCloud,
}

/// A decoded IMU sample (MTData2 messages with acceleration and rate of turn).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Host time of the chunk that completed the message \[s since session start\], if indexed.
    pub host_s: Option<f64>,
    /// Unwrapped SampleTimeFine \[s\].
    pub sensor_s: f64,
    /// Specific force, sensor frame \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn, sensor frame \[rad/s\].
    pub gyro: [f64; 3],
    /// PacketCounter, if sent.
    pub packet_counter: Option<u16>,
    /// Message length on the wire \[B\].
    pub bytes: usize,
}

/// What decoding a stream found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StreamReport {
    /// Bytes read \[B\].
    pub bytes: u64,
    /// Frames or messages decoded (radar: released by the framer and found plausible).
    pub ok: u64,
    /// Frames or messages rejected by the framer.
    pub bad: u64,
    /// Bytes not in any good frame \[B\].
    pub bytes_skipped: u64,
    /// Messages without the fields a sample needs (config acks, GNSS-only messages, ...).
    pub not_samples: u64,
    /// Barometer readings in the IMU stream ([`PressureSample`]).
    pub pressure: u64,
    /// Radar frames the framer released but the plausibility checker rejected, indexed by
    /// [`radar_driver::plausible::Implausible::kind_index`] (names: [`IMPLAUSIBLE_NAMES`]).
    pub implausible: [u64; IMPLAUSIBLE_KINDS],
    /// Radar frames that confirmed a sensor restart or frame-number jump (the frame before them
    /// was rejected as `frame_number`, these were accepted).
    pub reanchored: u64,
    /// Radar frames the framer retracted (they lost bytes on the wire and ended inside the next
    /// frame's magic word); never published.
    pub retracted: u64,
    /// Radar frames held for the bytes after them before they were published or retracted
    /// (their last bytes began a magic word).
    pub held: u64,
}

impl StreamReport {
    /// Radar frames rejected as implausible, all reasons.
    pub fn implausible_total(&self) -> u64 {
        self.implausible.iter().sum()
    }

    /// `(reason, count)` of the implausible radar frames, every reason listed.
    pub fn implausible_by_reason(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        IMPLAUSIBLE_NAMES
            .iter()
            .copied()
            .zip(self.implausible.iter().copied())
    }
}

/// Decodes the radar stream with the streaming [`Decoder`] the runtime's live reader runs, fed
/// the recorded chunks: frames, point clouds (Doppler indices scaled with the session's .cfg when
/// it has one), sensor time unwrapped with the .cfg's frame period, every frame held to the
/// .cfg's plausibility [`radar_driver::plausible::Limits`], frames the framer retracts never
/// published. Rejected frames are counted in [`StreamReport::implausible`].
pub fn radar_frames(session: &Session) -> Result<(Vec<RadarFrame>, StreamReport), SessionError> {
    let Some(stream) = &session.radar else {
        return Ok((Vec::new(), StreamReport::default()));
    };
    let derived = session
        .radar_cfg()?
        .and_then(|text| RadarConfig::parse(&text).ok())
        .and_then(|c| c.derive(None).ok());
    let bytes = stream.read_all()?;
    let mut dec = Decoder::new(DecoderConfig::from_derived(derived.as_ref()));
    let mut out = Vec::new();
    let mut keep = |f: &Decoded<'_, Option<f64>>| {
        out.push(RadarFrame {
            host_s: f.stamp,
            sensor_s: f.sensor_s,
            frame_number: f.frame_number,
            bytes: f.bytes,
            cloud: f.cloud.clone(),
        })
    };
    for chunk in stream.chunks() {
        let host_s = chunk.host_ns.map(|n| n as f64 * 1e-9);
        dec.feed(
            &bytes[chunk.start as usize..chunk.end as usize],
            host_s,
            &mut keep,
        );
    }
    dec.finish(&mut keep);
    let r = dec.report();
    let (c, p) = (r.framer, r.plausibility);
    debug_assert_eq!(c.frames_ok, p.accepted + p.rejected_total());
    Ok((
        out,
        StreamReport {
            bytes: c.bytes_in,
            ok: r.published,
            bad: c.frames_bad_total(),
            bytes_skipped: c.bytes_skipped,
            not_samples: 0,
            pressure: 0,
            implausible: p.rejected,
            reanchored: p.reanchored,
            retracted: p.retracted,
            held: r.held,
        },
    ))
}

/// A decoded barometer reading (an MTData2 message with BaroPressure and SampleTimeFine in the
/// IMU stream).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PressureSample {
    /// Host time of the chunk that completed the message \[s since session start\], if indexed.
    pub host_s: Option<f64>,
    /// Unwrapped SampleTimeFine \[s\] (the IMU's clock).
    pub sensor_s: f64,
    /// Pressure \[Pa\].
    pub pa: f64,
}

/// Decodes the IMU stream into samples (messages carrying acceleration, rate of turn and
/// SampleTimeFine) with the streaming [`ImuDecoder`] the runtime's live reader runs.
pub fn imu_samples(session: &Session) -> Result<(Vec<ImuSample>, StreamReport), SessionError> {
    imu_and_pressure(session).map(|(s, _, r)| (s, r))
}

/// [`imu_samples`] and the barometer readings of the same stream (empty without a barometer),
/// from one decoding pass.
#[allow(clippy::type_complexity)]
pub fn imu_and_pressure(
    session: &Session,
) -> Result<(Vec<ImuSample>, Vec<PressureSample>, StreamReport), SessionError> {
    let Some(stream) = &session.imu else {
        return Ok((Vec::new(), Vec::new(), StreamReport::default()));
    };
    let wrap = session
        .meta
        .imu
        .as_ref()
        .map_or(TimeWrap::Pow32, |m| m.time_wrap());
    let bytes = stream.read_all()?;
    let mut dec = ImuDecoder::new(wrap);
    let mut out = Vec::new();
    let mut baro = Vec::new();
    for chunk in stream.chunks() {
        let host_s = chunk.host_ns.map(|n| n as f64 * 1e-9);
        dec.feed_with_pressure(
            &bytes[chunk.start as usize..chunk.end as usize],
            host_s,
            |s| {
                out.push(ImuSample {
                    host_s: s.stamp,
                    sensor_s: s.sensor_s,
                    accel: s.accel,
                    gyro: s.gyro,
                    packet_counter: s.packet_counter,
                    bytes: s.bytes,
                })
            },
            |p| {
                baro.push(PressureSample {
                    host_s: p.stamp,
                    sensor_s: p.sensor_s,
                    pa: p.pa,
                })
            },
        );
    }
    dec.finish();
    let r = dec.report();
    Ok((
        out,
        baro,
        StreamReport {
            bytes: r.framer.bytes_in,
            ok: r.framer.frames_ok,
            bad: r.framer.frames_bad_total(),
            bytes_skipped: r.framer.bytes_skipped,
            not_samples: r.not_samples,
            pressure: r.pressure,
            ..StreamReport::default()
        },
    ))
}

/// A linear map from a sensor clock to the host clock, `host = offset + rate * sensor`, fitted to
/// the lower envelope of (sensor, host) stamps: host stamps carry only positive delays (UART,
/// USB, scheduling), so the earliest arrivals are the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockFit {
    /// Host time at sensor time 0 \[s\].
    pub offset: f64,
    /// Host seconds per sensor second (1 + drift).
    pub rate: f64,
    /// Pairs the fit used.
    pub used: usize,
    /// RMS of the kept residuals \[s\].
    pub residual_rms: f64,
}

impl ClockFit {
    /// Fits `host = offset + rate * sensor`; `None` with fewer than 2 pairs or no sensor spread.
    pub fn fit(pairs: &[(f64, f64)]) -> Option<ClockFit> {
        let mut keep: Vec<(f64, f64)> = pairs
            .iter()
            .copied()
            .filter(|(s, h)| s.is_finite() && h.is_finite())
            .collect();
        let mut fit = None;
        for _ in 0..4 {
            let f = least_squares(&keep)?;
            fit = Some(f);
            // Keep the lower envelope: residuals at or below the 25th percentile.
            let mut r: Vec<f64> = keep
                .iter()
                .map(|(s, h)| h - (f.offset + f.rate * s))
                .collect();
            r.sort_by(f64::total_cmp);
            let cut = r[r.len() / 4];
            let next: Vec<(f64, f64)> = keep
                .iter()
                .copied()
                .filter(|(s, h)| h - (f.offset + f.rate * s) <= cut)
                .collect();
            if next.len() < 2 || next.len() == keep.len() {
                break;
            }
            keep = next;
        }
        fit
    }

    /// Host time of a sensor time \[s\].
    pub fn host(&self, sensor_s: f64) -> f64 {
        self.offset + self.rate * sensor_s
    }
}

fn least_squares(p: &[(f64, f64)]) -> Option<ClockFit> {
    let n = p.len() as f64;
    if p.len() < 2 {
        return None;
    }
    let (ms, mh) = (
        p.iter().map(|x| x.0).sum::<f64>() / n,
        p.iter().map(|x| x.1).sum::<f64>() / n,
    );
    let sss: f64 = p.iter().map(|x| (x.0 - ms).powi(2)).sum();
    if sss <= 0.0 {
        return None;
    }
    let rate = p.iter().map(|x| (x.0 - ms) * (x.1 - mh)).sum::<f64>() / sss;
    let offset = mh - rate * ms;
    let rms = (p
        .iter()
        .map(|x| (x.1 - offset - rate * x.0).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    Some(ClockFit {
        offset,
        rate,
        used: p.len(),
        residual_rms: rms,
    })
}

/// One time base for a session's radar frames and IMU samples: the session host clock \[s\],
/// through the lower-envelope [`ClockFit`] of each stream after taking each frame's transmission
/// time off its host stamp (host stamps mark a frame's LAST byte). Without an index (no host
/// stamps) a stream falls back to its own sensor clock, starting at its first stamp.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SessionClock {
    /// Radar sensor-to-host map (None without a timing index).
    pub radar: Option<ClockFit>,
    /// IMU sensor-to-host map (None without a timing index).
    pub imu: Option<ClockFit>,
    /// Radar UART rate \[bit/s\] (10 bits a byte on the wire).
    pub radar_baud: u32,
    /// IMU UART rate \[bit/s\].
    pub imu_baud: u32,
    /// Half the active chirping time of a frame \[s\] (0 without a .cfg): a frame's points are
    /// measured at the middle of its chirps.
    pub half_chirps_s: f64,
    first_radar_sensor_s: f64,
    first_imu_sensor_s: f64,
}

impl SessionClock {
    /// Fits both streams' clocks to the host clock.
    pub fn fit(
        session: &Session,
        frames: &[RadarFrame],
        imu: &[ImuSample],
    ) -> Result<SessionClock, SessionError> {
        let radar_baud = session.meta.radar.as_ref().map_or(921_600, |r| r.baud);
        let imu_baud = session.meta.imu.as_ref().map_or(115_200, |m| m.baud);
        let radar = ClockFit::fit(
            &frames
                .iter()
                .filter_map(|f| Some((f.sensor_s?, f.host_s? - tx_s(f.bytes, radar_baud))))
                .collect::<Vec<_>>(),
        );
        let imu_fit = ClockFit::fit(
            &imu.iter()
                .filter_map(|s| Some((s.sensor_s, s.host_s? - tx_s(s.bytes, imu_baud))))
                .collect::<Vec<_>>(),
        );
        let half_chirps_s = session
            .radar_cfg()?
            .and_then(|t| RadarConfig::parse(&t).ok())
            .and_then(|c| c.derive(None).ok())
            .map_or(0.0, |d| d.active_frame_time_ms / 2e3);
        Ok(SessionClock {
            radar,
            imu: imu_fit,
            radar_baud,
            imu_baud,
            half_chirps_s,
            first_radar_sensor_s: frames.first().and_then(|f| f.sensor_s).unwrap_or(0.0),
            first_imu_sensor_s: imu.first().map_or(0.0, |s| s.sensor_s),
        })
    }

    /// True when the streams could not be put on one clock (no index): the sensor clocks are then
    /// assumed to start together.
    pub fn unsynced(&self) -> bool {
        self.radar.is_none() || self.imu.is_none()
    }

    /// Host time of an IMU sensor time \[s\].
    pub fn imu_s(&self, sensor_s: f64) -> f64 {
        self.imu
            .map_or(sensor_s - self.first_imu_sensor_s, |c| c.host(sensor_s))
    }

    /// Host time at which a radar frame's points were measured \[s\]: when its output was ready,
    /// less the processing time (stats TLV) and half the chirping. None for a frame with neither
    /// a host stamp nor a sensor time.
    pub fn radar_s(&self, f: &RadarFrame) -> Option<f64> {
        let ready = match (self.radar, f.sensor_s, f.host_s) {
            (Some(c), Some(s), _) => c.host(s),
            (None, _, Some(h)) => h - tx_s(f.bytes, self.radar_baud),
            (None, Some(s), None) => s - self.first_radar_sensor_s,
            _ => return None,
        };
        let processing = f
            .cloud
            .stats
            .map_or(0.0, |s| f64::from(s.inter_frame_processing_time_us) * 1e-6);
        Some(ready - processing - self.half_chirps_s)
    }
}

/// Time on the wire of `bytes` at `baud` \[s\] (8N1: 10 bits a byte).
fn tx_s(bytes: usize, baud: u32) -> f64 {
    bytes as f64 * 10.0 / f64::from(baud.max(1))
}
