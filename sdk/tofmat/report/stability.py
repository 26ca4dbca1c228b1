# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Numerical stability of the fixed-point path against the float reference, at its stiff cases.

What the SDK exposes of the fixed-point path is the Eq. (12) classifier
(``Classifier(table, backend="fixed", method="eq12")``), so that is what is computed here, in Python, on synthetic
queries: each candidate's distance against the float classifier's, next to the bound of
docs/numerics.md (each query element moves by at most half a table step ``s`` when quantised, so a
mean squared distance moves by at most ``s * mean|q - e| + s^2 / 4``; two labels can differ only
where the float distances of the two lie within the sum of their bounds). The decode's stages, the
depth bins and the box mean are measured at their stiff cases by the C++ build
(``tofmat_bench_fixed --op stiff``, read by :func:`.cppbench.parse_stiff_cases`); what only the C++
tests check (the vector kernels bit for bit, the per-pixel classifier, the majority filter) is
listed with those tests (:data:`CPP_TESTS_ONLY`).
"""

from __future__ import annotations

import math
import tempfile
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .. import BinSpec, Classifier, ExemplarTable
from ..tools.sweeps import random_windows

INT16_MAX = 32767
CLASSIFIER_BUDGET = "s * mean\\|q - e\\| + s^2/4 per distance; labels differ only within the two bounds"

F32 = npt.NDArray[np.float32]


@dataclass(frozen=True)
class StabilityRow:
    """One stage at one case: the worst error found, next to the budget docs/numerics.md states."""

    stage: str
    case: str
    inputs: str  # what was computed
    queries: int  # queries classified (0: not measured here)
    distances: int  # candidate distances compared
    worst_error: float  # mm^2: the largest |d_fixed - d_float| (NaN: not measured here)
    bound_at_worst: float  # mm^2: the documented bound for that distance
    worst_ratio: float  # the largest |d_fixed - d_float| / bound over every distance (<= 1: within)
    labels_differ: int  # queries whose fixed label is not the float label
    labels_outside: int  # of those, where the float margin exceeds the two bounds (must be 0)
    valid_mismatch: int  # candidate distances whose element counts differ (must be 0)
    note: str  # what else this case shows (ties, saturation)
    covered_by: str  # C++ tests of the same case
    step_mm: float  # the table step s of the case's table

    @property
    def within_budget(self) -> bool:
        return (
            math.isfinite(self.worst_ratio)
            and self.worst_ratio <= 1.0 + 1e-9
            and self.labels_outside == 0
            and self.valid_mismatch == 0
        )


@dataclass(frozen=True)
class CppTestsOnly:
    """A stage and its stiff cases that only the C++ tests check: the tests that cover them."""

    stage: str
    cases: str
    budget: str  # as docs/numerics.md states it
    tests: str


# What neither Python nor `tofmat_bench_fixed --op stiff` measures, with the C++ tests (tests/cpp,
# run by `make test`; the NEON kernels by `make cross-test`) that check it.
CPP_TESTS_ONLY: list[CppTestsOnly] = [
    CppTestsOnly(
        "decode, depth bins, box mean: the NEON and AVX2 kernels",
        "random pixels over the whole range, exact wrap points, extremes, lengths that leave a scalar tail; "
        "thresholds none, default, strict and NaN",
        "bit for bit the scalar kernel (the one 2.2 measures)",
        "`FixedDecode.VectorKernelIsBitExactWithScalar`, `FixedDepthBins.VectorBinKernelIsBitExactWithScalar`, "
        "`BoxMeanFilter.TheKernelsAgreeBitForBit`",
    ),
    CppTestsOnly(
        "depth bins: a full bin",
        "a bin at its limit of observations (2^32; a test asks for 3)",
        "further observations refused and counted, the sums never overflow",
        "`FixedDepthBins.FullBinsRefuseFurtherObservations` (tests/cpp/test_fixed_depth_bins.cpp)",
    ),
    CppTestsOnly(
        "per-pixel classification (`PixelClassifier`)",
        "features at the int32 extremes, 1 to 254 candidates, missing elements",
        "labels differ from `FloatClassifier` only in near ties (the features' quantisation)",
        "`PixelClassifier.AgreesWithTheFloatClassifierUpToTheQuantisation`, `PixelClassifier.VectorKernelIsBitExactWithScalar` "
        "(tests/cpp/test_pixel_classifier.cpp)",
    ),
    CppTestsOnly(
        "segmentation majority filter (`MajorityFilter`)",
        "windows up to 15 x 15, up to 255 classes, frames narrower than the window",
        "exact: every label its window's majority",
        "`MajorityFilter.EveryLabelIsItsWindowsMajority` (tests/cpp/test_frame_smoothing.cpp)",
    ),
    CppTestsOnly(
        "Eq. (12) NEON kernel (aarch64)",
        "saturated opposite values, the longest rows (16 x 65535 elements), 20,000 short random inputs",
        "bit for bit the scalar kernel (this host runs the scalar kernel, measured in 2.1)",
        "`FixedKernel.NeonIsBitExactWithScalar`, `FixedKernel.ScalarEqualsThePlainDefinition` "
        "(tests/cpp/test_fixed_classifier.cpp; NEON under `make cross-test`)",
    ),
]


# ---------------------------------------------------------------- comparing the two classifiers


@dataclass
class _Tally:
    queries: int = 0
    distances: int = 0
    worst_error: float = 0.0
    bound_at_worst: float = math.nan
    worst_ratio: float = 0.0
    labels_differ: int = 0
    labels_outside: int = 0
    valid_mismatch: int = 0


class _Pair:
    """The float and fixed classifiers of one table, and its values for the bound."""

    def __init__(self, table: ExemplarTable) -> None:
        self.table = table
        self.step = float(table.quant_step_mm)
        if not self.step > 0.0:
            raise ValueError("the stability cases need a table with its .tmx step (load it from a .tmx file)")
        self.float = Classifier(table, backend="float", method="eq12")
        self.fixed = Classifier(table, backend="fixed", method="eq12")
        self.values = table.features.reshape(len(table), -1).astype(np.float64)
        self.valid = ~np.isnan(self.values)
        self.values0 = np.nan_to_num(self.values)
        self.limit = np.float32(INT16_MAX * self.step)  # exact in binary32

    def saturated(self, q: F32) -> F32:
        """The query as the fixed path sees its range: each value clamped to +-32767 steps."""
        return np.clip(q, -self.limit, self.limit).astype(np.float32)

    def compare(self, tally: _Tally, query: F32, reference: F32 | None = None) -> tuple[int, int]:
        """Classifies ``query`` with the fixed path and ``reference`` (default: the query) with the
        float one, and adds each candidate's distance error and the labels to ``tally``.
        Returns the two labels (fixed, float)."""
        ref = query if reference is None else reference
        a = self.float.classify(ref)
        with warnings.catch_warnings():  # (the cases saturate on purpose: the fixed backend's warning says so)
            warnings.simplefilter("ignore", RuntimeWarning)
            b = self.fixed.classify(query)
        q = ref.reshape(-1).astype(np.float64)
        both = self.valid & ~np.isnan(q)[None, :]
        n = both.sum(axis=1)
        diff = np.where(both, np.abs(np.nan_to_num(q)[None, :] - self.values0), 0.0)
        mean_abs = diff.sum(axis=1) / np.maximum(n, 1)
        bound = self.step * mean_abs + self.step * self.step / 4.0
        by_index = {m.index: m for m in a.ranking}
        tally.queries += 1
        if len(a.ranking) != len(b.ranking):
            tally.valid_mismatch += abs(len(a.ranking) - len(b.ranking))
        for mb in b.ranking:
            ma = by_index.get(mb.index)
            if ma is None or ma.valid != mb.valid or mb.valid != int(n[mb.index]):
                tally.valid_mismatch += 1
                continue
            err = abs(ma.distance - mb.distance)
            # (the distances are doubles: allow their last bits beside the bound)
            ratio = err / (float(bound[mb.index]) + 1e-12 * max(1.0, abs(ma.distance)))
            tally.distances += 1
            if err > tally.worst_error or math.isnan(tally.bound_at_worst):
                tally.worst_error, tally.bound_at_worst = err, float(bound[mb.index])
            tally.worst_ratio = max(tally.worst_ratio, ratio)
        if a.index != b.index:
            tally.labels_differ += 1
            margin = by_index[b.index].distance - a.distance if b.index in by_index else math.inf
            allowed = float(bound[a.index] + bound[b.index])
            if margin > allowed * (1.0 + 1e-9) + 1e-12:
                tally.labels_outside += 1
        return b.index, a.index


def _tmx_round_trip(table: ExemplarTable, folder: Path, name: str = "table.tmx") -> ExemplarTable:
    """The table as a .tmx file holds it (its values on the file's int16 grid, its step known)."""
    path = folder / name
    table.save(path)
    return ExemplarTable.load(path)


def _row(
    stage: str, case: str, inputs: str, t: _Tally, step: float, note: str = "", covered_by: str = ""
) -> StabilityRow:
    return StabilityRow(
        stage=stage,
        case=case,
        inputs=inputs,
        queries=t.queries,
        distances=t.distances,
        worst_error=t.worst_error,
        bound_at_worst=t.bound_at_worst,
        worst_ratio=t.worst_ratio,
        labels_differ=t.labels_differ,
        labels_outside=t.labels_outside,
        valid_mismatch=t.valid_mismatch,
        note=note,
        covered_by=covered_by,
        step_mm=step,
    )


# ---------------------------------------------------------------- the cases

STAGE = 'Eq. (12) classifier (`Classifier(table, backend="fixed", method="eq12")`)'
WINDOWS = (1, 3, 10, 30, 100)


def _full_query(pair: _Pair, values: npt.NDArray[np.float64]) -> F32:
    return values.astype(np.float32).reshape(pair.table.n_rows, pair.table.n_bins)


def classifier_stability(
    table: ExemplarTable,
    quick: bool = False,
    seed: int = 0,
    noise_mm: float = 0.3,
    tick: Callable[[str], None] | None = None,
) -> list[StabilityRow]:
    """The fixed classifier against the float one at its stiff cases, on synthetic queries.

    The table is taken through a .tmx file first (as the C++ tests do), so that both classifiers see
    the same values and the step is the file's. ``tick`` is told the name of each case as it starts.
    """
    say = tick or (lambda _what: None)
    rows: list[StabilityRow] = []
    rng = np.random.default_rng(seed)
    with tempfile.TemporaryDirectory(prefix="tofmat-report-") as tmp:
        folder = Path(tmp)
        pair = _Pair(_tmx_round_trip(table, folder))
        s = pair.step
        m_count, length = len(pair.table), pair.values.shape[1]
        per_material = 3 if quick else 40

        say("noisy windows")
        t = _Tally()
        for w in WINDOWS:
            if w > pair.table.n_bins:
                continue
            for win in random_windows(pair.table, w, noise_mm, per_material, np.random.default_rng(seed + w)):
                if np.isnan(win.query).all():
                    continue
                pair.compare(t, win.query)
        rows.append(
            _row(
                STAGE,
                "noisy windows of the table's curves (the queries of `make bench`)",
                f"windows of {', '.join(map(str, WINDOWS))} bins, {per_material} per material and length, "
                f"N(0, {noise_mm:g} mm) noise",
                t,
                s,
                covered_by="`FixedClassifierRealDatabase.SameLabelsAsFloatExceptWithinTheQuantisationBound`",
            )
        )

        say("one valid element, half steps")
        t = _Tally()
        k_per = 3 if quick else 20
        for m in range(m_count):
            idx = np.flatnonzero(pair.valid[m])
            for i in rng.choice(idx, size=min(k_per, idx.size), replace=False):
                q = np.full(length, np.nan)
                base = round(pair.values[m, i] / s)
                q[i] = (base + int(rng.integers(-200, 201)) + 0.5) * s  # exactly between two steps
                pair.compare(t, _full_query(pair, q))
        for v in (0.49 * s, -0.49 * s, 0.5 * s, -0.5 * s, 1.5 * s, 1e-30, -1e-30):  # below half a step, on it
            q = np.full(length, np.nan)
            q[int(rng.integers(length))] = v
            if pair.valid[:, np.flatnonzero(~np.isnan(q))[0]].any():
                pair.compare(t, _full_query(pair, q))
        rows.append(
            _row(
                STAGE,
                "one valid element (N = 1), its value exactly between two steps",
                f"{k_per} elements per material at (k + 1/2) s, and values of +-0.49, +-0.5, 1.5 steps and +-1e-30 mm",
                t,
                s,
                covered_by="`FixedKernel.ScalarEqualsThePlainDefinition` (one valid element)",
            )
        )

        say("every element on a half step")
        t = _Tally()
        for m in range(m_count):
            for _ in range(1 if quick else 4):
                base = np.where(pair.valid[m], pair.values[m], rng.uniform(-50, 50, length))
                q = (np.round(base / s) + rng.integers(-50, 51, length) + 0.5) * s
                pair.compare(t, _full_query(pair, q))
        rows.append(
            _row(
                STAGE,
                "every element exactly between two steps (whole curves)",
                "each material's curve moved by (j + 1/2) s, j uniform in -50..50, missing elements filled",
                t,
                s,
            )
        )

        say("largest values")
        t = _Tally()
        for _ in range(3 if quick else 10):
            q = rng.choice([-1.0, 1.0], length) * INT16_MAX * s
            pair.compare(t, _full_query(pair, q))
        rows.append(
            _row(
                STAGE,
                "the largest values a query holds: +-32767 steps",
                f"every element +-32767 s (+-{INT16_MAX * s:g} mm), random signs",
                t,
                s,
                covered_by="`FixedKernel.ScalarEqualsThePlainDefinition` (saturated opposite values)",
            )
        )

        say("saturation")
        t = _Tally()
        agree_unsaturated = 0
        factors = (1.0001, 2.0, 1e3, 1e6, 1e30)
        n_sat = 5 if quick else 20
        for k in range(n_sat):
            m = k % m_count
            q = np.where(pair.valid[m], pair.values[m], 0.0) + rng.normal(0.0, noise_mm, length)
            beyond = rng.random(length) < 0.3
            q = np.where(beyond, rng.choice([-1.0, 1.0], length) * INT16_MAX * s * factors[k % len(factors)], q)
            qq = _full_query(pair, q)
            fixed_label, _ = pair.compare(t, qq, pair.saturated(qq))
            agree_unsaturated += fixed_label == pair.float.classify(qq).index
        rows.append(
            _row(
                STAGE,
                "values beyond +-32767 steps: saturation",
                f"{n_sat} noisy curves with 30 % of their elements at 1.0001, 2, 1e3, 1e6 or 1e30 times 32767 s; the "
                "float path on the query clamped to +-32767 s (the documented behaviour)",
                t,
                s,
                note=f"against the float path on the unclamped query: {agree_unsaturated} of {n_sat} labels agree "
                "(the ranking is that of the saturated query, by design)",
                covered_by="`FixedClassifier.TiesGoToTheLowerIndexAndOutOfRangeValuesSaturate`",
            )
        )

        say("ties")
        t = _Tally()
        copy_wins = 0
        first = pair.table.materials[0]
        feats = pair.table.features
        twin = ExemplarTable(
            [*pair.table.materials, f"{first}-copy"],
            np.concatenate([feats, feats[:1]]),
            pair.table.bins,
            pair.table.rows,
        )
        tp = _Pair(_tmx_round_trip(twin, folder, "twin.tmx"))
        copy = len(twin) - 1
        for w in (1, 10, 100):
            if w > twin.n_bins:
                continue
            for win in random_windows(twin, w, noise_mm, 3 if quick else 20, np.random.default_rng(seed + 7 * w)):
                if win.material != 0 or np.isnan(win.query).all():
                    continue
                fx, fl = tp.compare(t, win.query)
                copy_wins += (fx == copy) + (fl == copy)
        rows.append(
            _row(
                STAGE,
                "exact ties: a material and its copy",
                f"the table with {first} appended again; noisy windows of {first}",
                t,
                tp.step,
                note=f"the copy (the higher index) was chosen {copy_wins} times by either path (ties go to the "
                "lower index)",
                covered_by="`FixedClassifier.TiesGoToTheLowerIndexAndOutOfRangeValuesSaturate`",
            )
        )

        say("largest table")
        rows.append(_largest_table(folder, rng, quick))
    return rows


def _largest_table(folder: Path, rng: np.random.Generator, quick: bool) -> StabilityRow:
    """16 rows x 65535 bins (2^20 elements a material, a table's limit): the uint64 sums at their
    largest, 2^20 x 65534^2, with values of +-32767 steps and a query saturated against them."""
    rows, bins = 16, 65535
    s = 2.0**-7
    top = INT16_MAX * s
    f = np.empty((3, rows, bins), np.float32)
    f[0], f[1] = top, -top
    f[2] = rng.uniform(-top, top, (rows, bins)).astype(np.float32)
    f[2][rng.random((rows, bins)) < 0.1] = np.nan
    table = ExemplarTable(["plus", "minus", "random"], f, BinSpec(0.0, 0.1, bins), [(16, 120), (80, 120)] * (rows // 2))
    pair = _Pair(_tmx_round_trip(table, folder, "largest.tmx"))
    t = _Tally()
    queries: list[F32] = [
        np.full((rows, bins), -1e6, np.float32),  # saturates to -32767 steps: 65534 steps from "plus"
        np.full((rows, bins), top, np.float32),
    ]
    for _ in range(1 if quick else 3):
        q = rng.uniform(-top, top, (rows, bins)).astype(np.float32)
        q[rng.random((rows, bins)) < 0.5] = np.nan
        queries.append(q)
    for q in queries:
        pair.compare(t, q, pair.saturated(q))
    plus = next(m for m in pair.fixed.classify(queries[0]).ranking if m.material == "plus")
    sums_ok = plus.valid == rows * bins and plus.distance == (2 * INT16_MAX * pair.step) ** 2
    return _row(
        STAGE,
        "the largest table: 16 rows x 65535 bins (2^20 elements a material)",
        f"3 materials (+32767 steps everywhere, -32767, random with 10 % missing); {len(queries)} queries: all at "
        "-1e6 mm (saturated), all at +32767 s, random",
        t,
        pair.step,
        note="the saturated query's distance to +32767 steps is (65534 s)^2 exactly (sum 2^20 x 65534^2 in uint64): "
        + ("yes" if sums_ok else "**no**"),
        covered_by="`FixedKernel.ScalarEqualsThePlainDefinition` (16 x 65535 elements)",
    )


def all_within_budget(rows: Iterable[StabilityRow]) -> bool:
    return all(r.within_budget for r in rows)


__all__ = [
    "CLASSIFIER_BUDGET",
    "CPP_TESTS_ONLY",
    "CppTestsOnly",
    "StabilityRow",
    "all_within_budget",
    "classifier_stability",
]
