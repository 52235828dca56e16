//! The Doppler quantisation step, read from the radial velocities themselves.
//!
//! A TI radar reports a point's radial velocity as its Doppler bin times the velocity
//! resolution, so the values of a stream lie on a lattice `n x step`. The ego-velocity's inlier
//! gate and noise floor need that step ([`crate::ego_velocity::Config::doppler_step`]), and the
//! `.cfg` does not always tell it: a firmware or driver that reports Doppler coarser than its
//! bins (the 0.49 m/s steps of a vehicle rig's IWR6843), a compressed point cloud with its own
//! unit, or a recording whose `.cfg` is missing or belongs to another configuration. A gate
//! narrower than the rounding rejects the static world (half a 0.42 m/s step is 0.21 m/s against
//! a 0.12 m/s gate) and the frames fall back to the IMU alone.
//!
//! [`DopplerLattice`] keeps the latest [`LATTICE_VALUES`] non-zero magnitudes and finds the
//! largest step whose multiples hold [`LATTICE_SHARE`] of them within [`LATTICE_TOLERANCE`] of a
//! step. Continuous Doppler (interpolated, or imported from a driver that smooths) has no such
//! step and gives none: the configured step stays. Allocation-free, deterministic for its input.

use crate::ego_velocity::Detection;

/// Non-zero radial-velocity magnitudes kept (the most recent).
pub const LATTICE_VALUES: usize = 256;
/// Fewest non-zero magnitudes before a step is decided.
pub const LATTICE_MIN_VALUES: usize = 64;
/// Share of the kept magnitudes that must lie on the lattice.
pub const LATTICE_SHARE: f64 = 0.95;
/// How far from a multiple of the step a magnitude may lie, in steps: float rounding, and TI's
/// compressed point clouds, whose values are multiples of their own unit (0.06972 and 0.13916
/// m/s in one capture, on a step of 0.0696). Wide enough for those, narrow enough that a finer
/// lattice does not take in off-lattice values by chance.
pub const LATTICE_TOLERANCE: f64 = 0.03;
/// Magnitudes below this are zero Doppler \[m/s\] (they lie on every lattice).
const ZERO_MPS: f32 = 1e-4;
/// Largest divisor of a candidate magnitude tried: a stream whose smallest value is two or
/// three steps (no point ever in the first bin) still shows its step.
const MAX_DIVISOR: u32 = 3;
/// Smallest distinct magnitudes tried as (multiples of) the step.
const CANDIDATES: usize = 4;

/// The Doppler step of a stream of radar frames.
#[derive(Debug, Clone)]
pub struct DopplerLattice {
    values: [f32; LATTICE_VALUES],
    len: usize,
    next: usize,
    step: Option<f64>,
}

impl Default for DopplerLattice {
    fn default() -> Self {
        DopplerLattice {
            values: [0.0; LATTICE_VALUES],
            len: 0,
            next: 0,
            step: None,
        }
    }
}

impl DopplerLattice {
    /// No values seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes one frame's points; returns the step \[m/s\] the stream shows so far, if any.
    pub fn observe(&mut self, detections: &[Detection]) -> Option<f64> {
        let mut added = false;
        for d in detections {
            let v = d.radial_velocity.abs();
            if v.is_finite() && v > ZERO_MPS {
                self.values[self.next] = v;
                self.next = (self.next + 1) % LATTICE_VALUES;
                self.len = (self.len + 1).min(LATTICE_VALUES);
                added = true;
            }
        }
        if added && self.len >= LATTICE_MIN_VALUES {
            self.step = lattice_step(&self.values[..self.len]);
        }
        self.step
    }

    /// The step found so far \[m/s\].
    pub fn step(&self) -> Option<f64> {
        self.step
    }
}

/// The largest step whose multiples hold [`LATTICE_SHARE`] of the magnitudes of `values` (at most
/// [`LATTICE_VALUES`] are looked at). Candidates: each of the 4 smallest distinct
/// magnitudes divided by 1, 2 or 3 (one stray small value does not hide the step; a stream whose
/// smallest value is two or three steps still shows it), each refined by least squares over the
/// values on its lattice.
pub fn lattice_step(values: &[f32]) -> Option<f64> {
    let values = &values[..values.len().min(LATTICE_VALUES)];
    let mut sorted = [0f32; LATTICE_VALUES];
    let sorted = &mut sorted[..values.len()];
    for (s, v) in sorted.iter_mut().zip(values) {
        *s = v.abs();
    }
    sorted.sort_unstable_by(f32::total_cmp);
    let on = |q: f64, v: f32| {
        let x = f64::from(v.abs()) / q;
        let n = x.round();
        (n >= 1.0 && (x - n).abs() <= LATTICE_TOLERANCE).then_some(n)
    };
    let mut best: Option<f64> = None;
    let mut last = 0f32;
    let mut tried = 0;
    for &smallest in sorted.iter() {
        if tried == CANDIDATES {
            break;
        }
        // Distinct: more than the tolerance above the last candidate.
        if !(smallest.is_finite() && smallest > ZERO_MPS)
            || (tried > 0 && smallest <= last * (1.0 + LATTICE_TOLERANCE as f32))
        {
            continue;
        }
        tried += 1;
        last = smallest;
        for k in 1..=MAX_DIVISOR {
            let mut q = f64::from(smallest) / f64::from(k);
            if best.is_some_and(|b| q <= b) {
                continue;
            }
            // Least squares over the values on the lattice: the step as the values average
            // it, not as one of them rounds it.
            for _ in 0..2 {
                let (mut snv, mut snn) = (0.0, 0.0);
                for &v in values.iter() {
                    if let Some(n) = on(q, v) {
                        snv += n * f64::from(v.abs());
                        snn += n * n;
                    }
                }
                if snn > 0.0 {
                    q = snv / snn;
                }
            }
            let count = values.iter().filter(|&&v| on(q, v).is_some()).count();
            if count as f64 >= LATTICE_SHARE * values.len() as f64 && best.is_none_or(|b| q > b) {
                best = Some(q);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(vs: &[f32]) -> Vec<Detection> {
        vs.iter()
            .map(|&v| Detection {
                position: [1.0, 2.0, 0.0],
                radial_velocity: v,
            })
            .collect()
    }

    /// A deterministic spread of radial velocities in about ±2 m/s.
    fn spread(n: usize, seed: u32) -> Vec<f32> {
        let mut x = seed.wrapping_mul(2_654_435_761).max(1);
        (0..n)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (f64::from(x) / f64::from(u32::MAX) * 4.0 - 2.0) as f32
            })
            .collect()
    }

    fn quantised(vs: &[f32], step: f32) -> Vec<f32> {
        vs.iter().map(|v| (v / step).round() * step).collect()
    }

    #[test]
    fn a_coarse_step_is_found_and_continuous_doppler_gives_none() {
        for step in [0.134f32, 0.42, 0.49, 0.0697] {
            let mut l = DopplerLattice::new();
            let vs = quantised(&spread(400, 7), step);
            let mut got = None;
            for f in vs.chunks(10) {
                got = l.observe(&frame(f));
            }
            let got = got.unwrap_or_else(|| panic!("no step found for {step}"));
            assert!((got - f64::from(step)).abs() < 1e-4, "{step}: {got}");
        }
        let mut l = DopplerLattice::new();
        for f in spread(1000, 3).chunks(10) {
            assert_eq!(l.observe(&frame(f)), None);
        }
    }

    #[test]
    fn the_step_is_found_when_no_value_is_in_the_first_bin() {
        // Only even and odd multiples from the second bin up: the smallest value is 2 steps.
        let step = 0.3f32;
        let vs: Vec<f32> = spread(300, 11)
            .iter()
            .map(|v| {
                let n = (v / step).round();
                let n = if n.abs() < 2.0 { 2.0 * v.signum() } else { n };
                n * step
            })
            .collect();
        let got = lattice_step(&vs).expect("step");
        assert!((got - 0.3).abs() < 1e-4, "{got}");
    }

    #[test]
    fn a_few_off_lattice_values_do_not_hide_the_step_and_many_do() {
        let step = 0.42f32;
        let mut vs: Vec<f32> = quantised(&spread(LATTICE_VALUES, 5), step)
            .into_iter()
            .filter(|v| v.abs() > 1e-3)
            .collect();
        vs.truncate(200);
        // 3% off the lattice: found.
        for v in vs.iter_mut().take(6) {
            *v += 0.1;
        }
        assert!(lattice_step(&vs).is_some());
        // 10% off: not a lattice.
        for v in vs.iter_mut().take(20).skip(6) {
            *v += 0.1;
        }
        assert_eq!(lattice_step(&vs), None);
    }

    #[test]
    fn zero_doppler_does_not_count_and_too_few_values_decide_nothing() {
        let mut l = DopplerLattice::new();
        // A stream at rest: all zero, nothing decided.
        for _ in 0..100 {
            assert_eq!(l.observe(&frame(&[0.0; 10])), None);
        }
        let vs = quantised(&spread(LATTICE_MIN_VALUES - 1, 9), 0.42);
        let vs: Vec<f32> = vs.into_iter().map(|v| v.abs().max(0.42)).collect();
        assert_eq!(l.observe(&frame(&vs)), None);
        assert!(l.observe(&frame(&[0.84])).is_some());
        // Not finite: skipped.
        assert!(l.observe(&frame(&[f32::NAN, f32::INFINITY])).is_some());
    }
}
