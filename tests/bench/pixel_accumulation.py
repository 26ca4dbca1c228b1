# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Would accumulating each pixel's features over frames help the segmentation? (docs/benchmarks.md,
"Segmentation accuracy").

A static simulated scene is rendered with noise N times (different seeds) and decoded (the float
decode); each pixel's two Eq. (10) features and combined depth are averaged over the first 1, 2,
4, ... frames, and the pixel is labelled by Eq. (12) at the bin of its own depth (m = 1, no spatial
smoothing) among the scene's materials, against a table recorded with the simulated camera. Per
target it prints the share of its valid pixels labelled right by the number of frames averaged,
and how far apart its material's curve and the nearest other candidate's are over the target's
depths (rms mm): where more frames do not raise the share, the pixels' error is not noise.

    python3 -m tofmat sim table --range 500,2100 --bins 533 -o build/sim_table_wide.tmx
    python3 tests/bench/pixel_accumulation.py --table build/sim_table_wide.tmx \\
        --scene objects,materials=cork+paper+acryl,far=1000

Runs in a few seconds.
"""

from __future__ import annotations

import argparse

import numpy as np
import numpy.typing as npt

import tofmat
from tofmat._tofmat import decode_frame
from tofmat.sim import Renderer, Scene, load_device, load_library

F64 = npt.NDArray[np.float64]


def labels_of(table: tofmat.ExemplarTable, candidates: list[int], depth: F64, features: F64,
              valid: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:  # fmt: skip
    """Each pixel's candidate (position in `candidates`) by Eq. (12) at its depth's bin; -1: none."""
    b = table.bins
    valid = valid & np.isfinite(depth)
    bins = np.floor((np.where(valid, depth, b.start_mm) - b.start_mm) / b.width_mm).astype(np.int64)
    inside = valid & (bins >= 0) & (bins < b.count)
    at = np.clip(bins, 0, b.count - 1)
    curves = np.asarray(table.features, dtype=np.float64)[candidates]  # (k, 2, bins)
    sq = [(c[:, at] - features) ** 2 for c in curves]
    # Eq. (12): the mean over the elements both have (inf where none)
    d = np.stack([np.where(np.isfinite(s).any(axis=0), np.nansum(s, axis=0) / np.maximum(np.isfinite(s).sum(axis=0), 1),
                           np.inf) for s in sq])  # fmt: skip
    out = np.full(depth.shape, -1, np.int64)
    out[inside] = np.argmin(d[:, inside], axis=0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--table", required=True, help="a table recorded with the simulated camera (.tmx)")
    ap.add_argument("--scene", default="objects,materials=cork+paper+acryl,far=1000", help="sim:SCENE spec")
    ap.add_argument("--frames", type=int, default=8, help="frames averaged at most (1, 2, 4, ... up to it)")
    a = ap.parse_args()
    table = tofmat.ExemplarTable.load(a.table)
    renderer = Renderer(load_device(), load_library(), 0)
    scene = Scene.of_source(a.scene)
    names = list(dict.fromkeys(t.material for t in scene.targets))
    candidates = [table.index_of(n) for n in names]
    truth = renderer.render(scene, 0, False)
    target = np.asarray(truth.target).reshape(-1)
    p0 = np.asarray(renderer.p0_tables()).reshape(3, -1)
    decoded = []
    for seed in range(a.frames):
        f = renderer.render(scene, 100 + seed, True)
        d = decode_frame(np.asarray(f.raw).reshape(9, -1), p0)
        decoded.append((np.asarray(d.combined_mm, np.float64), np.asarray(d.features, np.float64),
                        np.asarray(d.flags) == 0))  # fmt: skip
    counts = [n for n in (1, 2, 4, 8, 16, 32) if n <= a.frames]
    print(f"scene {a.scene}; table {a.table}; per-pixel labels (m = 1, no smoothing) right, by frames averaged")
    print("| target | material | " + " | ".join(f"{n} frame{'s' if n > 1 else ''}" for n in counts)
          + " | nearest other curve (rms mm over its depths) |")  # fmt: skip
    print("|---|---|" + "---:|" * len(counts) + "---|")
    rows: dict[int, list[str]] = {k: [] for k in range(len(scene.targets))}
    for n in counts:
        depth = np.mean([d[0] for d in decoded[:n]], axis=0)
        features = np.mean([d[1] for d in decoded[:n]], axis=0)
        valid = np.all([d[2] for d in decoded[:n]], axis=0)
        labels = labels_of(table, candidates, depth, features, valid)
        for k, t in enumerate(scene.targets):
            on = (target == k) & valid
            rows[k].append(f"{100 * np.mean(labels[on] == names.index(t.material)):.1f} %")
    b = table.bins
    centres = b.start_mm + b.width_mm * (np.arange(b.count) + 0.5)
    true_range = np.asarray(truth.range_mm).reshape(-1)
    for k, t in enumerate(scene.targets):
        ranges = true_range[target == k]
        over = (centres >= np.nanmin(ranges)) & (centres <= np.nanmax(ranges))
        own = np.asarray(table.features[table.index_of(t.material)], np.float64)[:, over]
        gaps = {n: float(np.sqrt(np.nanmean((np.asarray(table.features[table.index_of(n)], np.float64)[:, over]
                                             - own) ** 2))) for n in names if n != t.material}  # fmt: skip
        other = min(gaps, key=lambda n: gaps[n])
        print(f"| {k} | {t.material} | " + " | ".join(rows[k]) + f" | {other}: {gaps[other]:.2f} |")


if __name__ == "__main__":
    main()
