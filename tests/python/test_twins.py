# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat table twins`: each material's nearest other curve once a per-row offset and slope are
taken out, on the real database (paper and plaster are each other's twins; fakeleather, the
noisiest curve, has none near) and on a constructed table whose answer is known exactly."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from click.testing import CliRunner

import tofmat
from tofmat.cli import main
from tofmat.tools.twins import near_twins


def test_a_curve_moved_by_an_offset_and_a_slope_is_an_exact_twin(real_table: tofmat.ExemplarTable) -> None:
    f = real_table.features[[real_table.index_of(m) for m in ("cork", "copper")]].copy()
    moved = f[0] + np.array([[2.0], [-1.0]], dtype=np.float32) + 0.01 * np.arange(f.shape[2], dtype=np.float32)
    t = tofmat.ExemplarTable(
        ["cork", "copper", "moved"], np.stack([f[0], f[1], moved]), real_table.bins, real_table.rows
    )
    twins = {x.material: x for x in near_twins(t)}
    assert twins["cork"].twin == "moved" and twins["moved"].twin == "cork"
    assert twins["cork"].after_drift_mm < 1e-3 < twins["cork"].after_offset_mm < twins["cork"].raw_mm
    assert twins["copper"].after_drift_mm > 1.0


def test_the_databases_near_twins(real_table: tofmat.ExemplarTable) -> None:
    twins = near_twins(real_table)
    by = {x.material: x for x in twins}
    assert len(twins) == len(real_table.materials)
    assert by["paper"].twin == "plaster" and by["plaster"].twin == "paper"
    assert by["paper"].after_drift_mm < 0.5 and twins[-1].material == "fakeleather"
    for x in twins:
        assert x.after_drift_mm <= x.after_offset_mm + 1e-12 and math.isfinite(x.noise_mm) and x.noise_mm > 0
    assert [x.after_drift_mm for x in twins] == sorted(x.after_drift_mm for x in twins)


def test_the_command(db_dir: Path, real_table: tofmat.ExemplarTable, tmp_path: Path) -> None:
    r = CliRunner().invoke(main, ["table", "twins", str(db_dir), "--json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.output)
    assert {x["material"] for x in rows} == set(real_table.materials)
    r = CliRunner().invoke(main, ["table", "twins", str(db_dir)])
    assert r.exit_code == 0 and "| paper | plaster |" in r.output
    one = tmp_path / "one.tmx"
    tofmat.ExemplarTable(["cork"], real_table.features[:1].copy(), real_table.bins, real_table.rows).save(str(one))
    r = CliRunner().invoke(main, ["table", "twins", str(one)])
    assert r.exit_code == 2 and "one material" in r.output


def test_a_missing_table_is_a_clear_error(tmp_path: Path) -> None:
    r = CliRunner().invoke(main, ["table", "twins", str(tmp_path / "missing.tmx")])
    assert r.exit_code == 2 and "does not exist" in r.output
