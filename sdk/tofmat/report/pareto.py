# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The Pareto front of (cost, error) points: the points that no other point beats on both."""

from __future__ import annotations

import math
from collections.abc import Sequence


def dominates(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """True when ``a`` = (cost, error) is no worse than ``b`` on both and better on at least one."""
    return a[0] <= b[0] and a[1] <= b[1] and (a[0] < b[0] or a[1] < b[1])


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points (cost, error) on the Pareto front, by cost, then error, then index.

    Lower is better on both axes. A point is on the front when no other point dominates it (is at
    most as costly and at most as wrong, and strictly better on one of the two). Points that tie
    exactly are all on the front (neither beats the other); a point with the same error as another
    but a higher cost (or the same cost and a higher error) is not. A point with a NaN coordinate is
    never on the front and beats no other point.
    """
    finite = [i for i, (c, e) in enumerate(points) if not (math.isnan(c) or math.isnan(e))]
    front = [i for i in finite if not any(dominates(points[j], points[i]) for j in finite if j != i)]
    return sorted(front, key=lambda i: (points[i][0], points[i][1], i))


__all__ = ["dominates", "pareto_front"]
