# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Capturing a new material's curve with the box (``tofmat table add``).

The box's tofmatd runs its hand-held profile; the user sweeps the material through the depth range
in front of the camera, several times. Each pass (from the target appearing to its ``no_target``
label) is accumulated the way the profile accumulates a query: each frame's surface (the valid
pixels of the region's depth images within 64 mm of their median) gives its mean combined depth and
the sums of its pixels' two Eq. (10) rows, added to that depth's bin (``DepthBinAccumulator.add_sums``;
binning each pixel by its own depth would sort the pixels by their noise, docs/numerics.md).
The passes' mean is the material's curve; the spread of the passes about it, pooled over the
elements two or more passes saw, is its bin noise (the session matcher's per-material noise,
stored with the table in format 1.1). With one pass the curve's roughness stands in for it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import DepthBinAccumulator, ExemplarTable, curve_roughness, unambiguous_range_mm
from .._tofmat import SURFACE_BAND_MM
from ..client import Client, DepthImage, Label

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
DEPTH_STREAMS = ("depth:80", "depth:16", "depth:120", "depth:combined")
_FREQS = {"80": 80, "16": 16, "120": 120}
# Frames whose depth images wait for their label: a few, for labels that come after their images.
_PENDING_FRAMES = 8


class CaptureError(RuntimeError):
    """The capture could not finish: no pass in time, or the daemon's table does not fit."""


@dataclass(frozen=True)
class Capture:
    curve: F32  # (rows, bins), NaN where no pass saw the element
    noise_mm: F64  # (rows,): the bin noise per row, NaN if it could not be measured
    passes: list[F32]  # each pass's curve
    noise_from: str  # "passes" (their spread) or "roughness" (one pass)


def frame_observations(images: Mapping[str, DepthImage], rows: list[tuple[int, int]]) -> tuple[F64, F64]:
    """(combined depth (n,), rows (n, len(rows))) of the frame's valid pixels. Each frequency's
    wrapped depth is unwrapped to the wrap nearest the combined depth (the decode's own unwrapping
    for a valid pixel, whose depths agree within the decode's gaps: far less than half a wrap)."""
    comb = np.asarray(images["combined"].depth_mm, dtype=np.float64).ravel()
    unwrapped: dict[int, F64] = {}
    for kind, f in _FREQS.items():
        d = np.asarray(images[kind].depth_mm, dtype=np.float64).ravel()
        r = unambiguous_range_mm(f)
        unwrapped[f] = d + r * np.round((comb - d) / r)
    values = np.stack([unwrapped[f] - unwrapped[ref] for f, ref in rows], axis=1)
    ok = np.isfinite(comb) & np.all(np.isfinite(values), axis=1)
    return comb[ok], values[ok]


def frame_surface(depth_mm: F64, values: F64) -> tuple[float, F64, int] | None:
    """A frame's surface from its valid pixels (``frame_observations``): (mean combined depth, the
    sums of the rows, pixels) of those within SURFACE_BAND_MM of the median depth; None if none.
    (The core's ``surface_mean`` also keeps to one side of every wrap: its features are differences
    of wrapped depths, these of depths unwrapped near the combined one, which have no such jump.)"""
    if depth_mm.size == 0:
        return None
    near = np.abs(depth_mm - np.median(depth_mm)) <= SURFACE_BAND_MM
    return float(depth_mm[near].mean()), values[near].sum(axis=0), int(near.sum())


def check_rows(table: ExemplarTable) -> list[tuple[int, int]]:
    rows = list(table.rows)
    if not rows or any(f not in _FREQS.values() or ref not in _FREQS.values() for f, ref in rows):
        raise CaptureError(f"the table's rows {rows} are not the Kinect v2's frequencies (16, 80, 120 MHz)")
    return rows


def capture_passes(
    client: Client,
    table: ExemplarTable,
    passes: int,
    min_bins: int,
    timeout_s: float,
    echo: Callable[[str], None] = lambda _s: None,
) -> list[F32]:
    """``passes`` hand-held passes of one target through the daemon's region (its hand-held
    profile), each a (rows, bins) curve on the table's bins. A pass under ``min_bins`` bins is
    left out, and so is one already under way when the capture starts (it would lack its start).
    Raises CaptureError when they do not come within ``timeout_s`` seconds."""
    rows = check_rows(table)
    status = client.status()
    if status.get("profile") != "handheld":
        raise CaptureError(f"tofmatd runs the {status.get('profile')} profile: set the handheld one to capture")
    client.subscribe("labels", *DEPTH_STREAMS)
    last = client.latest_label()
    skip = last is not None and last.state in ("tracking", "unknown")
    if skip:
        echo("a target is in view: its pass is left out; take it away and sweep again")
    acc = DepthBinAccumulator(table.bins, table.n_rows)
    pending: dict[int, dict[str, DepthImage]] = {}
    out: list[F32] = []
    in_pass = False
    deadline = time.monotonic() + timeout_s
    while len(out) < passes:
        left = deadline - time.monotonic()
        event = client.next_event(max(0.0, left)) if left > 0 else None
        if event is None:
            raise CaptureError(f"{len(out)} of {passes} passes within {timeout_s:g} s")
        if isinstance(event, DepthImage):
            pending.setdefault(event.frame, {})[event.kind] = event
            for old in sorted(pending)[:-_PENDING_FRAMES]:
                del pending[old]
        elif isinstance(event, Label):
            if event.state in ("tracking", "unknown"):
                in_pass = True
                images = pending.pop(event.frame, {})
                if not skip and len(images) == len(_FREQS) + 1:  # (a frame whose images were dropped: none)
                    surface = frame_surface(*frame_observations(images, rows))
                    if surface is not None:
                        acc.add_sums(*surface)
            elif event.state == "no_target" and in_pass:
                covered = acc.bins_covered()
                if skip:
                    skip = False
                elif covered >= min_bins:
                    out.append(acc.query())
                    echo(f"pass {len(out)} of {passes}: {covered} bins")
                else:
                    echo(f"a pass of {covered} bins left out (fewer than {min_bins}): sweep through more of the range")
                acc.reset()
                in_pass = False
    return out


def combine_passes(passes: list[F32], table: ExemplarTable, name: str) -> Capture:
    """The passes' mean and their pooled spread per row (module docstring)."""
    if not passes:
        raise CaptureError("no pass to combine")
    stack = np.stack([np.asarray(p, dtype=np.float64) for p in passes])  # (P, R, B)
    seen = np.isfinite(stack)
    n = seen.sum(axis=0)
    with np.errstate(invalid="ignore"):
        mean = np.where(n > 0, np.nansum(stack, axis=0) / np.maximum(n, 1), np.nan)
    dev2 = np.where(seen, (stack - mean[None]) ** 2, 0.0).sum(axis=0)  # (R, B)
    dof = np.maximum(n - 1, 0).sum(axis=1)  # per row
    if np.all(dof >= 5):
        noise = np.sqrt(dev2.sum(axis=1) / dof)
        source = "passes"
    else:
        one = ExemplarTable([name], mean[None].astype(np.float32), table.bins, table.rows)
        noise = curve_roughness(one)[0]
        source = "roughness"
    return Capture(mean.astype(np.float32), noise, list(passes), source)


def with_material(table: ExemplarTable, name: str, capture: Capture, replace: bool = False) -> ExemplarTable:
    """``table`` with the captured material added (or, with ``replace``, in place of its old curve)
    and its noise stored; the other materials keep theirs (NaN where the table had none), and
    everything else the table carries, its depth distortion and its calibration included. A hand-held capture measures
    no absolute distortion (it has no true depth), so the captured material has none: NaN, which
    tofmatd's corrected depth leaves uncorrected (a replaced material loses its old one, which
    belonged to the old curve)."""
    names = list(table.materials)
    features = table.features
    noise = table.noise_mm if table.noise_mm is not None else np.full((len(names), table.n_rows), np.nan)
    grid, distortion = table.distortion_grid, table.distortion_mm
    if not np.isfinite(capture.curve).any():
        raise CaptureError("the capture observed no element of the table's bins")
    if name in names:
        if not replace:
            raise CaptureError(f"the table already has '{name}': give --replace to capture it again")
        i = names.index(name)
        features = features.copy()
        features[i] = capture.curve
        noise = noise.copy()
        noise[i] = capture.noise_mm
        out = ExemplarTable(names, features, table.bins, table.rows, noise)
        if distortion is not None:
            distortion = distortion.copy()
            distortion[i] = np.nan
    else:
        out = ExemplarTable(
            [*names, name],
            np.concatenate([features, capture.curve[None]]),
            table.bins,
            table.rows,
            np.concatenate([noise, capture.noise_mm[None]]),
        )
        if distortion is not None:
            distortion = np.concatenate([distortion, np.full((1, distortion.shape[1]), np.nan)])
    out = out.with_distortion(grid, distortion) if distortion is not None else out
    return out.with_calibration(table.calibration)  # (its prior and temperatures were fitted without the new one)
