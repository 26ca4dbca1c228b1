# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat snapshot`: what tofmatd sees in one frame, as pictures and a point cloud.

One frame's label map and depth image (the same frame number) are taken from the daemon:

- ``labels.png``: the label map in the materials' colours, with a legend of their names;
- ``depth.png``: the depth (range along each ray) colour-mapped, with a scale in mm;
- ``corrected.png``: the material-corrected depth (each labelled pixel's combined depth less its
  material's distortion, Eq. (8)) on the same colour scale, and its difference from the measured
  depth; blank where the daemon corrects nothing (a table without depth distortion, a daemon
  before protocol minor 9);
- ``points.ply``: every valid pixel as a 3D point (mm, camera frame: x right, y down, z forward)
  with its material's colour, label index (255: none) and whether the point is at its corrected
  depth (1) or its measured one (0: no correction for the pixel); the label names are in the
  file's comments and in ``snapshot.json``;
- ``snapshot.json``: the frame, profile, materials with their colours, the intrinsics, the files.

In the segmentation profile the label map is the daemon's per-pixel map; in the handheld and
sorting profiles it is the region's one label over the region's valid pixels (no label elsewhere).
A PLY needs the camera's intrinsics: tofmatd sends them with depth images from protocol minor 9.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .._extras import require_pyplot
from ..client import Client, DepthImage, Label, LabelMap
from ..geometry import Intrinsics, range_to_points

NO_LABEL = LabelMap.NO_LABEL
NONE_COLOUR = (64, 64, 64)  # pixels without a label (and the legend's "no label")
FILES = ("labels.png", "depth.png", "corrected.png", "points.ply", "snapshot.json")


class SnapshotError(RuntimeError):
    """The daemon did not give a frame to snapshot, or the snapshot cannot be written."""


@dataclass(frozen=True)
class Snapshot:
    frame: int
    profile: str
    materials: list[str]  # label index -> name
    labels: npt.NDArray[np.uint8]  # (height, width) of the depth image's region; 255 = no label
    depth: DepthImage
    simulated: bool
    corrected: DepthImage | None = None  # the same frame's material-corrected depth, if served

    @property
    def corrected_mm(self) -> npt.NDArray[np.float32]:
        """The corrected depth over the region, NaN where the daemon corrected nothing (all of it
        when it served no corrected image)."""
        if self.corrected is not None:
            return self.corrected.depth_mm
        return np.full(self.labels.shape, np.nan, np.float32)


def palette(n: int) -> list[tuple[int, int, int]]:
    """n distinct RGB colours for label indices 0..n-1 (matplotlib's tab20, then tab20b, repeating)."""
    plt = _pyplot()
    cmaps = [plt.get_cmap("tab20"), plt.get_cmap("tab20b")]
    out = []
    for i in range(n):
        r, g, b, _ = cmaps[(i // 20) % 2](i % 20)
        out.append((round(r * 255), round(g * 255), round(b * 255)))
    return out


def _pyplot() -> Any:
    require_pyplot(extra="plot", feature="tofmat snapshot")
    import matplotlib.pyplot as plt

    return plt


def capture(client: Client, timeout: float) -> Snapshot:
    """The next frame for which the daemon sends both a depth image and its labels."""
    profile = client.status()["profile"]
    per_pixel = profile == "segmentation"
    corrects = int(client.hello.get("minor", 0)) >= 9  # depth:corrected is served from protocol minor 9
    client.subscribe("depth:combined", "label_map" if per_pixel else "labels",
                     *(["depth:corrected"] if corrects else []))  # fmt: skip
    depths: dict[int, DepthImage] = {}
    corrected: dict[int, DepthImage] = {}
    labels: dict[int, LabelMap | Label] = {}
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        e = client.next_event(timeout=left)
        if isinstance(e, DepthImage) and e.kind in ("combined", "corrected"):
            (depths if e.kind == "combined" else corrected)[e.frame] = e
        elif isinstance(e, LabelMap) or (isinstance(e, Label) and e.profile == profile):
            labels[e.frame] = e
        else:
            continue
        complete = set(depths) & set(labels) & (set(corrected) if corrects else set(depths))
        if complete:
            frame = max(complete)
            return _snapshot(profile, depths[frame], labels[frame], corrected.get(frame))
        for seen in (depths, corrected, labels):  # keep the last few frames only
            for frame in sorted(seen)[:-8]:
                del seen[frame]
    hint = " (the sorting profile decodes frames only during a burst: trigger one)" if profile == "sorting" else ""
    raise SnapshotError(f"tofmatd sent no frame with both a depth image and labels within {timeout:g} s{hint}")


def _snapshot(profile: str, depth: DepthImage, labelled: LabelMap | Label,
              corrected: DepthImage | None = None) -> Snapshot:  # fmt: skip
    h, w = depth.depth_mm.shape
    if corrected is not None and corrected.depth_mm.shape != (h, w):
        raise SnapshotError(f"the corrected depth ({corrected.depth_mm.shape}) is not the depth image's region")
    if isinstance(labelled, LabelMap):
        labels = labelled.labels[depth.y0 : depth.y0 + h, depth.x0 : depth.x0 + w].copy()
        if labels.shape != (h, w):
            raise SnapshotError(f"the label map ({labelled.labels.shape}) does not hold the depth image's region")
        return Snapshot(depth.frame, profile, labelled.materials, labels, depth, labelled.simulated, corrected)
    # A region profile: its one label over the region's valid pixels.
    labels = np.full((h, w), NO_LABEL, np.uint8)
    materials: list[str] = []
    if labelled.material is not None:
        materials = [labelled.material]
        labels[np.isfinite(depth.depth_mm)] = 0
    return Snapshot(depth.frame, profile, materials, labels, depth, labelled.simulated, corrected)


def label_colours(labels: npt.NDArray[np.uint8], colours: list[tuple[int, int, int]]) -> npt.NDArray[np.uint8]:
    """(height, width, 3) RGB of a label map (NONE_COLOUR where no label)."""
    lut = np.array([*colours, *[NONE_COLOUR] * (256 - len(colours))], np.uint8)
    lut[NO_LABEL] = NONE_COLOUR
    out: npt.NDArray[np.uint8] = lut[labels]
    return out


def write_ply(path: Path, points: npt.NDArray[np.float32], rgb: npt.NDArray[np.uint8],
              labels: npt.NDArray[np.uint8], corrected: npt.NDArray[np.bool_],
              comments: list[str]) -> None:  # fmt: skip
    """A binary little-endian PLY of N points: x, y, z (float), red, green, blue, label, corrected (uchar)."""
    n = len(points)
    if rgb.shape != (n, 3) or labels.shape != (n,) or points.shape != (n, 3) or corrected.shape != (n,):
        raise ValueError("points (N, 3), colours (N, 3), labels (N,) and corrected (N,) must agree")
    for c in comments:
        if "\n" in c or "\r" in c:
            raise ValueError("a PLY comment must be one line")
    vertex = np.empty(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                                ("blue", "u1"), ("label", "u1"), ("corrected", "u1")])  # fmt: skip
    vertex["x"], vertex["y"], vertex["z"] = points[:, 0], points[:, 1], points[:, 2]
    vertex["red"], vertex["green"], vertex["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    vertex["label"] = labels
    vertex["corrected"] = corrected
    header = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments),
              f"element vertex {n}", "property float x", "property float y", "property float z",
              "property uchar red", "property uchar green", "property uchar blue", "property uchar label",
              "property uchar corrected", "end_header"]  # fmt: skip
    with path.open("wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(vertex.tobytes())


def write_snapshot(s: Snapshot, out_dir: Path, *, intrinsics: Intrinsics | None = None,
                   overwrite: bool = False) -> list[Path]:  # fmt: skip
    """Writes FILES into out_dir (made if missing); refuses to replace files unless ``overwrite``."""
    intr = intrinsics or s.depth.intrinsics
    if intr is None:
        raise SnapshotError("the depth image carries no intrinsics (a daemon before protocol minor 9, or a "
                            "recording without them): pass --intrinsics FX,FY,CX,CY")  # fmt: skip
    paths = [out_dir / name for name in FILES]
    if not overwrite and (taken := [str(p) for p in paths if p.exists()]):
        raise SnapshotError(f"would replace {', '.join(taken)} (--overwrite to replace)")
    out_dir.mkdir(parents=True, exist_ok=True)
    colours = palette(len(s.materials))
    rgb = label_colours(s.labels, colours)
    _labels_png(paths[0], s, rgb, colours)
    scale = _depth_png(paths[1], s)
    _corrected_png(paths[2], s, scale)
    # Each point at its corrected depth where the daemon corrected the pixel, else at its measured one.
    fixed = np.isfinite(s.corrected_mm)
    ranges = np.where(fixed, s.corrected_mm, s.depth.depth_mm)
    points = range_to_points(ranges, intr, s.depth.x0, s.depth.y0)
    valid = np.isfinite(points).all(axis=-1)
    write_ply(paths[3], points[valid], rgb[valid], s.labels[valid], fixed[valid],
              [f"tofmat snapshot of frame {s.frame} ({s.profile} profile{', simulated' if s.simulated else ''})",
               "units mm, camera frame: x right, y down, z forward",
               "corrected 1: the point is at its material-corrected depth, 0: at its measured depth",
               *(f"label {i} {name}" for i, name in enumerate(s.materials)), f"label {NO_LABEL} none"])  # fmt: skip
    meta = {
        "frame": s.frame,
        "profile": s.profile,
        "simulated": s.simulated,
        "region": {
            "x0": s.depth.x0,
            "y0": s.depth.y0,
            "width": int(s.labels.shape[1]),
            "height": int(s.labels.shape[0]),
        },
        "materials": [
            {"label": i, "name": m, "rgb": list(c)} for i, (m, c) in enumerate(zip(s.materials, colours, strict=True))
        ],
        "intrinsics": vars(intr),
        "points": int(valid.sum()),
        "points_corrected": int((valid & fixed).sum()),
        "files": list(FILES),
    }
    paths[4].write_text(json.dumps(meta, indent=2) + "\n")
    return paths


def _region_extent(s: Snapshot) -> tuple[float, float, float, float]:
    h, w = s.labels.shape
    return (s.depth.x0, s.depth.x0 + w, s.depth.y0 + h, s.depth.y0)  # pixel coordinates of the whole frame


def _unit_rgb(c: tuple[int, int, int]) -> tuple[float, float, float]:
    return (c[0] / 255, c[1] / 255, c[2] / 255)


def _labels_png(path: Path, s: Snapshot, rgb: npt.NDArray[np.uint8], colours: list[tuple[int, int, int]]) -> None:
    plt = _pyplot()
    from matplotlib.patches import Patch

    fig, ax = plt.subplots(figsize=(8, 5.5), layout="constrained")
    ax.imshow(rgb, extent=_region_extent(s), interpolation="nearest")
    ax.set_title(f"labels, frame {s.frame} ({s.profile}{', simulated' if s.simulated else ''})")
    handles = [Patch(color=_unit_rgb(c), label=m) for m, c in zip(s.materials, colours, strict=True)]
    handles.append(Patch(color=_unit_rgb(NONE_COLOUR), label="no label"))
    ax.legend(handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _depth_axes(ax: Any, s: Snapshot, depth_mm: npt.NDArray[np.float32], cmap_name: str,
                scale: tuple[float, float] | None, label: str) -> tuple[float, float]:  # fmt: skip
    """One colour-mapped image (NaN in the no-label grey) with its colour bar; returns its scale."""
    plt = _pyplot()
    cmap = plt.get_cmap(cmap_name).with_extremes(bad=_unit_rgb(NONE_COLOUR))
    shown = np.ma.masked_invalid(depth_mm)
    if scale is None:
        scale = (float(shown.min()), float(shown.max())) if shown.count() else (0.0, 1.0)
    im = ax.imshow(shown, extent=_region_extent(s), cmap=cmap, vmin=scale[0], vmax=scale[1], interpolation="nearest")
    ax.figure.colorbar(im, ax=ax, label=label)
    return scale


def _depth_png(path: Path, s: Snapshot) -> tuple[float, float]:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 5.5), layout="constrained")
    scale = _depth_axes(ax, s, s.depth.depth_mm, "viridis", None, "mm")
    ax.set_title(f"depth (range along each ray), frame {s.frame}")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return scale


def _corrected_png(path: Path, s: Snapshot, scale: tuple[float, float]) -> None:
    """The corrected depth on depth.png's scale, and the correction (measured less corrected)."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 9), layout="constrained")
    corrected = s.corrected_mm
    _depth_axes(top, s, corrected, "viridis", scale, "mm")
    n = int(np.isfinite(corrected).sum())
    why = "" if n else ": none (the table has no depth distortion for these materials, or an older daemon)"
    top.set_title(f"material-corrected depth, frame {s.frame}{why}")
    delta = s.depth.depth_mm - corrected
    reach = float(np.nanmax(np.abs(delta))) if n else 1.0
    _depth_axes(bottom, s, delta, "coolwarm", (-reach, reach), "mm")
    bottom.set_title(f"correction (measured less corrected), {n} pixels")
    fig.savefig(path, dpi=100)
    plt.close(fig)
