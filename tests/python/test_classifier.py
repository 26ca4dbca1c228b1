# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Classifier API and Eq. (12) partial matching, against an independent numpy reference."""

from __future__ import annotations

import gc
import threading
import warnings

import numpy as np
import pytest

import tofmat


# ---------------------------------------------------------------------------------------------
# Independent reference: Eq. (12) in numpy.
#   xi_p = (1/N) sum_k (v_k - v_k^p)^2 over the N elements valid (not NaN) in both.
# ---------------------------------------------------------------------------------------------
def eq12_reference(query: np.ndarray, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per material: distance (NaN when N == 0) and N. Inputs rounded to float32 first, sums in float64."""
    q = np.asarray(query, dtype=np.float32).astype(np.float64)
    ex = np.asarray(features, dtype=np.float32).astype(np.float64)
    both = ~np.isnan(q)[None] & ~np.isnan(ex)
    diff = np.where(both, q[None] - ex, 0.0)
    n = both.reshape(len(ex), -1).sum(axis=1)
    s = (diff**2).reshape(len(ex), -1).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(n > 0, s / np.maximum(n, 1), np.nan)
    return d, n


def check_against_reference(
    result: tofmat.ClassificationResult,
    query: np.ndarray,
    table: tofmat.ExemplarTable,
    candidates: list[int] | None = None,
) -> None:
    d, n = eq12_reference(query, table.features)
    cand = list(range(len(table))) if candidates is None else candidates
    expected = {i for i in cand if n[i] > 0}
    got = [m.index for m in result.ranking]
    assert len(got) == len(set(got))
    assert set(got) == expected
    for m in result.ranking:
        assert m.material == table.materials[m.index]
        assert m.valid == n[m.index]
        np.testing.assert_allclose(m.distance, d[m.index], rtol=1e-5, atol=1e-9)
    dists = [m.distance for m in result.ranking]
    assert dists == sorted(dists)
    order = sorted(expected, key=lambda i: (d[i], i))
    best = order[0]
    np.testing.assert_allclose(result.distance, d[best], rtol=1e-5, atol=1e-9)
    # The label is the reference's argmin, unless the runner-up is within float rounding of it.
    if len(order) == 1 or d[order[1]] - d[best] > 1e-5 * max(d[best], 1e-9):
        assert result.index == best, f"best is {result.material}, reference {table.materials[best]}"
    assert result.material == result.ranking[0].material
    assert result.index == result.ranking[0].index
    assert result.distance == result.ranking[0].distance
    assert result.valid == result.ranking[0].valid


def nan_query(table: tofmat.ExemplarTable) -> np.ndarray:
    return np.full((table.n_rows, table.n_bins), np.nan, dtype=np.float32)


# ---------------------------------------------------------------------------------------------
# Result structure
# ---------------------------------------------------------------------------------------------
def test_result_fields_and_full_ranking(real_table, real_clf, rng) -> None:
    m = real_table.index_of("cork")
    q = (real_table.features[m] + rng.normal(0, 0.3, (2, 200))).astype(np.float32)
    r = real_clf.classify(q)
    assert isinstance(r, tofmat.ClassificationResult)
    assert r.material == "cork" and r.index == m
    assert isinstance(r.distance, float) and r.distance > 0
    assert r.valid == 400
    assert all(isinstance(x, tofmat.RankedMatch) for x in r.ranking)
    # Every material shares elements with a full query: the ranking covers all 29.
    assert sorted(x.index for x in r.ranking) == list(range(len(real_table)))
    dists = [x.distance for x in r.ranking]
    assert dists == sorted(dists)
    check_against_reference(r, q, real_table)
    assert "cork" in repr(r) and "cork" in repr(r.ranking[0])


def test_classifier_properties(real_table, real_clf) -> None:
    assert real_clf.backend == "float"
    assert real_clf.materials == real_table.materials
    assert real_clf.table.materials == real_table.materials
    sub = tofmat.Classifier(real_table, materials=["pvc", "epvc"], method="eq12")
    assert sorted(sub.materials) == ["epvc", "pvc"]


def test_classify_batch_equals_classify(real_table, real_clf, rng) -> None:
    n = 60
    mats = rng.integers(0, len(real_table), n)
    qs = (real_table.features[mats] + rng.normal(0, 0.5, (n, 2, 200))).astype(np.float32)
    # Random partial queries, some very sparse.
    keep = rng.random((n, 1, 200)) < rng.uniform(0.02, 1.0, (n, 1, 1))
    keep[:, :, 100] = True  # at least one valid bin each (valid in every material)
    qs = np.where(keep, qs, np.nan).astype(np.float32)
    batch = real_clf.classify_batch(qs)
    assert isinstance(batch, list) and len(batch) == n
    for q, b in zip(qs, batch, strict=True):
        s = real_clf.classify(q)
        assert (b.material, b.index, b.distance, b.valid) == (s.material, s.index, s.distance, s.valid)
        assert [(m.index, m.distance, m.valid) for m in b.ranking] == [
            (m.index, m.distance, m.valid) for m in s.ranking
        ]
    assert real_clf.classify_batch(np.empty((0, 2, 200), np.float32)) == []


def test_classify_batch_names_the_bad_query(real_table, real_clf) -> None:
    qs = real_table.features[:3].copy()
    qs[1] = np.nan
    with pytest.raises(ValueError, match=r"queries\[1\].*no valid element"):
        real_clf.classify_batch(qs)
    with pytest.raises(ValueError, match=r"expected"):
        real_clf.classify_batch(real_table.features[0])


def test_materials_restrict_the_ranking(real_table, rng) -> None:
    clf = tofmat.Classifier(real_table, materials=["pvc", "epvc"], method="eq12")
    pvc, epvc = real_table.index_of("pvc"), real_table.index_of("epvc")
    for m in range(len(real_table)):
        q = real_table.features[m] + rng.normal(0, 0.3, (2, 200)).astype(np.float32)
        r = clf.classify(q)
        assert {x.material for x in r.ranking} == {"pvc", "epvc"}
        assert r.material in ("pvc", "epvc")
        check_against_reference(r, q, real_table, candidates=[pvc, epvc])
    assert clf.classify(real_table.features[epvc]).material == "epvc"
    assert clf.classify(real_table.features[pvc]).material == "pvc"


def test_a_candidate_named_twice_is_refused(real_table) -> None:
    # (issue 33) as tofmatd's --candidates: a repeat is a mistake to report, not to fold away
    with pytest.raises(ValueError, match='"pvc" is given twice'):
        tofmat.Classifier(real_table, materials=["pvc", "pvc"], method="eq12")


def test_a_material_without_a_measured_value_is_refused(real_table) -> None:
    feats = real_table.features.copy()
    feats[3] = np.nan
    t = tofmat.ExemplarTable(real_table.materials, feats, real_table.bins, real_table.rows)
    with pytest.raises(tofmat.FormatError, match=f'material "{real_table.materials[3]}" has no measured value'):
        tofmat.Classifier(t)


@pytest.mark.parametrize("materials", [["pvc", "granite"], ["granite"], ["PVC"], [""]])
def test_unknown_material_is_value_error(real_table, materials) -> None:
    with pytest.raises(ValueError):
        tofmat.Classifier(real_table, materials=materials, method="eq12")


def test_empty_candidate_list_is_value_error(real_table) -> None:
    with pytest.raises(ValueError):
        tofmat.Classifier(real_table, materials=[], method="eq12")


@pytest.mark.parametrize("backend", ["nope", "", "FLOAT", "fixed16", "Fixed"])
def test_unknown_backend_is_value_error(real_table, backend) -> None:
    with pytest.raises(ValueError, match="backend"):
        tofmat.Classifier(real_table, backend=backend, method="eq12")


# ---------------------------------------------------------------------------------------------
# Query validation
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(2, 199), (3, 200), (200, 2), (400,), (1, 2, 200), (2, 200, 1), (0, 200)])
def test_wrong_query_shape_is_value_error_naming_expected_shape(real_clf, shape) -> None:
    with pytest.raises(ValueError, match=r"\(2, 200\)"):
        real_clf.classify(np.zeros(shape, dtype=np.float32))


def test_scalar_query_is_value_error(real_clf) -> None:
    with pytest.raises(ValueError, match=r"\(2, 200\)"):
        real_clf.classify(np.float32(1.0))


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint8, np.bool_, np.complex64])
def test_non_float_dtype_is_type_error(real_clf, dtype) -> None:
    with pytest.raises(TypeError, match="dtype"):
        real_clf.classify(np.zeros((2, 200), dtype=dtype))


def test_python_lists_are_array_likes(real_table, real_clf) -> None:
    """Nested lists of numbers (NaN included) classify as the same array would; other things are TypeError."""
    q = np.full((2, 200), np.nan, np.float32)
    q[:, 40:50] = real_table.features[real_table.index_of("cork"), :, 40:50]
    as_list = q.tolist()
    assert real_clf.classify(as_list).material == real_clf.classify(q).material == "cork"
    assert real_clf.classify(as_list).distance == real_clf.classify(q).distance
    batch = real_clf.classify_batch([as_list, as_list])
    assert [r.material for r in batch] == ["cork", "cork"]
    with pytest.raises(ValueError, match=r"\(2, 200\)"):  # a list of the wrong shape: still the shape's error
        real_clf.classify(as_list[0])
    none_is_missing = [[None if np.isnan(v) else v for v in row] for row in as_list]  # numpy reads None as NaN
    assert real_clf.classify(none_is_missing).distance == real_clf.classify(q).distance
    for bad in ([["cork"] * 200] * 2, {"a": 1}, "cork"):
        with pytest.raises(TypeError, match="array of numbers"):
            real_clf.classify(bad)


def test_float64_and_other_layouts_give_the_float32_result(real_table, real_clf, rng) -> None:
    m = real_table.index_of("wood")
    q64 = real_table.features[m].astype(np.float64) + rng.normal(0, 0.4, (2, 200))
    q64[:, :50] = np.nan
    r32 = real_clf.classify(q64.astype(np.float32))
    variants = {
        "float64": q64,
        "big-endian float64": q64.astype(">f8"),
        "Fortran order": np.asfortranarray(q64.astype(np.float32)),
        "strided view": np.repeat(q64.astype(np.float32), 2, axis=1)[:, ::2],
    }
    for name, q in variants.items():
        r = real_clf.classify(q)
        assert (r.index, r.distance, r.valid) == (r32.index, r32.distance, r32.valid), name
        assert [(x.index, x.distance) for x in r.ranking] == [(x.index, x.distance) for x in r32.ranking], name
    assert r32.material == "wood"
    # classify_batch too.
    b = real_clf.classify_batch(np.stack([q64, q64]))
    assert [(x.index, x.distance) for x in b[0].ranking] == [(x.index, x.distance) for x in r32.ranking]


def test_query_is_not_modified(real_table, real_clf) -> None:
    q = real_table.features[4].copy()
    q[0, :10] = np.nan
    before = q.copy()
    real_clf.classify(q)
    real_clf.classify_batch(q[None])
    np.testing.assert_array_equal(q, before)


def test_all_nan_query_is_value_error(real_table, real_clf) -> None:
    with pytest.raises(ValueError, match="no valid element"):
        real_clf.classify(nan_query(real_table))


@pytest.mark.parametrize("big", [1e300, -4e38])
def test_float64_beyond_float32_range_names_the_range(real_table, real_clf, big) -> None:
    # Such a value must not be silently cast to Inf and blamed as "infinite".
    q = nan_query(real_table).astype(np.float64)
    q[0, 7] = big
    with pytest.raises(ValueError, match="outside the float32 range"):
        real_clf.classify(q)


@pytest.mark.parametrize("backend", ["float", "fixed"])
def test_the_fixed_backend_says_when_a_value_saturates(real_table, backend) -> None:
    # (issue 33) Near float32's limits (3e38 mm) the backends answered different materials without a
    # word. Beyond the fixed-point range (32767 steps: 1024 mm for this table built from the .npy
    # curves with 2 bits of headroom, 256 mm for the real .tmx) the fixed backend ranks the clamped
    # value and says so with a RuntimeWarning; the float one (the reference) ranks the value itself.
    q = real_table.features[3].copy()
    for method in ("eq12", "session"):
        clf = tofmat.Classifier(real_table, backend=backend, method=method)
        for big in (3e38, -5000.0):
            q[1, 50] = big
            for batch in (False, True):
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    clf.classify_batch(q[None]) if batch else clf.classify(q)
                said = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
                assert len(said) == (1 if backend == "fixed" else 0), said
                assert all("saturate in the fixed-point backend" in w for w in said)
        q[1, 50] = 900.0  # (inside: nothing to say)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert clf.classify(q).material


@pytest.mark.parametrize("bad", [np.inf, -np.inf])
@pytest.mark.parametrize("where", [(0, 0), (1, 199), (0, 123)])
def test_infinite_query_element_is_value_error(real_table, real_clf, bad, where) -> None:
    q = real_table.features[0].copy()
    q[where] = bad
    with pytest.raises(ValueError, match="infinite"):
        real_clf.classify(q)
    # Even when the rest of the query is missing.
    q2 = nan_query(real_table)
    q2[where] = bad
    with pytest.raises(ValueError):
        real_clf.classify(q2)


# ---------------------------------------------------------------------------------------------
# Partial matching: NaN = missing
# ---------------------------------------------------------------------------------------------
def test_nan_elements_are_missing_matches_numpy_reference(real_table, real_clf, rng) -> None:
    feats = real_table.features
    for trial in range(80):
        m = int(rng.integers(0, len(real_table)))
        q = feats[m] + rng.normal(0, rng.uniform(0.05, 3.0), (2, 200))
        # Random masks of every density, elementwise (rows independently) and bin-wise.
        if trial % 2:
            mask = rng.random((2, 200)) < rng.uniform(0.002, 1.0)
        else:
            start = int(rng.integers(0, 200))
            mask = np.zeros((2, 200), bool)
            mask[:, start : start + int(rng.integers(1, 40))] = True
        if not mask.any():
            mask[int(rng.integers(0, 2)), int(rng.integers(0, 200))] = True
        q = np.where(mask, q, np.nan).astype(np.float32)
        check_against_reference(real_clf.classify(q), q, real_table)


def test_nan_elements_equal_the_sub_problem(real_table, real_clf, rng) -> None:
    # Classifying a query with NaN holes equals Eq. (12) on the non-NaN part alone, computed by hand.
    feats = real_table.features.astype(np.float64)
    m = real_table.index_of("bamboo")
    q = (real_table.features[m] + rng.normal(0, 0.3, (2, 200))).astype(np.float32)
    keep = np.zeros((2, 200), bool)
    keep[0, 20:35] = True
    keep[1, 150:160] = True
    r = real_clf.classify(np.where(keep, q, np.nan))
    sub_q = q[keep].astype(np.float64)
    for x in r.ranking:
        sub_ex = feats[x.index][keep]
        assert x.valid == keep.sum()
        np.testing.assert_allclose(x.distance, np.mean((sub_q - sub_ex) ** 2), rtol=1e-5)
    assert r.material == "bamboo"


def test_one_valid_element(real_table, real_clf, rng) -> None:
    feats = real_table.features
    for _ in range(30):
        row, b = int(rng.integers(0, 2)), int(rng.integers(0, 200))
        v = np.float32(rng.normal(0, 40))
        q = nan_query(real_table)
        q[row, b] = v
        candidates = [i for i in range(len(real_table)) if not np.isnan(feats[i, row, b])]
        r = real_clf.classify(q)
        assert r.valid == 1
        assert all(x.valid == 1 for x in r.ranking)
        assert sorted(x.index for x in r.ranking) == candidates
        expected = {i: (float(v) - float(feats[i, row, b])) ** 2 for i in candidates}
        best = min(candidates, key=lambda i: (expected[i], i))
        assert r.index == best
        assert r.distance == pytest.approx(expected[best], rel=1e-9, abs=1e-12)


def test_candidate_without_common_element_is_skipped_real_table(real_table, real_clf) -> None:
    # bin 0 is missing in paper (and others with missing near bins): a query there cannot judge them.
    paper = real_table.index_of("paper")
    missing = np.isnan(real_table.features[paper]).all(axis=0)
    assert missing[0]
    q = nan_query(real_table)
    src = real_table.index_of("alumi")
    q[:, missing] = real_table.features[src][:, missing]
    r = real_clf.classify(q)
    names = [x.material for x in r.ranking]
    assert "paper" not in names
    assert r.material == "alumi"
    assert len(names) == sum(
        1 for i in range(len(real_table)) if not np.isnan(real_table.features[i][:, missing]).all()
    )


# ---------------------------------------------------------------------------------------------
# Synthetic tables built with the constructor
# ---------------------------------------------------------------------------------------------
def make_table(materials, features, rows=None, bins=None) -> tofmat.ExemplarTable:
    features = np.asarray(features, dtype=np.float32)
    n_rows, n_bins = features.shape[1:]
    rows = rows if rows is not None else [(16, 120), (80, 120), (40, 120)][:n_rows]
    bins = bins if bins is not None else tofmat.BinSpec(100.0, 2.5, n_bins)
    return tofmat.ExemplarTable(materials, features, bins, rows)


def test_constructor_table_properties(rng) -> None:
    feats = rng.normal(0, 5, (3, 2, 12)).astype(np.float32)
    feats[1, :, :4] = np.nan
    bins = tofmat.BinSpec(100.0, 2.5, 12)
    t = tofmat.ExemplarTable(["a", "b", "c"], feats, bins, [(16, 120), (80, 120)])
    assert t.materials == ["a", "b", "c"] and len(t) == 3
    assert t.rows == [(16, 120), (80, 120)]
    assert t.bins == bins and t.n_bins == 12 and t.n_rows == 2
    assert t.valid_counts == [24, 16, 24]
    assert t.quant_step_mm == 0.0
    np.testing.assert_array_equal(t.features, feats)
    np.testing.assert_allclose(t.bin_edges_mm, 100.0 + 2.5 * np.arange(13))
    # The table holds its own copy of the values; features returns a copy.
    feats[0] = 999.0
    assert not np.any(t.features == 999.0)
    f = t.features
    f[:] = 0.0
    assert not np.all(t.features == 0.0)


def test_a_table_with_an_all_nan_material_is_refused_whatever_the_candidates(rng) -> None:
    # (issue 33: such a material could never be matched; tofmatd and `tofmat table import` refuse it too)
    feats = rng.normal(0, 3, (4, 2, 20)).astype(np.float32)
    feats[2] = np.nan
    t = make_table(["a", "b", "gone", "d"], feats)
    assert t.valid_counts[2] == 0
    for materials in (None, ["a", "b"], ["gone"]):
        with pytest.raises(ValueError, match='material "gone" has no measured value'):
            tofmat.Classifier(t, materials=materials, method="eq12")
    feats[2, 0, 5] = 1.0  # one measured value is enough
    tofmat.Classifier(make_table(["a", "b", "gone", "d"], feats), method="eq12")


def test_candidate_sharing_no_element_is_skipped_and_none_is_error() -> None:
    n_bins = 10
    feats = np.full((3, 1, n_bins), np.nan, np.float32)
    feats[0, 0, 0:4] = 1.0  # "left" known only in bins 0..3
    feats[1, 0, 4:8] = 2.0  # "right" only in bins 4..7
    feats[2, 0, 2:6] = 3.0  # "middle" in bins 2..5
    t = make_table(["left", "right", "middle"], feats, rows=[(16, 120)])
    clf = tofmat.Classifier(t, method="eq12")

    q = np.full((1, n_bins), np.nan, np.float32)
    q[0, 6:8] = 2.5
    r = clf.classify(q)
    assert [x.material for x in r.ranking] == ["right"]
    assert r.valid == 2 and r.distance == pytest.approx(0.25)

    q = np.full((1, n_bins), np.nan, np.float32)
    q[0, 3:5] = 1.0
    r = clf.classify(q)
    assert {x.material for x in r.ranking} == {"left", "right", "middle"}
    by = {x.material: x for x in r.ranking}
    assert by["left"].valid == 1 and by["left"].distance == pytest.approx(0.0)
    assert by["right"].valid == 1 and by["right"].distance == pytest.approx(1.0)
    assert by["middle"].valid == 2 and by["middle"].distance == pytest.approx(4.0)
    assert r.material == "left"

    q = np.full((1, n_bins), np.nan, np.float32)
    q[0, 8:] = 1.0  # no material is known in bins 8..9
    with pytest.raises(ValueError, match="shares no valid element"):
        clf.classify(q)
    with pytest.raises(ValueError, match="shares no valid element"):
        tofmat.Classifier(t, materials=["left"], method="eq12").classify(
            np.where(np.arange(n_bins) >= 4, 1.0, np.nan)[None].astype(np.float32)
        )


def test_ties_are_broken_by_the_lower_index() -> None:
    feats = np.zeros((4, 1, 5), np.float32)
    feats[0] += 2.0
    feats[3] += 2.0  # same as material 0
    feats[1] -= 1.0
    feats[2] += 1.0  # 1 and 2 are equally far from 0
    t = make_table(["w", "x", "y", "z"], feats, rows=[(16, 120)])
    clf = tofmat.Classifier(t, method="eq12")
    r = clf.classify(np.zeros((1, 5), np.float32))
    assert [x.material for x in r.ranking] == ["x", "y", "w", "z"]
    assert [x.distance for x in r.ranking] == [1.0, 1.0, 4.0, 4.0]


@pytest.mark.parametrize(
    "materials, shape, rows, match",
    [
        (["a", "b"], (3, 2, 8), [(16, 120), (80, 120)], r"expected"),  # features vs materials
        (["a", "b"], (2, 2, 7), [(16, 120), (80, 120)], r"expected"),  # features vs bins
        (["a", "b"], (2, 1, 8), [(16, 120), (80, 120)], r"expected"),  # features vs rows
        (["a", "a"], (2, 2, 8), [(16, 120), (80, 120)], r"duplicate"),
        (["a", "b c"], (2, 2, 8), [(16, 120), (80, 120)], r"name"),
        (["a", ""], (2, 2, 8), [(16, 120), (80, 120)], r"name"),
        (["a", "x" * 65], (2, 2, 8), [(16, 120), (80, 120)], r"name"),
        ([], (0, 2, 8), [(16, 120), (80, 120)], r"material"),
        (["a", "b"], (2, 2, 8), [(16, 120), (80, 70000)], r"65535"),
        (["a", "b"], (2, 2, 8), [(16, 120), (-1, 120)], r"65535"),
        (["a", "b"], (2, 0, 8), [], r"rows"),
    ],
)
def test_constructor_rejects_bad_input(materials, shape, rows, match) -> None:
    with pytest.raises(ValueError, match=match):
        tofmat.ExemplarTable(materials, np.zeros(shape, np.float32), tofmat.BinSpec(0.0, 1.0, 8), rows)


def test_constructor_rejects_infinite_values_and_non_float() -> None:
    f = np.zeros((1, 1, 4), np.float32)
    f[0, 0, 2] = np.inf
    with pytest.raises(ValueError, match="Inf"):
        tofmat.ExemplarTable(["a"], f, tofmat.BinSpec(0.0, 1.0, 4), [(16, 120)])
    with pytest.raises(TypeError, match="floating-point dtype"):
        tofmat.ExemplarTable(["a"], np.zeros((1, 1, 4), np.int32), tofmat.BinSpec(0.0, 1.0, 4), [(16, 120)])


def test_classifier_keeps_its_table_alive(rng) -> None:
    feats = rng.normal(0, 1, (3, 2, 30)).astype(np.float32)
    t = make_table(["a", "b", "c"], feats)
    clf = tofmat.Classifier(t, method="eq12")
    del t
    gc.collect()
    assert clf.classify(feats[1]).material == "b"
    assert clf.table.materials == ["a", "b", "c"]


def test_concurrent_classify_is_consistent(real_table, real_clf, rng) -> None:
    # classify releases the GIL; results from threads must equal serial ones.
    qs = (real_table.features[rng.integers(0, 29, 64)] + rng.normal(0, 0.5, (64, 2, 200))).astype(np.float32)
    serial = [(r.index, r.distance) for r in real_clf.classify_batch(qs)]
    out: dict[int, list] = {}

    def work(k: int) -> None:
        out[k] = [(r.index, r.distance) for r in (real_clf.classify(q) for q in qs)]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert all(out[k] == serial for k in range(4))


def test_fixed_backend_agrees_with_float_on_noisy_windows(real_table, rng) -> None:
    """The fixed-point path (int16 table steps, integer Eq. (12)) labels noisy 10-bin windows
    of the real curves as the float path does, with distances within the quantisation bound."""
    fixed = tofmat.Classifier(real_table, backend="fixed", method="eq12")
    flt = tofmat.Classifier(real_table, backend="float", method="eq12")
    assert fixed.backend == "fixed" and fixed.materials == real_table.materials
    feats = real_table.features
    n_bins = real_table.n_bins
    same = 0
    for m in range(len(real_table)):
        for _ in range(5):
            s = int(rng.integers(0, n_bins - 10))
            q = np.full(feats.shape[1:], np.nan, np.float32)
            q[:, s : s + 10] = feats[m, :, s : s + 10] + rng.normal(0, 0.3, (feats.shape[1], 10))
            if np.isnan(q).all():
                continue
            a, b = flt.classify(q), fixed.classify(q)
            same += a.material == b.material
            assert abs(a.distance - b.distance) <= 0.01 * max(1.0, a.distance)
            assert [r.valid for r in a.ranking][:1] == [r.valid for r in b.ranking][:1]
    assert same >= 140  # of 145: every one in practice; a flip needs a near tie


def test_fixed_backend_errors_and_candidates(real_table) -> None:
    fixed = tofmat.Classifier(real_table, backend="fixed", materials=["pvc", "epvc"], method="eq12")
    assert sorted(fixed.materials) == ["epvc", "pvc"]
    q = np.full((real_table.n_rows, real_table.n_bins), np.nan, np.float32)
    with pytest.raises(ValueError, match="no valid element"):
        fixed.classify(q)
    q[:, 50:60] = real_table.features[real_table.index_of("pvc"), :, 50:60]
    assert fixed.classify(q).material == "pvc"
    assert [r.material for r in fixed.classify_batch(np.stack([q, q]))] == ["pvc", "pvc"]


def test_exemplars_of_one_material_label_and_rank_as_that_material(rng) -> None:
    """Entries named MATERIAL@TAG are exemplars of MATERIAL: the label, ranking and candidates speak of
    the material, ranked by its best exemplar, with its exemplars' probabilities summed."""
    bins = tofmat.BinSpec.linspace(600.0, 1200.0, 8)
    base = rng.normal(0.0, 3.0, (3, 2, 8))
    names = ["cork@0", "paper@0", "cork@30", "paper@30", "wood"]
    features = np.stack([base[0], base[1], base[0] + 0.8, base[1] + 0.8, base[2]])
    table = tofmat.ExemplarTable(names, features, bins, [(16, 120), (80, 120)])
    clf = tofmat.Classifier(table, method="eq12")
    res = clf.classify(features[2] + rng.normal(0.0, 0.05, (2, 8)))
    assert res.material == "cork"
    assert table.materials[res.index] == "cork@30"  # the best exemplar
    assert sorted(r.material for r in res.ranking) == ["cork", "paper", "wood"]  # each material once
    assert res.confidence == pytest.approx(1.0 - sum(r.probability for r in res.ranking[1:]))
    # the material's probability is its exemplars' sum: more than the table's best entry alone would have
    plain = tofmat.Classifier(
        tofmat.ExemplarTable([n.replace("@", "_") for n in names], features, bins, [(16, 120), (80, 120)]),
        method="eq12",
    )
    alone = plain.classify(features[2] + 0.0)
    assert alone.material == "cork_30"
    assert clf.classify(features[2] + 0.0).confidence > alone.confidence
    # a material as a candidate takes all its exemplars; an exemplar's own name takes that one
    assert {r.index for r in tofmat.Classifier(table, materials=["cork"]).classify(features[0]).ranking} == {0}
    only = tofmat.Classifier(table, materials=["cork@0", "wood"]).classify(features[2])
    assert [r.material for r in only.ranking] == ["cork", "wood"] and only.index == 0
    with pytest.raises(ValueError, match="twice"):
        tofmat.Classifier(table, materials=["cork", "cork@30"])
    with pytest.raises(ValueError, match="MATERIAL@TAG"):
        tofmat.ExemplarTable(["cork@"], features[:1], bins, [(16, 120), (80, 120)])
