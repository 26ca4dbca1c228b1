# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Material-corrected depth: the table's depth distortion (format 1.2), where it comes from (the
simulated camera, or the calibrated simulator for a database table), tofmatd's `depth:corrected`
stream, and its error against the simulator's truth (`tofmat bench-depth`)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import Daemon

import tofmat
from tofmat.client import DepthImage, Label

GRID = tofmat.BinSpec(500.0, 10.0, 4)  # samples at 505, 515, 525, 535 mm


def _small(real_table: tofmat.ExemplarTable, names: list[str]) -> tofmat.ExemplarTable:
    idx = [real_table.index_of(n) for n in names]
    return tofmat.ExemplarTable(names, real_table.features[idx], real_table.bins, real_table.rows)


def test_a_tables_distortion_round_trips_and_interpolates(real_table: tofmat.ExemplarTable, tmp_path: Path) -> None:
    t = _small(real_table, ["cork", "paper"])
    assert t.distortion_grid is None and t.distortion_mm is None
    assert np.isnan(t.distortion_at("cork", [510.0])).all()  # none: nothing to correct with
    d = np.array([[10.0, 20.0, np.nan, -5.5], [-1.0, -2.0, -3.0, -4.0]])
    td = t.with_distortion(GRID, d)
    np.testing.assert_allclose(td.distortion_at("cork", [505.0, 510.0, 517.5]), [10.0, 15.0, np.nan])
    np.testing.assert_allclose(td.distortion_at("paper", np.array([[532.5, 535.0], [540.0, 499.0]])),
                               [[-3.75, -4.0], [np.nan, np.nan]])  # fmt: skip
    td.save(str(tmp_path / "d.tmx"))
    back = tofmat.ExemplarTable.load(str(tmp_path / "d.tmx"))
    assert back.distortion_grid is not None and back.distortion_grid.count == 4
    np.testing.assert_array_equal(back.distortion_mm, d)
    assert back.noise_mm is None  # (1.2 always stores a noise block: all NaN reads back as none)
    assert back.with_distortion(None, None).distortion_mm is None
    with pytest.raises(ValueError, match="both"):
        t.with_distortion(GRID, None)
    with pytest.raises(ValueError, match="distortion_mm"):
        t.with_distortion(GRID, d[:, :3])
    with pytest.raises(ValueError, match="10000"):
        t.with_distortion(GRID, d * 1e4)
    with pytest.raises(KeyError, match="unobtainium"):
        td.distortion_at("unobtainium", [510.0])
    info = subprocess.run([sys.executable, "-m", "tofmat", "table", "info", str(tmp_path / "d.tmx"), "--json"],
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["distortion"]["known_samples"] == {"cork": 3, "paper": 4}


def test_the_simulated_cameras_table_carries_each_materials_distortion(sim_table: Path) -> None:
    from tofmat._tofmat import decode_frame
    from tofmat.sim import Renderer, Scene, load_device, load_library
    from tofmat.sim.table import ROI

    t = tofmat.ExemplarTable.load(str(sim_table))
    assert t.distortion_mm is not None and np.isfinite(t.distortion_mm).mean() > 0.9
    # Its sign and size: a noise-free frame of cork at 900 mm, measured minus true along the rays.
    r = Renderer(load_device(), load_library(), 1)
    f = r.render_region(Scene.centred_target("cork", 900.0, 10.0, 160), 0, False, ROI)
    x0, y0, x1, y1 = ROI
    p0 = np.asarray(r.p0_tables())[:, y0:y1, x0:x1].reshape(3, -1)
    d = decode_frame(np.asarray(f.raw).reshape(9, -1), np.ascontiguousarray(p0))
    ok = np.asarray(d.flags) == 0
    measured = np.asarray(d.combined_mm)[ok]
    error = measured - np.asarray(f.range_mm).reshape(-1)[ok]
    assert abs(np.median(error)) > 5.0  # the camera's own error at this depth is not small...
    corrected = measured - t.distortion_at("cork", measured)
    assert abs(np.median(corrected - np.asarray(f.range_mm).reshape(-1)[ok])) < 1.0  # ...and the table removes it


def test_sim_table_records_the_range_asked_and_keeps_a_current_table(real_table: tofmat.ExemplarTable,
                                                                     tmp_path: Path) -> None:  # fmt: skip
    out = tmp_path / "far.tmx"

    def sim_table(*extra: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "tofmat", "sim", "table", "--materials", "cork,paper", "--bins",
                               "41", "--range", "1200,1600", "--calibration-sessions", "0", "-o", str(out), *extra],
                              capture_output=True, text=True, timeout=300)  # fmt: skip

    p = sim_table()
    assert p.returncode == 0, p.stderr
    t = tofmat.ExemplarTable.load(str(out))
    assert (t.bins.start_mm, t.bins.width_mm, t.bins.count) == (1200.0, 10.0, 41)
    # The sweeps reach the whole range (a target at up to 1.6 m), not only the database's 600..1200 mm.
    assert np.isfinite(t.features[:, :, 1:-1]).all()
    assert np.isfinite(t.distortion_at("paper", [1250.0, 1550.0])).all()
    before = out.read_bytes()
    p = sim_table("--keep-current")
    assert p.returncode == 0 and "kept" in p.stdout and out.read_bytes() == before
    # A table of an older tofmat (no depth distortion) is recorded again.
    _small(real_table, ["cork"]).save(str(out))
    p = sim_table("--keep-current")
    assert p.returncode == 0 and "kept" not in p.stdout and "without a depth distortion" in p.stderr
    assert tofmat.ExemplarTable.load(str(out)).distortion_mm is not None
    # So is a file that is no table at all, saying why.
    out.write_bytes(b"not a table")
    p = sim_table("--keep-current")
    assert p.returncode == 0 and "not a table this tofmat reads" in p.stderr, p.stderr
    assert tofmat.ExemplarTable.load(str(out)).distortion_mm is not None


def test_table_distortion_adds_the_calibrated_simulators(real_table: tofmat.ExemplarTable, tmp_path: Path) -> None:
    t = _small(real_table, ["cork", "acryl"])
    features = np.concatenate([t.features, t.features[:1]])
    odd = tofmat.ExemplarTable(["cork", "acryl", "unobtainium"], features, t.bins, t.rows)
    odd.save(str(tmp_path / "t.tmx"))
    before = (tmp_path / "t.tmx").read_bytes()
    p = subprocess.run([sys.executable, "-m", "tofmat", "table", "distortion", str(tmp_path / "t.tmx"), "-o",
                        str(tmp_path / "d.tmx")], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert "2 of 3 materials" in p.stdout and "unobtainium    none: not in the simulator's library" in p.stdout
    assert "fit rms 0.33 mm" in p.stdout  # cork's fit to the database's rows (the library's)
    assert (tmp_path / "t.tmx").read_bytes() == before  # -o: the input stays as it was
    d = tofmat.ExemplarTable.load(str(tmp_path / "d.tmx"))
    assert d.distortion_mm is not None
    assert np.isfinite(d.distortion_mm[:2]).all() and np.isnan(d.distortion_mm[2]).all()
    np.testing.assert_array_equal(d.features, tofmat.ExemplarTable.load(str(tmp_path / "t.tmx")).features)  # untouched


def _same_frame(c: tofmat.Client, kinds: tuple[str, ...], timeout: float = 60.0) -> dict[str, object]:
    seen: dict[int, dict[str, object]] = {}
    for e in c.events(timeout=timeout):
        if isinstance(e, DepthImage):
            seen.setdefault(e.frame, {})[e.kind] = e
        elif isinstance(e, Label):
            seen.setdefault(e.frame, {})["label"] = e
        for v in seen.values():
            if set(kinds) <= set(v) and "label" in v:
                return v
    raise AssertionError("no frame with a label and every depth kind")


def test_the_daemon_corrects_each_labelled_pixel(start: Callable[..., Daemon], sim_table: Path) -> None:
    t = tofmat.ExemplarTable.load(str(sim_table))
    d = start("sim:static,material=cork,depth=900,realtime=0", "--candidates", "cork,paper,pvc")
    with d.client() as c:
        c.subscribe("labels", "depth:combined", "depth:corrected")
        for _ in range(3):
            v = _same_frame(c, ("combined", "corrected"))
            label, comb, corr = v["label"], v["combined"], v["corrected"]
            assert isinstance(label, Label) and isinstance(comb, DepthImage) and isinstance(corr, DepthImage)
            assert label.material is not None and corr.intrinsics == comb.intrinsics
            expected = comb.depth_mm - t.distortion_at(label.material, comb.depth_mm)
            assert np.isfinite(expected).mean() > 0.9
            np.testing.assert_allclose(corr.depth_mm, expected, atol=1e-3, equal_nan=True)


def test_without_a_distortion_the_corrected_depth_is_all_invalid(start: Callable[..., Daemon], real_table,
                                                                 tmp_path: Path) -> None:  # fmt: skip
    plain = tmp_path / "plain.tmx"
    real_table.save(str(plain))
    d = start("sim:static,material=cork,depth=900,realtime=0", table=plain)
    with d.client() as c:
        img = c.depth("corrected", timeout=60)
        assert img.kind == "corrected" and img.depth_mm.shape == (48, 48) and not img.valid.any()


def test_bench_depth_meets_the_target_on_opaque_materials(sim_table: Path) -> None:
    # Three opaque materials placed so that every range along the rays lies in the table's bins.
    p = subprocess.run([sys.executable, "-m", "tofmat", "bench-depth", "--table", str(sim_table), "--frames", "2",
                        "--scenes", "regions,materials=cork+pvc+paper,near=650,far=900", "--json"],
                       capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    rows = {r["material"]: r for r in out["depth"]}
    (labels,) = out["labels"]
    assert labels["accuracy"] > 0.95 and labels["band"] > 0.9 and 0.0 < labels["band_share"] < 0.5, labels
    assert sorted(rows) == ["cork", "paper", "pvc"]
    for name, r in rows.items():
        assert r["corrected_share"] > 0.9 and r["right_share"] > 0.5, (name, r)
        assert r["before_abs_median"] > 2.0 * r["right_abs_median"], (name, r)  # the correction removes most of it
        assert abs(r["right_median"]) < 1.0 and r["right_abs_median"] < 1.5, (name, r)  # corrected: under 1 mm
