"""Static int8 quantization in the form tract runs fastest.

    python -m milliego_models.quantize --model model.onnx --data DATASET_DIR --out model-int8.onnx \
        [--calib-windows 256] [--per-channel] [--ops auto|conv|conv+matmul] [--min-matmul-weights N]

Recipe (see shared/reference/milliego-model.md, tract findings): onnxruntime `quantize_static`,
QOperator format, s8 activations and weights, both symmetric (zero point 0, so tract folds the int8
weights once), only standard QLinearConv and QLinearMatMul plus
QuantizeLinear / DequantizeLinear around them; every other op stays fp32. Default `--ops auto`: the
convolutions, and the MatMuls whose weight matrix has at least 2^18 elements (memory-bound matrix-
vector products: the fusion-LSTM input projections; in the compact model only the first one's two
parts, below). On the simulator's held-out test set the compact model's int8 ATE was 1.71 m against
1.70 m fp32 with convs only, 2.22-2.33 m with every MatMul (LSTMs, attention, heads) quantized as well
(`--ops conv+matmul`). A MatMul that reads a Concat is split into one MatMul per concatenated input
first (`split_concat_matmuls`), so that each part is quantized with its own activation scale: the
compact model's fusion projection reads radar and IMU features of different ranges (validation
ATE unchanged with the split, 0.7-0.8% worse without it; docs/int8-speed.md). Convolutions with fewer
than 16 output channels are widened with zero filters first (`pad_narrow_convs`: same values, but tract then runs them on its 16-row int8
tile; the compact model's first convolution, 8 channels, ran 3x slower on the 8-row one). Timings per
recipe: docs/int8-speed.md. No com.microsoft ops. Calibration (MinMax) runs
on real dataset windows; for a stateful model the `state` input of each calibration window is the state
the fp32 model reaches when run along that window's chain from its start.
Per-tensor weight scales by default (the recipe measured in tract); `--per-channel` gives per-output-
channel weight scales, still standard ops (checked), but not yet measured in tract.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import onnx

from .data import expand_panorama, stack_pair
from .onnx_utils import consumers_of, get_metadata, nonzero_zero_points, op_problems, ort_session, set_metadata

MAX_CHAIN_RUN = 200
# `--ops auto` quantizes a MatMul only when its weight matrix has at least this many elements: the
# large matrix-vector products are memory-bound and int8 moves a quarter of the bytes, while small
# ones run faster in fp32 in tract (no quantize/dequantize around them, no int8 tile set-up) and
# keep the LSTMs' accuracy. 2^18: the compact model's fusion projection parts (512 x 512 and
# 1280 x 512; its next largest MatMul has 81920 weights), the paper graph's fusion-LSTM matrices
# and its attention / cross-modal projections.
MIN_MATMUL_WEIGHTS = 1 << 18
# Convolutions narrower than this many output channels are widened with zero filters before
# quantizing (`pad_narrow_convs`): tract's int8 kernels tile 16 output channels at a time.
CONV_TILE = 16


def calibration_feeds(fp32_path: str, data, n: int, stateful: bool, hidden: int) -> list[dict]:
    """`n` feed dicts {radar, imu, state} spread over the dataset's chains."""
    chains = sorted(data.chains, key=len, reverse=True)
    per_chain = max(1, -(-n // len(chains)))
    sess = ort_session(fp32_path) if stateful else None
    feeds = []
    for c in chains:
        if len(feeds) >= n:
            break
        span = min(len(c), MAX_CHAIN_RUN) if stateful else len(c)
        picks = set(np.linspace(0, span - 1, min(per_chain, span)).round().astype(int).tolist())
        state = np.zeros((1, 4, hidden), np.float32)
        for t in range(max(picks) + 1 if stateful else 0):
            feed = {"radar": data.radar([c[t]]), "imu": data.imu[[c[t]]], "state": state}
            if t in picks:
                feeds.append(feed)
            state = sess.run(["state_out"], feed)[0]
        if not stateful:
            feeds += [{"radar": data.radar([c[t]]), "imu": data.imu[[c[t]]], "state": state} for t in sorted(picks)]
    return feeds[:n]


def random_feeds(n: int, hidden: int, seed: int = 0) -> list[dict]:
    """Seeded random inputs shaped like real ones (panorama-like sparse image, IMU near gravity)."""
    rng = np.random.default_rng(seed)
    feeds = []
    for _ in range(n):
        pano = np.where(rng.random((2, 16, 64)) < 0.1, rng.random((2, 16, 64)), 0).astype(np.float32)
        img = expand_panorama(pano, {"min": 0.0, "max": 1.0, "mean": float(pano.mean())})
        radar = stack_pair(img[0], img[1])[None]
        imu = (rng.normal(0, 1, (1, 20, 6)) + np.array([0, 0, 9.81, 0, 0, 0])).astype(np.float32)
        feeds.append({"radar": radar.astype(np.float32), "imu": imu,
                      "state": np.zeros((1, 4, hidden), np.float32)})
    return feeds


def small_matmuls(model: onnx.ModelProto, min_weights: int) -> list[str]:
    """MatMuls whose constant weight has fewer than `min_weights` elements (kept fp32 by `auto`)."""
    sizes = {i.name: int(np.prod(i.dims)) for i in model.graph.initializer}
    return [n.name for n in model.graph.node if n.op_type == "MatMul"
            and max((sizes.get(i, 0) for i in n.input), default=0) < min_weights]


def pad_narrow_convs(model: onnx.ModelProto, width: int = CONV_TILE) -> list[str]:
    """Widens, in place, every Conv with fewer than `width` output channels whose output goes through
    an optional LeakyRelu/Relu into exactly one other Conv: zero filters and biases are appended, and
    the next Conv gets zero weights for the new input channels. The network computes the same values
    (the new channels are 0 after the activation and are multiplied by 0), but tract's int8 kernel
    picker gives a convolution with fewer than 16 output channels its 8-row AMX tile, which costs the
    compact model's first convolution 3x (docs/int8-speed.md). Returns the widened Convs' names."""
    from onnx import numpy_helper as nh
    g = model.graph
    inits = {i.name: i for i in g.initializer}
    consumers = consumers_of(g)
    outputs = {o.name for o in g.output}

    def only_consumer(tensor):
        c = consumers.get(tensor, [])
        return c[0] if len(c) == 1 and tensor not in outputs else None

    def attr(node, name, default):
        return next((onnx.helper.get_attribute_value(a) for a in node.attribute if a.name == name), default)

    widened = []
    for conv in [n for n in g.node if n.op_type == "Conv"]:
        if len(conv.input) < 2 or conv.input[1] not in inits or attr(conv, "group", 1) != 1:
            continue
        w = nh.to_array(inits[conv.input[1]])
        if w.shape[0] >= width:
            continue
        nxt = only_consumer(conv.output[0])
        if nxt is not None and nxt.op_type in ("LeakyRelu", "Relu"):
            nxt = only_consumer(nxt.output[0])
        if (nxt is None or nxt.op_type != "Conv" or attr(nxt, "group", 1) != 1
                or nxt.input[1] not in inits):
            continue
        extra = width - w.shape[0]
        inits[conv.input[1]].CopyFrom(nh.from_array(
            np.concatenate([w, np.zeros((extra,) + w.shape[1:], w.dtype)]), conv.input[1]))
        if len(conv.input) > 2 and conv.input[2] in inits:
            b = nh.to_array(inits[conv.input[2]])
            inits[conv.input[2]].CopyFrom(nh.from_array(
                np.concatenate([b, np.zeros(extra, b.dtype)]), conv.input[2]))
        w2 = nh.to_array(inits[nxt.input[1]])
        inits[nxt.input[1]].CopyFrom(nh.from_array(
            np.concatenate([w2, np.zeros((w2.shape[0], extra) + w2.shape[2:], w2.dtype)], 1),
            nxt.input[1]))
        widened.append(conv.name)
    if widened:
        del g.value_info[:]  # stale channel counts; re-inferred by whoever loads the graph
    return widened


def split_concat_matmuls(model: onnx.ModelProto) -> list[str]:
    """Splits, in place, every MatMul whose left operand is a Concat along its last axis and whose
    right operand is a constant [K, N] matrix into one MatMul per Concat input (the matching rows of
    the matrix) and an Add of their results: the same values up to float rounding. Quantized, each
    part then gets its own activation scale. The compact model's fusion-LSTM projection reads the
    radar features (512) and the IMU features (1280) concatenated, whose ranges differ; with one
    scale for both its int8 form cost 0.7-0.8% validation ATE, with one per part none
    (docs/int8-speed.md).
    tract splits that product the same way internally, so the split costs nothing in fp32.
    Returns the split MatMuls' names."""
    from onnx import numpy_helper as nh
    g = model.graph
    inits = {i.name: i for i in g.initializer}
    producers = {o: n for n in g.node for o in n.output}
    consumers = consumers_of(g)
    outputs = {o.name for o in g.output}
    inferred = onnx.shape_inference.infer_shapes(model).graph
    dims = {v.name: [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
            for v in list(inferred.value_info) + list(inferred.input) + list(inferred.output)}

    def part_widths(n) -> list[int] | None:
        """The Concat inputs' widths along the last axis, when `n` can be split; else None."""
        if n.op_type != "MatMul" or n.input[1] not in inits or n.input[0] not in producers:
            return None
        cat = producers[n.input[0]]
        shapes = [dims.get(x) for x in cat.input]
        if cat.op_type != "Concat" or len(shapes) < 2 or any(not p or len(p) != len(shapes[0]) for p in shapes):
            return None
        axis = next((a.i for a in cat.attribute if a.name == "axis"), 0)
        widths = [p[-1] for p in shapes]
        w = inits[n.input[1]].dims
        if axis % len(shapes[0]) != len(shapes[0]) - 1 or None in widths or len(w) != 2 or sum(widths) != w[0]:
            return None
        return widths

    split, nodes, dropped, replaced = [], [], set(), set()
    for n in g.node:
        widths = part_widths(n)
        if widths is None:
            nodes.append(n)
            continue
        cat, w = producers[n.input[0]], nh.to_array(inits[n.input[1]])
        acc, row = None, 0
        for k, (x, width) in enumerate(zip(cat.input, widths)):
            name = f"{n.input[1]}.part{k}"
            g.initializer.append(nh.from_array(np.ascontiguousarray(w[row:row + width]), name))
            row += width
            term = f"{n.output[0]}.part{k}"
            nodes.append(onnx.helper.make_node("MatMul", [x, name], [term], name=f"{n.name}.part{k}"))
            if acc is not None:
                out = n.output[0] if k == len(widths) - 1 else f"{n.output[0]}.sum{k}"
                nodes.append(onnx.helper.make_node("Add", [acc, term], [out], name=f"{n.name}.sum{k}"))
                term = out
            acc = term
        if len(consumers[cat.output[0]]) == 1 and cat.output[0] not in outputs:
            dropped.add(id(cat))
        replaced.add(n.input[1])
        split.append(n.name)
    if split:
        del g.node[:]
        g.node.extend(node for node in nodes if id(node) not in dropped)
        # The split matrices go unless something else still reads them; other initializers stay.
        still_read = {i for node in g.node for i in node.input}
        keep = [i for i in g.initializer if i.name not in replaced or i.name in still_read]
        del g.initializer[:]
        g.initializer.extend(keep)
        del g.value_info[:]
    return split


def quantize_model(fp32_path: str, out_path: str, feeds: list[dict], per_channel: bool = False,
                   ops: str = "auto", calibration: str = "dataset",
                   min_matmul_weights: int = MIN_MATMUL_WEIGHTS) -> float:
    """Quantize, check the graph, copy metadata; returns max |int8 - fp32| pose diff over `feeds[:16]`."""
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.it = iter(feeds)

        def get_next(self):
            return next(self.it, None)

    fp32_model = onnx.load(fp32_path)
    widened = pad_narrow_convs(fp32_model)
    split = split_concat_matmuls(fp32_model)  # before `small_matmuls`: each part judged by its size
    # The MatMul fed by the raw IMU window stays fp32: its input mixes specific force (~10 m/s^2)
    # and rate of turn (~0.1 rad/s); one symmetric int8 scale for both rounds the gyro to a few
    # steps and the rotation output degrades (measured: yaw errors ~1 deg per window). It is
    # 20 x 6 x 4H MACs, nothing next to the convolutions.
    exclude = [n.name for n in fp32_model.graph.node
               if n.op_type in ("MatMul", "Conv") and "imu" in n.input]
    if ops == "auto":
        exclude += small_matmuls(fp32_model, min_matmul_weights)
    source = fp32_path
    if widened or split:
        source = out_path + ".prepared-fp32.onnx"
        onnx.save(fp32_model, source)
    try:
        quantize_static(source, out_path, Reader(), quant_format=QuantFormat.QOperator,
                        nodes_to_exclude=exclude,
                        activation_type=QuantType.QInt8, weight_type=QuantType.QInt8,
                        op_types_to_quantize=["Conv"] if ops == "conv" else ["Conv", "MatMul"],
                        per_channel=per_channel,
                        extra_options={"ActivationSymmetric": True, "WeightSymmetric": True})
    finally:
        if source != fp32_path:
            import os
            os.remove(source)
    model = onnx.load(out_path)
    problems = op_problems(model) + [f"nonzero zero point: {n}" for n in nonzero_zero_points(model)]
    if problems:
        raise RuntimeError(f"int8 graph breaks the tract recipe: {problems[:10]}")
    meta = get_metadata(onnx.load(fp32_path))
    meta.update(precision="int8", quantization={
        "recipe": "onnxruntime quantize_static QOperator, s8 symmetric activations+weights",
        "ops": ops, "min_matmul_weights": min_matmul_weights if ops == "auto" else None,
        "widened_convs": widened, "split_matmuls": split,
        "per_channel": per_channel, "calibration": calibration, "calib_windows": len(feeds)})
    set_metadata(model, meta)
    onnx.save(model, out_path)
    f32, i8 = ort_session(fp32_path), ort_session(out_path)
    return float(max(np.abs(f32.run(["pose"], f)[0] - i8.run(["pose"], f)[0]).max() for f in feeds[:16]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="int8-quantize a milliEgo ONNX model for tract")
    p.add_argument("--model", required=True)
    p.add_argument("--data", required=True, help="dataset directory (or authors' h5) for calibration")
    p.add_argument("--out", required=True)
    p.add_argument("--calib-windows", type=int, default=256)
    p.add_argument("--per-channel", action="store_true")
    p.add_argument("--ops", choices=["auto", "conv", "conv+matmul"], default="auto",
                   help="operator types to quantize (default auto: convolutions, and MatMuls whose weight "
                        "has at least --min-matmul-weights elements; conv: convolutions only; "
                        "conv+matmul: every MatMul too, which cost the compact model 31%% held-out ATE, "
                        "see models/python/README.md)")
    p.add_argument("--min-matmul-weights", type=int, default=MIN_MATMUL_WEIGHTS,
                   help="with --ops auto: smallest weight matrix (elements) quantized (default 2^18)")
    a = p.parse_args(argv)
    from .data import load_any
    meta = get_metadata(onnx.load(a.model))
    data = load_any(a.data)
    if meta.get("norm"):
        data.norm = meta["norm"]  # calibrate on what the runtime will feed: the model's normalisation
    data.radar_input = meta.get("radar_input", "depth")
    feeds = calibration_feeds(a.model, data, a.calib_windows, meta["stateful"], meta["hidden"])
    diff = quantize_model(a.model, a.out, feeds, a.per_channel, a.ops,
                          min_matmul_weights=a.min_matmul_weights)
    print(f"wrote {a.out}: int8 (QLinearConv/QLinearMatMul, symmetric s8), calibrated on {len(feeds)} windows "
          f"of {a.data}; int8 vs fp32 pose max abs diff {diff:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
