import json
import shutil
import subprocess
from pathlib import Path

import pytest
import torch

from conftest import PYTHON, run_train, subprocess_env


def metrics(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]


def test_train_resume_continues_and_matches_uninterrupted(datasets, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    run_train(*datasets, a, "--epochs", "1", "--seed", "3")
    assert (a / "best.pt").exists() and (a / "last.pt").exists()
    assert [m["epoch"] for m in metrics(a)] == [1]
    r = run_train(*datasets, a, "--epochs", "2", "--seed", "3", "--resume")
    assert "resumed from" in r.stdout
    assert [m["epoch"] for m in metrics(a)] == [1, 2]
    assert torch.load(a / "last.pt", weights_only=False)["epoch"] == 2
    m = metrics(a)[-1]
    assert m["val_ate_rmse_m"] > 0 and m["gamma"] > 0
    run_train(*datasets, b, "--epochs", "2", "--seed", "3")
    wa = torch.load(a / "last.pt", weights_only=False)["model"]
    wb = torch.load(b / "last.pt", weights_only=False)["model"]
    for k in wa:
        torch.testing.assert_close(wa[k], wb[k], msg=f"resumed run diverged at {k}")


def test_stateful_training_writes_checkpoint(stateful_run):
    ck = torch.load(stateful_run / "best.pt", weights_only=False)
    assert ck["stateful"] and ck["config"] == "tiny" and ck["epoch"] == 1
    assert metrics(stateful_run)[0]["val_ate_rmse_m"] > 0


def test_time_budget_stops_after_first_epoch(datasets, tmp_path):
    r = run_train(*datasets, tmp_path / "t", "--epochs", "5", "--time-budget-min", "0")
    assert "time budget" in r.stdout
    assert [m["epoch"] for m in metrics(tmp_path / "t")] == [1]


def _torchrun():
    p = Path(PYTHON).parent / "torchrun"
    return str(p) if p.exists() else shutil.which("torchrun")


@pytest.mark.skipif(_torchrun() is None, reason="torchrun not installed next to this python or on PATH")
def test_torchrun_ddp_two_ranks(datasets, tmp_path):
    out = tmp_path / "ddp"
    cmd = [_torchrun(), "--standalone", "--nproc_per_node=2", "-m", "milliego_models.train",
           "--data", str(datasets[0]), "--val", str(datasets[1]), "--config", "tiny", "--out", str(out),
           "--epochs", "1", "--batch", "8", "--threads", "1"]
    r = subprocess.run(cmd, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert sorted(p.name for p in out.glob("*.pt")) == ["best.pt", "last.pt"]
    m = metrics(out)
    assert len(m) == 1 and m[0]["world"] == 2
