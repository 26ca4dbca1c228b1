# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat bench-targets`: still targets and sweeps through tofmatd's live hand-held path, against
the table the simulated camera recorded.

For every depth and angle of a grid, tofmatd runs on the simulated camera with one still target of
each material after another (``sim:sweep`` with ``near = far``, a few frames apart, so each target
starts a new accumulation), and for every angle a hand-held sweep of each material over the table's
range. Two daemons see the same frames: one with the default (session) matcher, whose final label
and confidence per target are what a user gets, and one with the paper's Eq. (12), whose distance
to the true material says whether the live query agrees with the table (it should be within the
noise: a few hundredths of a mm^2).

A target is also judged among the materials it can be told from: the candidates whose curves differ
from its own over the bins it covered by more than ``SEPARABLE_MM`` rms. Among near twins (cork and
wood at 900 mm differ by 0.2 mm) one position cannot name the material; the label must then not be
confident.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import ExemplarTable
from .._progress import Progress
from ..client import Client, DepthImage, Label
from .live_demo import connect, start_daemon, stop_daemon_or_raise

# Curves closer than this (rms over the target's bins, mm) are not told apart by one target.
SEPARABLE_MM = 0.5
# A label this confident is a promise: wrong at or above it is a defect (issue 32).
CONFIDENT = 0.9


@dataclass(frozen=True)
class TargetResult:
    kind: str  # "still" or "sweep"
    material: str
    near_mm: float
    far_mm: float
    yaw_deg: float
    label: str | None  # the default matcher's final label (None: unknown or none)
    confidence: float | None
    bins: int  # bins the final label's query covered
    eq12_truth: float  # Eq. (12) distance of the live query to the true material's curve, mm^2
    eq12_best: str  # Eq. (12)'s nearest material
    separable: tuple[str, ...]  # the candidates this target can be told from (and itself)
    label_among_separable: str | None  # the first of those in the default matcher's ranking

    @property
    def correct(self) -> bool:
        return self.label == self.material

    @property
    def confidently_wrong(self) -> bool:
        return not self.correct and self.confidence is not None and self.confidence >= CONFIDENT


@dataclass(frozen=True)
class _Seen:
    label: Label  # the target's last label
    measured_mm: tuple[float, float]  # the range of its frames' median combined depths


def _final_labels(client: Client, n: int, timeout_s: float) -> list[_Seen]:
    """The last label of each of the next n targets (a target ends at no_target), with the measured
    depths its frames covered. The target in view when the client arrived is left out: it may have
    started before."""
    client.subscribe("labels", "depth:combined")
    out: list[_Seen] = []
    last: Label | None = None
    depths: list[float] = []
    started = False
    deadline = time.monotonic() + timeout_s
    while len(out) < n:
        left = deadline - time.monotonic()
        event = client.next_event(left) if left > 0 else None
        if event is None:
            raise RuntimeError(f"tofmatd labelled {len(out)} of {n} targets within {timeout_s:g} s")
        if isinstance(event, DepthImage):
            z = np.asarray(event.depth_mm, dtype=np.float64)
            if started and np.isfinite(z).any():
                depths.append(float(np.nanmedian(z)))
        elif isinstance(event, Label) and event.state == "no_target":
            if started and last is not None and depths:
                out.append(_Seen(last, (min(depths), max(depths))))
            started, last, depths = True, None, []
        elif isinstance(event, Label) and started:
            last = event
    return out


def _run(table: Path, source: str, extra: list[str], n: int, timeout_s: float) -> list[_Seen]:
    with tempfile.TemporaryDirectory(prefix="tofmat-targets-") as tmp:
        sock, log = Path(tmp) / "tofmatd.sock", Path(tmp) / "log"
        daemon = start_daemon(table, sock, source, log, "handheld", ["--top-k", "64", *extra])
        try:
            with connect(sock, daemon) as c:
                seen = _final_labels(c, n, timeout_s)
        finally:
            stop_daemon_or_raise(daemon, log, print)
    return seen


def _separable(t: ExemplarTable, truth: str, query_bins: tuple[float, float]) -> tuple[str, ...]:
    lo, hi = t.bins.index_of(query_bins[0]), t.bins.index_of(query_bins[1])
    lo, hi = max(lo, 0), (hi if hi >= 0 else t.n_bins - 1) + 1
    own = t.features[t.index_of(truth), :, lo:hi]
    out = []
    for m in t.materials:
        d = t.features[t.index_of(m), :, lo:hi] - own
        d = d[np.isfinite(d)]
        if m == truth or (d.size and float(np.sqrt(np.mean(d**2))) > SEPARABLE_MM):
            out.append(m)
    return tuple(out)


def scenes(
    t: ExemplarTable, depths: list[float], yaws: list[float], sweeps: bool
) -> Iterator[tuple[str, float, float, float]]:
    """(kind, near, far, yaw) of every scene of the grid: stills at each depth and angle, a sweep
    over the table's range (less 30 mm at each end) at each angle."""
    for yaw in yaws:
        for d in depths:
            yield "still", d, d, yaw
        if sweeps:
            yield "sweep", t.bins.start_mm + 30.0, t.bins.edges_mm[-1] - 30.0, yaw


def bench_targets(
    table_path: Path,
    depths: list[float],
    yaws: list[float],
    sweeps: bool = True,
    still_frames: int = 10,
    sweep_frames: int = 90,
    materials: list[str] | None = None,
    progress: Progress | None = None,
    labeller_args: list[str] | None = None,
) -> list[TargetResult]:
    """``labeller_args``: more tofmatd flags for the daemon whose labels are counted (the other one
    runs --classifier eq12 for the distances)."""
    t = ExemplarTable.load(table_path)
    mats = materials or list(t.materials)
    out: list[TargetResult] = []
    grid = list(scenes(t, depths, yaws, sweeps))
    for k, (kind, near, far, yaw) in enumerate(grid):
        frames = still_frames if kind == "still" else sweep_frames
        source = (f"sim:sweep,materials={'+'.join(mats)},near={near:g},far={far:g},frames={frames},gap=3,"
                  f"yaw={yaw:g}")  # fmt: skip
        timeout = 30.0 + (frames + 3) * len(mats) * 2 / 30.0
        if progress:
            progress(k, len(grid), f"{kind} {near:g}..{far:g} mm, {yaw:g} deg")
        # The two daemons side by side (one core each) see the same frames: the simulator is seeded.
        with ThreadPoolExecutor(2) as pool:
            jobs = [pool.submit(_run, table_path, source, extra, len(mats), timeout)
                    for extra in (list(labeller_args or []), ["--classifier", "eq12"])]  # fmt: skip
            runs = [j.result() for j in jobs]  # (a daemon's failure is raised here)
        if len(runs[0]) != len(mats) or len(runs[1]) != len(mats):
            raise RuntimeError(f"tofmatd did not label every target of {source}")
        for sa, sb in zip(runs[0], runs[1], strict=True):
            a, b = sa.label, sb.label
            truth = a.truth.material if a.truth and a.truth.material else None
            if truth is None or b.truth is None or b.truth.material != truth:
                raise RuntimeError(f"the two daemons saw different targets ({a.truth}, {b.truth})")
            dist = {r.material: r.distance for r in b.ranking}
            # The bins the target covered: its frames' measured depths, half a bin either side.
            half = t.bins.width_mm / 2.0
            sep = _separable(t, truth, (sa.measured_mm[0] - half, sa.measured_mm[1] + half))
            among = [r.material for r in a.ranking if r.material in sep]
            out.append(
                TargetResult(
                    kind,
                    truth,
                    near,
                    far,
                    yaw,
                    a.material if a.state == "tracking" else None,
                    a.confidence,
                    a.bins_covered,
                    float(dist.get(truth, np.inf)),
                    b.ranking[0].material,
                    sep,
                    among[0] if among else None,
                )
            )
    return out


def summary(results: list[TargetResult]) -> dict[str, object]:
    """The figures: per kind, labels right, right among the separable candidates, confidently wrong,
    and the Eq. (12) distance to the truth (median and worst)."""
    out: dict[str, object] = {}
    for kind in ("still", "sweep"):
        rs = [r for r in results if r.kind == kind]
        if not rs:
            continue
        d = np.array([r.eq12_truth for r in rs])
        out[kind] = {
            "targets": len(rs),
            "right": sum(r.correct for r in rs),
            "right_among_separable": sum(r.label_among_separable == r.material for r in rs),
            "confidently_wrong": sum(r.confidently_wrong for r in rs),
            "eq12_truth_median_mm2": float(np.median(d)),
            "eq12_truth_worst_mm2": float(d.max()),
            "worst": asdict(max(rs, key=lambda r: r.eq12_truth)),
        }
    return out


def format_markdown(results: list[TargetResult]) -> str:
    """One line per (kind, depth, angle): labels right, confidently wrong, Eq. (12) distances."""
    lines = [
        "| kind | depth (mm) | angle (deg) | right | right among separable | confident and wrong | "
        "Eq. (12) to truth, median / worst (mm^2) |",
        "|---|---|---|---|---|---|---|",
    ]
    keys = sorted({(r.kind, r.near_mm, r.far_mm, r.yaw_deg) for r in results}, key=lambda k: (k[0], k[3], k[1]))
    for kind, near, far, yaw in keys:
        rs = [r for r in results if (r.kind, r.near_mm, r.far_mm, r.yaw_deg) == (kind, near, far, yaw)]
        d = np.array([r.eq12_truth for r in rs])
        depth = f"{near:g}" if near == far else f"{near:g}..{far:g}"
        lines.append(
            f"| {kind} | {depth} | {yaw:g} | {sum(r.correct for r in rs)}/{len(rs)} | "
            f"{sum(r.label_among_separable == r.material for r in rs)}/{len(rs)} | "
            f"{sum(r.confidently_wrong for r in rs)} | {np.median(d):.3f} / {d.max():.3f} |"
        )
    return "\n".join(lines)
