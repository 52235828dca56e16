//! The learned milliEgo model as a runtime estimator: radar frames and IMU samples go through the
//! shared window builder (`milliego_preprocess`, the code that built the training data), the model
//! runs with tract on the keyframe chain (every `gap`-th radar frame: each window starts where the
//! previous one ended) and returns the relative pose between the two keyframes.
//!
//! A window needs IMU samples past its current frame, which the synchroniser delivers after the
//! frame, so the pose of keyframe n is published with radar frame n + 1 (one radar period later);
//! the IMU-rate prediction fills the gap for AR consumers.

use crate::estimator::{Estimator, EstimatorError, ImuInput, Mounting, RadarInput, RelativePose};
use milliego_models::Model;
use milliego_preprocess::pose::from_label;
use milliego_preprocess::window::{BuilderConfig, WindowBuilder};
use nalgebra::{Isometry3, Vector3};

/// Consecutive inference failures after which the estimator reports itself unhealthy.
const MAX_FAILURES: u32 = 3;

/// The learned-model estimator.
pub struct ModelEstimator {
    model: Model,
    builder: WindowBuilder,
    /// Last keyframe: push sequence number, frame number, time, world pose (own composition,
    /// for the velocity hint).
    last: Option<(u64, u32, f64, Isometry3<f64>)>,
    failures: u32,
    unhealthy: Option<String>,
    chain_breaks: u64,
}

impl std::fmt::Debug for ModelEstimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelEstimator")
            .field("model", &self.model.path())
            .field("steps", &self.model.steps())
            .field("chain_breaks", &self.chain_breaks)
            .field("unhealthy", &self.unhealthy)
            .finish()
    }
}

impl ModelEstimator {
    /// Loads `path` (checked against this build's preprocessing) for sensors mounted as `m`.
    pub fn load(path: &std::path::Path, m: &Mounting) -> Result<ModelEstimator, String> {
        let pre = milliego_preprocess::Config::default();
        let model = Model::load(path, Some(&pre)).map_err(|e| e.to_string())?;
        let builder = WindowBuilder::new(BuilderConfig {
            pre,
            imu_to_body: m.imu.rotation,
            ..BuilderConfig::default()
        })?;
        Ok(ModelEstimator {
            model,
            builder,
            last: None,
            failures: 0,
            unhealthy: None,
            chain_breaks: 0,
        })
    }

    /// Windows the model ran on.
    pub fn steps(&self) -> u64 {
        self.model.steps()
    }

    /// Times the keyframe chain broke (a lost window) and the LSTM state was reset.
    pub fn chain_breaks(&self) -> u64 {
        self.chain_breaks
    }

    fn next_pose(&mut self) -> Result<Option<RelativePose>, EstimatorError> {
        let mut out = None;
        while let Some(w) = self.builder.poll() {
            let from = match self.last {
                None => Isometry3::identity(),
                Some((seq, _, _, pose)) if seq == w.prev_seq => pose,
                Some((seq, _, _, pose)) if w.prev_seq > seq => {
                    // The chain's next window never came (lost frame, IMU gap): restart the
                    // chain here with a fresh state.
                    self.chain_breaks += 1;
                    self.model.reset();
                    pose
                }
                Some(_) => continue, // off the keyframe chain
            };
            let label = match self.model.step(&w) {
                Ok(l) => {
                    self.failures = 0;
                    l
                }
                Err(e) => {
                    self.failures += 1;
                    if self.failures >= MAX_FAILURES {
                        self.unhealthy = Some(e.to_string());
                    }
                    return Err(EstimatorError::Unhealthy(e.to_string()));
                }
            };
            let rel = from_label(&label.map(f64::from))
                .ok_or_else(|| EstimatorError::Unhealthy(format!("model output {label:?}")))?;
            let pose = from * rel;
            let dt = (w.t_cur - w.t_prev).max(1e-3);
            // Mean velocity over the window, in the world frame at the current keyframe.
            let v: Vector3<f64> = from.rotation * rel.translation.vector / dt;
            self.last = Some((w.cur_seq, w.cur_frame, w.t_cur, pose));
            out = Some(RelativePose {
                from_frame: w.prev_frame,
                to_frame: w.cur_frame,
                t_from: w.t_prev,
                t_to: w.t_cur,
                rel,
                velocity_world: Some(v),
            });
        }
        Ok(out)
    }
}

impl Estimator for ModelEstimator {
    fn name(&self) -> &'static str {
        "model"
    }

    fn push_imu(&mut self, s: &ImuInput) {
        self.builder.push_imu(s.t, s.accel, s.gyro);
    }

    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        // Windows completed by the IMU samples since the last frame, then this frame.
        let ready = self.next_pose()?;
        self.builder.push_radar(f.frame_number, f.t, f.points);
        let now = self.next_pose()?;
        Ok(now.or(ready))
    }

    fn healthy(&self) -> bool {
        self.unhealthy.is_none()
    }
}
