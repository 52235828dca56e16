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


def test_uncertainty_head_learns_deviations_without_touching_the_poses(datasets, tmp_path):
    """--uncertainty trains the poses exactly as without it (the head reads a detached input and its
    loss uses detached errors), and exports pose_std; --init-onnx --train-only std adds the head to an
    exported model, trains it alone and keeps every pose."""
    import numpy as np
    import onnx

    from milliego_models.export import example_inputs, load_checkpoint
    from milliego_models.onnx_utils import get_metadata, ort_session
    plain, unc = tmp_path / "plain", tmp_path / "unc"
    run_train(*datasets, plain, "--epochs", "2", "--seed", "4")
    run_train(*datasets, unc, "--epochs", "2", "--seed", "4", "--uncertainty")
    wp = torch.load(plain / "last.pt", weights_only=False)["model"]
    wu = torch.load(unc / "last.pt", weights_only=False)["model"]
    assert {k for k in wu if not k.startswith("std_head.")} == set(wp)
    for k in wp:
        torch.testing.assert_close(wu[k], wp[k], msg=f"the uncertainty head changed the pose path at {k}")
    m = metrics(unc)
    assert all(k in m[-1] for k in ("train_nll", "val_nll", "val_z2_trans", "val_z2_rot", "val_std_err_rank_corr"))
    assert m[-1]["train_nll"] < m[0]["train_nll"], m  # the head learns (it starts at deviation 1 m / 1 deg)

    fp32 = tmp_path / "m.onnx"
    r = subprocess.run([PYTHON, "-m", "milliego_models.export", "--checkpoint", str(unc / "best.pt"), "--out", str(fp32)],
                       env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    model = onnx.load(fp32)
    assert [o.name for o in model.graph.output] == ["pose", "state_out", "pose_std"]
    assert "pose_std" in get_metadata(model)
    net, _ = load_checkpoint(str(unc / "best.pt"))
    radar, imu, state = (t.numpy() for t in example_inputs(net))
    pose, _, std = ort_session(str(fp32)).run(None, {"radar": radar, "imu": imu, "state": state})
    assert std.shape == (1, 6) and np.all(std > 0) and np.all(np.isfinite(std))

    # Head only, from the exported plain model: poses identical, deviations trained.
    plain_onnx = tmp_path / "plain.onnx"
    subprocess.run([PYTHON, "-m", "milliego_models.export", "--checkpoint", str(plain / "best.pt"), "--out",
                    str(plain_onnx)], env=subprocess_env(), capture_output=True, text=True, timeout=300, check=True)
    head = tmp_path / "head"
    r = run_train(*datasets, head, "--epochs", "2", "--uncertainty", "--init-onnx", plain_onnx, "--train-only", "std")
    assert "initialised from" in r.stdout
    wh = torch.load(head / "last.pt", weights_only=False)["model"]
    wb = torch.load(plain / "best.pt", weights_only=False)["model"]
    for k in wb:  # the folded first convolution comes back spread over the copies: same function
        if k != "convs.0.weight":
            torch.testing.assert_close(wh[k], wb[k], msg=f"--train-only std changed {k}")
    assert any(not torch.equal(wh[k], torch.zeros_like(wh[k])) for k in wh if k.startswith("std_head.2"))
    mh = metrics(head)
    plain_best = torch.load(plain / "best.pt", weights_only=False)["val_ate_m"]
    assert all(m["val_ate_rmse_m"] == pytest.approx(plain_best, rel=1e-4) for m in mh)
    head_onnx = tmp_path / "head.onnx"
    subprocess.run([PYTHON, "-m", "milliego_models.export", "--checkpoint", str(head / "best.pt"), "--out",
                    str(head_onnx)], env=subprocess_env(), capture_output=True, text=True, timeout=300, check=True)
    feed = {"radar": radar, "imu": imu, "state": np.zeros_like(state)}
    p0 = ort_session(str(plain_onnx)).run(["pose"], feed)[0]
    p1, s1 = ort_session(str(head_onnx)).run(["pose", "pose_std"], feed)
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-5)
    assert np.all(s1 > 0)
    # Without --uncertainty the head cannot be trained alone.
    r = run_train(*datasets, tmp_path / "bad", "--epochs", "1", "--train-only", "std", check=False)
    assert r.returncode != 0 and "needs --uncertainty" in r.stderr
