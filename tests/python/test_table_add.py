# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat table add`: a material the database does not have (the simulator's example "wax"),
captured with a running tofmatd on the simulated camera in several passes, added to the box's
table with its noise, and served after SIGHUP; the pieces (unwrapping the depth images, combining
passes) on cases worked by hand; the errors."""

from __future__ import annotations

import shutil
import signal
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import Daemon, final_labels

import tofmat
from tofmat.cli import main
from tofmat.client import DepthImage
from tofmat.tools.capture import CaptureError, combine_passes, frame_observations, with_material

WAX = "sim:sweep,materials=wax,library=examples,frames=30,gap=6,realtime=0"


def image(kind: str, mm: list[float]) -> DepthImage:
    return DepthImage(1, 0, kind, 0, 0, np.array([mm], dtype=np.float32))  # type: ignore[arg-type]


def test_frame_observations_unwrap_each_frequency_near_the_combined_depth() -> None:
    # A pixel at 2000 mm: 80 MHz wraps at 1875 (reads 125), 16 at 9375 (2000), 120 at 1250 (750);
    # the 16 MHz reads 3 mm long and the 80 MHz 1 mm long. A NaN pixel is left out.
    images = {
        "combined": image("combined", [2000.0, np.nan]),
        "80": image("80", [126.0, 5.0]),
        "16": image("16", [2003.0, 5.0]),
        "120": image("120", [750.0, 5.0]),
    }
    depth, rows = frame_observations(images, [(16, 120), (80, 120)])
    assert depth.tolist() == [2000.0]
    assert rows.tolist() == [[3.0, 1.0]]


def test_combining_passes_gives_their_mean_and_pooled_spread(real_table: tofmat.ExemplarTable) -> None:
    rng = np.random.default_rng(0)
    base = real_table.features[real_table.index_of("cork")]
    passes = [(base + rng.normal(0.0, 0.4, base.shape)).astype(np.float32) for _ in range(4)]
    passes[0][:, :50] = np.nan  # a pass that missed the near end
    cap = combine_passes(passes, real_table, "cork2")
    assert cap.noise_from == "passes"
    assert np.allclose(cap.noise_mm, 0.4, rtol=0.1)
    assert np.allclose(cap.curve[:, :50], np.mean([p[:, :50] for p in passes[1:]], axis=0), atol=1e-5)
    one = combine_passes(passes[1:2], real_table, "cork2")
    assert one.noise_from == "roughness" and np.all(one.noise_mm > 0.2)
    # Added at the end with its noise; the others keep theirs (NaN: not stored).
    t = with_material(real_table, "cork2", cap)
    assert t.materials[-1] == "cork2" and t.materials[:-1] == real_table.materials
    assert t.noise_mm is not None and np.allclose(t.noise_mm[-1], cap.noise_mm) and np.isnan(t.noise_mm[0]).all()
    with pytest.raises(CaptureError, match="--replace"):
        with_material(real_table, "cork", cap)
    assert with_material(real_table, "cork", cap, replace=True).materials == real_table.materials
    # A table with a depth distortion keeps it; a replaced material's old one goes with its old curve.
    grid = tofmat.BinSpec(450.0, 4.0, 500)
    dist = np.tile(np.linspace(-5.0, 5.0, grid.count), (len(real_table), 1))
    with_d = real_table.with_distortion(grid, dist)
    added = with_material(with_d, "cork2", cap)
    assert added.distortion_mm is not None and added.distortion_mm.shape == (len(real_table) + 1, grid.count)
    assert np.allclose(added.distortion_mm[:-1], dist) and np.isnan(added.distortion_mm[-1]).all()
    replaced = with_material(with_d, "cork", cap, replace=True)
    assert replaced.distortion_mm is not None
    k = real_table.index_of("cork")
    assert np.isnan(replaced.distortion_mm[k]).all() and np.allclose(
        np.delete(replaced.distortion_mm, k, 0), np.delete(dist, k, 0)
    )


def test_a_new_material_captured_with_the_box_is_served_after_sighup(
    start: Callable[..., Daemon], sim_table: Path, tmp_path: Path
) -> None:
    table = tmp_path / "box.tmx"
    shutil.copy(sim_table, table)
    before = tofmat.ExemplarTable.load(table)
    assert "wax" not in before.materials
    d = start(WAX, table=table)
    d.client().close()  # listening
    r = CliRunner().invoke(
        main, ["table", "add", "wax", "--address", str(d.socket), "--table", str(table), "--passes", "3"]
    )
    assert r.exit_code == 0, r.output
    assert "pass 3 of 3" in r.output and "noise" in r.output
    after = tofmat.ExemplarTable.load(table)
    assert after.materials == [*before.materials, "wax"]
    assert np.array_equal(after.features[:-1], before.features, equal_nan=True)
    assert after.noise_mm is not None and np.all(after.noise_mm[-1] > 0)
    # One bin a frame of each pass (the region's surface at its mean depth): 30 frames over 600 mm.
    assert np.isfinite(after.features[-1]).all(axis=0).sum() >= 25
    # Everything the table carried stays: its depth distortion too (none measured for wax).
    assert before.distortion_mm is not None and after.distortion_mm is not None
    assert after.distortion_grid is not None and before.distortion_grid is not None
    assert after.distortion_grid.count == before.distortion_grid.count
    assert np.array_equal(after.distortion_mm[:-1], before.distortion_mm, equal_nan=True)
    assert np.isnan(after.distortion_mm[-1]).all()
    with d.client() as c:
        d.proc.send_signal(signal.SIGHUP)
        deadline = time.monotonic() + 20
        while (c.status()["last_reload"] or {}).get("ok") is not True:
            assert time.monotonic() < deadline, "the reload was not reported"
            time.sleep(0.05)
        assert c.status()["table"]["materials"][-1] == "wax"
        # The next whole sweeps of wax are labelled wax.
        finals = final_labels(c, 2)
        assert [f.material for f in finals] == ["wax", "wax"]


def test_table_add_refuses_what_cannot_work(start: Callable[..., Daemon], sim_table: Path, tmp_path: Path) -> None:
    table = tmp_path / "box.tmx"
    shutil.copy(sim_table, table)
    cork = tofmat.ExemplarTable.load(table).materials[0]
    runner = CliRunner()
    for name, needle in ((cork, "--replace"), ("unknown", "reserved"), ("a b", "printable")):
        r = runner.invoke(main, ["table", "add", name, "--address", str(tmp_path / "none.sock"), "--table", str(table)])
        assert r.exit_code == 2 and needle in r.output, r.output
    # No daemon there: one line, exit 1 or 2, the table untouched.
    data = table.read_bytes()
    r = runner.invoke(main, ["table", "add", "wax", "--address", str(tmp_path / "none.sock"), "--table", str(table)])
    assert r.exit_code != 0 and "Traceback" not in r.output
    # The daemon in another profile than handheld.
    d = start(WAX, "--profile", "segmentation", table=table)
    d.client().close()
    r = runner.invoke(
        main, ["table", "add", "wax", "--address", str(d.socket), "--table", str(table), "--timeout", "5"]
    )
    assert r.exit_code == 1 and "handheld" in r.output, r.output
    assert table.read_bytes() == data
