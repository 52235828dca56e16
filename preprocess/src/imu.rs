//! IMU samples between two radar frames -> a fixed-length window.
//!
//! The window holds `IMU_LEN` (20) rows `[ax, ay, az, gx, gy, gz]` (specific force \[m/s^2\], rate
//! of turn \[rad/s\], body frame, oldest first), linearly interpolated at the times
//! `t0 + (k + 1) (t1 - t0) / 20`, k = 0..19: the last row is at the current radar frame. Times are
//! on one clock (the IMU's sensor clock mapped to the session clock), so a device whose rate
//! differs from nominal, or a dropped sample, still gives rows at the right times.

use crate::IMU_LEN;

/// One IMU sample on the common clock, body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Time \[s\].
    pub t: f64,
    /// Specific force \[m/s^2\].
    pub accel: [f64; 3],
    /// Rate of turn \[rad/s\].
    pub gyro: [f64; 3],
}

/// Why a window could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ImuWindowError {
    /// The interval is empty, reversed or not finite.
    BadInterval {
        /// Start \[s\].
        t0: f64,
        /// End \[s\].
        t1: f64,
    },
    /// The samples do not reach over the interval (none before its first row or none after its
    /// last).
    NotCovered {
        /// First row time needed \[s\].
        from: f64,
        /// Last row time needed \[s\].
        to: f64,
        /// First sample time, if any \[s\].
        first: Option<f64>,
        /// Last sample time, if any \[s\].
        last: Option<f64>,
    },
    /// Two consecutive samples inside the interval are further apart than allowed.
    Gap {
        /// Time of the sample before the gap \[s\].
        at: f64,
        /// Length of the gap \[s\].
        gap_s: f64,
    },
}

impl core::fmt::Display for ImuWindowError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ImuWindowError::BadInterval { t0, t1 } => {
                write!(
                    f,
                    "IMU window interval {t0} s .. {t1} s is empty or not finite"
                )
            }
            ImuWindowError::NotCovered {
                from,
                to,
                first,
                last,
            } => write!(
                f,
                "IMU samples ({first:?} .. {last:?} s) do not cover the window {from} .. {to} s"
            ),
            ImuWindowError::Gap { at, gap_s } => {
                write!(
                    f,
                    "IMU gap of {:.1} ms after {at} s inside the window",
                    gap_s * 1e3
                )
            }
        }
    }
}

impl std::error::Error for ImuWindowError {}

/// Resamples `samples` (sorted by time) over (t0, t1\] into `out`. `max_gap_s`: the longest
/// allowed spacing of consecutive samples within the window.
pub fn resample(
    samples: &[ImuSample],
    t0: f64,
    t1: f64,
    max_gap_s: f64,
    out: &mut [[f32; 6]; IMU_LEN],
) -> Result<(), ImuWindowError> {
    if !(t0.is_finite() && t1.is_finite() && t1 > t0) {
        return Err(ImuWindowError::BadInterval { t0, t1 });
    }
    let dt = (t1 - t0) / IMU_LEN as f64;
    let from = t0 + dt;
    let not_covered = || ImuWindowError::NotCovered {
        from,
        to: t1,
        first: samples.first().map(|s| s.t),
        last: samples.last().map(|s| s.t),
    };
    // Index of the last sample at or before the first row, and of the first at or after t1.
    let lo = samples.partition_point(|s| s.t <= from);
    let hi = samples.partition_point(|s| s.t < t1);
    if lo == 0 || hi == samples.len() {
        return Err(not_covered());
    }
    let (lo, hi) = (lo - 1, hi);
    for w in samples[lo..=hi].windows(2) {
        let gap = w[1].t - w[0].t;
        if gap.is_nan() || gap > max_gap_s {
            return Err(ImuWindowError::Gap {
                at: w[0].t,
                gap_s: gap,
            });
        }
    }
    let mut j = lo;
    for (k, row) in out.iter_mut().enumerate() {
        let t = if k + 1 == IMU_LEN {
            t1
        } else {
            t0 + (k + 1) as f64 * dt
        };
        while j + 1 < samples.len() && samples[j + 1].t < t {
            j += 1;
        }
        let (a, b) = (&samples[j], &samples[(j + 1).min(samples.len() - 1)]);
        let span = b.t - a.t;
        let w = if span > 0.0 {
            ((t - a.t) / span).clamp(0.0, 1.0)
        } else {
            0.0
        };
        for i in 0..3 {
            row[i] = (a.accel[i] + w * (b.accel[i] - a.accel[i])) as f32;
            row[3 + i] = (a.gyro[i] + w * (b.gyro[i] - a.gyro[i])) as f32;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples of a linear signal: accel x = t, gyro z = 2 t, at `hz` from `t0`.
    fn ramp(t0: f64, n: usize, hz: f64) -> Vec<ImuSample> {
        (0..n)
            .map(|i| {
                let t = t0 + i as f64 / hz;
                ImuSample {
                    t,
                    accel: [t, 1.0, -9.81],
                    gyro: [0.0, 0.0, 2.0 * t],
                }
            })
            .collect()
    }

    #[test]
    fn linear_signals_are_reproduced_at_the_row_times() {
        let s = ramp(0.0, 200, 100.0);
        let mut w = [[0.0; 6]; IMU_LEN];
        resample(&s, 0.5, 0.75, 0.05, &mut w).unwrap();
        for (k, row) in w.iter().enumerate() {
            let t = 0.5 + (k + 1) as f64 * 0.25 / 20.0;
            assert!((f64::from(row[0]) - t).abs() < 1e-6, "row {k}: {row:?}");
            assert!((f64::from(row[5]) - 2.0 * t).abs() < 1e-6);
            assert_eq!(row[1], 1.0);
            assert_eq!(row[2], -9.81);
        }
        // The last row is at t1 exactly.
        assert!((f64::from(w[19][0]) - 0.75).abs() < 1e-7);
    }

    #[test]
    fn irregular_rates_give_rows_at_the_same_times() {
        // 87 Hz with a 1.3 ms offset: rows are still at the window's times.
        let s = ramp(0.0013, 300, 87.0);
        let mut w = [[0.0; 6]; IMU_LEN];
        resample(&s, 1.0, 1.2, 0.05, &mut w).unwrap();
        assert!((f64::from(w[0][0]) - 1.01).abs() < 1e-6);
        assert!((f64::from(w[19][0]) - 1.2).abs() < 1e-6);
    }

    #[test]
    fn uncovered_windows_and_gaps_are_reported() {
        let s = ramp(0.0, 100, 100.0); // 0 .. 0.99 s
        let mut w = [[0.0; 6]; IMU_LEN];
        assert!(matches!(
            resample(&s, 0.9, 1.1, 0.05, &mut w),
            Err(ImuWindowError::NotCovered { .. })
        ));
        assert!(matches!(
            resample(&s[10..], 0.0, 0.2, 0.05, &mut w),
            Err(ImuWindowError::NotCovered { .. })
        ));
        assert!(matches!(
            resample(&[], 0.0, 0.2, 0.05, &mut w),
            Err(ImuWindowError::NotCovered { .. })
        ));
        assert!(matches!(
            resample(&s, 0.5, 0.5, 0.05, &mut w),
            Err(ImuWindowError::BadInterval { .. })
        ));
        let mut holed = s.clone();
        holed.retain(|x| !(0.3..0.4).contains(&x.t));
        match resample(&holed, 0.25, 0.5, 0.05, &mut w) {
            Err(ImuWindowError::Gap { gap_s, .. }) => assert!((gap_s - 0.11).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        // The same hole outside the window does not matter.
        resample(&holed, 0.45, 0.7, 0.05, &mut w).unwrap();
    }
}
