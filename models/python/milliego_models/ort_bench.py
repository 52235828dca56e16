"""onnxruntime side of the `milliego-bench` inference rows: one thread, batch 1, same inputs as tract.

    python -m milliego_models.ort_bench --fp32 model.onnx --int8 model-int8.onnx \
        --inputs golden.safetensors [--runs 100] [--warmup 5] [--variants all]

Times, each in a fresh interpreter (so peak RSS deltas do not overlap) and on the same inputs, the fp32 graph, the int8 file shipped for tract, and
onnxruntime's own preferred int8 graphs (made here with `quantize_static`, QDQ format, per-channel or
per-tensor weights, u8 or s8 activations), and prints ONE JSON object on stdout (progress on stderr).
The best onnxruntime variant (lowest median) is the `ort_best_int8` entry: it is the figure tract's
int8 has to beat.

Inputs: `radar_K`, `imu_K`, `state_K` of the safetensors bundle (a golden bundle); window 0 is timed,
all windows calibrate. A `state_K` whose width differs from the model's (the paper graph, H = 512)
is replaced by zeros of the model's width. The variants are cached next to the fp32 model as
`<stem>.ort-<variant>.onnx` and reused when newer than the fp32 file.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

# name -> (activation type, weight type, per channel); all QDQ with onnxruntime's default op list.
VARIANTS = {
    "qdq-u8s8-perchannel": ("QUInt8", "QInt8", True),
    "qdq-s8s8-perchannel": ("QInt8", "QInt8", True),
    "qdq-u8s8-pertensor": ("QUInt8", "QInt8", False),
}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def state_width(model_path: str) -> int:
    import onnx

    m = onnx.load(model_path, load_external_data=False)
    for i in m.graph.input:
        if i.name == "state":
            return int(i.type.tensor_type.shape.dim[2].dim_value)
    raise SystemExit(f"{model_path}: no 'state' input")


def load_feeds(bundle: str, hidden: int) -> list[dict]:
    """Every window of the bundle as {radar, imu, state} (state zeros when its width differs)."""
    from safetensors.numpy import load_file

    d = load_file(bundle)
    feeds = []
    k = 0
    while f"radar_{k}" in d:
        state = d.get(f"state_{k}")
        if state is None or state.shape != (1, 4, hidden):
            state = np.zeros((1, 4, hidden), np.float32)
        feeds.append({"radar": d[f"radar_{k}"].astype(np.float32), "imu": d[f"imu_{k}"].astype(np.float32),
                      "state": state.astype(np.float32)})
        k += 1
    if not feeds:
        raise SystemExit(f"{bundle}: no radar_0")
    return feeds


def _clear_peak() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _status_kb(key: str) -> float:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return float(line.split()[1])
    except OSError:
        pass
    return float("nan")


def session(path: str):
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def time_model(path: str, feed: dict, runs: int, warmup: int) -> dict:
    """Median / p99 latency [ms] and peak RSS delta [MB] (session creation included) of one graph."""
    gc.collect()
    _clear_peak()
    base = _status_kb("VmRSS")
    t0 = time.perf_counter()
    s = session(path)
    load_s = time.perf_counter() - t0
    for _ in range(warmup):
        s.run(None, feed)
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        s.run(None, feed)
        times.append((time.perf_counter() - t) * 1e3)
    peak = _status_kb("VmHWM")
    pose = s.run(["pose"], feed)[0].reshape(-1).tolist()
    del s
    gc.collect()
    times.sort()
    return {"file": path, "median_ms": times[len(times) // 2],
            "p99_ms": times[max(0, -(-len(times) * 99 // 100) - 1)], "runs": runs,
            "rss_delta_mb": (peak - base) / 1024.0, "load_s": load_s, "pose": pose}


def time_fresh(path: str, feed: dict, runs: int, warmup: int) -> dict:
    """`time_model` in a fresh interpreter, so the peak RSS delta is this graph's alone."""
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(time_model, (path, feed, runs, warmup))


def make_variant(fp32: str, name: str, feeds: list[dict]) -> str:
    """onnxruntime's int8 of `fp32` for variant `name`, cached next to it."""
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    src = Path(fp32)
    out = src.with_name(f"{src.stem}.ort-{name}.onnx")
    if out.is_file() and out.stat().st_mtime >= src.stat().st_mtime:
        return str(out)
    act, wt, per_channel = VARIANTS[name]

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.it = iter(feeds)

        def get_next(self):
            return next(self.it, None)

    log(f"quantizing {src.name} -> {out.name} ({len(feeds)} calibration windows)")
    tmp = out.with_suffix(".tmp.onnx")
    quantize_static(str(src), str(tmp), Reader(), quant_format=QuantFormat.QDQ,
                    activation_type=getattr(QuantType, act), weight_type=getattr(QuantType, wt),
                    per_channel=per_channel)
    os.replace(tmp, out)
    return str(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="onnxruntime latency (1 thread) of fp32 / tract int8 / ORT-best int8")
    p.add_argument("--fp32", required=True)
    p.add_argument("--int8", required=True, help="the int8 file shipped for tract")
    p.add_argument("--inputs", required=True, help="safetensors bundle with radar_K, imu_K, state_K")
    p.add_argument("--runs", type=int, default=100)
    p.add_argument("--warmup", type=int, default=5)
    p.add_argument("--variants", default="all", help="comma-separated subset of " + ",".join(VARIANTS))
    a = p.parse_args(argv)
    import onnxruntime as ort

    hidden = state_width(a.fp32)
    feeds = load_feeds(a.inputs, hidden)
    names = list(VARIANTS) if a.variants == "all" else a.variants.split(",")
    out = {"engine": f"onnxruntime {ort.__version__}", "threads": 1, "hidden": hidden,
           "fp32": time_fresh(a.fp32, feeds[0], a.runs, a.warmup),
           "tract_int8_file": time_fresh(a.int8, feeds[0], a.runs, a.warmup), "variants": {}}
    for n in names:
        path = make_variant(a.fp32, n, feeds)
        r = time_fresh(path, feeds[0], a.runs, a.warmup)
        r["max_abs_diff_vs_fp32"] = float(np.max(np.abs(np.array(r["pose"]) - np.array(out["fp32"]["pose"]))))
        out["variants"][n] = r
        log(f"{n}: median {r['median_ms']:.3f} ms")
    best = min(out["variants"], key=lambda n: out["variants"][n]["median_ms"])
    out["ort_best_int8"] = dict(out["variants"][best], variant=best)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
