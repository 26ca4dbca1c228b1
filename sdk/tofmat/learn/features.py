# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The learned model's input features, in NumPy: what the ONNX graph's first nodes compute from a
raw query and the table's curves (:mod:`.export` builds the same steps as ONNX operators; tests
check they agree).

A query (R rows x B bins, NaN = missing) is compared with every material's curve, row by row, over
the elements both have, the way the exemplar matchers compare it; the network learns how to weigh
what it finds. Per material and row:

- ``log(1 + v)``, v the variance of the differences about their mean: how well the curve's shape
  fits, whatever the session's offset of that row;
- ``d / 5 mm``, the mean difference: the row's offset if this were the material (a session moves
  it by a few mm; a wrong material by more);
- ``n / bins``, the elements compared over the sweep's bins: how much of the sweep the curve covers.

And for the sweep: the log of its bins, and its centroid as a fraction of the table's bins.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]

OFFSET_SCALE_MM = 5.0


def n_features(materials: int, rows: int) -> int:
    return 3 * materials * rows + 2


def features(queries: npt.ArrayLike, exemplars: npt.ArrayLike, chunk: int = 2048) -> F32:
    """(N, 3 x M x R + 2) float32 features of N queries (each R x B, any shape that flattens to
    it) against the M exemplar curves (M, R, B), NaN = missing in both."""
    t = np.asarray(exemplars, dtype=np.float32)
    _, rows, bins = t.shape
    q = np.asarray(queries, dtype=np.float32).reshape(-1, rows, bins)
    if len(q) > chunk:
        return np.concatenate([features(q[i : i + chunk], t, chunk) for i in range(0, len(q), chunk)])
    t_mask = np.isfinite(t).astype(np.float32)
    t_val = np.where(t_mask > 0, t, np.float32(0.0))
    q_mask = np.isfinite(q).astype(np.float32)
    q_val = np.where(q_mask > 0, q, np.float32(0.0))
    both = q_mask[:, None] * t_mask[None]  # (N, M, R, B)
    diff = (q_val[:, None] - t_val[None]) * both
    n = both.sum(axis=3, dtype=np.float32)
    n1 = np.maximum(n, np.float32(1.0))
    d = diff.sum(axis=3, dtype=np.float32) / n1
    v = np.square((diff - d[..., None]) * both).sum(axis=3, dtype=np.float32) / n1
    cover = q_mask.max(axis=1)  # (N, B): a bin with any observed row
    nb = np.maximum(cover.sum(axis=1, dtype=np.float32), np.float32(1.0))
    centroid = (cover * np.arange(bins, dtype=np.float32)).sum(axis=1, dtype=np.float32) / nb / np.float32(bins)
    out = np.concatenate(
        [
            np.log(v + np.float32(1.0)).reshape(len(q), -1),
            (d / np.float32(OFFSET_SCALE_MM)).reshape(len(q), -1),
            (n / nb[:, None, None]).reshape(len(q), -1),
            np.log(nb)[:, None],
            centroid[:, None],
        ],
        axis=1,
    )
    return out.astype(np.float32)
