# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""How the shipped matchers hold when sessions move less, or more, than the calibration says.

docs/evaluation.md draws new sessions with the spreads the calibration measured (its per-capture
residuals, which also hold the simulator's misfit of each material). How far a real box's sessions
move is not known, so the matchers as they ship (the built-in session prior and temperatures, not
tuned again) are measured on the real curves' test split with the session spreads scaled by 0 to 2:
accuracy by sweep length, and the share of labels wrong with a confidence of 0.9 or more.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .. import Classifier, ExemplarTable
from .._progress import Progress
from .confidence import reliability_of
from .run import LENGTHS, SPLIT_SEEDS, calibrated_json
from .sessions import CurveSessions, Queries, calibrated_model, draw_queries, scaled_model

if TYPE_CHECKING:
    from ..learn import LearnedClassifier

SCALES = (0.0, 0.25, 0.5, 1.0, 2.0)
CONFIDENT = 0.9


@dataclass(frozen=True)
class ScaleRow:
    scale: float  # of the calibration's session spreads (row offsets and waveform state)
    # "eq12" or "session", as tofmat.Classifier ships them; "onnx": a learned model (tofmat train); "eq12,
    # table at 0/10/20/30 deg" and the like: against a table of each material at those angles (angle_tables)
    method: str
    accuracy: dict[int, float]  # % right by sweep length
    confidently_wrong: dict[int, float]  # % of labels wrong with confidence >= 0.9, by sweep length
    queries: dict[int, int]
    confidently_right: dict[int, float]  # % of labels right with confidence >= 0.9, by sweep length
    ece: float = 0.0  # over all lengths together (0..1)
    reliability: list[tuple[float, float, int]] = field(default_factory=list)  # (confidence, accuracy, labels)
    yaw_deg: float | None = None  # the simulator's target angle (None: the real curves, no angle)
    # The labels wrong with confidence >= 0.9: "truth -> label" and how many, most first.
    confident_errors: dict[str, int] = field(default_factory=dict)


def by_length(
    right: np.ndarray, sure: np.ndarray, lengths: np.ndarray, among: np.ndarray | None = None
) -> tuple[dict[int, float], dict[int, float], dict[int, int], dict[int, float]]:
    """Per sweep length (of the labels ``among`` selects, default all): % right, % wrong with
    confidence >= CONFIDENT, the count, and % right with confidence >= CONFIDENT; a length with no
    label is left out."""
    acc, wrong, count, sure_right = {}, {}, {}, {}
    for n in sorted(set(lengths.tolist())):
        sel = lengths == n if among is None else among & (lengths == n)
        if not sel.any():
            continue
        acc[int(n)] = 100.0 * float(right[sel].mean())
        wrong[int(n)] = 100.0 * float((sure & ~right)[sel].mean())
        count[int(n)] = int(sel.sum())
        sure_right[int(n)] = 100.0 * float((sure & right)[sel].mean())
    return acc, wrong, count, sure_right


def overall(share: dict[int, float], count: dict[int, int]) -> float:
    """A per-length share (%) over all lengths together, each length weighted by its labels."""
    total = sum(count[n] for n in share)
    return sum(share[n] * count[n] for n in share) / total if total else 0.0


def check_scales(scales: tuple[float, ...]) -> None:
    """Before any draw: ValueError for a scale that is negative or not finite."""
    if any(not (s >= 0.0 and np.isfinite(s)) for s in scales):
        raise ValueError(f"session scales must be finite and >= 0, got {scales}")


def scaled_sessions(table: ExemplarTable, scales: tuple[float, ...]) -> Iterator[tuple[float, CurveSessions]]:
    """The real curves' sessions with the calibration's spreads (row offsets and waveform state)
    times each scale. Raises ValueError for a scale that is negative or not finite."""
    check_scales(scales)
    library, device = calibrated_json()
    base = calibrated_model(library, table)
    for s in scales:
        yield s, CurveSessions(table, scaled_model(base, s), device, library)


def _rows(
    table: ExemplarTable,
    scale: float,
    q: Queries,
    yaw_deg: float | None = None,
    learned: LearnedClassifier | None = None,
) -> list[ScaleRow]:
    out = []
    names = list(table.materials)
    for method in ("eq12", "session"):
        results = Classifier(table, method=method).classify_batch(q.queries)
        label = np.array([r.index for r in results], dtype=np.int64)
        conf = np.array([r.confidence for r in results])
        out.append(_row(scale, method, label, q.truth, conf, q.lengths, yaw_deg, names))
    if learned is not None:
        label, conf = learned_labels(learned, q.queries)
        out.append(_row(scale, "onnx", label, q.truth, conf, q.lengths, yaw_deg, names))
    return out


def _row(
    scale: float,
    method: str,
    label: np.ndarray,
    truth: np.ndarray,
    conf: np.ndarray,
    lengths: np.ndarray,
    yaw_deg: float | None,
    names: list[str],
) -> ScaleRow:
    right = label == truth
    ece, diagram = reliability_of(conf, right)
    errors = Counter(f"{names[truth[i]]} -> {names[label[i]]}" for i in np.flatnonzero(~right & (conf >= CONFIDENT)))
    return ScaleRow(
        scale, method, *by_length(right, conf >= CONFIDENT, lengths), ece, diagram, yaw_deg, _most_first(errors)
    )


def _most_first(counts: Counter[str]) -> dict[str, int]:
    """The pairs by count, most first (ties by name)."""
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))


def learned_labels(model: LearnedClassifier, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A learned model's labels as it ships (LearnedClassifier.classify over every material, with the
    temperatures its metadata carries): each label's table index, and its confidence."""
    from ..learn.model import SMALLEST_SHARE
    from .confidence import probabilities

    p = model.probabilities(queries).astype(np.float64)
    p = p / np.maximum(p.sum(axis=1, keepdims=True), np.finfo(np.float64).tiny)
    distance = -np.log(np.maximum(p, SMALLEST_SHARE))
    rows = model.contract.rows
    conf = np.empty(len(queries))
    for i, q in enumerate(queries):
        t = model.calibration.temperature(float(np.isfinite(q).sum()) / rows)
        conf[i] = probabilities(distance[i : i + 1], t)[0].max()
    return np.argmin(distance, axis=1), conf


def evaluate_scales(
    table: ExemplarTable,
    scales: tuple[float, ...] = SCALES,
    sessions_per_material: int = 10,
    lengths: tuple[int, ...] = LENGTHS,
    progress: Progress | None = None,
    learned: LearnedClassifier | None = None,
) -> list[ScaleRow]:
    """The shipped matchers on the real curves' test split, sessions drawn with the calibration's
    spreads times each scale (the same seeds at every scale: only the spread changes); ``learned``:
    also a learned model trained for ``table``."""
    out: list[ScaleRow] = []
    for i, (s, sessions) in enumerate(scaled_sessions(table, scales)):
        if progress:
            progress(i, len(scales), f"sessions at {s:g} x the calibration's spread")
        q = draw_queries(sessions, list(lengths), sessions_per_material, SPLIT_SEEDS["test"])
        out.extend(_rows(table, s, q, learned=learned))
    return out


def evaluate_sim_scales(
    table: ExemplarTable,
    scales: tuple[float, ...] = SCALES,
    yaws: tuple[float, ...] = (0.0, 10.0, 20.0, 30.0),
    sessions_per_material: int = 2,
    lengths: tuple[int, ...] = LENGTHS,
    progress: Progress | None = None,
    learned: LearnedClassifier | None = None,
    table_yaws: tuple[float, ...] = (),
) -> list[ScaleRow]:
    """The shipped matchers (and ``learned``, a model trained for ``table``) on simulator sweeps
    against ``table`` (the simulated camera's, recorded at one angle): sessions drawn with the
    calibration's spreads times each scale, the target at each angle (the same seeds throughout:
    only the spread and the angle change). With ``table_yaws``, Eq. (12) and the session matcher
    also against a table of ``table``'s materials recorded at each of those angles
    (angle_tables.record_angle_table), on the same sweeps. Rendered: about 5 s a session of 29
    materials, per scale and angle; each angle's table about 5 s."""
    from .angle_tables import angle_table_labels, record_angle_table
    from .sim_sessions import SimSessions, sim_session_model

    check_scales(scales)
    base = sim_session_model(calibrated_json()[0])
    names = list(table.materials)
    angles = record_angle_table(names, table_yaws, table, progress) if table_yaws else None
    tag = "/".join(f"{y:g}" for y in table_yaws)
    out: list[ScaleRow] = []
    cells = [(s, y) for s in scales for y in yaws]
    for i, (s, y) in enumerate(cells):
        if progress:
            progress(i, len(cells), f"simulator sessions at {s:g} x the spread, {y:g} degrees")
        q = SimSessions(None, scaled_model(base, s), table=table).draw(
            list(lengths), sessions_per_material, SPLIT_SEEDS["test"], yaw_deg=y
        )
        out.extend(_rows(table, s, q, y, learned))
        if angles is not None:
            for method in ("eq12", "session"):
                label, conf = angle_table_labels(angles[0], angles[1], len(names), method, q.queries)
                out.append(_row(s, f"{method}, table at {tag} deg", label, q.truth, conf, q.lengths, y, names))
    return out


def format_markdown(rows: list[ScaleRow]) -> str:
    lengths = sorted({n for r in rows for n in r.accuracy})
    head = " | ".join(f"{n} bins" for n in lengths)
    angle = any(r.yaw_deg is not None for r in rows)
    lines = [
        f"| scale | {'angle | ' if angle else ''}matcher | {head} | confident and wrong (worst length) | "
        "confident and right (all) |",
        "|---|---|" + ("---|" if angle else "") + "---|" * len(lengths) + "---|---|",
    ]
    for r in rows:
        cells = " | ".join(f"{r.accuracy[n]:.1f} %" if n in r.accuracy else "-" for n in lengths)
        worst = max(r.confidently_wrong, key=lambda n: r.confidently_wrong[n])
        where = f"{r.yaw_deg:g} deg | " if angle else ""
        lines.append(
            f"| {r.scale:g} | {where}{r.method} | {cells} | {r.confidently_wrong[worst]:.1f} % ({worst} bins) | "
            f"{overall(r.confidently_right, r.queries):.1f} % |"
        )
    lines.extend(confident_errors(rows))
    return "\n".join(lines)


def confident_errors(rows: list[ScaleRow], most: int = 8) -> list[str]:
    """Under the table: each matcher's labels wrong with confidence >= 0.9 over all its rows, as
    "truth -> label" and their count, most first (the first ``most``); nothing if there are none."""
    out: list[str] = []
    for method in dict.fromkeys(r.method for r in rows):
        total = sum((Counter(r.confident_errors) for r in rows if r.method == method), Counter[str]())
        if not total:
            continue
        pairs = list(_most_first(total).items())
        shown = ", ".join(f"{k} {v}" for k, v in pairs[:most])
        rest = len(pairs) - most
        more = f", and {rest} other pair{'s' if rest > 1 else ''}" if rest > 0 else ""
        n = sum(total.values())
        if not out:
            out.append("")
        out.append(f"Confidently wrong, {method} ({n} label{'s' if n > 1 else ''}; truth -> label): {shown}{more}.")
    return out
