# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Accuracy and run time of the classifier on noisy windows of the real curves.

Error and latency are always reported together (DESIGN.md section 6). This is a
benchmark: it prints figures and never asserts on time.
"""

from __future__ import annotations

import platform
import time
from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np

from .. import Classifier, ExemplarTable
from ..client import Backend
from .sweeps import random_windows


@dataclass(frozen=True)
class BenchRow:
    backend: str
    window_bins: int
    queries: int
    accuracy: float  # fraction of windows labelled with their own material
    us_per_query: float  # median of single classify() calls, Python call included (best of `repeats`)
    us_per_query_batch: float  # classify_batch() wall time / queries (best of `repeats`)
    # Most frequent confused pairs (material a, material b, count), either direction.
    confusions: list[tuple[str, str, int]] = field(default_factory=list)

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def bench_windows(
    table: ExemplarTable,
    windows: list[int],
    noise_mm: float = 0.3,
    per_material: int = 40,
    seed: int = 0,
    backend: Backend = "float",
    repeats: int = 3,
) -> list[BenchRow]:
    """Timings are the best of `repeats` passes: on a shared machine the
    slower passes measure the neighbours, not the code."""
    clf = Classifier(table, backend=backend, method="eq12")
    rows: list[BenchRow] = []
    for length in windows:
        rng = np.random.default_rng(seed + length)
        ws = list(random_windows(table, length, noise_mm, per_material, rng))
        queries = np.stack([w.query for w in ws])
        truth = np.array([w.material for w in ws])
        times = np.empty(len(ws))
        labels = np.empty(len(ws), dtype=np.int64)
        single_ns = batch_ns = float("inf")
        for _ in range(max(1, repeats)):
            for i, q in enumerate(queries):
                t0 = time.perf_counter_ns()
                labels[i] = clf.classify(q).index
                times[i] = time.perf_counter_ns() - t0
            single_ns = min(single_ns, float(np.median(times)))
            t0 = time.perf_counter_ns()
            batch = clf.classify_batch(queries)
            batch_ns = min(batch_ns, time.perf_counter_ns() - t0)
        if any(b.index != lab for b, lab in zip(batch, labels, strict=True)):
            raise RuntimeError("classify_batch disagrees with classify")
        pairs: Counter[tuple[str, str]] = Counter()
        for t, lab in zip(truth, labels, strict=True):
            if t != lab:
                a, b = sorted((table.materials[t], table.materials[lab]))
                pairs[(a, b)] += 1
        rows.append(
            BenchRow(
                backend=backend,
                window_bins=length,
                queries=len(ws),
                accuracy=float(np.mean(labels == truth)),
                us_per_query=single_ns / 1e3,
                us_per_query_batch=batch_ns / 1e3 / len(ws),
                confusions=[(a, b, n) for (a, b), n in pairs.most_common(5)],
            )
        )
    return rows


def format_markdown(rows: list[BenchRow], noise_mm: float) -> str:
    lines = [
        f"host: {platform.machine()} {platform.processor() or ''}".rstrip(),
        f"noise: N(0, {noise_mm} mm) on every element of the window",
        "",
        "| backend | window (bins) | queries | accuracy | us/query (single) | us/query (batch) |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.backend} | {r.window_bins} | {r.queries} | {100 * r.accuracy:.1f} % "
            f"| {r.us_per_query:.1f} | {r.us_per_query_batch:.1f} |"
        )
    lines.append("")
    for r in rows:
        if r.confusions:
            pairs = ", ".join(f"{a}/{b} {n}" for a, b, n in r.confusions)
            lines.append(f"most confused at {r.window_bins} bins ({r.backend}): {pairs}")
    return "\n".join(lines)
