"""Export a trained checkpoint to ONNX (fp32, batch 1) for tract.

    python -m milliego_models.export --checkpoint RUN/best.pt --out model.onnx

    python -m milliego_models.export --onnx OLD.onnx --out model.onnx   # the graph passes on an exported file

Inputs `radar` [1,6,64,256], `imu` [1,20,6], `state` [1,4,H]; outputs `pose` [1,6], `state_out` [1,4,H].
Uses the TorchScript exporter (dynamo=False), then folds constants and merges the explicit 'same' Pad
nodes into Conv `pads` with our own passes (onnxruntime's offline optimizer would fuse MatMul+Add into
Gemm), folds the radar input's copied channels into the first convolution (`fold_copied_inputs`: the
previous and the current image are each fed 3 times, so the convolution reads 2 channels with summed
weights: a third of its work, the same values), runs shape inference and checks the op set. Metadata
JSON under `metadata_props["milliego"]` (`radar_copies_folded` names the folded convolutions).
`--onnx` applies the passes to a file exported before them (its metadata kept) and checks that
onnxruntime gives the same outputs on inputs with copied channels.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile

import numpy as np
import onnx
import torch

from .geometry import LABEL_CONVENTION
from .model import IMU_SHAPE, RADAR_INPUTS, RADAR_SHAPE, Exported, MilliEgo, count_params
from .onnx_utils import (fold_constants, fold_copied_inputs, fold_pads_into_convs, get_metadata, op_problems,
                         ort_session, set_metadata)

OPSET = 17


def copied_radar(images: torch.Tensor, radar_input: str = "depth") -> torch.Tensor:
    """[B, groups, 64, 256] -> radar input [B, 6, 64, 256], image k in every channel of group k
    (`model.RADAR_INPUTS[radar_input]`)."""
    out = images.new_empty(images.shape[0], RADAR_SHAPE[0], *images.shape[2:])
    for k, grp in enumerate(RADAR_INPUTS[radar_input]):
        out[:, list(grp)] = images[:, k:k + 1]
    return out


def example_inputs(net: MilliEgo | None, seed: int = 0, hidden: int | None = None, radar_input: str | None = None):
    """Seeded inputs as the runtime feeds them (copied radar channels, see model.RADAR_INPUTS)."""
    g = torch.Generator().manual_seed(seed)
    radar_input = radar_input or (net.radar_input if net is not None else "depth")
    groups = RADAR_INPUTS[radar_input]
    images = torch.rand(1, len(groups), *RADAR_SHAPE[1:], generator=g) - 0.1
    return (copied_radar(images, radar_input), torch.randn(1, *IMU_SHAPE, generator=g),
            torch.randn(1, 4, net.hidden if hidden is None else hidden, generator=g) * 0.5)


def clean_graph(model: onnx.ModelProto, meta: dict) -> onnx.ModelProto:
    """The graph passes after the exporter; checks the op set and stores `meta` (plus what was folded)."""
    model = fold_pads_into_convs(fold_constants(model))
    folded = fold_copied_inputs(model, "radar", RADAR_INPUTS[meta.get("radar_input", "depth")])
    model = onnx.shape_inference.infer_shapes(model, strict_mode=True)
    bad = op_problems(model)
    if bad:
        raise RuntimeError(f"exported graph uses ops outside the tract set: {bad[:10]}")
    set_metadata(model, {**meta, "radar_copies_folded": folded})
    onnx.checker.check_model(model)
    return model


def make_metadata(net: MilliEgo, stateful: bool, preprocess: dict | None, norm: dict | None, trained: bool,
                  val_ate_m: float | None = None, precision: str = "fp32") -> dict:
    meta = {"config": net.config.name, "stateful": bool(stateful), "hidden": net.hidden,
            "preprocess": preprocess, "norm": norm, "label": LABEL_CONVENTION,
            "state": "state[:,0..4] = h1, c1, h2, c2 of the 2 fusion LSTM layers; zeros at a chain start"
                     + ("" if stateful else "; stateless model: feed zeros every call"),
            "trained": bool(trained), "precision": precision, "params": count_params(net),
            "radar_input": net.radar_input}
    if val_ate_m is not None:
        meta["val_ate_m"] = float(val_ate_m)
    if net.uncertainty:
        meta["pose_std"] = ("output pose_std [1,6]: the predicted standard deviation of each pose component "
                            "(m, deg), from the uncertainty head (Gaussian NLL)")
    return meta


def export_model(net: MilliEgo, out: str, meta: dict) -> float:
    """Write the cleaned fp32 ONNX to `out`; returns max |onnxruntime - PyTorch| on a random input."""
    net = net.eval().cpu()
    # torch.onnx.export puts the module back into the mode it found it in; a fresh wrapper is in
    # training mode, which would switch dropout on for the check below.
    wrapper = Exported(net).eval()
    args = example_inputs(net)
    with tempfile.TemporaryDirectory() as tmp:
        raw = os.path.join(tmp, "raw.onnx")
        outputs = ["pose", "state_out"] + (["pose_std"] if net.uncertainty else [])
        # Without the head, the network itself (its initializers keep the parameter names; the wrapper
        # would prefix them with "net.").
        torch.onnx.export(wrapper if net.uncertainty else net, args, raw, input_names=["radar", "imu", "state"], output_names=outputs,
                          opset_version=OPSET, dynamo=False, do_constant_folding=True)
        model = onnx.load(raw)
    onnx.save(clean_graph(model, meta), out)
    with torch.no_grad():
        ref = [t.numpy() for t in wrapper(*args)]
    got = ort_session(out).run(None, {"radar": args[0].numpy(), "imu": args[1].numpy(), "state": args[2].numpy()})
    return float(max(np.abs(a - b).max() for a, b in zip(ref, got)))


def reexport(src: str, out: str) -> float:
    """Applies the graph passes to an exported fp32 file `src` (metadata kept); returns max |out - src|
    in onnxruntime over seeded inputs with copied radar channels."""
    model = onnx.load(src)
    meta = get_metadata(model)
    if meta.get("precision", "fp32") != "fp32":
        raise ValueError(f"{src}: precision {meta.get('precision')}; re-export the fp32 file, then quantize it")
    if "radar_copies_folded" in meta:
        raise ValueError(f"{src}: already folded ({meta['radar_copies_folded']})")
    onnx.save(clean_graph(model, meta), out)
    a, b = ort_session(src), ort_session(out)
    diff = 0.0
    for seed in range(4):
        radar, imu, state = (t.numpy() for t in example_inputs(None, seed, hidden=meta["hidden"],
                                                               radar_input=meta.get("radar_input", "depth")))
        feed = {"radar": radar, "imu": imu, "state": state}
        diff = max(diff, max(float(np.abs(x - y).max()) for x, y in zip(a.run(None, feed), b.run(None, feed))))
    return diff


def load_checkpoint(path: str) -> tuple[MilliEgo, dict]:
    ck = torch.load(path, map_location="cpu", weights_only=False)
    net = MilliEgo(ck["config"], ck.get("uncertainty", False), ck.get("radar_input", "depth"))
    net.load_state_dict(ck["model"])
    return net.eval(), ck


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="export a milliEgo checkpoint to ONNX")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--checkpoint", help="training checkpoint (RUN/best.pt)")
    src.add_argument("--onnx", help="an fp32 file exported before the current graph passes")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    if a.onnx:
        try:
            diff = reexport(a.onnx, a.out)
        except ValueError as e:
            print(f"export: {e}", file=sys.stderr)
            return 2
        meta = get_metadata(onnx.load(a.out))
        print(f"wrote {a.out}: graph passes applied to {a.onnx} (folded {meta['radar_copies_folded']}); "
              f"onnxruntime max abs diff {diff:.3g}")
        return 0
    net, ck = load_checkpoint(a.checkpoint)
    meta = make_metadata(net, ck["stateful"], ck.get("preprocess"), ck.get("norm"), trained=True,
                         val_ate_m=ck.get("val_ate_m"))
    diff = export_model(net, a.out, meta)
    print(f"wrote {a.out}: config {meta['config']}, stateful {meta['stateful']}, {meta['params']:,} params; "
          f"onnxruntime vs PyTorch max abs diff {diff:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
