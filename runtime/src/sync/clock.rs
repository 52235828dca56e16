//! Sensor-clock alignment, online: each sensor clock is mapped to the host clock by a sliding-window
//! fit on the lower envelope of (sensor time, host time of the first byte) pairs, the online form of
//! [`milliego_session::streams::ClockFit`]. Host stamps only ever carry extra delay (UART, USB,
//! scheduling), so the earliest arrivals are the truth; a stamp far above the envelope is rejected
//! as late and never enters the window.

/// Settings of an [`OnlineClock`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockConfig {
    /// Pairs in the sliding window.
    pub window: usize,
    /// Pairs needed before the clock counts as synchronised.
    pub min_pairs: usize,
    /// Sensor-time span below which only the offset is fitted (rate 1) \[s\]: a short span
    /// cannot tell drift from jitter.
    pub min_rate_span_s: f64,
    /// A stamp later than the envelope by more than this is rejected \[s\].
    pub late_s: f64,
    /// After this many rejections in a row the window restarts (the clock jumped).
    pub restart_after: u32,
    /// Refit every this many accepted pairs.
    pub refit_every: u32,
}

impl Default for ClockConfig {
    fn default() -> Self {
        ClockConfig {
            window: 1024,
            min_pairs: 16,
            min_rate_span_s: 4.0,
            late_s: 0.02,
            restart_after: 50,
            refit_every: 1,
        }
    }
}

/// Online sensor-to-host clock map, `host = offset + rate * sensor`.
#[derive(Debug, Clone)]
pub struct OnlineClock {
    cfg: ClockConfig,
    ring: Vec<(f64, f64)>,
    head: usize,
    len: usize,
    keep: Vec<(f64, f64)>,
    scratch: Vec<f64>,
    offset: f64,
    rate: f64,
    fitted: bool,
    since_fit: u32,
    rejected_run: u32,
    /// Pairs accepted into the window.
    pub accepted: u64,
    /// Pairs rejected as late.
    pub rejected_late: u64,
    /// Window restarts after runs of rejections.
    pub restarts: u64,
}

impl OnlineClock {
    /// A clock with `cfg` (all buffers allocated here, none later).
    pub fn new(cfg: ClockConfig) -> Self {
        let w = cfg.window.max(2);
        OnlineClock {
            cfg,
            ring: vec![(0.0, 0.0); w],
            head: 0,
            len: 0,
            keep: Vec::with_capacity(w),
            scratch: Vec::with_capacity(w),
            offset: 0.0,
            rate: 1.0,
            fitted: false,
            since_fit: 0,
            rejected_run: 0,
            accepted: 0,
            rejected_late: 0,
            restarts: 0,
        }
    }

    /// True once enough pairs are in the window.
    pub fn synced(&self) -> bool {
        self.fitted && self.len >= self.cfg.min_pairs
    }

    /// Current map (offset \[s\], rate), if any pair was seen.
    pub fn map(&self) -> Option<(f64, f64)> {
        self.fitted.then_some((self.offset, self.rate))
    }

    /// Host time of a sensor time \[s\] (the identity shifted by the first pair before a fit).
    pub fn host(&self, sensor_s: f64) -> f64 {
        self.offset + self.rate * sensor_s
    }

    /// Adds a pair: sensor time \[s\] and host time at which the message STARTED arriving \[s\]
    /// (last-byte stamp less its transmission time). Returns false when rejected as late.
    pub fn push(&mut self, sensor_s: f64, host_s: f64) -> bool {
        if !(sensor_s.is_finite() && host_s.is_finite()) {
            return false;
        }
        if self.synced() && host_s - self.host(sensor_s) > self.cfg.late_s {
            self.rejected_late += 1;
            self.rejected_run += 1;
            if self.rejected_run < self.cfg.restart_after {
                return false;
            }
            self.restarts += 1;
            self.len = 0;
            self.fitted = false;
        }
        self.rejected_run = 0;
        let w = self.ring.len();
        self.ring[self.head] = (sensor_s, host_s);
        self.head = (self.head + 1) % w;
        self.len = (self.len + 1).min(w);
        self.accepted += 1;
        self.since_fit += 1;
        if !self.fitted || self.since_fit >= self.cfg.refit_every {
            self.refit();
        }
        true
    }

    fn refit(&mut self) {
        self.since_fit = 0;
        let w = self.ring.len();
        self.keep.clear();
        for k in 0..self.len {
            self.keep
                .push(self.ring[(self.head + w - self.len + k) % w]);
        }
        let Some((mut smin, mut smax)) = self.keep.first().map(|p| (p.0, p.0)) else {
            return;
        };
        for p in &self.keep {
            smin = smin.min(p.0);
            smax = smax.max(p.0);
        }
        let fit_rate = smax - smin >= self.cfg.min_rate_span_s;
        let mut fit = None;
        for _ in 0..4 {
            let Some(f) = fit_line(&self.keep, fit_rate) else {
                break;
            };
            fit = Some(f);
            // Keep the lower envelope: residuals at or below the 25th percentile.
            self.scratch.clear();
            self.scratch
                .extend(self.keep.iter().map(|(s, h)| h - (f.0 + f.1 * s)));
            let k = self.scratch.len() / 4;
            let (_, cut, _) = self.scratch.select_nth_unstable_by(k, f64::total_cmp);
            let cut = *cut;
            let before = self.keep.len();
            self.keep.retain(|(s, h)| h - (f.0 + f.1 * s) <= cut);
            if self.keep.len() < 2 || self.keep.len() == before {
                break;
            }
        }
        if let Some((o, r)) = fit {
            self.offset = o;
            self.rate = r;
            self.fitted = true;
        } else if let Some(&(s, h)) = self.keep.first() {
            // One pair: offset only.
            self.offset = h - s;
            self.rate = 1.0;
            self.fitted = true;
        }
    }
}

/// Least squares `host = offset + rate * sensor` (rate fixed at 1 unless `fit_rate`).
fn fit_line(p: &[(f64, f64)], fit_rate: bool) -> Option<(f64, f64)> {
    if p.is_empty() || (fit_rate && p.len() < 2) {
        return None;
    }
    let n = p.len() as f64;
    // Centred on the first sensor time for precision.
    let s0 = p[0].0;
    let ms = p.iter().map(|x| x.0 - s0).sum::<f64>() / n;
    let mh = p.iter().map(|x| x.1).sum::<f64>() / n;
    let rate = if fit_rate {
        let sss: f64 = p.iter().map(|x| (x.0 - s0 - ms).powi(2)).sum();
        if sss <= 0.0 {
            return None;
        }
        p.iter().map(|x| (x.0 - s0 - ms) * (x.1 - mh)).sum::<f64>() / sss
    } else {
        1.0
    };
    // host = mh + rate (s - s0 - ms)
    Some((mh - rate * (s0 + ms), rate))
}

/// Time on the wire of `bytes` at `baud` \[s\] (8N1: 10 bits a byte).
pub fn tx_s(bytes: usize, baud: u32) -> f64 {
    bytes as f64 * 10.0 / f64::from(baud.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_offset_and_drift_from_delayed_stamps() {
        let mut c = OnlineClock::new(ClockConfig::default());
        assert!(!c.synced());
        // 50 ppm drift, 2.5 s offset, delays 0..8 ms with a few 100 ms outliers.
        let mut seed = 1u64;
        for i in 0..2000 {
            let s = i as f64 * 0.01;
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (seed >> 11) as f64 / (1u64 << 53) as f64;
            let delay = if i % 97 == 5 { 0.1 } else { u * 0.008 };
            c.push(s, 2.5 + 1.00005 * s + delay);
            if i < 15 {
                assert!(!c.synced());
            }
        }
        assert!(c.synced());
        assert!(
            c.rejected_late > 10,
            "outliers rejected: {}",
            c.rejected_late
        );
        let (o, r) = c.map().unwrap();
        assert!((r - 1.00005).abs() < 2e-5, "rate {r}");
        assert!(
            (c.host(20.0) - (2.5 + 1.00005 * 20.0)).abs() < 1e-3,
            "offset {o}"
        );
    }
}
