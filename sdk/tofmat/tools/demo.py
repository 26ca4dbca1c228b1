# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The live demo on the real database: simulated hand-held sweeps, classified as they grow.

Each sweep moves one material through part of the depth range. Every frame
adds a noisy observation of the real curve at the current depth to a
DepthBinAccumulator; after every frame the partial query is classified with
Eq. (12), as the paper's real-time system does. (The daemon issue replaces this
with tofmatd on the simulated camera.)
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .. import Classifier, DepthBinAccumulator, ExemplarTable

REPORT_AT = (1, 2, 3, 5, 8, 13, 20, 30, 45, 60, 90)


@dataclass
class DemoStats:
    sweeps: int = 0
    correct_final: int = 0
    # bins covered -> [correct, total] over all sweeps at that point
    by_bins: dict[int, list[int]] = field(default_factory=dict)
    classify_ns: list[int] = field(default_factory=list)


def run_sweep(
    table: ExemplarTable,
    clf: Classifier,
    material: int,
    n_bins: int,
    frames_per_bin: int,
    noise_mm: float,
    rng: np.random.Generator,
    stats: DemoStats,
    echo: Callable[[str], None],
) -> bool:
    curve = table.features[material]
    bins = table.bins
    start = int(rng.integers(0, table.n_bins - n_bins + 1))
    path = np.arange(start, start + n_bins)
    if rng.random() < 0.5:  # moving away or towards the camera
        path = path[::-1]
    acc = DepthBinAccumulator(bins, table.n_rows)
    name = table.materials[material]
    lo, hi = bins.edges_mm[path.min()], bins.edges_mm[path.max() + 1]
    echo(f"sweep {stats.sweeps + 1}: {name} moving {'away' if path[0] < path[-1] else 'closer'}, {lo:.0f}..{hi:.0f} mm")
    label = None
    for b in path:
        for _ in range(frames_per_bin):
            depth = bins.edges_mm[b] + rng.uniform(0.05, 0.95) * bins.width_mm
            acc.add(depth, curve[:, b] + rng.normal(0.0, noise_mm, table.n_rows).astype(np.float32))
        covered = acc.bins_covered()
        if covered == 0:
            continue  # this bin is missing in the real curve: nothing to match yet
        t0 = time.perf_counter_ns()
        result = clf.classify(acc.query())
        stats.classify_ns.append(time.perf_counter_ns() - t0)
        label = result.index
        ok = label == material
        tally = stats.by_bins.setdefault(covered, [0, 0])
        tally[0] += ok
        tally[1] += 1
        if covered in REPORT_AT or b == path[-1]:
            mark = "ok" if ok else f"wrong (truth: {name})"
            echo(f"  {covered:3d} bins  label {result.material:<12s} distance {result.distance:8.3f} mm^2  {mark}")
    stats.sweeps += 1
    stats.correct_final += label == material
    return label == material


def run_demo(
    table: ExemplarTable,
    sweeps: int,
    sweep_bins: int,
    frames_per_bin: int,
    noise_mm: float,
    seed: int,
    echo: Callable[[str], None] = print,
) -> DemoStats:
    if not 1 <= sweep_bins <= table.n_bins:
        raise ValueError(f"sweep length must be 1..{table.n_bins} bins")
    rng = np.random.default_rng(seed)
    clf = Classifier(table, backend="float")
    stats = DemoStats()
    order = rng.permutation(len(table.materials))
    for i in range(sweeps):
        material = int(order[i % len(order)])
        run_sweep(table, clf, material, sweep_bins, frames_per_bin, noise_mm, rng, stats, echo)
        echo(f"  accuracy so far: {stats.correct_final}/{stats.sweeps} sweeps")
    echo("")
    echo("accuracy vs bins covered (all sweeps):")
    for n in sorted(k for k in stats.by_bins if k in REPORT_AT or k == sweep_bins):
        c, t = stats.by_bins[n]
        echo(f"  {n:3d} bins: {100 * c / t:5.1f} %  ({c}/{t})")
    ns = np.array(stats.classify_ns)
    echo(
        f"final labels: {stats.correct_final}/{stats.sweeps} correct; "
        f"classify latency median {np.median(ns) / 1e3:.1f} us, p99 {np.percentile(ns, 99) / 1e3:.1f} us"
    )
    return stats
