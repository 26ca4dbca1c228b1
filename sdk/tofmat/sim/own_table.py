# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The simulated camera's own table, recorded and calibrated for itself, as a box does with its camera.

A table carries its own calibration (the session prior, the confidence temperatures and the open-set
thresholds of ``tofmat table calibrate``); without one, tofmatd falls back on the built-in one, which
was tuned on the real database's curves and is too sharp for rendered sweeps at angles away from the
table's (docs/evaluation.md). So the simulated camera's table is calibrated on sessions the simulator
renders as soon as it is recorded.
"""

from __future__ import annotations

from pathlib import Path

from .. import ExemplarTable
from .._progress import Progress

# Rendered sessions a material and split the calibration draws (as docs/evaluation.md's simulator
# figures are drawn): about 20 minutes for the whole library on one core.
CALIBRATION_SESSIONS = 6


def current_table(path: Path) -> tuple[ExemplarTable | None, str]:
    """The table at ``path`` and "" if it is current (this tofmat reads it and it has a depth
    distortion); else None and why it must be recorded again."""
    try:
        table = ExemplarTable.load(str(path))
    except (OSError, ValueError) as e:  # (FormatError is a ValueError)
        return None, f"not a table this tofmat reads ({e})"
    if table.distortion_mm is None:
        return None, "an older tofmat's table, without a depth distortion"
    return table, ""


def calibrated(table: ExemplarTable, sessions: int, progress: Progress | None = None) -> ExemplarTable:
    """``table`` (recorded by the default simulated camera) with the calibration its own rendered
    sessions give (table_calibration.calibrate_table). Raises ValueError for a table of one material."""
    from ..evaluation.table_calibration import calibrate_table

    return calibrate_table(table, "sim", sessions, progress)[0]


def ensure_sim_table(path: Path, progress: Progress | None = None, sessions: int = CALIBRATION_SESSIONS) -> Path:
    """The default simulated camera's table of the whole library at ``path``: kept if the file there is
    current and calibrated; calibrated if it is current without a calibration (and ``sessions`` > 0);
    recorded (and calibrated) again if it is missing, unreadable or an older tofmat's (current_table).
    The file is replaced atomically, so an interrupted run leaves the one before."""
    from . import Renderer, load_device, load_library
    from .table import database_bins, simulated_table

    table = current_table(path)[0] if path.is_file() else None
    if table is not None and (table.calibration is not None or sessions == 0):
        return path
    if table is None:
        r = Renderer(load_device(), load_library())
        table = simulated_table(r, list(r.library.names), database_bins(), progress=progress)
    if sessions > 0:
        table = calibrated(table, sessions, progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    table.save(str(path))
    return path
