//! The classical estimators, `doppler` and `imu`: a thin adapter from the runtime's inputs to
//! [`milliego_odometry::runner::Runner`] (the loop `milliego odometry` runs offline, so the two
//! agree pose for pose) and from its body poses to relative poses between radar frames.

use super::{ClassicalConfig, Estimator, EstimatorError, ImuInput, RadarInput, RelativePose};
use milliego_odometry::rio::Rio;
use milliego_odometry::runner::{FrameInput, Runner};
use milliego_odometry::strapdown::ImuSample;
use nalgebra::{Isometry3, Vector3};

/// Doppler radar-inertial odometry (or IMU dead reckoning) over the runtime's ordered stream.
#[derive(Debug)]
pub struct Classical {
    runner: Runner,
    /// Last pose given: frame number, time \[s\], body pose in the world frame.
    prev: Option<(u32, f64, Isometry3<f64>)>,
}

impl Classical {
    /// Doppler radar-inertial odometry.
    pub fn doppler(cfg: ClassicalConfig) -> Self {
        Self::new(cfg, true)
    }

    /// IMU dead reckoning.
    pub fn imu_only(cfg: ClassicalConfig) -> Self {
        Self::new(cfg, false)
    }

    fn new(cfg: ClassicalConfig, use_radar: bool) -> Self {
        Classical {
            runner: Runner::new(&cfg, use_radar),
            prev: None,
        }
    }

    /// The runner (its counters: ego-velocity statuses, dead-reckoned frames, restarts).
    pub fn runner(&self) -> &Runner {
        &self.runner
    }

    /// The runner, to give it measurements of its own (the fused estimator's learned motions).
    pub(crate) fn runner_mut(&mut self) -> &mut Runner {
        &mut self.runner
    }

    /// The filter, once levelled.
    pub fn filter(&self) -> Option<&Rio> {
        self.runner.filter()
    }

    /// Time \[s\], body pose in the world frame and world velocity \[m/s\] of the current state.
    pub fn body_state(&self) -> Option<(f64, Isometry3<f64>, Vector3<f64>)> {
        self.runner.body_state()
    }
}

impl Estimator for Classical {
    fn radar_time_offset(&self) -> Option<(f64, f64)> {
        self.runner.filter().and_then(|f| f.time_offset())
    }

    fn doppler_step(&self) -> Option<(f32, Option<f32>)> {
        self.runner.uses_radar().then(|| self.runner.doppler_step())
    }

    fn filter(&self) -> Option<crate::summary::FilterSummary> {
        self.runner.uses_radar().then(|| {
            let p = self.runner.persist_counters();
            let unaided = self.runner.longest_unaided();
            crate::summary::FilterSummary {
                frames_weighed: p.frames,
                points_seen_again: p.seen_again,
                points_fresh: p.fresh,
                radar_nis_mean: self.runner.filter().and_then(|f| f.nis_mean()),
                radar_noise_scale: self.runner.filter().map(|f| f.radar_noise_scale()),
                near_field_m: self.runner.near_field_m(),
                near_field_tested: self
                    .runner
                    .near_field_leakage()
                    .map_or((0, 0), |(tested, zero, _)| (tested, zero)),
                near_field_points: self.runner.counters().near_field_points,
                unaided_longest_s: unaided.length_s,
                unaided_from_s: unaided.from_s,
                poses_unaided: unaided.poses_unaided,
                ..self.runner.filter_counters().into()
            }
        })
    }

    fn last_aid_s(&self) -> Option<f64> {
        self.runner.last_aid_s()
    }

    fn name(&self) -> &'static str {
        if self.runner.uses_radar() {
            "doppler"
        } else {
            "imu"
        }
    }

    fn push_imu(&mut self, s: &ImuInput) {
        if let Some((t, pa)) = s.pressure {
            self.runner.push_pressure(t, pa);
        }
        self.runner.push_imu(ImuSample {
            t: s.t,
            accel: s.accel,
            gyro: s.gyro,
        });
        // Poses that come out here are of frames seen while levelling (the runtime publishes no
        // pose before the filter starts) or of frames that came ahead of the IMU (published at
        // once, from the state then): none is published late.
        while self.runner.pop_pose().is_some() {}
    }

    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        let id = u64::from(f.frame_number);
        self.runner.push_radar(&FrameInput {
            t: f.t,
            id,
            points: f.points,
        });
        let mut own = None;
        while let Some(p) = self.runner.pop_pose() {
            if p.id == id {
                own = Some((p.body, p.velocity_world));
            }
        }
        if !self.runner.started() {
            return Ok(None);
        }
        // A frame ahead of the IMU gets its pose at the next sample: publish the state now.
        let Some((body, v)) = own.or_else(|| self.runner.body_state().map(|(_, b, v)| (b, v)))
        else {
            return Ok(None);
        };
        let out = match self.prev {
            Some((pf, pt, pb)) => RelativePose {
                from_frame: pf,
                to_frame: f.frame_number,
                t_from: pt,
                t_to: f.t,
                rel: pb.inverse() * body,
                velocity_world: Some(v),
            },
            // The first pose: relative to the world origin (the levelled start), announced as
            // coming from a frame the composer does not know.
            None => RelativePose {
                from_frame: f.frame_number.wrapping_sub(1),
                to_frame: f.frame_number,
                t_from: f.t,
                t_to: f.t,
                rel: body,
                velocity_world: Some(v),
            },
        };
        self.prev = Some((f.frame_number, f.t, body));
        Ok(Some(out))
    }

    fn healthy(&self) -> bool {
        self.runner.started()
    }
}
