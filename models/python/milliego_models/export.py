"""Export a trained checkpoint to ONNX (fp32, batch 1) for tract.

    python -m milliego_models.export --checkpoint RUN/best.pt --out model.onnx

Inputs `radar` [1,6,64,256], `imu` [1,20,6], `state` [1,4,H]; outputs `pose` [1,6], `state_out` [1,4,H].
Uses the TorchScript exporter (dynamo=False), then folds constants and merges the explicit 'same' Pad
nodes into Conv `pads` with our own passes (onnxruntime's offline optimizer would fuse MatMul+Add into
Gemm), runs shape inference and checks the op set. Metadata JSON under `metadata_props["milliego"]`.
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
from .model import IMU_SHAPE, RADAR_SHAPE, MilliEgo, count_params
from .onnx_utils import fold_constants, fold_pads_into_convs, op_problems, ort_session, set_metadata

OPSET = 17


def example_inputs(net: MilliEgo, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(1, *RADAR_SHAPE, generator=g) - 0.1, torch.randn(1, *IMU_SHAPE, generator=g),
            torch.randn(1, 4, net.hidden, generator=g) * 0.5)


def make_metadata(net: MilliEgo, stateful: bool, preprocess: dict | None, norm: dict | None, trained: bool,
                  val_ate_m: float | None = None, precision: str = "fp32") -> dict:
    meta = {"config": net.config.name, "stateful": bool(stateful), "hidden": net.hidden,
            "preprocess": preprocess, "norm": norm, "label": LABEL_CONVENTION,
            "state": "state[:,0..4] = h1, c1, h2, c2 of the 2 fusion LSTM layers; zeros at a chain start"
                     + ("" if stateful else "; stateless model: feed zeros every call"),
            "trained": bool(trained), "precision": precision, "params": count_params(net)}
    if val_ate_m is not None:
        meta["val_ate_m"] = float(val_ate_m)
    return meta


def export_model(net: MilliEgo, out: str, meta: dict) -> float:
    """Write the cleaned fp32 ONNX to `out`; returns max |onnxruntime - PyTorch| on a random input."""
    net = net.eval().cpu()
    args = example_inputs(net)
    with tempfile.TemporaryDirectory() as tmp:
        raw = os.path.join(tmp, "raw.onnx")
        torch.onnx.export(net, args, raw, input_names=["radar", "imu", "state"], output_names=["pose", "state_out"],
                          opset_version=OPSET, dynamo=False, do_constant_folding=True)
        model = onnx.load(raw)
    model = fold_pads_into_convs(fold_constants(model))
    model = onnx.shape_inference.infer_shapes(model, strict_mode=True)
    bad = op_problems(model)
    if bad:
        raise RuntimeError(f"exported graph uses ops outside the tract set: {bad[:10]}")
    set_metadata(model, meta)
    onnx.checker.check_model(model)
    onnx.save(model, out)
    with torch.no_grad():
        ref = [t.numpy() for t in net(*args)]
    got = ort_session(out).run(None, {"radar": args[0].numpy(), "imu": args[1].numpy(), "state": args[2].numpy()})
    return float(max(np.abs(a - b).max() for a, b in zip(ref, got)))


def load_checkpoint(path: str) -> tuple[MilliEgo, dict]:
    ck = torch.load(path, map_location="cpu", weights_only=False)
    net = MilliEgo(ck["config"])
    net.load_state_dict(ck["model"])
    return net.eval(), ck


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="export a milliEgo checkpoint to ONNX")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    net, ck = load_checkpoint(a.checkpoint)
    meta = make_metadata(net, ck["stateful"], ck.get("preprocess"), ck.get("norm"), trained=True,
                         val_ate_m=ck.get("val_ate_m"))
    diff = export_model(net, a.out, meta)
    print(f"wrote {a.out}: config {meta['config']}, stateful {meta['stateful']}, {meta['params']:,} params; "
          f"onnxruntime vs PyTorch max abs diff {diff:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
