//! f32 -> i8 quantization (`QuantizeLinear`) that the compiler vectorises.
//!
//! tract's `QuantizeLinearI8` computes `clamp(round_ties_even(x * scale) + zero_point)` one
//! element at a time through a library call for the rounding (no `roundps` in the x86_64
//! baseline); on the paper-size graph the radar input alone costs 0.17 ms per call. Here the
//! rounding is the classic add-and-subtract of 1.5 * 2^23: for |t| < 2^22 the sum lands where the
//! float spacing is exactly 1, so the hardware's round-to-nearest-even does the rounding, and
//! for larger |t| the result saturates to -128 or 127 either way. Values match tract's for every
//! finite input (`tests/bit_exact.rs`); for an infinite input with a non-zero zero point this op
//! saturates where tract's i32 sum would overflow.

use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::*;
use tract_onnx::tract_core::ops::element_wise::ElementWiseOp;
use tract_onnx::tract_core::ops::quant::QuantizeLinearI8;
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};

/// `QuantizeLinear` from f32 to i8: `y = clamp(round_ties_even(x * scale) + zero_point)`.
#[derive(Debug, Clone, PartialEq)]
pub struct FastQuantizeI8 {
    /// Multiplier (the reciprocal of the ONNX scale, as tract stores it).
    pub scale: f32,
    pub zero_point: i8,
}

impl Eq for FastQuantizeI8 {}

impl std::hash::Hash for FastQuantizeI8 {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.scale.to_bits().hash(state);
        self.zero_point.hash(state);
    }
}

/// 1.5 * 2^23: adding it to |t| <= 256 lands where the float spacing is exactly 1, so the
/// hardware's round-to-nearest-even rounds t, and the low bits of the sum are the integer.
const ROUNDER: f32 = 12_582_912.0;
/// `ROUNDER.to_bits()`.
const ROUNDER_BITS: i32 = 0x4B40_0000;

/// Quantizes `x` into `y` (same length). NaN gives -128 (tract's op gives the zero point).
pub fn quantize_i8(x: &[f32], y: &mut [i8], scale: f32, zero_point: i8) {
    let zp = i32::from(zero_point);
    for (x, y) in x.iter().zip(y) {
        // Clamping to +-256 first changes nothing after the final clamp to i8 (|zp| <= 128).
        // max/min rather than clamp: they turn NaN into -256, clamp would keep it.
        #[allow(clippy::manual_clamp)]
        let t = (x * scale).max(-256.0).min(256.0);
        let i = (t + ROUNDER).to_bits() as i32 - ROUNDER_BITS;
        *y = (i + zp).clamp(-128, 127) as i8;
    }
}

impl FastQuantizeI8 {
    /// The replacement for a tract `QuantizeLinearI8` node reading f32 and writing plain i8.
    pub fn from_tract(op: &ElementWiseOp, input: &TypedFact, output: &TypedFact) -> Option<Self> {
        let q = op.0.downcast_ref::<QuantizeLinearI8>()?;
        (input.datum_type == f32::datum_type() && output.datum_type == i8::datum_type()).then_some(
            FastQuantizeI8 {
                scale: q.scale,
                zero_point: q.zero_point,
            },
        )
    }
}

impl Op for FastQuantizeI8 {
    fn name(&self) -> StaticName {
        "FastQuantizeI8".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!(
            "scale: {} zero_point: {}",
            self.scale, self.zero_point
        )])
    }

    op_as_typed_op!();
}

impl EvalOp for FastQuantizeI8 {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        ensure!(inputs.len() == 1, "FastQuantizeI8: {} inputs", inputs.len());
        let xv = inputs[0]
            .as_plain_ram()
            .context("FastQuantizeI8: input not in memory")?;
        let mut y = Tensor::zero::<i8>(inputs[0].shape())?;
        {
            let mut yv = y
                .as_plain_ram_mut()
                .context("FastQuantizeI8: output not in memory")?;
            let ys = yv.as_slice_mut::<i8>()?;
            quantize_i8(xv.as_slice::<f32>()?, ys, self.scale, self.zero_point);
        }
        Ok(tvec!(y.into_tvalue()))
    }
}

impl TypedOp for FastQuantizeI8 {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        Ok(tvec!(i8::fact(inputs[0].shape.clone())))
    }
}
