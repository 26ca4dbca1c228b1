# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A table's own calibration (format 1.3, ``tofmat table calibrate``).

The evaluation of docs/evaluation.md run on one table: its tuning split (sessions drawn with the
calibration's spreads) tunes the session matcher's prior, fits each method's
confidence temperature per sweep length, and chooses the open-set thresholds. Those are what the
table then carries; tofmatd and :class:`tofmat.Classifier` use them in place of the built-in ones
(which were tuned on the real database's curves). The test split's figures come back beside them,
so the command can say how the calibrated table does on sessions it was not tuned on.
"""

from __future__ import annotations

from typing import Any

from .. import ExemplarTable
from .._progress import Progress
from .matchers import session_prior
from .run import SourceResult, evaluate_curves, evaluate_sim


def calibration_of(result: SourceResult, n_rows: int) -> dict[str, Any]:
    """The table calibration (``ExemplarTable.with_calibration``'s dict) from an evaluation's
    tuning split: the tuned session prior, each method's temperatures and the open-set thresholds."""
    if result.tuned is None or not result.open_set:
        raise ValueError("the evaluation has no tuning split to calibrate from")
    prior = session_prior(result.tuned)
    offsets = list(prior.offset_sd_mm)
    if len(offsets) != n_rows:
        raise ValueError(f"the evaluation tuned {len(offsets)} row offsets for a table of {n_rows} rows")
    methods: dict[str, dict[str, list[list[float]]]] = {}
    for row in result.rows:
        if row.split != "tune" or row.method not in ("eq12", "session") or not row.temperature:
            continue
        methods[row.method] = {"temperatures": [[float(n), float(t)] for n, t in sorted(row.temperature.items())]}
    if "session" in methods:
        fits = result.open_set[0].thresholds  # the tuning split's
        methods["session"]["unknown_fits"] = [[float(n), float(f)] for n, f in sorted(fits.items())]
    return {
        "offset_sd_mm": offsets,
        "drift_sd_mm": [prior.drift1_sd_mm, prior.drift2_sd_mm],
        "noise_scale": prior.noise_scale,
        "floor_mm": prior.floor_mm,
        "huber_k": prior.huber_k,
        "iterations": prior.iterations,
        "methods": methods,
    }


def calibrate_table(
    table: ExemplarTable, source: str, sessions: int, progress: Progress | None = None
) -> tuple[ExemplarTable, SourceResult]:
    """``table`` carrying the calibration its evaluation gives (``source``: "curves" for a table of
    the real database's curves, "sim" for one the simulated camera recorded), and the evaluation.
    Raises ValueError for a table of one material (nothing to calibrate a choice on)."""
    if len(table.materials) < 2:
        raise ValueError("a table of one material has nothing to calibrate a choice on")
    if source == "curves":
        result = evaluate_curves(table, sessions, progress=progress)
    elif source == "sim":
        result = evaluate_sim(None, sessions, progress=progress, table=table)
    else:
        raise ValueError(f"unknown source {source!r}: 'curves' or 'sim'")
    return table.with_calibration(calibration_of(result, table.n_rows)), result
