"""Paper-size milliEgo graphs with UNTRAINED weights, for tract/onnxruntime speed benchmarks only.

    python -m milliego_models.paper_graph --out DIR [--data DATASET_DIR] [--seed 0] [--stateful]

Writes DIR/milliego-paper-fp32.onnx and DIR/milliego-paper-int8.onnx (metadata trained=false). The int8
graph is calibrated on dataset windows when `--data` is given, else on seeded random inputs.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

from .export import export_model, make_metadata
from .model import MilliEgo, count_params
from .quantize import calibration_feeds, quantize_model, random_feeds
from .synthetic import PREPROCESS


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="paper-size untrained milliEgo ONNX graphs (benchmarks only)")
    p.add_argument("--out", required=True)
    p.add_argument("--data", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--config", default="paper")
    p.add_argument("--stateful", action="store_true", help="mark the graph stateful (the graph is the same)")
    p.add_argument("--calib-windows", type=int, default=32)
    a = p.parse_args(argv)
    banner = f"weights are UNTRAINED (random, seed {a.seed}): for speed benchmarks only"
    print(banner, flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(a.seed)
    net = MilliEgo(a.config).eval()
    data = None
    if a.data:
        from .data import load_any
        data = load_any(a.data)
    meta = make_metadata(net, a.stateful, data.preprocess if data else PREPROCESS,
                         data.norm if data else None, trained=False)
    meta["note"] = banner
    fp32, int8 = out / f"milliego-{a.config}-fp32.onnx", out / f"milliego-{a.config}-int8.onnx"
    diff = export_model(net, str(fp32), meta)
    print(f"wrote {fp32}: {count_params(net):,} params; onnxruntime vs PyTorch max abs diff {diff:.3g}", flush=True)
    if data is not None:
        feeds = calibration_feeds(str(fp32), data, a.calib_windows, a.stateful, net.hidden)
        how = f"dataset {a.data} ({len(feeds)} windows)"
    else:
        feeds = random_feeds(a.calib_windows, net.hidden, a.seed)
        how = f"seeded random inputs (seed {a.seed}, {len(feeds)} windows): no dataset given"
    d8 = quantize_model(str(fp32), str(int8), feeds, calibration=how)
    print(f"wrote {int8}: calibrated on {how}; int8 vs fp32 pose max abs diff {d8:.3g}")
    print(banner)
    return 0


if __name__ == "__main__":
    sys.exit(main())
