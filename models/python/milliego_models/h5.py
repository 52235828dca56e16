"""Loader for the authors' released dataset layout (MAPS-Lab/OdomBeyondVision, ChristopherLu/milliEgo).

One h5 file per sequence with
- `mmwave_middle_data` (N,1,64,256,1): the final 64x256 radar images (already overlaid and upscaled),
- `imu_data` (N,30,6): the IMU rows before each frame, NEWEST FIRST,
- `label_data` (1,N-1,6): relative pose frame k -> k+1 (tx ty tz [m], roll pitch yaw [deg], same
  convention as our labels),
- `timestamp` (N,).

Converted to the in-memory window form of `data.WindowData` (kind 'image'): window k = frames (k, k+1),
label `label_data[0,k]`, IMU = the 20 newest rows of `imu_data[k+1]` reversed to oldest first. The
images are used directly (no panorama expansion); they are normalised `(x - min)/(max - min) - mean` with
min, max and mean computed over THIS dataset (all files given), since the authors' files carry no
statistics. Ground-truth poses are not in the files: `gt_pose` is the composition of the labels from the
identity, which is all the ATE evaluation needs. Each file is one chain (gap 1 in its own frame indices).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .data import Session, WindowData
from .geometry import compose, rot_to_quat

IMU_LEN = 20


def _poses_from_labels(label: np.ndarray) -> np.ndarray:
    mats = compose(np.eye(4), label)
    return np.stack([np.concatenate([m[:3, 3], rot_to_quat(m[:3, :3])]) for m in mats])


def read_h5_session(path: Path) -> Session:
    import h5py
    with h5py.File(path, "r") as f:
        img = np.asarray(f["mmwave_middle_data"], dtype=np.float32)[:, 0, :, :, 0]
        imu = np.asarray(f["imu_data"], dtype=np.float32)
        label = np.asarray(f["label_data"], dtype=np.float32)[0]
        ts = np.asarray(f["timestamp"], dtype=np.float64).reshape(-1)
    n = len(img)
    if label.shape[0] != n - 1 or imu.shape[0] != n:
        raise ValueError(f"{path}: inconsistent lengths images {n}, imu {imu.shape[0]}, labels {label.shape[0]}")
    pair = np.stack([np.arange(n - 1), np.arange(1, n)], 1).astype(np.int64)
    win_imu = np.ascontiguousarray(imu[1:, :IMU_LEN][:, ::-1])
    return Session(path.stem, img, ts, _poses_from_labels(label), pair, win_imu, label)


def load_h5(path: str | Path) -> WindowData:
    """One h5 file, or every `*.h5` in a directory (sorted), as one dataset."""
    p = Path(path)
    files = sorted(p.glob("*.h5")) if p.is_dir() else [p]
    if not files:
        raise FileNotFoundError(f"no .h5 files in {p}")
    sessions = [read_h5_session(f) for f in files]
    lo = float(min(s.frames.min() for s in sessions))
    hi = float(max(s.frames.max() for s in sessions))
    hi = hi if hi > lo else lo + 1.0
    total = sum(float(((s.frames - lo) / (hi - lo)).sum(dtype=np.float64)) for s in sessions)
    mean = total / sum(s.frames.size for s in sessions)
    preprocess = {"source": "authors-h5", "gap": 1, "img_h": 64, "img_w": 256, "imu_len": IMU_LEN}
    return WindowData(sessions, {"min": lo, "max": hi, "mean": mean}, preprocess, kind="image")
