//! Point persistence: which radar points were seen again.
//!
//! A static reflector seen in one frame is seen again in the next ones, at the same place in the
//! world (where the motion carried the sensor, the point stays). A false alarm (noise, clutter)
//! comes up at a random place each frame, and a multipath return sits at a range that changes
//! with the path it took. In a sparse frame (an atrium, outdoors: one or two static points among
//! ten ghosts) such points can outvote the static world in the ego-velocity consensus, and the
//! Doppler of one frame alone cannot tell them apart. Their history can: [`PointHistory`] keeps
//! the points of the last frames in the world frame (placed with the filter's pose at each
//! frame) and gives each point of a new frame a voting weight, 1 when a point of an earlier frame
//! within [`PersistConfig::window_s`] lies within [`PersistConfig::radius_m`] of it, else
//! [`PersistConfig::fresh_weight`] ([`crate::ego_velocity::EgoVelocityEstimator::estimate_weighted_into`]).
//!
//! Over a window of a few frames the filter's pose error barely moves the points: a velocity
//! error of 1 m/s shifts a point seen 0.125 s ago by 0.125 m. The weights only choose the
//! consensus (a point seen once still counts as an inlier of it), so a scene that changes (the
//! first frame, a turn into a new room) costs nothing: with no earlier point near any of them,
//! every point weighs the same.

use crate::ego_velocity::Detection;
use nalgebra::{Isometry3, Point3, Vector3};
use std::collections::VecDeque;

/// Points remembered at most (older frames are forgotten first).
pub const HISTORY_POINTS: usize = 4096;

/// Frames remembered at most.
pub const HISTORY_FRAMES: usize = 32;

/// The window chosen on the validation sets of both benchmark splits \[s\] (docs/odometry.md,
/// "Points seen again"): the two frames before at 20 Hz. It lies between two frames back at 10,
/// 15, 20, 25, 30 and 50 Hz, so the frames counted do not depend on stamp jitter.
pub const RECOMMENDED_WINDOW_S: f64 = 0.125;

/// Settings of the persistence weighting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PersistConfig {
    /// How far back a point may have been seen \[s\] (default [`RECOMMENDED_WINDOW_S`], the
    /// setting chosen on the validation sets; 0: off, every point weighs 1). Keep it off a
    /// multiple of the frame period: a frame exactly one window back is in or out by the clock's
    /// jitter, and runs of the same data differ.
    pub window_s: f64,
    /// How near an earlier point must lie to count as the same reflector \[m\] (the radar's
    /// position error at the ranges it sees, plus the filter's drift over the window).
    pub radius_m: f64,
    /// Voting weight of a point no earlier one lies near (in \[0, 1\]; 1: no weighting).
    pub fresh_weight: f32,
}

impl Default for PersistConfig {
    fn default() -> Self {
        // Chosen on the validation sets (docs/odometry.md, "Points seen again").
        PersistConfig {
            window_s: RECOMMENDED_WINDOW_S,
            radius_m: 0.3,
            fresh_weight: 0.25,
        }
    }
}

impl PersistConfig {
    /// True when points are weighted at all.
    pub fn enabled(&self) -> bool {
        self.window_s.is_finite() && self.window_s > 0.0 && self.fresh_weight < 1.0
    }
}

/// What the weighting did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PersistCounters {
    /// Frames weighted (an earlier frame within the window had points).
    pub frames: u64,
    /// Points of those frames seen again (weight 1).
    pub seen_again: u64,
    /// Points of those frames seen for the first time ([`PersistConfig::fresh_weight`]).
    pub fresh: u64,
}

/// The points of the last frames in the world frame, and the weights of a new frame's.
#[derive(Debug, Clone)]
pub struct PointHistory {
    cfg: PersistConfig,
    // (time, points) per frame, oldest first; their points are in `points` in the same order.
    frames: VecDeque<(f64, usize)>,
    points: Vec<Point3<f64>>,
    // This frame's points in the world frame.
    current: Vec<Point3<f64>>,
    weights: Vec<f32>,
    counters: PersistCounters,
}

impl PointHistory {
    /// An empty history with `cfg` (its buffers allocated once, here).
    pub fn new(cfg: PersistConfig) -> PointHistory {
        PointHistory {
            cfg,
            frames: VecDeque::with_capacity(HISTORY_FRAMES),
            points: Vec::with_capacity(HISTORY_POINTS),
            current: Vec::with_capacity(HISTORY_POINTS),
            weights: Vec::with_capacity(HISTORY_POINTS),
            counters: PersistCounters::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &PersistConfig {
        &self.cfg
    }

    /// What the weighting did so far.
    pub fn counters(&self) -> &PersistCounters {
        &self.counters
    }

    /// Forgets every frame (the world frame changed, or the pose is not to be trusted).
    pub fn clear(&mut self) {
        self.frames.clear();
        self.points.clear();
    }

    fn drop_oldest(&mut self) {
        if let Some((_, n)) = self.frames.pop_front() {
            self.points.drain(..n.min(self.points.len()));
        }
    }

    /// The voting weights of the detections `dets` of a frame at `t` \[s\] seen from the radar
    /// pose `radar_in_world`, then the frame joins the history. None when the weighting is off
    /// or no earlier frame within the window had points (every point then weighs the same).
    pub fn weigh(
        &mut self,
        t: f64,
        radar_in_world: &Isometry3<f64>,
        dets: &[Detection],
    ) -> Option<&[f32]> {
        if !self.cfg.enabled() || !t.is_finite() {
            return None;
        }
        // Forget frames outside the window (and any from the future: a clock that went back).
        while self
            .frames
            .front()
            .is_some_and(|&(tf, _)| t - tf > self.cfg.window_s)
        {
            self.drop_oldest();
        }
        while self.frames.back().is_some_and(|&(tf, _)| tf > t) {
            if let Some((_, n)) = self.frames.pop_back() {
                self.points.truncate(self.points.len().saturating_sub(n));
            }
        }
        self.current.clear();
        self.current.extend(dets.iter().map(|d| {
            let p = Point3::new(
                f64::from(d.position[0]),
                f64::from(d.position[1]),
                f64::from(d.position[2]),
            );
            radar_in_world * p
        }));
        let weighted = !self.points.is_empty();
        self.weights.clear();
        if weighted {
            let fresh = self.cfg.fresh_weight.clamp(0.0, 1.0);
            self.counters.frames += 1;
            let r2 = self.cfg.radius_m * self.cfg.radius_m;
            for x in &self.current {
                let again = x.coords.iter().all(|c| c.is_finite())
                    && self.points.iter().any(|h| (h - x).norm_squared() <= r2);
                let w = if again { 1.0 } else { fresh };
                self.weights.push(w);
                if again {
                    self.counters.seen_again += 1;
                } else {
                    self.counters.fresh += 1;
                }
            }
        }
        // Remember this frame (its finite points), forgetting the oldest to make room.
        let n = self
            .current
            .iter()
            .filter(|x| x.coords.iter().all(|c| c.is_finite()))
            .count();
        if n > 0 && n <= HISTORY_POINTS {
            while self.frames.len() >= HISTORY_FRAMES || self.points.len() + n > HISTORY_POINTS {
                self.drop_oldest();
            }
            self.points.extend(
                self.current
                    .iter()
                    .filter(|x| x.coords.iter().all(|c| c.is_finite())),
            );
            self.frames.push_back((t, n));
        }
        weighted.then_some(&self.weights[..])
    }
}

/// The radar pose in the world frame from the IMU's (`q_wi`, `p_wi`) and the radar's mounting in
/// the IMU frame.
pub fn radar_pose(
    q_wi: &nalgebra::UnitQuaternion<f64>,
    p_wi: &Vector3<f64>,
    q_ir: &nalgebra::UnitQuaternion<f64>,
    t_ir: &Vector3<f64>,
) -> Isometry3<f64> {
    Isometry3::from_parts((p_wi + q_wi * t_ir).into(), q_wi * q_ir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn det(x: f32, y: f32, z: f32) -> Detection {
        Detection {
            position: [x, y, z],
            radial_velocity: 0.0,
        }
    }

    fn on() -> PointHistory {
        PointHistory::new(PersistConfig {
            window_s: RECOMMENDED_WINDOW_S,
            radius_m: 0.3,
            fresh_weight: 0.25,
        })
    }

    /// The radar at `y` \[m\] along the world's y axis, turned by `yaw` \[rad\].
    fn at(y: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.0, y, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        )
    }

    #[test]
    fn a_reflector_seen_again_where_the_motion_carried_it_weighs_one() {
        let mut h = on();
        // A reflector 5 m ahead, and a false alarm.
        assert_eq!(
            h.weigh(
                0.0,
                &at(0.0, 0.0),
                &[det(0.0, 5.0, 0.0), det(3.0, 2.0, 1.0)]
            ),
            None
        );
        // 0.1 s later the radar moved 1 m ahead: the reflector is 4 m ahead; a new false alarm.
        let w = h.weigh(
            0.1,
            &at(1.0, 0.0),
            &[det(0.0, 4.0, 0.0), det(-2.0, 6.0, 0.5)],
        );
        assert_eq!(w, Some(&[1.0, 0.25][..]));
        assert_eq!(
            *h.counters(),
            PersistCounters {
                frames: 1,
                seen_again: 1,
                fresh: 1
            }
        );
        // Turned by +90 deg about z, the radar's x axis points along the world's y: the
        // reflector, still at (0, 5, 0) in the world, reads (4, 0, 0).
        let w = h.weigh(
            0.12,
            &at(1.0, std::f64::consts::FRAC_PI_2),
            &[det(4.0, 0.0, 0.0)],
        );
        assert_eq!(w, Some(&[1.0][..]));
    }

    #[test]
    fn the_pose_places_the_points_a_wrong_one_loses_them() {
        let mut h = on();
        h.weigh(0.0, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]);
        // The same reading from a pose 0.5 m off (beyond the radius): not the same reflector.
        let w = h.weigh(0.05, &at(0.5, 0.0), &[det(0.0, 5.0, 0.0)]);
        assert_eq!(w, Some(&[0.25][..]));
    }

    #[test]
    fn the_recommended_window_counts_the_same_frames_whatever_the_stamp_jitter() {
        // At the usual radar rates, frame times jittered by +-1 ms keep the same earlier frames
        // within the window as exact ones (a window on a multiple of the period does not: 0.15 s
        // at 20 Hz took the third frame back or not by the clock fit's sub-millisecond error,
        // and a live run differed from the offline one by 20%).
        let w = RECOMMENDED_WINDOW_S;
        for hz in [10.0, 15.0, 20.0, 25.0, 30.0, 50.0] {
            let period = 1.0 / hz;
            let exact = (0..10).filter(|&k| f64::from(k) * period <= w).count();
            for jitter in [-0.001, 0.001] {
                let jittered = (0..10)
                    .filter(|&k| f64::from(k) * period + jitter * f64::from(k % 2) <= w)
                    .count();
                assert_eq!(jittered, exact, "{hz} Hz, jitter {jitter} s");
            }
        }
    }

    #[test]
    fn frames_older_than_the_window_are_forgotten() {
        let mut h = on();
        h.weigh(0.0, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]);
        // 0.2 s later (window 0.125 s): nothing to compare with, every point weighs the same.
        assert_eq!(h.weigh(0.2, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]), None);
        // The frame just given is remembered.
        assert_eq!(
            h.weigh(0.25, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]),
            Some(&[1.0][..])
        );
        h.clear();
        assert_eq!(h.weigh(0.3, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]), None);
        // A clock that went back forgets the frames "after" it.
        assert_eq!(h.weigh(0.1, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]), None);
    }

    #[test]
    fn off_and_bad_input_give_no_weights_and_never_grow_past_the_capacity() {
        let mut off = PointHistory::new(PersistConfig::default());
        off.cfg.window_s = 0.0;
        off.weigh(0.0, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]);
        assert_eq!(off.weigh(0.05, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]), None);
        let mut h = on();
        h.weigh(0.0, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]);
        assert_eq!(
            h.weigh(f64::NAN, &at(0.0, 0.0), &[det(0.0, 5.0, 0.0)]),
            None
        );
        // A non-finite point weighs as new and is not remembered.
        let w = h.weigh(0.05, &at(0.0, 0.0), &[det(f32::NAN, 5.0, 0.0)]);
        assert_eq!(w, Some(&[0.25][..]));
        assert_eq!(h.points.len(), 1);
        // Many large frames: the oldest go first, the buffers never grow.
        let big: Vec<Detection> = (0..1500).map(|i| det(i as f32 * 0.01, 5.0, 0.0)).collect();
        for k in 0..10 {
            h.weigh(0.1 + 0.001 * f64::from(k), &at(0.0, 0.0), &big);
            assert!(h.points.len() <= HISTORY_POINTS);
        }
        assert_eq!(h.points.capacity(), HISTORY_POINTS);
        assert_eq!(h.frames.iter().map(|f| f.1).sum::<usize>(), h.points.len());
    }
}
