import os
import sys
from pathlib import Path

import pytest
import torch

PKG_ROOT = Path(__file__).resolve().parents[1]
torch.set_num_threads(1)  # the test machine's 2 cores are shared; >1 thread oversubscribes badly


def subprocess_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(PKG_ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["OMP_NUM_THREADS"] = "1"
    env["PYTHONWARNINGS"] = "ignore"
    return env


@pytest.fixture(scope="session")
def datasets(tmp_path_factory):
    """(train_dir, val_dir): tiny synthetic datasets in the `milliego dataset build` format."""
    from milliego_models.synthetic import write_synthetic_dataset
    root = tmp_path_factory.mktemp("data")
    train = write_synthetic_dataset(root / "train", [("syn-a", 90), ("syn-b", 70)], seed=1)
    val = write_synthetic_dataset(root / "val", [("syn-v", 60)], seed=2)
    return train, val


PYTHON = sys.executable


def run_train(train, val, out, *extra, check=True):
    import subprocess
    cmd = [PYTHON, "-m", "milliego_models.train", "--data", str(train), "--val", str(val), "--config", "tiny",
           "--out", str(out), "--batch", "16", "--threads", "1", *map(str, extra)]
    r = subprocess.run(cmd, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    if check:
        assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r


@pytest.fixture(scope="session")
def stateful_run(datasets, tmp_path_factory):
    """A 1-epoch stateful tiny run directory (best.pt, last.pt, metrics.jsonl)."""
    out = tmp_path_factory.mktemp("run") / "stateful"
    run_train(*datasets, out, "--mode", "stateful", "--seq-len", "4", "--batch", "4", "--epochs", "1")
    return out
