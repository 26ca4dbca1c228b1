# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmatd with a table of several exemplars a material (entries MATERIAL@ANGLE, docs/table-format.md):
its labels, rankings, candidates and sorting line speak of materials, never of an exemplar's tag."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import Daemon

import tofmat
from tofmat.client import daemon_binary
from tofmat.tools.line_demo import LineSetup, run_line

MATERIALS = ("acryl", "copper", "silicone")  # the line's (told apart at one depth: tools.line_demo.LineSetup)
YAWS = (0.0, 10.0, 30.0)


@pytest.fixture(scope="module")
def angle_table(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated camera's table of the line's materials, each at three angles."""
    from tofmat.evaluation.angle_tables import record_angle_table
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    r = Renderer(load_device(), load_library(), 1)
    first = simulated_table(r, list(MATERIALS), database_bins(), yaw_deg=YAWS[0], distortion=False)
    table, owner = record_angle_table(list(MATERIALS), YAWS, first, renderer=r, distortion=True)
    assert table.materials == [f"{m}@{y:g}" for y in YAWS for m in MATERIALS] and list(owner) == [0, 1, 2] * 3
    path = tmp_path_factory.mktemp("angletable") / "angles.tmx"
    table.save(str(path))
    return path


def assert_speaks_of_materials(label: tofmat.client.Label, entries: list[str]) -> None:
    ranked = [r.material for r in label.ranking]
    assert len(ranked) == len(set(ranked)) and set(ranked) <= set(MATERIALS), ranked  # each material once
    assert label.material in MATERIALS and label.material == ranked[0]
    # the label's index is the best exemplar's entry in the table, an exemplar of the label's material
    assert entries[label.index].split("@")[0] == label.material


def test_sorting_labels_and_candidates_name_the_material(
    start: Callable[..., Daemon], angle_table: Path, tmp_path: Path
) -> None:
    entries = tofmat.ExemplarTable.load(angle_table).materials
    d = start("sim:static,material=acryl,depth=850,realtime=0", "--profile", "sorting", "--burst", "6",
              table=angle_table)  # fmt: skip
    with d.client() as c:
        assert c.status()["table"]["materials"] == entries  # status lists the table's entries
        c.subscribe("labels")
        n = c.trigger()
        label = next(c.labels(timeout=30))
        assert label.trigger == n and label.state == "final" and label.material == "acryl", label
        assert_speaks_of_materials(label, entries)
        assert label.confidence is not None and 0.0 < label.confidence <= 1.0
    # Candidates by material take all its exemplars; one exemplar by its entry name; both of one
    # exemplar is refused at start.
    d = start("sim:static,material=acryl,depth=850,realtime=0", "--profile", "sorting", "--burst", "6",
              "--candidates", "acryl,copper", table=angle_table, name="cand")  # fmt: skip
    with d.client() as c:
        c.subscribe("labels")
        c.trigger()
        label = next(c.labels(timeout=30))
        assert label.material == "acryl" and {r.material for r in label.ranking} == {"acryl", "copper"}, label
    for bad, word in (("acryl,acryl@0", "twice"), ("acryl@45", "acryl@45")):
        p = subprocess.run([str(daemon_binary()), "--table", str(angle_table), "--socket", str(tmp_path / "s"),
                            "--candidates", bad], capture_output=True, text=True, timeout=30)  # fmt: skip
        assert p.returncode != 0 and word in p.stderr + p.stdout, (bad, p.stderr)


def test_the_line_sorts_by_material_against_a_table_of_angles(angle_table: Path) -> None:
    setup = LineSetup(MATERIALS, speed_mm_s=500.0, rate_per_min=90.0, burst=4, seed=5)
    r = run_line(angle_table, setup, seconds=8.0)
    outlets = {name for name, _ in setup.outlets()}
    assert outlets == set(MATERIALS) | {"reject"}
    assert r.items >= 8 and r.decided
    for d in r.decided:
        assert d.outlet in outlets, d
        if d.reason == "sorted":
            assert d.material in MATERIALS and d.outlet == d.material, d
    assert r.missing_truth() == 0
    assert r.right_fraction() >= 0.8, r.reasons()
    assert r.wrong() <= 1


def test_a_label_map_names_each_material_once(start: Callable[..., Daemon], angle_table: Path) -> None:
    # The regions scene's three targets side by side (700, 850, 1000 mm), labelled against exemplars at
    # three angles: the map's labels are the materials, so the smoothing and the region vote count a
    # material's exemplars together.
    d = start("sim:regions,materials=acryl+copper+silicone,near=700,far=1000,realtime=0", "--profile", "segmentation",
              table=angle_table)  # fmt: skip
    with d.client() as c:
        m = c.label_map(timeout=60)
        assert m.materials == list(MATERIALS)
        assert set(np.unique(m.labels)) <= {0, 1, 2, tofmat.client.LabelMap.NO_LABEL}
        assert m.truth_accuracy is not None and m.truth_accuracy > 0.7
        for material, (x0, x1) in zip(MATERIALS, ((16, 168), (180, 332), (344, 496)), strict=True):
            region = m.labels[32:204, x0:x1]
            labelled = region[region != tofmat.client.LabelMap.NO_LABEL]
            assert np.bincount(labelled).argmax() == m.materials.index(material)
