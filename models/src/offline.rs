//! The model over a recorded or simulated session, offline: the session's streams go through the
//! shared window builder (`milliego_preprocess::dataset::feed_session`), the model runs on the
//! keyframe chain (each window starts where the previous one ended: every `gap`-th radar frame)
//! and the relative poses are composed into a trajectory (`T_cur = T_prev * T_rel`). The chain is
//! [`crate::chain::KeyframeChain`], the one the on-device runtime runs.

use crate::chain::{ChainError, ChainStep, KeyframeChain, Stepper};
use crate::{Model, ModelError};
use milliego_preprocess::dataset::{feed_session, DatasetError, Event, Fed};
use milliego_preprocess::pose::to_tum;
use milliego_preprocess::window::Window;
use milliego_session::{Session, TumPose};
use nalgebra::Isometry3;
use std::time::Instant;

/// What an offline model run produced.
#[derive(Debug, Clone)]
pub struct ModelRun {
    /// Body poses at the keyframes, starting at the identity (time: session clock \[s\]).
    pub trajectory: Vec<TumPose>,
    /// Windows the model ran on.
    pub steps: u64,
    /// Windows not on the keyframe chain (the builder emits one per frame).
    pub off_chain: u64,
    /// Times the chain broke (a lost window): composition bridged from the last keyframe and the
    /// LSTM state was reset.
    pub chain_breaks: u64,
    /// Windows whose model output was not a finite pose: no pose for them, the chain broke after
    /// each (counted in `chain_breaks` when a later window came).
    pub bad_outputs: u64,
    /// Inference time per window \[ms\] (tract only, excludes preprocessing).
    pub infer_ms: Vec<f64>,
    /// What feeding the session saw.
    pub fed: Fed,
}

/// Why an offline model run failed.
#[derive(Debug)]
pub enum RunError {
    /// Reading or feeding the session failed.
    Session(DatasetError),
    /// The model failed.
    Model(ModelError),
}

impl std::fmt::Display for RunError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunError::Session(e) => write!(f, "{e}"),
            RunError::Model(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for RunError {}

/// The model with its inference time per window recorded \[ms\].
struct Timed<'a> {
    model: &'a mut Model,
    infer_ms: &'a mut Vec<f64>,
}

impl Stepper for Timed<'_> {
    fn step(&mut self, w: &Window<'_>) -> Result<[f32; 6], ModelError> {
        let t0 = Instant::now();
        let out = self.model.step(w)?;
        self.infer_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        Ok(out)
    }

    fn reset(&mut self) {
        self.model.reset();
    }
}

/// Runs `model` over `session` (the model's state is reset first): a loop over one
/// [`KeyframeChain`]. A window whose output is not a finite pose gets no pose and is counted in
/// [`ModelRun::bad_outputs`] (the chain breaks after it); a failing model ends the run.
pub fn run_session(model: &mut Model, session: &Session) -> Result<ModelRun, RunError> {
    model.reset();
    let pre = model.meta().preprocess;
    let mut trajectory = Vec::new();
    let mut infer_ms = Vec::new();
    let mut chain = KeyframeChain::new();
    let mut failure: Option<ModelError> = None;
    let mut timed = Timed {
        model,
        infer_ms: &mut infer_ms,
    };
    let fed = feed_session(session, &pre, &mut |ev| {
        let Event::Window(w) = ev else { return };
        if failure.is_some() {
            return;
        }
        match chain.step(&mut timed, &w) {
            Ok(ChainStep::Pose(p)) => {
                if p.starts_chain && trajectory.is_empty() {
                    trajectory.push(to_tum(p.t_from, &Isometry3::identity()));
                }
                trajectory.push(to_tum(p.t_to, &p.pose));
            }
            Ok(ChainStep::OffChain) | Err(ChainError::BadOutput { .. }) => {}
            Err(ChainError::Model(e)) => failure = Some(e),
        }
    })
    .map_err(RunError::Session)?;
    if let Some(e) = failure {
        return Err(RunError::Model(e));
    }
    let c = *chain.counters();
    Ok(ModelRun {
        trajectory,
        steps: c.steps,
        off_chain: c.off_chain,
        chain_breaks: c.chain_breaks,
        bad_outputs: c.bad_outputs,
        infer_ms,
        fed,
    })
}
