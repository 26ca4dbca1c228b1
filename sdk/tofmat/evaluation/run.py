# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The held-out protocol of docs/evaluation.md: draw a tuning split and a test split from separate
seeds, tune the session-robust matcher (the C++ core's) on the tuning split only, report every
matcher on the test split by sweep length, with its cost per query."""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import ExemplarTable
from .._progress import Progress
from ..learn import LearnedClassifier
from .confidence import ECE_BINS, TAIL_CONFIDENCE, TAIL_SHARE, fit_temperatures, reliability, tail_safe
from .matchers import CompiledSessionMatcher, Eq12Matcher, LearnedMatcher, Matcher, SessionParams, session_prior
from .open_set import MAX_FALSE_REJECT, choose_thresholds, open_set_curves, subset
from .sessions import CurveSessions, Queries, SessionModel, calibrated_model, draw_queries, scaled_model

LENGTHS = (1, 3, 10, 30, 100)
# Every random draw of a split comes from its own generator: nothing of the test split is seen
# while tuning.
SPLIT_SEEDS = {"tune": 1001, "test": 2002}
# The session sizes (times the calibration's spreads) at which the tuning split must show labels
# wrong with a confidence of 0.9 or more rarely (confidence.tail_safe): how far a box's sessions move
# is not known (docs/evaluation.md).
TAIL_SCALES = (0.0, 0.25, 0.5, 1.0, 2.0)
# The real curves' tuning split is drawn this many times larger for that check: a confidently wrong
# label is a rare event, and none in a split's 290 labels of a length (10 sessions of 29 materials)
# left up to 1.7 % on the test split at twice the spread; none in 1,740 bounds it near 0.2 %. (The
# simulator's split is rendered, at about 5 s a session: its check uses the split's own size for
# every length, and SIM_SHORT_TAIL_FACTOR times it for the short ones.)
TAIL_SESSIONS_FACTOR = 6
# The simulator's sweeps of up to SIM_SHORT_TAIL_BINS bins are the ones Eq. (12) is confidently wrong
# on when a session moves twice as far as the calibration's (its 1-bin labels: 1.2 % in sessions of
# sweeps at 2 x, where none of the split's own 348 a spread was): the check draws them this many times
# as often, each in a session of its own (the session's state is what makes a label confidently
# wrong). Their frames are few, but each session builds its own renderer: the table's calibration
# takes about three times the CPU it did without them (19 min of one core against 6).
SIM_SHORT_TAIL_FACTOR = 8
SIM_SHORT_TAIL_BINS = 3

# The tuning grid of the session matcher (its offset prior is the calibration's spread, not tuned).
DRIFT_GRID: tuple[tuple[float, ...], ...] = ((), (3.0,), (5.0, 3.0))
FLOOR_GRID = (0.1, 0.3, 0.5, 1.0, 2.0)
HUBER_GRID = (3.0, math.inf)


@dataclass(frozen=True)
class Row:
    source: str
    method: str
    split: str
    accuracy: dict[int, float]  # % right by sweep length
    queries: dict[int, int]
    us_per_query: float  # host time per query (the whole batch / its queries)
    temperature: dict[int, float] = field(
        default_factory=dict
    )  # of the confidence per length, fitted on the tuning split
    ece: float = math.nan  # expected calibration error of that confidence on this split, 0..1
    reliability: list[tuple[float, float, int]] = field(default_factory=list)  # (confidence, accuracy, queries)
    # Per sweep length, queries by true material (row) and label (column), the table's order.
    confusion: dict[int, list[list[int]]] = field(default_factory=dict)


@dataclass(frozen=True)
class OpenSetRow:
    """The session matcher's open set on one split: per sweep length the thresholds (chosen on the
    tuning split), the share of known queries rejected and of held-out materials' queries accepted,
    and (test split, the longest... every length) each held-out material's accepted share."""

    split: str
    thresholds: dict[int, float]
    false_reject: dict[int, float]
    false_accept: dict[int, float]
    accepted_by_material: dict[int, dict[str, float]]


@dataclass
class SourceResult:
    source: str
    description: str
    materials: int
    rows: list[Row] = field(default_factory=list)
    tuned: SessionParams | None = None
    tuning: list[tuple[SessionParams, float]] = field(default_factory=list)  # each setting and its tuning score
    open_set: list[OpenSetRow] = field(default_factory=list)
    seconds: float = 0.0
    names: list[str] = field(default_factory=list)  # the table's materials (the confusions' order)
    tail_scales: tuple[float, ...] = ()  # the session sizes the temperatures were made safe at (none: nominal only)


def confusion_by_length(scores: np.ndarray, q: Queries) -> dict[int, list[list[int]]]:
    """Per sweep length, the count of queries of each true material (row) given each label
    (column: the best score's material)."""
    n = scores.shape[1]
    labels = np.argmin(scores, axis=1)
    out: dict[int, list[list[int]]] = {}
    for length in sorted(set(q.lengths.tolist())):
        m = np.zeros((n, n), dtype=np.int64)
        sel = q.lengths == length
        np.add.at(m, (q.truth[sel], labels[sel]), 1)
        out[int(length)] = m.tolist()
    return out


def accuracy_by_length(scores: np.ndarray, q: Queries) -> tuple[dict[int, float], dict[int, int]]:
    pred = np.argmin(scores, axis=1)
    acc: dict[int, float] = {}
    count: dict[int, int] = {}
    for n in sorted(set(q.lengths.tolist())):
        sel = q.lengths == n
        count[n] = int(sel.sum())
        acc[n] = 100.0 * float(np.mean(pred[sel] == q.truth[sel]))
    return acc, count


def scored(matcher: Matcher, queries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A matcher's scores, and the scores the confidence's softmax takes: each query's divided by
    its best match's fit tempering where the matcher has one (the C++ core's judge() does so), from
    one classification."""
    both = getattr(matcher, "scored", None)
    if both is None:
        s = matcher.scores(queries)
        return s, s
    s, g = both(queries)
    return s, s / g[:, None]


def _score(matcher: Matcher, q: Queries) -> tuple[np.ndarray, np.ndarray, float]:
    t0 = time.perf_counter()
    s, c = scored(matcher, q.queries)
    return s, c, 1e6 * (time.perf_counter() - t0) / max(1, len(q.truth))


def tune(
    table: ExemplarTable, model: SessionModel, q: Queries, progress: Progress | None = None
) -> list[tuple[SessionParams, float]]:
    """Every setting of the grid with its mean accuracy over the sweep lengths on ``q`` (the tuning
    split), best first (ties: the simpler setting, fewer drift terms, then the larger floor)."""
    grid = list(itertools.product(DRIFT_GRID, FLOOR_GRID, HUBER_GRID))
    out: list[tuple[SessionParams, float]] = []
    for i, (drift, floor, k) in enumerate(grid):
        if progress:
            progress(i, len(grid), "tuning the session matcher")
        p = SessionParams(model.offsets_sd_mm, drift_sd_mm=drift, floor_mm=floor, huber_k=k)
        acc, _ = accuracy_by_length(CompiledSessionMatcher(table, p).scores(q.queries), q)
        out.append((p, float(np.mean(list(acc.values())))))
    out.sort(key=lambda t: (-t[1], len(t[0].drift_sd_mm), -t[0].floor_mm))
    return out


def evaluate_source(
    source: str,
    description: str,
    table: ExemplarTable,
    model: SessionModel,
    draw: Callable[[int], Queries],
    progress: Progress | None = None,
    learned: Sequence[Matcher] = (),
    draw_scaled: Callable[[float, int], Queries] | None = None,
) -> SourceResult:
    """``draw(seed)``: the queries of one split. ``learned``: learned models' matchers, reported
    beside the exemplar matchers. ``draw_scaled(scale, seed)``: the queries of a split with the
    session spreads times ``scale``; given, every matcher's temperatures (the learned models' too, as
    ``tofmat train`` fits them) are made safe (confidence.tail_safe) on the tuning split at each of
    TAIL_SCALES."""
    t0 = time.perf_counter()
    res = SourceResult(source, description, len(table.materials), names=list(table.materials))
    tune_q = draw(SPLIT_SEEDS["tune"])
    res.tuning = tune(table, model, tune_q, progress)
    res.tuned = res.tuning[0][0]
    test_q = draw(SPLIT_SEEDS["test"])
    matchers: list[Matcher] = [Eq12Matcher(table), CompiledSessionMatcher(table, res.tuned), *learned]
    temperature: dict[str, dict[int, float]] = {}
    scaled_tune: list[Queries] = []
    if draw_scaled is not None:
        if progress:
            progress(0, 1, "the tuning split at other session sizes")
        scaled_tune = [draw_scaled(x, SPLIT_SEEDS["tune"]) for x in TAIL_SCALES]
        res.tail_scales = TAIL_SCALES
    for split, q in (("tune", tune_q), ("test", test_q)):  # (the tuning split first: it fits T)
        for m in matchers:
            s, c, us = _score(m, q)
            acc, count = accuracy_by_length(s, q)
            if split == "tune":
                t = fit_temperatures(c, q.truth, q.lengths)
                if scaled_tune:
                    t = tail_safe(t, [(scored(m, x.queries)[1], x.truth, x.lengths) for x in scaled_tune])
                temperature[m.name] = t
            ece, diagram = reliability(c, q.truth, q.lengths, temperature[m.name])
            res.rows.append(
                Row(source, m.name, split, acc, count, us, temperature[m.name], ece, diagram, confusion_by_length(s, q))
            )
    thresholds: dict[int, float] = {}
    for split, q in (("tune", tune_q), ("test", test_q)):  # (the tuning split first: it chooses the thresholds)
        if progress:
            progress(0, 1, f"open set, {split} split")
        curves = open_set_curves(table, session_prior(res.tuned), q)
        if split == "tune":
            thresholds = choose_thresholds(curves)
        by_material = {
            n: dict(
                zip(
                    table.materials,
                    curves.accepted_by_material(thresholds, n, len(table.materials)).tolist(),
                    strict=True,
                )
            )
            for n in sorted(curves.novel)
        }
        res.open_set.append(
            OpenSetRow(split, thresholds, curves.false_reject(thresholds), curves.false_accept(thresholds), by_material)
        )
    res.seconds = time.perf_counter() - t0
    return res


def evaluate_curves(
    table: ExemplarTable,
    sessions_per_material: int,
    lengths: Sequence[int] = LENGTHS,
    progress: Progress | None = None,
    learned: LearnedClassifier | None = None,
    materials: Sequence[str] | None = None,
) -> SourceResult:
    """The real curves in new sessions (:mod:`.sessions`), with the calibrated simulator's drift;
    ``learned``: also a learned model trained for this table (``tofmat train``); ``materials``:
    only these of the table (at least two), as both the candidates and the swept targets."""
    described = f"the {len(table.materials)} stored curves in new sessions"
    if materials is not None:
        unknown = [m for m in materials if m not in table.materials]
        if unknown:
            raise ValueError(f"not in the table: {', '.join(unknown)} (it has {', '.join(table.materials)})")
        if len(set(materials)) < 2 or len(set(materials)) != len(materials):
            raise ValueError("--materials needs at least two different materials, each once")
        table = subset(table, [table.materials.index(m) for m in materials])
        described = f"{len(materials)} stored curves ({', '.join(materials)}) in new sessions, among themselves"
    library, device = calibrated_json()
    model = calibrated_model(library, table)
    cs = CurveSessions(table, model, device, library)

    def draw_scaled(scale: float, seed: int) -> Queries:
        sessions = CurveSessions(table, scaled_model(model, scale), device, library)
        return draw_queries(sessions, list(lengths), TAIL_SESSIONS_FACTOR * sessions_per_material, seed)

    return evaluate_source(
        "curves",
        _describe(model, described),
        table,
        model,
        lambda seed: draw_queries(cs, list(lengths), sessions_per_material, seed),
        progress,
        [LearnedMatcher(learned)] if learned is not None else [],
        draw_scaled,
    )


def evaluate_sim(
    materials: list[str] | None,
    sessions_per_material: int,
    lengths: Sequence[int] = LENGTHS,
    progress: Progress | None = None,
    table: ExemplarTable | None = None,
    learned: LearnedClassifier | None = None,
) -> SourceResult:
    """Simulator captures in new sessions against a table the simulated camera recorded
    (:mod:`.sim_sessions`): ``table`` (e.g. ``tofmat sim table``'s), or one recorded here.
    ``learned``: also a learned model trained for that table."""
    from .sim_sessions import TAIL_YAWS_DEG, SimSessions, sim_session_model

    model = sim_session_model(calibrated_json()[0])
    ss = SimSessions(materials, model, progress=progress, table=table)

    def draw_scaled(scale: float, seed: int) -> Queries:
        scaled = SimSessions(None, scaled_model(model, scale), table=ss.table)
        drawn = [
            scaled.draw(list(lengths), sessions_per_material, seed + k, progress, yaw_deg=y)
            for k, y in enumerate(TAIL_YAWS_DEG)
        ]
        short = [n for n in lengths if n <= SIM_SHORT_TAIL_BINS]
        if short:  # (their own seeds: the same draws of the other lengths with or without them)
            drawn += [
                scaled.draw(short, SIM_SHORT_TAIL_FACTOR * sessions_per_material, seed + 100 + k, progress, yaw_deg=y)
                for k, y in enumerate(TAIL_YAWS_DEG)
            ]
        return Queries(*(np.concatenate([getattr(q, f) for q in drawn]) for f in ("truth", "lengths", "queries")))

    return evaluate_source(
        "sim",
        _describe(
            model, f"simulator sweeps of {len(ss.table.materials)} materials in new sessions, against a simulated table"
        ),
        ss.table,
        model,
        lambda seed: ss.draw(list(lengths), sessions_per_material, seed, progress),
        progress,
        [LearnedMatcher(learned)] if learned is not None else [],
        draw_scaled,
    )


def calibrated_json() -> tuple[dict[str, Any], dict[str, Any]]:
    """The calibrated simulator's material library and device as JSON, with the calibration's
    per-capture fits (the loaded objects keep only what rendering needs)."""
    from ..sim import DEFAULT_DEVICE, DEFAULT_LIBRARY, data_dir

    root = data_dir()
    library = json.loads((root / "materials" / f"{DEFAULT_LIBRARY}.json").read_text())
    device = json.loads((root / "devices" / f"{DEFAULT_DEVICE}.json").read_text())
    return library, device


def _describe(model: SessionModel, what: str) -> str:
    o = ", ".join(f"{s:.2f}" for s in model.offsets_sd_mm)
    t = ", ".join(f"{s:.2f}" for s in model.state_sd)
    extra = (
        f"; dropped bins {100 * model.drop_p:.0f} %, outlier bins {100 * model.outlier_p:.1f} % of "
        f"{model.outlier_units:.1f} roughness units"
        if model.drop_p or model.outlier_p
        else ""
    )
    return f"{what}: row offsets sd {o} mm, session states sd {t}{extra}"


# A sweep length "suffices" for a matcher from this share of its test queries right on.
SUFFICIENT = 90.0


def format_confusions(r: SourceResult) -> list[str]:
    """The test split's confusions of every matcher at every sweep length (rows: the true material,
    columns: the label), and the shortest length from which each gets SUFFICIENT % right."""
    lines: list[str] = []
    short = [n[:10] for n in r.names]
    for row in sorted((x for x in r.rows if x.split == "test"), key=lambda x: x.method):
        lengths = sorted(row.confusion)
        enough = next((n for n in lengths if all(row.accuracy[m] >= SUFFICIENT for m in lengths if m >= n)), None)
        lines += [
            "",
            f"Confusions of {row.method} (test split; rows: the true material, columns: the label). "
            + (
                f"{SUFFICIENT:.0f} % right from {enough} bins on."
                if enough is not None
                else f"Under {SUFFICIENT:.0f} % right at {lengths[-1]} bins."
            ),
        ]
        for n in lengths:
            lines += ["", f"| {n} bins | " + " | ".join(short) + " |", "|---|" + "---:|" * len(short)]
            lines += [
                f"| {name} | " + " | ".join(str(c) for c in counts) + " |"
                for name, counts in zip(short, row.confusion[n], strict=True)
            ]
    return lines


def format_markdown(results: Sequence[SourceResult], confusions: bool = False) -> str:
    """The test split's table (and the tuning split's beside it), per source; ``confusions``: also
    each matcher's confusion tables (format_confusions)."""
    lines: list[str] = []
    for r in results:
        lengths = sorted(next(iter(r.rows)).accuracy) if r.rows else []
        lines += [f"### {r.source}: {r.description}", ""]
        head = "| method | split | " + " | ".join(f"{n} bins" for n in lengths) + " | ECE | host us / query |"
        lines += [head, "|---|---|" + "---:|" * (len(lengths) + 2)]
        for row in sorted(r.rows, key=lambda x: (x.split != "test", x.method)):
            cells = " | ".join(f"{row.accuracy[n]:.1f} %" for n in lengths)
            lines.append(f"| {row.method} | {row.split} | {cells} | {100 * row.ece:.1f} % | {row.us_per_query:.0f} |")
        if r.rows:
            counts = next(x for x in r.rows if x.split == "test").queries
            lines.append("")
            lines.append("Test queries per length: " + ", ".join(f"{n} bins {counts[n]}" for n in lengths) + ".")
            temps = {x.method: x.temperature for x in r.rows if x.split == "test"}
            lines.append(
                "Confidence: softmax(-score / T) over the candidates, T fitted on the tuning split for each length ("
                + "; ".join(
                    f"{m}: " + ", ".join(f"{t:.3g}" for _n, t in sorted(ts.items())) for m, ts in sorted(temps.items())
                )
                + f"); ECE over {ECE_BINS} confidence bins, all lengths together."
                + (
                    " Every matcher's T raised until "
                    + (f"at most {100 * TAIL_SHARE:g} %" if TAIL_SHARE > 0 else "none")
                    + f" of a length's tuning labels are wrong with a confidence of {TAIL_CONFIDENCE:g} or more"
                    " at session spreads of " + ", ".join(f"{x:g}" for x in r.tail_scales) + " x the calibration's."
                    if r.tail_scales
                    else ""
                )
            )
        for o in r.open_set:
            if o.split != "test":
                continue
            ns = sorted(o.thresholds)
            lines += [
                "",
                f"Open set (session matcher; thresholds on the fit chosen on the tuning split to reject "
                f"{100 * MAX_FALSE_REJECT:.0f} % of known queries at each length; test split):",
                "",
                "| | " + " | ".join(f"{n} bins" for n in ns) + " |",
                "|---|" + "---:|" * len(ns),
                "| threshold (fit) | " + " | ".join(f"{o.thresholds[n]:.2f}" for n in ns) + " |",
                "| known rejected (false reject) | "
                + " | ".join(f"{100 * o.false_reject[n]:.1f} %" for n in ns)
                + " |",
                "| held-out accepted (false accept) | "
                + " | ".join(f"{100 * o.false_accept[n]:.1f} %" for n in ns)
                + " |",
            ]
            longest = ns[-1]
            caught = sorted(
                ((1.0 - a, m) for m, a in o.accepted_by_material[longest].items() if a == a and a < 1.0), reverse=True
            )
            lines += [
                "",
                f"Held out at {longest} bins, the materials rejected at least once: "
                + (", ".join(f"{m} {100 * c:.0f} %" for c, m in caught) or "none")
                + ".",
            ]
        if r.tuned is not None:
            t = r.tuned
            lines.append(
                f"Tuned on the tuning split: drift priors {list(t.drift_sd_mm) or 'none'} mm, floor {t.floor_mm:g} mm, "
                f"Huber k {t.huber_k:g}, offset priors {', '.join(f'{s:.2f}' for s in t.offset_sd_mm)} mm "
                f"(the calibration's spread); {r.seconds:.0f} s."
            )
        if confusions:
            lines += format_confusions(r)
        lines.append("")
    return "\n".join(lines)
