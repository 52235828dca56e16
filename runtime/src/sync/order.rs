//! Ordering: the synchroniser puts both streams on one clock ([`super::clock::OnlineClock`], or the
//! session's offline fit) and releases them in time order, the order the offline runner uses.

use super::clock::{tx_s, ClockConfig, OnlineClock};
use crate::reader::{ImuItem, RadarItem};
use pose_link::Health;
use std::collections::VecDeque;

/// What the synchroniser releases, in the order estimators must see it.
#[derive(Debug)]
pub enum SyncOut {
    /// An IMU sample (time on the common clock).
    Imu {
        /// Sample.
        input: crate::estimator::ImuInput,
        /// Host read time of the sample \[ns since the epoch\].
        read_ns: u64,
        /// Sensor and clock flags.
        health: Health,
    },
    /// A radar frame (`t` set).
    Radar {
        /// Frame.
        item: Box<RadarItem>,
        /// Sensor and clock flags.
        health: Health,
    },
    /// An IMU sample as soon as it arrives, before it is put in order (IMU-rate prediction
    /// only; the same sample comes again as [`SyncOut::Imu`] for the estimator).
    Preview {
        /// Sample.
        input: crate::estimator::ImuInput,
        /// Host read time of the sample \[ns since the epoch\].
        read_ns: u64,
        /// Sensor and clock flags.
        health: Health,
    },
    /// Radar is missing: a pose is due anyway (once per radar period).
    Tick {
        /// Time on the common clock \[s\].
        t: f64,
        /// Sensor and clock flags.
        health: Health,
    },
}

/// Settings of the [`Synchroniser`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyncConfig {
    /// Radar frame period \[s\] (from the `.cfg`; measured when None).
    pub radar_period_s: Option<f64>,
    /// A stream is missing after this many of its periods without data.
    pub stall_periods: f64,
    /// Radar UART rate \[bit/s\].
    pub radar_baud: u32,
    /// IMU UART rate \[bit/s\].
    pub imu_baud: u32,
    /// Half the active chirping of a frame \[s\].
    pub half_chirps_s: f64,
    /// Longest an IMU sample waits for a radar frame due before it \[s\]; a radar frame waits
    /// for the IMU to pass it this long plus one frame period.
    pub max_hold_s: f64,
    /// Whether a radar stream is expected at all.
    pub radar_enabled: bool,
    /// Whether an IMU stream is expected at all.
    pub imu_enabled: bool,
    /// Clock fits.
    pub clock: ClockConfig,
    /// Emit every IMU sample at once as [`SyncOut::Preview`] (IMU-rate output).
    pub preview_imu: bool,
}

impl Default for SyncConfig {
    fn default() -> Self {
        SyncConfig {
            radar_period_s: None,
            stall_periods: 3.0,
            radar_baud: 921_600,
            imu_baud: 115_200,
            half_chirps_s: 0.0,
            max_hold_s: 0.25,
            radar_enabled: true,
            imu_enabled: true,
            clock: ClockConfig::default(),
            preview_imu: false,
        }
    }
}

/// Counters of the synchroniser.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SyncCounters {
    /// Radar frames released.
    pub radar: u64,
    /// IMU samples released.
    pub imu: u64,
    /// Radar frames released after the IMU had passed their time.
    pub radar_late: u64,
    /// Items dropped because the synchroniser's own buffers were full.
    pub dropped: u64,
    /// Times the radar was declared missing.
    pub radar_gaps: u64,
    /// Times the IMU was declared missing.
    pub imu_gaps: u64,
    /// Items held while the clocks were not yet synchronised (start-up), re-timed after.
    pub warmup: u64,
}

/// Puts both streams on one clock and releases them in time order: each radar frame right after
/// the first IMU sample at or past its time (the order the offline runner uses), IMU samples held
/// only while a radar frame may still be due before them. Detects stalled streams.
#[derive(Debug)]
pub struct Synchroniser {
    cfg: SyncConfig,
    /// Radar clock.
    pub radar_clock: OnlineClock,
    /// IMU clock.
    pub imu_clock: OnlineClock,
    radar: VecDeque<Box<RadarItem>>,
    imu: VecDeque<ImuItem>,
    last_radar_t: Option<f64>,
    last_imu_t: Option<f64>,
    radar_period: Option<f64>,
    imu_period: Option<f64>,
    last_radar_host: Option<f64>,
    last_imu_host: Option<f64>,
    start_host: Option<f64>,
    radar_missing: bool,
    imu_missing: bool,
    /// How long the IMU has been silent at the last poll \[s\] (host or data time, as stalls
    /// are judged).
    imu_silent_s: f64,
    last_tick: f64,
    imu_done_t: Option<f64>,
    released_t: f64,
    retimed: bool,
    last_virtual: f64,
    virtual_frame: u32,
    unpreviewed: usize,
    last_imu_seen: Option<f64>,
    /// Set when items carry precomputed times from an offline clock fit.
    pub offline_clock: bool,
    /// Set for sessions: stalls are judged on the streams' data times, not on arrival.
    pub data_time: bool,
    /// Counters.
    pub counters: SyncCounters,
}

/// Radar stamp pairs before the radar clock counts as synchronised.
const RADAR_MIN_PAIRS: usize = 4;

impl Synchroniser {
    /// A synchroniser (buffers allocated here).
    pub fn new(cfg: SyncConfig) -> Self {
        Synchroniser {
            cfg,
            // The radar sends 10-30 frames a second: 16 pairs would hold the first frames for
            // up to 1.6 s. With rate fixed at 1 for the first seconds (`min_rate_span_s`), an
            // offset from the lower envelope of 4 pairs is within the stamps' jitter, and the
            // fit goes on improving as pairs come.
            radar_clock: OnlineClock::new(ClockConfig {
                min_pairs: cfg.clock.min_pairs.min(RADAR_MIN_PAIRS),
                ..cfg.clock
            }),
            imu_clock: OnlineClock::new(ClockConfig {
                refit_every: 10,
                ..cfg.clock
            }),
            radar: VecDeque::with_capacity(128),
            imu: VecDeque::with_capacity(4096),
            last_radar_t: None,
            last_imu_t: None,
            radar_period: cfg.radar_period_s,
            imu_period: None,
            last_radar_host: None,
            last_imu_host: None,
            start_host: None,
            radar_missing: false,
            imu_missing: false,
            imu_silent_s: 0.0,
            last_tick: f64::NEG_INFINITY,
            imu_done_t: None,
            released_t: f64::NEG_INFINITY,
            retimed: false,
            last_virtual: f64::NEG_INFINITY,
            virtual_frame: 0,
            unpreviewed: 0,
            last_imu_seen: None,
            offline_clock: false,
            data_time: false,
            counters: SyncCounters::default(),
        }
    }

    /// Radar frame period in use \[s\].
    pub fn radar_period(&self) -> f64 {
        self.radar_period.unwrap_or(0.1)
    }

    /// IMU sample period in use \[s\].
    pub fn imu_period(&self) -> f64 {
        self.imu_period.unwrap_or(0.01)
    }

    fn radar_time(&self, item: &RadarItem) -> f64 {
        let ready = match item.sensor_s {
            Some(s) => self.radar_clock.host(s),
            None => item.host_s - tx_s(item.bytes, self.cfg.radar_baud),
        };
        ready - item.processing_s - self.cfg.half_chirps_s
    }

    /// Times of what was held while the clocks settled, from the settled fits.
    fn retime(&mut self) {
        for k in 0..self.radar.len() {
            let t = self.radar_time(&self.radar[k]);
            self.radar[k].t = Some(t);
        }
        self.last_radar_t = self.radar.back().and_then(|r| r.t).or(self.last_radar_t);
        for k in 0..self.imu.len() {
            let t = self.imu_clock.host(self.imu[k].sensor_s);
            self.imu[k].t = Some(t);
        }
        self.retimed = true;
    }

    /// True once every expected stream's clock is synchronised (always for offline times).
    pub fn clocks_ready(&self) -> bool {
        self.offline_clock
            || ((!self.cfg.radar_enabled || self.radar_clock.synced())
                && (!self.cfg.imu_enabled || self.imu_clock.synced()))
    }

    /// Current flags (radar/IMU missing, clock unsynced).
    pub fn health(&self) -> Health {
        let mut h = 0;
        if self.radar_missing {
            h |= Health::RADAR_MISSING.0;
        }
        if self.imu_missing {
            h |= Health::IMU_MISSING.0;
        }
        let unsynced = !self.offline_clock
            && ((self.cfg.radar_enabled && !self.radar_clock.synced())
                || (self.cfg.imu_enabled && !self.imu_clock.synced()));
        if unsynced {
            h |= Health::CLOCK_UNSYNCED.0;
        }
        Health(h)
    }

    /// Takes a radar frame; its box comes back out of [`Synchroniser::poll`] (or, when the
    /// buffer overflows, through `recycle`).
    pub fn push_radar(&mut self, mut item: Box<RadarItem>, recycle: impl FnOnce(Box<RadarItem>)) {
        let t = match (item.t, item.sensor_s) {
            (Some(t), _) => t,
            (None, s) => {
                if let Some(s) = s {
                    let tx = tx_s(item.bytes, self.cfg.radar_baud);
                    self.radar_clock.push(s, item.host_s - tx);
                }
                self.radar_time(&item)
            }
        };
        item.t = Some(t);
        tracing::trace!(frame = item.frame_number, t, sensor_s = ?item.sensor_s, host_s = item.host_s, "radar");
        if !self.clocks_ready() {
            self.counters.warmup += 1;
        }
        if self.cfg.radar_period_s.is_none() {
            if let Some(prev) = self.last_radar_t {
                let d = t - prev;
                if d > 0.0 && d < 1.0 {
                    let p = self.radar_period.unwrap_or(d);
                    self.radar_period = Some(p + 0.1 * (d - p));
                }
            }
        }
        self.last_radar_t = Some(t);
        self.last_radar_host = Some(item.host_s);
        if self.radar.len() == self.radar.capacity() {
            if let Some(old) = self.radar.pop_front() {
                self.counters.dropped += 1;
                recycle(old);
            }
        }
        self.radar.push_back(item);
    }

    /// Takes an IMU sample.
    pub fn push_imu(&mut self, mut item: ImuItem) {
        let t = match item.t {
            Some(t) => t,
            None => {
                self.imu_clock.push(
                    item.sensor_s,
                    item.host_s - tx_s(item.bytes, self.cfg.imu_baud),
                );
                self.imu_clock.host(item.sensor_s)
            }
        };
        if let Some(prev) = self
            .imu
            .back()
            .map(|s| s.t.unwrap_or(t))
            .or(self.last_imu_t)
        {
            let d = t - prev;
            if d > 0.0 && d < 0.5 {
                let p = self.imu_period.unwrap_or(d);
                self.imu_period = Some(p + 0.05 * (d - p));
            }
        }
        item.t = Some(t);
        self.last_imu_seen = Some(self.last_imu_seen.map_or(t, |l| l.max(t)));
        tracing::trace!(t, sensor_s = item.sensor_s, host_s = item.host_s, "imu");
        if !self.clocks_ready() {
            self.counters.warmup += 1;
        }
        self.last_imu_host = Some(item.host_s);
        if self.imu.len() == self.imu.capacity() {
            self.imu.pop_front();
            self.counters.dropped += 1;
        }
        self.imu.push_back(item);
        self.unpreviewed = (self.unpreviewed + 1).min(self.imu.len());
    }

    fn stalls(&mut self, now: f64) {
        let start = *self.start_host.get_or_insert(now);
        // Sessions run on data time: the streams' own times on the common clock (host stamps of
        // the two streams lead each other by the radar's processing and transfer time).
        let (now, last_radar, last_imu) = if self.data_time {
            (now, self.last_radar_t, self.last_imu_seen)
        } else {
            (now, self.last_radar_host, self.last_imu_host)
        };
        let start = if self.data_time {
            now.min(start)
        } else {
            start
        };
        let margin = 0.05;
        let rm = self.cfg.radar_enabled
            && now - last_radar.unwrap_or(start)
                > self.cfg.stall_periods * self.radar_period() + margin;
        self.imu_silent_s = now - last_imu.unwrap_or(start);
        let im = self.cfg.imu_enabled
            && self.imu_silent_s > self.cfg.stall_periods * self.imu_period() + margin;
        if rm && !self.radar_missing {
            self.counters.radar_gaps += 1;
            tracing::warn!(now, "radar missing");
        }
        if im && !self.imu_missing {
            self.counters.imu_gaps += 1;
            tracing::warn!(now, "IMU missing");
        }
        if !rm && self.radar_missing {
            tracing::warn!(now, "radar back");
        }
        if !im && self.imu_missing {
            tracing::warn!(now, "IMU back");
        }
        self.radar_missing = rm;
        self.imu_missing = im;
    }

    /// Releases what can go at host time `now` \[s since the epoch\] (sessions: the feeder's
    /// watermark on the common clock), in order.
    pub fn poll(&mut self, now: f64, mut emit: impl FnMut(SyncOut)) {
        // Sessions: `now` is the feeder's watermark on the common clock (everything up to it has
        // been pushed), so a stream behind it by more than its stall time really has a gap.
        if !now.is_finite() {
            return;
        }
        self.stalls(now);
        if !self.clocks_ready() {
            // Times from a clock fit of a few pairs are not good enough to start on: hold
            // everything, then re-time it from the settled fits.
            return;
        }
        if !self.retimed && !self.offline_clock {
            self.retime();
        }
        let health = self.health();
        if self.cfg.preview_imu {
            let n = self.imu.len();
            for k in n - self.unpreviewed.min(n)..n {
                let s = self.imu[k];
                emit(SyncOut::Preview {
                    input: crate::estimator::ImuInput {
                        t: s.t.unwrap_or(0.0),
                        accel: s.accel,
                        gyro: s.gyro,
                        // Prediction only: the reading comes with the ordered sample.
                        pressure: None,
                    },
                    read_ns: s.read_ns,
                    health,
                });
            }
        }
        self.unpreviewed = 0;
        loop {
            // Radar frames the IMU passed before they arrived (late), or that cannot wait.
            if let Some(r) = self.radar.front() {
                let rt = r.t.unwrap_or(0.0);
                let late = self.imu_done_t.is_some_and(|ti| rt <= ti);
                // A frame waits for the IMU to pass it at most the hold time (and a frame
                // period): across a short gap in the IMU it then goes behind the first sample
                // after the gap, as offline, and the filter integrates the IMU over the gap
                // instead of dead-reckoning the frame from its Doppler alone. Once the IMU has
                // been silent for longer, frames go at once.
                let hold = self.cfg.max_hold_s + self.radar_period();
                let no_imu = !self.cfg.imu_enabled || now - rt > hold || self.imu_silent_s > hold;
                if late || (no_imu && self.imu.is_empty()) {
                    if let Some(item) = self.radar.pop_front() {
                        self.counters.radar_late += u64::from(late);
                        self.counters.radar += 1;
                        self.released_t = self.released_t.max(rt);
                        self.last_tick = now;
                        emit(SyncOut::Radar { item, health });
                        continue;
                    }
                }
            }
            let Some(s) = self.imu.front().copied() else {
                break;
            };
            let t = s.t.unwrap_or(0.0);
            let may = !self.cfg.radar_enabled
                || self.radar_missing
                || !self.radar.is_empty()
                || self.imu_done_t.is_none_or(|prev| {
                    self.last_radar_t
                        .is_some_and(|lr| prev < lr + 0.8 * self.radar_period())
                })
                || now - t > self.cfg.max_hold_s;
            if !may {
                break;
            }
            self.imu.pop_front();
            self.imu_done_t = Some(t);
            self.released_t = self.released_t.max(t);
            self.counters.imu += 1;
            emit(SyncOut::Imu {
                input: crate::estimator::ImuInput {
                    t,
                    accel: s.accel,
                    gyro: s.gyro,
                    pressure: pressure_at(&s, t),
                },
                read_ns: s.read_ns,
                health,
            });
            // Without a radar stream, empty frames at the radar period give the estimator its
            // radar-rate poses (IMU dead reckoning).
            if !self.cfg.radar_enabled && t - self.last_virtual >= self.radar_period() {
                self.last_virtual = t;
                self.virtual_frame = self.virtual_frame.wrapping_add(1);
                let item = Box::new(RadarItem {
                    host_s: s.host_s,
                    read_ns: s.read_ns,
                    frame_number: self.virtual_frame,
                    t: Some(t),
                    ..RadarItem::default()
                });
                self.counters.radar += 1;
                emit(SyncOut::Radar { item, health });
            }
            // Radar frames due at or before this sample go right after it (not counted late).
            while self.radar.front().is_some_and(|r| r.t.unwrap_or(0.0) <= t) {
                if let Some(item) = self.radar.pop_front() {
                    self.counters.radar += 1;
                    self.last_tick = now;
                    emit(SyncOut::Radar { item, health });
                }
            }
        }
        if self.radar_missing && now - self.last_tick >= self.radar_period() {
            self.last_tick = now;
            emit(SyncOut::Tick { t: now, health });
        }
    }

    /// Releases everything still held (end of stream), in order.
    pub fn flush(&mut self, mut emit: impl FnMut(SyncOut)) {
        let health = self.health();
        while !self.radar.is_empty() || !self.imu.is_empty() {
            let rt = self.radar.front().and_then(|r| r.t);
            let it = self.imu.front().and_then(|s| s.t);
            let radar_first = match (rt, it) {
                (Some(r), Some(_)) => self.imu_done_t.is_some_and(|ti| r <= ti),
                (Some(_), None) => true,
                _ => false,
            };
            if radar_first {
                if let Some(item) = self.radar.pop_front() {
                    self.counters.radar += 1;
                    emit(SyncOut::Radar { item, health });
                }
                continue;
            }
            let Some(s) = self.imu.pop_front() else {
                break;
            };
            let t = s.t.unwrap_or(0.0);
            self.imu_done_t = Some(t);
            self.counters.imu += 1;
            emit(SyncOut::Imu {
                input: crate::estimator::ImuInput {
                    t,
                    accel: s.accel,
                    gyro: s.gyro,
                    pressure: pressure_at(&s, t),
                },
                read_ns: s.read_ns,
                health,
            });
            while self.radar.front().is_some_and(|r| r.t.unwrap_or(0.0) <= t) {
                if let Some(item) = self.radar.pop_front() {
                    self.counters.radar += 1;
                    emit(SyncOut::Radar { item, health });
                }
            }
        }
    }
}

/// Rebuilds the order an offline feeder pushed a session's items in, and drives the
/// [`Synchroniser`] with it, item by item.
///
/// The feeder pushes both streams in time order (each radar frame before the first IMU sample
/// at or after its time) through two queues, so the thread on the other side sees them in
/// batches whose sizes depend on how the two threads interleave. Polled once per batch, at the
/// feeder's watermark, the synchroniser would judge stalls (a gap in the IMU) at whatever time
/// the batch happened to end, and its releases (and flags) would differ from run to run. Here
/// each item goes in at its feed time ([`ImuItem::fed_s`], [`RadarItem::fed_s`]), and the
/// synchroniser is polled at that time: what it releases depends on the session alone, as if it
/// ran in the feeder's thread.
#[derive(Debug)]
pub struct FeedOrder {
    imu: VecDeque<ImuItem>,
    radar: VecDeque<Box<RadarItem>>,
}

impl FeedOrder {
    /// Holds up to the queues' capacities without allocating.
    pub fn new(imu_capacity: usize, radar_capacity: usize) -> FeedOrder {
        FeedOrder {
            imu: VecDeque::with_capacity(imu_capacity),
            radar: VecDeque::with_capacity(radar_capacity),
        }
    }

    /// Takes an IMU sample as it came off its queue.
    pub fn push_imu(&mut self, s: ImuItem) {
        self.imu.push_back(s);
    }

    /// Takes a radar frame as it came off its queue.
    pub fn push_radar(&mut self, r: Box<RadarItem>) {
        self.radar.push_back(r);
    }

    /// Nothing is held.
    pub fn is_empty(&self) -> bool {
        self.imu.is_empty() && self.radar.is_empty()
    }

    /// Hands `sync` every held item fed at or before `upto` \[s\] (the feeder's watermark read
    /// before the queues were drained: everything fed up to it has been taken), in feed order (a
    /// radar frame before an IMU sample of the same time), polling it at each item's feed time.
    /// Items without a feed time (or a NaN one) go first.
    pub fn release(
        &mut self,
        upto: f64,
        sync: &mut Synchroniser,
        mut recycle: impl FnMut(Box<RadarItem>),
        mut emit: impl FnMut(SyncOut),
    ) {
        let fed = |t: Option<f64>| t.filter(|t| !t.is_nan()).unwrap_or(f64::NEG_INFINITY);
        loop {
            let ti = self.imu.front().map(|s| fed(s.fed_s));
            let tr = self.radar.front().map(|r| fed(r.fed_s));
            let radar_next = match (tr, ti) {
                (Some(r), Some(i)) => r <= i,
                (Some(_), None) => true,
                (None, _) => false,
            };
            let t = if radar_next { tr } else { ti };
            let Some(t) = t.filter(|&t| t <= upto) else {
                return;
            };
            if radar_next {
                if let Some(r) = self.radar.pop_front() {
                    sync.push_radar(r, &mut recycle);
                }
            } else if let Some(s) = self.imu.pop_front() {
                sync.push_imu(s);
            }
            if t.is_finite() {
                sync.poll(t, &mut emit);
            }
        }
    }
}

/// The barometer reading carried by `s` on the common clock: the sample's time `t` \[s\] less
/// the SampleTimeFine between reading and sample (one device clock).
fn pressure_at(s: &ImuItem, t: f64) -> Option<(f64, f64)> {
    s.pressure
        .map(|(sensor_s, pa)| (t - (s.sensor_s - sensor_s).max(0.0), pa))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A session's feed: IMU at 100 Hz for 3 s with a gap of `gap` \[s\] from 1.0 s, radar at
    /// 10 Hz from 0.05 s, in the feeder's order (each frame before the first sample at or after
    /// it).
    fn session(gap: f64) -> Vec<(bool, f64)> {
        let imu = (0..300)
            .map(|k| k as f64 * 0.01)
            .filter(|t| !(1.0..1.0 + gap - 1e-9).contains(t));
        let radar: Vec<f64> = (0..30).map(|k| 0.05 + k as f64 * 0.1).collect();
        let mut out = Vec::new();
        let mut next = 0;
        for t in imu {
            while next < radar.len() && radar[next] <= t {
                out.push((true, radar[next]));
                next += 1;
            }
            out.push((false, t));
        }
        out.extend(radar[next..].iter().map(|&t| (true, t)));
        out
    }

    /// What the synchroniser released (kind, time \[s\], health) when the feed arrives in
    /// batches of the given sizes, each released up to its last item's time (the watermark).
    fn released(gap: f64, batches: &[usize]) -> Vec<(char, f64, u16)> {
        let feed = session(gap);
        let mut sync = Synchroniser::new(SyncConfig {
            radar_period_s: Some(0.1),
            ..SyncConfig::default()
        });
        sync.offline_clock = true;
        sync.data_time = true;
        let mut order = FeedOrder::new(64, 8);
        let mut out = Vec::new();
        let mut emit = |ev: SyncOut| {
            out.push(match ev {
                SyncOut::Imu { input, health, .. } => ('i', input.t, health.0),
                SyncOut::Radar { item, health } => ('r', item.t.unwrap_or(f64::NAN), health.0),
                SyncOut::Tick { t, health } => ('t', t, health.0),
                SyncOut::Preview { input, health, .. } => ('p', input.t, health.0),
            })
        };
        let mut k = 0;
        for &n in batches.iter().cycle() {
            if k >= feed.len() {
                break;
            }
            let end = (k + n).min(feed.len());
            // The radar queue is drained after the IMU queue: within a batch, IMU samples come
            // first, as the thread takes them.
            let mut batch: Vec<_> = feed[k..end].to_vec();
            batch.sort_by_key(|x| x.0);
            for &(radar, t) in &batch {
                if radar {
                    order.push_radar(Box::new(RadarItem {
                        t: Some(t),
                        fed_s: Some(t),
                        ..RadarItem::default()
                    }));
                } else {
                    order.push_imu(ImuItem {
                        t: Some(t),
                        fed_s: Some(t),
                        ..ImuItem::default()
                    });
                }
            }
            let watermark = feed[end - 1].1;
            order.release(watermark, &mut sync, drop, &mut emit);
            k = end;
        }
        order.release(f64::INFINITY, &mut sync, drop, &mut emit);
        assert!(order.is_empty());
        sync.flush(&mut emit);
        out
    }

    #[test]
    fn what_a_session_releases_does_not_depend_on_how_the_feed_is_batched() {
        let one_by_one = released(0.6, &[1]);
        // Every item comes out once, the radar frames in the gap among them.
        assert_eq!(one_by_one.iter().filter(|e| e.0 == 'i').count(), 240);
        assert_eq!(one_by_one.iter().filter(|e| e.0 == 'r').count(), 30);
        // The gap is seen: the IMU is declared missing inside it.
        let missing = Health::IMU_MISSING.0;
        assert!(one_by_one.iter().any(|e| e.2 & missing != 0));
        for batches in [&[7][..], &[64], &[3, 50, 1, 120], &[1000]] {
            let got = released(0.6, batches);
            assert_eq!(got.len(), one_by_one.len(), "batches {batches:?}");
            for (a, b) in got.iter().zip(&one_by_one) {
                assert_eq!(a, b, "batches {batches:?}");
            }
        }
    }

    /// The kinds and times released between 0.9 s and 1.8 s.
    fn around_the_gap(out: &[(char, f64, u16)]) -> Vec<(char, f64)> {
        out.iter()
            .filter(|e| (0.9..1.8).contains(&e.1) && e.0 != 't')
            .map(|e| (e.0, (e.1 * 100.0).round() / 100.0))
            .collect()
    }

    #[test]
    fn frames_in_a_short_imu_gap_wait_for_it_and_a_long_gap_does_not_hold_them() {
        // 0.2 s without IMU (shorter than the hold, 0.25 s + a frame): the frames at 1.05 and
        // 1.15 s go right behind the first sample after the gap (1.2 s), as offline.
        let short = around_the_gap(&released(0.2, &[1]));
        let at = |x: &[(char, f64)], e: (char, f64)| x.iter().position(|&y| y == e).unwrap();
        let first_after = at(&short, ('i', 1.2));
        assert_eq!(at(&short, ('r', 1.05)), first_after + 1, "{short:?}");
        assert_eq!(at(&short, ('r', 1.15)), first_after + 2, "{short:?}");
        // 0.6 s without IMU: the frames go once it has been silent past the hold, before it
        // comes back at 1.6 s.
        let long = around_the_gap(&released(0.6, &[1]));
        let back = at(&long, ('i', 1.6));
        for f in [1.05, 1.15, 1.25, 1.35] {
            assert!(at(&long, ('r', f)) < back, "frame {f}: {long:?}");
        }
    }
}
