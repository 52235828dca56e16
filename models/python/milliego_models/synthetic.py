"""Synthetic datasets in the exact `milliego dataset build` format (manifest + safetensors shards), and
small h5 files in the authors' layout, for tests and speed measurements.

The scene is a cloud of random points around a smooth 6-DoF trajectory; panoramas are rendered with the
manifest geometry (azimuth +-63 deg, elevation +-15 deg, 2 deg per pixel, nearer = brighter, 3 frames
overlaid). This is a stand-in renderer, NOT the Rust preprocessing; only the file format is normative.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .data import expand_panorama
from .geometry import relative_label, rot_to_quat

PREPROCESS = {"gap": 5, "overlay": 3, "az_half_deg": 63.0, "el_half_deg": 15.0, "deg_per_px": 2.0,
              "pano_h": 16, "pano_w": 64, "upscale": 4, "img_h": 64, "img_w": 256, "imu_len": 20,
              "max_range_m": 20.0}
GRAVITY = 9.81


class Trajectory:
    """Smooth random motion: position and roll/pitch/yaw are sums of sinusoids of time."""

    def __init__(self, rng: np.random.Generator):
        self.amp = rng.uniform(0.3, 2.0, (6, 3)) * np.array([0.6, 0.6, 0.1, 0.05, 0.05, 0.3])[:, None]
        self.freq = rng.uniform(0.05, 0.4, (6, 3))
        self.phase = rng.uniform(0, 2 * np.pi, (6, 3))

    def rpy(self, t):
        return (self.amp[3:, :, None] * np.sin(2 * np.pi * self.freq[3:, :, None] * t + self.phase[3:, :, None])).sum(1).T

    def pos(self, t):
        return (self.amp[:3, :, None] * np.sin(2 * np.pi * self.freq[:3, :, None] * t + self.phase[:3, :, None])).sum(1).T

    def rot(self, t):
        r, p, y = self.rpy(np.atleast_1d(t)).T
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        return np.stack([np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
                         np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
                         np.stack([-sp, cp * sr, cp * cr], -1)], -2)

    def imu(self, t, h=1e-3):
        """Specific force and angular rate in the body frame at times t [N] -> [N,6]."""
        acc = (self.pos(t + h) - 2 * self.pos(t) + self.pos(t - h)) / h**2
        r = self.rot(t)
        f = np.einsum("nji,nj->ni", r, acc + np.array([0, 0, GRAVITY]))
        dr = np.einsum("nji,njk->nik", r, self.rot(t + h)) - np.eye(3)
        w = np.stack([dr[:, 2, 1] - dr[:, 1, 2], dr[:, 0, 2] - dr[:, 2, 0], dr[:, 1, 0] - dr[:, 0, 1]], -1) / (2 * h)
        return np.concatenate([f, w], 1)


def render_panoramas(points, pos, rot, pre=PREPROCESS, vel=None):
    """Per-frame single panoramas [F,16,64], values 1 - r/max_range (0 = no return). With the sensor's
    world velocity `vel` [F,3], also each bin's radial velocity (the nearest point's; negative
    approaching): returns (panoramas, Doppler panoramas)."""
    out = np.zeros((len(pos), pre["pano_h"], pre["pano_w"]), np.float32)
    dop = np.zeros_like(out)
    for f in range(len(pos)):
        body = (points - pos[f]) @ rot[f]
        r = np.linalg.norm(body, axis=1)
        if vel is not None:
            vr = -(body / np.maximum(r, 1e-9)[:, None]) @ (rot[f].T @ vel[f])
        az = np.degrees(np.arctan2(body[:, 1], body[:, 0]))
        el = np.degrees(np.arctan2(body[:, 2], np.hypot(body[:, 0], body[:, 1])))
        ok = (np.abs(az) < pre["az_half_deg"]) & (np.abs(el) < pre["el_half_deg"]) & (r < pre["max_range_m"])
        col = np.clip(((pre["az_half_deg"] - az[ok]) / pre["deg_per_px"]).astype(int), 0, pre["pano_w"] - 1)
        row = np.clip(((pre["el_half_deg"] - el[ok]) / pre["deg_per_px"]).astype(int), 0, pre["pano_h"] - 1)
        val = (1 - r[ok] / pre["max_range_m"]).astype(np.float32)
        np.maximum.at(out[f], (row, col), val)
        if vel is not None:
            order = np.argsort(val, kind="stable")  # the nearest point of a bin is written last
            dop[f][row[order], col[order]] = vr[ok][order]
    return out if vel is None else (out, dop)


def synthetic_session(frames: int, seed: int, rate_hz: float = 10.0, points: int = 600, pre=PREPROCESS) -> dict:
    rng = np.random.default_rng(seed)
    traj = Trajectory(rng)
    t = np.arange(frames) / rate_hz + 1.0
    pos, rot = traj.pos(t), traj.rot(t)
    cloud = np.concatenate([rng.uniform(-12, 12, (points, 2)), rng.uniform(-2, 2.5, (points, 1))], 1)
    vel = (traj.pos(t + 1e-3) - traj.pos(t - 1e-3)) / 2e-3
    single, single_dop = render_panoramas(cloud, pos, rot, pre, vel)
    pano, dop = single.copy(), single_dop.copy()
    for k in range(1, pre["overlay"]):
        older = single[:-k] > pano[k:]  # the nearest return of the overlaid frames and its Doppler
        pano[k:] = np.where(older, single[:-k], pano[k:])
        dop[k:] = np.where(older, single_dop[:-k], dop[k:])
    gt = np.concatenate([pos, np.stack([rot_to_quat(r) for r in rot])], 1)
    gap, n_imu = pre["gap"], pre["imu_len"]
    cur = np.arange(gap, frames)
    pair = np.stack([cur - gap, cur], 1).astype(np.int64)
    tk = t[pair[:, :1]] + (np.arange(1, n_imu + 1) / n_imu) * (t[pair[:, 1:]] - t[pair[:, :1]])
    imu = traj.imu(tk.reshape(-1)).reshape(len(pair), n_imu, 6)
    imu += rng.normal(0, [0.05, 0.05, 0.05, 0.005, 0.005, 0.005], imu.shape)
    label = np.stack([relative_label(gt[a], gt[b]) for a, b in pair])
    return {"panorama": pano.astype(np.float32), "doppler": dop.astype(np.float32), "frame_time": t.astype(np.float64), "gt_pose": gt,
            "pair": pair, "imu": imu.astype(np.float32), "label": label.astype(np.float32)}


def write_synthetic_dataset(out_dir, sessions=(("synthetic-0", 200),), seed: int = 0) -> Path:
    """Write `manifest.json` + one shard per (name, frames) session; returns the directory."""
    from safetensors.numpy import save_file
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shards, tensors = [], []
    for i, (name, frames) in enumerate(sessions):
        s = synthetic_session(frames, seed * 1000 + i)
        fname = f"shard-{i:04d}.safetensors"
        save_file(s, str(out / fname))
        shards.append({"file": fname, "session": name, "frames": frames, "windows": len(s["pair"])})
        tensors.append(s)
    mean = float(np.mean(np.concatenate([s["panorama"].reshape(-1) for s in tensors])))
    manifest = {"format": "milliego-dataset", "version": 1, "preprocess": PREPROCESS,
                "norm": {"min": 0.0, "max": 1.0, "mean": mean}, "shards": shards,
                "frames": sum(s["frames"] for s in shards), "windows": sum(s["windows"] for s in shards)}
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return out


def write_authors_h5(path, frames: int = 40, seed: int = 0) -> Path:
    """A small h5 in the authors' layout (see `h5.py`), from a synthetic session with gap 1."""
    import h5py
    pre = dict(PREPROCESS, gap=1)
    s = synthetic_session(frames, seed, pre=pre)
    rng = np.random.default_rng(seed)
    img = expand_panorama(s["panorama"], {"min": 0.0, "max": 1.0, "mean": 0.0}) * 255.0
    imu30 = rng.normal(0, 1, (frames, 30, 6)).astype(np.float32)
    imu30[1:, :20] = s["imu"][:, ::-1]  # newest first
    with h5py.File(path, "w") as f:
        f["mmwave_middle_data"] = img[:, None, :, :, None].astype(np.float32)
        f["imu_data"] = imu30
        f["label_data"] = s["label"][None]
        f["timestamp"] = s["frame_time"]
    return Path(path)
