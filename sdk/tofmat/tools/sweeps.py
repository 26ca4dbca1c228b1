# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Hand-held sweeps simulated from real curves.

Until the physical simulator lands, a "sweep" is a window of consecutive depth
bins of one material's real curve with Gaussian noise added: the partial
feature vector a user builds by moving a target through part of the range.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import ExemplarTable


@dataclass(frozen=True)
class Window:
    material: int  # index into table.materials
    start: int  # first bin
    length: int  # bins covered
    query: npt.NDArray[np.float32]  # n_rows x n_bins, NaN outside the window


def window_query(
    curve: npt.NDArray[np.float32], start: int, length: int, noise_mm: float, rng: np.random.Generator
) -> npt.NDArray[np.float32]:
    """The curve's bins [start, start + length) plus N(0, noise_mm) noise; NaN elsewhere."""
    n_rows, n_bins = curve.shape
    if not 0 <= start < n_bins or length < 1 or start + length > n_bins:
        raise ValueError(f"window [{start}, {start + length}) does not fit in {n_bins} bins")
    q = np.full((n_rows, n_bins), np.nan, dtype=np.float32)
    part = curve[:, start : start + length]
    q[:, start : start + length] = part + rng.normal(0.0, noise_mm, part.shape)
    return q


def window_starts(table: ExemplarTable, m: int, length: int) -> npt.NDArray[np.int64]:
    """Starts of the windows of ``length`` bins holding at least one observed element of material m."""
    observed = np.isfinite(table.features[m]).any(axis=0).astype(np.int64)
    in_window = np.convolve(observed, np.ones(length, dtype=np.int64), mode="valid")
    return np.flatnonzero(in_window > 0)


def random_windows(
    table: ExemplarTable, length: int, noise_mm: float, per_material: int, rng: np.random.Generator
) -> Iterator[Window]:
    """`per_material` windows of `length` bins at random positions for every material.

    Only windows holding at least one observed element of the curve are drawn
    (a hand-held sweep over bins the material was never measured in has nothing
    to classify); a material with no such window yields none.
    """
    features = table.features
    n_bins = table.n_bins
    if not 1 <= length <= n_bins:
        raise ValueError(f"window length must be 1..{n_bins}, got {length}")
    for m in range(len(table.materials)):
        starts = window_starts(table, m, length)
        if starts.size == 0:
            continue
        for _ in range(per_material):
            start = int(starts[rng.integers(0, starts.size)])
            yield Window(m, start, length, window_query(features[m], start, length, noise_mm, rng))
