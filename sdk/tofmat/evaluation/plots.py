# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The reliability diagram of ``tofmat evaluate --plot``: for each source and matcher, the test
split's accuracy against its confidence, per confidence bin, with the diagonal of a calibrated
confidence."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from .._extras import require_pyplot
from .run import SourceResult


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
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_xlabel("confidence of the top label")
        ax.set_ylabel("share right")
        ax.set_title(f"{r.source}: test split")
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
