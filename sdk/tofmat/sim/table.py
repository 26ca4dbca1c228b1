# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""An exemplar table recorded with the simulated camera.

What a sensor box does with its own camera before it labels anything: every material is moved
through the depth range in front of it, and each frame's region of interest goes through the same
decode as tofmatd's (the simulated device's P0 tables, the 11-bit samples, the camera's
unwrapping and validity rules). The two Eq. (10) rows, averaged over the region's valid pixels,
are binned by the camera's own combined depth: that is the bin a hand-held query lands in.

The same sweeps give each material's absolute depth distortion (Eq. (8): the combined depth minus
the true range along the ray), which the database cannot: its rows are relative (Eq. (10)). A table
carrying it lets tofmatd serve a material-corrected depth.
"""

from __future__ import annotations

import json

import numpy as np

from .. import BinSpec, ExemplarTable
from .._progress import Progress
from .._tofmat import DecodedFrame, decode_frame, surface_mean
from . import Frame, Renderer, Scene, library_path

ROWS = [(16, 120), (80, 120)]
ROI = (232, 188, 280, 236)  # tofmatd's default handheld ROI: 48 x 48 at the centre
# Where a table's depth distortion is sampled: every 4 mm of measured depth from 452 to 2448 mm
# (the ranges along the rays of targets at 600..1200 mm reach about 1.6 m at the frame's corners).
DISTORTION_GRID = BinSpec(450.0, 4.0, 500)


def database_bins(n_bins: int = 200, first_mm: float = 600.0, last_mm: float = 1200.0) -> BinSpec:
    """The real database's binning by default: n bins of (last - first) / (n - 1) mm from `first`
    (3.015 mm for 200 over 600..1200 mm)."""
    if n_bins < 2 or not last_mm > first_mm:
        raise ValueError(f"bins need n >= 2 and last > first (got {n_bins}, {first_mm:g}..{last_mm:g} mm)")
    return BinSpec(first_mm, (last_mm - first_mm) / (n_bins - 1), n_bins)


def _roi_frame(
    renderer: Renderer, p0: np.ndarray, material: str, depth_mm: float, yaw_deg: float, seed: int
) -> tuple[Frame, DecodedFrame, np.ndarray]:
    """A centred target rendered in the ROI, its decode, and the mask of its valid pixels."""
    x0, y0, x1, y1 = ROI
    frame = renderer.render_region(Scene.centred_target(material, depth_mm, yaw_deg, 160), seed, True, ROI)
    d = decode_frame(np.asarray(frame.raw).reshape(9, -1), np.ascontiguousarray(p0[:, y0:y1, x0:x1]).reshape(3, -1))
    return frame, d, np.asarray(d.flags) == 0


def roi_observation(
    renderer: Renderer, p0: np.ndarray, material: str, depth_mm: float, yaw_deg: float, seed: int
) -> tuple[float, np.ndarray] | None:
    """(combined depth, the two rows) averaged over the ROI's surface as tofmatd takes it (the valid
    pixels near their median depth, on its side of every frequency's wrap: ``surface_mean``); None
    if no pixel is valid, or none lies near the median (valid pixels in two clusters farther apart
    than the surface's band, the median between them: tofmatd bins nothing from such a frame)."""
    _, d, ok = _roi_frame(renderer, p0, material, depth_mm, yaw_deg, seed)
    if not ok.any():
        return None
    depth, sums, pixels = surface_mean(d, float(np.median(np.asarray(d.combined_mm)[ok])))
    if pixels == 0:
        return None
    return depth, sums / pixels


def library_fit_rms(library: str) -> dict[str, float]:
    """Each material's fit to the real database's relative rows, rms in mm, from a library file (by
    name or path): how far its simulated response, and so its absolute distortion, can be trusted.
    Empty for a library without fits (the examples)."""
    out: dict[str, float] = {}
    for m in json.loads(library_path(library).read_text()).get("materials", []):
        fit = m.get("fit") or {}
        if isinstance(fit.get("rms_mm"), (int, float)):
            out[str(m["name"])] = float(fit["rms_mm"])
    return out


def roi_distortion(
    renderer: Renderer, p0: np.ndarray, material: str, depth_mm: float, yaw_deg: float, seed: int
) -> tuple[float, float] | None:
    """(combined depth, combined depth minus the true range) averaged over the ROI's valid pixels."""
    frame, d, ok = _roi_frame(renderer, p0, material, depth_mm, yaw_deg, seed)
    true_range = np.asarray(frame.range_mm).reshape(-1)
    ok &= np.isfinite(true_range)
    if ok.sum() < 10:
        return None
    combined = np.asarray(d.combined_mm)[ok].astype(np.float64)
    return float(combined.mean()), float((combined - true_range[ok]).mean())


def depth_distortion(
    renderer: Renderer,
    materials: list[str],
    grid: BinSpec = DISTORTION_GRID,
    yaw_deg: float = 10.0,
    seed: int = 11,
    progress: Progress | None = None,
) -> np.ndarray:
    """Each material's distortion of the combined depth (Eq. (8), mm), shape (len(materials),
    grid.count), at the grid's bin centres of the measured depth: a centred target swept in true
    depth over the grid's range and 250 mm beyond it, every grid step. A sample is NaN where the sweep
    measured no depth within two steps of it (too dark, saturated, or out of the sweep)."""
    p0 = np.asarray(renderer.p0_tables())
    centres = grid.start_mm + grid.width_mm * (np.arange(grid.count) + 0.5)
    depths = np.arange(grid.start_mm - 250.0, grid.start_mm + grid.width_mm * grid.count + 250.0, grid.width_mm)
    out = np.full((len(materials), grid.count), np.nan)
    for k, name in enumerate(materials):
        if progress:
            progress(k, len(materials), f"{name}: depth distortion")
        obs = [roi_distortion(renderer, p0, name, float(z), yaw_deg, seed + 1000 * k + i) for i, z in enumerate(depths)]
        got = np.array([o for o in obs if o is not None]).reshape(-1, 2)
        if len(got) < 2:
            continue
        got = got[np.argsort(got[:, 0])]
        near = np.abs(centres[:, None] - got[None, :, 0]).min(axis=1) <= 2.0 * grid.width_mm
        inside = (centres >= got[0, 0]) & (centres <= got[-1, 0]) & near
        out[k, inside] = np.interp(centres[inside], got[:, 0], got[:, 1])
    return out


def simulated_table(
    renderer: Renderer,
    materials: list[str],
    bins: BinSpec,
    yaw_deg: float = 10.0,
    step_mm: float = 4.0,
    seed: int = 7,
    progress: Progress | None = None,
    distortion: bool = True,
) -> ExemplarTable:
    """Sweeps of `materials` over the bins' range (plus a margin) every `step_mm`, resampled at
    the bin centres of the measured combined depth; bins a sweep does not reach are missing.
    With `distortion`, the table carries each material's depth distortion (depth_distortion)."""
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
    table = ExemplarTable(list(materials), np.stack(features), bins, ROWS)
    if distortion:
        table = table.with_distortion(DISTORTION_GRID, depth_distortion(renderer, materials, yaw_deg=yaw_deg))
    if progress:
        progress(len(materials), len(materials), "recorded")
    return table
