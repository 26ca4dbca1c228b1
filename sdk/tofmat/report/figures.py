# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The report's figures: error against cost, one panel per family, its Pareto front drawn."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .._extras import require_pyplot
from .families import Family, Point

_MARKERS = ("o", "s", "^", "D", "v", "P", "X")


def plot_families(path: Path, title: str, families: Sequence[Family]) -> Path:
    """Writes a PNG with one scatter panel per family: cost across, error up; the points on the
    Pareto front filled and joined by a dashed staircase (the region they dominate lies above and to
    the right of it), the others hollow; a horizontal bar through a point spans its runs' costs."""
    require_pyplot(extra="plot", feature="tofmat report")
    import matplotlib.pyplot as plt

    fams = [f for f in families if any(_plottable(p.cost.median, p.error) for p in f.points)]
    if not fams:
        raise ValueError(f"{path.name}: no family has a point to plot")
    fig, axes = plt.subplots(1, len(fams), figsize=(5.4 * len(fams), 4.4), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, fam in zip(axes[0], fams, strict=True):
        front = set(fam.front())
        series = list(dict.fromkeys(p.series for p in fam.points))
        shown = [i for i, p in enumerate(fam.points) if _plottable(p.cost.median, p.error)]
        costs = [fam.points[i].cost.median for i in shown]
        errors = [fam.points[i].error for i in shown]
        placed: list[tuple[float, float]] = []  # annotated points, to stagger labels that would overlap
        for k, name in enumerate(series):
            colour, marker = colours[k % len(colours)], _MARKERS[k % len(_MARKERS)]
            first = True
            for i in shown:
                p = fam.points[i]
                if p.series != name:
                    continue
                on = i in front
                ax.scatter(
                    [p.cost.median],
                    [p.error],
                    marker=marker,
                    s=52,
                    zorder=3,
                    facecolors=colour if on else "none",
                    edgecolors=colour,
                    label=name if first else None,
                )
                first = False
                if p.cost.runs > 1 and p.cost.hi > p.cost.lo:
                    ax.plot([p.cost.lo, p.cost.hi], [p.error, p.error], color=colour, alpha=0.45, lw=1.2, zorder=2)
                if p.label:
                    near = sum(1 for c, e in placed if _near(c, e, p.cost.median, p.error, costs, errors))
                    placed.append((p.cost.median, p.error))
                    ax.annotate(
                        p.label,
                        (p.cost.median, p.error),
                        textcoords="offset points",
                        xytext=(5, 4 - 10 * near),
                        fontsize=7,
                        color=colour,
                    )
        if costs and min(costs) > 0 and max(costs) / min(costs) > 20:
            ax.set_xscale("log")
        _draw_front(ax, [fam.points[i] for i in sorted(front, key=lambda i: fam.points[i].cost.median)])
        ax.set_xlabel(fam.cost_label)
        ax.set_ylabel(fam.error_label)
        ax.set_title(fam.title, fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _draw_front(ax: Any, front: Sequence[Point]) -> None:
    """The front's staircase, from the top of the axes down through each front point (by cost) to
    the right edge: the points above and to the right of it are beaten."""
    pts = [p for p in front if _plottable(p.cost.median, p.error)]
    if not pts:
        return
    ax.margins(x=0.08, y=0.12)
    ax.autoscale_view()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    xs, ys = [pts[0].cost.median], [y1]
    for a, b in zip(pts, [*pts[1:], None], strict=True):
        xs.append(a.cost.median)
        ys.append(a.error)
        xs.append(b.cost.median if b is not None else x1)
        ys.append(a.error)
    ax.plot(xs, ys, ls="--", lw=1.0, color="0.2", zorder=1, label="Pareto front")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def _near(c0: float, e0: float, c1: float, e1: float, costs: Sequence[float], errors: Sequence[float]) -> bool:
    """Two points whose labels would overlap: within 6 % of the cost (ratio, as on a log axis) and
    4 % of the errors' span."""
    span = (max(errors) - min(errors)) or 1.0
    return abs(e0 - e1) <= 0.04 * span and max(c0, c1) <= 1.06 * min(c0, c1)


def _plottable(cost: float, error: float) -> bool:
    return math.isfinite(cost) and math.isfinite(error) and cost > 0


__all__ = ["plot_families"]
