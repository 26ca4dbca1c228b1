# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The paper's evaluation (Sec. 5), reproduced on the calibrated simulator.

A database in the paper's protocol: every material on a translation stage,
13 orientations, depths 600..1250 mm, a region of interest averaged per
position. Leave-one-orientation-out nearest neighbour (Eq. 12) with three
features, side by side with the paper's figures:

- frequency only (n = 3, m = 1): Eq. (10) rows at one stage position;
- depth only (n = 1, m = all): Eq. (11) with one frequency and the known stage movement;
- both (n = 3, m = all): Eq. (10) rows at every position.

Each of the paper's captures was its own session, and the real database shows per-capture level
offsets of the two rows (the calibration fits them: robust spread about 1.6 mm in row 0 and
0.5 mm in row 1, docs/simulator.md). With ``session_offsets_mm`` every capture gets such offsets,
drawn N(0, sigma) per row and seeded, added to its 16 and 80 MHz depths: they shift the
Eq. (10) rows and cancel in Eq. (11), which is why the paper's depth-only feature beats its
frequency-only one.

The calibration also fits every capture's session state: the illumination waveform of a session
is the device's harmonics moved along a fitted drift direction (docs/simulator-model.md 2.2).
With ``session_drift_sd`` every capture is rendered by a device in its own session, the state
drawn N(0, sigma_f) per group and seeded: unlike the offsets this changes the shape of the
distortion, so it disturbs the depth-only feature as well.

Also the feature stability of Figs. 6 and 7: the distance of a material's
query to its own class as the orientation (or the fold angle) changes, next
to the distance from that class to its nearest other class.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from .. import BinSpec, Classifier, ExemplarTable
from .._progress import Progress
from . import Renderer, Target, stage_sweep

PAPER_ACCURACY = {"frequency": 57.4, "depth": 81.6, "both": 90.5}
ORIENTATIONS_DEG = tuple(float(a) for a in range(0, 61, 5))  # 13 orientations
ROI = (246, 202, 266, 222)  # 20 x 20 pixels at the image centre, as the authors' demo
TARGET_RECT = (216, 172, 296, 252)  # the target covers the ROI with a margin
FREQ_NAMES = ("80", "16", "120")

Array = npt.NDArray[np.float64]


@dataclass
class Capture:
    material: str
    orientation_deg: float
    fold_deg: float
    stage_mm: Array
    depth_mm: Array  # (3, n) unwrapped ROI means, groups 80, 16, 120 MHz


def capture(
    renderer: Renderer,
    material: str,
    orientation_deg: float,
    stage_mm: Array,
    seed: int,
    fold_deg: float = 0.0,
    frames: int = 1,
) -> Capture:
    t = Target(material, float(stage_mm[0]), orientation_deg, 0.0, fold_deg, TARGET_RECT)
    c = stage_sweep(renderer, t, ROI, list(map(float, stage_mm)), frames, seed)
    return Capture(material, orientation_deg, fold_deg, c["stage_mm"], c["depth_mm"])


# --- features -----------------------------------------------------------------


def feature_both(c: Capture) -> npt.NDArray[np.float32]:
    """Eq. (10) rows (database sign) at every stage position: (2, n)."""
    d80, d16, d120 = c.depth_mm
    return np.stack([d16 - d120, d80 - d120]).astype(np.float32)


def feature_frequency(c: Capture, position: int) -> npt.NDArray[np.float32]:
    """Eq. (10) rows at one stage position (m = 1): (2, 1)."""
    return feature_both(c)[:, position : position + 1]


def feature_depth(c: Capture, group: int, base: int) -> npt.NDArray[np.float32]:
    """Eq. (11) for one frequency: d(f, base) - d(f, j) + (stage_j - stage_base), (1, n)."""
    d: Array = c.depth_mm[group]
    v: Array = d[base] - d + (c.stage_mm - c.stage_mm[base])
    return np.asarray(v[None, :], dtype=np.float32)


def feature_functions(n_positions: int) -> dict[str, Callable[[Capture], npt.NDArray[np.float32]]]:
    centre = n_positions // 2
    return {
        "frequency": lambda c: feature_frequency(c, centre),
        "depth": lambda c: feature_depth(c, 0, centre),  # 80 MHz, the authors' choice
        "depth_16": lambda c: feature_depth(c, 1, centre),
        "depth_120": lambda c: feature_depth(c, 2, centre),
        "both": feature_both,
    }


# --- leave-one-orientation-out nearest neighbour -------------------------------------


@dataclass
class Evaluation:
    materials: list[str]
    accuracy: dict[str, float] = field(default_factory=dict)  # percent
    confusion: dict[str, npt.NDArray[np.int64]] = field(default_factory=dict)  # truth x predicted
    capture_seconds: float = 0.0
    classify_seconds: dict[str, float] = field(default_factory=dict)
    # The fixed-point backend against the float one on the same queries: per feature, the queries
    # labelled differently, as (truth, held-out orientation, float label, fixed label, the float
    # path's margin between the two labels in mm^2).
    fixed_disagreements: dict[str, list[tuple[str, float, str, str, float]]] = field(default_factory=dict)


def exemplar_table(features: list[npt.NDArray[np.float32]], names: list[str]) -> ExemplarTable:
    stacked = np.stack(features)
    n_rows, n_bins = stacked.shape[1:]
    rows = [(16, 120), (80, 120)] if n_rows == 2 else [(0, 0)] * n_rows
    return ExemplarTable(names, stacked, BinSpec(0.0, 1.0, n_bins), rows)


def _nearest_exemplars(
    feats: dict[tuple[str, float], npt.NDArray[np.float32]],
    materials: list[str],
    train: list[float],
    queries: npt.NDArray[np.float32],
    backend: Literal["float", "fixed"],
) -> npt.NDArray[np.float64]:
    """Each query's Eq. (12) distance to each material's nearest exemplar, (queries, materials).

    A table holds at most 255 materials while the protocol's exemplars are materials x training
    orientations (348 for the whole library), so each training orientation is a table of its own
    and a material's distance is the least over them: the nearest neighbour over every exemplar."""
    out = np.full((len(queries), len(materials)), np.inf)
    for o in train:
        table = exemplar_table([feats[(m, o)] for m in materials], materials)
        for q, r in enumerate(Classifier(table, backend=backend, method="eq12").classify_batch(queries)):
            for m in r.ranking:  # (m.index: the table's order, which is materials')
                out[q, m.index] = min(out[q, m.index], m.distance)
    return out


def leave_one_orientation_out(
    captures: dict[tuple[str, float], Capture],
    materials: list[str],
    orientations: list[float],
    feature: Callable[[Capture], npt.NDArray[np.float32]],
    disagreements: list[tuple[str, float, str, str, float]] | None = None,
) -> npt.NDArray[np.int64]:
    """Confusion matrix (truth x predicted) over every material and held-out orientation, with
    the float backend: each query's label is the material of its nearest exemplar among the other
    orientations (Eq. (12)). With `disagreements`, the fixed-point backend classifies the same
    queries and every query it labels differently is appended (see Evaluation.fixed_disagreements)."""
    feats = {k: feature(c) for k, c in captures.items()}
    conf = np.zeros((len(materials), len(materials)), dtype=np.int64)
    for held in orientations:
        train = [o for o in orientations if o != held]
        queries = np.stack([feats[(m, held)] for m in materials])
        dist = _nearest_exemplars(feats, materials, train, queries, "float")
        labels = dist.argmin(axis=1)
        for truth, label in enumerate(labels):
            conf[truth, label] += 1
        if disagreements is None:
            continue
        fixed = _nearest_exemplars(feats, materials, train, queries, "fixed").argmin(axis=1)
        for truth, (a, b) in enumerate(zip(labels, fixed, strict=True)):
            if a != b:
                disagreements.append(
                    (materials[truth], held, materials[a], materials[b], float(dist[truth, b] - dist[truth, a]))
                )
    return conf


def _fit_spread(library_json: dict[str, Any], key: str, count: int) -> Array:
    """Robust standard deviation (1.4826 x MAD) of one per-capture quantity (``key``, ``count``
    values) that a calibrated library's materials carry in their "fit" blocks; zeros without it."""
    values = [m.get("fit", {}).get(key) for m in library_json.get("materials", [])]
    x = np.array([v for v in values if v is not None], dtype=float)
    if x.size == 0:
        return np.zeros(count)
    return np.asarray(1.4826 * np.median(np.abs(x - np.median(x, axis=0)), axis=0), dtype=np.float64)


def session_offset_spread(library_json: dict[str, Any]) -> tuple[float, float]:
    """The spread of the per-capture row offsets (rows 0 and 1, mm); (0, 0) without them."""
    s = _fit_spread(library_json, "offsets_mm", 2)
    return (float(s[0]), float(s[1]))


def session_state_spread(library_json: dict[str, Any]) -> tuple[float, float, float]:
    """The spread of the per-capture session states per group (80, 16, 120 MHz); zeros without them."""
    s = _fit_spread(library_json, "session", 3)
    return (float(s[0]), float(s[1]), float(s[2]))


def with_session_offsets(c: Capture, offsets_mm: tuple[float, float]) -> Capture:
    """The capture with row offsets (o0, o1) added: d16 += o0, d80 += o1 (d120 the reference)."""
    d = c.depth_mm.copy()
    d[1] += offsets_mm[0]
    d[0] += offsets_mm[1]
    return Capture(c.material, c.orientation_deg, c.fold_deg, c.stage_mm, d)


def evaluate(
    renderer: Renderer,
    materials: list[str],
    orientations: tuple[float, ...] = ORIENTATIONS_DEG,
    stage_mm: Array | None = None,
    seed: int = 0,
    progress: Progress | None = None,
    session_offsets_mm: tuple[float, float] = (0.0, 0.0),
    compare_fixed: bool = False,
    session_drift_sd: tuple[float, float, float] = (0.0, 0.0, 0.0),
    session_renderer: Callable[[tuple[float, float, float]], Renderer] | None = None,
) -> tuple[Evaluation, dict[tuple[str, float], Capture]]:
    """``session_renderer(state)`` renders in a session (a device moved by ``in_session``); it is
    needed when ``session_drift_sd`` is not all zero."""
    stage = np.arange(600.0, 1250.0 + 1e-9, 1.0) if stage_mm is None else stage_mm
    drift = any(s > 0.0 for s in session_drift_sd)
    if drift and session_renderer is None:
        raise ValueError("session_drift_sd needs a session_renderer")
    t0 = time.perf_counter()
    captures: dict[tuple[str, float], Capture] = {}
    rng = np.random.default_rng(seed + 424242)
    rng_drift = np.random.default_rng(seed + 737373)  # its own stream: the offsets stay as they were
    for i, m in enumerate(materials):
        for j, o in enumerate(orientations):
            r = renderer
            if drift:
                assert session_renderer is not None
                state = tuple(float(rng_drift.normal(0.0, sd)) for sd in session_drift_sd)
                r = session_renderer((state[0], state[1], state[2]))
            c = capture(r, m, o, stage, seed + 1000 * i + j)
            if session_offsets_mm != (0.0, 0.0):
                c = with_session_offsets(c, (float(rng.normal(0.0, session_offsets_mm[0])),
                                             float(rng.normal(0.0, session_offsets_mm[1]))))  # fmt: skip
            captures[(m, o)] = c
        if progress:
            progress(i + 1, len(materials), f"captured {m}")
    ev = Evaluation(materials, capture_seconds=time.perf_counter() - t0)
    for name, fn in feature_functions(len(stage)).items():
        t1 = time.perf_counter()
        differ: list[tuple[str, float, str, str, float]] | None = [] if compare_fixed else None
        conf = leave_one_orientation_out(captures, materials, list(orientations), fn, differ)
        ev.classify_seconds[name] = time.perf_counter() - t1
        if differ is not None:
            ev.fixed_disagreements[name] = differ
        ev.confusion[name] = conf
        ev.accuracy[name] = 100.0 * float(np.trace(conf)) / float(conf.sum())
    return ev, captures


def top_confusions(ev: Evaluation, feature: str, n: int = 8) -> list[tuple[str, str, int]]:
    """Most frequent (truth, predicted) errors."""
    conf = ev.confusion[feature].copy()
    np.fill_diagonal(conf, 0)
    order = np.argsort(conf, axis=None)[::-1][:n]
    out = []
    for k in order:
        t, p = divmod(int(k), conf.shape[1])
        if conf[t, p] > 0:
            out.append((ev.materials[t], ev.materials[p], int(conf[t, p])))
    return out


# --- feature stability (Figs. 6 and 7) ------------------------------------------------


def eq12(a: npt.NDArray[np.float32], b: npt.NDArray[np.float32]) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    return float(np.mean((a[ok] - b[ok]) ** 2)) if ok.any() else float("nan")


def stability(
    renderer: Renderer,
    materials: list[str],
    probe: str,
    angles_deg: list[float],
    fold: bool,
    stage_mm: Array,
    seed: int,
) -> dict[str, Any]:
    """Distance of `probe` at each angle to its own 0-degree exemplar, and the
    class's upper bound (its distance to the nearest other material at 0 degrees)."""
    ref = {m: feature_both(capture(renderer, m, 0.0, stage_mm, seed + k)) for k, m in enumerate(materials)}
    own = ref[probe]
    bound = min(eq12(own, ref[m]) for m in materials if m != probe)
    dists = []
    for k, a in enumerate(angles_deg):
        c = capture(renderer, probe, 0.0 if fold else a, stage_mm, seed + 7919 * (k + 1), fold_deg=a if fold else 0.0)
        dists.append(eq12(feature_both(c), own))
    return {"probe": probe, "angles_deg": list(angles_deg), "distance": dists, "upper_bound": bound}
