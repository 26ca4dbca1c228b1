# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A trained MLP as an ONNX model with the tofmat model contract (:mod:`.model`), written with the
``onnx`` package's helper API: the table's curves, the features of :mod:`.features`, the
standardisation and the network's layers are all in the graph, so a model's user feeds it the raw
query, as tofmatd does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._extras import require
from .features import OFFSET_SCALE_MM, features
from .model import INPUT, OUTPUT, ModelContract

OPSET = 17
F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Network:
    """A ReLU MLP with a softmax output over the features of :mod:`.features` (against
    ``exemplars``, the table's curves), standardised by (f - mean) / scale."""

    exemplars: F32  # (M, R, B), NaN = missing
    mean: F64  # (F,)
    scale: F64  # (F,)
    weights: Sequence[F64]  # each (in, out)
    biases: Sequence[F64]  # each (out,)

    @classmethod
    def from_sklearn(cls, mlp: Any, exemplars: F32, mean: F64, scale: F64) -> Network:
        """From a fitted sklearn ``MLPClassifier`` (relu hidden layers, classes 0..M-1)."""
        if mlp.activation != "relu":
            raise ValueError("only relu networks are exported")
        classes = np.asarray(mlp.classes_)
        if not np.array_equal(classes, np.arange(classes.size)):
            raise ValueError("the network must have seen every material (classes 0..M-1)")
        return cls(
            np.asarray(exemplars, dtype=np.float32),
            mean,
            scale,
            [np.asarray(w) for w in mlp.coefs_],
            [np.asarray(b) for b in mlp.intercepts_],
        )

    def probabilities(self, queries: npt.ArrayLike) -> F64:
        """The reference in NumPy (features in float32 as the graph computes them, the network in
        float64): what the exported graph must reproduce."""
        h = (features(queries, self.exemplars).astype(np.float64) - self.mean) / self.scale
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = h @ w + b
            if i < len(self.weights) - 1:
                h = np.maximum(h, 0.0)
        h = h - h.max(axis=1, keepdims=True)
        e = np.exp(h)
        return np.asarray(e / e.sum(axis=1, keepdims=True), dtype=np.float64)


def to_onnx(net: Network, contract: ModelContract, doc: str = "") -> bytes:
    """The serialised ONNX model (opset 17)."""
    onnx: Any = require("onnx", extra="learn", feature="tofmat train")
    from onnx import TensorProto, helper, numpy_helper

    rows, bins = contract.rows, contract.bins[2]
    elements = rows * bins

    def const(name: str, value: npt.ArrayLike, dtype: type = np.float32) -> Any:
        return numpy_helper.from_array(np.asarray(value, dtype=dtype), name)

    t = np.asarray(net.exemplars, dtype=np.float32)
    m = t.shape[0]
    if t.shape != (len(contract.materials), rows, bins):
        raise ValueError(
            f"the network's exemplars are {t.shape}, the contract's table {(len(contract.materials), rows, bins)}"
        )
    t_mask = np.isfinite(t).astype(np.float32)
    inits = [
        const("zero", 0.0),
        const("one", 1.0),
        const("offset_scale", OFFSET_SCALE_MM),
        const("bin_count", float(bins)),
        const("bin_index", np.arange(bins, dtype=np.float32)),
        const("exemplar_values", np.where(t_mask > 0, t, 0.0)[None]),  # (1, M, R, B)
        const("exemplar_mask", t_mask[None]),
        const("shape_query", [-1, 1, rows, bins], np.int64),
        const("shape_flat", [-1, m * rows], np.int64),
        const("axis1", [1], np.int64),
        const("axis2", [2], np.int64),
        const("axis3", [3], np.int64),
        const("mean", net.mean),
        const("inv_scale", 1.0 / np.asarray(net.scale)),
    ]
    n = helper.make_node
    nodes = [
        # the query's values and mask, (N, 1, R, B)
        n("IsNaN", [INPUT], ["missing"]),
        n("Not", ["missing"], ["observed"]),
        n("Cast", ["observed"], ["q_mask2"], to=TensorProto.FLOAT),
        n("Where", ["missing", "zero", INPUT], ["q_val2"]),
        n("Reshape", ["q_val2", "shape_query"], ["q_val"]),
        n("Reshape", ["q_mask2", "shape_query"], ["q_mask"]),
        # against every exemplar, (N, M, R, B) -> (N, M, R)
        n("Mul", ["q_mask", "exemplar_mask"], ["both"]),
        n("Sub", ["q_val", "exemplar_values"], ["diff0"]),
        n("Mul", ["diff0", "both"], ["diff"]),
        n("ReduceSum", ["both", "axis3"], ["count"], keepdims=0),
        n("Max", ["count", "one"], ["count1"]),
        n("ReduceSum", ["diff", "axis3"], ["diff_sum"], keepdims=0),
        n("Div", ["diff_sum", "count1"], ["offset"]),
        n("Unsqueeze", ["offset", "axis3"], ["offset4"]),
        n("Sub", ["diff", "offset4"], ["resid0"]),
        n("Mul", ["resid0", "both"], ["resid"]),
        n("Mul", ["resid", "resid"], ["resid_sq"]),
        n("ReduceSum", ["resid_sq", "axis3"], ["resid_sum"], keepdims=0),
        n("Div", ["resid_sum", "count1"], ["variance"]),
        n("Add", ["variance", "one"], ["variance1"]),
        n("Log", ["variance1"], ["f_shape"]),
        n("Div", ["offset", "offset_scale"], ["f_offset"]),
        # the sweep: bins with any observed row, (N, B)
        n("ReduceMax", ["q_mask"], ["cover4"], axes=[2], keepdims=0),  # (axes an attribute up to opset 17)
        n("Reshape", ["cover4", "shape_bins"], ["cover"]),
        n("ReduceSum", ["cover", "axis1"], ["nb0"], keepdims=1),
        n("Max", ["nb0", "one"], ["nb"]),
        n("Unsqueeze", ["nb", "axis2"], ["nb3"]),
        n("Div", ["count", "nb3"], ["f_cover"]),
        n("Log", ["nb"], ["f_bins"]),
        n("Mul", ["cover", "bin_index"], ["cover_index"]),
        n("ReduceSum", ["cover_index", "axis1"], ["index_sum"], keepdims=1),
        n("Div", ["index_sum", "nb"], ["centroid0"]),
        n("Div", ["centroid0", "bin_count"], ["f_centroid"]),
        n("Reshape", ["f_shape", "shape_flat"], ["f_shape2"]),
        n("Reshape", ["f_offset", "shape_flat"], ["f_offset2"]),
        n("Reshape", ["f_cover", "shape_flat"], ["f_cover2"]),
        n("Concat", ["f_shape2", "f_offset2", "f_cover2", "f_bins", "f_centroid"], ["features"], axis=1),
        n("Sub", ["features", "mean"], ["features0"]),
        n("Mul", ["features0", "inv_scale"], ["h0"]),
    ]
    inits.append(const("shape_bins", [-1, bins], np.int64))
    h = "h0"
    for i, (w, b) in enumerate(zip(net.weights, net.biases, strict=True)):
        inits += [const(f"w{i}", w), const(f"b{i}", b)]
        nodes += [n("MatMul", [h, f"w{i}"], [f"mm{i}"]), n("Add", [f"mm{i}", f"b{i}"], [f"z{i}"])]
        h = f"z{i}"
        if i < len(net.weights) - 1:
            nodes.append(n("Relu", [h], [f"a{i}"]))
            h = f"a{i}"
    nodes.append(n("Softmax", [h], [OUTPUT], axis=1))
    graph = helper.make_graph(
        nodes,
        "tofmat_mlp",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["batch", elements])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["batch", m])],
        initializer=inits,
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="tofmat", doc_string=doc
    )
    model.ir_version = 8  # what onnxruntime 1.21 (the oldest tofmatd runs with) reads
    helper.set_model_props(model, contract.metadata())
    onnx.checker.check_model(model)
    return bytes(model.SerializeToString())
