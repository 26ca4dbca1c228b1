# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Open set (docs/evaluation.md): how often the session matcher's fit test calls a known material
``unknown`` (false rejects: the table holds every material) and lets a new one through (false
accepts: each material held out of the table in turn, its own queries asked), by sweep length and
threshold on the fit (:attr:`tofmat.RankedMatch.fit`); the default thresholds, one per sweep
length, are chosen on the tuning split: each the fit that rejects MAX_FALSE_REJECT of the known
queries of its length."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .. import Calibration, Classifier, ExemplarTable, SessionPrior
from .sessions import Queries

F64 = npt.NDArray[np.float64]
# The share of known queries the chosen threshold of a length rejects, on the tuning split.
MAX_FALSE_REJECT = 0.05


@dataclass
class OpenSetCurves:
    """Per sweep length: each query's best fit with the full table (known) and with its material
    held out (novel); +inf where the held-out table had nothing to compare (always rejected)."""

    known: dict[int, F64] = field(default_factory=dict)
    novel: dict[int, F64] = field(default_factory=dict)
    truth: dict[int, npt.NDArray[np.int64]] = field(default_factory=dict)  # each query's material

    def false_reject(self, thresholds: dict[int, float]) -> dict[int, float]:
        """Per length, the share of known queries whose fit exceeds its length's threshold."""
        return {n: float(np.mean(f > thresholds[n])) for n, f in sorted(self.known.items())}

    def false_accept(self, thresholds: dict[int, float]) -> dict[int, float]:
        """Per length, the share of held-out materials' queries that pass as known."""
        return {n: float(np.mean(f <= thresholds[n])) for n, f in sorted(self.novel.items())}

    def accepted_by_material(self, thresholds: dict[int, float], n: int, materials: int) -> F64:
        """At length n, each held-out material's share of its queries that passed as known (NaN: none)."""
        ok = self.novel[n] <= thresholds[n]
        t = self.truth[n]
        return np.array([float(np.mean(ok[t == i])) if np.any(t == i) else np.nan for i in range(materials)])


def _without(table: ExemplarTable, m: int) -> ExemplarTable:
    return subset(table, [i for i in range(len(table.materials)) if i != m])


def subset(table: ExemplarTable, keep: list[int]) -> ExemplarTable:
    """The table of the materials ``keep`` (indices, in that order), with their stored noise."""
    noise = table.noise_mm
    return ExemplarTable(
        [table.materials[i] for i in keep],
        table.features[keep],
        table.bins,
        table.rows,
        None if noise is None else noise[keep],
    )


def _best_fits(clf: Classifier, queries: np.ndarray) -> F64:
    out = np.empty(len(queries))
    for i, q in enumerate(queries):
        try:
            out[i] = clf.classify(q).fit
        except ValueError:  # nothing in common with any candidate: nothing can explain it
            out[i] = np.inf
    return out


def open_set_curves(table: ExemplarTable, prior: SessionPrior, q: Queries) -> OpenSetCurves:
    """The fits of one split's queries (:class:`OpenSetCurves`)."""
    never = Calibration([(1.0, 1.0)])  # the raw fits, no rejection
    full = Classifier(table, method="session", prior=prior, calibration=never)
    known = np.array([r.fit for r in full.classify_batch(q.queries)])
    novel = np.empty(len(q.truth))
    for m in range(len(table.materials)):
        sel = np.flatnonzero(q.truth == m)
        if sel.size:
            held = Classifier(_without(table, m), method="session", prior=prior, calibration=never)
            novel[sel] = _best_fits(held, q.queries[sel])
    curves = OpenSetCurves()
    for n in sorted(set(q.lengths.tolist())):
        sel = q.lengths == n
        curves.known[n] = known[sel]
        curves.novel[n] = novel[sel]
        curves.truth[n] = q.truth[sel]
    return curves


def choose_thresholds(curves: OpenSetCurves) -> dict[int, float]:
    """Per length, the fit that MAX_FALSE_REJECT of the known queries exceed (numpy's linear quantile)."""
    return {n: float(np.quantile(f, 1.0 - MAX_FALSE_REJECT)) for n, f in sorted(curves.known.items())}
