//! The passes must not change a single value: every test here compares tract's own ops (or a whole
//! stock plan) against the accelerated ones on the same inputs, byte for byte.

use milliego_accel::{accelerate, amx_tile_slack, quantize_i8, FastQuantizeI8, PackedIm2Col};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::{EvalContext, EvalOp, TypedOp};
use tract_onnx::tract_core::ops::cnn::conv::{Conv, Im2Col};
use tract_onnx::tract_core::ops::cnn::{KernelFormat, PaddingSpec, PoolSpec};
use tract_onnx::tract_core::ops::nn::DataFormat;
use tract_onnx::tract_core::ops::quant::quantize_linear_f32_i8;
use tract_onnx::tract_core::tract_linalg::mmm::{
    EagerPackedInput, PackedExoticFact, PackedMatrixStorage,
};
use tract_onnx::tract_core::tract_linalg::pack::PackedFormat;
use tract_onnx::tract_core::tract_linalg::MmmDispatch;

/// One quantized convolution's geometry.
#[derive(Debug, Clone)]
struct Geo {
    c: usize,
    h: usize,
    w: usize,
    o: usize,
    kernel: [usize; 2],
    stride: [usize; 2],
    dilation: [usize; 2],
    pad_before: [usize; 2],
    pad_after: [usize; 2],
    group: usize,
    /// Input zero point (the im2col padding value).
    x0: i8,
}

impl Geo {
    fn pool_spec(&self) -> PoolSpec {
        PoolSpec {
            data_format: DataFormat::NCHW,
            kernel_shape: tvec!(self.kernel[0], self.kernel[1]),
            padding: PaddingSpec::Explicit(
                tvec!(self.pad_before[0], self.pad_before[1]),
                tvec!(self.pad_after[0], self.pad_after[1]),
            ),
            dilations: Some(tvec!(self.dilation[0], self.dilation[1])),
            strides: Some(tvec!(self.stride[0], self.stride[1])),
            input_channels: self.c,
            output_channels: self.o,
        }
    }
}

/// Geometries covering the paper graph's convolutions (7x7/5x5 stride 2, 3x3 stride 1 and 2) and
/// the corners: k not a multiple of 4, n not a multiple of the panel width, stride 3, dilation,
/// asymmetric and no padding, groups, a non-zero input zero point, one output position.
fn geometries() -> Vec<Geo> {
    let g = |c, h, w, o, kernel, stride, dilation, pad_before, pad_after, group, x0| Geo {
        c,
        h,
        w,
        o,
        kernel,
        stride,
        dilation,
        pad_before,
        pad_after,
        group,
        x0,
    };
    vec![
        g(6, 16, 48, 16, [7, 7], [2, 2], [1, 1], [3, 3], [3, 3], 1, 0),
        g(6, 16, 48, 8, [7, 7], [2, 2], [1, 1], [3, 3], [3, 3], 1, 0),
        g(16, 12, 20, 32, [5, 5], [2, 2], [1, 1], [2, 2], [2, 2], 1, 0),
        g(5, 9, 11, 16, [3, 3], [1, 1], [1, 1], [1, 1], [1, 1], 1, 0),
        g(7, 10, 13, 12, [3, 2], [1, 3], [2, 1], [0, 2], [1, 0], 1, 0),
        g(8, 11, 17, 8, [3, 3], [2, 1], [1, 2], [0, 0], [0, 0], 2, 0),
        g(4, 8, 9, 20, [3, 3], [1, 1], [1, 1], [1, 1], [1, 1], 1, 5),
        g(3, 5, 5, 4, [5, 5], [1, 1], [1, 1], [0, 0], [0, 0], 1, -3),
        g(24, 6, 6, 40, [3, 3], [2, 2], [1, 1], [1, 1], [1, 1], 1, 0),
    ]
}

fn random_i8(rng: &mut StdRng, shape: &[usize]) -> Tensor {
    let n: usize = shape.iter().product();
    let v: Vec<i8> = (0..n).map(|_| rng.gen()).collect();
    Tensor::from_shape(shape, &v).unwrap()
}

/// A model with one quantized convolution (i8 in, i8 out), optimised by tract.
fn conv_model(geo: &Geo, rng: &mut StdRng) -> TractResult<TypedModel> {
    let mut model = TypedModel::default();
    let x = model.add_source("x", i8::fact([1, geo.c, geo.h, geo.w]))?;
    let kernel = random_i8(
        rng,
        &[geo.o, geo.c / geo.group, geo.kernel[0], geo.kernel[1]],
    );
    let bias: Vec<i32> = (0..geo.o).map(|_| rng.gen_range(-500..500)).collect();
    let mut c = |name: &str, t: Tensor| model.add_const(name, t);
    let inputs = [
        x,
        c("kernel", kernel)?,
        c("bias", Tensor::from_shape(&[geo.o], &bias)?)?,
        c("x0", tensor0(i32::from(geo.x0)))?,
        c("x_scale", tensor0(0.05f32))?,
        c("k0", tensor0(0i32))?,
        c("k_scale", tensor0(0.01f32))?,
        c("y0", tensor0(0i32))?,
        c("y_scale", tensor0(0.5f32))?,
    ];
    let conv = Conv {
        pool_spec: geo.pool_spec(),
        kernel_fmt: KernelFormat::OIHW,
        group: geo.group,
        q_params: Some(i8::datum_type()),
    };
    let y = model.wire_node("conv", conv, &inputs)?;
    model.select_output_outlets(&y)?;
    model.into_optimized()
}

fn run(model: TypedModel, x: &Tensor) -> TractResult<Tensor> {
    let plan = model.into_runnable()?;
    Ok(plan.run(tvec!(x.clone().into()))?.remove(0).into_tensor())
}

#[test]
fn quantized_convolutions_are_bit_identical() -> TractResult<()> {
    let mut rng = StdRng::seed_from_u64(7);
    let mut replaced = 0;
    for geo in geometries() {
        let stock = conv_model(&geo, &mut rng)?;
        let mut fast = stock.clone();
        let report = accelerate(&mut fast)?;
        assert!(report.im2col_kept.is_empty(), "{geo:?}: {report}");
        replaced += report.im2col_replaced;
        for _ in 0..3 {
            let x = random_i8(&mut rng, &[1, geo.c, geo.h, geo.w]);
            let (a, b) = (run(stock.clone(), &x)?, run(fast.clone(), &x)?);
            assert_eq!(a, b, "{geo:?}");
        }
    }
    // The comparison above means something only if the pass took the im2col over.
    assert_eq!(replaced, geometries().len());
    Ok(())
}

/// The bytes of batch item 0, group `g` of a packed im2col output.
fn packed_bytes(t: &Tensor, g: usize) -> Vec<u8> {
    let storage = t
        .try_storage_as::<PackedMatrixStorage>()
        .expect("packed output");
    let value = storage.value_at(&[0, g]);
    let eager = value
        .downcast_ref::<EagerPackedInput>()
        .expect("eager packed input");
    eager.packed.as_bytes().to_vec()
}

/// tract's `Im2col` and ours evaluated directly, for every packing the host's int8 kernels use
/// (K=4-inner for VNNI/AMX) and for the K-major `PackedFormat` of the AVX2/portable kernels.
#[test]
fn im2col_panels_match_tract_for_every_int8_packing() -> TractResult<()> {
    let mut rng = StdRng::seed_from_u64(11);
    let mut layouts = std::collections::BTreeSet::new();
    for geo in geometries() {
        let input = i8::fact([1, geo.c, geo.h, geo.w]);
        let k = geo.c / geo.group * geo.kernel[0] * geo.kernel[1];
        for mmm in MmmDispatch::native().runnable() {
            for (packing, (_, b)) in mmm.packings().iter().enumerate() {
                let k_major = b
                    .downcast_ref::<PackedFormat>()
                    .is_some_and(|f| f.dt == i8::datum_type());
                let k4 = format!("{b:?}").starts_with("PackedI8K4");
                if !(k_major || k4) {
                    continue;
                }
                let tract_op = Im2Col::new(
                    geo.pool_spec(),
                    geo.group,
                    k,
                    &input.shape,
                    mmm.clone(),
                    packing,
                )?;
                let out_fact = tract_op.output_facts(&[&input])?.remove(0);
                let ours = PackedIm2Col::from_tract(&tract_op, &input, &out_fact)
                    .map_err(|e| TractError::msg(format!("{geo:?}: {e}")))?;
                let x = random_i8(&mut rng, &[1, geo.c, geo.h, geo.w]);
                let feed = || tvec!(x.clone().into_tvalue(), tensor0(geo.x0).into_tvalue());
                let ctx = EvalContext::out_of_plan();
                let a = EvalOp::eval(&tract_op, &ctx, feed())?.remove(0);
                let b_out = EvalOp::eval(&ours, &ctx, feed())?.remove(0);
                let pof = out_fact.exotic_fact.as_ref().unwrap();
                let pof = pof.downcast_ref::<PackedExoticFact>().unwrap();
                for g in 0..geo.group {
                    let (ta, tb) = (packed_bytes(&a, g), packed_bytes(&b_out, g));
                    // Ours carries the AMX kernels' tile over-read as zeroed slack past the
                    // panels (docs/amx-overread.md); the panels themselves are tract's bytes.
                    let slack = amx_tile_slack(k, pof.format.r());
                    assert_eq!(ta.len() + slack, tb.len(), "{geo:?} {b:?}");
                    assert!(
                        tb[ta.len()..].iter().all(|&x| x == 0),
                        "{geo:?} {b:?}: slack not zeroed"
                    );
                    let tb = tb[..ta.len()].to_vec();
                    if k4 {
                        assert!(ta == tb, "{geo:?} {b:?}: packed bytes differ");
                    } else {
                        // tract leaves a K-major panel's tail padding unwritten: compare the
                        // items, (k, n) for every k < K and n < N.
                        let r = pof.format.r();
                        let n = pof.mn.as_i64().unwrap() as usize;
                        let pl = ta.len() / n.div_ceil(r);
                        for item in 0..n {
                            for kk in 0..k {
                                let at = item / r * pl + kk * r + item % r;
                                assert_eq!(ta[at], tb[at], "{geo:?} {b:?} k={kk} n={item}");
                            }
                        }
                    }
                }
                layouts.insert(if k4 { "K4" } else { "K-major" });
            }
        }
    }
    // x86_64 and aarch64 hosts always run at least one K-major int8 kernel (the portable ones).
    assert!(
        layouts.contains("K-major"),
        "no K-major int8 kernel tried: {layouts:?}"
    );
    eprintln!("im2col layouts compared: {layouts:?}");
    Ok(())
}

#[test]
fn quantize_matches_tract_wherever_tract_does_not_overflow() {
    let mut rng = StdRng::seed_from_u64(3);
    let mut xs: Vec<f32> = (0..20_000).map(|_| rng.gen_range(-3.0f32..3.0)).collect();
    // Exact ties after scaling (x * 4 = k + 0.5), both signs, the clamp edges and extremes.
    xs.extend((-600..600).map(|k| (k as f32 + 0.5) / 4.0));
    xs.extend([
        0.0,
        -0.0,
        1e-30,
        -1e-30,
        1e30,
        -1e30,
        f32::MAX,
        f32::MIN,
        31.875,
        -32.125,
    ]);
    xs.extend([f32::INFINITY, f32::NEG_INFINITY]);
    for (scale, zp) in [
        (4.0f32, 0i8),
        (132.80135, 0),
        (4.0, 3),
        (0.37, -5),
        (40.0, 127),
    ] {
        let mut ours = vec![0i8; xs.len()];
        quantize_i8(&xs, &mut ours, scale, zp);
        for (x, y) in xs.iter().zip(&ours) {
            let theirs = if (x * scale).abs() >= 2f32.powi(31) {
                // tract's `round(x * scale) as i32 + zero_point` overflows out there (the sum
                // wraps in release builds); this op saturates, which is what the clamp means.
                if *x > 0.0 {
                    127
                } else {
                    -128
                }
            } else {
                quantize_linear_f32_i8(*x, scale, i32::from(zp))
            };
            assert_eq!(*y, theirs, "x={x} scale={scale} zp={zp}");
        }
    }
}

#[test]
fn shipped_int8_model_runs_bit_identical_with_the_passes() -> TractResult<()> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/compact/model-int8.onnx");
    let load = || -> TractResult<TypedModel> {
        let mut m = tract_onnx::onnx().model_for_path(&path)?;
        let h = 128; // the shipped compact model's LSTM width (tract checks it against the graph)
        for (i, s) in [vec![1, 6, 64, 256], vec![1, 20, 6], vec![1, 4, h]]
            .iter()
            .enumerate()
        {
            m.set_input_fact(i, f32::fact(s.as_slice()).into())?;
        }
        m.into_optimized()
    };
    let stock = load()?;
    let mut fast = stock.clone();
    let report = accelerate(&mut fast)?;
    assert!(report.im2col_replaced >= 9, "{report}");
    assert!(report.quantize_replaced >= 1, "{report}");
    assert!(report.im2col_kept.is_empty(), "{report}");
    let nodes =
        |m: &TypedModel, name: &str| m.nodes().iter().filter(|n| n.op().name() == name).count();
    assert_eq!(nodes(&fast, "Im2col"), 0);
    assert_eq!(nodes(&fast, "PackedIm2col"), report.im2col_replaced);
    assert!(nodes(&fast, "FastQuantizeI8") >= 1);
    let (stock, fast) = (stock.into_runnable()?, fast.into_runnable()?);
    let mut rng = StdRng::seed_from_u64(5);
    for _ in 0..3 {
        let radar: Vec<f32> = (0..6 * 64 * 256)
            .map(|_| rng.gen_range(-1.0..3.0))
            .collect();
        let imu: Vec<f32> = (0..120).map(|_| rng.gen_range(-2.0..2.0)).collect();
        let feed = || -> TractResult<TVec<TValue>> {
            Ok(tvec!(
                Tensor::from_shape(&[1, 6, 64, 256], &radar)?.into(),
                Tensor::from_shape(&[1, 20, 6], &imu)?.into(),
                Tensor::zero::<f32>(&[1, 4, 128])?.into(),
            ))
        };
        let (a, b) = (stock.run(feed()?)?, fast.run(feed()?)?);
        assert_eq!(a.len(), b.len());
        for (a, b) in a.iter().zip(b.iter()) {
            assert_eq!(**a, **b);
        }
    }
    Ok(())
}

#[test]
fn quantize_op_replaces_only_f32_to_i8() -> TractResult<()> {
    use tract_onnx::tract_core::ops::element_wise::ElementWiseOp;
    use tract_onnx::tract_core::ops::quant::{QuantizeLinearI8, QuantizeLinearU8};
    let i8_op = ElementWiseOp(
        Box::new(QuantizeLinearI8 {
            scale: 2.0,
            zero_point: 1,
        }),
        None,
    );
    let u8_op = ElementWiseOp(
        Box::new(QuantizeLinearU8 {
            scale: 2.0,
            zero_point: 1,
        }),
        None,
    );
    let f = f32::fact([4]);
    assert_eq!(
        FastQuantizeI8::from_tract(&i8_op, &f, &i8::fact([4])),
        Some(FastQuantizeI8 {
            scale: 2.0,
            zero_point: 1
        })
    );
    assert_eq!(FastQuantizeI8::from_tract(&u8_op, &f, &u8::fact([4])), None);
    assert_eq!(
        FastQuantizeI8::from_tract(&i8_op, &f16::fact([4]), &i8::fact([4])),
        None
    );
    Ok(())
}
