# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The session-robust matcher of the C++ core (``Classifier(table, method="session")``) against
its NumPy reference (tofmat.evaluation.matchers.SessionMatcher) on queries of new sessions of the
real curves, under every kind of setting; its roughness against the reference's; its errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tofmat
from tofmat.evaluation.matchers import CompiledSessionMatcher, SessionMatcher, SessionParams, session_prior
from tofmat.evaluation.sessions import CurveSessions, SessionModel, draw_queries, roughness


@pytest.fixture(scope="module")
def queries(real_table: tofmat.ExemplarTable) -> np.ndarray:
    # Offsets, noise at each material's level, outliers and dropped bins (no drift: that needs
    # the simulator, and the matcher does not care where a query came from).
    model = SessionModel((2.27, 0.73), (0.0, 0.0, 0.0), 0.05, 0.02, 18.0)
    q = draw_queries(CurveSessions(real_table, model), [1, 3, 10, 30, 100], 2, seed=5).queries
    return q


SETTINGS = [
    SessionParams((2.27, 0.73), drift_sd_mm=(5.0, 3.0), floor_mm=0.5, huber_k=3.0),  # the tuned one
    SessionParams((2.27, 0.73), drift_sd_mm=(3.0,), floor_mm=0.3, huber_k=math.inf),  # Gaussian, one drift term
    SessionParams((2.27, 0.73), floor_mm=0.1, huber_k=1.5, iterations=5),  # offsets only, hard Huber
    SessionParams((0.0, 0.0), drift_sd_mm=(0.0, 2.0), floor_mm=1.0),  # no offset term, degree 2 only
    SessionParams((0.0, 0.0), noise_scale=1.0, floor_mm=0.0),  # no nuisance term at all
]


@pytest.mark.parametrize("params", SETTINGS, ids=lambda p: f"drift{p.drift_sd_mm}-k{p.huber_k}-floor{p.floor_mm}")
def test_the_compiled_matcher_equals_its_numpy_reference(
    real_table: tofmat.ExemplarTable, queries: np.ndarray, params: SessionParams
) -> None:
    ref = SessionMatcher(real_table, params).scores(queries)
    got = CompiledSessionMatcher(real_table, params).scores(queries)
    assert np.array_equal(np.isinf(ref), np.isinf(got))
    finite = np.isfinite(ref)
    assert np.allclose(got[finite], ref[finite], rtol=1e-9, atol=1e-9), np.max(np.abs(got - ref)[finite])
    # The same labels (ties aside: none here).
    assert np.array_equal(np.argmin(got, axis=1), np.argmin(ref, axis=1))


def test_both_take_the_tables_stored_noise(real_table: tofmat.ExemplarTable, queries: np.ndarray) -> None:
    # A table carrying its noise (format 1.1): measured for half the materials, NaN for the rest.
    stored = np.full((29, 2), np.nan)
    stored[::2] = np.linspace(0.2, 2.0, 15)[:, None]
    noisy = real_table.with_noise(stored)
    ref = SessionMatcher(noisy, SETTINGS[0])
    assert np.allclose(ref.sigma[::2], stored[::2]) and np.array_equal(
        ref.sigma[1::2], SessionMatcher(real_table, SETTINGS[0]).sigma[1::2]
    )
    want = ref.scores(queries)
    got = CompiledSessionMatcher(noisy, SETTINGS[0]).scores(queries)
    finite = np.isfinite(want)
    assert np.allclose(got[finite], want[finite], rtol=1e-9, atol=1e-9)
    # The stored noise changes the scores: it is used, not ignored.
    assert not np.allclose(want[finite], SessionMatcher(real_table, SETTINGS[0]).scores(queries)[finite])


def test_the_roughness_is_the_reference_s(real_table: tofmat.ExemplarTable) -> None:
    got = tofmat.curve_roughness(real_table)
    ref = roughness(real_table.features.astype(np.float64))
    assert got.shape == (29, 2) and np.allclose(got, ref, rtol=1e-12)
    clf = tofmat.Classifier(real_table, method="session")
    assert clf.noise_mm is not None and np.allclose(clf.noise_mm, got)
    fl = real_table.index_of("fakeleather")
    wood = real_table.index_of("wood")
    assert got[fl, 0] > 3 * got[wood, 0]  # the noisiest curve is several times the quietest's


def test_the_tuned_prior_and_the_classifier_s_settings(real_table: tofmat.ExemplarTable) -> None:
    p = tofmat.SessionPrior.tuned(real_table)
    assert p.offset_sd_mm == [2.27, 0.73] and (p.drift1_sd_mm, p.drift2_sd_mm) == (5.0, 3.0)
    assert (p.floor_mm, p.huber_k, p.iterations) == (0.5, 3.0, 3)
    clf = tofmat.Classifier(real_table, method="session")
    assert clf.method == "session" and clf.prior is not None and clf.prior.offset_sd_mm == [2.27, 0.73]
    # The default method is the session matcher; Eq. (12) by name, without its settings.
    default = tofmat.Classifier(real_table)
    assert default.method == "session" and default.backend == "float" and default.prior is not None
    assert tofmat.Classifier(real_table, method="eq12").prior is None
    # Candidates and given noise levels.
    noise = np.full((29, 2), 0.25)
    c = tofmat.Classifier(real_table, method="session", materials=["wood", "cork"], noise_mm=noise)
    assert c.materials == ["cork", "wood"]
    r = c.classify(real_table.features[real_table.index_of("cork")])
    assert r.material == "cork" and [m.material for m in r.ranking] == ["cork", "wood"]


def test_the_fixed_point_backend_follows_the_float_one(real_table: tofmat.ExemplarTable, queries: np.ndarray) -> None:
    # (The exhaustive check against the float reference on the same quantised values:
    # tests/cpp/test_fixed_session_classifier.cpp.) On the unquantised queries the labels agree but
    # for near ties, and the settings and noise are shared.
    fixed = tofmat.Classifier(real_table, backend="fixed", method="session")
    flt = tofmat.Classifier(real_table, method="session")
    assert fixed.backend == "fixed" and fixed.prior is not None and np.array_equal(fixed.noise_mm, flt.noise_mm)
    a, b = fixed.classify_batch(queries), flt.classify_batch(queries)
    same = np.mean([x.index == y.index for x, y in zip(a, b, strict=True)])
    assert same >= 0.98, same
    diff = [
        abs(x.distance - y.distance) / (1 + abs(y.distance)) for x, y in zip(a, b, strict=True) if x.index == y.index
    ]
    assert max(diff) < 0.02, max(diff)


def test_bad_settings_are_clear_errors(real_table: tofmat.ExemplarTable) -> None:
    with pytest.raises(ValueError, match="unknown method 'nearest'"):
        tofmat.Classifier(real_table, method="nearest")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="settings of method='session'"):
        tofmat.Classifier(real_table, method="eq12", prior=tofmat.SessionPrior([1.0, 1.0]))
    with pytest.raises(ValueError, match="noise_mm"):
        tofmat.Classifier(real_table, method="session", noise_mm=np.ones((29, 3)))
    with pytest.raises(ValueError, match="3 row offsets for a table of 2 rows"):
        tofmat.Classifier(real_table, method="session", prior=tofmat.SessionPrior([1.0, 1.0, 1.0]))
    for kwargs, message in [
        ({"offset_sd_mm": [-1.0, 1.0]}, "finite and >= 0"),
        ({"offset_sd_mm": [math.nan, 1.0]}, "finite and >= 0"),
        ({"offset_sd_mm": [1.0, 1.0], "drift1_sd_mm": math.inf}, "drift"),
        ({"offset_sd_mm": [1.0, 1.0], "noise_scale": 0.0, "floor_mm": 0.0}, "no noise at all"),
        ({"offset_sd_mm": [1.0, 1.0], "huber_k": 0.0}, "huber_k"),
        ({"offset_sd_mm": [1.0, 1.0], "iterations": 0}, "iterations"),
    ]:
        with pytest.raises(ValueError, match=message):
            tofmat.SessionPrior(**kwargs)  # type: ignore[arg-type]
    clf = tofmat.Classifier(real_table, method="session")
    with pytest.raises(ValueError, match="no valid element"):
        clf.classify(np.full((2, 200), np.nan, np.float32))
    with pytest.raises(ValueError, match="infinite"):
        clf.classify(np.full((2, 200), np.inf, np.float32))
    # session_prior maps the evaluation's settings one to one.
    p = session_prior(SessionParams((1.0, 2.0), drift_sd_mm=(4.0,), floor_mm=0.2, huber_k=math.inf))
    assert (p.offset_sd_mm, p.drift1_sd_mm, p.drift2_sd_mm, p.floor_mm, p.huber_k) == (
        [1.0, 2.0],
        4.0,
        0.0,
        0.2,
        math.inf,
    )
