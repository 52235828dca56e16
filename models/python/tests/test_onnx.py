import json
import subprocess

import numpy as np
import onnx
import torch

from conftest import PKG_ROOT, PYTHON, subprocess_env
from milliego_models.data import load_dataset
from milliego_models.export import OPSET, example_inputs, load_checkpoint, make_metadata
from milliego_models.model import RADAR_COPIES
from milliego_models.onnx_utils import (ALLOWED_OPS, fold_constants, fold_copied_inputs, fold_pads_into_convs,
                                        get_metadata, nonzero_zero_points, ort_session, set_metadata)


PKG_MODEL = PKG_ROOT.parents[0] / "compact" / "model.onnx"


def run(*args):
    r = subprocess.run([PYTHON, "-m", *map(str, args)], env=subprocess_env(), capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r.stdout


def test_export_quantize_golden_roundtrip(stateful_run, datasets, tmp_path):
    fp32, int8, gold = tmp_path / "m.onnx", tmp_path / "m8.onnx", tmp_path / "golden.safetensors"
    out = run("milliego_models.export", "--checkpoint", stateful_run / "best.pt", "--out", fp32)
    assert "max abs diff" in out
    net, ck = load_checkpoint(str(stateful_run / "best.pt"))
    H = net.hidden

    model = onnx.load(fp32)
    assert [i.name for i in model.graph.input] == ["radar", "imu", "state"]
    assert [o.name for o in model.graph.output] == ["pose", "state_out"]
    dims = {v.name: [d.dim_value for d in v.type.tensor_type.shape.dim]
            for v in list(model.graph.input) + list(model.graph.output)}
    assert dims == {"radar": [1, 6, 64, 256], "imu": [1, 20, 6], "state": [1, 4, H], "pose": [1, 6],
                    "state_out": [1, 4, H]}
    ops = {n.op_type for n in model.graph.node}
    assert ops <= ALLOWED_OPS and "Gemm" not in ops and "LSTM" not in ops and "Pad" not in ops
    meta = get_metadata(model)
    assert meta["stateful"] is True and meta["trained"] is True and meta["precision"] == "fp32"
    assert meta["hidden"] == H and meta["config"] == "tiny" and meta["preprocess"]["gap"] == 5
    assert "norm" in meta and "label" in meta and meta["params"] > 0
    # The copied radar channels are folded: the first convolution reads one channel per copy group.
    assert meta["radar_copies_folded"] == ["/convs.0/Conv"]
    conv0 = next(n for n in model.graph.node if n.name == "/convs.0/Conv")
    w0 = next(i for i in model.graph.initializer if i.name == conv0.input[1])
    assert conv0.input[0] == "radar_folded_copies" and list(w0.dims[:2]) == [net.convs[0].out_channels, 2]

    # fp32 ONNX == PyTorch on a real window with a non-zero state.
    d = load_dataset(datasets[1])
    feed = {"radar": d.radar([3]), "imu": d.imu[[3]], "state": example_inputs(net)[2].numpy()}
    with torch.no_grad():
        ref = [t.numpy() for t in net(*(torch.from_numpy(feed[k]) for k in ("radar", "imu", "state")))]
    got = ort_session(str(fp32)).run(None, feed)
    for a, b in zip(ref, got):
        np.testing.assert_allclose(b, a, atol=1e-4, rtol=0)

    out = run("milliego_models.quantize", "--model", fp32, "--data", datasets[0], "--out", int8,
              "--calib-windows", "32")
    assert "max abs diff" in out
    q = onnx.load(int8)
    for n in q.graph.node:
        assert n.domain in ("", "ai.onnx"), n
        assert n.op_type in ALLOWED_OPS, n.op_type
    qops = {n.op_type for n in q.graph.node}
    # Default recipe: every convolution int8, dense layers and LSTMs fp32.
    assert {"QLinearConv", "QuantizeLinear", "DequantizeLinear"} <= qops
    assert "Conv" not in qops and "QLinearMatMul" not in qops and "MatMul" in qops
    # --ops conv+matmul quantizes the MatMuls too, except the one fed by the raw IMU window.
    int8mm = str(int8).replace(".onnx", "-mm.onnx")
    run("milliego_models.quantize", "--model", fp32, "--data", datasets[0], "--out", int8mm,
        "--calib-windows", "32", "--ops", "conv+matmul")
    qm = onnx.load(int8mm)
    mm = [n for n in qm.graph.node if n.op_type == "MatMul"]
    assert {n.op_type for n in qm.graph.node} >= {"QLinearConv", "QLinearMatMul"}
    assert mm and all("imu" in n.input for n in mm), [n.input for n in mm]
    assert nonzero_zero_points(q) == []
    zps = [i for i in q.graph.initializer if i.name.endswith("zero_point")]
    assert zps and all(onnx.numpy_helper.to_array(z).dtype == np.int8 for z in zps)
    qmeta = get_metadata(q)
    assert qmeta["precision"] == "int8" and qmeta["stateful"] is True
    # int8 vs fp32: symmetric s8 gives each quantized tensor a step of range/254; ~60 quantized
    # MatMul/Conv layers in series accumulate that to a few 1e-3 relative, so allow 0.02 + 5% of |pose|.
    # The state must be one the model really reaches (calibration saw those ranges), so run the chain.
    s32, s8 = ort_session(str(fp32)), ort_session(str(int8))
    state = np.zeros((1, 4, H), np.float32)
    for w in d.chains[0][:6]:
        f = {"radar": d.radar([w]), "imu": d.imu[[w]], "state": state}
        p32, state = s32.run(["pose", "state_out"], f)
        p8 = s8.run(["pose"], f)[0]
        assert np.abs(p8 - p32).max() <= 0.02 + 0.05 * np.abs(p32).max(), (p8, p32)

    out = run("milliego_models.golden", "--fp32", fp32, "--int8", int8, "--data", datasets[1], "--out", gold,
              "--windows", "3")
    from safetensors import safe_open
    with safe_open(str(gold), "numpy") as f:
        keys = set(f.keys())
        assert json.loads(f.metadata()["milliego"])["stateful"] is True
        assert f.get_tensor("window_pair").dtype == np.int64
        assert np.all(f.get_tensor("state_0") == 0)
        np.testing.assert_array_equal(f.get_tensor("state_1"), f.get_tensor("state_out_fp32_0"))
        assert not np.allclose(f.get_tensor("state_1"), 0)
        wp = f.get_tensor("window_pair")
        assert np.all(wp[1:, 0] == wp[:-1, 1])
    for k in range(3):
        for name in ("radar", "imu", "state", "pose_fp32", "state_out_fp32", "pose_int8", "state_out_int8"):
            assert f"{name}_{k}" in keys


def test_paper_graph_tiny_untrained(tmp_path):
    out = run("milliego_models.paper_graph", "--out", tmp_path, "--config", "tiny", "--seed", "5",
              "--calib-windows", "4")
    assert "UNTRAINED (random, seed 5)" in out and "seeded random inputs" in out
    meta = get_metadata(onnx.load(tmp_path / "milliego-tiny-int8.onnx"))
    assert meta["trained"] is False and meta["precision"] == "int8"


def conv_graph(group: int = 1) -> onnx.ModelProto:
    """x [1,6,9,11] -> Conv 3x3 stride 2 (4 output channels) -> Relu, plus a second reader of x."""
    from onnx import TensorProto, helper, numpy_helper
    rng = np.random.default_rng(3)
    w = rng.normal(size=(4, 6 // group, 3, 3)).astype(np.float32)
    b = rng.normal(size=4).astype(np.float32)
    nodes = [helper.make_node("Conv", ["x", "w", "b"], ["c"], kernel_shape=[3, 3], strides=[2, 2],
                              pads=[1, 1, 1, 1], group=group, name="conv"),
             helper.make_node("Relu", ["c"], ["y"]),
             helper.make_node("ReduceMean", ["x"], ["m"], keepdims=0)]
    g = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 6, 9, 11])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, 5, 6]),
                           helper.make_tensor_value_info("m", TensorProto.FLOAT, [])],
                          [numpy_helper.from_array(w, "w"), numpy_helper.from_array(b, "b")])
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", OPSET)])


def run_graph(model: onnx.ModelProto, x: np.ndarray) -> list[np.ndarray]:
    import onnxruntime as ort
    return ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"x": x})


def test_fold_copied_inputs_same_values_on_copies_only():
    rng = np.random.default_rng(0)
    images = rng.normal(size=(1, 2, 9, 11)).astype(np.float32)
    copies = np.concatenate([np.repeat(images[:, :1], 3, 1), np.repeat(images[:, 1:], 3, 1)], 1)
    model = conv_graph()
    before = run_graph(model, copies)
    assert fold_copied_inputs(model, "x", RADAR_COPIES) == ["conv"]
    onnx.checker.check_model(model)
    w = onnx.numpy_helper.to_array(next(i for i in model.graph.initializer if i.name == "w"))
    assert w.shape == (4, 2, 3, 3)
    after = run_graph(model, copies)
    for a, b in zip(before, after):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-5)
    # Only valid for copies: independent channels give other values (the pass trusts the interface).
    other = rng.normal(size=(1, 6, 9, 11)).astype(np.float32)
    assert np.abs(run_graph(conv_graph(), other)[0] - run_graph(model, other)[0]).max() > 0.1
    # Grouped convolutions are left alone; groups must partition the channels.
    grouped = conv_graph(group=2)
    assert fold_copied_inputs(grouped, "x", RADAR_COPIES) == []
    assert not any(n.op_type == "Gather" for n in grouped.graph.node)
    try:
        fold_copied_inputs(conv_graph(), "x", ((0, 1), (3, 4, 5)))
        raise AssertionError("a grouping that leaves channel 2 out was accepted")
    except ValueError as e:
        assert "partition" in str(e)


def test_reexport_folds_an_older_file(stateful_run, tmp_path):
    """`export --onnx` applies the graph passes to a file exported without the fold, same outputs."""
    net, ck = load_checkpoint(str(stateful_run / "best.pt"))
    old, new = tmp_path / "old.onnx", tmp_path / "new.onnx"
    args = example_inputs(net)
    torch.onnx.export(net, args, str(old), input_names=["radar", "imu", "state"],
                      output_names=["pose", "state_out"], opset_version=OPSET, dynamo=False)
    model = fold_pads_into_convs(fold_constants(onnx.load(old)))
    set_metadata(model, make_metadata(net, True, ck.get("preprocess"), ck.get("norm"), trained=True))
    onnx.save(model, old)
    out = run("milliego_models.export", "--onnx", old, "--out", new)
    assert "folded ['/convs.0/Conv']" in out
    diff = float(out.rsplit("max abs diff", 1)[1])
    assert diff < 1e-4, out
    meta = get_metadata(onnx.load(new))
    assert meta["radar_copies_folded"] == ["/convs.0/Conv"] and meta["config"] == "tiny"
    feed = {"radar": args[0].numpy(), "imu": args[1].numpy(), "state": args[2].numpy()}
    for a, b in zip(ort_session(str(old)).run(None, feed), ort_session(str(new)).run(None, feed)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-4)
    # A folded file is refused with the reason, not folded twice.
    r = subprocess.run([PYTHON, "-m", "milliego_models.export", "--onnx", str(new), "--out", str(tmp_path / "x.onnx")],
                       env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "already folded" in r.stderr, r.stderr


def test_fixtures_write_a_loadable_uncertainty_model(tmp_path):
    from safetensors.numpy import load_file
    out = run("milliego_models.fixtures", "--out", tmp_path)
    assert "tiny-uncertainty.onnx" in out
    model = onnx.load(tmp_path / "tiny-uncertainty.onnx")
    assert [o.name for o in model.graph.output] == ["pose", "state_out", "pose_std"]
    meta = get_metadata(model)
    ref = get_metadata(onnx.load(PKG_MODEL))
    assert meta["trained"] is False and meta["preprocess"] == ref["preprocess"] and meta["norm"] == ref["norm"]
    t = load_file(str(tmp_path / "tiny-uncertainty.safetensors"))
    feed = {"radar": np.zeros((1, 6, 64, 256), np.float32), "imu": t["imu"], "state": t["state"]}
    pose, std = ort_session(str(tmp_path / "tiny-uncertainty.onnx")).run(["pose", "pose_std"], feed)
    np.testing.assert_array_equal(pose, t["pose"])
    np.testing.assert_array_equal(std, t["pose_std"])
    assert np.all(std > 0) and np.ptp(std) > 0


def test_a_doppler_network_starts_as_the_depth_file_and_exports_with_its_layout(stateful_run, datasets, tmp_path):
    """--init-onnx of a depth file into a depth_doppler network: the same function whatever the Doppler
    channels hold (their weights start at zero); its export folds the depth copies only, says
    `radar_input`, and matches PyTorch on real Doppler windows; golden bundles carry the Doppler panoramas."""
    from milliego_models.model import MilliEgo
    from milliego_models.train import load_onnx_weights
    depth = tmp_path / "depth.onnx"
    run("milliego_models.export", "--checkpoint", stateful_run / "best.pt", "--out", depth)
    net = MilliEgo("tiny", radar_input="depth_doppler")
    load_onnx_weights(net, str(depth))
    net.eval()
    d = load_dataset(datasets[1])
    state = example_inputs(net)[2]
    plain = ort_session(str(depth)).run(None, {"radar": d.radar([3]), "imu": d.imu[[3]], "state": state.numpy()})
    d.radar_input = "depth_doppler"
    radar = d.radar([3])
    assert np.abs(radar[:, 1]).max() > 0.01  # the window has Doppler to ignore
    with torch.no_grad():
        pose, state_out = net(torch.from_numpy(radar), torch.from_numpy(d.imu[[3]]), state)
    np.testing.assert_allclose(pose.numpy(), plain[0], atol=1e-5, rtol=0)
    np.testing.assert_allclose(state_out.numpy(), plain[1], atol=1e-5, rtol=0)

    # Give the Doppler channels weight, then export: 4 folded channels, metadata, ORT == PyTorch.
    with torch.no_grad():
        net.convs[0].weight[:, [1, 4]] = torch.randn_like(net.convs[0].weight[:, [1, 4]])
    meta = make_metadata(net, True, get_metadata(onnx.load(depth))["preprocess"], d.norm, trained=True)
    from milliego_models.export import export_model
    plusd = tmp_path / "plusd.onnx"
    export_model(net, str(plusd), meta)
    model = onnx.load(plusd)
    assert get_metadata(model)["radar_input"] == "depth_doppler"
    conv0 = next(n for n in model.graph.node if n.name == "/convs.0/Conv")
    w0 = next(i for i in model.graph.initializer if i.name == conv0.input[1])
    assert list(w0.dims[:2]) == [net.convs[0].out_channels, 4]
    got = ort_session(str(plusd)).run(None, {"radar": radar, "imu": d.imu[[3]], "state": state.numpy()})
    with torch.no_grad():
        pose, _ = net(torch.from_numpy(radar), torch.from_numpy(d.imu[[3]]), state)
    np.testing.assert_allclose(got[0], pose.numpy(), atol=1e-4, rtol=0)
    assert np.abs(got[0] - plain[0]).max() > 1e-4, "the Doppler channels now count"
    # A depth_doppler file cannot initialise a depth network (its Doppler weights would be lost).
    try:
        load_onnx_weights(MilliEgo("tiny"), str(plusd))
        raise AssertionError("a depth network took a depth_doppler file's weights")
    except ValueError as e:
        assert "radar input" in str(e)

    int8, gold = tmp_path / "plusd8.onnx", tmp_path / "golden.safetensors"
    run("milliego_models.quantize", "--model", plusd, "--data", datasets[0], "--out", int8, "--calib-windows", "16")
    assert get_metadata(onnx.load(int8))["radar_input"] == "depth_doppler"
    run("milliego_models.golden", "--fp32", plusd, "--int8", int8, "--data", datasets[1], "--out", gold,
        "--windows", "2")
    from safetensors import safe_open
    with safe_open(str(gold), "numpy") as f:
        assert {"doppler_prev_0", "doppler_cur_1"} <= set(f.keys())
        assert np.abs(f.get_tensor("radar_0")[:, 1]).max() > 0
