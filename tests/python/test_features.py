# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Depth bins (BinSpec, DepthBinAccumulator) and per-frequency depth, Eq. (1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tofmat

C = 300.0  # mm/ns, the constant the authors' code used (docs/features.md)


# ---------------------------------------------------------------------------------------------
# Eq. (1)
# ---------------------------------------------------------------------------------------------
def test_speed_of_light_constant() -> None:
    assert tofmat.SPEED_OF_LIGHT_MM_PER_NS == C


def test_phase_pi_at_120_mhz_is_625_mm() -> None:
    assert tofmat.depth_from_phase_mm(math.pi, 120.0) == pytest.approx(625.0, rel=1e-12)


@pytest.mark.parametrize("freq, expected", [(16.0, 9375.0), (80.0, 1875.0), (120.0, 1250.0)])
def test_unambiguous_range(freq, expected) -> None:
    assert tofmat.unambiguous_range_mm(freq) == pytest.approx(expected, rel=1e-12)
    assert tofmat.unambiguous_range_mm(freq) == pytest.approx(C / (2 * freq * 1e-3), rel=1e-12)


def test_depth_from_phase_matches_eq1(rng) -> None:
    for f in (16.0, 80.0, 120.0, 37.5):
        for phase in rng.uniform(0, 2 * math.pi, 50):
            expected = C * phase / (4 * math.pi * f * 1e-3)  # f in 1/ns
            assert tofmat.depth_from_phase_mm(float(phase), f) == pytest.approx(expected, rel=1e-12)


def test_depth_from_phase_wraps_modulo_2pi(rng) -> None:
    for f in (16.0, 80.0, 120.0):
        for phase in rng.uniform(0, 2 * math.pi, 20):
            d = tofmat.depth_from_phase_mm(float(phase), f)
            for k in (-3, -1, 1, 2, 10):
                assert tofmat.depth_from_phase_mm(float(phase + 2 * math.pi * k), f) == pytest.approx(
                    d, rel=1e-9, abs=1e-9
                )
    assert tofmat.depth_from_phase_mm(-math.pi, 120.0) == pytest.approx(625.0)
    assert tofmat.depth_from_phase_mm(3 * math.pi, 120.0) == pytest.approx(625.0)
    assert tofmat.depth_from_phase_mm(0.0, 120.0) == 0.0
    # Always inside [0, range): 2 pi (and values that round to it) wrap to 0.
    r = tofmat.unambiguous_range_mm(120.0)
    for phase in (2 * math.pi, -2 * math.pi, 4 * math.pi, np.nextafter(2 * math.pi, 0), -1e-300, 1e6):
        d = tofmat.depth_from_phase_mm(float(phase), 120.0)
        assert 0.0 <= d < r, phase


@pytest.mark.parametrize("phase", [math.nan, math.inf, -math.inf])
def test_depth_from_non_finite_phase_is_nan(phase) -> None:
    assert math.isnan(tofmat.depth_from_phase_mm(phase, 120.0))


@pytest.mark.parametrize("freq", [0.0, -16.0, math.nan])
def test_depth_from_phase_bad_frequency_is_nan(freq) -> None:
    assert math.isnan(tofmat.depth_from_phase_mm(1.0, freq))


# ---------------------------------------------------------------------------------------------
# BinSpec
# ---------------------------------------------------------------------------------------------
def test_binspec_linspace_and_edges() -> None:
    b = tofmat.BinSpec.linspace(600.0, 1200.0, 200)
    assert (b.start_mm, b.count) == (600.0, 200)
    assert b.width_mm == pytest.approx(600.0 / 199.0, rel=1e-15)
    assert b == tofmat.BinSpec(600.0, 600.0 / 199.0, 200)
    assert b != tofmat.BinSpec(600.0, 3.0, 200)
    np.testing.assert_allclose(b.edges_mm[:-1], np.linspace(600, 1200, 200), rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.centres_mm, b.edges_mm[:-1] + b.width_mm / 2, rtol=0, atol=1e-9)
    assert "600" in repr(b)


def test_binspec_index_of_inside_and_outside() -> None:
    b = tofmat.BinSpec(600.0, 3.0, 200)
    assert b.index_of(600.0) == 0
    assert b.index_of(602.999) == 0
    assert b.index_of(603.0) == 1
    assert b.index_of(1199.999) == 199
    assert b.index_of(1200.0) == -1
    assert b.index_of(599.999) == -1
    for bad in (math.nan, math.inf, -math.inf, -1e300, 1e300):
        assert b.index_of(bad) == -1
    real = tofmat.BinSpec.linspace(600.0, 1200.0, 200)
    for j, c in enumerate(real.centres_mm):
        assert real.index_of(float(c)) == j


def test_binspec_lower_edges_belong_to_their_bin() -> None:
    # docs/features.md and bin_spec.hpp: bin j covers [start + j*width, start + (j+1)*width),
    # and edges_mm[j] is that lower edge. A depth equal to edges_mm[j] must be in bin j.
    for b in (tofmat.BinSpec.linspace(600.0, 1200.0, 200), tofmat.BinSpec(0.3, 0.1, 1000)):
        edges = b.edges_mm
        wrong = [j for j in range(b.count) if b.index_of(float(edges[j])) != j]
        assert wrong == [], (
            f"{b}: index_of(edges_mm[j]) != j for {len(wrong)} bins, first j={wrong[:5]} "
            f"(index_of(edges_mm[{wrong[0] if wrong else 0}]) = {b.index_of(float(edges[wrong[0]])) if wrong else ''})"
        )


@pytest.mark.parametrize(
    "args",
    [
        (600.0, 0.0, 10),
        (600.0, -1.0, 10),
        (600.0, math.nan, 10),
        (math.inf, 1.0, 10),
        (600.0, 1.0, 0),
        (600.0, 1.0, 65536),
    ],
)
def test_binspec_rejects_bad_specs(args) -> None:
    with pytest.raises(ValueError):
        tofmat.BinSpec(*args)


def test_binspec_linspace_rejects_bad_specs() -> None:
    for args in ((600.0, 1200.0, 1), (600.0, 600.0, 10), (1200.0, 600.0, 10)):
        with pytest.raises(ValueError):
            tofmat.BinSpec.linspace(*args)


# ---------------------------------------------------------------------------------------------
# DepthBinAccumulator
# ---------------------------------------------------------------------------------------------
def test_accumulator_add_query_count_reset() -> None:
    bins = tofmat.BinSpec(600.0, 3.0, 10)
    acc = tofmat.DepthBinAccumulator(bins, 2)
    assert acc.n_rows == 2 and acc.bins == bins
    q = acc.query()
    assert q.shape == (2, 10) and q.dtype == np.float32 and np.isnan(q).all()
    assert acc.bins_covered() == 0

    assert acc.add(601.0, np.array([1.0, 10.0], np.float32)) == 0
    assert acc.add(602.5, np.array([3.0, 20.0])) == 0  # float64 accepted
    assert acc.add(607.0, np.array([5.0, np.nan], np.float32)) == 2  # NaN row skipped
    q = acc.query()
    assert q[0, 0] == pytest.approx(2.0) and q[1, 0] == pytest.approx(15.0)
    assert q[0, 2] == pytest.approx(5.0) and np.isnan(q[1, 2])
    assert np.isnan(q[:, [1, 3, 4, 5, 6, 7, 8, 9]]).all()
    assert acc.count(0, 0) == 2 and acc.count(1, 0) == 2
    assert acc.count(0, 2) == 1 and acc.count(1, 2) == 0
    assert acc.bins_covered() == 2
    assert acc.bins_covered(min_count=2) == 1
    q2 = acc.query(min_count=2)
    assert not np.isnan(q2[:, 0]).any() and np.isnan(q2[:, 2]).all()
    np.testing.assert_array_equal(acc.query(min_count=0), acc.query(min_count=1))

    acc.reset()
    assert np.isnan(acc.query()).all()
    assert acc.bins_covered() == 0 and acc.count(0, 0) == 0


def test_accumulator_out_of_range_depth() -> None:
    acc = tofmat.DepthBinAccumulator(tofmat.BinSpec(600.0, 3.0, 10), 2)
    v = np.array([1.0, 2.0], np.float32)
    for d in (599.99, 630.0, 5000.0, -1.0, math.nan, math.inf):
        assert acc.add(d, v) == -1
    assert acc.bins_covered() == 0 and np.isnan(acc.query()).all()


def test_accumulator_add_many(rng) -> None:
    bins = tofmat.BinSpec(0.0, 1.0, 20)
    acc = tofmat.DepthBinAccumulator(bins, 2)
    depths = rng.uniform(-5, 25, 500)
    values = rng.normal(0, 1, (500, 2)).astype(np.float32)
    added = acc.add_many(depths, values)
    inside = (depths >= 0) & (depths < 20)
    assert added == inside.sum()
    idx = np.floor(depths[inside]).astype(int)
    expected = np.full((2, 20), np.nan)
    for j in range(20):
        sel = idx == j
        if sel.any():
            expected[:, j] = values[inside][sel].astype(np.float64).mean(axis=0)
        assert acc.count(0, j) == sel.sum()
    np.testing.assert_allclose(acc.query(), expected, rtol=1e-6, atol=1e-6)
    # add_many equals repeated add.
    acc2 = tofmat.DepthBinAccumulator(bins, 2)
    for d, v in zip(depths, values, strict=True):
        acc2.add(float(d), v)
    np.testing.assert_array_equal(acc2.query(), acc.query())


def test_accumulator_bad_input() -> None:
    acc = tofmat.DepthBinAccumulator(tofmat.BinSpec(0.0, 1.0, 20), 2)
    with pytest.raises(ValueError):
        acc.add(1.0, np.array([1.0, 2.0, 3.0], np.float32))
    with pytest.raises(TypeError, match="floating-point dtype"):
        acc.add(1.0, np.array([1, 2], np.int32))
    with pytest.raises(TypeError, match="array of numbers"):
        acc.add(1.0, ["a", "b"])
    with pytest.raises(ValueError, match="infinite"):
        acc.add(1.0, np.array([1.0, np.inf], np.float32))
    with pytest.raises(ValueError):
        acc.add_many(np.zeros(3), np.zeros((4, 2), np.float32))
    with pytest.raises(ValueError):
        acc.add_many(np.zeros((3, 1)), np.zeros((3, 2), np.float32))
    with pytest.raises(ValueError):
        acc.add_many(np.zeros(3), np.zeros((3, 3), np.float32))
    assert acc.bins_covered() == 0  # nothing half-added
    acc.add(1.0, [1.0, 2.0])  # an array-like of numbers
    assert acc.bins_covered() == 1
    with pytest.raises(ValueError):
        tofmat.DepthBinAccumulator(tofmat.BinSpec(0.0, 1.0, 20), 0)
    with pytest.raises(ValueError):
        tofmat.DepthBinAccumulator(tofmat.BinSpec(0.0, 1.0, 20), 17)


@pytest.mark.parametrize("row, b", [(2, 0), (0, 20), (5, 500), (2**31, 0)])
def test_accumulator_count_out_of_range_raises(row, b) -> None:
    acc = tofmat.DepthBinAccumulator(tofmat.BinSpec(0.0, 1.0, 20), 2)
    with pytest.raises(IndexError):
        acc.count(row, b)


@pytest.mark.parametrize("row, b", [(-1, 0), (0, -1)])
def test_accumulator_count_negative_raises(row, b) -> None:
    acc = tofmat.DepthBinAccumulator(tofmat.BinSpec(0.0, 1.0, 20), 2)
    with pytest.raises((IndexError, TypeError, ValueError, OverflowError)):
        acc.count(row, b)


def test_partial_sweep_through_a_real_curve_classifies(real_table, real_clf, rng) -> None:
    bins = real_table.bins
    for name in ("cork", "pvc", "copper", "leather"):
        m = real_table.index_of(name)
        curve = real_table.features[m]
        acc = tofmat.DepthBinAccumulator(bins, real_table.n_rows)
        for b in range(50, 70):
            depth = bins.start_mm + (b + rng.uniform(0.05, 0.95)) * bins.width_mm
            assert acc.add(depth, curve[:, b] + rng.normal(0, 0.1, 2).astype(np.float32)) == b
        assert acc.bins_covered() == 20
        q = acc.query()
        assert np.count_nonzero(~np.isnan(q)) == 40
        r = real_clf.classify(q)
        assert r.material == name
        assert r.valid == 40


def test_accumulated_mean_converges_to_the_curve(real_table, rng) -> None:
    m = real_table.index_of("ceramic")
    curve = real_table.features[m]
    bins = real_table.bins
    acc = tofmat.DepthBinAccumulator(bins, 2)
    n = 200
    b = rng.integers(0, 200, 60000)
    depths = bins.start_mm + (b + rng.uniform(0.05, 0.95, b.size)) * bins.width_mm
    values = (curve[:, b].T + rng.normal(0, 0.3, (b.size, 2))).astype(np.float32)
    assert acc.add_many(depths, values) == b.size
    q = acc.query(min_count=n)
    covered = ~np.isnan(q).all(axis=0)
    assert covered.sum() > 150
    # Standard error 0.3/sqrt(>=200) < 0.022 mm: 6 sigma < 0.13 mm.
    assert np.nanmax(np.abs(q[:, covered] - curve[:, covered])) < 0.13
