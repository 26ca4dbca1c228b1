# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Points of error against cost, grouped in families of paths that do the same work."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass, field

from .pareto import pareto_front


@dataclass(frozen=True)
class Stat:
    """A figure measured in several runs: the median, and the smallest and largest."""

    median: float
    lo: float
    hi: float
    runs: int

    @staticmethod
    def of(values: Sequence[float]) -> Stat:
        v = [x for x in values if not math.isnan(x)]
        if not v:
            return Stat(math.nan, math.nan, math.nan, 0)
        return Stat(float(statistics.median(v)), min(v), max(v), len(v))

    def spread(self, fmt: str = "{:.3g}") -> str:
        """'lo-hi' over the runs ('' for one run)."""
        if self.runs <= 1 or math.isnan(self.lo):
            return ""
        return f"{fmt.format(self.lo)}-{fmt.format(self.hi)}"


@dataclass(frozen=True)
class Point:
    series: str  # the legend's group: a backend, a kernel
    label: str  # the point's own name in the figure (a window length, a stage)
    cost: Stat
    error: float
    note: str = ""  # e.g. where the error comes from when it is not measured for this point itself


@dataclass(frozen=True)
class Family:
    """Paths doing the same work, so that their costs and errors compare."""

    key: str  # file-name part
    title: str
    cost_label: str
    error_label: str
    points: list[Point] = field(default_factory=list)
    cost_unit: str = ""  # short forms for one-line summaries: "us", "ms", "% wrong", "mm"
    error_unit: str = ""

    def front(self) -> list[int]:
        """Indices of the points on the Pareto front (by cost)."""
        return pareto_front([(p.cost.median, p.error) for p in self.points])


__all__ = ["Family", "Point", "Stat"]
