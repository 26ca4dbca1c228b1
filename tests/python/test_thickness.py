# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A slab's thickness from its rows (sim/thickness.py): the model inverted on its own curves, on
rendered sweeps (tofmat bench-thickness), the interval's honesty where the rows stop telling, and
`tofmat thickness` on query files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tofmat.sim import load_device, load_library
from tofmat.sim.table import database_bins
from tofmat.sim.thickness import ThicknessEstimator, slab_materials, slab_params
from tofmat.tools.thickness_bench import bench_thickness, sweep_rows, window


@pytest.fixture(scope="module")
def estimator() -> ThicknessEstimator:
    return ThicknessEstimator(load_device(), load_library(), "acryl3mm", database_bins())


def test_the_model_curves_invert_to_their_thickness(estimator: ThicknessEstimator) -> None:
    rng = np.random.default_rng(4)
    for k in (8, 37, 58, 90):  # 0.5, 1.95, 3.0, 4.6 mm: grid points
        t = float(estimator.grid[k])
        rows = estimator.curves[k] + rng.normal(0.0, 0.2, estimator.curves[k].shape)  # a sweep's noise
        e = estimator.estimate(rows)
        assert abs(e.thickness_mm - t) < 0.03 and e.low_mm <= t <= e.high_mm and not e.open_above, (t, e)
        assert 0.1 < e.residual_mm < 0.3 and e.values == int(np.isfinite(rows).sum())
        # Another session's row offsets: wrong without fitting them, right with.
        shifted = rows + np.array([[3.0], [-2.0]])
        assert abs(estimator.estimate(shifted, offsets=True).thickness_mm - t) < 0.05
        assert estimator.estimate(shifted).residual_mm > 2.0


def test_between_grid_points_the_parabola_refines(estimator: ThicknessEstimator) -> None:
    mid = 0.5 * (estimator.curves[40] + estimator.curves[41])  # halfway between 2.05 and 2.1 mm, near enough
    e = estimator.estimate(mid)
    assert estimator.grid[40] < e.thickness_mm < estimator.grid[41]


def test_a_thick_slab_is_at_least_what_its_rows_tell(estimator: ThicknessEstimator) -> None:
    k = int(np.searchsorted(estimator.grid, 10.0))
    rng = np.random.default_rng(5)
    e = estimator.estimate(estimator.curves[k] + rng.normal(0.0, 0.2, estimator.curves[k].shape))
    assert e.open_above and 5.0 < e.low_mm < 10.0, e  # the interval holds 10 mm and all thicker


def test_bad_inputs_are_clear_errors(estimator: ThicknessEstimator) -> None:
    with pytest.raises(ValueError, match="a thickness needs a slab"):
        ThicknessEstimator(load_device(), load_library(), "cork", database_bins())
    with pytest.raises(ValueError, match="grid"):
        ThicknessEstimator(load_device(), load_library(), "acryl3mm", database_bins(), grid=(2.0, 1.0, 0.1))
    with pytest.raises(ValueError, match="shape"):
        estimator.estimate(np.zeros((2, 10)))
    with pytest.raises(ValueError, match="no finite bin"):
        estimator.estimate(np.full((2, 200), np.nan))
    one_row = estimator.curves[20].copy()
    one_row[1] = np.nan
    with pytest.raises(ValueError, match="in each row"):
        estimator.estimate(one_row, offsets=True)
    assert "acryl3mm" in slab_materials(load_library()) and "cork" not in slab_materials(load_library())


def test_rendered_sweeps_give_the_slabs_thickness_and_say_when_they_cannot() -> None:
    rows = {(r.thickness_mm, r.session): r for r in bench_thickness(thicknesses=(1.0, 3.0, 10.0), sweeps=2,
                                                                    lengths=(0,))}  # fmt: skip
    for t in (1.0, 3.0):
        for session in ("same", "new"):
            r = rows[(t, session)]
            assert r.median_abs_error_mm < 0.05 and r.covered == 1.0 and r.open_above == 0.0, r
    for session in ("same", "new"):  # 10 mm: the back's echo has decayed; every interval is open
        r = rows[(10.0, session)]
        assert r.open_above == 1.0 and r.covered == 1.0, r


def test_a_window_keeps_that_many_bins_of_the_sweep() -> None:
    rows = np.arange(2 * 12, dtype=float).reshape(2, 12)
    rows[:, :2] = np.nan
    w = window(rows, 4, np.random.default_rng(0))
    kept = np.isfinite(w).all(axis=0)
    assert kept.sum() == 4 and np.ptp(np.nonzero(kept)[0]) == 3 and not kept[:2].any()
    assert window(rows, 0, np.random.default_rng(0)) is rows


def _thickness(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tofmat", "thickness", *args], capture_output=True, text=True,
                          timeout=300)  # fmt: skip


def test_the_thickness_command_reads_queries_and_refuses_bad_ones(tmp_path: Path, db_dir: Path) -> None:
    from tofmat.sim import MaterialLibrary, Renderer

    lib = load_library()
    d = lib.to_dict()
    (plate,) = slab_params(lib, "acryl3mm", [2.5])
    d["materials"].append(plate)
    r = Renderer(load_device(), MaterialLibrary.from_dict(d), 1)
    q = sweep_rows(r, plate["name"], database_bins(), seed=3)
    np.save(tmp_path / "q.npy", q)
    p = _thickness(str(tmp_path / "q.npy"), "--json")
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert abs(got["thickness_mm"] - 2.5) < 0.05 and got["low_mm"] <= 2.5 <= got["high_mm"]
    np.save(tmp_path / "batch.npy", np.stack([q, q + np.array([[2.0], [1.0]])]))
    p = _thickness(str(tmp_path / "batch.npy"), "--new-session")
    assert p.returncode == 0 and p.stdout.count("2.5") >= 2 and p.stdout.startswith("[0] acryl3mm: 2."), p.stdout
    # A database file (Python 2's, zeros for missing) reads; the real plates do not follow one slab model.
    p = _thickness(str(db_dir / "acryl2mm.npy"), "--new-session")
    assert p.returncode == 0 and "residual" in p.stdout and p.stderr == "", p.stderr
    for args, says in (([str(tmp_path / "q.npy"), "--material", "cork"], "not a slab"),
                       ([str(db_dir / "README.md")], "not a readable"),
                       ([str(tmp_path / "short.npy")], "shape")):  # fmt: skip
        if "short" in args[0]:
            np.save(tmp_path / "short.npy", np.zeros((2, 50)))
        p = _thickness(*args)
        assert p.returncode == 2 and says in p.stderr, (args, p.stderr)
