//! The sensor hub as the pipeline's input (`milliego run --hub serial:DEV[@BAUD]`): one port
//! carries the hub link (`docs/hub-link.md`), whose radar frames and IMU messages go through the
//! same decoders as the direct ports' bytes, stamped with the hub's time of their last byte (one
//! clock for both sensors) instead of the host time of the read.
//!
//! The hub clock is mapped onto the pipeline's host clock by one offset, fixed at the first
//! message: `host_s = host_s(first read) + (t_hub - t_hub(first))` ([`hub_link::LinkClock`], as
//! `record --hub` does). It follows the hub's oscillator from there (no drift correction: tens
//! of ppm, well inside the synchroniser's tolerances over a session). A restarted hub (link
//! sequence back to 0) re-anchors the offset.

use super::{spawn_named, InputCounters, RunError, Shared};
use crate::reader::{
    radar_sink, read_loop, ImuDecoder, ImuItem, RadarDecoder, RadarItem, SerialSource, Source,
};
use hub_link::{Deframer, DeframerCounters, Event, Health, LinkClock, Message, FRAME_MAX};
use imu_driver::TimeWrap;
use radar_driver::host::DecoderConfig;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

/// `serial:DEV` or `serial:DEV@BAUD` (default 921600 bit/s).
pub fn parse_spec(spec: &str) -> Result<(String, u32), String> {
    let rest = spec
        .strip_prefix("serial:")
        .ok_or_else(|| format!("--hub {spec}: expected serial:DEV[@BAUD]"))?;
    match rest.rsplit_once('@') {
        Some((dev, baud)) => baud
            .parse()
            .map(|b| (dev.to_string(), b))
            .map_err(|_| format!("--hub {spec}: bad baud rate {baud:?}")),
        None => Ok((rest.to_string(), 921_600)),
    }
}

/// Hub link -> radar and IMU decoders, on the hub's clock.
pub struct HubDecoder {
    deframer: Box<Deframer<FRAME_MAX>>,
    radar: RadarDecoder,
    imu: ImuDecoder,
    /// Sequence and clock of the link (missing messages, restarts, the hub-to-host offset).
    clock: LinkClock,
    /// The hub's last health message.
    pub health: Option<Health>,
}

impl std::fmt::Debug for HubDecoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HubDecoder")
            .field("clock", &self.clock)
            .finish()
    }
}

impl HubDecoder {
    /// Decoders with the radar settings of the `.cfg` and the IMU's time wrap.
    pub fn new(radar: DecoderConfig, wrap: TimeWrap) -> Self {
        HubDecoder {
            deframer: Box::default(),
            radar: RadarDecoder::new(radar),
            imu: ImuDecoder::new(wrap),
            clock: LinkClock::default(),
            health: None,
        }
    }

    /// The radar decoder.
    pub fn radar(&self) -> &RadarDecoder {
        &self.radar
    }

    /// The IMU decoder.
    pub fn imu(&self) -> &ImuDecoder {
        &self.imu
    }

    /// Link messages missing by sequence number (dropped by the hub for backpressure, or
    /// corrupted on the way).
    pub fn seq_gaps(&self) -> u64 {
        self.clock.seq_gaps
    }

    /// The link's counters (bytes, messages, bad frames and their bytes).
    pub fn link(&self) -> &DeframerCounters {
        self.deframer.counters()
    }

    /// Feeds link bytes read at `host_s`; radar frames go to `radar`, IMU samples to `imu`.
    pub fn feed(
        &mut self,
        bytes: &[u8],
        host_s: f64,
        read_ns: u64,
        radar: &mut impl FnMut(&mut dyn FnMut(&mut RadarItem)),
        imu: &mut impl FnMut(ImuItem),
    ) {
        let mut input = bytes;
        loop {
            let m = match self.deframer.poll(&mut input) {
                Event::Message(m) => m,
                Event::BadFrame(e) => {
                    tracing::warn!(error = %e, "hub link: bad frame dropped");
                    continue;
                }
                Event::NeedMore => break,
            };
            // The hub clock on the host's, in ns (host_s is seconds since the run started).
            let o = self
                .clock
                .observe(m.header(), (host_s.max(0.0) * 1e9).round() as u64);
            if o.restarted {
                tracing::warn!("hub link: the hub restarted (sequence 0); clock re-anchored");
            } else if o.missing > 0 {
                tracing::warn!(
                    missing = o.missing,
                    seq = m.header().seq,
                    "hub link: messages missing"
                );
            }
            let t = o.t_ns as f64 * 1e-9;
            match m {
                Message::Radar { bytes, .. } => self.radar.feed(bytes, t, read_ns, &mut *radar),
                Message::Imu { bytes, .. } => self.imu.feed(bytes, t, read_ns, &mut *imu),
                Message::Health { health, .. } => {
                    tracing::info!(?health, "hub health");
                    self.health = Some(health);
                }
            }
        }
    }

    /// The port was reopened: a held radar frame is published, partial messages forgotten.
    pub fn resync(&mut self, radar: &mut impl FnMut(&mut dyn FnMut(&mut RadarItem))) {
        self.radar.resync(&mut *radar);
        self.imu.resync();
        let dropped = self.deframer.resync();
        if dropped > 0 {
            tracing::warn!(
                bytes = dropped,
                "hub link: partial message dropped on reopen"
            );
        }
    }
}

/// Opens the hub port (before any thread starts, so a missing device stops the run).
pub(super) fn open(spec: &str) -> Result<(Box<dyn std::io::Read + Send>, SerialSource), RunError> {
    let (path, baud) = parse_spec(spec).map_err(|e| RunError::Port {
        role: super::PortRole::RadarData,
        path: spec.to_string(),
        error: std::io::Error::new(std::io::ErrorKind::InvalidInput, e),
    })?;
    let mut src = SerialSource { path, baud };
    let port = src.open().map_err(|error| RunError::Port {
        role: super::PortRole::RadarData,
        path: src.path.clone(),
        error,
    })?;
    Ok((port, src))
}

/// The hub reader thread: link port -> [`HubDecoder`] -> radar and IMU queues (drop-oldest).
pub(super) fn spawn(
    sh: &Arc<Shared>,
    spec: &str,
    decoding: DecoderConfig,
    wrap: TimeWrap,
    backoff: Duration,
    counters: &InputCounters,
) -> Result<std::thread::JoinHandle<()>, RunError> {
    let (port, mut src) = open(spec)?;
    let sh2 = Arc::clone(sh);
    let ctx = super::reader_ctx(sh, &counters.radar, backoff);
    let dec = Arc::clone(&counters.decoded);
    let stats = Arc::clone(&counters.radar);
    spawn_named("hub", move || {
        let mut hub = HubDecoder::new(decoding, wrap);
        let mut sink = radar_sink(&sh2.radar_q, &sh2.pool);
        let mut imu = |it: ImuItem| {
            sh2.imu_q.push(it);
        };
        read_loop(&mut src, Some(port), &ctx, |b, host_s, ns, reopened| {
            if reopened {
                hub.resync(&mut sink);
            }
            sh2.last_data_ns.store(ns, Ordering::Relaxed);
            hub.feed(b, host_s, ns, &mut sink, &mut imu);
            hub.radar().publish(&stats);
            dec[0].store(hub.radar().frames(), Ordering::Relaxed);
            dec[1].store(hub.imu().samples(), Ordering::Relaxed);
        });
        if let Some(h) = hub.health {
            tracing::info!(?h, seq_gaps = hub.seq_gaps(), "hub: last health");
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hub_link::{Header, Kind};
    use radar_driver::encode::FrameBuilder;

    #[test]
    fn specs_parse() {
        assert_eq!(
            parse_spec("serial:/dev/ttyACM0"),
            Ok(("/dev/ttyACM0".into(), 921_600))
        );
        assert_eq!(
            parse_spec("serial:/dev/pts/3@115200"),
            Ok(("/dev/pts/3".into(), 115_200))
        );
        assert!(parse_spec("udp://x").is_err());
        assert!(parse_spec("serial:/dev/x@fast").is_err());
    }

    #[test]
    fn frames_carry_the_hub_time_in_any_chunking() {
        let mut wire = Vec::new();
        for n in 1..=3u32 {
            let f = FrameBuilder::oob(0x0303_0002, 0xA6843, n)
                .points(&[[1.0, 2.0, 0.0, 0.5]])
                .to_vec();
            let h = Header {
                seq: n - 1,
                t_ns: u64::from(n) * 50_000_000,
                ..Header::default()
            };
            hub_link::encode_serial(Kind::Radar, &h, &[&f], &mut |b| wire.push(b));
        }
        for chunk in [1usize, 5, 4096] {
            let mut hub = HubDecoder::new(DecoderConfig::default(), TimeWrap::Pow32);
            let mut seen = Vec::new();
            for (i, c) in wire.chunks(chunk).enumerate() {
                // Host reads at arbitrary times: the stamps must not follow them.
                let host = 100.0 + i as f64;
                hub.feed(
                    c,
                    host,
                    0,
                    &mut |fill: &mut dyn FnMut(&mut RadarItem)| {
                        let mut it = RadarItem::default();
                        fill(&mut it);
                        seen.push((it.frame_number, it.host_s));
                    },
                    &mut |_| {},
                );
            }
            let t0 = seen[0].1;
            let rel: Vec<(u32, i64)> = seen
                .iter()
                .map(|&(n, t)| (n, ((t - t0) * 1e3).round() as i64))
                .collect();
            assert_eq!(rel, [(1, 0), (2, 50), (3, 100)], "chunks of {chunk}");
            assert_eq!(hub.seq_gaps(), 0);
        }
    }

    /// One MTData2 message as the simulated MTi-1 sends it (SampleTimeFine at 10 kHz).
    fn imu_message(counter: u16, sample_time_fine: u32) -> Vec<u8> {
        let s = milliego_sim::imu::ImuSample {
            accel: nalgebra::Vector3::new(0.1, 0.0, 9.81),
            gyro: nalgebra::Vector3::new(0.0, 0.0, 0.2),
            accel_bias: nalgebra::Vector3::zeros(),
            gyro_bias: nalgebra::Vector3::zeros(),
        };
        milliego_sim::imu::encode(counter, sample_time_fine, &s)
    }

    fn encoded(kind: Kind, seq: u32, t_ms: u64, body: &[u8]) -> Vec<u8> {
        let h = Header {
            seq,
            t_ns: t_ms * 1_000_000,
            ..Header::default()
        };
        let mut w = Vec::new();
        hub_link::encode_serial(kind, &h, &[body], &mut |b| w.push(b));
        w
    }

    /// A radar sink that keeps (frame number, time).
    fn collect(seen: &mut Vec<(u32, f64)>) -> impl FnMut(&mut dyn FnMut(&mut RadarItem)) + '_ {
        move |fill: &mut dyn FnMut(&mut RadarItem)| {
            let mut it = RadarItem::default();
            fill(&mut it);
            seen.push((it.frame_number, it.host_s));
        }
    }

    /// Both sensors through one link: every sample on the hub's clock whatever the host read
    /// times; a corrupted message, a sequence gap and a reopened port mid-message are counted,
    /// and the messages after each of them decode.
    #[test]
    fn both_sensors_on_the_hub_clock_with_damage_and_a_reopen() {
        let radar = |n: u32| {
            FrameBuilder::oob(0x0303_0002, 0xA6843, n)
                .points(&[[1.0, 2.0, 0.0, 0.5]])
                .to_vec()
        };
        let mut corrupt = encoded(Kind::Imu, 2, 52, &imu_message(2, 520));
        let mid = corrupt.len() / 2;
        // Any non-zero value but the original: the frame stays one frame and fails its check.
        corrupt[mid] = if corrupt[mid] == 0xFF {
            0x7F
        } else {
            corrupt[mid] + 1
        };
        let mut wire = Vec::new();
        wire.extend(encoded(Kind::Radar, 0, 50, &radar(1)));
        wire.extend(encoded(Kind::Imu, 1, 51, &imu_message(1, 510)));
        wire.extend(&corrupt);
        wire.extend(encoded(Kind::Imu, 3, 53, &imu_message(3, 530)));
        // Sequence 4 lost on the way (e.g. dropped by the hub for backpressure).
        wire.extend(encoded(Kind::Radar, 5, 100, &radar(2)));
        wire.extend(encoded(Kind::Imu, 6, 101, &imu_message(4, 1010)));
        let cut = encoded(Kind::Imu, 7, 102, &imu_message(5, 1020));
        let after = encoded(Kind::Imu, 8, 103, &imu_message(6, 1030));

        for chunk in [1usize, 7, 4096] {
            let mut hub = HubDecoder::new(DecoderConfig::default(), TimeWrap::Pow32);
            let mut radar_seen = Vec::new();
            let mut imu_seen = Vec::new();
            let feed = |hub: &mut HubDecoder,
                        seen: &mut Vec<(u32, f64)>,
                        imu_seen: &mut Vec<(f64, f64)>,
                        bytes: &[u8],
                        host: f64| {
                for (i, c) in bytes.chunks(chunk).enumerate() {
                    let host = host + i as f64 * 0.25;
                    hub.feed(c, host, 0, &mut collect(seen), &mut |it: ImuItem| {
                        imu_seen.push((it.sensor_s, it.host_s))
                    });
                }
            };
            feed(&mut hub, &mut radar_seen, &mut imu_seen, &wire, 1000.0);
            assert_eq!(
                hub.seq_gaps(),
                2,
                "chunks of {chunk}: seq 2 corrupted, 4 lost"
            );
            let link = *hub.link();
            assert_eq!(
                (
                    link.frames_bad_cobs + link.frames_bad_message,
                    link.bytes_dropped
                ),
                (1, corrupt.len() as u64),
                "chunks of {chunk}"
            );
            // The port is reopened in the middle of a message.
            let half = &cut[..cut.len() / 2];
            feed(&mut hub, &mut radar_seen, &mut imu_seen, half, 2000.0);
            hub.resync(&mut collect(&mut radar_seen));
            feed(&mut hub, &mut radar_seen, &mut imu_seen, &after, 3000.0);
            let link = *hub.link();
            assert_eq!(
                link.bytes_dropped,
                (corrupt.len() + cut.len() / 2) as u64,
                "chunks of {chunk}: the cut message's bytes are counted as dropped"
            );
            assert_eq!(
                link.messages_ok, 6,
                "chunks of {chunk}: seq 0, 1, 3, 5, 6, 8"
            );
            assert_eq!(
                hub.seq_gaps(),
                3,
                "chunks of {chunk}: and seq 7, cut by the reopen"
            );

            // Times relative to the first message (the anchor), in ms of hub time.
            let t0 = radar_seen[0].1;
            let ms = |t: f64| ((t - t0) * 1e3).round() as i64;
            let r: Vec<(u32, i64)> = radar_seen.iter().map(|&(n, t)| (n, ms(t))).collect();
            assert_eq!(r, [(1, 0), (2, 50)], "chunks of {chunk}");
            let i: Vec<(i64, i64)> = imu_seen
                .iter()
                .map(|&(s, t)| ((s * 1e4).round() as i64, ms(t)))
                .collect();
            assert_eq!(
                i,
                [(510, 1), (530, 3), (1010, 51), (1030, 53)],
                "chunks of {chunk}: (SampleTimeFine, hub ms)"
            );
        }
    }
}
