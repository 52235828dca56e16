"""ONNX graph clean-up and checks shared by export, quantize, golden and paper_graph.

The graphs must stay within the plain ONNX ops tract runs (see `ALLOWED_OPS`); onnxruntime's own offline
optimizer is not used because it fuses MatMul+Add into Gemm, which would not quantize to QLinearMatMul.
"""
from __future__ import annotations

import json

import numpy as np
import onnx
from onnx import helper, numpy_helper
from onnx.reference import ReferenceEvaluator

METADATA_KEY = "milliego"

ALLOWED_OPS = frozenset({
    "Conv", "QLinearConv", "MatMul", "QLinearMatMul", "QuantizeLinear", "DequantizeLinear", "Add", "Sub",
    "Mul", "Div", "Sigmoid", "Tanh", "Relu", "LeakyRelu", "Concat", "Reshape", "Transpose", "ReduceMean",
    "GlobalAveragePool", "Slice", "Gather", "Split", "Squeeze", "Unsqueeze", "Flatten", "Pad", "Constant",
    "Identity", "Shape", "Clip", "Exp",
})


def fold_constants(model: onnx.ModelProto) -> onnx.ModelProto:
    """Evaluate every node whose inputs are all constants and store its outputs as initializers."""
    g = model.graph
    consts = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    graph_inputs = {i.name for i in g.input}
    keep = []
    for node in g.node:
        ins = [i for i in node.input if i]
        if all(i in consts for i in ins) and not (graph_inputs & set(ins)):
            outs = ReferenceEvaluator(node).run(None, {i: consts[i] for i in ins})
            for name, value in zip(node.output, outs):
                consts[name] = np.asarray(value)
        else:
            keep.append(node)
    used = {i for n in keep for i in n.input} | {o.name for o in g.output}
    del g.node[:]
    g.node.extend(keep)
    del g.initializer[:]
    g.initializer.extend(numpy_helper.from_array(v, k) for k, v in consts.items() if k in used)
    return model


def consumers_of(graph: onnx.GraphProto) -> dict[str, list]:
    """Tensor name -> the nodes that read it."""
    consumers: dict[str, list] = {}
    for n in graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    return consumers


def fold_pads_into_convs(model: onnx.ModelProto) -> onnx.ModelProto:
    """Merge zero `Pad` (spatial axes only) into the consuming `Conv`'s `pads` attribute."""
    g = model.graph
    inits = {i.name: i for i in g.initializer}
    consumers = consumers_of(g)
    drop = set()
    for pad in g.node:
        if pad.op_type != "Pad" or len(consumers.get(pad.output[0], [])) != 1:
            continue
        conv = consumers[pad.output[0]][0]
        mode = next((a.s for a in pad.attribute if a.name == "mode"), b"constant")
        if conv.op_type != "Conv" or mode != b"constant" or pad.input[1] not in inits:
            continue
        if len(pad.input) > 2 and pad.input[2]:
            if pad.input[2] not in inits or numpy_helper.to_array(inits[pad.input[2]]).item() != 0:
                continue
        p = numpy_helper.to_array(inits[pad.input[1]]).tolist()
        if len(p) != 8 or p[0] or p[1] or p[4] or p[5] or min(p) < 0:
            continue
        old = next((a for a in conv.attribute if a.name == "pads"), None)
        cur = list(old.ints) if old is not None else [0, 0, 0, 0]
        new = [cur[0] + p[2], cur[1] + p[3], cur[2] + p[6], cur[3] + p[7]]
        if old is not None:
            conv.attribute.remove(old)
        conv.attribute.append(helper.make_attribute("pads", new))
        conv.input[0] = pad.input[0]
        drop.add(id(pad))
    keep = [n for n in g.node if id(n) not in drop]
    del g.node[:]
    g.node.extend(keep)
    used = {i for n in keep for i in n.input}
    live = [i for i in g.initializer if i.name in used]
    del g.initializer[:]
    g.initializer.extend(live)
    return model


def fold_copied_inputs(model: onnx.ModelProto, input_name: str, groups) -> list[str]:
    """Folds, in place, the channels of graph input `input_name` that always carry the same values
    (`groups`: tuples of channel indices, e.g. `model.RADAR_COPIES`) in every Conv that reads the input
    directly: the Conv's weights for a group are summed into one input channel and the Conv reads one
    channel per group through a `Gather` (axis 1). For inputs whose groups hold copies the outputs are
    the same up to float rounding (sum of products regrouped), at 1/len(group) of the multiply-adds and
    im2col bytes. Convs with groups != 1 or non-constant weights are left. Returns the folded Convs' names."""
    g = model.graph
    inits = {i.name: i for i in g.initializer}
    channels = [c for grp in groups for c in grp]
    if sorted(channels) != list(range(len(channels))) or any(len(grp) == 0 for grp in groups):
        raise ValueError(f"channel groups {groups} must partition 0..{len(channels) - 1}")

    def group_attr(node):
        return next((helper.get_attribute_value(a) for a in node.attribute if a.name == "group"), 1)

    convs = [n for n in g.node if n.op_type == "Conv" and n.input and n.input[0] == input_name
             and len(n.input) > 1 and n.input[1] in inits and group_attr(n) == 1]
    if not convs:
        return []
    picked = f"{input_name}_folded_copies"
    index = f"{picked}_index"
    g.initializer.append(numpy_helper.from_array(np.array([grp[0] for grp in groups], np.int64), index))
    first = min(list(g.node).index(c) for c in convs)
    g.node.insert(first, helper.make_node("Gather", [input_name, index], [picked], axis=1,
                                          name=f"/{picked}/Gather"))
    for conv in convs:
        w = numpy_helper.to_array(inits[conv.input[1]])
        if w.shape[1] != len(channels):
            raise ValueError(f"{conv.name}: weight {w.shape} does not read {len(channels)} channels")
        folded = np.stack([w[:, list(grp)].sum(1) for grp in groups], 1).astype(w.dtype)
        inits[conv.input[1]].CopyFrom(numpy_helper.from_array(folded, conv.input[1]))
        conv.input[0] = picked
    del g.value_info[:]  # stale channel counts; re-inferred by whoever loads the graph
    return [c.name for c in convs]


def op_problems(model: onnx.ModelProto) -> list[str]:
    """Nodes outside the allowed op set or outside the default ONNX domain."""
    bad = []
    for n in model.graph.node:
        if n.domain not in ("", "ai.onnx"):
            bad.append(f"{n.name or n.op_type}: domain {n.domain!r}")
        if n.op_type not in ALLOWED_OPS:
            bad.append(f"{n.name or n.op_type}: op {n.op_type}")
    return bad


def nonzero_zero_points(model: onnx.ModelProto) -> list[str]:
    """Names of Quantize/DequantizeLinear nodes whose zero point is not all zeros (asymmetric)."""
    consts = {i.name: i for i in model.graph.initializer}
    for n in model.graph.node:
        if n.op_type == "Constant":
            consts[n.output[0]] = n.attribute[0].t
    bad = []
    for n in model.graph.node:
        if n.op_type in ("QuantizeLinear", "DequantizeLinear") and len(n.input) > 2 and n.input[2]:
            zp = consts.get(n.input[2])
            if zp is None or np.any(numpy_helper.to_array(zp) != 0):
                bad.append(n.name or n.output[0])
    return bad


def get_metadata(model: onnx.ModelProto) -> dict:
    for p in model.metadata_props:
        if p.key == METADATA_KEY:
            return json.loads(p.value)
    raise KeyError(f"ONNX model has no {METADATA_KEY!r} metadata")


def set_metadata(model: onnx.ModelProto, meta: dict) -> None:
    for p in list(model.metadata_props):
        if p.key == METADATA_KEY:
            model.metadata_props.remove(p)
    onnx.helper.set_model_props(model, {**{p.key: p.value for p in model.metadata_props},
                                        METADATA_KEY: json.dumps(meta, sort_keys=True)})


def ort_session(path: str, threads: int = 1):
    import onnxruntime as ort
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])
