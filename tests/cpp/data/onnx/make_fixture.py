# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Writes the learned-classifier fixture of tests/cpp/test_onnx_classifier.cpp beside this file:

- tiny_mlp.onnx: a 16-unit network with seeded random weights for the real database's table (its
  curves in the graph),
  exported by tofmat.learn.export (its predictions mean nothing; the test checks that tofmatd's
  onnxruntime path computes what the NumPy reference does);
- queries.npy: (8, 400) float32 queries: windows of real curves of 1 to 200 bins, NaN elsewhere;
- expected.npy: (8, 29) float64, the reference network's probabilities for them;
- saturated.onnx: a network whose softmax gives material 0 everything (float32's exp underflows
  to 0 for the others), for the distances' bound;
- logits.onnx, nan.onnx, short.onnx: models tofmatd must refuse at load (its probe on each
  material's own curve): tiny_mlp without its softmax (values that are no probabilities), with a
  NaN bias (NaN out), and with one output fewer than the table's materials.

Usage: python3 make_fixture.py DB_DIR [OUT_DIR]. Deterministic: tests/python/test_learn.py checks
that it gives the committed files again (expected.npy to 1e-12: the last bit of NumPy's matrix
products depends on the CPU its BLAS kernel was chosen for).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import onnx

from tofmat.learn.export import OUTPUT, Network, to_onnx
from tofmat.learn.features import features, n_features
from tofmat.learn.model import ModelContract
from tofmat.tools.tables import open_table


def main(db: str, out: Path) -> None:
    table = open_table(db)
    rng = np.random.default_rng(20261126)
    rows, bins = table.n_rows, table.n_bins
    f = n_features(len(table.materials), rows)
    net = Network(
        exemplars=table.features.astype(np.float32),
        mean=rng.normal(0.0, 1.0, f),
        scale=rng.uniform(0.1, 2.0, f),
        weights=[rng.normal(0.0, 0.1, (f, 16)), rng.normal(0.0, 0.05, (16, len(table.materials)))],
        biases=[rng.normal(0.0, 0.1, 16), rng.normal(0.0, 0.1, len(table.materials))],
    )
    queries = []
    for i, length in enumerate((1, 2, 5, 17, 40, 99, 150, 200)):
        m = (7 * i + 3) % len(table.materials)
        q = np.full((rows, bins), np.nan, dtype=np.float32)
        start = (13 * i) % (bins - length + 1)
        q[:, start : start + length] = table.features[m][:, start : start + length]
        if not np.isfinite(q).any():  # a window the curve never reached: one element of its own
            q[0, start] = 5.0
        queries.append(q.reshape(-1))
    qs = np.stack(queries)
    assert features(qs, table.features).shape == (len(qs), f)
    out.mkdir(parents=True, exist_ok=True)
    (out / "tiny_mlp.onnx").write_bytes(to_onnx(net, ModelContract.of_table(table), doc="tofmat test fixture"))
    np.save(out / "queries.npy", qs)
    np.save(out / "expected.npy", net.probabilities(qs))
    m = len(table.materials)
    bias = np.zeros(m)
    bias[0] = 200.0
    saturated = Network(net.exemplars, net.mean, net.scale, [np.zeros((f, 4)), np.zeros((4, m))], [np.zeros(4), bias])
    (out / "saturated.onnx").write_bytes(to_onnx(saturated, ModelContract.of_table(table), doc="tofmat test fixture"))
    contract = ModelContract.of_table(table)
    nan_bias = [b.copy() for b in net.biases]
    nan_bias[-1][2] = np.nan
    nan = Network(net.exemplars, net.mean, net.scale, net.weights, nan_bias)
    (out / "nan.onnx").write_bytes(to_onnx(nan, contract, doc="tofmat test fixture"))
    short = Network(net.exemplars, net.mean, net.scale, [net.weights[0], net.weights[1][:, :-1]],
                    [net.biases[0], net.biases[1][:-1]])  # fmt: skip
    model = onnx.load_from_string(to_onnx(net, contract, doc="tofmat test fixture"))
    softmax = model.graph.node[-1]
    assert softmax.op_type == "Softmax"
    model.graph.node.remove(softmax)
    model.graph.node[-1].output[0] = OUTPUT  # (the logits are the output)
    (out / "logits.onnx").write_bytes(model.SerializeToString())
    model = onnx.load_from_string(to_onnx(short, contract, doc="tofmat test fixture"))
    model.graph.output[0].type.tensor_type.shape.dim[1].dim_value = m - 1
    (out / "short.onnx").write_bytes(model.SerializeToString())


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]) if len(sys.argv) > 2 else Path(__file__).parent)
