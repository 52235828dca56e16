//! The sensor clock: frame numbers and the wrapping 32-bit CPU cycle counter.
//!
//! timeCpuCycles counts at 200 MHz on SDK 3.x (R4F PMU; wraps every ~21.5 s) and at 600 MHz on
//! SDK 1.x/2.x xWR16xx builds (DSP; wraps every ~7.2 s). [`CycleUnwrapper`] turns it into a
//! monotonic 64-bit count. When the frame period is known, a gap of several frames (even longer
//! than a wrap) is unwrapped with the frame counter's help instead of being guessed.

use crate::frame::Header;

/// Rate of timeCpuCycles for a header \[Hz\]: 600 MHz for SDK 1/2 on xWR16xx, 200 MHz otherwise.
pub fn cpu_clock_hz(header: &Header) -> u32 {
    if header.version.major() < 3 && header.platform & 0xFFFF == 0x1642 {
        600_000_000
    } else {
        200_000_000
    }
}

/// A frame's place on the sensor clock.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorTime {
    /// Frame counter as sent.
    pub frame_number: u32,
    /// Unwrapped CPU cycle count since the first frame seen (None when the layout has no cycle
    /// counter).
    pub cycles: Option<u64>,
    /// Seconds since the first frame seen, from the unwrapped cycles \[s\].
    pub seconds: Option<f64>,
}

/// Unwraps the 32-bit cycle counter into a monotonic count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleUnwrapper {
    rate_hz: u32,
    frame_period_cycles: Option<u64>,
    first: Option<u32>,
    last: Option<(u32, u64)>,
}

impl CycleUnwrapper {
    /// An unwrapper for a counter at `rate_hz`. With `frame_period_s` (from the .cfg), gaps of any
    /// length are unwrapped from the frame-number delta; without it, consecutive stamps are
    /// assumed less than one wrap apart.
    pub fn new(rate_hz: u32, frame_period_s: Option<f64>) -> Self {
        let frame_period_cycles = frame_period_s
            .filter(|p| p.is_finite() && *p > 0.0)
            .map(|p| (p * f64::from(rate_hz)) as u64);
        CycleUnwrapper {
            rate_hz,
            frame_period_cycles,
            first: None,
            last: None,
        }
    }

    /// Counter rate \[Hz\].
    pub fn rate_hz(&self) -> u32 {
        self.rate_hz
    }

    /// Feeds one frame's stamp and returns its sensor time.
    pub fn push(&mut self, frame_number: u32, cycles: u32) -> SensorTime {
        const WRAP: u64 = 1 << 32;
        let unwrapped = match self.last {
            None => {
                self.first = Some(cycles);
                u64::from(cycles)
            }
            Some((last_frame, last)) => {
                let base = last - last % WRAP;
                let mut candidate = base + u64::from(cycles);
                if candidate < last {
                    candidate += WRAP;
                }
                if let Some(period) = self.frame_period_cycles {
                    let frames = u64::from(frame_number.wrapping_sub(last_frame));
                    let expected = last + frames.saturating_mul(period);
                    // Pick the number of wraps that lands closest to the expected time.
                    while candidate + WRAP / 2 < expected {
                        candidate += WRAP;
                    }
                }
                candidate
            }
        };
        self.last = Some((frame_number, unwrapped));
        let origin = u64::from(self.first.unwrap_or(0));
        let since = unwrapped - origin;
        SensorTime {
            frame_number,
            cycles: Some(since),
            seconds: Some(since as f64 / f64::from(self.rate_hz)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_forward_without_period() {
        let mut u = CycleUnwrapper::new(200_000_000, None);
        assert_eq!(u.push(1, u32::MAX - 10).cycles, Some(0));
        assert_eq!(u.push(2, 5).cycles, Some(16));
        assert_eq!(u.push(3, 100).cycles, Some(111));
    }

    #[test]
    fn long_gap_uses_frame_period() {
        // 100 ms frames at 200 MHz = 20e6 cycles; a gap of 500 frames = 50 s = 2.33 wraps.
        let mut u = CycleUnwrapper::new(200_000_000, Some(0.1));
        u.push(1, 1000);
        let expected = 1000u64 + 500 * 20_000_000;
        let t = u.push(501, (expected % (1 << 32)) as u32);
        assert_eq!(t.cycles, Some(expected - 1000));
        assert!((t.seconds.unwrap() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn rate_follows_sdk_and_platform() {
        let mut h = crate::frame::Header {
            layout: crate::Layout::Oob40,
            version: crate::frame::Version(0x0200_0004),
            total_len: 64,
            platform: 0xA1642,
            frame_number: 1,
            subframe: Some(0),
            time_cpu_cycles: Some(0),
            num_detected_obj: Some(0),
            num_tlvs: 0,
            checksum: None,
            lab_timing: None,
        };
        assert_eq!(cpu_clock_hz(&h), 600_000_000);
        h.version = crate::frame::Version(0x0300_0000);
        assert_eq!(cpu_clock_hz(&h), 200_000_000);
        h.version = crate::frame::Version(0x0200_0004);
        h.platform = 0xA1843;
        assert_eq!(cpu_clock_hz(&h), 200_000_000);
    }
}
