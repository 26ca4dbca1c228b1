# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Still targets and sweeps through tofmatd's live hand-held path agree with the table the simulated
camera recorded (issue 32): the live query's Eq. (12) distance to the true material is within the
noise at every depth and angle, no label is confidently wrong, and a target is labelled right among
the candidates it can be told from.

Before the region was binned by its surface's mean depth, a still cork target at 900 mm was 4.4 mm^2
from every opaque candidate (pixels binned by their own noisy depth) and labelled "alumi" with
confidence 1.0.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import SIM_TABLE_MATERIALS

from tofmat.tools.target_bench import CONFIDENT, TargetResult, bench_targets, format_markdown


@pytest.fixture(scope="module")
def table_at_30(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated camera's table of the same materials recorded with targets at 30 degrees."""
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    t = simulated_table(Renderer(load_device(), load_library(), 1), SIM_TABLE_MATERIALS, database_bins(), yaw_deg=30.0,
                        distortion=False)  # fmt: skip
    path = tmp_path_factory.mktemp("table30") / "sim30.tmx"
    t.save(str(path))
    return path


@pytest.fixture(scope="module")
def results(sim_table: Path, table_at_30: Path) -> list[TargetResult]:
    """Targets at 0 degrees against the table recorded at 10 (the default), and at 30 degrees against
    the one recorded at 30: the live path against the recording path, at a small and a large angle."""
    near = bench_targets(sim_table, [700.0, 1000.0], [0.0], sweeps=True, sweep_frames=40)
    steep = bench_targets(table_at_30, [700.0, 1000.0], [30.0], sweeps=True, sweep_frames=40)
    return near + steep


def test_every_target_of_the_grid_is_labelled(results: list[TargetResult]) -> None:
    n = len(SIM_TABLE_MATERIALS)
    assert len(results) == 2 * n * 3  # two angles: stills at 2 depths and a sweep
    assert {r.material for r in results} == set(SIM_TABLE_MATERIALS)
    print(format_markdown(results))


def test_the_live_query_is_the_tables_curve_within_the_noise(results: list[TargetResult]) -> None:
    # Measured (docs/benchmarks.md, Still targets and sweeps): at most 0.26 mm^2 at 0 degrees against
    # the 10-degree table; the bug was 4.4 mm^2 for every opaque material at 900 mm.
    for r in results:
        assert r.eq12_truth <= 0.3, r


def test_no_label_is_confidently_wrong(results: list[TargetResult]) -> None:
    wrong = [r for r in results if r.confidently_wrong]
    assert not wrong, f"labels wrong with confidence >= {CONFIDENT}: {wrong}"


def test_a_target_is_right_among_the_candidates_it_can_be_told_from(results: list[TargetResult]) -> None:
    assert all(r.material in r.separable for r in results)
    missed = [r for r in results if r.label_among_separable != r.material]
    assert len(missed) <= len(results) // 20, missed
    # A whole sweep at the table's own angle names every material but the near twins.
    sweeps = [r for r in results if r.kind == "sweep"]
    assert sum(r.correct for r in sweeps) >= len(sweeps) - 4, sweeps
