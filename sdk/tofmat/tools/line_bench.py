# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat bench-line`: how many items a minute the simulated sorting line sorts right.

Runs `tofmat line-demo`'s line (tools/line_demo.py) over a grid of belt speeds, offered rates and
seeds and prints one markdown row per speed and rate, pooled over the seeds. Offered rates are given
as a load: the fraction of what the belt can carry at that speed, an item and the loader's 20 mm
between items (``capacity_per_min``). The simulated belt never puts an item closer than that, so a
load above 1 is a belt packed as tight as the loader goes.

A benchmark: it prints figures and never fails on them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .._progress import Progress
from .line_demo import LineResult, LineSetup, run_line

LOADER_GAP_MM = 20.0  # the simulated loader's least gap between items (firmware/daemon/src/belt_sim.cpp)
RIGHT_TARGET = 0.99


def capacity_per_min(setup: LineSetup) -> float:
    """Items a minute the belt carries packed tight: one item and the loader's gap per pitch."""
    return 60.0 * setup.speed_mm_s / (setup.item_mm + LOADER_GAP_MM)


@dataclass
class Cell:
    """One speed, rate and burst, pooled over its seeds."""

    setup: LineSetup
    load: float
    runs: list[LineResult]

    def items(self) -> int:
        return sum(r.items for r in self.runs)

    def right_fraction(self) -> float:
        """Right among the items whose truth is known (the simulated belt's item, from the barrier)."""
        known = self.items() - sum(r.missing_truth() for r in self.runs)
        return sum(r.right() for r in self.runs) / known if known else 0.0

    def worst_seed(self) -> float:
        return min((r.right_fraction() for r in self.runs), default=0.0)

    def per_min(self) -> float:
        """Items a minute through the barrier (each run's from its first item's edge to its last's), mean."""
        rates = [r.per_min() for r in self.runs if r.items >= 2]
        return sum(rates) / len(rates) if rates else 0.0

    def reasons(self) -> Counter[str]:
        total: Counter[str] = Counter()
        for r in self.runs:
            total.update(r.reasons())
        return total

    def wrong(self) -> int:
        return sum(r.wrong() for r in self.runs)

    def pooled(self, what: Callable[[LineResult], np.ndarray]) -> np.ndarray:
        parts = [what(r) for r in self.runs]
        return np.concatenate(parts) if parts else np.array([], dtype=float)


def run_grid(table: Path, base: LineSetup, speeds: Iterable[float], loads: Iterable[float], seeds: int,
             seconds: float, bursts: Iterable[int], progress: Progress | None = None) -> list[Cell]:  # fmt: skip
    """Every (speed, burst, load) cell, `seeds` runs each; `progress` hears of every run."""
    speeds, bursts, loads = list(speeds), list(bursts), list(loads)
    total = len(speeds) * len(bursts) * len(loads) * seeds
    cells: list[Cell] = []
    for speed in speeds:
        for burst in bursts:
            for load in loads:
                setup = replace(base, speed_mm_s=speed, burst=burst)
                setup = replace(setup, rate_per_min=round(load * capacity_per_min(setup), 1))
                runs = []
                for seed in range(1, seeds + 1):
                    r = run_line(table, replace(setup, seed=seed), seconds)
                    runs.append(r)
                    if progress:
                        done = sum(len(c.runs) for c in cells) + len(runs)
                        progress(done, total, f"{speed:g} mm/s, burst {burst}, {setup.rate_per_min:g}/min: "
                                 f"{100.0 * r.right_fraction():.1f} % right")  # fmt: skip
                cells.append(Cell(setup, load, runs))
    return cells


def _pct(a: np.ndarray, q: float) -> str:
    return f"{np.percentile(a, q):.0f}" if a.size else "-"


def format_markdown(cells: list[Cell], seeds: int, seconds: float) -> list[str]:
    out = [
        f"{seeds} seed(s) of {seconds:g} s per row, pooled; load = offered rate / what the belt carries packed tight",
        "",
        "| belt mm/s | burst | load | offered /min | sorted /min | items | right outlet | worst seed | wrong outlet "
        "| rejects | barrier to decision p50 / p99 ms | margin p1 ms |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---:|",
    ]
    for c in cells:
        rejects = ", ".join(f"{k} {v}" for k, v in sorted(c.reasons().items()) if k != "sorted") or "none"
        decision = c.pooled(LineResult.decision_ms)
        margins = c.pooled(LineResult.margins_ms)
        out.append(
            f"| {c.setup.speed_mm_s:g} | {c.setup.burst} | {c.load:.2f} | {c.setup.rate_per_min:g} | {c.per_min():.0f} "
            f"| {c.items()} | {100.0 * c.right_fraction():.1f} % | {100.0 * c.worst_seed():.1f} % | {c.wrong()} "
            f"| {rejects} | {_pct(decision, 50)} / {_pct(decision, 99)} | {_pct(margins, 1)} |"
        )
    out.append("")
    for speed in sorted({c.setup.speed_mm_s for c in cells}):
        for burst in sorted({c.setup.burst for c in cells if c.setup.speed_mm_s == speed}):
            good = [c for c in cells if c.setup.speed_mm_s == speed and c.setup.burst == burst
                    and c.right_fraction() >= RIGHT_TARGET]  # fmt: skip
            if good:
                best = max(good, key=lambda c: c.per_min())
                out.append(f"- {speed:g} mm/s, burst {burst}: at least {100 * RIGHT_TARGET:g} % right up to "
                           f"{best.per_min():.0f} items/min sorted (offered {best.setup.rate_per_min:g}, load "
                           f"{best.load:.2f}); the belt carries {capacity_per_min(best.setup):.0f}/min packed tight")  # fmt: skip
            else:
                out.append(f"- {speed:g} mm/s, burst {burst}: below {100 * RIGHT_TARGET:g} % right at every rate tried")
    return out
