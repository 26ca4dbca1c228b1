# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmat.tools: simulated sweeps (windows), the benchmark and the demo on the real database."""

from __future__ import annotations

import numpy as np
import pytest

import tofmat
from tofmat.tools.bench import bench_windows, format_markdown
from tofmat.tools.demo import run_demo
from tofmat.tools.sweeps import random_windows, window_query
from tofmat.tools.tables import open_table


def test_window_query_is_the_curve_plus_noise_inside_nan_outside(real_table, rng) -> None:
    curve = real_table.features[5]
    q = window_query(curve, 40, 10, 0.3, rng)
    assert q.shape == (2, 200) and q.dtype == np.float32
    assert np.isnan(q[:, :40]).all() and np.isnan(q[:, 50:]).all()
    noise = (q[:, 40:50] - curve[:, 40:50]).astype(np.float64)
    assert 0 < np.std(noise) < 1.0
    assert not np.isnan(q[:, 40:50]).any()
    # Without noise, the window is the curve exactly.
    np.testing.assert_array_equal(window_query(curve, 0, 200, 0.0, rng), curve)


@pytest.mark.parametrize("start, length", [(-1, 5), (200, 1), (195, 10), (0, 0), (0, 201)])
def test_window_query_rejects_windows_outside(real_table, rng, start, length) -> None:
    with pytest.raises(ValueError):
        window_query(real_table.features[0], start, length, 0.3, rng)


def test_random_windows_cover_every_material(real_table) -> None:
    ws = list(random_windows(real_table, 7, 0.3, 5, np.random.default_rng(3)))
    assert len(ws) == 5 * len(real_table)
    assert [w.material for w in ws] == [m for m in range(len(real_table)) for _ in range(5)]
    for w in ws:
        assert w.length == 7 and 0 <= w.start <= 200 - 7
        outside = np.ones(200, bool)
        outside[w.start : w.start + 7] = False
        assert np.isnan(w.query[:, outside]).all()
    # Fixed seed -> same windows.
    ws2 = list(random_windows(real_table, 7, 0.3, 5, np.random.default_rng(3)))
    assert all(
        a.start == b.start and np.array_equal(a.query, b.query, equal_nan=True) for a, b in zip(ws, ws2, strict=True)
    )
    with pytest.raises(ValueError):
        list(random_windows(real_table, 0, 0.3, 5, np.random.default_rng(3)))


def test_random_windows_are_classifiable(real_table) -> None:
    # A "sweep" must observe something: a window whose every element is missing in the real
    # curve (1-bin windows on paper/plaster/fakeapple's missing bins) is not a query at all, and
    # classify() raises on it. Seed 2 (what `tofmat bench --seed 1` uses for 1-bin windows),
    # 40 windows per material, hits such bins: paper at bins 3 and 4.
    ws = list(random_windows(real_table, 1, 0.3, 40, np.random.default_rng(2)))
    empty = [(real_table.materials[w.material], w.start) for w in ws if np.isnan(w.query).all()]
    assert empty == [], f"{len(empty)} windows with no valid element: {empty}"


def test_bench_windows_library(real_table) -> None:
    rows = bench_windows(real_table, [3, 30], noise_mm=0.3, per_material=4, seed=0)
    assert [r.window_bins for r in rows] == [3, 30]
    for r in rows:
        assert r.queries == 4 * len(real_table)
        assert 0.0 <= r.accuracy <= 1.0
        assert r.us_per_query > 0
    assert rows[1].accuracy >= 0.95  # measured 100 % (116 windows of 30 bins)
    text = format_markdown(rows, 0.3)
    assert "| float | 3 |" in text and "| float | 30 |" in text


def test_demo_reports_and_counts(real_table) -> None:
    lines: list[str] = []
    stats = run_demo(real_table, sweeps=4, sweep_bins=40, frames_per_bin=2, noise_mm=0.3, seed=1, echo=lines.append)
    assert stats.sweeps == 4
    assert 0 <= stats.correct_final <= 4
    assert stats.correct_final >= 3  # 40-bin sweeps: measured 4/4
    assert any(line.startswith("final labels:") for line in lines)
    with pytest.raises(ValueError):
        run_demo(real_table, 1, 0, 1, 0.3, 0, echo=lines.append)


def test_open_table_accepts_folder_and_file(db_dir, real_tmx) -> None:
    a = open_table(db_dir)
    b = open_table(real_tmx)
    assert a.materials == b.materials
    assert a.quant_step_mm == 0 and b.quant_step_mm > 0
    assert isinstance(a, tofmat.ExemplarTable)
