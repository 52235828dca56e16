//! The one place estimators are built: the classical ones, the learned model, the fused estimator,
//! and for `auto` the fused one with its online check (or Doppler when no model is given).

use super::{Classical, ClassicalConfig, Estimator, EstimatorKind, Fused, ModelEstimator};

/// Why an estimator could not be built.
#[derive(Debug)]
pub enum BuildError {
    /// No model file was given.
    ModelUnavailable,
    /// The model file could not be loaded (the error names the file and why).
    BadModel(milliego_models::ModelError),
    /// This build's preprocessing settings cannot feed the model.
    Preprocessing(milliego_preprocess::SettingError),
}

impl std::fmt::Display for BuildError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BuildError::ModelUnavailable => {
                write!(
                    f,
                    "the learned-model estimator needs a model file (--model PATH)"
                )
            }
            BuildError::BadModel(e) => write!(f, "cannot load the model: {e}"),
            BuildError::Preprocessing(e) => write!(f, "learned-model estimator: {e}"),
        }
    }
}

impl std::error::Error for BuildError {}

/// The estimators of a run: the primary one, and for `auto` the fallback beside it.
pub struct Built {
    /// The estimator that produces poses while healthy.
    pub primary: Box<dyn Estimator>,
    /// Fallback used when the primary is unavailable or unhealthy (`auto` only).
    pub fallback: Option<Box<dyn Estimator>>,
    /// True when `auto` could not get the model (poses carry MODEL_FALLBACK).
    pub model_fallback: bool,
}

impl std::fmt::Debug for Built {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Built")
            .field("primary", &self.primary.name())
            .field("fallback", &self.fallback.as_ref().map(|e| e.name()))
            .field("model_fallback", &self.model_fallback)
            .finish()
    }
}

/// The learned model of a run: its file and the threads tract may use for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ModelSource<'a> {
    /// The ONNX file.
    pub path: &'a std::path::Path,
    /// Threads for the model's matrix products (1: none besides the estimator thread).
    pub threads: usize,
}

impl<'a> From<&'a std::path::Path> for ModelSource<'a> {
    /// One thread.
    fn from(path: &'a std::path::Path) -> Self {
        ModelSource { path, threads: 1 }
    }
}

/// Builds one estimator of `kind`. The single place where estimators are made: the learned
/// model joins here (`model` names its file).
pub fn build_estimator(
    kind: EstimatorKind,
    cfg: &ClassicalConfig,
    model: Option<ModelSource<'_>>,
) -> Result<Box<dyn Estimator>, BuildError> {
    match kind {
        EstimatorKind::Doppler => Ok(Box::new(Classical::doppler(*cfg))),
        EstimatorKind::Imu => Ok(Box::new(Classical::imu_only(*cfg))),
        EstimatorKind::Model => {
            let m = model.ok_or(BuildError::ModelUnavailable)?;
            ModelEstimator::load(m.path, &cfg.mounting, m.threads)
                .map(|m| Box::new(m) as Box<dyn Estimator>)
        }
        EstimatorKind::Fused => {
            let m = model.ok_or(BuildError::ModelUnavailable)?;
            let mut cfg = *cfg;
            cfg.learned.monitor = false;
            Ok(Box::new(Fused::load(&cfg, m)?))
        }
        EstimatorKind::Auto => match model {
            Some(m) => {
                let mut cfg = *cfg;
                cfg.learned.monitor = true;
                Ok(Box::new(Fused::load(&cfg, m)?))
            }
            None => build_estimator(EstimatorKind::Doppler, cfg, None),
        },
    }
}

/// The estimators for a run of `kind`: `auto` runs the fused estimator with its online check
/// when a model is given (Doppler beside it, taking over when the check fails), Doppler
/// (MODEL_FALLBACK on every pose) when none is; a model that is
/// given but cannot be loaded, or a fixed kind that cannot be built, fails at start-up.
pub fn build_run_estimators(
    kind: EstimatorKind,
    cfg: &ClassicalConfig,
    model: Option<ModelSource<'_>>,
) -> Result<Built, BuildError> {
    match kind {
        EstimatorKind::Auto => match build_estimator(EstimatorKind::Auto, cfg, model) {
            // The Doppler filter beside it takes over when the online check fails.
            Ok(m) if model.is_some() => Ok(Built {
                primary: m,
                fallback: Some(build_estimator(EstimatorKind::Doppler, cfg, None)?),
                model_fallback: false,
            }),
            Ok(doppler) => Ok(Built {
                primary: doppler,
                fallback: None,
                model_fallback: true,
            }),
            // A model that was given but cannot be used stops the run: falling back silently
            // would hide a broken deployment.
            Err(e) => Err(e),
        },
        k => Ok(Built {
            primary: build_estimator(k, cfg, model)?,
            fallback: None,
            model_fallback: false,
        }),
    }
}
