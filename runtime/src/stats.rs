//! Latency histograms with fixed log buckets: recording allocates nothing, quantiles are within
//! 1/16 (about 6%) of the true value.

/// Sub-buckets per power of two.
const SUB: usize = 16;
/// Powers of two covered: 1 ns up to 2^40 ns (about 18 minutes).
const OCTAVES: usize = 40;

/// Histogram of durations \[ns\].
#[derive(Clone)]
pub struct Histogram {
    counts: Box<[u64; SUB * OCTAVES]>,
    n: u64,
    max: u64,
    sum: u128,
}

impl std::fmt::Debug for Histogram {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Histogram")
            .field("n", &self.n)
            .field("p50", &self.quantile(0.5))
            .field("p99", &self.quantile(0.99))
            .finish()
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            counts: Box::new([0; SUB * OCTAVES]),
            n: 0,
            max: 0,
            sum: 0,
        }
    }
}

fn bucket(v: u64) -> usize {
    if v < SUB as u64 {
        return v as usize;
    }
    let octave = 63 - v.leading_zeros() as usize; // >= 4
    let shift = octave - 4; // SUB = 16 = 2^4
    let sub = ((v >> shift) as usize) & (SUB - 1);
    ((octave - 3) * SUB + sub).min(SUB * OCTAVES - 1)
}

fn bucket_mid(b: usize) -> u64 {
    if b < SUB {
        return b as u64;
    }
    let octave = b / SUB + 3;
    let sub = (b % SUB) as u64;
    let shift = octave - 4;
    let lo = (SUB as u64 + sub) << shift;
    lo + (1u64 << shift) / 2
}

impl Histogram {
    /// Records one duration \[ns\].
    pub fn record(&mut self, ns: u64) {
        self.counts[bucket(ns)] += 1;
        self.n += 1;
        self.max = self.max.max(ns);
        self.sum += u128::from(ns);
    }

    /// Records a duration in seconds (negative values count as 0).
    pub fn record_s(&mut self, s: f64) {
        self.record((s.max(0.0) * 1e9) as u64);
    }

    /// Durations recorded.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Longest duration \[ns\].
    pub fn max(&self) -> u64 {
        self.max
    }

    /// Mean \[ns\] (0 when empty).
    pub fn mean(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.sum as f64 / self.n as f64
        }
    }

    /// The `q` quantile (0..=1) \[ns\], None when empty.
    pub fn quantile(&self, q: f64) -> Option<u64> {
        if self.n == 0 {
            return None;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.n as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (b, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(bucket_mid(b).min(self.max));
            }
        }
        Some(self.max)
    }

    /// Adds another histogram's counts.
    pub fn merge(&mut self, o: &Histogram) {
        for (a, b) in self.counts.iter_mut().zip(o.counts.iter()) {
            *a += b;
        }
        self.n += o.n;
        self.max = self.max.max(o.max);
        self.sum += o.sum;
    }

    /// The histogram's count, quantiles and mean \[ms\], as the run summary reports them.
    pub fn summary(&self) -> crate::summary::HistogramSummary {
        let ms = |v: Option<u64>| v.map(|v| v as f64 * 1e-6);
        crate::summary::HistogramSummary {
            count: self.n,
            p50_ms: ms(self.quantile(0.5)),
            p99_ms: ms(self.quantile(0.99)),
            max_ms: ms((self.n > 0).then_some(self.max)),
            mean_ms: self.mean() * 1e-6,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_within_bucket_resolution() {
        let mut h = Histogram::default();
        for v in 1..=10_000u64 {
            h.record(v * 1000); // 1 us .. 10 ms
        }
        let p50 = h.quantile(0.5).unwrap() as f64;
        let p99 = h.quantile(0.99).unwrap() as f64;
        assert!((p50 / 5.0e6 - 1.0).abs() < 1.0 / 16.0, "{p50}");
        assert!((p99 / 9.9e6 - 1.0).abs() < 1.0 / 16.0, "{p99}");
        assert_eq!(h.max(), 10_000_000);
        assert_eq!(h.count(), 10_000);
        assert_eq!(Histogram::default().quantile(0.5), None);
        for v in [0u64, 1, 15, 16, 17, 1000, 123_456_789, u64::MAX / 2] {
            let b = bucket(v);
            let m = bucket_mid(b) as f64;
            if b < SUB * OCTAVES - 1 {
                assert!(
                    (m - v as f64).abs() <= (v as f64 / 16.0).max(0.5),
                    "{v} -> {m}"
                );
            }
        }
    }
}
