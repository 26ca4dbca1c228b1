# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Plots of exemplar tables: every material's distortion curves vs depth (cf. the paper's Fig. 4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import ExemplarTable
from .._extras import require_pyplot


def row_label(row: tuple[int, int]) -> str:
    f, ref = row
    return f"d({f} MHz) - d({ref} MHz) [mm]" if f and ref else "relative distortion [mm]"


def plot_table(table: ExemplarTable, out: Path, title: str | None = None) -> None:
    """One panel per row, one line per material, depth (bin centres) on x (needs the ``plot`` extra)."""
    require_pyplot(extra="plot", feature="plotting a table (tofmat.tools.plot)")
    import matplotlib.pyplot as plt

    feats = table.features
    if not np.isfinite(feats).any():
        raise ValueError("table has no valid value to plot")
    x = table.bin_centres_mm
    n_rows = table.n_rows
    fig, axes = plt.subplots(n_rows, 1, figsize=(11, 4.2 * n_rows), sharex=True, squeeze=False)
    cmap = plt.get_cmap("tab20")
    styles = ["-", "--", ":"]
    for r in range(n_rows):
        ax = axes[r, 0]
        for m, name in enumerate(table.materials):
            y = feats[m, r]
            ax.plot(x, y, styles[(m // 20) % 3], color=cmap(m % 20), lw=1.1, label=name)
        ax.set_ylabel(row_label(table.rows[r]))
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("measured depth [mm]")
    axes[0, 0].legend(ncol=6, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, 1.32), frameon=False)
    fig.suptitle(title or f"Relative depth distortion of {len(table.materials)} materials", y=0.995)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
