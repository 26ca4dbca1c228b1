# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Figures of the simulator's calibration and evaluation (docs/simulator.md); need the ``sim`` extra (matplotlib)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .._extras import require_pyplot

FEATURE = "the simulator's figures (tofmat.sim.plots)"


def confusion_matrix(conf: npt.NDArray[np.int64], materials: Sequence[str], title: str, out: Path) -> None:
    require_pyplot(extra="sim", feature=FEATURE)
    import matplotlib.pyplot as plt

    n = len(materials)
    frac = conf / np.maximum(conf.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(9.5, 8.5))
    im = ax.imshow(frac, cmap="Blues", vmin=0.0, vmax=1.0)
    ax.set_xticks(range(n), materials, rotation=90, fontsize=7)
    ax.set_yticks(range(n), materials, fontsize=7)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true material")
    for t in range(n):
        for p in range(n):
            if conf[t, p]:
                ax.text(
                    p,
                    t,
                    str(conf[t, p]),
                    ha="center",
                    va="center",
                    fontsize=5,
                    color="white" if frac[t, p] > 0.5 else "black",
                )
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="fraction of the true material's queries")
    ax.set_title(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def stability(results: Sequence[dict[str, Any]], xlabel: str, title: str, out: Path) -> None:
    require_pyplot(extra="sim", feature=FEATURE)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for k, r in enumerate(results):
        color = f"C{k}"
        ax.plot(r["angles_deg"], r["distance"], "o-", color=color, label=f"{r['probe']}: distance to own class")
        ax.axhline(r["upper_bound"], color=color, ls="--", lw=1, label=f"{r['probe']}: nearest other class")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("Eq. (12) distance [mm$^2$]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
