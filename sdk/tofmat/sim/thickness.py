# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A slab's thickness in mm from a sweep's curves, by inverting the calibrated slab model.

A slab (the material library's kind "slab", the paper's Sec. 6 acrylic plates) answers the camera
with light scattered inside it for the time its thickness takes to cross, and an echo from its back
(docs/simulator-model.md: the transit T = path_factor * 2 * thickness * n / c). Its two Eq. (10)
rows therefore change with thickness. For a slab of a known material, the model's noise-free rows
(``distortion_curves``) are computed once on a grid of thicknesses with every other parameter
held at the calibrated material's; a sweep's rows are matched against each, Eq. (12)'s mean squared
difference over the bins both have, and the least one, refined by a parabola through its
neighbours, is the estimate.

The thicker the slab, the less its back shows: past a few transit times (for acryl3mm's parameters,
about 7 mm) the echo has decayed and every thickness gives the same rows. ``ThicknessEstimate``
says so with an interval: the thicknesses whose mismatch is within a chi-square margin of the best
(95 %, the residual taken as the noise), open above when it reaches the grid's end.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import BinSpec
from . import DeviceProfile, Material, MaterialLibrary, distortion_curves

CHI2_95 = 3.841  # one parameter
# The model's own error (rms mm of the rows) that the interval allows beyond the noise: the analytic
# slab curves against sweeps rendered from the same parameters differ by this much in shape (the
# ROI's spread of incidence, the decode's quantisation), which noise alone would not explain.
MODEL_ERROR_MM = 0.1
DEFAULT_GRID = (0.1, 14.0, 0.05)  # mm: first, last, step
DEFAULT_INCIDENCE_DEG = 10.0  # the simulated sweeps' yaw (tofmat sim table's default)


@dataclass(frozen=True)
class ThicknessEstimate:
    thickness_mm: float
    low_mm: float  # the 95 % interval's ends on the grid
    high_mm: float
    open_above: bool  # the interval reaches the grid's end: "at least low_mm" is all the rows say
    residual_mm: float  # rms difference between the sweep's rows and the model's at the estimate
    values: int  # how many row values the match used


class ThicknessEstimator:
    """Thickness of slabs of ``material`` (a slab in ``library``) from rows binned as ``bins``."""

    def __init__(self, device: DeviceProfile, library: MaterialLibrary, material: str, bins: BinSpec,
                 incidence_deg: float = DEFAULT_INCIDENCE_DEG, grid: tuple[float, float, float] = DEFAULT_GRID,
                 model_error_mm: float = MODEL_ERROR_MM) -> None:  # fmt: skip
        base = library[material]
        if base.kind != "slab":
            raise ValueError(f"{material!r} is a {base.kind} material; a thickness needs a slab")
        first, last, step = grid
        if not (0.0 < first < last <= 1000.0 and 0.0 < step <= last - first):
            raise ValueError(f"bad thickness grid {grid}: 0 < first < last <= 1000 mm, 0 < step")
        if not (0.0 <= model_error_mm < 100.0):
            raise ValueError(f"model error {model_error_mm} mm: 0 to 100")
        self.material = material
        self.bins = bins
        self.model_error_mm = model_error_mm
        self.grid = np.round(np.arange(first, last + 0.5 * step, step), 6)
        slabs = [Material.from_dict(p) for p in slab_params(library, material, self.grid)]
        # (grid, 2, bins): each thickness's noise-free rows, NaN where the model has none
        self.curves = np.asarray(distortion_curves(device, slabs, bins, incidence_deg), dtype=np.float64)

    def mismatch(self, rows: npt.ArrayLike, offsets: bool = False) -> tuple[npt.NDArray[np.float64], int]:
        """Eq. (12)'s mean squared difference (mm^2) against every thickness of the grid, and the
        number of row values it used (the rows' and every curve's finite ones). With ``offsets``,
        each row's mean difference is taken out first (a capture session's row offsets)."""
        q = np.asarray(rows, dtype=np.float64)
        if q.shape != self.curves.shape[1:]:
            raise ValueError(f"rows of shape {q.shape}; this estimator's bins need {self.curves.shape[1:]}")
        ok = np.isfinite(q) & np.isfinite(self.curves).all(axis=0)
        n = int(ok.sum())
        if n == 0 or (offsets and not ok.any(axis=1).all()):
            raise ValueError("the rows share no finite bin with the model" + (" in each row" if n else ""))
        diff = np.where(ok, self.curves - np.where(ok, q, 0.0), np.nan)  # (grid, 2, bins)
        if offsets:
            diff = diff - np.nanmean(diff, axis=2, keepdims=True)
        d = np.nansum(diff**2, axis=(1, 2)) / n
        return d, n

    def estimate(self, rows: npt.ArrayLike, offsets: bool = False) -> ThicknessEstimate:
        """The thickness whose model rows are nearest to ``rows`` (2 x bins, mm, NaN: no value);
        ``offsets``: free row offsets (rows from another capture session than the model's)."""
        d, n = self.mismatch(rows, offsets)
        i = int(np.argmin(d))
        n_eff = n * _independence(np.asarray(rows, dtype=np.float64) - self.curves[i], offsets)
        t = float(self.grid[i])
        if 0 < i < len(d) - 1:
            a, b, c = d[i - 1], d[i], d[i + 1]
            curvature = a - 2.0 * b + c
            if curvature > 0.0:  # the parabola's vertex lies within half a step of the grid point
                t += float(0.5 * (a - c) / curvature) * float(self.grid[1] - self.grid[0])
        # Profile likelihood: n (d - d_min) / d_min follows chi-square(1) with the residual as the
        # noise, n counting independent values: the residual is correlated along the depth (the model
        # misses smoothly), so n is the values' count scaled as for a first-order autoregression. The
        # model's own error widens it: a thickness whose rows differ from the best by less is as good.
        floor = max(float(d[i]), 1e-12)
        inside = np.nonzero(n_eff * (d - d[i]) / floor <= CHI2_95 + n_eff * self.model_error_mm**2 / floor)[0]
        half = 0.5 * float(self.grid[1] - self.grid[0])  # the grid's own resolution
        low, high = min(float(self.grid[inside[0]]), t) - half, max(float(self.grid[inside[-1]]), t) + half
        return ThicknessEstimate(t, max(low, 0.0), high, bool(inside[-1] == len(d) - 1), float(np.sqrt(d[i])),
                                 n)  # fmt: skip


def _independence(residual: npt.NDArray[np.float64], offsets: bool) -> float:
    """(1 - rho) / (1 + rho) for the residual's lag-1 correlation rho along the bins (0 <= rho < 1):
    the share of its values that count as independent."""
    num = den = 0.0
    for r in residual:
        ok = np.isfinite(r)
        x = np.where(ok, r - (np.nanmean(r) if offsets and ok.any() else 0.0), 0.0)
        pair = ok[1:] & ok[:-1]
        num += float((x[1:] * x[:-1])[pair].sum())
        den += float((x[ok] ** 2).sum())
    rho = min(max(num / den, 0.0), 0.99) if den > 0.0 else 0.0
    return (1.0 - rho) / (1.0 + rho)


def slab_params(library: MaterialLibrary, material: str, thicknesses: Iterable[float]) -> list[dict[str, Any]]:
    """The material's parameters with each of the thicknesses, named MATERIAL@Tmm (for
    Material.from_dict, or to add to a library's to_dict() for a renderer)."""
    params = library[material].to_dict()
    return [{**params, "name": f"{material}@{t:g}mm", "thickness_mm": float(t)} for t in thicknesses]


def slab_materials(library: MaterialLibrary) -> list[str]:
    """The library's slab materials (what ThicknessEstimator takes)."""
    return [m.name for m in library.materials if m.kind == "slab"]
