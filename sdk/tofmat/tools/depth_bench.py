# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat bench-depth`: how far tofmatd's material-corrected depth is from the truth.

tofmatd runs the segmentation profile on a simulated scene (`--source sim:SCENE`) with a table that
carries the materials' depth distortion (a table recorded with the simulated camera does). For a few
frames the bench takes the label map, the combined depth and the corrected depth of the same frame;
the truth is the same scene rendered without noise (`sim.Scene.of_source`): each pixel's target and
its true range along the ray. Per material (the pixel's true one) it reports the error of the
combined depth (before) and of the corrected depth (after), over the pixels that have a corrected
depth: those labelled right, and all labelled ones (wrong labels included: corrected for the wrong
material), with the share of the target's pixels that got a corrected depth at all.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .._progress import Progress
from ..client import DepthImage, LabelMap
from ..sim import Renderer, Scene, load_device, load_library
from .live_demo import connect, start_daemon, stop_daemon

# The scenes: the regions scene with 3 and with 6 materials at 600..1200 mm.
DEFAULT_SCENES = (
    "regions,materials=cork+paper+acryl,near=600,far=1200",
    "regions,materials=cork+pvc+wood+paper+acryl+fabric,near=600,far=1200",
)


BAND_PX = 5  # the boundary band: target pixels within this many pixels of another target or of none


@dataclass(frozen=True)
class SceneLabels:
    """The label map's accuracy on a scene's target pixels: all, away from the edges, in the band."""

    scene: str
    frames: int
    accuracy: float  # mean over the frames
    interior: float
    band: float
    band_share: float  # of the target pixels, the share in the band
    first_frame: float  # the first frame taken (the third the daemon labels)
    last_frame: float  # the last one (with --accumulate, the pixels' means hold the most frames there)


def boundary_band(target: npt.NDArray[np.int16], px: int = BAND_PX) -> npt.NDArray[np.bool_]:
    """Target pixels within px (Chebyshev distance) of a pixel of another target or of none."""
    h, w = target.shape
    padded = np.pad(target, px, constant_values=-1)
    band = np.zeros((h, w), bool)
    for dy in range(-px, px + 1):
        for dx in range(-px, px + 1):
            band |= padded[px + dy : px + dy + h, px + dx : px + dx + w] != target
    out: npt.NDArray[np.bool_] = band & (target >= 0)
    return out


@dataclass(frozen=True)
class MaterialError:
    scene: str
    material: str
    pixels: int  # the target's pixels with a true range, over the frames
    corrected_share: float  # of those, the share with a corrected depth
    right_share: float  # of those corrected, the share labelled right
    before_median: float  # combined - truth, mm, over the corrected pixels (signed)
    before_abs_median: float
    before_p95: float  # |error| p95
    after_median: float  # corrected - truth, every corrected pixel (wrong labels included)
    after_abs_median: float
    after_p95: float
    right_median: float  # corrected - truth, pixels labelled right only
    right_abs_median: float
    right_p95: float


def _stats(e: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    if e.size == 0:
        return (float("nan"),) * 3
    a = np.abs(e)
    return float(np.median(e)), float(np.median(a)), float(np.percentile(a, 95))


def truth_of(spec: str) -> tuple[list[str], npt.NDArray[np.int16], npt.NDArray[np.float32]]:
    """The scene's materials, each pixel's target (-1: none) and true range (mm, NaN: none)."""
    scene = Scene.of_source(spec)
    frame = Renderer(load_device(), load_library(), 1).render(scene, 0, False)
    target = np.asarray(frame.target).reshape(424, 512)
    true_range = np.asarray(frame.range_mm).reshape(424, 512)
    return [t.material for t in scene.targets], target, true_range


def bench_scene(table: Path, spec: str, frames: int, timeout_s: float = 120.0,
                extra: list[str] | None = None) -> tuple[SceneLabels, list[MaterialError]]:  # fmt: skip
    """Runs tofmatd on `spec` (segmentation, the scene's materials as candidates) for `frames` frames."""
    materials, target, true_range = truth_of(spec)
    with tempfile.TemporaryDirectory(prefix="tofmat-depth-") as tmp:
        sock, log = Path(tmp) / "d.sock", Path(tmp) / "d.log"
        daemon = start_daemon(table, sock, f"sim:{spec},realtime=0", log, "segmentation",
                              ["--candidates", ",".join(dict.fromkeys(materials)), *(extra or [])])  # fmt: skip
        try:
            try:
                client = connect(sock, daemon)
            except RuntimeError as e:
                raise RuntimeError(f"{e}: {log.read_text(errors='replace').strip()[-500:]}") from e
            with client:
                client.subscribe("label_map", "depth:combined", "depth:corrected")
                seen: dict[int, dict[str, LabelMap | DepthImage]] = {}
                taken: list[dict[str, LabelMap | DepthImage]] = []
                skip = 2  # the first frames: the daemon settles (its queue, the first full decode)
                for event in client.events(timeout=timeout_s):
                    if isinstance(event, LabelMap):
                        seen.setdefault(event.frame, {})["map"] = event
                    elif isinstance(event, DepthImage):
                        seen.setdefault(event.frame, {})[event.kind] = event
                    else:
                        continue
                    whole = [f for f, v in seen.items() if len(v) == 3]
                    for f in whole:
                        if skip > 0:
                            skip -= 1
                        else:
                            taken.append(seen[f])
                        del seen[f]
                    if len(taken) >= frames:
                        break
                else:
                    raise RuntimeError(f"tofmatd sent {len(taken)} of {frames} frames within {timeout_s:g} s")
        finally:
            stop_daemon(daemon)
    # Labels: right where the pixel's label names its target's material.
    band = boundary_band(target)
    on_target = target >= 0
    per_frame = []
    for shot in taken:
        m = shot["map"]
        assert isinstance(m, LabelMap)
        names = np.array([*m.materials, ""])[np.minimum(m.labels, len(m.materials))]
        truth = np.array([*materials, ""])[np.where(on_target, target, len(materials))]
        right = on_target & (names == truth)
        per_frame.append([right[on_target].mean(), right[on_target & ~band].mean(), right[band].mean()])
    acc = np.array(per_frame)
    mean = acc.mean(axis=0)
    labels = SceneLabels(spec, len(taken), float(mean[0]), float(mean[1]), float(mean[2]),
                         float(band.sum() / on_target.sum()), float(acc[0, 0]), float(acc[-1, 0]))  # fmt: skip
    out = []
    for i, name in enumerate(materials):
        on = (target == i) & np.isfinite(true_range)
        before, after, right, n_corrected, n_right = [], [], [], 0, 0
        for shot in taken:
            m, comb, corr = shot["map"], shot["combined"], shot["corrected"]
            assert isinstance(m, LabelMap) and isinstance(comb, DepthImage) and isinstance(corr, DepthImage)
            ok = on & np.isfinite(corr.depth_mm)
            labelled_right = ok & (m.labels < len(m.materials))
            labelled_right[labelled_right] = np.array(m.materials)[m.labels[labelled_right]] == name
            before.append((comb.depth_mm[ok] - true_range[ok]).astype(np.float64))
            after.append((corr.depth_mm[ok] - true_range[ok]).astype(np.float64))
            right.append((corr.depth_mm[labelled_right] - true_range[labelled_right]).astype(np.float64))
            n_corrected += int(ok.sum())
            n_right += int(labelled_right.sum())
        n = int(on.sum()) * len(taken)
        b, a, r = (np.concatenate(x) for x in (before, after, right))
        out.append(MaterialError(spec, name, n, n_corrected / max(n, 1), n_right / max(n_corrected, 1), *_stats(b),
                                 *_stats(a), *_stats(r)))  # fmt: skip
    return labels, out


def bench_depth(table: Path, scenes: list[str], frames: int, progress: Progress | None = None,
                extra: list[str] | None = None) -> tuple[list[SceneLabels], list[MaterialError]]:  # fmt: skip
    """Every scene in turn; `extra`: more tofmatd flags (--no-region-vote, --smooth N)."""
    labels: list[SceneLabels] = []
    results: list[MaterialError] = []
    for k, spec in enumerate(scenes):
        if progress:
            progress(k, len(scenes), spec)
        scene_labels, errors = bench_scene(table, spec, frames, extra=extra)
        labels.append(scene_labels)
        results.extend(errors)
    if progress:
        progress(len(scenes), len(scenes), "done")
    return labels, results


def format_labels_markdown(labels: list[SceneLabels]) -> str:
    lines = [
        f"| scene | frames | target pixels right | away from edges | within {BAND_PX} px of an edge (share) | first frame "
        "| last frame |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for s in labels:
        lines.append(f"| {s.scene} | {s.frames} | {100 * s.accuracy:.1f} % | {100 * s.interior:.1f} % | "
                     f"{100 * s.band:.1f} % ({100 * s.band_share:.1f} %) | {100 * s.first_frame:.1f} % | "
                     f"{100 * s.last_frame:.1f} % |")  # fmt: skip
    return "\n".join(lines)


def format_markdown(results: list[MaterialError]) -> str:
    lines = [
        "| scene | material | corrected px | labelled right | before: median / med abs / p95 | after, all labels | "
        "after, right labels |",
        "|---|---|---:|---:|---|---|---|",
    ]
    for r in results:
        scene = r.scene.split(",")[1].removeprefix("materials=").count("+") + 1
        lines.append(
            f"| {scene} materials | {r.material} | {100 * r.corrected_share:.1f} % | {100 * r.right_share:.1f} % | "
            f"{r.before_median:+.2f} / {r.before_abs_median:.2f} / {r.before_p95:.2f} | "
            f"{r.after_median:+.2f} / {r.after_abs_median:.2f} / {r.after_p95:.2f} | "
            f"{r.right_median:+.2f} / {r.right_abs_median:.2f} / {r.right_p95:.2f} |"
        )
    return "\n".join(lines)
