# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat bench-thickness`: a slab's thickness from its sweep, against the truth, by thickness.

Slabs of one calibrated slab material (its parameters, the thickness varied) are swept through
600..1200 mm in front of the simulated camera, 10 degrees off facing it, as ``tofmat sim table``
sweeps a material: the ROI's mean rows against its combined depth, binned as the database bins.
Each sweep, or a window of it, goes to ``ThicknessEstimator`` (sim/thickness.py):

- same session: the rows as rendered, matched without offsets (the model's own camera state);
- new session: each row shifted by a capture session's offset (drawn from the spread the
  calibration found between the database's captures) and matched with free row offsets, as rows
  from a real camera would be.

Per thickness it reports the estimate's median error, the median and 95th percentile of the
absolute error, how often the 95 % interval holds the truth, and how often the interval is open
above (the rows cannot tell the slab from a thicker one).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np
import numpy.typing as npt

from .. import BinSpec
from .._clikit import strict_json
from .._progress import Progress
from ..sim import MaterialLibrary, Renderer, library_path, load_device, load_library
from ..sim.evaluate import session_offset_spread
from ..sim.table import database_bins, roi_observation
from ..sim.thickness import ThicknessEstimate, ThicknessEstimator, slab_params

DEFAULT_THICKNESSES = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0)
SWEEP_STEP_MM = 3.0  # one frame every 3 mm of the stage: a bin of the database's about every frame
YAW_DEG = 10.0


@dataclass(frozen=True)
class ThicknessRow:
    thickness_mm: float
    session: str  # "same" or "new"
    bins: int  # the sweep's length in bins (0: the whole sweep)
    sweeps: int
    median_error_mm: float
    median_abs_error_mm: float
    p95_abs_error_mm: float
    covered: float  # share of intervals holding the truth
    open_above: float  # share of intervals open above
    median_width_mm: float  # of the closed intervals (NaN: none closed)


def sweep_rows(renderer: Renderer, material: str, bins: BinSpec, seed: int) -> npt.NDArray[np.float64]:
    """A stage sweep's rows (2, bins): the ROI means of the frames whose combined depth falls in
    each bin, averaged; NaN where no frame fell."""
    p0 = np.asarray(renderer.p0_tables())
    sums = np.zeros((2, bins.count))
    counts = np.zeros(bins.count)
    stage = np.arange(bins.start_mm - 40.0, bins.start_mm + bins.width_mm * bins.count + 40.0, SWEEP_STEP_MM)
    for i, z in enumerate(stage):
        obs = roi_observation(renderer, p0, material, float(z), YAW_DEG, seed * 100_003 + i)
        if obs is None:
            continue
        b = int(np.floor((obs[0] - bins.start_mm) / bins.width_mm))
        if 0 <= b < bins.count:
            sums[:, b] += obs[1]
            counts[b] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / counts


def window(rows: npt.NDArray[np.float64], length: int, rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """A contiguous window of `length` bins at a random place among the bins both rows have (the
    whole sweep for 0 or a length beyond it), NaN elsewhere."""
    filled = np.nonzero(np.isfinite(rows).all(axis=0))[0]
    if length <= 0 or length >= len(filled):
        return rows
    start = int(rng.integers(0, len(filled) - length + 1))
    keep = np.zeros(rows.shape[1], bool)
    keep[filled[start : start + length]] = True
    return np.where(keep[None, :], rows, np.nan)


def bench_thickness(material: str = "acryl3mm", thicknesses: tuple[float, ...] = DEFAULT_THICKNESSES,
                    sweeps: int = 5, lengths: tuple[int, ...] = (0, 30), seed: int = 11,
                    progress: Progress | None = None) -> list[ThicknessRow]:  # fmt: skip
    device, library = load_device(), load_library()
    bins = database_bins()
    estimator = ThicknessEstimator(device, library, material, bins)
    slabs = slab_params(library, material, thicknesses)
    names = [p["name"] for p in slabs]
    lib = library.to_dict()
    lib["materials"] = [*lib["materials"], *slabs]
    renderer = Renderer(device, MaterialLibrary.from_dict(lib), 1)
    spread = session_offset_spread(json.loads(library_path("tanaka2017").read_text()))
    rng = np.random.default_rng(seed)
    rows: list[ThicknessRow] = []
    for k, (name, t) in enumerate(zip(names, thicknesses, strict=True)):
        if progress:
            progress(k, len(thicknesses), f"{t:g} mm")
        captured = [sweep_rows(renderer, name, bins, seed + 1000 * k + s) for s in range(sweeps)]
        for session in ("same", "new"):
            for length in lengths:
                got: list[ThicknessEstimate] = []
                for q in captured:
                    q = window(q, length, rng)
                    if session == "new":  # a capture session's row offsets: d16 - d120 and d80 - d120
                        q = q + np.array([[rng.normal(0.0, spread[0])], [rng.normal(0.0, spread[1])]])
                    got.append(estimator.estimate(q, offsets=session == "new"))
                err = np.array([e.thickness_mm - t for e in got])
                rows.append(ThicknessRow(
                    t, session, length, sweeps, float(np.median(err)), float(np.median(np.abs(err))),
                    float(np.percentile(np.abs(err), 95)),
                    float(np.mean([e.low_mm <= t <= e.high_mm for e in got])),
                    float(np.mean([e.open_above for e in got])),
                    float(np.median([e.high_mm - e.low_mm for e in closed])) if (closed := [
                        e for e in got if not e.open_above]) else float("nan")))  # fmt: skip
    if progress:
        progress(len(thicknesses), len(thicknesses), "done")
    return rows


def format_markdown(rows: list[ThicknessRow]) -> str:
    out = ["| thickness | session | sweep | median error | median abs error | p95 abs error | interval holds it "
           "| open above | closed intervals' median width |", "|---:|---|---|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for r in rows:
        length = "whole" if r.bins == 0 else f"{r.bins} bins"
        out.append(f"| {r.thickness_mm:g} mm | {r.session} | {length} | {r.median_error_mm:+.3f} mm | "
                   f"{r.median_abs_error_mm:.3f} mm | {r.p95_abs_error_mm:.3f} mm | {100 * r.covered:.0f} % | "
                   f"{100 * r.open_above:.0f} % | "
                   f"{'-' if np.isnan(r.median_width_mm) else f'{r.median_width_mm:.2f} mm'} |")  # fmt: skip
    return "\n".join(out)


def format_json(rows: list[ThicknessRow]) -> str:
    return json.dumps(strict_json([asdict(r) for r in rows]), indent=2)
