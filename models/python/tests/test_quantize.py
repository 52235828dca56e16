import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from milliego_models.onnx_utils import ort_session
from milliego_models.quantize import pad_narrow_convs, small_matmuls, split_concat_matmuls


def _chain(tmp_path, widths=(3, 4, 5), act="LeakyRelu", extra_consumer=False):
    """x -> Conv(w0 -> w1, 3x3) -> act -> Conv(w1 -> w2, 3x3) -> MatMul(8 x 6) -> y."""
    rng = np.random.default_rng(0)
    w0 = rng.normal(size=(widths[1], widths[0], 3, 3)).astype(np.float32)
    b0 = rng.normal(size=widths[1]).astype(np.float32)
    w1 = rng.normal(size=(widths[2], widths[1], 3, 3)).astype(np.float32)
    m = rng.normal(size=(8, 6)).astype(np.float32)
    nodes = [
        helper.make_node("Conv", ["x", "w0", "b0"], ["c0"], name="conv0", pads=[1, 1, 1, 1]),
        helper.make_node(act, ["c0"], ["a0"], name="act0"),
        helper.make_node("Conv", ["a0", "w1"], ["c1"], name="conv1", pads=[1, 1, 1, 1]),
        helper.make_node("MatMul", ["c1", "m"], ["y"], name="mm"),
    ]
    outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)]
    if extra_consumer:
        outputs.append(helper.make_tensor_value_info("a0", TensorProto.FLOAT, None))
    graph = helper.make_graph(
        nodes, "chain", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, widths[0], 8, 8])],
        outputs, [numpy_helper.from_array(a, n) for a, n in ((w0, "w0"), (b0, "b0"), (w1, "w1"), (m, "m"))])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    path = tmp_path / "chain.onnx"
    onnx.save(model, path)
    return model, path


def _weights(model):
    return {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}


def test_narrow_conv_is_widened_without_changing_values(tmp_path):
    for act in ("LeakyRelu", "Relu"):
        model, path = _chain(tmp_path, act=act)
        x = {"x": np.random.default_rng(1).normal(size=(1, 3, 8, 8)).astype(np.float32)}
        before = ort_session(str(path)).run(None, x)[0]
        assert pad_narrow_convs(model) == ["conv0"]
        w = _weights(model)
        assert w["w0"].shape == (16, 3, 3, 3) and w["b0"].shape == (16,) and w["w1"].shape == (5, 16, 3, 3)
        assert not w["w0"][4:].any() and not w["b0"][4:].any() and not w["w1"][:, 4:].any()
        wide = tmp_path / "wide.onnx"
        onnx.save(model, wide)
        # fp32 sums over more (zero) terms in another order: equal to rounding. In int8 the added
        # products are exact zeros (the shipped compact int8 file gives identical outputs).
        np.testing.assert_allclose(ort_session(str(wide)).run(None, x)[0], before, rtol=1e-5, atol=1e-5)


def test_widening_leaves_convs_it_cannot_prove_equivalent(tmp_path):
    # Already 16 wide, its output read elsewhere too (a graph output), or no Conv behind it.
    for widths, extra in (((3, 16, 5), False), ((3, 4, 5), True)):
        model, _ = _chain(tmp_path, widths=widths, extra_consumer=extra)
        assert pad_narrow_convs(model) == []
    model, _ = _chain(tmp_path, widths=(3, 4, 5))
    # conv1 (5 outputs) feeds a MatMul, not a Conv: only conv0 qualifies.
    assert pad_narrow_convs(model) == ["conv0"]


def test_small_matmuls_are_listed_by_weight_size(tmp_path):
    model, _ = _chain(tmp_path)
    assert small_matmuls(model, 49) == ["mm"]  # 8 x 6 = 48 weights
    assert small_matmuls(model, 48) == []


def _concat_matmul(tmp_path, axis=-1, concat_is_output=False):
    """a [2,3], b [2,5] -> Concat(axis) -> MatMul(8 x 4) -> y."""
    w = np.random.default_rng(2).normal(size=(8, 4)).astype(np.float32)
    shapes = ([2, 3], [2, 5]) if axis in (-1, 1) else ([3, 8], [5, 8])
    nodes = [helper.make_node("Concat", ["a", "b"], ["ab"], name="cat", axis=axis),
             helper.make_node("MatMul", ["ab", "w"], ["y"], name="mm")]
    outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, [shapes[0][0], 4])]
    if concat_is_output:
        outputs.append(helper.make_tensor_value_info("ab", TensorProto.FLOAT, [2, 8]))
    graph = helper.make_graph(
        nodes, "cat", [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in zip("ab", shapes)],
        outputs, [numpy_helper.from_array(w, "w")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    path = tmp_path / "cat.onnx"
    onnx.save(model, path)
    feeds = {n: np.random.default_rng(3).normal(size=s).astype(np.float32) for n, s in zip("ab", shapes)}
    return model, path, feeds


def test_a_matmul_of_a_concat_is_split_per_input_without_changing_values(tmp_path):
    for axis, as_output in ((-1, False), (1, False), (1, True)):
        model, path, feeds = _concat_matmul(tmp_path, axis, as_output)
        before = ort_session(str(path)).run(None, feeds)
        assert split_concat_matmuls(model) == ["mm"]
        ops = [n.op_type for n in model.graph.node]
        # The Concat stays only where something else reads it (here: a graph output).
        assert ops == (["Concat"] if as_output else []) + ["MatMul", "MatMul", "Add"]
        w = _weights(model)
        assert "w" not in w and w["w.part0"].shape == (3, 4) and w["w.part1"].shape == (5, 4)
        assert small_matmuls(model, 13) == ["mm.part0"]  # each part is judged by its own size
        onnx.checker.check_model(model)
        split = tmp_path / "split.onnx"
        onnx.save(model, split)
        after = ort_session(str(split)).run(None, feeds)
        np.testing.assert_allclose(after[0], before[0], rtol=1e-6, atol=1e-6)
        if as_output:
            np.testing.assert_array_equal(after[1], before[1])


def test_a_concat_along_another_axis_is_left_alone(tmp_path):
    model, _, _ = _concat_matmul(tmp_path, axis=0)
    assert split_concat_matmuls(model) == []
    assert [n.op_type for n in model.graph.node] == ["Concat", "MatMul"]


def test_a_concat_of_three_is_summed_in_a_chain(tmp_path):
    w = np.random.default_rng(4).normal(size=(10, 4)).astype(np.float32)
    shapes = ([2, 3], [2, 5], [2, 2])
    graph = helper.make_graph(
        [helper.make_node("Concat", ["a", "b", "c"], ["abc"], name="cat", axis=1),
         helper.make_node("MatMul", ["abc", "w"], ["y"], name="mm")], "cat3",
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in zip("abc", shapes)],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [2, 4])], [numpy_helper.from_array(w, "w")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    feeds = {n: np.random.default_rng(5).normal(size=s).astype(np.float32) for n, s in zip("abc", shapes)}
    onnx.save(model, tmp_path / "cat3.onnx")
    before = ort_session(str(tmp_path / "cat3.onnx")).run(None, feeds)[0]
    assert split_concat_matmuls(model) == ["mm"]
    assert [n.op_type for n in model.graph.node] == ["MatMul", "MatMul", "Add", "MatMul", "Add"]
    onnx.save(model, tmp_path / "split3.onnx")
    after = ort_session(str(tmp_path / "split3.onnx")).run(None, feeds)[0]
    np.testing.assert_allclose(after, before, rtol=1e-6, atol=1e-6)
