# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Sessions of many sweeps: how the matcher that learns its session (``Classifier(...,
learning=True)``, tofmatd's session learning) does from a session's first sweep on.

A box labels many sweeps in one capture session, and what the session does to the curves (row
offsets, the waveform's state) is common to all of them. Each session here is drawn once with the
calibration's spreads times a scale (:mod:`.scales`), and then sweeps of materials and lengths at
random follow in it; the learning matcher starts each session afresh and learns from every sweep
after labelling it, while Eq. (12) and the session matcher label each sweep on its own. Two
sources: the real curves' test split (:func:`evaluate_sequences`), and sweeps the simulated camera
renders against its own table with every target of a session at one angle
(:func:`evaluate_sim_sequences`). The matchers as they ship (the table's prior and temperatures).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from .. import ClassificationResult, Classifier, ExemplarTable
from .._progress import Progress
from ..tools.sweeps import window_starts
from .run import LENGTHS, SPLIT_SEEDS, calibrated_json
from .scales import CONFIDENT, SCALES, by_length, check_scales, overall, scaled_sessions
from .sessions import scaled_model

MATCHERS = ("eq12", "session", "learning")
# A sweep's place in its session, as reported: the first, the second to fourth, the fifth on.
STAGES = ((0, 1, "1st"), (1, 4, "2nd-4th"), (4, None, "5th on"))
# Every sweep of the split with the learner's prior weights (nothing learned): how it labels a
# session's first sweep, measured on ten times as many sweeps as the first sweeps themselves.
UNLEARNED = "every, unlearned"


# A sweep is drawn again at another window (and then another material) this many times at most
# when it holds no element the table has (a rendered material can show none at some angles).
MAX_TRIES = 50


@dataclass(frozen=True)
class SequenceRow:
    scale: float  # of the calibration's session spreads
    matcher: str  # one of MATCHERS (", table at 0/10/20/30 deg" after it: against a table of angles)
    stage: str  # one of STAGES' names: which sweeps of their session
    accuracy: dict[int, float]  # % right by sweep length
    confidently_wrong: dict[int, float]  # % of labels wrong with confidence >= 0.9, by sweep length
    sweeps: dict[int, int]
    confidently_right: dict[int, float]  # % of labels right with confidence >= 0.9, by sweep length
    yaw_deg: float | None = None  # the simulator's target angle (None: the real curves, no angle)


class SweepSource(Protocol):
    """Where sessions of sweeps come from: :class:`.sessions.CurveSessions`, or the simulator at one
    angle (:class:`_AtAngle`)."""

    table: ExemplarTable

    def session(self, rng: np.random.Generator) -> Any: ...

    def sweep(self, session: Any, m: int, start: int, length: int, rng: np.random.Generator) -> np.ndarray: ...


class _AtAngle:
    """The simulator's sessions with every target at one angle."""

    def __init__(self, sim: Any, yaw_deg: float) -> None:
        self.sim, self.yaw_deg, self.table = sim, yaw_deg, sim.table

    def session(self, rng: np.random.Generator) -> Any:
        return self.sim.session(rng, self.yaw_deg)

    def sweep(self, session: Any, m: int, start: int, length: int, rng: np.random.Generator) -> np.ndarray:
        return np.asarray(self.sim.sweep(session, m, start, length, rng))


@dataclass(frozen=True)
class _Sweep:
    session: int
    position: int  # in its session, from 0
    truth: int
    length: int
    query: np.ndarray


def draw_sequences(
    sessions: SweepSource,
    n_sessions: int,
    sweeps_per_session: int,
    lengths: tuple[int, ...],
    seed: int,
    progress: Progress | None = None,
) -> list[_Sweep]:
    """``n_sessions`` sessions of ``sweeps_per_session`` sweeps each: a material and a length (of
    ``lengths``) at random per sweep, a window at random where the material's curve has elements.
    Raises ValueError for a sweep that holds no element the table has after MAX_TRIES windows of
    each of MAX_TRIES materials."""
    if n_sessions < 1 or sweeps_per_session < 1:
        raise ValueError("give at least one session and one sweep per session")
    table = sessions.table
    for n in lengths:
        if not 1 <= n <= table.n_bins:
            raise ValueError(f"a sweep length must be 1..{table.n_bins}, got {n}")
    rng = np.random.default_rng(seed)
    out: list[_Sweep] = []
    for s in range(n_sessions):
        if progress:
            progress(s, n_sessions, f"session {s + 1} of {n_sessions}")
        session = sessions.session(rng)
        for k in range(sweeps_per_session):
            q = None
            for _ in range(MAX_TRIES):
                while True:
                    m = int(rng.integers(0, len(table.materials)))
                    n = int(lengths[rng.integers(0, len(lengths))])
                    starts = window_starts(table, m, n)
                    if starts.size:
                        break
                for _ in range(MAX_TRIES):
                    drawn = sessions.sweep(session, m, int(starts[rng.integers(0, starts.size)]), n, rng)
                    if (np.isfinite(drawn) & np.isfinite(table.features[m])).any():
                        q = drawn
                        break
                if q is not None:
                    break
            if q is None:
                raise ValueError(f"no sweep with an element of the table in {MAX_TRIES} materials' windows")
            out.append(_Sweep(s, k, m, n, q))
    return out


def _right(results: list[ClassificationResult], sweeps: list[_Sweep], owner: np.ndarray | None) -> np.ndarray:
    """Whether each result names its sweep's material: its entry's, ``owner`` mapping a table of
    angles' entries to the materials (angle_tables.record_angle_table)."""
    index = np.array([r.index for r in results], dtype=np.int64)
    if owner is not None:
        index = np.where(index >= 0, owner[np.clip(index, 0, None)], -1)
    right: np.ndarray = index == np.array([s.truth for s in sweeps], dtype=np.int64)
    return right


def _label(
    sweeps: list[_Sweep], table: ExemplarTable, owner: np.ndarray | None = None
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each matcher's (right, confident) per sweep against ``table`` (with ``owner``: a table of
    angles, right when the best exemplar is of the sweep's material); the learning one session by
    session, learning from each sweep after it labels it."""
    eq12 = Classifier(table, method="eq12")
    session = Classifier(table, method="session")
    learning = Classifier(table, method="session", learning=True)
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, c in (("eq12", eq12), ("session", session)):
        results = c.classify_batch(np.stack([s.query for s in sweeps]))
        out[name] = (_right(results, sweeps, owner), np.array([r.confidence >= CONFIDENT for r in results]))
    learned, sure = [], []
    current = -1
    for s in sweeps:
        if s.session != current:
            learning.reset_session()
            current = s.session
        r = learning.classify(s.query)
        learned.append(r)
        sure.append(r.confidence >= CONFIDENT)
        learning.learn(s.query)
    out["learning"] = (_right(learned, sweeps, owner), np.array(sure))
    learning.reset_session()
    results = learning.classify_batch(np.stack([s.query for s in sweeps]))  # (classify does not learn)
    out[UNLEARNED] = (_right(results, sweeps, owner), np.array([r.confidence >= CONFIDENT for r in results]))
    return out


def evaluate_sequences(
    table: ExemplarTable,
    scales: tuple[float, ...] = SCALES,
    n_sessions: int = 290,
    sweeps_per_session: int = 10,
    lengths: tuple[int, ...] = LENGTHS,
    progress: Progress | None = None,
) -> list[SequenceRow]:
    """Eq. (12), the session matcher and the learning matcher on sessions of many sweeps of the real
    curves' test split, at each scale of the calibration's session spreads (the same draws at every
    scale: only the spread changes)."""
    rows: list[SequenceRow] = []
    for i, (scale, sessions) in enumerate(scaled_sessions(table, scales)):
        if progress:
            progress(i, len(scales), f"sessions of {sweeps_per_session} sweeps at {scale:g} x the spread")
        sweeps = draw_sequences(sessions, n_sessions, sweeps_per_session, lengths, SPLIT_SEEDS["test"])
        rows.extend(_rows(sweeps, table, scale, sweeps_per_session, None))
    return rows


def evaluate_sim_sequences(
    table: ExemplarTable,
    scales: tuple[float, ...] = SCALES,
    yaws: tuple[float, ...] = (0.0, 10.0, 20.0, 30.0),
    n_sessions: int = 58,
    sweeps_per_session: int = 10,
    lengths: tuple[int, ...] = LENGTHS,
    progress: Progress | None = None,
    table_yaws: tuple[float, ...] = (),
) -> list[SequenceRow]:
    """The same on sweeps the simulated camera renders against ``table`` (its own, recorded at one
    angle: ``tofmat sim table``): sessions drawn with the simulator's calibration spreads times each
    scale, every target of a session at each of ``yaws`` degrees in turn (the same seeds in every
    cell: only the spread and the angle change). Rendered frame by frame: about 0.6 s a session of
    ten sweeps on one core. With ``table_yaws``, the three matchers also label the same sweeps
    against a table of ``table``'s materials at each of those angles (angle_tables.record_angle_table,
    ``table``'s calibration carried to every exemplar), in rows of their own ("learning, table at
    0/10/20/30 deg")."""
    from .angle_tables import record_angle_table
    from .sim_sessions import SimSessions, sim_session_model

    check_scales(scales)
    base = sim_session_model(calibrated_json()[0])
    angles = record_angle_table(list(table.materials), table_yaws, table, progress) if table_yaws else None
    tag = "/".join(f"{y:g}" for y in table_yaws)
    rows: list[SequenceRow] = []
    cells = [(s, y) for s in scales for y in yaws]
    for i, (scale, yaw) in enumerate(cells):
        sim = SimSessions(None, scaled_model(base, scale), table=table)
        where = f"{scale:g} x the spread, {yaw:g} deg"

        def step(done: int, total: int, what: str = "", i: int = i, where: str = where) -> None:
            if progress:
                progress(i * total + done, len(cells) * total, f"{where}: {what}")

        sweeps = draw_sequences(_AtAngle(sim, yaw), n_sessions, sweeps_per_session, lengths, SPLIT_SEEDS["test"], step)
        rows.extend(_rows(sweeps, table, scale, sweeps_per_session, yaw))
        if angles is not None:
            rows.extend(_rows(sweeps, angles[0], scale, sweeps_per_session, yaw, angles[1], f", table at {tag} deg"))
    return rows


def _rows(
    sweeps: list[_Sweep],
    table: ExemplarTable,
    scale: float,
    sweeps_per_session: int,
    yaw: float | None,
    owner: np.ndarray | None = None,
    suffix: str = "",
) -> list[SequenceRow]:
    """Every matcher's rows of one cell (a scale, and the simulator's angle): by stage, and unlearned;
    each matcher named with ``suffix`` (the rows against a table of angles)."""
    rows: list[SequenceRow] = []
    labelled = _label(sweeps, table, owner)
    position = np.array([s.position for s in sweeps])
    length = np.array([s.length for s in sweeps])
    for name in MATCHERS:
        right, sure = labelled[name]
        for lo, hi, stage in STAGES:
            in_stage = (position >= lo) & (position < (hi if hi is not None else sweeps_per_session))
            if in_stage.any():
                rows.append(
                    SequenceRow(scale, name + suffix, stage, *by_length(right, sure, length, in_stage), yaw_deg=yaw)
                )
        if sweeps_per_session > 1:  # (with one sweep a session, "1st" is every sweep already)
            right, sure = labelled[UNLEARNED if name == "learning" else name]
            rows.append(SequenceRow(scale, name + suffix, UNLEARNED, *by_length(right, sure, length), yaw_deg=yaw))
    return rows


def margins(rows: list[SequenceRow]) -> dict[tuple[float, float | None, str, str], dict[int, float]]:
    """The learning matcher's accuracy less the better of Eq. (12) and the session matcher on the
    same sweeps (against the same table), per (scale, angle, stage, matcher) and sweep length, points
    (the angle None on the real curves)."""
    out: dict[tuple[float, float | None, str, str], dict[int, float]] = {}
    by = {(r.scale, r.yaw_deg, r.matcher, r.stage): r for r in rows}
    for r in rows:
        if not r.matcher.startswith("learning"):
            continue
        suffix = r.matcher[len("learning") :]
        cells = {}
        for n, a in r.accuracy.items():
            better = max(by[(r.scale, r.yaw_deg, m + suffix, r.stage)].accuracy[n] for m in ("eq12", "session"))
            cells[n] = a - better
        out[(r.scale, r.yaw_deg, r.stage, r.matcher)] = cells
    return out


def format_markdown(rows: list[SequenceRow]) -> str:
    lengths = sorted({n for r in rows for n in r.accuracy})
    head = " | ".join(f"{n} bins" for n in lengths)
    angle = any(r.yaw_deg is not None for r in rows)
    lines = [
        f"| scale | {'angle | ' if angle else ''}matcher | sweeps | {head} | confident and wrong (worst length) | "
        "confident and right (all) |",
        "|---|---|---|" + ("---|" if angle else "") + "---|" * len(lengths) + "---|---|",
    ]
    gap = margins(rows)
    for r in rows:
        cells = []
        for n in lengths:
            if n not in r.accuracy:
                cells.append("")
                continue
            cell = f"{r.accuracy[n]:.1f} %"
            if r.matcher.startswith("learning"):
                cell += f" ({gap[(r.scale, r.yaw_deg, r.stage, r.matcher)][n]:+.1f})"
            cells.append(cell)
        worst = max(r.confidently_wrong, key=lambda n: r.confidently_wrong[n])
        where = f"{r.yaw_deg:g} deg | " if angle else ""
        lines.append(
            f"| {r.scale:g} | {where}{r.matcher} | {r.stage} | {' | '.join(cells)} | "
            f"{r.confidently_wrong[worst]:.1f} % ({worst} bins) | {overall(r.confidently_right, r.sweeps):.1f} % |"
        )
    return "\n".join(lines)
