//! The model's keyframe chain, once, as a stream: windows from the shared window builder go in,
//! the model runs on those that continue the chain (each window starts where the previous one
//! ended: every `gap`-th radar frame) and the relative poses come out, composed into world poses
//! (`T_cur = T_prev * T_rel`, the chain's first keyframe at the identity).
//!
//! Both the offline run ([`crate::offline::run_session`]) and the on-device runtime's `model`
//! estimator are loops over a [`KeyframeChain`], so the rules are written here only:
//!
//! * a window whose previous frame is the chain's last keyframe continues the chain;
//! * a window that starts before the last keyframe is off the chain (counted, not run);
//! * a window that starts after it means the chain's next window never came (lost frame, IMU
//!   gap): the chain breaks, the LSTM state is reset and composition bridges from the last
//!   keyframe;
//! * a model output that is not a finite pose is an error ([`ChainError::BadOutput`], counted):
//!   no pose for that window, the chain does not advance (so the next window breaks it). The
//!   runtime reports it (its hand-over to the fallback), offline counts it in its result.

use crate::{Model, ModelError};
use milliego_preprocess::pose::from_label;
use milliego_preprocess::window::Window;
use nalgebra::{Isometry3, Vector3};

/// What the chain needs of a model: one step on a window, and a reset of its recurrent state.
pub trait Stepper {
    /// One window: the relative pose `[tx, ty, tz [m], roll, pitch, yaw [deg]]`.
    fn step(&mut self, w: &Window<'_>) -> Result<[f32; 6], ModelError>;
    /// Forgets the recurrent state.
    fn reset(&mut self);
}

impl Stepper for Model {
    fn step(&mut self, w: &Window<'_>) -> Result<[f32; 6], ModelError> {
        Model::step(self, w)
    }

    fn reset(&mut self) {
        Model::reset(self);
    }
}

/// A keyframe's pose from the chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeyframePose {
    /// Frame number of the previous keyframe.
    pub from_frame: u32,
    /// Frame number of this keyframe.
    pub to_frame: u32,
    /// Time of the previous keyframe \[s\].
    pub t_from: f64,
    /// Time of this keyframe \[s\].
    pub t_to: f64,
    /// Body pose at `to` in the body frame at `from` (translation \[m\]).
    pub rel: Isometry3<f64>,
    /// Body pose at `to` in the chain's world frame (its first keyframe at the identity).
    pub pose: Isometry3<f64>,
    /// Mean body velocity over the window, in the world frame at `to` \[m/s\].
    pub velocity_world: Vector3<f64>,
    /// True for the chain's first pose (`from` is the world origin).
    pub starts_chain: bool,
    /// True when the chain broke before this window (the LSTM state was reset).
    pub after_break: bool,
}

/// What one window did to the chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ChainStep {
    /// A pose on the chain.
    Pose(KeyframePose),
    /// The window is off the chain (not run).
    OffChain,
}

/// Why a window gave no pose.
#[derive(Debug)]
pub enum ChainError {
    /// The model failed on the window.
    Model(ModelError),
    /// The model's output is not a finite pose.
    BadOutput {
        /// Frame number of the window's current frame.
        to_frame: u32,
        /// Its time \[s\].
        t_to: f64,
        /// The output `[tx, ty, tz, roll, pitch, yaw]`.
        output: [f32; 6],
    },
}

impl std::fmt::Display for ChainError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ChainError::Model(e) => write!(f, "{e}"),
            ChainError::BadOutput {
                to_frame,
                t_to,
                output,
            } => write!(
                f,
                "model output for frame {to_frame} at {t_to:.3} s is not a finite pose: {output:?}"
            ),
        }
    }
}

impl std::error::Error for ChainError {}

/// Counters of a chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ChainCounters {
    /// Windows the model ran on.
    pub steps: u64,
    /// Windows off the chain.
    pub off_chain: u64,
    /// Times the chain broke and the LSTM state was reset.
    pub chain_breaks: u64,
    /// Windows whose model output was not a finite pose.
    pub bad_outputs: u64,
}

/// The keyframe chain.
#[derive(Debug, Clone, Default)]
pub struct KeyframeChain {
    /// Last keyframe: push sequence number and world pose.
    last: Option<(u64, Isometry3<f64>)>,
    counters: ChainCounters,
}

impl KeyframeChain {
    /// An empty chain (call [`Stepper::reset`] on the model too when reusing one).
    pub fn new() -> KeyframeChain {
        KeyframeChain::default()
    }

    /// Counters.
    pub fn counters(&self) -> &ChainCounters {
        &self.counters
    }

    /// Runs `model` on `w` if it is on the chain.
    pub fn step(
        &mut self,
        model: &mut impl Stepper,
        w: &Window<'_>,
    ) -> Result<ChainStep, ChainError> {
        let (from, starts_chain, after_break) = match self.last {
            None => (Isometry3::identity(), true, false),
            Some((seq, pose)) if seq == w.prev_seq => (pose, false, false),
            Some((seq, pose)) if w.prev_seq > seq => {
                self.counters.chain_breaks += 1;
                model.reset();
                (pose, false, true)
            }
            Some(_) => {
                self.counters.off_chain += 1;
                return Ok(ChainStep::OffChain);
            }
        };
        let out = model.step(w).map_err(ChainError::Model)?;
        self.counters.steps += 1;
        let Some(rel) = from_label(&out.map(f64::from)) else {
            self.counters.bad_outputs += 1;
            return Err(ChainError::BadOutput {
                to_frame: w.cur_frame,
                t_to: w.t_cur,
                output: out,
            });
        };
        let pose = from * rel;
        let dt = (w.t_cur - w.t_prev).max(1e-3);
        self.last = Some((w.cur_seq, pose));
        Ok(ChainStep::Pose(KeyframePose {
            from_frame: w.prev_frame,
            to_frame: w.cur_frame,
            t_from: w.t_prev,
            t_to: w.t_cur,
            rel,
            pose,
            velocity_world: from.rotation * rel.translation.vector / dt,
            starts_chain,
            after_break,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use milliego_preprocess::{IMU_LEN, PANO_LEN};

    /// A model that moves 0.1 m forward a window, or gives NaN where told to.
    struct Fake {
        nan_at: Option<u32>,
        resets: u32,
    }

    impl Stepper for Fake {
        fn step(&mut self, w: &Window<'_>) -> Result<[f32; 6], ModelError> {
            if self.nan_at == Some(w.cur_frame) {
                return Ok([f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]);
            }
            Ok([0.0, 0.1, 0.0, 0.0, 0.0, 0.0])
        }
        fn reset(&mut self) {
            self.resets += 1;
        }
    }

    fn run(chain: &mut KeyframeChain, model: &mut Fake, windows: &[(u64, u64)]) -> Vec<String> {
        let pano = vec![0.0f32; PANO_LEN];
        let pano: &[f32; PANO_LEN] = pano.as_slice().try_into().unwrap();
        let imu = [[0.0f32; 6]; IMU_LEN];
        windows
            .iter()
            .map(|&(prev, cur)| {
                let w = Window {
                    prev_seq: prev,
                    cur_seq: cur,
                    prev_frame: prev as u32,
                    cur_frame: cur as u32,
                    t_prev: prev as f64 * 0.1,
                    t_cur: cur as f64 * 0.1,
                    prev: pano,
                    cur: pano,
                    prev_doppler: pano,
                    cur_doppler: pano,
                    imu: &imu,
                };
                match chain.step(model, &w) {
                    Ok(ChainStep::Pose(p)) => format!("{:.1}", p.pose.translation.y),
                    Ok(ChainStep::OffChain) => "off".into(),
                    Err(ChainError::BadOutput { to_frame, .. }) => format!("bad {to_frame}"),
                    Err(e) => format!("{e}"),
                }
            })
            .collect()
    }

    #[test]
    fn the_chain_skips_off_chain_windows_and_bridges_breaks() {
        let mut chain = KeyframeChain::new();
        let mut m = Fake {
            nan_at: None,
            resets: 0,
        };
        let got = run(&mut chain, &mut m, &[(0, 2), (1, 3), (2, 4), (6, 8)]);
        assert_eq!(got, ["0.1", "off", "0.2", "0.3"]);
        let c = chain.counters();
        assert_eq!(
            (c.steps, c.off_chain, c.chain_breaks, m.resets),
            (3, 1, 1, 1)
        );
    }

    #[test]
    fn a_bad_output_is_an_error_and_the_chain_breaks_after_it() {
        let mut chain = KeyframeChain::new();
        let mut m = Fake {
            nan_at: Some(4),
            resets: 0,
        };
        let got = run(&mut chain, &mut m, &[(0, 2), (2, 4), (4, 6)]);
        // No identity step for the bad window: the next one bridges from the last keyframe.
        assert_eq!(got, ["0.1", "bad 4", "0.2"]);
        let c = chain.counters();
        assert_eq!((c.bad_outputs, c.chain_breaks, m.resets), (1, 1, 1));
    }
}
