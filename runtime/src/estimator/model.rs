//! The learned milliEgo model as a runtime estimator: radar frames and IMU samples go through the
//! shared window builder (`milliego_preprocess`, the code that built the training data), the model
//! runs with tract on the keyframe chain ([`milliego_models::chain::KeyframeChain`], the chain the
//! offline run uses: every `gap`-th radar frame, each window starting where the previous one
//! ended) and returns the relative pose between the two keyframes.
//!
//! A model failure or an output that is not a finite pose is returned as an error (the stage then
//! hands over to the fallback); after [`MAX_FAILURES`] in a row the estimator reports itself
//! unhealthy.
//!
//! A window needs IMU samples past its current frame, which the synchroniser delivers after the
//! frame, so the pose of keyframe n is published with radar frame n + 1 (one radar period later);
//! the IMU-rate prediction fills the gap for AR consumers.

use super::{BuildError, Estimator, EstimatorError, ImuInput, Mounting, RadarInput, RelativePose};
use milliego_models::chain::{ChainError, ChainStep, KeyframeChain};
use milliego_models::Model;
use milliego_preprocess::window::{BuilderConfig, WindowBuilder};

/// Consecutive failed windows (inference errors or non-finite outputs) after which the estimator
/// reports itself unhealthy.
pub const MAX_FAILURES: u32 = 3;

/// The learned-model estimator.
pub struct ModelEstimator {
    model: Model,
    builder: WindowBuilder,
    chain: KeyframeChain,
    failures: u32,
    unhealthy: Option<String>,
}

impl std::fmt::Debug for ModelEstimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelEstimator")
            .field("model", &self.model.path())
            .field("steps", &self.model.steps())
            .field("chain", self.chain.counters())
            .field("unhealthy", &self.unhealthy)
            .finish()
    }
}

impl ModelEstimator {
    /// Loads `path` (checked against this build's preprocessing) for sensors mounted as `m`,
    /// its matrix products on `threads` threads (1: the estimator thread alone).
    pub fn load(
        path: &std::path::Path,
        m: &Mounting,
        threads: usize,
    ) -> Result<ModelEstimator, BuildError> {
        let pre = milliego_preprocess::Config::default();
        let model =
            Model::load_with_threads(path, Some(&pre), threads).map_err(BuildError::BadModel)?;
        let builder = WindowBuilder::new(BuilderConfig {
            pre,
            imu_to_body: m.imu.rotation,
            ..BuilderConfig::default()
        })
        .map_err(BuildError::Preprocessing)?;
        Ok(ModelEstimator {
            model,
            builder,
            chain: KeyframeChain::new(),
            failures: 0,
            unhealthy: None,
        })
    }

    /// Windows the model ran on.
    pub fn steps(&self) -> u64 {
        self.model.steps()
    }

    /// Times the keyframe chain broke (a lost window) and the LSTM state was reset.
    pub fn chain_breaks(&self) -> u64 {
        self.chain.counters().chain_breaks
    }

    /// The predicted standard deviation of the translation of the pose [`Estimator::push_radar`]
    /// last returned, per body axis \[m\], for a model with the uncertainty head (`None`
    /// otherwise). That pose is always the model's last step: off-chain windows do not run it.
    pub fn translation_std(&self) -> Option<[f64; 3]> {
        self.model
            .pose_std()
            .map(|s| [f64::from(s[0]), f64::from(s[1]), f64::from(s[2])])
    }

    /// Windows whose output was not a finite pose.
    pub fn bad_outputs(&self) -> u64 {
        self.chain.counters().bad_outputs
    }

    fn next_pose(&mut self) -> Result<Option<RelativePose>, EstimatorError> {
        let mut out = None;
        while let Some(w) = self.builder.poll() {
            let p = match self.chain.step(&mut self.model, &w) {
                Ok(ChainStep::Pose(p)) => p,
                Ok(ChainStep::OffChain) => continue,
                Err(e) => {
                    self.failures += 1;
                    if self.failures >= MAX_FAILURES {
                        self.unhealthy = Some(e.to_string());
                    }
                    return Err(match e {
                        ChainError::BadOutput {
                            to_frame,
                            t_to,
                            output,
                        } => EstimatorError::BadOutput {
                            frame: to_frame,
                            t: t_to,
                            output,
                        },
                        ChainError::Model(e) => EstimatorError::Unhealthy(e.to_string()),
                    });
                }
            };
            self.failures = 0;
            out = Some(RelativePose {
                from_frame: p.from_frame,
                to_frame: p.to_frame,
                t_from: p.t_from,
                t_to: p.t_to,
                rel: p.rel,
                velocity_world: Some(p.velocity_world),
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
