# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""An exemplar table recorded with the simulated camera.

What a sensor box does with its own camera before it labels anything: every material is moved
through the depth range in front of it, and each frame's region of interest goes through the same
decode as tofmatd's (the simulated device's P0 tables, the 11-bit samples, the camera's
unwrapping and validity rules). The two Eq. (10) rows, averaged over the region's valid pixels,
are binned by the camera's own combined depth: that is the bin a hand-held query lands in.
"""

from __future__ import annotations

import numpy as np

from .. import BinSpec, ExemplarTable
from .._progress import Progress
from .._tofmat import decode_frame
from . import Renderer, Scene

ROWS = [(16, 120), (80, 120)]
ROI = (232, 188, 280, 236)  # tofmatd's default handheld ROI: 48 x 48 at the centre


def database_bins(n_bins: int = 200) -> BinSpec:
    """The real database's binning: n bins of (1200 - 600) / (n - 1) mm from 600 mm (3.015 mm for 200)."""
    return BinSpec(600.0, (1200.0 - 600.0) / (n_bins - 1), n_bins)


def roi_observation(
    renderer: Renderer, p0: np.ndarray, material: str, depth_mm: float, yaw_deg: float, seed: int
) -> tuple[float, np.ndarray] | None:
    """(combined depth, the two rows) averaged over the ROI's valid pixels; None if none is valid."""
    x0, y0, x1, y1 = ROI
    frame = renderer.render_region(Scene.centred_target(material, depth_mm, yaw_deg, 160), seed, True, ROI)
    raw = np.asarray(frame.raw).reshape(9, -1)
    d = decode_frame(raw, np.ascontiguousarray(p0[:, y0:y1, x0:x1]).reshape(3, -1))
    ok = np.asarray(d.flags) == 0
    if not ok.any():
        return None
    features = np.asarray(d.features)[:, ok].astype(np.float64)
    return float(np.mean(np.asarray(d.combined_mm)[ok])), features.mean(axis=1)


def simulated_table(
    renderer: Renderer,
    materials: list[str],
    bins: BinSpec,
    yaw_deg: float = 10.0,
    step_mm: float = 4.0,
    seed: int = 7,
    progress: Progress | None = None,
) -> ExemplarTable:
    """Sweeps of `materials` over the bins' range (plus a margin) every `step_mm`, resampled at
    the bin centres of the measured combined depth; bins a sweep does not reach are missing."""
    if not materials:
        raise ValueError("no materials to record")
    p0 = np.asarray(renderer.p0_tables())
    centres = bins.start_mm + bins.width_mm * (np.arange(bins.count) + 0.5)
    depths = np.arange(centres[0] - 60.0, centres[-1] + 60.0 + 1e-9, step_mm)
    features = []
    for k, name in enumerate(materials):
        if progress:
            progress(k, len(materials), name)
        obs = [
            roi_observation(renderer, p0, name, float(z), yaw_deg, seed + 1000 * k + i) for i, z in enumerate(depths)
        ]
        got = [o for o in obs if o is not None]
        out = np.full((2, bins.count), np.nan, np.float32)
        if len(got) >= 2:
            combined = np.array([o[0] for o in got])
            rows = np.stack([o[1] for o in got], axis=1)
            order = np.argsort(combined)
            inside = (centres >= combined[order][0]) & (centres <= combined[order][-1])
            for r in range(2):
                out[r, inside] = np.interp(centres[inside], combined[order], rows[r, order])
        features.append(out)
    if progress:
        progress(len(materials), len(materials), "recorded")
    return ExemplarTable(list(materials), np.stack(features), bins, ROWS)
