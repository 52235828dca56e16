//! Near-field leakage, read from the points themselves.
//!
//! Some radars report returns within a metre or so at zero Doppler whatever the motion: TX-RX
//! coupling, reflections off the mount or the housing (a vehicle rig showed up to 24% of its
//! points there). A static point's Doppler is `-u . v` for its direction `u` and the radar's
//! velocity `v`; leakage reads 0. In the ego-velocity's consensus and least squares these points
//! pull the velocity towards zero (a robot at 0.4 m/s read 4% slow, its track 1.6 m short over
//! 24 m), and at low speed they outvote the static world for "at rest". Leaving every near point
//! at zero Doppler out of the vote is right for such a radar and wrong for one without leakage:
//! there the near points at zero Doppler are real static points abeam, and an atrium walk that
//! lost them went 3.2 -> 10 m (docs/odometry.md, "Near-field leakage").
//!
//! [`LeakageDetector`] asks the data. A point within [`LEAK_RANGE_M`] is *tested* when the
//! filter's prediction of the radar's velocity puts its static Doppler clear of the zero gate
//! (by [`LEAK_MARGIN_SIGMAS`] deviations of the prediction along its direction, and by the gate
//! itself: a static point there cannot read within the gate of 0) and the frame's own
//! ego-velocity puts it outside the gate too (its consensus would call a reading of 0 there an
//! outlier: a filter that lost its velocity, confidently wrong for seconds on an atrium walk,
//! does not get to test the static points against a motion the radar does not see). A tested
//! point that reads within the gate of 0 anyway is leakage or a non-static return. Without
//! leakage 0-31% of the tested points read 0 (median 16%: ghosts, multipath, the prediction's
//! own error; 74 simulated sessions of the benchmark's training and validation sets with 10
//! tested points or more); with 5-16% of all points leaking, 64-100% do. A CUSUM test of "at
//! most [`LEAK_P0`] at zero" against "[`LEAK_P1`]" decides: each tested point adds its
//! log-likelihood ratio, the sum is floored at 0 (leakage that begins late is still found), and
//! at [`LEAK_THRESHOLD`] the radar leaks: the near field is taken out of the vote from then on
//! ([`crate::ego_velocity::Config::near_field_m`]). A slow robot whose near points never have a
//! static Doppler clear of the gate tests none and keeps every point. Allocation-free and
//! deterministic for its input.

use crate::ego_velocity::Detection;
use nalgebra::{Matrix3, Vector3};

/// The near field examined, and left out of the vote once leakage is found \[m\].
pub const LEAK_RANGE_M: f32 = 1.0;
/// Share of the tested points at zero Doppler without leakage, at most (the CUSUM's null).
pub const LEAK_P0: f64 = 0.3;
/// Share of the tested points at zero Doppler with leakage (the CUSUM's alternative).
pub const LEAK_P1: f64 = 0.7;
/// The CUSUM's decision threshold, `ln(1000)`: with the shares above, 8 more tested points at
/// zero than off it since the sum was last at 0 (at a share of 0.3, about 1 in 1000 such runs
/// reaches it).
pub const LEAK_THRESHOLD: f64 = 6.91;
/// How far outside the zero gate a tested point's static Doppler must be, in deviations of the
/// prediction along its direction.
pub const LEAK_MARGIN_SIGMAS: f64 = 3.0;

/// Evidence for near-field leakage in a stream of radar frames.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LeakageDetector {
    tested: u32,
    zero: u32,
    cusum: f64,
    found: bool,
}

impl LeakageDetector {
    /// No evidence yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// One frame's points with the filter's prediction `prior` of the radar's velocity \[m/s,
    /// radar frame\] and its covariance \[m^2/s^2\], and the frame's own ego-velocity `frame`
    /// \[m/s, radar frame\] (see the module documentation for which points are tested).
    /// `zero_gate` \[m/s\] is the Doppler gate around 0
    /// ([`crate::ego_velocity::Config::inlier_threshold`]) and `min_range` \[m\] the range below
    /// which points are skipped. Returns whether the radar leaks (once found, it stays found).
    pub fn observe(
        &mut self,
        detections: &[Detection],
        prior: (&[f64; 3], &[[f64; 3]; 3]),
        frame: &[f64; 3],
        zero_gate: f64,
        min_range: f64,
    ) -> bool {
        if self.found {
            return true;
        }
        let v = Vector3::from(*prior.0);
        let c = Matrix3::from_fn(|i, j| prior.1[i][j]);
        let w = Vector3::from(*frame);
        if !v
            .iter()
            .chain(c.iter())
            .chain(w.iter())
            .all(|x| x.is_finite())
        {
            return false;
        }
        for d in detections {
            let p = d.position_m();
            let r = p.norm();
            if !(r.is_finite()
                && r >= min_range
                && r < f64::from(LEAK_RANGE_M)
                && d.radial_velocity.is_finite())
            {
                continue;
            }
            let u = p / r;
            let sd = (u.transpose() * c * u)[(0, 0)].max(0.0).sqrt();
            if u.dot(&v).abs() - LEAK_MARGIN_SIGMAS * sd <= 2.0 * zero_gate
                || u.dot(&w).abs() <= zero_gate
            {
                continue;
            }
            self.tested = self.tested.saturating_add(1);
            let at_zero = f64::from(d.radial_velocity.abs()) <= zero_gate;
            self.zero = self.zero.saturating_add(u32::from(at_zero));
            let llr = if at_zero {
                (LEAK_P1 / LEAK_P0).ln()
            } else {
                ((1.0 - LEAK_P1) / (1.0 - LEAK_P0)).ln()
            };
            self.cusum = (self.cusum + llr).max(0.0);
            if self.cusum >= LEAK_THRESHOLD {
                self.found = true;
                break;
            }
        }
        self.found
    }

    /// Whether the radar leaks.
    pub fn found(&self) -> bool {
        self.found
    }

    /// Near points tested so far, and how many of them read zero Doppler (counting stops once
    /// leakage is found).
    pub fn counts(&self) -> (u32, u32) {
        (self.tested, self.zero)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Radar moving forward (boresight +y) at 1 m/s, predicted to within 0.05 m/s.
    const V: [f64; 3] = [0.0, 1.0, 0.0];
    const C: [[f64; 3]; 3] = [[0.0025, 0.0, 0.0], [0.0, 0.0025, 0.0], [0.0, 0.0, 0.0025]];
    const GATE: f64 = 0.15;

    /// A point at `range` m in direction `az` (rad from boresight, in the horizontal plane),
    /// reading `vr` m/s.
    fn point(range: f32, az: f32, vr: f32) -> Detection {
        Detection {
            position: [range * az.sin(), range * az.cos(), 0.0],
            radial_velocity: vr,
        }
    }

    /// A static point's Doppler at 1 m/s forward.
    fn static_vr(az: f32) -> f32 {
        -az.cos()
    }

    /// One frame: far static points, and near points ahead that are static or leak (0 m/s).
    fn frame(k: usize, leaking: bool) -> Vec<Detection> {
        let mut f: Vec<Detection> = (0..8)
            .map(|i| {
                let az = -0.6 + 0.15 * i as f32;
                point(4.0 + i as f32, az, static_vr(az))
            })
            .collect();
        for j in 0..2 {
            let az = -0.3 + 0.3 * ((k + j) % 3) as f32;
            f.push(point(0.6, az, if leaking { 0.0 } else { static_vr(az) }));
        }
        f
    }

    fn run(d: &mut LeakageDetector, frames: usize, leaking: bool, v: [f64; 3]) -> bool {
        let mut found = false;
        for k in 0..frames {
            found = d.observe(&frame(k, leaking), (&v, &C), &v, GATE, 0.1);
        }
        found
    }

    #[test]
    fn near_points_at_zero_doppler_against_the_motion_are_leakage() {
        let mut d = LeakageDetector::new();
        assert!(!d.observe(&frame(0, true), (&V, &C), &V, GATE, 0.1));
        assert!(run(&mut d, 10, true, V));
        let (tested, zero) = d.counts();
        assert!(tested >= 8 && zero == tested, "{tested} {zero}");
        // Once found it stays found, whatever comes.
        assert!(run(&mut d, 50, false, V) && d.found());
    }

    #[test]
    fn near_static_points_and_a_few_ghosts_at_zero_are_not() {
        let mut d = LeakageDetector::new();
        for k in 0..400 {
            let mut f = frame(k, false);
            // One near ghost at zero Doppler every fourth frame: 1 in 9 tested points.
            if k % 4 == 0 {
                f.push(point(0.5, 0.1, 0.0));
            }
            assert!(!d.observe(&f, (&V, &C), &V, GATE, 0.1), "frame {k}");
        }
        let (tested, zero) = d.counts();
        assert!(tested > 800 && zero == 100, "{tested} {zero}");
    }

    #[test]
    fn leakage_that_begins_late_is_still_found() {
        let mut d = LeakageDetector::new();
        assert!(!run(&mut d, 500, false, V));
        assert!(run(&mut d, 10, true, V));
    }

    #[test]
    fn nothing_is_tested_when_the_motion_cannot_tell_leakage_from_a_static_point() {
        for (prior, frame_v, cov) in [
            // Slow: a static point's Doppler is within twice the gate of 0.
            ([0.0, 0.25, 0.0], [0.0, 0.25, 0.0], C),
            // The prediction too uncertain along the points' directions.
            (V, V, [[0.09, 0.0, 0.0], [0.0, 0.09, 0.0], [0.0, 0.0, 0.09]]),
            // The frame's own estimate says the points may read 0 (the filter lost its velocity).
            (V, [0.0, 0.1, 0.0], C),
        ] {
            let mut d = LeakageDetector::new();
            for k in 0..50 {
                assert!(!d.observe(&frame(k, true), (&prior, &cov), &frame_v, GATE, 0.1));
            }
            assert_eq!(d.counts(), (0, 0), "{prior:?} {frame_v:?}");
        }
        // Far points are never tested; nor are points inside the minimum range, or not finite.
        let mut d = LeakageDetector::new();
        for _ in 0..50 {
            let f = [
                point(1.5, 0.0, 0.0),
                point(0.05, 0.0, 0.0),
                point(0.5, 0.0, f32::NAN),
                Detection {
                    position: [f32::NAN, 0.5, 0.0],
                    radial_velocity: 0.0,
                },
            ];
            assert!(!d.observe(&f, (&V, &C), &V, GATE, 0.1));
        }
        assert_eq!(d.counts(), (0, 0));
        // A prediction that is not finite tests nothing.
        let bad = [f64::NAN, 1.0, 0.0];
        assert!(!d.observe(&frame(0, true), (&bad, &C), &V, GATE, 0.1));
        assert_eq!(d.counts(), (0, 0));
    }
}
