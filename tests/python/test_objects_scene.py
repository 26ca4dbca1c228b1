# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The simulator's objects scene (irregular outlines in front of a tilted plane), tables recorded over
the depth range a scene needs, and the segmentation on that scene against its truth."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tofmat.sim import Renderer, Scene, load_device, load_library

SIX = "cork+pvc+wood+paper+acryl+fabric"


def _truth(spec: str) -> tuple[list[str], np.ndarray, np.ndarray]:
    scene = Scene.of_source(spec)
    f = Renderer(load_device(), load_library(), 1).render(scene, 0, False)
    return ([t.material for t in scene.targets], np.asarray(f.target).reshape(424, 512),
            np.asarray(f.range_mm).reshape(424, 512))  # fmt: skip


def test_objects_have_irregular_outlines_in_front_of_a_tilted_plane() -> None:
    materials, target, ranges = _truth(f"objects,materials={SIX},far=1000")
    assert materials == ["fabric", "cork", "pvc", "wood", "paper", "acryl"]  # the plane (the last), then objects
    plane = target == 0
    assert plane.mean() > 0.7 and (target >= 0).all()  # the plane fills what the objects leave
    # Tilted (pitch 20, yaw 10 degrees): its range grows across the frame by hundreds of mm.
    assert np.nanmax(ranges[plane]) - np.nanmin(ranges[plane]) > 500.0
    for k in range(1, 6):
        on = target == k
        ys, xs = np.nonzero(on)
        box = (ys.max() - ys.min() + 1) * (xs.max() - xs.min() + 1)
        assert 5_000 < on.sum() < 0.75 * box, k  # not a rectangle
        # Non-convex: some row crosses the object in more than one run.
        runs = np.diff(on.astype(np.int8), axis=1).clip(min=0).sum(axis=1)
        assert runs.max() >= 2, k
        # In front of the plane: its edge is a depth step the segmentation's surfaces do not cross.
        assert np.nanmax(ranges[on]) < np.nanmin(ranges[plane]) + 200.0
        ring = np.zeros_like(on)
        ring[1:-1, 1:-1] = (on[:-2, 1:-1] | on[2:, 1:-1] | on[1:-1, :-2] | on[1:-1, 2:]) & ~on[1:-1, 1:-1]
        step = ranges[ring & plane].mean() - ranges[on].mean()
        assert step > 100.0, (k, step)


@pytest.mark.parametrize(
    ("spec", "says"),
    [("objects,materials=cork", "2 to 6"), (f"objects,materials={SIX}+copper", "2 to 6"),
     ("objects,pitch=86", "pitch"), ("objects,pitch=x", "pitch"), ("shapes", "unknown scene")],
)  # fmt: skip
def test_bad_objects_specs_are_clear_errors(spec: str, says: str) -> None:
    with pytest.raises(ValueError, match=says):
        Scene.of_source(spec)


@pytest.fixture(scope="module")
def wide_table(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The six materials over 500..2100 mm: the tilted plane's far corner is 2.0 m along the ray."""
    table = tmp_path_factory.mktemp("wide") / "wide.tmx"
    p = subprocess.run([sys.executable, "-m", "tofmat", "sim", "table", "--materials", SIX.replace("+", ","),
                        "--range", "500,2100", "--bins", "533", "--calibration-sessions", "0", "-o", str(table)],
                       capture_output=True, text=True, timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stderr
    return table


def _bench(table: Path, scene: str, frames: int, *extra: str) -> dict[str, Any]:
    p = subprocess.run([sys.executable, "-m", "tofmat", "bench-depth", "--table", str(table), "--frames", str(frames),
                        "--scenes", scene, "--json", *extra], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 0, p.stderr
    out: dict[str, Any] = json.loads(p.stdout)
    return out


def test_segmentation_of_the_objects_scene_with_a_table_over_its_depths(wide_table: Path) -> None:
    """The segmentation labels a pixel only within its table's depth bins: the table covers the scene."""
    out = _bench(wide_table, f"objects,materials={SIX},far=1000", 2)
    (labels,) = out["labels"]
    assert labels["accuracy"] > 0.95 and labels["band"] > 0.9, labels
    rows = {r["material"]: r for r in out["depth"]}
    assert sorted(rows) == sorted(SIX.split("+"))
    for name, r in rows.items():  # every object and the plane, labelled and corrected
        assert r["right_share"] > 0.9 and r["corrected_share"] > 0.9, (name, r)
        assert abs(r["right_median"]) < 1.0, (name, r)


def test_accumulating_frames_labels_the_object_one_frame_cannot(wide_table: Path) -> None:
    """Cork's and paper's curves are 0.5 mm apart at the cork object's depths (650..700 mm): frame by
    frame the object's vote goes one way or the other; the pixels' means over frames settle it."""
    scene = "objects,materials=cork+paper+acryl,far=1000"
    (alone,) = _bench(wide_table, scene, 6)["labels"]
    assert alone["accuracy"] < 0.995, alone  # some frames label the cork object paper
    (accumulated,) = _bench(wide_table, scene, 6, "--accumulate", "8")["labels"]
    assert accumulated["accuracy"] > 0.995 and accumulated["last_frame"] > 0.99, accumulated
