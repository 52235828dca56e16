//! Plan passes that make tract's optimised milliEgo graphs faster (stage "model": between
//! `into_optimized` and `into_runnable`).
//!
//! [`accelerate`] walks an optimised `TypedModel` and swaps ops for faster ones that compute the
//! same values bit for bit:
//!
//! - tract's eager `Im2col` of 8-bit convolutions becomes [`PackedIm2Col`], which writes the
//!   int8 kernels' panels in whole rows instead of one element at a time. On the paper-size int8
//!   graph that op was 41-45% of the call (docs/int8-speed.md).
//! - tract's f32 -> i8 `QuantizeLinear` becomes [`FastQuantizeI8`], which rounds without a
//!   library call per element, so the compiler vectorises it.
//!
//! A node the pass cannot take over (another layout, a symbolic shape) keeps tract's op, and the
//! [`Report`] says which and why. `MILLIEGO_ACCEL=0` in the environment turns the pass off
//! ([`enabled`]), for side-by-side timing against the stock plan.
//!
//! ```no_run
//! use tract_onnx::prelude::*;
//! let mut model = tract_onnx::onnx()
//!     .model_for_path("models/compact/model-int8.onnx")?
//!     .into_optimized()?;
//! let report = milliego_accel::accelerate(&mut model)?;
//! eprintln!("{report}");
//! let plan = model.into_runnable()?;
//! # Ok::<(), TractError>(())
//! ```
// One audited exception: calling the SSE2/NEON byte interleave (baseline features of the two
// targets) in `im2col.rs`. Everything else is safe code.
#![deny(unsafe_code)]

mod amx;
mod im2col;
mod quantize;

pub use amx::{amx_nr, guard_amx, is_amx_kernel, AmxGuard, PanelSlack};
pub use im2col::{amx_tile_slack, PackedIm2Col};
pub use quantize::{quantize_i8, FastQuantizeI8};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::cnn::conv::Im2Col;
use tract_onnx::tract_core::ops::element_wise::ElementWiseOp;

/// What [`accelerate`] changed in a plan.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Report {
    /// `Im2col` nodes now running as [`PackedIm2Col`].
    pub im2col_replaced: usize,
    /// `Im2col` nodes left to tract: (node name, why).
    pub im2col_kept: Vec<(String, String)>,
    /// f32 -> i8 `QuantizeLinear` nodes now running as [`FastQuantizeI8`].
    pub quantize_replaced: usize,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} im2col node(s) packed, {} quantize node(s) vectorised",
            self.im2col_replaced, self.quantize_replaced
        )?;
        for (name, why) in &self.im2col_kept {
            write!(f, "; kept {name}: {why}")?;
        }
        Ok(())
    }
}

/// Whether the passes run: on unless `MILLIEGO_ACCEL` is `0`, `off` or `false`.
pub fn enabled() -> bool {
    !matches!(
        std::env::var("MILLIEGO_ACCEL")
            .ok()
            .as_deref()
            .map(str::trim),
        Some("0" | "off" | "false")
    )
}

/// What [`prepare`] did to a plan.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Prepared {
    /// The speed passes' report, `None` when they were turned off ([`enabled`]).
    pub speed: Option<Report>,
    /// The AMX over-read guard's report (it always runs: it is a safety fix, not a speed pass).
    pub amx: AmxGuard,
}

/// Everything this crate does between `into_optimized` and `into_runnable`: the speed passes
/// ([`accelerate`]) unless `MILLIEGO_ACCEL=0`, then [`guard_amx`] in every case.
pub fn prepare(model: &mut TypedModel) -> TractResult<Prepared> {
    let speed = if enabled() {
        Some(accelerate(model)?)
    } else {
        None
    };
    let amx = guard_amx(model)?;
    Ok(Prepared { speed, amx })
}

/// Applies every pass to an optimised model in place. Values computed by the plan do not change.
pub fn accelerate(model: &mut TypedModel) -> TractResult<Report> {
    let mut report = Report::default();
    for id in 0..model.nodes().len() {
        let node = model.node(id);
        if let Some(op) = node.op_as::<ElementWiseOp>() {
            let input = model.outlet_fact(node.inputs[0])?;
            if let Some(fast) = FastQuantizeI8::from_tract(op, input, &node.outputs[0].fact) {
                model.node_mut(id).op = Box::new(fast);
                report.quantize_replaced += 1;
            }
            continue;
        }
        let Some(op) = node.op_as::<Im2Col>() else {
            continue;
        };
        let input = model.outlet_fact(node.inputs[0])?;
        let output = &node.outputs[0].fact;
        match PackedIm2Col::from_tract(op, input, output) {
            Ok(packed) => {
                model.node_mut(id).op = Box::new(packed);
                report.im2col_replaced += 1;
            }
            Err(why) => report.im2col_kept.push((node.name.clone(), why)),
        }
    }
    Ok(report)
}
