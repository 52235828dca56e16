//! A learned relative motion (the milliEgo network's translation between two radar keyframes) as a
//! measurement of the radar-inertial filter, and the online check that decides whether to apply
//! such measurements at all.
//!
//! # Measurement
//!
//! The network says where the body at keyframe `to` is in the body frame at keyframe `from`
//! (translation `d` \[m\], over `dt = t_to - t_from` \[s\]). The filter keeps its body poses at
//! the radar frames ([`crate::runner::Runner`]), so both sides are mean world velocities over the
//! same interval:
//!
//! * learned: `v_m = R_wb(from) d / dt` (the filter's attitude at `from`);
//! * filter: `v_f = (p(to) - p(from)) / dt` (its own positions at the two keyframes).
//!
//! The innovation `v_m - v_f` is applied to the current velocity (Jacobian: identity on the
//! velocity error): the measurement comes at most one radar period after `to` and the filter's
//! velocity error changes slowly. Its covariance is `R_wb(from) diag(s^2) R_wb(from)^T / dt^2`
//! with the per-axis deviation `s_i = sqrt(base_std_m^2 + (scale_std |d|)^2 + (predicted_std
//! sigma_i)^2)`: an absolute part, a part growing with the distance (the network's error being
//! mostly one of scale) and, for a network with the uncertainty head, a part from its own
//! predicted deviation `sigma_i` of that window's translation along body axis i. Heading stays out
//! of the gain as for radar updates ([`crate::rio::RioConfig::radar_heading`]).
//!
//! The network's errors are not independent from one interval to the next, as the update assumes.
//! Where the radar covered an interval (or, for a ground vehicle, where the filter knows its
//! own motion: [`LearnedConfig::known_share`]), the network's residual against the filter, over
//! its stated deviation, measures that error; the update's covariance is widened by what those
//! residuals say ([`LearnedConfig::adapt_noise`], [`Calibration::noise_factor`]: per body axis
//! their mean square times `(1 + rho) / (1 - rho)` for their lag-1 correlation `rho`, the
//! largest over the axes, never below 1). The gate and the online check judge the stated
//! deviation.
//!
//! # Online consistency ([`Monitor`])
//!
//! Every measurement's normalised innovation square (NIS, 3 dof) is computed whether or not it is
//! applied. With the monitor on, measurements are applied until a window of
//! [`LearnedConfig::window`] of them is inconsistent: mean NIS over [`LearnedConfig::nis_max`]
//! or more than [`LearnedConfig::gated_max`] of them beyond the gate. Then they are off for good,
//! and the runtime's `auto` hands over to the Doppler filter it ran beside (the trajectory goes
//! on from the last pose: no new origin).

use std::collections::VecDeque;

/// Settings of the learned measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnedConfig {
    /// Absolute part of the per-axis translation deviation over one keyframe interval \[m\].
    pub base_std_m: f64,
    /// Part of the per-axis deviation proportional to the distance moved (unitless).
    pub scale_std: f64,
    /// Weight of the network's own predicted deviation ([`RelativeMotion::translation_std`]) in
    /// the per-axis deviation (unitless; 0: not used, and a measurement without one never uses it).
    pub predicted_std: f64,
    /// Chi-square gate (3 dof; 16.27 = 99.9%).
    pub gate: f64,
    /// Apply only while the recent measurements are consistent ([`Monitor`]).
    pub monitor: bool,
    /// Measurements the consistency check looks back over.
    pub window: usize,
    /// Largest mean NIS over the window (3 when consistent).
    pub nis_max: f64,
    /// Largest share of the window beyond the gate.
    pub gated_max: f64,
    /// Skip a measurement when the filter applied at least this many radar updates over its
    /// interval (the radar already saw the motion; 0: never skip).
    pub doppler_covers: u64,
    /// Calibrate the network's scale online against the filter: over intervals where the filter
    /// applied at least [`SCALE_COVERS`] radar updates (and a ground vehicle's known ones,
    /// [`LearnedConfig::known_share`]), the least-squares factor between the
    /// network's translation and the filter's (exponentially forgotten, [`SCALE_FORGET`]);
    /// every measurement is scaled by it (within [`SCALE_RANGE`]).
    pub calibrate_scale: bool,
    /// Calibrate the network's velocity offset online against the filter, over the same
    /// intervals as the scale: the forgotten mean ([`OFFSET_FORGET`]) of the network's mean
    /// velocity less the filter's, in the body frame at the interval's start, taken off every
    /// measurement. The network's errors are not white: on a held-out walk their correlation
    /// between consecutive intervals was 0.4-0.9 per axis, which a filter taking each
    /// measurement as independent cannot know; where the radar sees the motion, the part that
    /// persists is measured and removed, and where it does not, the last value holds. The
    /// online check ([`Monitor`]) judges each measurement before the offset is taken off (it
    /// would absorb a wrong axis convention too). Off by default (docs/model.md, "Fusion").
    pub calibrate_offset: bool,
    /// Widen the stated deviation by what the intervals the radar covered (and a ground
    /// vehicle's known ones, [`LearnedConfig::known_share`]) say of the network's error
    /// ([`Calibration::noise_factor`]): its variance and its correlation between consecutive
    /// intervals. A filter taking correlated measurements as
    /// independent trusts their mean too much: for errors with lag-1 correlation `rho` the mean
    /// of many has `(1 + rho) / (1 - rho)` times the variance that independence implies.
    pub adapt_noise: bool,
    /// For a ground vehicle ([`crate::rio::RioConfig::nonholonomic_std`] finite), an interval
    /// the radar did not cover calibrates too (scale, offset and noise, as above) when the
    /// filter knows its own motion there: its velocity deviation (the root mean of its three
    /// world velocity variances) times the interval's length is at most this share of the
    /// network's stated deviation (its smallest axis). A car's filter holds its lateral and
    /// vertical velocity by the constraint and integrates the rest from an IMU whose biases its
    /// rest measured; a radar tilted at the sky or a sparse outdoor scene covers few intervals,
    /// so without this the network's error there is never measured and it is trusted as stated.
    /// Not for other rigs: a walker's filter claimed to know its velocity through stretches of
    /// clutter-led radar velocities and the network's help there was lost (docs/model.md,
    /// "Fusion"). 0: covered intervals only.
    pub known_share: f64,
}

/// Radar updates over an interval for it to calibrate the scale, the offset and the noise
/// ([`LearnedConfig::calibrate_scale`], [`LearnedConfig::calibrate_offset`],
/// [`LearnedConfig::adapt_noise`]). Chosen on the validation sets (docs/model.md, "Fusion"): 2
/// lets a sparse outdoor scene, whose frames rarely give 4 velocities in a keyframe interval,
/// measure the network too.
pub const SCALE_COVERS: u64 = 2;
/// Forgetting factor of the scale calibration per interval (0.98: ~50 intervals, 12 s at 4 Hz).
pub const SCALE_FORGET: f64 = 0.98;
/// Squared distance \[m^2\] the calibration must have seen before it applies.
pub const SCALE_MIN_SUM_M2: f64 = 0.2;
/// The calibrated scale is kept within this range.
pub const SCALE_RANGE: (f64, f64) = (0.5, 2.0);
/// Forgetting factor of the offset calibration per interval (0.95: ~20 intervals, 5 s at 4 Hz;
/// the network's errors stay correlated over 1-2 s).
pub const OFFSET_FORGET: f64 = 0.95;
/// Intervals (forgotten weight) the offset calibration must have seen before it applies.
pub const OFFSET_MIN_WEIGHT: f64 = 5.0;

/// Forgetting factor of the noise estimate per interval ([`LearnedConfig::adapt_noise`]; 0.98:
/// ~50 intervals, 12 s at 4 Hz).
pub const NOISE_FORGET: f64 = 0.98;
/// Intervals (forgotten weight) the noise estimate must have seen before it applies.
pub const NOISE_MIN_WEIGHT: f64 = 10.0;
/// Largest lag-1 correlation the noise estimate takes (a factor of 9 from the correlation).
pub const NOISE_RHO_MAX: f64 = 0.8;
/// The factor on the learned measurements' covariance is kept within [1, this].
pub const NOISE_FACTOR_MAX: f64 = 25.0;

/// An exponentially forgotten mean: each push multiplies the sum and its weight by `forget` and
/// adds the value with weight 1, so a value pushed `k` pushes ago counts `forget^k` (the weight
/// settles at `1 / (1 - forget)`).
#[derive(Debug, Clone, Copy, Default)]
struct ForgottenMean<T> {
    sum: T,
    weight: f64,
}

impl<T> ForgottenMean<T>
where
    T: Copy
        + core::ops::Mul<f64, Output = T>
        + core::ops::Add<Output = T>
        + core::ops::Div<f64, Output = T>,
{
    fn push(&mut self, forget: f64, value: T) {
        self.sum = self.sum * forget + value;
        self.weight = forget * self.weight + 1.0;
    }

    /// The mean once the weight reached `min_weight`.
    fn mean(&self, min_weight: f64) -> Option<T> {
        (self.weight >= min_weight).then(|| self.sum / self.weight)
    }
}

/// The online calibration of the network against the filter: its scale
/// ([`LearnedConfig::calibrate_scale`]), velocity offset ([`LearnedConfig::calibrate_offset`]) and
/// noise ([`LearnedConfig::adapt_noise`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct Calibration {
    // The scale's forgotten sums of `learned . filter` and `|learned|^2` [m^2].
    num: f64,
    den: f64,
    // Residual velocities (body frame at `from`) [m/s].
    offset: ForgottenMean<nalgebra::Vector3<f64>>,
    // The normalised residual's square and the product of consecutive ones, per body axis, and
    // the last residual with the time it ended.
    noise_sq: ForgottenMean<nalgebra::Vector3<f64>>,
    noise_lag: ForgottenMean<nalgebra::Vector3<f64>>,
    last_residual: Option<(f64, nalgebra::Vector3<f64>)>,
}

impl Calibration {
    /// The factor to apply now (1 until enough distance was seen).
    pub fn scale(&self) -> f64 {
        if self.den < SCALE_MIN_SUM_M2 || !(self.num / self.den).is_finite() {
            return 1.0;
        }
        (self.num / self.den).clamp(SCALE_RANGE.0, SCALE_RANGE.1)
    }

    /// One interval: the network's translation `learned` and the filter's `filter` (same frame).
    pub fn push_scale(
        &mut self,
        learned: &nalgebra::Vector3<f64>,
        filter: &nalgebra::Vector3<f64>,
    ) {
        self.num = SCALE_FORGET * self.num + learned.dot(filter);
        self.den = SCALE_FORGET * self.den + learned.norm_squared();
    }

    /// The network's velocity offset to take off now \[m/s, body frame at `from`\] (zero until
    /// [`OFFSET_MIN_WEIGHT`] intervals were seen; [`LearnedConfig::calibrate_offset`]).
    pub fn offset(&self) -> nalgebra::Vector3<f64> {
        self.offset
            .mean(OFFSET_MIN_WEIGHT)
            .filter(|o| o.iter().all(|x| x.is_finite()))
            .unwrap_or_else(nalgebra::Vector3::zeros)
    }

    /// One interval the radar covered (or a vehicle's filter knew,
    /// [`LearnedConfig::known_share`]): the network's mean velocity over it (scaled, before the
    /// offset) less the filter's \[m/s, body frame at `from`\].
    pub fn push_offset(&mut self, residual_velocity: &nalgebra::Vector3<f64>) {
        if residual_velocity.iter().all(|x| x.is_finite()) {
            self.offset.push(OFFSET_FORGET, *residual_velocity);
        }
    }

    /// One interval the radar covered (or a vehicle's filter knew), from `t_from` to `t_to`
    /// \[s\]: the network's translation (scaled) less the filter's, per body axis, over the
    /// measurement's stated deviation
    /// ([`LearnedConfig::deviation`]; unitless). Consecutive intervals (the one ending where
    /// this one starts, within the keyframe tolerance of 1 ms) give the correlation.
    pub fn push_noise(&mut self, t_from: f64, t_to: f64, z: &nalgebra::Vector3<f64>) {
        if !(z.iter().all(|x| x.is_finite()) && t_from.is_finite() && t_to.is_finite()) {
            return;
        }
        self.noise_sq.push(NOISE_FORGET, z.component_mul(z));
        if let Some((t, prev)) = self.last_residual {
            if (t - t_from).abs() <= crate::runner::ANCHOR_TOLERANCE_S {
                self.noise_lag.push(NOISE_FORGET, z.component_mul(&prev));
            }
        }
        self.last_residual = Some((t_to, *z));
    }

    /// The factor on the learned measurements' stated covariance ([`LearnedConfig::adapt_noise`]):
    /// per body axis, the normalised residual's mean square `v` (1 when the stated deviation is
    /// right; it holds the filter's own error too, so it errs on the side of trusting the network
    /// less) times `(1 + rho) / (1 - rho)` for their lag-1 correlation `rho` (clamped to [0,
    /// [`NOISE_RHO_MAX`]]): the variance of a mean of many such residuals over what independent
    /// ones of the stated deviation would give; the largest over the axes. Within [1,
    /// [`NOISE_FACTOR_MAX`]] (the network is never trusted more than stated); 1 until
    /// [`NOISE_MIN_WEIGHT`] intervals were seen. Both
    /// moments are taken about zero: a lasting bias reads as correlation. The correlation alone
    /// does not widen: residuals well within the stated deviation that drift together (the
    /// filter's own slow error against a network that is right) stay at 1.
    pub fn noise_factor(&self) -> f64 {
        let Some(v) = self.noise_sq.mean(NOISE_MIN_WEIGHT) else {
            return 1.0;
        };
        let lag = self.noise_lag.mean(NOISE_MIN_WEIGHT);
        let f = (0..3)
            .map(|i| {
                let rho = match lag {
                    Some(lag) if v[i] > 0.0 => (lag[i] / v[i]).clamp(0.0, NOISE_RHO_MAX),
                    _ => 0.0,
                };
                v[i] * (1.0 + rho) / (1.0 - rho)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        if f.is_finite() {
            f.clamp(1.0, NOISE_FACTOR_MAX)
        } else {
            NOISE_FACTOR_MAX
        }
    }
}

impl Default for LearnedConfig {
    fn default() -> Self {
        LearnedConfig {
            // Chosen on the validation set of the benchmark split (docs/model.md, "Fusion").
            base_std_m: 0.15,
            scale_std: 0.3,
            predicted_std: 0.0,
            gate: 16.27,
            monitor: true,
            window: 40,
            nis_max: 6.0,
            gated_max: 0.2,
            doppler_covers: 0,
            calibrate_scale: true,
            calibrate_offset: false,
            adapt_noise: true,
            // Chosen on the validation sets (docs/model.md, "Fusion").
            known_share: 0.12,
        }
    }
}

/// A learned relative motion between two radar keyframes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeMotion {
    /// Time of the `from` keyframe (a radar frame's time on the IMU clock) \[s\].
    pub t_from: f64,
    /// Time of the `to` keyframe \[s\].
    pub t_to: f64,
    /// Body position at `to` in the body frame at `from` \[m\].
    pub translation: [f64; 3],
    /// The network's predicted standard deviation of `translation`, per body axis \[m\] (a model
    /// with the uncertainty head; `None` otherwise).
    pub translation_std: Option<[f64; 3]>,
}

impl LearnedConfig {
    /// The measurement's deviation per body axis over the interval \[m\] (before dividing by
    /// its length): see the module documentation. `d` is the (scaled) translation.
    pub fn deviation(
        &self,
        d: &nalgebra::Vector3<f64>,
        predicted: Option<[f64; 3]>,
    ) -> nalgebra::Vector3<f64> {
        let fixed = self.base_std_m.hypot(self.scale_std * d.norm());
        let p = match predicted {
            Some(p) if self.predicted_std > 0.0 && p.iter().all(|x| x.is_finite() && *x >= 0.0) => {
                p
            }
            _ => [0.0; 3],
        };
        nalgebra::Vector3::from(p.map(|x| fixed.hypot(self.predicted_std * x)))
    }
}

/// What became of one learned measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Applied; its NIS.
    Applied(f64),
    /// Beyond the chi-square gate; its NIS.
    Gated(f64),
    /// Within the gate but not applied: the online check failed earlier; its NIS.
    Suspended(f64),
    /// The body was at rest (the zero-velocity update stands in).
    AtRest,
    /// The radar updated the filter over the whole interval ([`LearnedConfig::doppler_covers`]).
    Covered,
    /// The filter has no pose at one of the keyframes (not started yet, or too long ago).
    NoAnchor,
    /// Not a usable measurement (interval not positive, values not finite).
    Invalid,
}

/// Counters of the learned measurements.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LearnedCounters {
    /// Measurements applied.
    pub applied: u64,
    /// Beyond the gate.
    pub gated: u64,
    /// Not applied because the online check had failed.
    pub suspended: u64,
    /// Skipped at rest.
    pub at_rest: u64,
    /// Skipped where the radar covered the interval.
    pub covered: u64,
    /// Without a filter pose at one keyframe.
    pub no_anchor: u64,
    /// Not usable.
    pub invalid: u64,
    /// Sum of the NIS of every evaluated measurement (applied, gated, suspended).
    pub nis_sum: f64,
    /// 1 once the online check switched the measurements off (for good).
    pub switched_off: u64,
}

impl LearnedCounters {
    /// Counts an outcome.
    pub fn count(&mut self, o: Outcome) {
        match o {
            Outcome::Applied(d) => {
                self.applied += 1;
                self.nis_sum += d;
            }
            Outcome::Gated(d) => {
                self.gated += 1;
                self.nis_sum += d;
            }
            Outcome::Suspended(d) => {
                self.suspended += 1;
                self.nis_sum += d;
            }
            Outcome::AtRest => self.at_rest += 1,
            Outcome::Covered => self.covered += 1,
            Outcome::NoAnchor => self.no_anchor += 1,
            Outcome::Invalid => self.invalid += 1,
        }
    }

    /// Mean NIS of the evaluated measurements (3 when their deviation is right).
    pub fn nis_mean(&self) -> Option<f64> {
        let n = self.applied + self.gated + self.suspended;
        (n > 0).then(|| self.nis_sum / n as f64)
    }
}

/// The online consistency check over the recent measurements' NIS: once a full window of them
/// is inconsistent, the measurements are off for good (the runtime's `auto` then hands over to a
/// Doppler filter that never took one; switching back and forth would apply a learned velocity
/// to a filter that drifted away from it meanwhile, and measured worse than either).
#[derive(Debug, Clone)]
pub struct Monitor {
    cfg: LearnedConfig,
    recent: VecDeque<f64>,
    failed: bool,
}

impl Monitor {
    /// A check with `cfg`'s window (none when [`LearnedConfig::monitor`] is off).
    pub fn new(cfg: LearnedConfig) -> Monitor {
        Monitor {
            cfg,
            recent: VecDeque::with_capacity(cfg.window.max(1)),
            failed: false,
        }
    }

    /// Whether measurements are applied: until the check fails.
    pub fn trusted(&self) -> bool {
        !self.failed
    }

    /// Records one evaluated measurement's NIS; returns true when this made the check fail.
    pub fn record(&mut self, nis: f64) -> bool {
        if !self.cfg.monitor || self.failed {
            return false;
        }
        let w = self.cfg.window.max(1);
        if self.recent.len() == w {
            self.recent.pop_front();
        }
        // A non-finite NIS counts as far beyond the gate.
        self.recent
            .push_back(if nis.is_finite() { nis } else { f64::MAX });
        self.failed = !self.consistent(w);
        self.failed
    }

    /// Whether the window of `w` measurements is consistent, or, while it is still filling,
    /// can still be: both bounds are on a full window's capped NIS sum and count beyond the
    /// gate, which only grow until it is full, so a first window already over either fails
    /// whatever comes next, and is judged at once instead of after `w` measurements, most of
    /// which would be applied.
    fn consistent(&self, w: usize) -> bool {
        let full = w as f64;
        // Each term capped at twice the gate: one wild value must not decide alone.
        let cap = 2.0 * self.cfg.gate;
        let sum = self.recent.iter().map(|d| d.min(cap)).sum::<f64>();
        let beyond = self.recent.iter().filter(|d| **d > self.cfg.gate).count() as f64;
        sum <= self.cfg.nis_max * full && beyond <= self.cfg.gated_max * full
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> LearnedConfig {
        LearnedConfig {
            window: 5,
            ..LearnedConfig::default()
        }
    }

    #[test]
    fn a_full_inconsistent_window_switches_off_for_good() {
        let mut m = Monitor::new(cfg());
        // A mean of 7 is inconsistent, but until the window is full it can still come down.
        for _ in 0..4 {
            assert!(!m.record(7.0));
            assert!(m.trusted());
        }
        assert!(m.record(7.0));
        assert!(!m.trusted());
        for _ in 0..10 {
            assert!(!m.record(1.0));
        }
        assert!(!m.trusted(), "no way back");
    }

    #[test]
    fn the_mean_and_the_share_beyond_the_gate_both_count() {
        // The mean of 2, 2, 2, 2 and 100 (capped at 32.5) is 8.1: over the default 6.
        let mut m = Monitor::new(cfg());
        for _ in 0..5 {
            m.record(2.0);
        }
        assert!(m.record(100.0));
        let mut m = Monitor::new(LearnedConfig {
            nis_max: 10.0,
            ..cfg()
        });
        for _ in 0..5 {
            m.record(2.0);
        }
        assert!(!m.record(100.0));
        assert!(m.trusted(), "one of five beyond the gate, mean 8.1 <= 10");
        assert!(m.record(100.0));
        assert!(!m.trusted(), "two of five beyond the gate");
    }

    #[test]
    fn a_high_mean_without_gated_values_is_inconsistent() {
        let mut m = Monitor::new(cfg());
        for _ in 0..4 {
            assert!(!m.record(7.0));
        }
        assert!(m.record(7.0));
        assert!(!m.trusted());
        let mut m = Monitor::new(cfg());
        for _ in 0..4 {
            m.record(1.0);
        }
        assert!(m.record(f64::NAN), "a non-finite NIS is beyond the gate");
    }

    #[test]
    fn a_first_window_bound_to_fail_switches_off_before_it_is_full() {
        // The shipped window of 40: at most 8 beyond the gate and a capped NIS sum of 240.
        let d = LearnedConfig::default();
        assert_eq!((d.window, d.nis_max, d.gated_max), (40, 6.0, 0.2));
        // Just beyond the gate: the ninth such measurement leaves no way to a consistent window.
        let mut m = Monitor::new(d);
        for k in 1..=8 {
            assert!(!m.record(17.0), "measurement {k}");
        }
        assert!(m.record(17.0), "the ninth beyond the gate");
        // Just within the gate: the sum passes 240 at the seventeenth (17 x 15 = 255).
        let mut m = Monitor::new(d);
        for k in 1..=16 {
            assert!(!m.record(15.0), "measurement {k}");
        }
        assert!(m.record(15.0), "the seventeenth");
        // Eight beyond the gate, then consistent ones: the full window passes, and so must
        // the partial ones on the way.
        let mut m = Monitor::new(d);
        for nis in [17.0; 8].into_iter().chain([1.0; 60]) {
            assert!(!m.record(nis));
        }
        assert!(m.trusted());
    }

    #[test]
    fn without_the_monitor_everything_is_trusted() {
        let mut m = Monitor::new(LearnedConfig {
            monitor: false,
            ..cfg()
        });
        assert!(m.trusted());
        assert!(!m.record(1e9));
        assert!(m.trusted());
    }

    #[test]
    fn counters_average_the_evaluated_measurements_only() {
        let mut c = LearnedCounters::default();
        assert_eq!(c.nis_mean(), None);
        c.count(Outcome::Applied(2.0));
        c.count(Outcome::Gated(20.0));
        c.count(Outcome::Suspended(5.0));
        c.count(Outcome::AtRest);
        c.count(Outcome::NoAnchor);
        assert_eq!(
            (c.applied, c.gated, c.suspended, c.at_rest, c.no_anchor),
            (1, 1, 1, 1, 1)
        );
        assert_eq!(c.nis_mean(), Some(9.0));
    }
}

#[cfg(test)]
mod deviation_tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_predicted_deviation_adds_per_axis_only_when_weighted_and_valid() {
        let d = Vector3::new(0.3, 0.0, 0.4); // 0.5 m
        let off = LearnedConfig::default();
        let fixed = off.base_std_m.hypot(off.scale_std * 0.5);
        let p = Some([0.2, 0.0, 1.0]);
        assert_eq!(
            off.deviation(&d, p),
            Vector3::repeat(fixed),
            "weight 0: not used"
        );
        assert_eq!(off.deviation(&d, None), Vector3::repeat(fixed));
        let on = LearnedConfig {
            predicted_std: 2.0,
            ..off
        };
        let s = on.deviation(&d, p);
        assert!((s.x - fixed.hypot(0.4)).abs() < 1e-12);
        assert!((s.y - fixed).abs() < 1e-12);
        assert!((s.z - fixed.hypot(2.0)).abs() < 1e-12);
        assert_eq!(on.deviation(&d, None), Vector3::repeat(fixed));
        for bad in [
            [f64::NAN, 0.1, 0.1],
            [0.1, -0.1, 0.1],
            [0.1, 0.1, f64::INFINITY],
        ] {
            assert_eq!(
                on.deviation(&d, Some(bad)),
                Vector3::repeat(fixed),
                "{bad:?} ignored"
            );
        }
    }
}

#[cfg(test)]
mod calibration_tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn the_offset_is_the_forgotten_mean_of_the_residuals_once_enough_were_seen() {
        let mut c = Calibration::default();
        let r = Vector3::new(0.4, -0.1, 0.0);
        // Less than OFFSET_MIN_WEIGHT of forgotten weight (5 intervals weigh 4.52): nothing
        // taken off yet.
        for _ in 0..5 {
            c.push_offset(&r);
            assert_eq!(c.offset(), Vector3::zeros());
        }
        c.push_offset(&r);
        assert!((c.offset() - r).norm() < 1e-12, "{:?}", c.offset());
        // A non-finite residual is skipped, not folded in.
        c.push_offset(&Vector3::new(f64::NAN, 0.0, 0.0));
        assert!((c.offset() - r).norm() < 1e-12);
        // The recent residuals weigh more: after many intervals of another offset the old one
        // is forgotten.
        let r2 = Vector3::new(-0.2, 0.0, 0.1);
        for _ in 0..200 {
            c.push_offset(&r2);
        }
        assert!((c.offset() - r2).norm() < 1e-3, "{:?}", c.offset());
        // The offset leaves the scale alone.
        assert_eq!(c.scale(), 1.0);
    }

    /// Residuals of an AR(1) process with lag-1 correlation `rho` and deviation `sigma`, pushed
    /// as consecutive intervals of 0.25 s from `t0` (seeded: the same every run).
    fn ar1(c: &mut Calibration, rho: f64, sigma: f64, n: usize, t0: f64) -> f64 {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
        // Sum of 12 uniforms less 6: mean 0, variance 1.
        let mut normal = move || (0..12).map(|_| rng.gen::<f64>()).sum::<f64>() - 6.0;
        let mut e = Vector3::new(normal(), normal(), normal()) * sigma;
        let k = (1.0 - rho * rho).sqrt();
        let mut t = t0;
        for _ in 0..n {
            e = e * rho + Vector3::new(normal(), normal(), normal()) * (sigma * k);
            c.push_noise(t, t + 0.25, &e);
            t += 0.25;
        }
        t
    }

    #[test]
    fn the_noise_factor_follows_the_residuals_variance_and_correlation() {
        let mut c = Calibration::default();
        assert_eq!(c.noise_factor(), 1.0);
        // Too few intervals: nothing applies yet, however large.
        for i in 0..9 {
            c.push_noise(
                f64::from(i) * 0.25,
                f64::from(i + 1) * 0.25,
                &Vector3::repeat(5.0),
            );
        }
        assert_eq!(c.noise_factor(), 1.0);

        // White residuals within their stated deviation: the stated covariance stands.
        let mut white = Calibration::default();
        ar1(&mut white, 0.0, 1.0, 2000, 0.0);
        let f = white.noise_factor();
        assert!((1.0..1.3).contains(&f), "white, unit variance: {f}");
        // Smaller than stated: never trusted more than stated (the correlation estimated over
        // ~50 intervals scatters about 0 by ~0.14).
        let mut small = Calibration::default();
        ar1(&mut small, 0.0, 0.3, 2000, 0.0);
        let f = small.noise_factor();
        assert!((1.0..1.3).contains(&f), "white, 0.3 of the deviation: {f}");
        // Twice the stated deviation, white: four times the variance.
        let mut wide = Calibration::default();
        ar1(&mut wide, 0.0, 2.0, 2000, 0.0);
        let f = wide.noise_factor();
        assert!((3.0..5.2).contains(&f), "white, twice the deviation: {f}");
        // Correlated at 0.6 with unit variance: (1 + 0.6) / (1 - 0.6) = 4.
        let mut corr = Calibration::default();
        ar1(&mut corr, 0.6, 1.0, 2000, 0.0);
        let f = corr.noise_factor();
        assert!((2.5..6.0).contains(&f), "correlated 0.6: {f}");
        // Correlated at 0.8 but 0.3 of the deviation: 0.09 x 9 = 0.81, within what is stated.
        let mut slow = Calibration::default();
        ar1(&mut slow, 0.8, 0.3, 2000, 0.0);
        let f = slow.noise_factor();
        assert!(
            (1.0..1.3).contains(&f),
            "correlated 0.8, 0.3 of the deviation: {f}"
        );
        // Correlated at 0.8 with half the deviation: 0.25 x 9 = 2.25.
        let mut half = Calibration::default();
        ar1(&mut half, 0.8, 0.5, 2000, 0.0);
        let f = half.noise_factor();
        assert!(
            (1.5..3.2).contains(&f),
            "correlated 0.8, half the deviation: {f}"
        );
        // A lasting bias reads as full correlation: the largest factor.
        let mut bias = Calibration::default();
        for i in 0..100 {
            let t = f64::from(i) * 0.25;
            bias.push_noise(t, t + 0.25, &Vector3::new(0.0, 3.0, 0.0));
        }
        assert_eq!(bias.noise_factor(), NOISE_FACTOR_MAX);
        // The same residuals over intervals that do not follow each other give no correlation:
        // only the variance (3 on one axis: a mean square of 9 there; the other axes' 0 do not
        // dilute it).
        let mut apart = Calibration::default();
        for i in 0..100 {
            let t = f64::from(i);
            apart.push_noise(t, t + 0.25, &Vector3::new(0.0, 3.0, 0.0));
        }
        assert!(
            (apart.noise_factor() - 9.0).abs() < 1e-9,
            "{}",
            apart.noise_factor()
        );
        // Non-finite residuals are skipped.
        let before = apart.noise_factor();
        apart.push_noise(200.0, 200.25, &Vector3::new(f64::NAN, 0.0, 0.0));
        assert_eq!(apart.noise_factor(), before);
        // The recent intervals weigh more: after white residuals the bias is forgotten.
        ar1(&mut bias, 0.0, 1.0, 1000, 25.0);
        assert!(bias.noise_factor() < 1.5, "{}", bias.noise_factor());
    }
}
