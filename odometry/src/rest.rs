//! Rest detection from the IMU and the radar together.
//!
//! The IMU alone cannot tell rest from steady motion: a robot cruising straight at 0.5 m/s reads
//! gravity and a constant rate of turn, just as it does parked. A static scene's Doppler can: at
//! rest its points have zero Doppler. Each radar frame gives a verdict:
//!
//! * still: at least [`RestConfig::zero_doppler_share_min`] of its points have zero Doppler
//!   (within the Doppler noise) and its ego-velocity is consistent with zero under its own
//!   covariance (chi-square, 3 dof, 99.9%);
//! * moving: its ego-velocity is inconsistent with zero, or fewer than
//!   [`RestConfig::moving_share_max`] of its points have zero Doppler, with or without an
//!   ego-velocity, and so few that rest would show that few less than
//!   [`RestConfig::moving_share_alpha`] of the time (binomial, each point static with
//!   probability [`RestConfig::zero_doppler_share_min`]): 1 of 8 points at zero Doppler is what
//!   a sparse scene at rest shows every few frames, 0 of 20 is motion;
//! * no verdict otherwise. A radar in a horizontal fan hardly sees
//!   vertical velocity (0.1-0.5 m/s vertical noise at rest in the simulator), so the estimate's
//!   size alone cannot call rest.
//!
//! Rest starts when the IMU is still (over the last [`RestConfig::window_s`] the spread, square
//! root of the covariance trace, of the specific force is below [`RestConfig::accel_std_max`]
//! and that of the rate of turn below [`RestConfig::gyro_std_max`]; the mean rate is below
//! [`RestConfig::gyro_rate_max`] and the mean specific force is gravity within
//! [`RestConfig::gravity_tolerance`]) and the latest verdict, at most
//! [`RestConfig::radar_max_age_s`] old, is still. It lasts while the IMU stays still and no frame
//! says moving: single frames with too much multipath do not break it.
//!
//! The start is the exception: the filter is levelled on the assumption that the rig starts at
//! rest, and until the IMU first moves or a frame says moving nothing contradicts it, so frames
//! without a verdict (too few points, no consensus: a sparse outdoor scene, a radar tilted up)
//! do not keep that first rest from counting once a frame is in ([`RestDetector::push_radar`]),
//! and the filter's velocity does not refute it (the filter starts from it: what it holds then
//! came from a radar frame, and at the very start a ghost consensus has no prior to stop it). A
//! start in motion ends it at once: the IMU is not still, or two frames in a row see the motion.
//!
//! A walker's stop is the other exception ([`RestConfig::gait_accel_std`]): a walker's IMU is
//! never still while it walks, so a still IMU within [`RestConfig::gait_memory_s`] of a gait
//! starts a rest through frames without a verdict, and the filter's velocity does not refute a
//! rest that begins then ([`RestDetector::stopped_walker`]). The runner turns this off for
//! ground vehicles.
//!
//! While at rest the filter takes zero-velocity, position-hold and zero-rate pseudo-measurements
//! ([`crate::rio::Rio::zero_velocity`], [`crate::rio::Rio::hold_position`],
//! [`crate::rio::Rio::zero_rate`]) every [`RestConfig::update_period_s`]: the velocity stays zero,
//! the position where the rest began (a tilt or accelerometer-bias error would otherwise creep it
//! by millimetres per update, and is learned instead), the gyroscope bias is learned from the
//! whole rest (not only from the levelling window; its last [`RestConfig::rate_margin_s`] only
//! once the rest has outlasted them, so the slow start of a motion the stillness test has not
//! yet seen is never taken for bias) and the heading stops drifting. Without radar
//! (IMU dead reckoning) the body is never taken to be at rest.
//!
//! No allocation after construction: the window is a ring of at most [`REST_CAPACITY`] samples.

use crate::strapdown::ImuSample;
use nalgebra::Vector3;
use std::collections::VecDeque;

/// IMU samples kept for the stillness test at most (the window shrinks to this many at high
/// rates: 1.28 s at 400 Hz).
pub const REST_CAPACITY: usize = 512;

/// Shortest IMU window the stillness test decides on \[s\].
pub const MIN_SPAN_S: f64 = 0.1;

/// Chi-square bound (3 dof, 99.9%) for "the radar's ego-velocity is consistent with zero".
const ZERO_GATE: f64 = 16.27;

/// Rest detection and the pseudo-measurements taken at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestConfig {
    /// Detect rest and apply the zero-velocity / zero-rate updates.
    pub enabled: bool,
    /// IMU window of the stillness test \[s\].
    pub window_s: f64,
    /// Largest specific-force spread (sqrt of the covariance trace) still counted as rest
    /// \[m/s^2\].
    pub accel_std_max: f64,
    /// Largest rate-of-turn spread (sqrt of the covariance trace) still counted as rest
    /// \[rad/s\].
    pub gyro_std_max: f64,
    /// Largest mean rate of turn over the window \[rad/s\] (above any MEMS gyro's bias; a robot
    /// turning on the spot at a steady rate has little spread but this much rate).
    pub gyro_rate_max: f64,
    /// Gravity \[m/s^2\] and the largest difference of the window's mean specific-force magnitude
    /// from it \[m/s^2\].
    pub gravity: f64,
    /// See [`RestConfig::gravity`].
    pub gravity_tolerance: f64,
    /// Smallest share of a frame's points with zero Doppler (within the ego-velocity's Doppler
    /// noise `sigma`) for the radar to call it rest. Moving at 0.2 m/s or faster, a forward-looking
    /// radar sees no static point at zero Doppler; at rest about half the points of a cluttered
    /// room are (the rest are multipath and false alarms with their own Doppler).
    pub zero_doppler_share_min: f64,
    /// Largest share of points with zero Doppler in a frame that says "moving".
    pub moving_share_max: f64,
    /// How improbable at rest a frame's count of zero-Doppler points must be for it to say
    /// "moving" (the binomial tail, each point static with probability
    /// [`RestConfig::zero_doppler_share_min`]). Frames of a few points say nothing by their
    /// share: at rest a handful of clutter and false alarms with their own Doppler outnumber the
    /// static points often enough, and a false "moving" ends a rest.
    pub moving_share_alpha: f64,
    /// The radar's verdict counts this long after its frame \[s\].
    pub radar_max_age_s: f64,
    /// Time between two pairs of rest updates \[s\].
    pub update_period_s: f64,
    /// Standard deviation of the zero-velocity pseudo-measurement \[m/s\] (a rig put down
    /// or held still still moves by millimetres per second).
    pub zero_velocity_std: f64,
    /// Standard deviation of the position-hold pseudo-measurement \[m\]: at rest the position
    /// stays where the rest began.
    pub hold_position_std: f64,
    /// Floor of the zero-rate pseudo-measurement's standard deviation \[rad/s\] per update
    /// period (its white-noise part is the gyro noise density over the span it averages).
    pub zero_rate_std_min: f64,
    /// The zero-rate measurement takes a rest's rate of turn only once the rest has outlasted
    /// it by this long \[s\]; a rest that ends drops its latest this-long. The stillness test
    /// sees a slow start of motion (a robot easing into a turn from rest) only once its window
    /// holds enough of it, and that onset taken as gyroscope bias would turn the heading for
    /// the rest of the session (the radar cannot see heading). Zero-velocity and
    /// position-hold updates are not held back: the radar corrects what they get wrong.
    pub rate_margin_s: f64,
    /// [`RestConfig::rate_margin_s`] for a rest no radar frame has called still yet \[s\]:
    /// the one the session starts in, carried through frames without a verdict. A rig that
    /// starts cruising in a gentle turn with a radar too sparse to say so (5 points a frame, none
    /// at zero Doppler) looks just like it for its first half second or so, and its rate of
    /// turn taken as gyroscope bias turned the heading 1.7 deg/s for the rest of a 60 s run.
    pub unconfirmed_rate_margin_s: f64,
    /// Specific-force spread \[m/s^2\] (sqrt of the covariance trace over the stillness
    /// window) that only a walker's gait reaches: each step swings the specific force by
    /// 2-5 m/s^2, where a robot or a car on a floor or a road stays well under 1.
    /// `f64::INFINITY`: no gait is ever seen, and no rest is taken for a walker's stop.
    pub gait_accel_std: f64,
    /// How long after the IMU last showed a gait \[s\] a still IMU is taken for a walker who
    /// stopped ([`RestConfig::gait_accel_std`]): it may then start a rest where the radar gives
    /// no verdict (a sparse scene: the rest cannot wait for a frame to call it still), and the
    /// filter's velocity does not refute that rest, nor one a frame called still (a walker's
    /// IMU is never still while it walks: a velocity the filter still holds is its error, not a
    /// smooth cruise).
    pub gait_memory_s: f64,
    /// How long the spread must last to be a gait \[s\] ([`RestConfig::gait_accel_std`]): a
    /// walk goes on for seconds, a bump or a braking does not.
    pub gait_min_s: f64,
}

impl Default for RestConfig {
    fn default() -> Self {
        RestConfig {
            enabled: true,
            window_s: 0.5,
            accel_std_max: 0.1,
            gyro_std_max: 0.02,
            gyro_rate_max: 0.05,
            gravity: crate::strapdown::STANDARD_GRAVITY,
            gravity_tolerance: 0.3,
            zero_doppler_share_min: 0.35,
            moving_share_max: 0.15,
            moving_share_alpha: 0.01,
            radar_max_age_s: 0.3,
            update_period_s: 0.05,
            zero_velocity_std: 0.01,
            hold_position_std: 0.001,
            zero_rate_std_min: 0.002,
            rate_margin_s: 0.5,
            unconfirmed_rate_margin_s: 1.0,
            gait_accel_std: 1.0,
            gait_memory_s: 3.0,
            gait_min_s: 2.0,
        }
    }
}

/// The detector's state.
#[derive(Debug, Clone)]
pub struct RestDetector {
    cfg: RestConfig,
    window: VecDeque<ImuSample>,
    /// The latest radar verdicts, oldest first, with their frame times \[s\].
    verdicts: VecDeque<(f64, Verdict)>,
    /// Whether the last decided sample was at rest, and the one before it.
    resting: [bool; 2],
    /// Whether the IMU was still at the last decided sample, and at the one before it.
    still: [bool; 2],
    /// Rate-of-turn sum and sample count since the last rest update.
    gyro_sum: Vector3<f64>,
    gyro_n: u32,
    /// The current rest's rates of turn not yet taken, one entry per rest update: its time
    /// \[s\], rate sum, sample count and span \[s\] ([`RestConfig::rate_margin_s`]).
    held: VecDeque<(f64, Vector3<f64>, u32, f64)>,
    /// Held rates pushed out of a full `held` before their time: taken with the next ones.
    early: (Vector3<f64>, u32, f64),
    since: Option<f64>,
    last_update: Option<f64>,
    /// The filter refuted the last rest ([`RestDetector::refute`]): no rest until the IMU has
    /// moved or the filter's velocity is consistent with rest again ([`RestDetector::retry`]).
    refuted: bool,
    /// A radar frame has said "still" during the current rest.
    confirmed: bool,
    /// Whether a refuted rest held at the last decided sample, and at the one before it.
    refuted_at: [bool; 2],
    /// Nothing has contradicted the rest the session starts in yet: every decided sample's IMU
    /// was still and no frame said moving.
    initial: bool,
    /// The last sample whose IMU window showed a gait ([`RestConfig::gait_accel_std`]) \[s\].
    gait_at: Option<f64>,
    /// Since when the IMU windows have shown a gait's spread without a break \[s\].
    gait_since: Option<f64>,
    /// The current rest began as a walker's stop: on a still IMU just after a gait
    /// ([`RestConfig::gait_memory_s`]).
    stopped_walker: bool,
}

/// Rest updates whose rates of turn are held back at most ([`RestConfig::rate_margin_s`]: 1.6 s
/// at the 50 ms update period; beyond, the oldest is taken early).
const HELD_CAPACITY: usize = 32;

/// Radar verdicts kept (frames come every 30-100 ms, IMU samples every 2.5-10 ms: one or two
/// lie ahead of the sample being evaluated at most).
const VERDICTS: usize = 4;

/// A radar frame's word on rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Most points at zero Doppler and the ego-velocity consistent with zero.
    Still,
    /// The ego-velocity is not zero, or hardly any point is at zero Doppler.
    Moving,
    /// Neither.
    None,
}

/// The pseudo-measurements due for one IMU sample at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestUpdate {
    /// Time of the sample at rest \[s\].
    pub t: f64,
    /// The zero-rate measurement, when the rest has outlasted some of its rates by
    /// [`RestConfig::rate_margin_s`]: their mean \[rad/s\] and the span they cover \[s\].
    pub rate: Option<(Vector3<f64>, f64)>,
    /// The first update of this rest (the position to hold is taken now).
    pub first: bool,
}

impl RestDetector {
    /// A detector with `cfg`.
    pub fn new(cfg: RestConfig) -> RestDetector {
        RestDetector {
            cfg,
            window: VecDeque::with_capacity(REST_CAPACITY),
            verdicts: VecDeque::with_capacity(VERDICTS),
            resting: [false; 2],
            still: [false; 2],
            gyro_sum: Vector3::zeros(),
            gyro_n: 0,
            held: VecDeque::with_capacity(HELD_CAPACITY),
            early: (Vector3::zeros(), 0, 0.0),
            since: None,
            last_update: None,
            refuted: false,
            confirmed: false,
            refuted_at: [false; 2],
            initial: true,
            gait_at: None,
            gait_since: None,
            stopped_walker: false,
        }
    }

    /// The settings.
    pub fn config(&self) -> &RestConfig {
        &self.cfg
    }

    /// A radar frame at `t` \[s\]: its ego-velocity \[m/s\] with covariance, or `None` when the
    /// frame gave none (too few points, no consensus), and how many of its `points` have zero
    /// Doppler (within the Doppler noise). Returns the frame's verdict.
    pub fn push_radar(
        &mut self,
        t: f64,
        velocity: Option<([f64; 3], [[f64; 3]; 3])>,
        zero_doppler: usize,
        points: usize,
    ) -> Verdict {
        let share = zero_doppler as f64 / points.max(1) as f64;
        let d2 = velocity.map(|(v, c)| {
            let v = Vector3::from(v);
            let c = nalgebra::Matrix3::from_fn(|i, j| c[i][j]);
            c.try_inverse()
                .map_or(f64::INFINITY, |ci| (v.transpose() * ci * v)[(0, 0)])
        });
        let improbable_at_rest = || {
            binomial_cdf(zero_doppler, points, self.cfg.zero_doppler_share_min)
                < self.cfg.moving_share_alpha
        };
        let verdict = if (share < self.cfg.moving_share_max && improbable_at_rest())
            || d2.is_some_and(|d2| d2 > ZERO_GATE)
        {
            Verdict::Moving
        } else if d2.is_some() && share >= self.cfg.zero_doppler_share_min {
            Verdict::Still
        } else {
            Verdict::None
        };
        // One frame saying moving amid still ones is a ghost consensus as often as not (the very
        // first frames have no prior to tell): two in a row end the initial rest.
        let last_moving = self.verdicts.back().is_some_and(|v| v.1 == Verdict::Moving);
        self.initial &= !(verdict == Verdict::Moving && last_moving);
        if self.verdicts.len() == VERDICTS {
            self.verdicts.pop_front();
        }
        self.verdicts.push_back((t, verdict));
        verdict
    }

    /// One IMU sample. It decides on the PREVIOUS sample (with the frames up to that sample's
    /// time, whichever order frames and samples came in) and returns the updates due there; the
    /// caller applies them before propagating to `s`. So a stream where each frame comes just
    /// before the first sample past it and one where it comes just after give the same result.
    pub fn push_imu(&mut self, s: &ImuSample) -> Option<RestUpdate> {
        if !self.cfg.enabled {
            return None;
        }
        let due = self.evaluate();
        if self.window.len() == REST_CAPACITY {
            self.window.pop_front();
        }
        self.window.push_back(*s);
        while self
            .window
            .front()
            .is_some_and(|f| s.t - f.t > self.cfg.window_s)
        {
            self.window.pop_front();
        }
        due
    }

    /// Rest at the newest sample of the window (see [`RestDetector::push_imu`]).
    fn evaluate(&mut self) -> Option<RestUpdate> {
        let s = *self.window.back()?;
        let stats = self.window_stats();
        let still = stats.is_some_and(|st| self.still_by(&st));
        // A gait lasts: a bump or a braking swings the specific force for a moment, a walk for
        // as long as it goes on.
        if stats.is_some_and(|st| st.accel_std > self.cfg.gait_accel_std) {
            let since = *self.gait_since.get_or_insert(s.t);
            if s.t - since >= self.cfg.gait_min_s {
                self.gait_at = Some(s.t);
            }
        } else {
            self.gait_since = None;
        }
        // The window fills over the first samples: only a full one that is not still ends the
        // initial rest.
        self.initial &= still || !self.window_decides();
        self.still = [still, self.still[0]];
        self.refuted &= still;
        self.refuted_at = [self.refuted, self.refuted_at[0]];
        let now = still && !self.refuted && self.radar_agrees(s.t);
        self.resting = [now, self.resting[0]];
        if !now {
            self.end_rest();
            return None;
        }
        if self.since.is_none() {
            // A rest begins: a walker's stop when the gait was just before it (whether or not
            // a frame calls it still).
            self.stopped_walker = !self.initial && self.gait_recent(s.t);
        }
        self.gyro_sum += Vector3::from(s.gyro);
        self.gyro_n += 1;
        self.confirmed |= self.radar_says_still(s.t);
        // A rest no frame has called still (the one the session starts in, through frames
        // without a verdict) may be a steady cruise the radar is too sparse to see: its rates
        // wait longer.
        let margin = if self.confirmed {
            self.cfg.rate_margin_s
        } else {
            self.cfg
                .unconfirmed_rate_margin_s
                .max(self.cfg.rate_margin_s)
        };
        let since = *self.since.get_or_insert(s.t);
        let from = self.last_update.map_or(since, |l| l.max(since));
        if s.t - from < self.cfg.update_period_s {
            return None;
        }
        if self.held.len() == HELD_CAPACITY {
            if let Some((_, g, k, dt)) = self.held.pop_front() {
                let e = &mut self.early;
                *e = (e.0 + g, e.1 + k, e.2 + dt);
            }
        }
        self.held
            .push_back((s.t, self.gyro_sum, self.gyro_n, s.t - from));
        self.gyro_sum = Vector3::zeros();
        self.gyro_n = 0;
        // The rates the rest has outlasted by the margin are taken.
        let u = RestUpdate {
            t: s.t,
            rate: self.take_held(s.t - margin),
            first: self.last_update.is_none_or(|l| l < since),
        };
        self.last_update = Some(s.t);
        Some(u)
    }

    /// The held rates up to `until` \[s\], taken: their mean \[rad/s\] and span \[s\].
    fn take_held(&mut self, until: f64) -> Option<(Vector3<f64>, f64)> {
        let (mut sum, mut n, mut span) =
            core::mem::replace(&mut self.early, (Vector3::zeros(), 0, 0.0));
        while let Some(&(t, g, k, dt)) = self.held.front() {
            if t > until {
                break;
            }
            self.held.pop_front();
            (sum, n, span) = (sum + g, n + k, span + dt);
        }
        (n > 0).then(|| (sum / f64::from(n), span))
    }

    /// The rest is over: its rates not yet taken go with it.
    fn end_rest(&mut self) {
        self.since = None;
        self.stopped_walker = false;
        self.confirmed = false;
        self.gyro_sum = Vector3::zeros();
        self.gyro_n = 0;
        self.held.clear();
        self.early = (Vector3::zeros(), 0, 0.0);
    }

    /// The filter's velocity says the body is not at rest (a smooth cruise keeps the IMU as
    /// still as a rest, and a sparse or tilted radar can read zero): the rest ends now, and none
    /// begins again until the IMU has moved or [`RestDetector::retry`].
    pub fn refute(&mut self) {
        self.refuted = true;
        self.refuted_at[0] = true;
        self.resting[0] = false;
        self.end_rest();
    }

    /// The filter's velocity is consistent with rest again after a refuted rest (the radar
    /// frames, applied meanwhile, brought it there): rest may begin again from the next sample.
    pub fn retry(&mut self) {
        self.refuted = false;
    }

    /// Whether a rest the filter refuted holds (no rest until the IMU has moved, or
    /// [`RestDetector::retry`]), at the last decided sample or, with `before`, at the one
    /// before it.
    pub fn refuted_before_frame(&self, before: bool) -> bool {
        self.refuted_at[usize::from(before)]
    }

    /// Whether the rest the session starts in is still uncontradicted (see the module
    /// documentation). The filter's velocity cannot refute it: the filter starts from that rest.
    pub fn initial(&self) -> bool {
        self.initial
    }

    /// Whether the last sample decided on was at rest.
    pub fn resting(&self) -> bool {
        self.resting[0]
    }

    /// Whether the sample decided on before that one was at rest.
    pub fn resting_before(&self) -> bool {
        self.resting[1]
    }

    /// [`RestDetector::resting_before`] when `before`, else [`RestDetector::resting`].
    pub fn resting_before_frame(&self, before: bool) -> bool {
        self.resting[usize::from(before)]
    }

    /// Whether the IMU was still at the last decided sample (`before`: at the one before it).
    pub fn was_still(&self, before: bool) -> bool {
        self.still[usize::from(before)]
    }

    /// Whether the newest verdict up to `t` \[s\] is still, and recent.
    fn radar_says_still(&self, t: f64) -> bool {
        self.recent_verdict(t) == Some(Verdict::Still)
    }

    /// The newest verdict up to `t` \[s\]; a "still" older than [`RestConfig::radar_max_age_s`]
    /// then reads as a frame without a verdict.
    fn recent_verdict(&self, t: f64) -> Option<Verdict> {
        let (tr, v) = self.verdicts.iter().rev().find(|(tr, _)| *tr <= t)?;
        let stale = *v == Verdict::Still && t - tr > self.cfg.radar_max_age_s;
        Some(if stale { Verdict::None } else { *v })
    }

    /// The radar's side of rest at `t` \[s\]: the newest verdict up to `t` is still (and recent),
    /// or the body was at rest and no frame since says moving.
    fn radar_agrees(&self, t: f64) -> bool {
        match self.recent_verdict(t) {
            Some(Verdict::Moving) | None => false,
            Some(Verdict::Still) => true,
            // A frame without a verdict (or a stale "still"): the rest goes on, and so does the
            // one the session starts in, uncontradicted so far.
            // So does a walker's stop: a still IMU just after a gait.
            Some(Verdict::None) => self.resting[0] || self.initial || self.gait_recent(t),
        }
    }

    /// Whether the IMU window is long enough to decide on stillness: at least 10 samples over
    /// [`MIN_SPAN_S`] (or the whole window when that is shorter).
    fn window_decides(&self) -> bool {
        let (Some(first), Some(last)) = (self.window.front(), self.window.back()) else {
            return false;
        };
        self.window.len() >= 10 && last.t - first.t >= MIN_SPAN_S.min(self.cfg.window_s)
    }

    /// True when the IMU window holds at least 10 samples over [`MIN_SPAN_S`] (so a rest at the
    /// start is found by the first radar frames), both triads' spreads are below their bounds, the
    /// mean rate of turn is below [`RestConfig::gyro_rate_max`] and the mean specific force is
    /// gravity within [`RestConfig::gravity_tolerance`].
    pub fn imu_still(&self) -> bool {
        self.window_stats().is_some_and(|st| self.still_by(&st))
    }

    /// Whether the window's statistics are those of rest (see [`RestDetector::imu_still`]).
    fn still_by(&self, st: &WindowStats) -> bool {
        // A steady turn or a steady pull has little spread: the means must be those of rest too.
        st.accel_std < self.cfg.accel_std_max
            && st.gyro_std < self.cfg.gyro_std_max
            && st.gyro_mean.norm() < self.cfg.gyro_rate_max
            && (st.accel_mean.norm() - self.cfg.gravity).abs() < self.cfg.gravity_tolerance
    }

    /// Means and spreads (sqrt of the covariance trace) of both triads over the window, once it
    /// decides ([`RestDetector::window_decides`]).
    fn window_stats(&self) -> Option<WindowStats> {
        if !self.window_decides() {
            return None;
        }
        let stats = |get: fn(&ImuSample) -> [f64; 3]| {
            let n = self.window.len() as f64;
            let mean = self
                .window
                .iter()
                .fold(Vector3::zeros(), |a, s| a + Vector3::from(get(s)))
                / n;
            let var = self
                .window
                .iter()
                .map(|s| (Vector3::from(get(s)) - mean).norm_squared())
                .sum::<f64>()
                / (n - 1.0);
            (mean, var.sqrt())
        };
        let (accel_mean, accel_std) = stats(|s| s.accel);
        let (gyro_mean, gyro_std) = stats(|s| s.gyro);
        Some(WindowStats {
            accel_mean,
            accel_std,
            gyro_mean,
            gyro_std,
        })
    }

    /// Whether a walker's gait was seen within [`RestConfig::gait_memory_s`] of `t` \[s\].
    fn gait_recent(&self, t: f64) -> bool {
        self.gait_at
            .is_some_and(|g| t - g <= self.cfg.gait_memory_s)
    }

    /// Whether the current rest began as a walker's stop, on a still IMU just after a gait
    /// ([`RestConfig::gait_memory_s`]): the filter's velocity is no evidence against it.
    pub fn stopped_walker(&self) -> bool {
        self.stopped_walker
    }
}

/// Means \[m/s^2, rad/s\] and spreads (sqrt of the covariance trace) of the IMU window.
#[derive(Debug, Clone, Copy)]
struct WindowStats {
    accel_mean: Vector3<f64>,
    accel_std: f64,
    gyro_mean: Vector3<f64>,
    gyro_std: f64,
}

/// Probability of at most `k` successes in `n` independent trials of probability `p` (summed
/// in logarithms: the first terms underflow for hundreds of points, the ones that matter do not).
fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    if k >= n {
        return 1.0;
    }
    let (lp, lq) = (p.ln(), (1.0 - p).ln());
    let mut log_term = n as f64 * lq;
    let mut sum = log_term.exp();
    for i in 0..k {
        log_term += ((n - i) as f64 / (i + 1) as f64).ln() + lp - lq;
        sum += log_term.exp();
    }
    sum.min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn still_imu(t: f64) -> ImuSample {
        // Tiny white-ish wobble, far below the stillness bounds.
        let w = 1e-4 * ((t * 1234.5).sin());
        ImuSample {
            t,
            accel: [w, -w, 9.81 + w],
            gyro: [0.003 + w, -0.002, 0.001 - w],
        }
    }

    const ZERO: Option<([f64; 3], [[f64; 3]; 3])> = Some((
        [0.0; 3],
        [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 1.0]],
    ));
    const FAST: Option<([f64; 3], [[f64; 3]; 3])> = Some((
        [0.0, 0.5, 0.0],
        [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 1.0]],
    ));

    /// Feeds 200 Hz still IMU samples over `from..to` \[s\]; returns the updates due.
    fn feed(d: &mut RestDetector, from: f64, to: f64) -> Vec<RestUpdate> {
        let mut out = Vec::new();
        let mut t = from;
        while t < to {
            out.extend(d.push_imu(&still_imu(t)));
            t += 0.005;
        }
        out
    }

    /// A walker's IMU: a 2 Hz step swinging the vertical specific force by 3 m/s^2 and the
    /// forward one by 1 m/s^2 at the stride's 1 Hz, with the trunk's sway in the rate of turn.
    fn walking_imu(t: f64) -> ImuSample {
        let step = 2.0 * std::f64::consts::PI * 2.0 * t;
        ImuSample {
            t,
            accel: [(0.5 * step).sin(), 0.0, 9.81 + 3.0 * step.sin()],
            gyro: [0.2 * (0.5 * step).cos(), 0.1 * step.sin(), 0.05],
        }
    }

    /// Feeds 200 Hz samples of `imu` over `from..to` \[s\] with a 20 Hz frame before each
    /// twentieth that gives no verdict (three points, one at zero Doppler, no velocity: a sparse
    /// scene); returns the updates due.
    fn feed_sparse(
        d: &mut RestDetector,
        from: f64,
        to: f64,
        imu: fn(f64) -> ImuSample,
    ) -> Vec<RestUpdate> {
        let mut out = Vec::new();
        let mut k = 0;
        let mut t = from;
        while t < to {
            if k % 10 == 0 {
                assert_eq!(d.push_radar(t, None, 1, 3), Verdict::None);
            }
            out.extend(d.push_imu(&imu(t)));
            t += 0.005;
            k += 1;
        }
        out
    }

    #[test]
    fn a_walker_who_stops_where_the_radar_says_nothing_comes_to_rest() {
        let mut d = RestDetector::new(RestConfig::default());
        assert!(feed_sparse(&mut d, 0.0, 4.0, walking_imu).is_empty());
        assert!(!d.resting() && !d.initial());
        // The walker stops: the IMU is still within the stillness window, and the rest begins
        // on the gait just before it, though no frame ever called it still.
        let ups = feed_sparse(&mut d, 4.0, 6.0, still_imu);
        assert!(d.resting() && d.stopped_walker());
        let first = ups.first().expect("rest updates");
        assert!(first.first && first.t > 4.0 && first.t < 4.7, "{ups:?}");
        // Walking again ends it.
        feed_sparse(&mut d, 6.0, 9.0, walking_imu);
        assert!(!d.resting() && !d.stopped_walker());
        // A stop a frame calls still is a walker's stop too (its filter's velocity cannot
        // refute it).
        for k in 0..20 {
            let t = 9.0 + 0.05 * f64::from(k);
            d.push_radar(t, ZERO, 12, 20);
            feed(&mut d, t, t + 0.05);
        }
        assert!(d.resting() && d.stopped_walker());
        // And a rest long after the gait is not.
        feed(&mut d, 10.0, 14.0);
        d.push_radar(14.0, FAST, 0, 20);
        feed(&mut d, 14.0, 14.5);
        assert!(!d.resting());
        d.push_radar(14.5, ZERO, 12, 20);
        feed(&mut d, 14.5, 15.0);
        assert!(d.resting() && !d.stopped_walker());
    }

    #[test]
    fn a_bump_or_a_braking_is_no_gait() {
        // The same swing for a second only (a robot over a threshold, a braking): a still IMU
        // after it is not taken for a walker's stop where the radar says nothing.
        let mut d = RestDetector::new(RestConfig::default());
        feed_sparse(&mut d, 0.0, 1.0, walking_imu);
        assert!(feed_sparse(&mut d, 1.0, 4.0, still_imu).is_empty());
        assert!(!d.resting());
        // Nor is any swing when the gait test is off (ground vehicles).
        let mut d = RestDetector::new(RestConfig {
            gait_accel_std: f64::INFINITY,
            ..RestConfig::default()
        });
        feed_sparse(&mut d, 0.0, 4.0, walking_imu);
        assert!(feed_sparse(&mut d, 4.0, 6.0, still_imu).is_empty());
        assert!(!d.resting());
    }

    #[test]
    fn a_still_imu_alone_is_not_rest() {
        let mut d = RestDetector::new(RestConfig::default());
        assert!(feed(&mut d, 0.0, 2.0).is_empty());
        assert!(d.imu_still() && !d.resting());
        // A cruising robot: the IMU is still, the Doppler says moving.
        d.push_radar(2.0, FAST, 0, 20);
        assert!(feed(&mut d, 2.0, 3.0).is_empty());
        assert!(!d.resting());
    }

    #[test]
    fn rest_needs_the_radar_lasts_through_frames_without_a_verdict_and_ends_on_motion() {
        let mut d = RestDetector::new(RestConfig::default());
        feed(&mut d, 0.0, 1.0);
        d.push_radar(1.0, ZERO, 12, 20);
        let ups = feed(&mut d, 1.0, 1.3);
        assert!(d.resting());
        assert!(ups.len() >= 5 && ups[0].first && !ups[1].first, "{ups:?}");
        // The first sample decided at rest is the first at or past the frame.
        assert!(ups[0].t >= 1.0 && ups[0].t < 1.0 + 0.05 + 0.006, "{ups:?}");
        // The zero-rate measurement is the mean rate over the span.
        // (Once the rest has outlasted it: at_once has no margin.)
        let mut at_once = RestDetector::new(RestConfig {
            rate_margin_s: 0.0,
            ..RestConfig::default()
        });
        feed(&mut at_once, 0.0, 1.0);
        at_once.push_radar(1.0, ZERO, 12, 20);
        let (mean_gyro, span_s) = feed(&mut at_once, 1.0, 1.3)[1].rate.expect("a rate");
        assert!((mean_gyro - Vector3::new(0.003, -0.002, 0.001)).norm() < 1e-3);
        assert!((span_s - 0.05).abs() < 0.006);
        // A frame full of multipath gives no verdict: the rest goes on past the verdict's age.
        d.push_radar(1.3, ZERO, 4, 20);
        assert!(!feed(&mut d, 1.3, 2.0).is_empty() && d.resting());
        // A frame that says moving ends it from the first sample at or past it.
        d.push_radar(2.0, FAST, 2, 20);
        assert!(feed(&mut d, 2.0, 2.5).iter().all(|u| u.t < 2.0));
        assert!(!d.resting() && !d.resting_before());
        // So does an IMU that moves.
        d.push_radar(2.5, ZERO, 18, 20);
        assert!(!feed(&mut d, 2.5, 2.7).is_empty() && d.resting());
        let shake = ImuSample {
            t: 2.7,
            accel: [3.0, 0.0, 9.81],
            gyro: [0.0, 0.5, 0.0],
        };
        d.push_imu(&shake);
        assert!(d.push_imu(&still_imu(2.705)).is_none() && !d.resting());
    }

    #[test]
    fn the_start_is_at_rest_until_the_imu_or_the_radar_says_otherwise() {
        // Still from the first sample, frames too sparse for a verdict (no velocity, 3 points):
        // the rest the session starts in counts once a frame is in.
        let mut d = RestDetector::new(RestConfig::default());
        assert!(feed(&mut d, 0.0, 0.5).is_empty() && !d.resting());
        assert_eq!(d.push_radar(0.5, None, 1, 3), Verdict::None);
        assert!(!feed(&mut d, 0.5, 1.0).is_empty() && d.resting());
        // One frame that says moving pauses it (a ghost consensus, as often as not); two in a row
        // end it, and frames without a verdict do not bring it back.
        assert_eq!(d.push_radar(1.0, FAST, 0, 3), Verdict::Moving);
        assert!(feed(&mut d, 1.0, 1.05).iter().all(|u| u.t < 1.0) && !d.resting());
        assert!(d.initial());
        d.push_radar(1.05, None, 1, 3);
        assert!(!feed(&mut d, 1.05, 1.2).is_empty() && d.resting());
        d.push_radar(1.2, FAST, 0, 3);
        d.push_radar(1.25, FAST, 0, 3);
        assert!(!d.initial());
        assert!(feed(&mut d, 1.2, 1.3).iter().all(|u| u.t < 1.2) && !d.resting());
        d.push_radar(1.3, None, 1, 3);
        assert!(feed(&mut d, 1.3, 2.0).is_empty() && !d.resting());

        // An IMU that moves first ends it too: still again, without a verdict, is not rest.
        let mut d = RestDetector::new(RestConfig::default());
        feed(&mut d, 0.0, 0.3);
        d.push_radar(0.3, None, 1, 3);
        assert!(!feed(&mut d, 0.3, 0.6).is_empty() && d.resting());
        for k in 0..40 {
            d.push_imu(&ImuSample {
                t: 0.6 + f64::from(k) * 0.005,
                accel: [2.0 * f64::from(k % 2), 0.0, 9.81],
                gyro: [0.0, 0.4, 0.0],
            });
        }
        assert!(!d.resting());
        d.push_radar(0.8, None, 1, 3);
        assert!(feed(&mut d, 0.8, 2.0).is_empty() && !d.resting());
        // The radar can still call a rest.
        d.push_radar(2.0, ZERO, 12, 20);
        assert!(!feed(&mut d, 2.0, 2.3).is_empty() && d.resting());
    }

    #[test]
    fn a_frame_ahead_of_the_sample_being_decided_waits_for_its_time() {
        // Frames may be in before the samples they precede (the offline order): a frame at 1.2 s
        // does not decide the samples before 1.2 s.
        let mut d = RestDetector::new(RestConfig::default());
        feed(&mut d, 0.0, 1.0);
        d.push_radar(1.2, ZERO, 18, 20);
        assert!(feed(&mut d, 1.0, 1.2).is_empty() && !d.resting());
        assert!(!feed(&mut d, 1.2, 1.4).is_empty() && d.resting());
    }

    #[test]
    fn a_steady_turn_is_not_still() {
        let mut d = RestDetector::new(RestConfig::default());
        let mut t = 0.0;
        while t < 1.0 {
            d.push_imu(&ImuSample {
                t,
                accel: [0.0, 0.0, 9.81],
                gyro: [0.0, 0.0, 0.3],
            });
            t += 0.005;
        }
        d.push_radar(1.0, ZERO, 18, 20);
        assert!(d.push_imu(&still_imu(1.0)).is_none());
        assert!(!d.imu_still() && !d.resting());
    }

    #[test]
    fn disabled_means_never() {
        let mut d = RestDetector::new(RestConfig {
            enabled: false,
            ..RestConfig::default()
        });
        d.push_radar(0.5, ZERO, 20, 20);
        assert!(feed(&mut d, 0.0, 2.0).is_empty());
    }

    #[test]
    fn the_binomial_tail_is_exact_and_never_underflows() {
        assert!((binomial_cdf(0, 5, 0.35) - 0.65f64.powi(5)).abs() < 1e-12);
        // sum_{i<=2} C(14,i) 0.35^i 0.65^(14-i), and the same for 40 points.
        assert!((binomial_cdf(2, 14, 0.35) - 0.083_926_573_726).abs() < 1e-9);
        assert!((binomial_cdf(2, 40, 0.35) - 8.169_521_461_6e-6).abs() < 1e-13);
        assert_eq!(binomial_cdf(5, 5, 0.35), 1.0);
        // 2000 points: the first terms underflow, the tail around the mean does not.
        let mid = binomial_cdf(700, 2000, 0.35);
        assert!(mid > 0.4 && mid < 0.6, "{mid}");
        assert!(binomial_cdf(500, 2000, 0.35) < 1e-20);
    }

    #[test]
    fn a_sparse_frame_says_moving_by_its_share_only_when_rest_could_hardly_show_it() {
        let mut d = RestDetector::new(RestConfig::default());
        // At rest a sparse scene shows 0 of 5 or 1 of 8 points at zero Doppler every few
        // frames (12% and 17% of the time with 35% static points): no verdict.
        assert_eq!(d.push_radar(0.0, None, 0, 5), Verdict::None);
        assert_eq!(d.push_radar(0.05, None, 1, 8), Verdict::None);
        assert_eq!(d.push_radar(0.1, None, 2, 14), Verdict::None);
        // 0 of 20, 2 of 40: motion.
        assert_eq!(d.push_radar(0.15, None, 0, 20), Verdict::Moving);
        assert_eq!(d.push_radar(0.2, None, 2, 40), Verdict::Moving);
        // A share above the bound never says moving, however many points.
        assert_eq!(d.push_radar(0.25, None, 80, 400), Verdict::None);
        // The ego-velocity still says moving on its own in a sparse frame.
        assert_eq!(d.push_radar(0.3, FAST, 0, 5), Verdict::Moving);
    }

    #[test]
    fn a_rests_rate_of_turn_is_taken_once_the_rest_has_outlasted_it() {
        let cfg = RestConfig::default();
        let mut d = RestDetector::new(cfg);
        feed(&mut d, 0.0, 1.0);
        d.push_radar(1.0, ZERO, 12, 20);
        let ups = feed(&mut d, 1.0, 2.0);
        assert!(d.resting() && ups.len() >= 15, "{ups:?}");
        // Zero-velocity updates from the start; the rates only once the rest is 0.5 s old,
        // each then the one of an update period 0.5 s back.
        for u in &ups {
            let age = u.t - ups[0].t;
            if age < cfg.rate_margin_s - 0.003 {
                assert!(u.rate.is_none(), "{u:?}");
            } else if age > cfg.rate_margin_s + 0.003 {
                assert!(u.rate.is_some(), "{u:?}");
            }
            if let Some((mean, span)) = u.rate {
                assert!((mean - Vector3::new(0.003, -0.002, 0.001)).norm() < 1e-3);
                assert!((span - cfg.update_period_s).abs() < 0.006, "{u:?}");
            }
        }
        assert!(ups.iter().filter(|u| u.rate.is_some()).count() >= 8);
        // A rest the IMU ends within its first 0.5 s gives no rate at all: what it held may be
        // the start of the motion.
        let shake = ImuSample {
            t: 2.0,
            accel: [3.0, 0.0, 9.81],
            gyro: [0.0, 0.5, 0.0],
        };
        d.push_imu(&shake);
        let mut later = feed(&mut d, 2.005, 3.0);
        d.push_radar(3.0, ZERO, 12, 20);
        later.extend(feed(&mut d, 3.0, 3.4));
        assert!(d.resting() && !later.is_empty(), "{later:?}");
        assert!(later.iter().all(|u| u.rate.is_none()), "{later:?}");
        // Without the margin every update takes its own rates.
        let mut at_once = RestDetector::new(RestConfig {
            rate_margin_s: 0.0,
            ..cfg
        });
        feed(&mut at_once, 0.0, 1.0);
        at_once.push_radar(1.0, ZERO, 12, 20);
        assert!(feed(&mut at_once, 1.0, 1.4)
            .iter()
            .all(|u| u.rate.is_some()));
    }

    #[test]
    fn a_margin_longer_than_the_held_rates_takes_the_oldest_early_and_loses_none() {
        // 3 s of margin against 32 held update periods (1.6 s): the oldest rates are taken as
        // the newest push them out, none dropped.
        let cfg = RestConfig {
            rate_margin_s: 3.0,
            ..RestConfig::default()
        };
        let mut d = RestDetector::new(cfg);
        feed(&mut d, 0.0, 1.0);
        d.push_radar(1.0, ZERO, 12, 20);
        let ups = feed(&mut d, 1.0, 6.0);
        assert!(d.resting());
        let taken: Vec<_> = ups
            .iter()
            .filter_map(|u| u.rate.map(|r| (u.t, r)))
            .collect();
        let first = taken.first().expect("rates taken").0 - ups[0].t;
        assert!(
            first > 1.5 && first < 1.8,
            "first rate {first:.2} s into the rest"
        );
        for (t, (mean, span)) in &taken {
            assert!(
                (mean - Vector3::new(0.003, -0.002, 0.001)).norm() < 1e-3,
                "{t}"
            );
            assert!((span - cfg.update_period_s).abs() < 0.006, "{t}: {span}");
        }
        // Every update from the first taken on takes one period: none is lost.
        let after = ups.iter().filter(|u| u.t >= taken[0].0).count();
        assert_eq!(taken.len(), after);
    }
}
