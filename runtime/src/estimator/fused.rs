//! The fused estimator: the Doppler radar-inertial filter with the learned model's relative
//! motion between keyframes as one more measurement ([`milliego_odometry::learned`]: gated by
//! its innovation, and with the online check on, applied only while the recent ones were
//! consistent). `auto` runs it with the check on, a Doppler filter beside it, and hands over to
//! that one when the check fails (the stage's hand-over: the trajectory goes on from the last
//! pose, flagged HANDOVER then MODEL_FALLBACK); `--estimator fused` runs it with the check off.
//!
//! A failing model (inference errors, outputs that are not a finite pose,
//! [`super::model::MAX_FAILURES`] in a row) is switched off and the filter goes on as the
//! Doppler filter it then is; the summary says why.

use super::{
    Classical, ClassicalConfig, Estimator, EstimatorError, ImuInput, ModelEstimator, ModelSource,
    RadarInput, RelativePose,
};
use crate::summary::LearnedSummary;
use milliego_odometry::learned::RelativeMotion;

/// Doppler radar-inertial odometry with the learned model as a measurement.
pub struct Fused {
    classical: Classical,
    model: ModelEstimator,
    /// Model failures (inference errors, outputs that are not a finite pose).
    model_failures: u64,
    /// Why the model was switched off, once it was.
    model_off: Option<String>,
}

impl std::fmt::Debug for Fused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fused")
            .field("classical", &self.classical)
            .field("model", &self.model)
            .field("model_off", &self.model_off)
            .finish()
    }
}

impl Fused {
    /// The Doppler filter of `cfg` (its [`ClassicalConfig::learned`] settings) with the model of
    /// `model`.
    pub fn load(cfg: &ClassicalConfig, model: ModelSource<'_>) -> Result<Fused, super::BuildError> {
        Ok(Fused {
            classical: Classical::doppler(*cfg),
            model: ModelEstimator::load(model.path, &cfg.mounting, model.threads)?,
            model_failures: 0,
            model_off: None,
        })
    }

    /// The Doppler filter underneath.
    pub fn classical(&self) -> &Classical {
        &self.classical
    }
}

impl Estimator for Fused {
    fn name(&self) -> &'static str {
        "fused"
    }

    fn push_imu(&mut self, s: &ImuInput) {
        self.classical.push_imu(s);
        if self.model_off.is_none() {
            self.model.push_imu(s);
        }
    }

    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        // The filter first: its pose at this frame is the `to` anchor of a window ending here.
        let out = self.classical.push_radar(f)?;
        if self.model_off.is_none() {
            match self.model.push_radar(f) {
                Ok(Some(r)) => {
                    self.classical
                        .runner_mut()
                        .push_relative_motion(&RelativeMotion {
                            t_from: r.t_from,
                            t_to: r.t_to,
                            translation: r.rel.translation.vector.into(),
                            translation_std: self.model.translation_std(),
                        });
                }
                Ok(None) => {}
                Err(e) => {
                    self.model_failures += 1;
                    if !self.model.healthy() {
                        tracing::warn!(
                            "learned model switched off, the Doppler filter goes on: {e}"
                        );
                        self.model_off = Some(e.to_string());
                    }
                }
            }
        }
        Ok(out)
    }

    /// False once the online check switched the learned measurements off (`auto` then hands
    /// over to the Doppler filter beside it).
    fn healthy(&self) -> bool {
        // Not the filter's start (levelling): the Doppler filter beside it would be no further.
        self.classical.runner().learned_trusted()
    }

    fn radar_time_offset(&self) -> Option<(f64, f64)> {
        self.classical.radar_time_offset()
    }

    fn doppler_step(&self) -> Option<(f32, Option<f32>)> {
        self.classical.doppler_step()
    }

    fn filter(&self) -> Option<crate::summary::FilterSummary> {
        Estimator::filter(&self.classical)
    }

    fn last_aid_s(&self) -> Option<f64> {
        self.classical.last_aid_s()
    }

    fn learned(&self) -> Option<LearnedSummary> {
        let r = self.classical.runner();
        let c = r.learned_counters();
        Some(LearnedSummary {
            applied: c.applied,
            gated: c.gated,
            suspended: c.suspended,
            at_rest: c.at_rest,
            covered: c.covered,
            no_anchor: c.no_anchor,
            invalid: c.invalid,
            nis_mean: c.nis_mean(),
            noise_factor: Some(r.learned_noise_factor()),
            switched_off: c.switched_off > 0,
            in_use_at_end: self.model_off.is_none() && r.learned_trusted(),
            model_windows: self.model.steps(),
            model_failures: self.model_failures,
            model_off: self.model_off.clone(),
            // The stage fills it in (`auto`).
            handover: None,
        })
    }
}
