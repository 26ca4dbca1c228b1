# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Opening a table from whatever the user points at."""

from __future__ import annotations

from pathlib import Path

from .. import ExemplarTable


def open_table(path: str | Path, bin_start_mm: float = 600.0, bin_stop_mm: float = 1200.0) -> ExemplarTable:
    """A folder of <material>.npy curves is imported; anything else is loaded as a .tmx table file."""
    p = Path(path)
    if p.is_dir():
        return ExemplarTable.from_npy_dir(p, bin_start_mm=bin_start_mm, bin_stop_mm=bin_stop_mm)
    return ExemplarTable.load(p)
