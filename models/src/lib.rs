//! The milliEgo network at run time (stage "windows -> model -> relative pose").
//!
//! [`Model::load`] reads an exported ONNX graph (fp32 or int8, see `models/python/README.md` and
//! `docs/model.md`), checks its metadata and input shapes against this build's preprocessing,
//! optimises it once with tract and keeps one runnable plan and one LSTM state. [`Model::step`]
//! runs one window: radar tensor 6 x 64 x 256, IMU window 20 x 6, giving the relative body pose
//! `[tx, ty, tz [m], roll, pitch, yaw [deg]]` (conventions: `milliego_preprocess::pose`).
//!
//! A stateless model (as the authors released it) is fed a zero state every call; a stateful one
//! carries its state from window to window until [`Model::reset`]. A model exported with the
//! uncertainty head has a third output, `pose_std`: the predicted standard deviation of each pose
//! component (m, deg), read after each step with [`Model::pose_std`].
#![forbid(unsafe_code)]

pub mod chain;
pub mod offline;

use milliego_preprocess::window::Window;
use milliego_preprocess::{Config, Norm, RadarInput, IMU_LEN, RADAR_LEN};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;

/// Model input names and shapes (batch 1), in graph order.
pub const INPUTS: [&str; 3] = ["radar", "imu", "state"];
/// Model output names.
pub const OUTPUTS: [&str; 2] = ["pose", "state_out"];
/// The optional third output of a model with the uncertainty head: 1 x 6, the predicted standard
/// deviation of each pose component (\[m\] for translation, \[deg\] for rotation).
pub const STD_OUTPUT: &str = "pose_std";
/// Rows of the LSTM state: h1, c1, h2, c2 of the two fusion layers.
pub const STATE_ROWS: usize = 4;
/// How far two int8 runs of one window may differ, per pose component (\[m\] or \[deg\]), when
/// different engines or kernels make them (tract against onnxruntime, x86 against aarch64): they
/// round the int8 intermediates differently (the requantized outputs of the convolutions and of
/// the quantized matrix products), and the LSTMs carry that on. On the shipped compact model's
/// golden windows tract and onnxruntime differ by up to 0.03.
pub const INT8_TOLERANCE: f32 = 5e-2;
/// How far an int8 file's pose may be from the fp32 file it was quantized from, per pose component
/// (\[m\] or \[deg\]), on one window: the quantization's own error, which a broken quantization
/// (wrong scales, a misread zero point) exceeds by far. The shipped compact files differ by up to
/// 0.052 deg of yaw on their golden windows in tract (0.060 in onnxruntime; the earlier v1-trained
/// files by 0.060 in onnxruntime too). What int8 costs in trajectory error is measured on the
/// benchmark instead (README "Accuracy": the int8 rows beside the fp32 ones).
pub const INT8_VS_FP32_TOLERANCE: f32 = 0.1;

/// What the exporter writes into the ONNX `metadata_props` under the key `milliego` (JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelMeta {
    /// Size configuration (`paper`, `compact`, `tiny`).
    pub config: String,
    /// True when the LSTM state is carried across windows.
    pub stateful: bool,
    /// Fusion LSTM width (the state is 1 x 4 x hidden).
    pub hidden: usize,
    /// Preprocessing the model was trained with.
    pub preprocess: Config,
    /// Normalisation of the radar images.
    pub norm: Norm,
    /// What the radar input's six channels carry (absent in files made before Doppler input
    /// existed: the depth copies).
    #[serde(default)]
    pub radar_input: RadarInput,
    /// Label conventions, in words.
    #[serde(default)]
    pub label: String,
    /// False for graphs with random weights (speed benchmarks only).
    pub trained: bool,
    /// `fp32` or `int8`.
    pub precision: String,
    /// Parameter count, if recorded.
    #[serde(default)]
    pub params: Option<u64>,
    /// Validation ATE of the checkpoint \[m\], if recorded.
    #[serde(default)]
    pub val_ate_m: Option<f64>,
}

/// Why a model could not be loaded or run. Every variant names the file.
#[derive(Debug)]
pub enum ModelError {
    /// The file could not be read or parsed as ONNX.
    Load {
        /// Model file.
        path: PathBuf,
        /// Cause.
        why: String,
    },
    /// The metadata is missing or malformed.
    Metadata {
        /// Model file.
        path: PathBuf,
        /// Cause.
        why: String,
    },
    /// The graph's inputs or outputs do not match what the preprocessing produces.
    Interface {
        /// Model file.
        path: PathBuf,
        /// What differs.
        why: String,
    },
    /// The metadata names a preprocessing setting this build cannot use.
    Setting {
        /// Model file.
        path: PathBuf,
        /// The setting and what it must be.
        error: milliego_preprocess::SettingError,
    },
    /// tract could not optimise or run the graph.
    Run {
        /// Model file.
        path: PathBuf,
        /// Cause.
        why: String,
    },
}

impl std::fmt::Display for ModelError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (what, path, why): (&str, &PathBuf, &dyn std::fmt::Display) = match self {
            ModelError::Load { path, why } => ("cannot load", path, why),
            ModelError::Metadata { path, why } => ("bad metadata in", path, why),
            ModelError::Interface { path, why } => ("interface mismatch in", path, why),
            ModelError::Setting { path, error } => ("unusable metadata in", path, error),
            ModelError::Run { path, why } => ("inference failed with", path, why),
        };
        write!(f, "model: {what} {}: {why}", path.display())
    }
}

impl std::error::Error for ModelError {}

/// A loaded, optimised model with its LSTM state.
#[derive(Debug)]
pub struct Model {
    path: PathBuf,
    meta: ModelMeta,
    /// One tract execution state, reused for every window (its buffers stay allocated).
    exec: TypedSimpleState,
    state: Tensor,
    zero_state: Tensor,
    radar: Box<[f32; RADAR_LEN]>,
    steps: u64,
    prepared: milliego_accel::Prepared,
    /// Radar input zeroed (the ablation `milliego score` reports).
    radar_zeroed: bool,
    /// The graph has the `pose_std` output.
    uncertainty: bool,
    /// The last step's `pose_std`.
    pose_std: Option<[f32; 6]>,
}

/// The values of an f32 tensor, in order.
pub fn floats(t: &Tensor) -> Result<Vec<f32>, String> {
    let v = t
        .to_plain_array_view::<f32>()
        .map_err(|e| format!("{e:#}"))?;
    Ok(v.iter().copied().collect())
}

/// The ONNX file's `milliego` metadata, without building the graph.
pub fn read_meta(path: &Path) -> Result<ModelMeta, ModelError> {
    let proto = tract_onnx::onnx()
        .proto_model_for_path(path)
        .map_err(|e| ModelError::Load {
            path: path.into(),
            why: format!("{e:#}"),
        })?;
    meta_of(path, &proto)
}

fn meta_of(path: &Path, proto: &tract_onnx::pb::ModelProto) -> Result<ModelMeta, ModelError> {
    let bad = |why: String| ModelError::Metadata {
        path: path.into(),
        why,
    };
    let entry = proto
        .metadata_props
        .iter()
        .find(|p| p.key == "milliego")
        .ok_or_else(|| {
            bad(
                "no 'milliego' entry in metadata_props (not exported by milliego_models.export?)"
                    .into(),
            )
        })?;
    let meta: ModelMeta =
        serde_json::from_str(&entry.value).map_err(|e| bad(format!("milliego entry: {e}")))?;
    let setting = |error| ModelError::Setting {
        path: path.into(),
        error,
    };
    meta.preprocess.validate().map_err(setting)?;
    meta.norm.validate().map_err(setting)?;
    if meta.hidden == 0 || meta.hidden > 65_536 {
        return Err(bad(format!("hidden size {} out of range", meta.hidden)));
    }
    Ok(meta)
}

impl Model {
    /// Loads, checks and optimises `path`. With `expect`, the model's preprocessing settings
    /// must equal it (the runtime passes its own so a model trained differently stops at
    /// start-up).
    pub fn load(path: &Path, expect: Option<&Config>) -> Result<Model, ModelError> {
        Model::load_with_threads(path, expect, 1)
    }

    /// [`Model::load`] with tract's matrix products split over `threads` threads (a pool of its
    /// own, `threads` > 1; 0 is taken as 1). Outputs are the same as with one thread: each thread
    /// computes whole tiles of the product (`tests/golden.rs` checks it).
    pub fn load_with_threads(
        path: &Path,
        expect: Option<&Config>,
        threads: usize,
    ) -> Result<Model, ModelError> {
        let load_err = |e: TractError| ModelError::Load {
            path: path.into(),
            why: format!("{e:#}"),
        };
        let iface = |why: String| ModelError::Interface {
            path: path.into(),
            why,
        };
        let onnx = tract_onnx::onnx();
        let proto = onnx.proto_model_for_path(path).map_err(load_err)?;
        let meta = meta_of(path, &proto)?;
        if let Some(want) = expect {
            if *want != meta.preprocess {
                return Err(iface(format!(
                    "trained with preprocessing {:?}, this runtime uses {want:?}",
                    meta.preprocess
                )));
            }
        }
        let names: Vec<&str> = proto
            .graph
            .as_ref()
            .map(|g| {
                let inits: Vec<&str> = g.initializer.iter().map(|t| t.name.as_str()).collect();
                g.input
                    .iter()
                    .map(|i| i.name.as_str())
                    .filter(|n| !inits.contains(n))
                    .collect()
            })
            .unwrap_or_default();
        if names != INPUTS {
            return Err(iface(format!("inputs {names:?}, expected {INPUTS:?}")));
        }
        let outputs: Vec<&str> = proto
            .graph
            .as_ref()
            .map(|g| g.output.iter().map(|o| o.name.as_str()).collect())
            .unwrap_or_default();
        let uncertainty = match outputs.as_slice() {
            [a, b] if [*a, *b] == OUTPUTS => false,
            [a, b, c] if [*a, *b] == OUTPUTS && *c == STD_OUTPUT => true,
            _ => {
                let why =
                    format!("outputs {outputs:?}, expected {OUTPUTS:?} (then {STD_OUTPUT:?})");
                return Err(iface(why));
            }
        };
        let h = meta.hidden;
        let mut model = onnx.model_for_proto_model(&proto).map_err(load_err)?;
        let shapes: [&[usize]; 3] = [&[1, 6, 64, 256], &[1, IMU_LEN, 6], &[1, STATE_ROWS, h]];
        for (i, s) in shapes.iter().enumerate() {
            model
                .set_input_fact(i, f32::fact(*s).into())
                .map_err(|e| iface(format!("input {} as {s:?}: {e:#}", INPUTS[i])))?;
        }
        let run_err = |e: TractError| ModelError::Run {
            path: path.into(),
            why: format!("{e:#}"),
        };
        let mut typed = model
            .into_optimized()
            .map_err(|e| iface(format!("{e:#}")))?;
        // Faster ops with identical values (packed int8 im2col, vectorised quantize; off with
        // MILLIEGO_ACCEL=0), and always the guard against tract's AMX int8 over-read.
        let prepared = milliego_accel::prepare(&mut typed).map_err(|e| iface(format!("{e:#}")))?;
        let out_shapes: Vec<Vec<usize>> = typed
            .output_outlets()
            .map_err(run_err)?
            .iter()
            .map(|o| {
                typed
                    .outlet_fact(*o)
                    .ok()
                    .and_then(|f| f.shape.as_concrete().map(|s| s.to_vec()))
                    .unwrap_or_default()
            })
            .collect();
        let mut want = vec![vec![1, 6], vec![1, STATE_ROWS, h]];
        if uncertainty {
            want.push(vec![1, 6]);
        }
        if out_shapes != want {
            return Err(iface(format!(
                "output shapes {out_shapes:?}, expected {want:?} ({outputs:?})"
            )));
        }
        let plan = if threads > 1 {
            let opts = tract_onnx::tract_core::runtime::RunOptions {
                executor: Some(tract_linalg::multithread::Executor::multithread(threads)),
                ..Default::default()
            };
            TypedSimplePlan::new_with_options(typed, &opts).map_err(run_err)?
        } else {
            typed.into_runnable().map_err(run_err)?
        };
        let exec = TypedSimpleState::new(&plan).map_err(run_err)?;
        let zero_state = Tensor::zero::<f32>(&[1, STATE_ROWS, h]).map_err(run_err)?;
        Ok(Model {
            path: path.into(),
            meta,
            state: zero_state.clone(),
            zero_state,
            exec,
            radar: Box::new([0.0; RADAR_LEN]),
            radar_zeroed: false,
            steps: 0,
            prepared,
            uncertainty,
            pose_std: None,
        })
    }

    /// What the plan passes of `milliego-accel` changed, or `None` when they were turned off
    /// (`MILLIEGO_ACCEL=0`).
    pub fn accel(&self) -> Option<&milliego_accel::Report> {
        self.prepared.speed.as_ref()
    }

    /// What the AMX over-read guard found and padded (docs/amx-overread.md).
    pub fn amx_guard(&self) -> &milliego_accel::AmxGuard {
        &self.prepared.amx
    }

    /// The model's metadata.
    pub fn meta(&self) -> &ModelMeta {
        &self.meta
    }

    /// The file it came from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Windows run so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Forgets the LSTM state (after a gap in the windows, a sensor restart).
    pub fn reset(&mut self) {
        self.state = self.zero_state.clone();
        self.pose_std = None;
    }

    /// True when the graph predicts its own uncertainty (the `pose_std` output).
    pub fn has_uncertainty(&self) -> bool {
        self.uncertainty
    }

    /// The last step's predicted standard deviation of each pose component `[tx, ty, tz [m],
    /// roll, pitch, yaw [deg]]`; `None` for a model without the uncertainty head or before a step.
    pub fn pose_std(&self) -> Option<[f32; 6]> {
        self.pose_std
    }

    /// Feeds zeros instead of the radar images from now on (`true`): the ablation that shows
    /// what the radar adds to the network (`milliego score`'s "radar zeroed" rows).
    pub fn set_radar_zeroed(&mut self, zeroed: bool) {
        self.radar_zeroed = zeroed;
    }

    /// One window: returns the relative pose `[tx, ty, tz, roll, pitch, yaw]`.
    pub fn step(&mut self, w: &Window<'_>) -> Result<[f32; 6], ModelError> {
        if self.radar_zeroed {
            self.radar.fill(0.0);
        } else {
            w.radar_tensor(self.meta.radar_input, &self.meta.norm, &mut self.radar);
        }
        let radar = self.tensor(&[1, 6, 64, 256], &self.radar[..])?;
        let imu = self.imu_tensor(w.imu)?;
        self.step_with(radar, imu)
    }

    /// One step on prepared inputs (radar 6 x 64 x 256 channels-first, IMU 20 x 6).
    pub fn step_tensors(
        &mut self,
        radar: &[f32],
        imu: &[[f32; 6]; IMU_LEN],
    ) -> Result<[f32; 6], ModelError> {
        let radar = self.tensor(&[1, 6, 64, 256], radar)?;
        let imu = self.imu_tensor(imu)?;
        self.step_with(radar, imu)
    }

    fn step_with(&mut self, radar: Tensor, imu: Tensor) -> Result<[f32; 6], ModelError> {
        let state = if self.meta.stateful {
            self.state.clone()
        } else {
            self.zero_state.clone()
        };
        let (pose, state_out, std) = self.run_raw_with_std(radar, imu, state)?;
        if self.meta.stateful {
            self.state = state_out;
        }
        self.pose_std = std;
        self.steps += 1;
        Ok(pose)
    }

    fn run_err(&self, why: String) -> ModelError {
        ModelError::Run {
            path: self.path.clone(),
            why,
        }
    }

    /// A tensor of `shape` from `data` (length checked).
    pub fn tensor(&self, shape: &[usize], data: &[f32]) -> Result<Tensor, ModelError> {
        Tensor::from_shape(shape, data).map_err(|e| self.run_err(format!("{e:#}")))
    }

    fn imu_tensor(&self, imu: &[[f32; 6]; IMU_LEN]) -> Result<Tensor, ModelError> {
        let mut flat = [0.0f32; IMU_LEN * 6];
        for (d, s) in flat.chunks_exact_mut(6).zip(imu) {
            d.copy_from_slice(s);
        }
        self.tensor(&[1, IMU_LEN, 6], &flat)
    }

    /// Runs the graph once with explicit inputs (radar 1 x 6 x 64 x 256, IMU 1 x 20 x 6, state
    /// 1 x 4 x hidden); returns the pose and the new state. The model's own state is untouched.
    pub fn run_raw(
        &mut self,
        radar: Tensor,
        imu: Tensor,
        state: Tensor,
    ) -> Result<([f32; 6], Tensor), ModelError> {
        self.run_raw_with_std(radar, imu, state)
            .map(|(pose, state_out, _)| (pose, state_out))
    }

    /// [`Model::run_raw`], with the predicted deviation when the graph has the `pose_std` output
    /// (checked positive and finite).
    #[allow(clippy::type_complexity)]
    pub fn run_raw_with_std(
        &mut self,
        radar: Tensor,
        imu: Tensor,
        state: Tensor,
    ) -> Result<([f32; 6], Tensor, Option<[f32; 6]>), ModelError> {
        let result = self.exec.run(tvec![radar.into(), imu.into(), state.into()]);
        let mut out = result.map_err(|e| self.run_err(format!("{e:#}")))?;
        let std = if self.uncertainty {
            let t = out
                .pop()
                .ok_or_else(|| self.run_err("no pose_std output".into()))?;
            let v = floats(&t.into_tensor()).map_err(|e| self.run_err(e))?;
            let std: [f32; 6] = v
                .as_slice()
                .try_into()
                .map_err(|_| self.run_err(format!("pose_std has {} values", v.len())))?;
            if !std.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(self.run_err(format!("pose_std {std:?} is not positive and finite")));
            }
            Some(std)
        } else {
            None
        };
        let state_out = out
            .pop()
            .ok_or_else(|| self.run_err("no state output".into()))?;
        let pose_t = out
            .pop()
            .ok_or_else(|| self.run_err("no pose output".into()))?;
        let p = floats(&pose_t.into_tensor()).map_err(|e| self.run_err(e))?;
        if p.len() != 6 {
            return Err(self.run_err(format!("pose has {} values", p.len())));
        }
        let mut pose = [0.0f32; 6];
        pose.copy_from_slice(&p);
        if !pose.iter().all(|v| v.is_finite()) {
            return Err(self.run_err(format!("non-finite pose {pose:?}")));
        }
        Ok((pose, state_out.into_tensor(), std))
    }
}
