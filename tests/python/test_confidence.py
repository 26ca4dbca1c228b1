# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Confidence and the open set in the SDK: the tuned calibration is what the evaluation fits on its
tuning split (fitted again here, made safe at every session size tried), every result carries
probabilities and a fit, a best match that fits badly flattens them as the evaluation's reference
says, a query unlike any material is ``unknown`` and a material's own sweep is not, and Eq. (12) is
never unknown."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tofmat
from tofmat.evaluation.confidence import fit_temperatures, fit_tempering, probabilities, tail_safe
from tofmat.evaluation.matchers import CompiledSessionMatcher, Eq12Matcher, SessionParams
from tofmat.evaluation.open_set import choose_thresholds, open_set_curves
from tofmat.evaluation.run import LENGTHS, SPLIT_SEEDS, TAIL_SCALES, TAIL_SESSIONS_FACTOR, calibrated_json, scored
from tofmat.evaluation.sessions import CurveSessions, calibrated_model, draw_queries, scaled_model


@pytest.fixture(scope="module")
def tuning(real_table: tofmat.ExemplarTable):  # type: ignore[no-untyped-def]
    library, device = calibrated_json()
    model = calibrated_model(library, real_table)
    cs = CurveSessions(real_table, model, device, library)
    scaled = [
        draw_queries(
            CurveSessions(real_table, scaled_model(model, x), device, library),
            list(LENGTHS),
            10 * TAIL_SESSIONS_FACTOR,
            SPLIT_SEEDS["tune"],
        )
        for x in TAIL_SCALES
    ]
    return model, draw_queries(cs, list(LENGTHS), 10, SPLIT_SEEDS["tune"]), scaled


def test_the_tuned_calibration_is_what_the_tuning_split_fits(real_table: tofmat.ExemplarTable, tuning) -> None:  # type: ignore[no-untyped-def]
    model, q, scaled = tuning
    params = SessionParams(model.offsets_sd_mm, drift_sd_mm=(5.0, 3.0), floor_mm=0.5, huber_k=3.0)
    for method, matcher in (("eq12", Eq12Matcher(real_table)), ("session", CompiledSessionMatcher(real_table, params))):
        fitted = fit_temperatures(scored(matcher, q.queries)[1], q.truth, q.lengths)
        fitted = tail_safe(
            fitted,
            [(scored(matcher, x.queries)[1], x.truth, x.lengths) for x in scaled],
        )
        tuned = tofmat.Calibration.tuned(method)
        assert [n for n, _ in tuned.temperatures] == list(LENGTHS)
        for n, t in tuned.temperatures:
            assert t == pytest.approx(fitted[int(n)], rel=1e-3), (method, n)
    prior = tofmat.SessionPrior(list(model.offsets_sd_mm))
    chosen = choose_thresholds(open_set_curves(real_table, prior, q))
    tuned = tofmat.Calibration.tuned("session")
    assert [n for n, _ in tuned.unknown_fits] == list(LENGTHS)
    for n, f in tuned.unknown_fits:
        assert f == pytest.approx(chosen[int(n)], rel=1e-3), n
    assert tofmat.Calibration.tuned("eq12").unknown_fits == []


def test_results_carry_probabilities_and_a_fit(real_table: tofmat.ExemplarTable, rng: np.random.Generator) -> None:
    m = real_table.index_of("cork")
    q = real_table.features[m].copy()
    q[:, 60:90] += rng.normal(0.0, 0.2, (2, 30)).astype(np.float32)
    q[:, :60] = np.nan
    q[:, 90:] = np.nan
    for method in ("eq12", "session"):
        r = tofmat.Classifier(real_table, method=method).classify(q)  # type: ignore[arg-type]
        p = np.array([x.probability for x in r.ranking])
        assert p.sum() == pytest.approx(1.0) and np.all(np.diff(p) <= 0)
        assert r.confidence == p[0] and 0.0 < r.confidence <= 1.0
        assert r.material == "cork" and r.nearest == "cork" and not r.unknown and r.index == m
        assert math.isnan(r.fit) if method == "eq12" else math.isfinite(r.fit)


def test_a_best_match_that_fits_badly_flattens_the_confidence(real_table: tofmat.ExemplarTable) -> None:
    m = real_table.index_of("cork")
    q = real_table.features[m].copy()
    q[:, :40] = np.nan
    q[:, 70:] = np.nan
    clf = tofmat.Classifier(real_table, method="session")
    good = clf.classify(q)
    q[0, 40:70] += np.tile(np.array([-3.0, 3.0], dtype=np.float32), 15)  # bin to bin: no session does that
    bad = clf.classify(q)
    assert clf.vagueness is not None
    vague = clf.vagueness[bad.ranking[0].index]
    assert fit_tempering([good.ranking[0].fit], [good.ranking[0].valid])[0] == 1.0
    g = float(fit_tempering([bad.ranking[0].fit], [bad.ranking[0].valid], [vague])[0])
    assert g > 2.0
    # judge() in the C++ core: softmax(-d / (T g)), T the length's (elements over the table's rows).
    t = tofmat.Calibration.tuned("session").temperature(bad.ranking[0].valid / real_table.n_rows)
    d = np.array([[r.distance for r in bad.ranking]])
    expected = probabilities(d, t * g)[0]
    assert np.allclose([r.probability for r in bad.ranking], expected, rtol=1e-9, atol=1e-12)
    assert bad.confidence < probabilities(d, t)[0][0]


def test_a_candidate_that_fits_only_by_its_wide_noise_gives_no_confident_label() -> None:
    # Two quiet curves and one whose noise is 5 mm (the simulator's aluminium: a dark, specular
    # material's frames scatter by millimetres). A query of "a" bent in a way no session explains is
    # explained only by the vague candidate's noise: it wins, but judged at the table's typical noise
    # it fits no better than the others, so the label is not a confident one.
    bins = tofmat.BinSpec(600.0, 3.0, 60)
    x = np.linspace(-1.0, 1.0, 60)
    curves = np.stack(
        [np.stack([10.0 + 4.0 * x, -2.0 + x]), np.stack([14.0 - 3.0 * x, 1.0 - x]), np.stack([12.0 + 0 * x, 0 * x])]
    ).astype(np.float32)
    table = tofmat.ExemplarTable(["a", "b", "vague"], curves, bins, [(16, 120), (80, 120)])
    noise = np.array([[0.2, 0.1], [0.2, 0.1], [5.0, 2.0]])
    clf = tofmat.Classifier(table, method="session", noise_mm=noise)
    assert clf.vagueness is not None
    assert clf.vagueness[0] == clf.vagueness[1] == 1.0 and clf.vagueness[2] > 30.0
    q = curves[0].copy()
    q[0] += 4.0 * np.sin(12.0 * x).astype(np.float32)  # 4 mm, bin to bin: no offset or drift
    r = clf.classify(q)
    assert r.material == "vague"
    best = r.ranking[0]
    t = clf.calibration.temperature(best.valid / table.n_rows)
    d = np.array([[m.distance for m in r.ranking]])
    at_own_noise = probabilities(d, t * float(fit_tempering([best.fit], [best.valid])[0]))[0][0]
    assert at_own_noise > 0.99  # what the confidence was before the fit was judged at the typical noise
    assert r.confidence < 0.9
    g = float(fit_tempering([best.fit], [best.valid], [clf.vagueness[2]])[0])
    assert np.allclose([m.probability for m in r.ranking], probabilities(d, t * g)[0], rtol=1e-9, atol=1e-12)
    # A quiet candidate's label is judged at its own noise, as before: the same query without the bend.
    clean = clf.classify(curves[0])
    assert clean.material == "a"
    best = clean.ranking[0]
    d = np.array([[m.distance for m in clean.ranking]])
    g = float(fit_tempering([best.fit], [best.valid])[0])
    assert clean.confidence == pytest.approx(probabilities(d, t * g)[0][0], rel=1e-9)
    # The learner (tofmatd --session-learning) and the fixed-point backend judge it so too.
    for other in (
        tofmat.Classifier(table, method="session", noise_mm=noise, learning=True),
        tofmat.Classifier(table, method="session", noise_mm=noise, backend="fixed"),
    ):
        assert other.vagueness is not None and np.allclose(other.vagueness, clf.vagueness)
        r2 = other.classify(q)
        assert r2.material == "vague" and r2.confidence < 0.9
    # Eq. (12) has no noise model: no vagueness.
    assert tofmat.Classifier(table, method="eq12").vagueness is None


def test_a_query_unlike_any_material_is_unknown(real_table: tofmat.ExemplarTable) -> None:
    # 30 bins of a curve no material has: 40 mm on the 16 MHz row, -40 on the 80 MHz row.
    q = np.full((2, 200), np.nan, dtype=np.float32)
    q[0, 50:80], q[1, 50:80] = 40.0, -40.0
    session = tofmat.Classifier(real_table, method="session", open_set=True)
    r = session.classify(q)
    assert r.unknown and r.material == "unknown" and r.index == -1
    assert r.fit > session.calibration.unknown_fit(30) and r.nearest in real_table.materials
    assert "unknown=True" in repr(r)
    # Eq. (12) has no noise model: it labels the nearest material.
    e = tofmat.Classifier(real_table, method="eq12").classify(q)
    assert not e.unknown and e.material == e.nearest
    # Without open_set (the default), or with a calibration without thresholds, nothing is rejected.
    assert not tofmat.Classifier(real_table).classify(q).unknown
    assert tofmat.Classifier(real_table).calibration.unknown_fits == []
    never = tofmat.Calibration([(1.0, 1.0)])
    assert not tofmat.Classifier(real_table, calibration=never, open_set=True).classify(q).unknown
    with pytest.raises(ValueError, match="open_set needs method='session'"):
        tofmat.Classifier(real_table, method="eq12", open_set=True)


def test_bad_calibrations_are_clear_errors() -> None:
    with pytest.raises(ValueError, match="temperature"):
        tofmat.Calibration([])
    with pytest.raises(ValueError, match="increasing"):
        tofmat.Calibration([(10.0, 1.0), (1.0, 1.0)])
    with pytest.raises(ValueError, match="> 0"):
        tofmat.Calibration([(1.0, -1.0)])
    with pytest.raises(ValueError, match="NaN"):
        tofmat.Calibration([(1.0, 1.0)], [(1.0, math.nan)])
    with pytest.raises(ValueError, match="unknown method"):
        tofmat.Calibration.tuned("onnx")
    with pytest.raises(ValueError, match="reserved"):
        tofmat.ExemplarTable(["unknown"], np.zeros((1, 1, 2)), tofmat.BinSpec(600, 3, 2), [(16, 120)])
