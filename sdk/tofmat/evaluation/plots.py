# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The reliability diagrams of ``tofmat evaluate --plot``: for each source and matcher, the test
split's accuracy against its confidence, per confidence bin, with the diagonal of a calibrated
confidence; with ``--session-scales``, one panel per matcher and a curve per session spread."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .._extras import require_pyplot
from .confidence import ECE_BINS
from .run import SourceResult
from .scales import ScaleRow


def reliability_diagram(results: Sequence[SourceResult], path: Path) -> Path:
    """Writes the PNG (one panel per source) and returns its path."""
    require_pyplot(extra="plot", feature="tofmat evaluate --plot")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, max(1, len(results)), figsize=(5.0 * max(1, len(results)), 4.6), squeeze=False)
    for ax, r in zip(axes[0], results, strict=False):
        ax.plot([0, 1], [0, 1], color="0.6", linestyle="--", linewidth=1, label="calibrated")
        for row in (x for x in r.rows if x.split == "test"):
            if not row.reliability:
                continue
            conf = [c for c, _a, _n in row.reliability]
            acc = [a for _c, a, _n in row.reliability]
            size = [8 + 200 * n / max(n for _c, _a, n in row.reliability) for _c, _a, n in row.reliability]
            ax.plot(conf, acc, marker="", linewidth=1)
            ax.scatter(conf, acc, s=size, alpha=0.7, label=f"{row.method} (ECE {100 * row.ece:.1f} %)")
        _frame(ax, "confidence of the top label", f"{r.source}: test split", 8)
    return _save(fig, path)


def scale_reliability_diagram(rows: Sequence[ScaleRow], path: Path) -> Path:
    """Writes the PNG of ``tofmat evaluate --session-scales ... --plot``: one panel per matcher, a
    curve per session spread (the simulator's target angles pooled; points sized by their labels),
    and returns its path."""
    require_pyplot(extra="plot", feature="tofmat evaluate --plot")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r.method for r in rows))
    fig, axes = plt.subplots(1, max(1, len(methods)), figsize=(5.0 * max(1, len(methods)), 4.6), squeeze=False)
    for ax, method in zip(axes[0], methods, strict=False):
        ax.plot([0, 1], [0, 1], color="0.6", linestyle="--", linewidth=1, label="calibrated")
        ax.axvspan(0.9, 1.0, color="0.9", zorder=0)
        mine = [r for r in rows if r.method == method]
        curves = {
            scale: _pooled([r for r in mine if r.scale == scale]) for scale in dict.fromkeys(r.scale for r in mine)
        }
        top = max((n for diagram, _e in curves.values() for _c, _a, n in diagram), default=1)
        for scale, (diagram, ece) in curves.items():
            if not diagram:
                continue
            conf = [c for c, _a, _n in diagram]
            acc = [a for _c, a, _n in diagram]
            (line,) = ax.plot(conf, acc, linewidth=1)
            ax.scatter(
                conf,
                acc,
                s=[8 + 150 * n / top for _c, _a, n in diagram],
                color=line.get_color(),
                alpha=0.7,
                label=f"{scale:g} x the spread (ECE {100 * ece:.1f} %)",
            )
        angles = sorted({r.yaw_deg for r in mine if r.yaw_deg is not None})
        what = "real curves" if not angles else f"simulator, {', '.join(f'{y:g}' for y in angles)} deg pooled"
        # (the legend where a confident, wrong label would be)
        _frame(
            ax, "confidence of the top label (shaded: 0.9 and more)", f"{method}: {what}, test split", 8, "lower right"
        )
    return _save(fig, path)


def _pooled(rows: Sequence[ScaleRow]) -> tuple[list[tuple[float, float, int]], float]:
    """The rows' reliability diagrams merged bin by bin (the same ECE_BINS edges), with their ECE."""
    sums: dict[int, list[float]] = {}
    for r in rows:
        for c, a, n in r.reliability:
            b = min(int(c * ECE_BINS), ECE_BINS - 1)
            acc = sums.setdefault(b, [0.0, 0.0, 0.0])
            acc[0] += c * n
            acc[1] += a * n
            acc[2] += n
    total = sum(v[2] for v in sums.values())
    diagram = [(v[0] / v[2], v[1] / v[2], int(v[2])) for _b, v in sorted(sums.items())]
    ece = sum(n / total * abs(c - a) for c, a, n in diagram) if total else 0.0
    return diagram, ece


def _frame(ax: Any, xlabel: str, title: str, legend_size: int, legend_at: str = "upper left") -> None:
    """A reliability panel's axes: both 0..1, labelled, with its legend and grid."""
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("share right")
    ax.set_title(title)
    ax.legend(loc=legend_at, fontsize=legend_size)
    ax.grid(alpha=0.3)


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
