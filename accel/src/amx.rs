//! The guard against tract 0.23's AMX int8 over-read (docs/amx-overread.md).
//!
//! `avx512amx_mmm_i32_{8x8,16x16}` take B as `PackedI8K4` panels (K padded to 4) but load them as
//! whole AMX tiles of 64 K values, so the last tile of a panel reads up to 60 K rows past it; past
//! the last panel that is past the buffer ([`amx_tile_slack`] bytes), and the process dies with
//! SIGSEGV when those bytes lie on an unmapped page. The bytes read meet the A panel's zero
//! K-padding, so they never change a value: giving them a home is the whole fix.
//!
//! [`guard_amx`] walks an optimised plan and makes every B operand of an AMX matmul carry that
//! slack: [`crate::PackedIm2Col`] already allocates it; any other producer (tract's own `Im2col`
//! when the speed passes are off, a runtime packer) gets a [`PanelSlack`] after it, and constant
//! B operands are re-packed once. It runs whether or not the speed passes do.

use crate::im2col::amx_tile_slack;
use crate::PackedIm2Col;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::*;
use tract_onnx::tract_core::ops::matmul::optimized::{MatMulOperand, OptMatMul, ProtoFusedSpec};
use tract_onnx::tract_core::tract_linalg::mmm::{
    EagerPackedInput, MMMInputValue, PackedMatrixStorage,
};
use tract_onnx::tract_core::{as_op, op_as_typed_op, op_out_of_plan};

/// Alignment of the re-allocated panels \[B\] (a cache line; AMX tile loads want 64).
const ALIGN: usize = 64;

/// What [`guard_amx`] found and did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AmxGuard {
    /// Matmul nodes running an AMX int8 kernel.
    pub amx_matmuls: usize,
    /// Of those, B operands whose K is not a multiple of 64 (the ones that over-read).
    pub overreading: usize,
    /// B operands already carrying the slack ([`PackedIm2Col`] outputs).
    pub already_safe: usize,
    /// B operands given a [`PanelSlack`] after their producer.
    pub slack_ops: usize,
    /// Constant B operands re-packed with the slack.
    pub consts_padded: usize,
}

impl std::fmt::Display for AmxGuard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} AMX matmul(s), {} over-reading B operand(s): {} already padded, {} padded at run time, {} constant(s) re-packed",
            self.amx_matmuls, self.overreading, self.already_safe, self.slack_ops, self.consts_padded
        )
    }
}

/// True for tract's AMX int8 kernels, the ones that read B in K=64 tiles.
pub fn is_amx_kernel(name: &str) -> bool {
    name.starts_with("avx512amx_")
}

/// The widest B panel (`nr`) among the AMX int8 kernels `op` may run, `None` when it runs none.
pub fn amx_nr(op: &OptMatMul) -> Option<usize> {
    op.mmm
        .iter()
        .filter(|m| is_amx_kernel(m.name()))
        .map(|m| m.nr())
        .max()
}

/// Makes every B operand of an AMX int8 matmul in `model` safe to over-read (see the module
/// docs). Values computed by the plan do not change.
pub fn guard_amx(model: &mut TypedModel) -> TractResult<AmxGuard> {
    let mut report = AmxGuard::default();
    // (node, input slot of B, slack) for B operands that need a PanelSlack after their producer.
    let mut wrap: Vec<(usize, usize, usize)> = Vec::new();
    for id in 0..model.nodes().len() {
        let Some(op) = model.node(id).op_as::<OptMatMul>() else {
            continue;
        };
        let Some(nr) = amx_nr(op) else {
            continue;
        };
        report.amx_matmuls += 1;
        let mut consts = Vec::new();
        for (ix, spec) in op.micro_ops.iter().enumerate() {
            let ProtoFusedSpec::AddMatMul { geo, b, .. } = spec else {
                continue;
            };
            // A symbolic K: assume the worst tail (60 K rows).
            let slack = geo.k.to_usize().map_or(60 * nr, |k| amx_tile_slack(k, nr));
            if slack == 0 {
                continue;
            }
            report.overreading += 1;
            match b {
                MatMulOperand::Input(slot) => {
                    let producer = model.node(model.node(id).inputs[*slot].node);
                    if producer.op_is::<PackedIm2Col>() {
                        report.already_safe += 1;
                    } else {
                        wrap.push((id, *slot, slack));
                    }
                }
                MatMulOperand::Const(v) => consts.push((ix, pad_value(&**v, slack)?)),
            }
        }
        if !consts.is_empty() {
            report.consts_padded += consts.len();
            let op = model
                .node_mut(id)
                .op_as_mut::<OptMatMul>()
                .context("OptMatMul node changed type")?;
            for (ix, v) in consts {
                if let ProtoFusedSpec::AddMatMul { b, .. } = &mut op.micro_ops[ix] {
                    *b = MatMulOperand::Const(v);
                }
            }
        }
    }
    for (id, slot, slack) in wrap {
        let outlet = model.node(id).inputs[slot];
        let name = format!("{}.amx_slack.{slot}", model.node(id).name);
        let padded = model.wire_node(name, PanelSlack { slack }, &[outlet])?[0];
        model.add_edge(padded, InletId::new(id, slot))?;
        report.slack_ops += 1;
    }
    Ok(report)
}

/// `v` copied into a buffer `slack` zero bytes longer.
fn pad_value(v: &dyn MMMInputValue, slack: usize) -> TractResult<Box<dyn MMMInputValue>> {
    let Some(e) = v.downcast_ref::<EagerPackedInput>() else {
        bail!(
            "AMX guard: B operand {v} is not eagerly packed; its panels cannot be given the \
             {slack} bytes the AMX kernel reads past them"
        );
    };
    let bytes = e.packed.as_bytes();
    let mut padded = Tensor::zero_aligned_dt(u8::datum_type(), &[bytes.len() + slack], ALIGN)?;
    padded.as_bytes_mut()[..bytes.len()].copy_from_slice(bytes);
    Ok(Box::new(EagerPackedInput {
        fact: e.fact.clone(),
        packed: Arc::new(padded.into_blob()?),
        panel_bytes: e.panel_bytes,
        mn: e.mn,
    }))
}

/// Copies packed B panels into buffers `slack` zero bytes longer, so the AMX kernels' whole-tile
/// reads stay inside them. Inserted by [`guard_amx`] after producers it does not control.
#[derive(Debug, Clone, Hash, PartialEq, Eq)]
pub struct PanelSlack {
    /// Zero bytes added past the last panel \[B\].
    pub slack: usize,
}

impl Op for PanelSlack {
    fn name(&self) -> StaticName {
        "PanelSlack".into()
    }

    fn info(&self) -> TractResult<Vec<String>> {
        Ok(vec![format!("{} bytes past the last panel", self.slack)])
    }

    op_as_typed_op!();
}

impl EvalOp for PanelSlack {
    op_out_of_plan!();

    fn eval(&self, _ctx: &EvalContext, inputs: TVec<TValue>) -> TractResult<TVec<TValue>> {
        let input = args_1!(inputs);
        let storage = input
            .try_storage_as::<PackedMatrixStorage>()
            .context("PanelSlack: input is not packed panels")?;
        let values = storage
            .values()
            .iter()
            .map(|v| pad_value(&**v, self.slack))
            .collect::<TractResult<TVec<_>>>()?;
        Ok(tvec!(PackedMatrixStorage::new_batched(
            storage.batch_shape(),
            values
        )
        .into_tensor(input.datum_type())
        .into_tvalue()))
    }
}

impl TypedOp for PanelSlack {
    as_op!();

    fn output_facts(&self, inputs: &[&TypedFact]) -> TractResult<TVec<TypedFact>> {
        Ok(tvec!(inputs[0].clone()))
    }
}
