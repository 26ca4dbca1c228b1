# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The matcher that learns its session (``Classifier(..., learning=True)``, tofmatd's session learning;
firmware/core/include/tofmat/core/session_learner.hpp): its score is the mixture of the session
matcher under scaled priors, its weights follow the sweeps it learns from, and on sessions of many
sweeps of the real curves and of the simulated camera it does what docs/evaluation.md says."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import tofmat
from tofmat.cli import main
from tofmat.evaluation.sequences import (
    MATCHERS,
    UNLEARNED,
    evaluate_sequences,
    evaluate_sim_sequences,
    format_markdown,
    margins,
)

SCALES = [0.0, 0.25, 0.5, 1.0, 2.0, 4.0]
# The weights a session starts from (SessionLearning::prior_weights): the calibration's scale and twice it.
PRIOR_WEIGHTS = [0.02, 0.02, 0.02, 0.70, 0.20, 0.04]


def scaled(prior: tofmat.SessionPrior, s: float) -> tofmat.SessionPrior:
    return tofmat.SessionPrior(
        [s * v for v in prior.offset_sd_mm],
        drift1_sd_mm=s * prior.drift1_sd_mm,
        drift2_sd_mm=s * prior.drift2_sd_mm,
        noise_scale=prior.noise_scale,
        floor_mm=prior.floor_mm,
        huber_k=prior.huber_k,
        iterations=prior.iterations,
    )


def sweep(table: tofmat.ExemplarTable, material: str, lo: int, n: int, rng: np.random.Generator,
          offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:  # fmt: skip
    q = np.full((table.n_rows, table.n_bins), np.nan, np.float32)
    part = table.features[table.index_of(material), :, lo : lo + n].astype(np.float64)
    q[:, lo : lo + n] = part + np.array(offset)[:, None] + rng.normal(0.0, 0.1, part.shape)
    return q


def learned_shift(table: tofmat.ExemplarTable, session: dict[str, object]) -> np.ndarray:
    """The learned offsets and drift at every element (n_rows, n_bins): what the scales above 0 take
    out of a query before they score it (session_offsets.hpp)."""
    x = 2.0 * ((np.arange(table.n_bins) + 0.5) / table.n_bins - 0.5)
    offsets = np.asarray(session["offsets_mm"], np.float64)[:, None]
    drift = np.asarray(session["drift_mm"], np.float64)
    return (offsets + drift[:, :1] * x + drift[:, 1:] * 0.5 * (3.0 * x * x - 1.0)).astype(np.float32)


def test_the_score_is_the_mixture_of_the_scaled_session_matchers(real_table: tofmat.ExemplarTable) -> None:
    rng = np.random.default_rng(3)
    learning = tofmat.Classifier(real_table, learning=True)
    prior = tofmat.SessionPrior.tuned(real_table)
    by_scale = [tofmat.Classifier(real_table, prior=scaled(prior, s)) for s in SCALES]
    # Before any sweep the weights are the prior's and nothing is learned of where the session is;
    # after three sweeps they are what the sweeps' evidence made them, and the scales above 0 score
    # the query less the offsets learned so far (scale 0 as it is: the table's own session). Sweeps
    # of 9 bins: from 10 a sweep is long and its scales above 1 are scored as scale 1.
    assert learning.session["weights"] == pytest.approx(PRIOR_WEIGHTS)
    assert learning.session["offsets_mm"] == [0.0] * real_table.n_rows
    for k in range(4):
        q = sweep(real_table, ["cork", "wood", "paper", "acryl"][k], 40 + 5 * k, 9, rng, offset=(0.8, -0.3))
        got = {r.material: r.distance for r in learning.classify(q).ranking}
        w = np.array(learning.session["weights"])
        moved = q - learned_shift(real_table, learning.session)
        assert (k == 0) == bool(np.all(moved[np.isfinite(q)] == q[np.isfinite(q)]))
        per = [{r.material: r.distance for r in c.classify(q if s == 0.0 else moved).ranking}
               for s, c in zip(SCALES, by_scale, strict=True)]  # fmt: skip
        for name, d in got.items():
            terms = [math.log(wk) - p[name] for wk, p in zip(w, per, strict=True) if wk > 0]
            want = -float(np.logaddexp.reduce(terms))
            assert d == pytest.approx(want, abs=1e-6 * max(1.0, abs(want))), (k, name)
        learning.learn(q)
    s = learning.session
    assert s["sweeps"] == 4 and s["scales"] == SCALES and sum(s["weights"]) == pytest.approx(1.0)
    # Sweeps read off the table moved by 0.8 and -0.3 mm: the offsets are learned towards them.
    assert 0.3 < s["offsets_mm"][0] < 1.0 and -0.45 < s["offsets_mm"][1] < 0.0, s
    learning.reset_session()
    assert learning.session["sweeps"] == 0 and learning.session["weights"] == pytest.approx(PRIOR_WEIGHTS)
    assert learning.session["offsets_mm"] == [0.0] * real_table.n_rows


def test_an_unmoved_session_settles_on_scale_zero(real_table: tofmat.ExemplarTable) -> None:
    rng = np.random.default_rng(3)
    learning = tofmat.Classifier(real_table, learning=True)
    for k in range(4):
        learning.learn(sweep(real_table, ["cork", "wood", "paper", "acryl"][k], 40 + 5 * k, 12, rng))
    s = learning.session
    assert s["weights"][0] > 0.9 and s["scale"] < 0.1, s
    assert all(abs(o) < 0.2 for o in s["offsets_mm"]), s


def test_a_long_sweep_is_scored_no_wider_than_its_tiers_scale(real_table: tofmat.ExemplarTable) -> None:
    # From 10 bins on, the scales above 1 enter the mixture with scale 1's scores, from 40 those
    # above 0.5 with scale 0.5's; under 10 every scale with its own.
    rng = np.random.default_rng(4)
    prior = tofmat.SessionPrior.tuned(real_table)
    by_scale = [tofmat.Classifier(real_table, prior=scaled(prior, s)) for s in SCALES]
    for n, widest in ((9, None), (10, 1.0), (39, 1.0), (40, 0.5)):
        learning = tofmat.Classifier(real_table, learning=True)
        q = sweep(real_table, "wood", 50, n, rng, offset=(1.5, 0.5))
        per = [{r.material: r.distance for r in c.classify(q).ranking} for c in by_scale]
        for r in learning.classify(q).ranking:
            terms = [
                math.log(w) - per[SCALES.index(widest) if widest is not None and s > widest else k][r.material]
                for k, (s, w) in enumerate(zip(SCALES, PRIOR_WEIGHTS, strict=True))
            ]
            want = -float(np.logaddexp.reduce(terms))
            assert r.distance == pytest.approx(want, abs=1e-6 * max(1.0, abs(want))), (n, r.material)


def test_a_moved_session_is_learned_on_either_backend(real_table: tofmat.ExemplarTable) -> None:
    rng = np.random.default_rng(5)
    sweeps = [sweep(real_table, m, 30, 30, rng, offset=(4.0, 1.5)) for m in ("cork", "wood", "pvc", "paper", "mdf")]
    for backend in ("float", "fixed"):
        c = tofmat.Classifier(real_table, backend=backend, learning=True)
        for q in sweeps:
            c.learn(q)
        assert c.session["scale"] > 0.5 and c.session["weights"][0] < 1e-6, (backend, c.session)
    # The fixed-point learner labels as the float one does.
    f = tofmat.Classifier(real_table, learning=True)
    x = tofmat.Classifier(real_table, backend="fixed", learning=True)
    for q in sweeps:
        assert f.classify(q).material == x.classify(q).material
        f.learn(q)
        x.learn(q)


def test_learning_is_refused_where_it_has_no_meaning(real_table: tofmat.ExemplarTable) -> None:
    with pytest.raises(ValueError, match="learning needs method='session'"):
        tofmat.Classifier(real_table, method="eq12", learning=True)
    plain = tofmat.Classifier(real_table)
    assert plain.session is None
    q = np.full((real_table.n_rows, real_table.n_bins), np.nan, np.float32)
    with pytest.raises(ValueError, match="learning=True"):
        plain.learn(q)
    with pytest.raises(ValueError, match="learning=True"):
        plain.reset_session()
    learning = tofmat.Classifier(real_table, learning=True)
    with pytest.raises(ValueError):
        learning.learn(q)  # no element
    assert learning.session["sweeps"] == 0


def test_on_sessions_of_many_sweeps_the_learner_keeps_up_with_the_better_matcher(
    real_table: tofmat.ExemplarTable,
) -> None:
    # A short run (docs/evaluation.md has the full one): an unmoved session and one that moved by
    # the calibration's spread, sweeps of 10 and 30 bins.
    rows = evaluate_sequences(real_table, scales=(0.0, 1.0), n_sessions=40, sweeps_per_session=6, lengths=(10, 30))
    assert {r.matcher for r in rows} == set(MATCHERS)
    by = {(r.scale, r.matcher, r.stage): r for r in rows}
    assert {r.stage for r in rows} == {"1st", "2nd-4th", "5th on", UNLEARNED}
    # Every sweep of the split, the learner with its prior weights only: it labels each as a first sweep.
    assert all(sum(by[(s, m, UNLEARNED)].sweeps.values()) == 40 * 6 for s in (0.0, 1.0) for m in MATCHERS)
    gap = margins(rows)
    # With its prior weights it is near the better of the two at either spread (docs: within 5 points on
    # 5,800 sweeps a scale; 120 a cell here).
    assert all(gap[(s, None, UNLEARNED, "learning")][n] > -8.0 for s in (0.0, 1.0) for n in (10, 30)), gap
    # Unmoved: Eq. (12) beats the session matcher at 10 bins; from the fifth sweep on the learner
    # is within a few points of it (40 sessions: 80 sweeps a cell), and far above the session matcher.
    assert by[(0.0, "eq12", "5th on")].accuracy[10] > by[(0.0, "session", "5th on")].accuracy[10]
    assert gap[(0.0, None, "5th on", "learning")][10] > -5.0
    # Moved by the calibration's spread: Eq. (12) fails, the learner is with the session matcher.
    assert by[(1.0, "eq12", "5th on")].accuracy[30] < 60.0
    assert gap[(1.0, None, "5th on", "learning")][30] > -5.0
    for r in rows:
        assert sum(r.sweeps.values()) > 0 and all(0.0 <= a <= 100.0 for a in r.accuracy.values())


def test_the_command_runs_sessions_of_sweeps(db_dir: Path) -> None:
    r = CliRunner().invoke(
        main,
        [
            "evaluate",
            "--source",
            "curves",
            "--table",
            str(db_dir),
            "--session-scales",
            "0.5",
            "--sweeps-per-session",
            "3",
            "--sessions",
            "1",
        ],
    )
    assert r.exit_code == 0, r.output
    assert "| 0.5 | learning | 1st |" in r.output and "| 0.5 | eq12 | 2nd-4th |" in r.output
    bad = CliRunner().invoke(main, ["evaluate", "--source", "curves", "--sweeps-per-session", "3"])
    assert bad.exit_code == 2 and "--session-scales" in bad.output


def test_sessions_of_rendered_sweeps_hold_their_angle_and_spread(sim_table: Path) -> None:
    # The simulator's sessions of sweeps (docs/evaluation.md): every target of a session at the cell's
    # angle, its rows moved by the session's offsets; the rows of each cell carry their angle.
    from tofmat.evaluation.sessions import SessionModel
    from tofmat.evaluation.sim_sessions import SimSessions

    table = tofmat.ExemplarTable.load(str(sim_table))
    still = SessionModel((0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
    sim = SimSessions(None, still, table=table)
    cork = table.index_of("cork")

    def rendered(yaw: float, seed: int = 5) -> np.ndarray:
        rng = np.random.default_rng(seed)
        return sim.sweep(sim.session(rng, yaw), cork, 60, 20, rng)

    face_on, tilted = rendered(0.0), rendered(30.0)
    assert face_on.dtype == np.float32 and np.isfinite(face_on).any()
    np.testing.assert_array_equal(face_on, rendered(0.0))  # (seeded)
    both = np.isfinite(face_on) & np.isfinite(tilted)
    assert both.any() and np.abs(face_on - tilted)[both].max() > 0.05  # the angle reaches the renderer
    moved = SimSessions(None, SessionModel((3.0, 1.0), (0.0, 0.0, 0.0), 0.0, 0.0, 0.0), table=table)
    rng = np.random.default_rng(5)
    session = moved.session(rng, 0.0)
    assert session.yaw_deg == 0.0 and np.abs(session.offsets_mm).max() > 0.0
    with pytest.raises(ValueError, match=r"0\.\.60 degrees"):
        sim.session(np.random.default_rng(1), 75.0)

    rows = evaluate_sim_sequences(table, scales=(0.0,), yaws=(0.0, 20.0), n_sessions=4, sweeps_per_session=5,
                                  lengths=(3, 10))  # fmt: skip
    assert {r.yaw_deg for r in rows} == {0.0, 20.0} and {r.matcher for r in rows} == set(MATCHERS)
    assert all(sum(r.sweeps.values()) == 4 * 5 for r in rows if r.stage == UNLEARNED)
    gap = margins(rows)
    assert set(gap) == {(0.0, y, s, "learning") for y in (0.0, 20.0) for s in ("1st", "2nd-4th", "5th on", UNLEARNED)}
    assert "| 0 | 20 deg | learning | 5th on |" in format_markdown(rows)


def test_the_command_runs_rendered_sessions_of_sweeps(sim_table: Path) -> None:
    r = CliRunner().invoke(
        main,
        ["evaluate", "--source", "sim", "--sim-table", str(sim_table), "--session-scales", "1", "--yaws", "30",
         "--sweeps-per-session", "2", "--sim-sessions", "1"],
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "| 1 | 30 deg | learning | 1st |" in r.output and "| 1 | 30 deg | eq12 | 2nd-4th |" in r.output
    bad = CliRunner().invoke(
        main,
        ["evaluate", "--source", "sim", "--sim-table", str(sim_table), "--session-scales", "1", "--sweeps-per-session",
         "2", "--plot", "x.png"],
    )  # fmt: skip
    assert bad.exit_code == 2 and "--sweeps-per-session" in bad.output
