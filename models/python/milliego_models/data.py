"""Loading `milliego dataset build` output into memory, and sampling windows or window chains.

Dataset directory: `manifest.json` plus one `shard-NNNN.safetensors` per session (format in README.md).
Everything is loaded into memory: a panorama is 16x64 f32 (4 KiB), so 100k frames are 400 MiB.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

FORMAT = "milliego-dataset"
UPSCALE = 4
# Radial velocity that maps to 1 in a Doppler image [m/s] (Rust: `milliego_preprocess::DOPPLER_SCALE_MPS`).
DOPPLER_SCALE_MPS = np.float32(5.0)


def normalise(img: np.ndarray, norm: dict) -> np.ndarray:
    """`(x - min) / (max - min) - mean` with the dataset-wide statistics."""
    lo, hi = float(norm["min"]), float(norm["max"])
    return ((img - lo) / (hi - lo) - float(norm["mean"])).astype(np.float32)


def expand_panorama(pano: np.ndarray, norm: dict) -> np.ndarray:
    """Panorama [..., 16, 64] -> normalised model image [..., 64, 256] (f32).

    Nearest-neighbour x4 upsample (every panorama pixel becomes a 4x4 block,
    `np.repeat(np.repeat(p, 4, -2), 4, -1)`), then `(x - min) / (max - min) - mean`.
    This MUST match the Rust `milliego_preprocess` expansion bit for bit (the Rust side checks parity
    against a fixture); change both or neither.
    """
    pano = np.asarray(pano, dtype=np.float32)
    img = np.repeat(np.repeat(pano, UPSCALE, axis=-2), UPSCALE, axis=-1)
    return normalise(img, norm)


def expand_doppler(doppler: np.ndarray) -> np.ndarray:
    """Doppler panorama [..., 16, 64] (m/s) -> Doppler image [..., 64, 256]: x4 nearest, then
    `clip(v / DOPPLER_SCALE_MPS, -1, 1)` in f32 (the Rust `panorama::expand_doppler`, bit for bit)."""
    d = np.clip(np.asarray(doppler, dtype=np.float32) / DOPPLER_SCALE_MPS, np.float32(-1), np.float32(1))
    return np.repeat(np.repeat(d, UPSCALE, axis=-2), UPSCALE, axis=-1).astype(np.float32)


def stack_pair(img_prev: np.ndarray, img_cur: np.ndarray, dop_prev: np.ndarray | None = None,
               dop_cur: np.ndarray | None = None) -> np.ndarray:
    """Two normalised images [..., 64, 256] -> radar input [..., 6, 64, 256]: prev x3 then cur x3
    (`radar_input` "depth"); with Doppler images, each frame's depth, Doppler, depth ("depth_doppler")."""
    if dop_prev is None:
        return np.concatenate([np.repeat(img_prev[..., None, :, :], 3, -3),
                               np.repeat(img_cur[..., None, :, :], 3, -3)], axis=-3)
    return np.stack([img_prev, dop_prev, img_prev, img_cur, dop_cur, img_cur], axis=-3)


@dataclass
class Session:
    """One recording. `frames` are panoramas [F,16,64] (kind 'panorama') or final images [F,64,256] ('image')."""
    name: str
    frames: np.ndarray
    frame_time: np.ndarray
    gt_pose: np.ndarray
    pair: np.ndarray
    imu: np.ndarray
    label: np.ndarray
    doppler: np.ndarray | None = None  # [F,16,64] m/s, datasets that carry it


@dataclass
class WindowData:
    """All windows of a dataset in memory, indexed globally 0..n-1."""
    sessions: list[Session]
    norm: dict
    preprocess: dict
    kind: str = "panorama"
    radar_input: str = "depth"
    frames: np.ndarray = field(init=False)
    doppler: np.ndarray | None = field(init=False)
    pair: np.ndarray = field(init=False)  # global frame indices
    imu: np.ndarray = field(init=False)
    label: np.ndarray = field(init=False)
    gt_pose: np.ndarray = field(init=False)
    session_of: np.ndarray = field(init=False)
    chains: list[np.ndarray] = field(init=False)

    def __post_init__(self):
        offsets = np.cumsum([0] + [len(s.frames) for s in self.sessions])
        self.frames = np.concatenate([s.frames for s in self.sessions]).astype(np.float32)
        self.doppler = (np.concatenate([s.doppler for s in self.sessions]).astype(np.float32)
                        if all(s.doppler is not None for s in self.sessions) else None)
        self.gt_pose = np.concatenate([s.gt_pose for s in self.sessions]).astype(np.float64)
        self.pair = np.concatenate([s.pair.astype(np.int64) + o for s, o in zip(self.sessions, offsets)])
        self.imu = np.concatenate([s.imu for s in self.sessions]).astype(np.float32)
        self.label = np.concatenate([s.label for s in self.sessions]).astype(np.float32)
        self.session_of = np.concatenate([np.full(len(s.pair), i) for i, s in enumerate(self.sessions)])
        self.chains = build_chains(self.pair, self.session_of)

    def __len__(self) -> int:
        return len(self.pair)

    def images(self, frame_idx: np.ndarray) -> np.ndarray:
        if self.kind == "panorama":
            return expand_panorama(self.frames[frame_idx], self.norm)
        return normalise(self.frames[frame_idx], self.norm)

    def radar(self, idx) -> np.ndarray:
        """Model radar input [B,6,64,256] for window ids `idx`."""
        p = self.pair[np.asarray(idx)]
        if self.radar_input == "depth":
            return stack_pair(self.images(p[..., 0]), self.images(p[..., 1]))
        if self.radar_input != "depth_doppler":
            raise ValueError(f"radar input {self.radar_input!r}: 'depth' or 'depth_doppler'")
        if self.doppler is None:
            raise ValueError("radar input 'depth_doppler' needs a dataset with a 'doppler' tensor in every "
                             "shard (built by `milliego dataset build` since Doppler input exists)")
        return stack_pair(self.images(p[..., 0]), self.images(p[..., 1]),
                          expand_doppler(self.doppler[p[..., 0]]), expand_doppler(self.doppler[p[..., 1]]))

    def batch(self, idx) -> dict[str, torch.Tensor]:
        idx = np.asarray(idx, dtype=np.int64)
        return {"radar": torch.from_numpy(self.radar(idx)), "imu": torch.from_numpy(self.imu[idx]),
                "label": torch.from_numpy(self.label[idx]), "index": torch.from_numpy(idx)}

    def truncated(self, max_windows: int | None) -> "WindowData":
        """The first `max_windows` windows (whole sessions first, the last one cut)."""
        if max_windows is None or max_windows >= len(self):
            return self
        keep, out = max_windows, []
        for s in self.sessions:
            if keep <= 0:
                break
            n = min(keep, len(s.pair))
            out.append(Session(s.name, s.frames, s.frame_time, s.gt_pose, s.pair[:n], s.imu[:n], s.label[:n],
                               s.doppler))
            keep -= n
        return WindowData(out, self.norm, self.preprocess, self.kind, self.radar_input)


def build_chains(pair: np.ndarray, session_of: np.ndarray) -> list[np.ndarray]:
    """Window chains: same session and `cur % gap`, increasing `cur`, each prev == previous cur."""
    chains = []
    gap = pair[:, 1] - pair[:, 0]
    for s in np.unique(session_of):
        ids = np.nonzero(session_of == s)[0]
        g = int(gap[ids[0]]) if len(ids) else 1
        for r in np.unique(pair[ids, 1] % g):
            sel = ids[pair[ids, 1] % g == r]
            sel = sel[np.argsort(pair[sel, 1], kind="stable")]
            start = 0
            for k in range(1, len(sel) + 1):
                if k == len(sel) or pair[sel[k], 0] != pair[sel[k - 1], 1]:
                    chains.append(sel[start:k])
                    start = k
    return chains


def load_dataset(path: str | Path, max_windows: int | None = None) -> WindowData:
    from safetensors.numpy import load_file
    path = Path(path)
    manifest = json.loads((path / "manifest.json").read_text())
    if manifest.get("format") != FORMAT or manifest.get("version") != 1:
        raise ValueError(f"{path}: not a {FORMAT} v1 dataset")
    sessions = []
    for shard in manifest["shards"]:
        t = load_file(str(path / shard["file"]))
        pair = t["pair"].astype(np.int64)
        gap = manifest["preprocess"]["gap"]
        if len(pair) and np.any(pair[:, 1] - pair[:, 0] != gap):
            raise ValueError(f"{shard['file']}: window with cur - prev != gap {gap}")
        sessions.append(Session(shard.get("session", shard["file"]), t["panorama"], t["frame_time"],
                                t["gt_pose"], pair, t["imu"], t["label"], t.get("doppler")))
    return WindowData(sessions, manifest["norm"], manifest["preprocess"]).truncated(max_windows)


def load_any(path: str | Path, max_windows: int | None = None) -> WindowData:
    """A `milliego dataset build` directory, or an authors'-layout h5 file / directory of h5 files."""
    p = Path(path)
    if (p / "manifest.json").exists():
        return load_dataset(p, max_windows)
    from .h5 import load_h5
    return load_h5(p).truncated(max_windows)


class ChainSampler:
    """Truncated-BPTT batches for stateful training: each item is L consecutive windows of one chain.

    Every epoch the chains are cut into non-overlapping pieces of `seq_len` from a random offset,
    shuffled, and dealt to the ranks (equal counts, so DDP ranks stay in step). Yields [B, L] window ids.
    """

    def __init__(self, chains, seq_len: int, batch: int, rank: int = 0, world: int = 1, seed: int = 0):
        self.chains = [c for c in chains if len(c) >= seq_len]
        self.seq_len, self.batch, self.rank, self.world, self.seed = seq_len, batch, rank, world, seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def _sequences(self) -> np.ndarray:
        rng = np.random.default_rng((self.seed, self.epoch))
        seqs = []
        for c in self.chains:
            off = int(rng.integers(0, max(1, len(c) - self.seq_len + 1))) % self.seq_len
            for i in range(off, len(c) - self.seq_len + 1, self.seq_len):
                seqs.append(c[i:i + self.seq_len])
        seqs = np.array(seqs, dtype=np.int64).reshape(-1, self.seq_len)
        seqs = seqs[rng.permutation(len(seqs))]
        per_rank = len(seqs) // self.world
        return seqs[self.rank * per_rank:(self.rank + 1) * per_rank]

    def __len__(self) -> int:
        return -(-len(self._sequences()) // self.batch)

    def __iter__(self):
        seqs = self._sequences()
        for i in range(0, len(seqs), self.batch):
            yield seqs[i:i + self.batch]


class WindowIndex(torch.utils.data.Dataset):
    """Window ids 0..n-1; the DataLoader's collate turns a list of ids into a batch via `WindowData.batch`."""

    def __init__(self, n: int):
        self.n = n

    def __len__(self):
        return self.n

    def __getitem__(self, i):
        return i
