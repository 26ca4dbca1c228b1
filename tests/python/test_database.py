# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The real 29-material Kinect v2 database: import, content, and classification accuracy."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import tofmat
from tofmat.tools.sweeps import random_windows

N_MATERIALS = 29
MATERIALS_WITH_MISSING = {"paper", "plaster", "fakeapple"}


def np_load_py2(path: Path) -> np.ndarray:
    """numpy's own reader as the reference (it warns about the Python 2 header)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.load(path, allow_pickle=False)


def test_dimensions_rows_and_bins(real_table: tofmat.ExemplarTable) -> None:
    t = real_table
    assert len(t) == N_MATERIALS
    assert len(t.materials) == N_MATERIALS
    assert t.n_rows == 2
    assert t.rows == [(16, 120), (80, 120)]
    assert t.n_bins == 200
    assert t.bins.count == 200
    assert t.bins.start_mm == 600.0
    assert t.bins.width_mm == pytest.approx(600.0 / 199.0, rel=1e-15, abs=0)
    # Left edges are numpy.linspace(600, 1200, 200), as the authors binned their captures.
    np.testing.assert_allclose(t.bin_edges_mm[:200], np.linspace(600.0, 1200.0, 200), rtol=0, atol=1e-9)
    assert t.bin_edges_mm.shape == (201,)
    np.testing.assert_allclose(t.bin_centres_mm, (t.bin_edges_mm[:-1] + t.bin_edges_mm[1:]) / 2, rtol=0, atol=1e-9)
    # An imported table never went through quantisation.
    assert t.quant_step_mm == 0.0


def test_materials_are_the_file_names(real_table: tofmat.ExemplarTable, db_files: dict[str, Path]) -> None:
    assert sorted(real_table.materials) == sorted(db_files)
    for i, name in enumerate(real_table.materials):
        assert real_table.index_of(name) == i
    with pytest.raises(KeyError, match="granite"):
        real_table.index_of("granite")


def test_missing_bins_only_in_paper_plaster_fakeapple(real_table: tofmat.ExemplarTable) -> None:
    full = real_table.n_rows * real_table.n_bins
    counts = dict(zip(real_table.materials, real_table.valid_counts, strict=True))
    for name, n in counts.items():
        if name in MATERIALS_WITH_MISSING:
            assert n < full, name
        else:
            assert n == full, name
    # valid_counts agrees with the NaN pattern of features.
    assert list(np.sum(~np.isnan(real_table.features), axis=(1, 2))) == real_table.valid_counts


def test_features_equal_numpy_load(real_table: tofmat.ExemplarTable, db_files: dict[str, Path]) -> None:
    feats = real_table.features
    assert feats.dtype == np.float32
    assert feats.shape == (N_MATERIALS, 2, 200)
    for i, name in enumerate(real_table.materials):
        ref = np_load_py2(db_files[name])
        assert ref.shape == (2, 200) and ref.dtype == np.float64
        missing = np.all(ref == 0.0, axis=0)  # a bin with exactly 0.0 in both rows = no observation
        assert np.array_equal(np.isnan(feats[i]), np.broadcast_to(missing, (2, 200))), name
        valid = ~np.isnan(feats[i])
        # Exactly the float32 rounding of the file's float64 values.
        assert np.array_equal(feats[i][valid], ref[valid].astype(np.float32)), name
        np.testing.assert_allclose(feats[i][valid], ref[valid], rtol=2.0**-24, atol=0)


def test_every_full_curve_classifies_as_itself(real_table: tofmat.ExemplarTable, real_clf: tofmat.Classifier) -> None:
    feats = real_table.features
    for i, name in enumerate(real_table.materials):
        r = real_clf.classify(feats[i])
        assert r.material == name
        assert r.index == i
        assert r.distance == pytest.approx(0.0, abs=1e-12)
        assert r.valid == real_table.valid_counts[i]
        # Every other material is strictly farther away.
        assert all(m.distance > 0 for m in r.ranking[1:]), name


def _window_accuracy(
    table: tofmat.ExemplarTable, clf: tofmat.Classifier, length: int, seed: int
) -> tuple[float, int, int]:
    """Accuracy over random_windows(per_material=40, noise 0.3 mm), windows with no valid element dropped."""
    rng = np.random.default_rng(seed)
    windows = list(random_windows(table, length, 0.3, 40, rng))
    assert len(windows) == 40 * len(table.materials)
    # A window lying entirely on missing bins (possible for 1-bin windows of paper, plaster,
    # fakeapple) has nothing to classify; it is not counted.
    kept = [w for w in windows if not np.isnan(w.query).all()]
    for w in kept:
        assert np.count_nonzero(~np.isnan(w.query).all(axis=0)) <= length
    results = clf.classify_batch(np.stack([w.query for w in kept]))
    correct = sum(r.index == w.material for r, w in zip(results, kept, strict=True))
    return correct / len(kept), correct, len(kept)


def test_10_bin_noisy_windows_classify_correctly(real_table: tofmat.ExemplarTable, real_clf: tofmat.Classifier) -> None:
    # Measured (seed 2017, 40 windows per material, N(0, 0.3 mm)): 1157/1160 = 99.74 %
    # (the misses: one window each of carpet, cork, plaster).
    rate, correct, n = _window_accuracy(real_table, real_clf, 10, seed=2017)
    assert n == 1160
    assert rate >= 0.97, f"10-bin windows: {correct}/{n} = {rate:.4f}"


def test_1_bin_noisy_windows_classify_mostly(real_table: tofmat.ExemplarTable, real_clf: tofmat.Classifier) -> None:
    # Measured (seed 2017, 40 windows per material, N(0, 0.3 mm)): 933/1156 = 80.7 %
    # (4 windows fell on missing bins and are not counted). One bin is a weak query: pvc/epvc
    # and paper/plaster, whose curves are under 1 mm apart, are the usual confusions.
    rate, correct, n = _window_accuracy(real_table, real_clf, 1, seed=2017)
    assert n >= 1100
    assert rate >= 0.75, f"1-bin windows: {correct}/{n} = {rate:.4f}"


def test_longer_windows_are_not_worse(real_table: tofmat.ExemplarTable, real_clf: tofmat.Classifier) -> None:
    rate1, _, _ = _window_accuracy(real_table, real_clf, 1, seed=7)
    rate10, _, _ = _window_accuracy(real_table, real_clf, 10, seed=7)
    rate100, _, _ = _window_accuracy(real_table, real_clf, 100, seed=7)
    assert rate1 < rate10 <= rate100
    assert rate100 == 1.0
