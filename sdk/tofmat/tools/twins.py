# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Each material's near twin in a table: the other curve closest to it once what a capture session
can do to a curve is taken out (`tofmat table twins`, docs/evaluation.md "Open set").

A session moves each row of a curve by an offset and a drift along depth (docs/evaluation.md), so
two materials whose curves differ by little more than a per-row offset and slope cannot be told
apart by a query that does not know its session, and a material held out of the table passes as
its twin. For every pair the difference of the curves over the bins both have is fitted, per row,
with an offset, and with an offset and a slope (least squares); what is left, as an rms over the
rows' bins, against the material's own bin noise (its roughness, docs/evaluation.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import ExemplarTable

F64 = npt.NDArray[np.float64]
MIN_COMMON_BINS = 10  # a pair with fewer bins in common on a row is not compared


@dataclass(frozen=True)
class Twin:
    material: str
    twin: str  # the closest other material after a per-row offset and slope ("" if none shares bins)
    raw_mm: float  # rms difference of the two curves as stored
    after_offset_mm: float  # rms left after a per-row offset
    after_drift_mm: float  # rms left after a per-row offset and slope
    noise_mm: float  # the material's bin noise (roughness), rms over its rows


def _residuals(d: F64, degree: int) -> F64 | None:
    """The per-row least-squares residuals of ``d`` (R, B) after a polynomial of ``degree`` along
    the bins; None where a row has fewer than MIN_COMMON_BINS finite bins."""
    parts = []
    for row in d:
        x = np.flatnonzero(np.isfinite(row))
        if x.size < MIN_COMMON_BINS:
            return None
        v = row[x]
        parts.append(v - np.polyval(np.polyfit(x.astype(np.float64), v, degree), x))
    return np.concatenate(parts)


def near_twins(table: ExemplarTable) -> list[Twin]:
    """Each material's near twin, closest pairs first. Raises ValueError for a table of fewer than
    two materials."""
    from ..evaluation.sessions import roughness

    if len(table.materials) < 2:
        raise ValueError("a table of one material has no twins")
    f = table.features.astype(np.float64)
    noise = roughness(f)
    out: list[Twin] = []
    for i, name in enumerate(table.materials):
        best: tuple[float, int, float, float] = (math.inf, -1, math.nan, math.nan)
        for j in range(len(table.materials)):
            if j == i:
                continue
            d = f[i] - f[j]
            drift = _residuals(d, 1)
            offset = _residuals(d, 0)
            if drift is None or offset is None:
                continue
            rms = float(np.sqrt(np.mean(drift**2)))
            if rms < best[0]:
                raw = float(np.sqrt(np.nanmean(d**2)))
                best = (rms, j, raw, float(np.sqrt(np.mean(offset**2))))
        own = noise[i][np.isfinite(noise[i])]
        out.append(
            Twin(
                name,
                table.materials[best[1]] if best[1] >= 0 else "",
                best[2],
                best[3],
                best[0],
                float(np.sqrt(np.mean(own**2))) if own.size else math.nan,
            )
        )
    return sorted(out, key=lambda t: (t.after_drift_mm, t.material))
