"""Golden input/output bundle for checking tract against onnxruntime on the Rust side.

    python -m milliego_models.golden --fp32 model.onnx --int8 model-int8.onnx --data DATASET_DIR \
        --out golden.safetensors [--windows 4] [--chain 0]

Takes N consecutive windows of one chain (the longest, or `--chain`) and writes, for k = 0..N-1 (f32):
`radar_k` [1,6,64,256], `imu_k` [1,20,6], `state_k` [1,4,H], `pose_fp32_k`, `state_out_fp32_k`,
`pose_int8_k`, `state_out_int8_k` (and `pose_std_fp32_k`, `pose_std_int8_k` for a model with the
uncertainty head), plus `window_pair` i64 [N,2] (frame indices within the session).
State: `state_0` is zeros; for a stateful model `state_k` = `state_out_fp32_{k-1}` (the fp32 chain), and
BOTH models are run on that same `state_k`, so each step is an independent check; a stateless model gets
zeros every step. The safetensors metadata repeats this and the ONNX metadata.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np
import onnx

from .onnx_utils import get_metadata, ort_session


def golden(fp32: str, int8: str, data, windows: int, chain: int | None = None) -> dict[str, np.ndarray]:
    meta = get_metadata(onnx.load(fp32))
    chains = data.chains if chain is None else [data.chains[chain]]
    c = max(chains, key=len)[:windows]
    if len(c) < windows:
        raise ValueError(f"longest chain has {len(c)} windows < {windows}")
    f32, i8 = ort_session(fp32), ort_session(int8)
    names = ["pose", "state_out"] + (["pose_std"] if "pose_std" in {o.name for o in f32.get_outputs()} else [])
    state = np.zeros((1, 4, meta["hidden"]), np.float32)
    out: dict[str, np.ndarray] = {}
    offset = np.cumsum([0] + [len(s.frames) for s in data.sessions])[data.session_of[c[0]]]
    out["window_pair"] = (data.pair[c] - offset).astype(np.int64)
    golden.session = data.sessions[data.session_of[c[0]]].name
    for k, w in enumerate(c):
        feed = {"radar": data.radar([w]).astype(np.float32), "imu": data.imu[[w]].astype(np.float32), "state": state}
        pose, state_out, *std = f32.run(names, feed)
        pose8, state_out8, *std8 = i8.run(names, feed)
        if std:
            out |= {f"pose_std_fp32_{k}": std[0], f"pose_std_int8_{k}": std8[0]}
        p = data.pair[w]
        out |= {f"panorama_prev_{k}": data.frames[p[0]][None].astype(np.float32),
                f"panorama_cur_{k}": data.frames[p[1]][None].astype(np.float32)}
        if data.radar_input == "depth_doppler":
            out |= {f"doppler_prev_{k}": data.doppler[p[0]][None].astype(np.float32),
                    f"doppler_cur_{k}": data.doppler[p[1]][None].astype(np.float32)}
        out |= {f"radar_{k}": feed["radar"], f"imu_{k}": feed["imu"], f"state_{k}": feed["state"],
                f"pose_fp32_{k}": pose, f"state_out_fp32_{k}": state_out,
                f"pose_int8_{k}": pose8, f"state_out_int8_{k}": state_out8}
        state = state_out if meta["stateful"] else np.zeros_like(state)
    return {k: np.ascontiguousarray(v) for k, v in out.items()}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="write a tract golden bundle")
    p.add_argument("--fp32", required=True)
    p.add_argument("--int8", required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--windows", type=int, default=4)
    p.add_argument("--chain", type=int, default=None)
    a = p.parse_args(argv)
    from safetensors.numpy import save_file

    from .data import load_any
    data = load_any(a.data)
    # Images through the model's own normalisation (what the runtime uses), not this dataset's.
    data.norm = get_metadata(onnx.load(a.fp32))["norm"] or data.norm
    data.radar_input = get_metadata(onnx.load(a.fp32)).get("radar_input", "depth")
    t = golden(a.fp32, a.int8, data, a.windows, a.chain)
    meta = get_metadata(onnx.load(a.fp32))
    save_file(t, a.out, metadata={"milliego": json.dumps(meta, sort_keys=True), "windows": str(a.windows),
                                  "session": golden.session,
                                  "state": "state_k fed to both models; stateful: state_k = state_out_fp32_{k-1}"})
    d = max(float(np.abs(t[f"pose_int8_{k}"] - t[f"pose_fp32_{k}"]).max()) for k in range(a.windows))
    print(f"wrote {a.out}: {a.windows} windows {t['window_pair'].tolist()}, stateful {meta['stateful']}, "
          f"int8 vs fp32 pose max abs diff {d:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
