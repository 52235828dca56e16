//! The model over a recorded or simulated session, offline: the session's streams go through the
//! shared window builder (`milliego_preprocess::dataset::feed_session`), the model runs on the
//! keyframe chain (each window starts where the previous one ended: every `gap`-th radar frame)
//! and the relative poses are composed into a trajectory (`T_cur = T_prev * T_rel`).

use crate::{Model, ModelError};
use milliego_preprocess::dataset::{feed_session, DatasetError, Event, Fed};
use milliego_preprocess::pose::{from_label, to_tum};
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

/// Runs `model` over `session` (the model's state is reset first).
pub fn run_session(model: &mut Model, session: &Session) -> Result<ModelRun, RunError> {
    model.reset();
    let pre = model.meta().preprocess;
    let mut run = ModelRun {
        trajectory: Vec::new(),
        steps: 0,
        off_chain: 0,
        chain_breaks: 0,
        infer_ms: Vec::new(),
        fed: Fed::default(),
    };
    let mut last: Option<(u64, Isometry3<f64>)> = None;
    let mut failure: Option<ModelError> = None;
    let fed = feed_session(session, &pre, &mut |ev| {
        let Event::Window(w) = ev else { return };
        if failure.is_some() {
            return;
        }
        let from = match last {
            None => {
                run.trajectory
                    .push(to_tum(w.t_prev, &Isometry3::identity()));
                Isometry3::identity()
            }
            Some((seq, pose)) if seq == w.prev_seq => pose,
            Some((seq, pose)) if w.prev_seq > seq => {
                run.chain_breaks += 1;
                model.reset();
                pose
            }
            Some(_) => {
                run.off_chain += 1;
                return;
            }
        };
        let t0 = Instant::now();
        match model.step(&w) {
            Ok(out) => {
                run.infer_ms.push(t0.elapsed().as_secs_f64() * 1e3);
                run.steps += 1;
                let rel = from_label(&out.map(f64::from)).unwrap_or_else(Isometry3::identity);
                let pose = from * rel;
                run.trajectory.push(to_tum(w.t_cur, &pose));
                last = Some((w.cur_seq, pose));
            }
            Err(e) => failure = Some(e),
        }
    })
    .map_err(RunError::Session)?;
    if let Some(e) = failure {
        return Err(RunError::Model(e));
    }
    run.fed = fed;
    Ok(run)
}
