"""Train milliEgo on `milliego dataset build` output (or authors' h5 files).

    python -m milliego_models.train --data TRAIN_DIR --val VAL_DIR --config compact \
        --mode stateless --out runs/compact-0 [--epochs 50] [--resume]
    torchrun --standalone --nproc_per_node=2 -m milliego_models.train ...   # DDP, same arguments

Loss (paper eq. 1): MSE(translation [m]) + gamma * MSE(rotation [deg]). The reference code uses
gamma = 0.001 on degrees, which with our windows (gap 5 radar frames) makes rotation almost invisible to
the optimizer. Default `--gamma auto` sets gamma = mean var(translation) / mean var(rotation) over the
training labels, so that both terms weigh the same for a predict-the-mean model; the value is printed and
logged in metrics.jsonl (on the synthetic data ~0.02-0.05; see README).

Optimizer: Adam (lr 1e-4, StepLR x0.75 every `--lr-step` epochs) instead of the paper's RMSprop lr 1e-5:
the paper fine-tunes from frozen FlowNet weights over 200 epochs, we train every layer from scratch in a
few CPU epochs, where Adam's per-parameter step sizes converge far faster. `--optimizer rmsprop` restores
the paper's choice.

Uncertainty (`--uncertainty`, our extension for issue 19): a third head predicts the log-variance of each
pose component from the fusion LSTM's output with the gradient stopped, trained by the Gaussian negative
log-likelihood of the (detached) errors, so the poses are trained exactly as without it. `--init-onnx
model.onnx --train-only std` adds the head to an exported model and trains the head alone (the trunk
frozen, in eval mode: the features it sees are the ones inference computes). Exported as `pose_std`.

Modes: `stateless` trains on random single windows with zero LSTM state (the released model's behaviour);
`stateful` trains on L = `--seq-len` consecutive windows of one chain from zero state with
backpropagation through the L steps (truncated BPTT), so the model learns to use the carried state.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
import torch.nn.functional as F
from torch.utils.data import DataLoader, DistributedSampler

from .data import ChainSampler, WindowData, WindowIndex, load_any
from .geometry import aligned_errors, compose, pose_to_matrix
from .model import CONFIGS, RADAR_INPUTS, MilliEgo, Unrolled, count_params


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True, help="training dataset directory (or h5 file/dir)")
    p.add_argument("--val", required=True, help="validation dataset directory (or h5 file/dir)")
    p.add_argument("--config", default="compact", choices=sorted(CONFIGS))
    p.add_argument("--mode", default="stateless", choices=["stateless", "stateful"])
    p.add_argument("--out", required=True, help="run directory (checkpoints, metrics.jsonl)")
    p.add_argument("--epochs", type=int, default=50, help="total epochs (a resumed run continues to this)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--batch", type=int, default=32, help="windows (stateless) or sequences (stateful) per rank")
    p.add_argument("--seq-len", type=int, default=8, help="stateful: windows per truncated-BPTT sequence")
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--lr-step", type=int, default=10, help="epochs between lr x0.75 steps")
    p.add_argument("--optimizer", default="adam", choices=["adam", "rmsprop"])
    p.add_argument("--gamma", default="auto", help="rotation loss weight, or 'auto' (label variance ratio)")
    p.add_argument("--clip", type=float, default=5.0, help="gradient norm clip (0 = off)")
    p.add_argument("--patience", type=int, default=8, help="early stop after this many epochs without val ATE gain")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    p.add_argument("--max-windows", type=int, default=None, help="use only the first N training windows")
    p.add_argument("--max-val-windows", type=int, default=None)
    p.add_argument("--time-budget-min", type=float, default=None, help="stop after the epoch that exceeds this")
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads per rank")
    p.add_argument("--uncertainty", action="store_true",
                   help="add the uncertainty head (predicted log-variance per pose component, Gaussian NLL)")
    p.add_argument("--init-onnx", default=None,
                   help="initialise from an exported fp32 model (its weights and image normalisation)")
    p.add_argument("--radar-input", default="depth", choices=sorted(RADAR_INPUTS),
                   help="what the radar input's channels carry: depth (the paper's copies) or depth_doppler "
                        "(milliEgo+D: each frame's Doppler image in its middle channel; needs a dataset with Doppler)")
    p.add_argument("--train-only", default="all", choices=["all", "std"],
                   help="std: train only the uncertainty head (needs --uncertainty; the rest frozen)")
    a = p.parse_args(argv)
    if a.train_only == "std" and not a.uncertainty:
        p.error("--train-only std needs --uncertainty")
    return a


def setup_distributed():
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local = int(os.environ.get("LOCAL_RANK", "0"))
    if torch.cuda.is_available():
        device = torch.device("cuda", local)
        torch.cuda.set_device(device)
    else:
        device = torch.device("cpu")
    if world > 1:
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return rank, world, device


def seed_all(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.cuda.manual_seed_all(seed)


def rng_states() -> dict:
    s = {"python": random.getstate(), "numpy": np.random.get_state(), "torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        s["cuda"] = torch.cuda.get_rng_state_all()
    return s


def set_rng_states(s: dict) -> None:
    random.setstate(s["python"])
    np.random.set_state(s["numpy"])
    torch.set_rng_state(s["torch"])
    if "cuda" in s and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(s["cuda"])


def auto_gamma(label: np.ndarray) -> float:
    var = label.astype(np.float64).var(0)
    return float(var[:3].mean() / max(var[3:].mean(), 1e-12))


def pose_loss(pred: torch.Tensor, target: torch.Tensor, gamma: float):
    """MSE(translation [m]) + gamma * MSE(rotation [deg]) of the first 6 columns of `pred`."""
    t = F.mse_loss(pred[..., :3], target[..., :3])
    r = F.mse_loss(pred[..., 3:6], target[..., 3:6])
    return t + gamma * r, t, r


def nll_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Gaussian negative log-likelihood (constant dropped, mean over components) of the errors of the
    pose columns `pred[..., :6]`, detached, under the predicted log-variances `pred[..., 6:12]`."""
    err2 = (pred[..., :6].detach() - target) ** 2
    log_var = pred[..., 6:12]
    return 0.5 * (log_var + err2 * torch.exp(-log_var)).mean()


def load_onnx_weights(net: MilliEgo, path: str) -> dict:
    """Copies an exported fp32 model's weights into `net` (initializer names = parameter names; a first
    convolution folded over the radar copies is spread back over them, the same function on copied
    inputs). Returns the file's metadata. Every parameter except the uncertainty head must be found."""
    import onnx
    from onnx import numpy_helper

    from .onnx_utils import get_metadata
    model = onnx.load(path)
    meta = get_metadata(model)
    if meta.get("precision", "fp32") != "fp32":
        raise ValueError(f"{path}: precision {meta.get('precision')}; initialise from the fp32 file")
    if meta["config"] != net.config.name:
        raise ValueError(f"{path}: config {meta['config']!r}, training {net.config.name!r}")
    src_input = meta.get("radar_input", "depth")
    if src_input != net.radar_input and src_input != "depth":
        raise ValueError(f"{path}: radar input {src_input!r}, training {net.radar_input!r}")
    inits = {i.name.removeprefix("net."): numpy_helper.to_array(i) for i in model.graph.initializer}
    state = net.state_dict()
    missing = []
    for name, value in state.items():
        if name not in inits:
            if not name.startswith("std_head."):
                missing.append(name)
            continue
        w = inits[name]
        if tuple(w.shape) != tuple(value.shape) and name == "convs.0.weight" and meta.get("radar_copies_folded"):
            # Each group's weight on its first channel, zeros on the copies: on copied inputs the same
            # function, and folding it again at export gives back the same floats (w + 0 + 0 = w). A depth
            # file's first channels (0 and 3) are depth in either layout, so a depth_doppler network
            # starts as the depth file's function, with zero weight on its Doppler channels.
            groups = RADAR_INPUTS[src_input]
            spread = np.zeros((w.shape[0], sum(len(g) for g in groups)) + w.shape[2:], w.dtype)
            for k, g in enumerate(groups):
                spread[:, g[0]] = w[:, k]
            w = spread
        if tuple(w.shape) != tuple(value.shape):
            raise ValueError(f"{path}: {name} has shape {w.shape}, the network {tuple(value.shape)}")
        state[name] = torch.from_numpy(np.ascontiguousarray(w, dtype=np.float32))
    if missing:
        raise ValueError(f"{path}: no weights for {missing[:5]} ({len(missing)} parameters)")
    net.load_state_dict(state)
    return meta


@torch.no_grad()
def predict_chains(net: MilliEgo, data: WindowData, chains, stateful: bool, device, batch: int = 64):
    """Predicted labels [len(c),6] for each chain; features batched, LSTM state carried if stateful."""
    net.eval()
    out = []
    for c in chains:
        feats = []
        for i in range(0, len(c), batch):
            b = data.batch(c[i:i + batch])
            feats.append(net.features(b["radar"].to(device), b["imu"].to(device)))
        feats = torch.cat(feats)
        if stateful:
            state, poses = net.zero_state(1, device), []
            for t in range(len(c)):
                pose, state = net.recurrent(feats[t:t + 1], state)
                poses.append(pose)
            poses = torch.cat(poses)
        else:
            poses = net.recurrent(feats, net.zero_state(len(c), device))[0]
        out.append(poses.cpu().numpy())
    return out


def evaluate(net, data: WindowData, stateful: bool, device, gamma: float) -> dict:
    """Validation loss and ATE: each chain composed from the GT pose of its first frame, SE(3)-aligned
    (Umeyama) to the GT positions of its frames; RMSE and mean per session, averaged over sessions."""
    preds = predict_chains(net, data, data.chains, stateful, device)
    errs: dict[int, list] = {}
    losses = []
    for c, p in zip(data.chains, preds):
        frames = np.concatenate([[data.pair[c[0], 0]], data.pair[c, 1]])
        est = compose(pose_to_matrix(data.gt_pose[frames[0]]), p[:, :6])[:, :3, 3]
        errs.setdefault(int(data.session_of[c[0]]), []).append(aligned_errors(est, data.gt_pose[frames, :3]))
        losses.append([x.item() * len(c) for x in pose_loss(torch.from_numpy(p), torch.from_numpy(data.label[c]), gamma)])
    per = [np.concatenate(v) for v in errs.values()]
    loss, trans, rot = np.sum(losses, axis=0) / max(1, sum(len(c) for c in data.chains))
    out = {"val_loss": float(loss), "val_trans_mse": float(trans), "val_rot_mse_deg2": float(rot),
           "val_ate_rmse_m": float(np.mean([np.sqrt(np.mean(e ** 2)) for e in per])),
           "val_ate_mean_m": float(np.mean([e.mean() for e in per]))}
    if net.uncertainty:
        out.update(uncertainty_metrics(np.concatenate(preds), data.label[np.concatenate(data.chains)]))
    return out


def uncertainty_metrics(pred: np.ndarray, label: np.ndarray) -> dict:
    """How well the predicted deviations fit the errors: the NLL, the mean squared normalised error of
    translation and rotation (1 when calibrated), and the rank correlation between the predicted
    translation deviation and the translation error's size (0: the head says nothing)."""
    err = pred[:, :6] - label
    var = np.exp(pred[:, 6:12])
    z2 = err ** 2 / var
    t_err = np.linalg.norm(err[:, :3], axis=1)
    t_std = np.sqrt(var[:, :3].sum(1))

    def ranks(x):
        r = np.empty(len(x))
        r[np.argsort(x)] = np.arange(len(x))
        return r
    rho = float(np.corrcoef(ranks(t_err), ranks(t_std))[0, 1]) if len(t_err) > 2 and t_std.std() > 0 else 0.0
    return {"val_nll": float(0.5 * (np.log(var) + z2).mean()), "val_z2_trans": float(z2[:, :3].mean()),
            "val_z2_rot": float(z2[:, 3:].mean()), "val_std_err_rank_corr": rho}


def batches(data: WindowData, args, rank, world, epoch):
    """Yields window-id arrays [B, L] (L = 1 when stateless)."""
    if args.mode == "stateful":
        sampler = ChainSampler(data.chains, args.seq_len, args.batch, rank, world, args.seed)
        sampler.set_epoch(epoch)
        yield from sampler
    else:
        sampler = DistributedSampler(WindowIndex(len(data)), num_replicas=world, rank=rank, shuffle=True,
                                     seed=args.seed)
        sampler.set_epoch(epoch)
        loader = DataLoader(WindowIndex(len(data)), batch_size=args.batch, sampler=sampler,
                            collate_fn=lambda ids: np.asarray(ids, dtype=np.int64)[:, None])
        yield from loader


def n_batches(data, args, world):
    if args.mode == "stateful":
        return len(ChainSampler(data.chains, args.seq_len, args.batch, 0, world, args.seed))
    return -(-(-(-len(data) // world)) // args.batch)


def save(path: Path, obj: dict) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def main(argv=None) -> int:
    args = parse_args(argv)
    rank, world, device = setup_distributed()
    if device.type == "cpu":
        torch.set_num_threads(args.threads or max(1, (os.cpu_count() or 2) // world))
    out = Path(args.out)
    log = (lambda *a: print(*a, flush=True)) if rank == 0 else (lambda *a: None)
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    started = time.time()

    train = load_any(args.data, args.max_windows)
    val = load_any(args.val, args.max_val_windows)
    # The model sees every image through the TRAINING set's normalisation (it ships with the model).
    val.norm = train.norm
    train.radar_input = val.radar_input = args.radar_input
    stateful = args.mode == "stateful"
    gamma = auto_gamma(train.label) if args.gamma == "auto" else float(args.gamma)
    log(f"train {len(train)} windows ({len(train.chains)} chains), val {len(val)} windows, "
        f"world {world}, device {device}, gamma {gamma:.4g}")

    seed_all(args.seed)
    net = MilliEgo(args.config, args.uncertainty, args.radar_input).to(device)
    if args.init_onnx:
        init_meta = load_onnx_weights(net, args.init_onnx)
        if init_meta.get("norm"):
            # The weights were trained on images through that normalisation: keep it.
            train.norm = val.norm = init_meta["norm"]
        log(f"initialised from {args.init_onnx} (its normalisation {train.norm})")
    if args.train_only == "std":
        for name, prm in net.named_parameters():
            prm.requires_grad_(name.startswith("std_head."))
    trainable = [prm for prm in net.parameters() if prm.requires_grad]
    # Gradient clipping per group: the pose path, then the uncertainty head.
    clip_groups = [[], []]
    for name, prm in net.named_parameters():
        if prm.requires_grad:
            clip_groups[name.startswith("std_head.")].append(prm)
    clip_groups = [g for g in clip_groups if g]
    log(f"config {args.config}: {count_params(net):,} parameters ({sum(p.numel() for p in trainable):,} trained), "
        f"mode {args.mode}, uncertainty {args.uncertainty}")
    opt = (torch.optim.Adam(trainable, lr=args.lr) if args.optimizer == "adam"
           else torch.optim.RMSprop(trainable, lr=args.lr))
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=args.lr_step, gamma=0.75)
    start_epoch, best, bad = 0, float("inf"), 0
    if args.resume:
        ck = torch.load(out / "last.pt", map_location=device, weights_only=False)
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        sched.load_state_dict(ck["scheduler"])
        start_epoch, best, bad, gamma = ck["epoch"], ck["best"], ck["bad_epochs"], ck["gamma"]
        set_rng_states(ck["rng"][min(rank, len(ck["rng"]) - 1)])
        log(f"resumed from {out / 'last.pt'} after epoch {start_epoch}, best val ATE {best:.4g} m")
    else:
        seed_all(args.seed + rank)
    model = Unrolled(net)
    if world > 1:
        model = torch.nn.parallel.DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)

    from tqdm import tqdm
    stop = False
    for epoch in range(start_epoch, args.epochs):
        if stop:
            break
        t0 = time.time()
        # Head-only training keeps the trunk in eval mode (no dropout): the features inference sees.
        model.train(args.train_only == "all")
        sums, seen = np.zeros(4), 0
        bar = tqdm(batches(train, args, rank, world, epoch), total=n_batches(train, args, world),
                   desc=f"epoch {epoch + 1}/{args.epochs}", disable=rank != 0, mininterval=5, file=sys.stdout)
        for ids in bar:
            b = train.batch(ids.reshape(-1))
            B, L = ids.shape
            radar = b["radar"].to(device).view(B, L, *b["radar"].shape[1:])
            imu = b["imu"].to(device).view(B, L, *b["imu"].shape[1:])
            label = b["label"].to(device).view(B, L, 6)
            pred, _ = model(radar, imu, net.zero_state(B, device))
            loss, lt, lr_ = pose_loss(pred, label, gamma)
            nll = nll_loss(pred, label) if net.uncertainty else torch.zeros(())
            if args.train_only == "std":
                loss = nll
            elif net.uncertainty:
                loss = loss + nll
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if args.clip > 0:
                # The pose path and the uncertainty head clipped apart: the head never changes the poses.
                for group in clip_groups:
                    torch.nn.utils.clip_grad_norm_(group, args.clip)
            opt.step()
            sums += np.array([loss.item(), lt.item(), lr_.item(), nll.item()]) * B * L
            seen += B * L
            bar.set_postfix(loss=f"{sums[0] / seen:.4g}")
        sched.step()
        train_s = time.time() - t0

        decision = [False, False]
        if rank == 0:
            m = evaluate(net, val, stateful, device, gamma)
            # The best checkpoint: by validation ATE, or by validation NLL when only the head trains.
            key = "val_nll" if args.train_only == "std" else "val_ate_rmse_m"
            improved = m[key] < best
            best, bad = (m[key], 0) if improved else (best, bad + 1)
            rec = {"epoch": epoch + 1, "train_loss": sums[0] / max(seen, 1), "train_trans_mse": sums[1] / max(seen, 1),
                   "train_rot_mse_deg2": sums[2] / max(seen, 1),
                   **({"train_nll": sums[3] / max(seen, 1)} if net.uncertainty else {}), **m, f"best_{key}": best,
                   "lr": opt.param_groups[0]["lr"], "gamma": gamma, "train_seconds": train_s,
                   "windows_per_s": seen * world / max(train_s, 1e-9), "world": world}
            with open(out / "metrics.jsonl", "a") as f:
                f.write(json.dumps(rec) + "\n")
            log(json.dumps(rec))
            ck = {"model": net.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
                  "epoch": epoch + 1, "best": best, "bad_epochs": bad, "gamma": gamma, "rng": [rng_states()],
                  "config": args.config, "stateful": stateful, "hidden": net.hidden, "args": vars(args),
                  "uncertainty": net.uncertainty, "radar_input": net.radar_input,
                  "preprocess": train.preprocess, "norm": train.norm, "val_ate_m": m["val_ate_rmse_m"],
                  "params": count_params(net)}
            save(out / "last.pt", ck)
            if improved:
                save(out / "best.pt", ck)
            over_budget = args.time_budget_min is not None and time.time() - started > 60 * args.time_budget_min
            decision = [bad >= args.patience, over_budget]
            if decision[0]:
                log(f"early stop: no {key} improvement in {args.patience} epochs (best {best:.4g})")
            if decision[1]:
                log(f"time budget {args.time_budget_min} min exceeded: stopping after epoch {epoch + 1}")
        if world > 1:
            dist.broadcast_object_list(decision, src=0)
        stop = any(decision)
    if world > 1:
        dist.barrier()
        dist.destroy_process_group()
    return 0


if __name__ == "__main__":
    sys.exit(main())
