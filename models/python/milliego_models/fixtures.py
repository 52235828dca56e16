"""Small ONNX fixtures for the Rust tests (`models/tests/`): interface variants the shipped model lacks.

    python -m milliego_models.fixtures --out models/tests/fixtures

Writes `tiny-uncertainty.onnx`, an UNTRAINED tiny network (seeded) with the uncertainty head (third output
`pose_std`), with the shipped model's preprocessing and normalisation in its metadata so that the runtime
loads it, and `tiny-uncertainty.safetensors`: one seeded input (radar zeros, `imu`, `state`) with
onnxruntime's `pose` and `pose_std` for it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import onnx
import torch

from .export import export_model, make_metadata
from .model import IMU_SHAPE, RADAR_SHAPE, MilliEgo
from .onnx_utils import get_metadata, ort_session


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="write the Rust tests' ONNX fixtures")
    p.add_argument("--out", required=True)
    p.add_argument("--reference", default=str(Path(__file__).resolve().parents[2] / "compact" / "model.onnx"),
                   help="model whose preprocessing and normalisation the fixtures carry")
    a = p.parse_args(argv)
    from safetensors.numpy import save_file
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    ref = get_metadata(onnx.load(a.reference))
    torch.manual_seed(11)
    net = MilliEgo("tiny", uncertainty=True)
    with torch.no_grad():  # a head that varies with its input (trained heads do)
        for layer in net.std_head:
            layer.weight.normal_(0, 0.5)
    meta = make_metadata(net, False, ref["preprocess"], ref["norm"], trained=False)
    path = out / "tiny-uncertainty.onnx"
    diff = export_model(net, str(path), meta)
    rng = np.random.default_rng(11)
    feed = {"radar": np.zeros((1, *RADAR_SHAPE), np.float32),
            "imu": (rng.normal(0, 1, (1, *IMU_SHAPE)) + [0, 0, 9.81, 0, 0, 0]).astype(np.float32),
            "state": np.zeros((1, 4, net.hidden), np.float32)}
    pose, _, std = ort_session(str(path)).run(["pose", "state_out", "pose_std"], feed)
    save_file({"imu": feed["imu"], "state": feed["state"], "pose": pose, "pose_std": std},
              str(out / "tiny-uncertainty.safetensors"))
    print(f"wrote {path} (onnxruntime vs PyTorch {diff:.3g}) and its expected outputs: pose_std {std.ravel()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
