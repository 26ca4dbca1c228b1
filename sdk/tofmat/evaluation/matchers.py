# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Matchers compared by ``tofmat evaluate``: each scores every candidate of every query (lower is
better) so that accuracy, rejection and confidence come from the same numbers.

- :class:`Eq12Matcher`: the paper's Eq. (12) (mean squared difference over the elements both have),
  through the SDK's C++ classifier: what tofmat ships.
- :class:`CompiledSessionMatcher`: the session-robust matcher of the C++ core
  (``Classifier(table, method="session")``), what ``tofmat evaluate`` reports.
- :class:`SessionMatcher`: its reference in NumPy (docs/evaluation.md), which the compiled one must
  equal (tests/python/test_session_classifier.py).
  Per candidate and row, the query's difference from the stored curve is modelled as what a
  session does (an offset and, optionally, a slope along depth, each with a Gaussian prior) plus
  bin noise at the candidate's own level (its roughness, stored per material and row), with
  outlier bins down-weighted (Huber). The score is the negative log-likelihood with the nuisance
  terms integrated out (a Laplace approximation: exact for the Gaussian part), so that a noisy
  material does not win by being vague and a short sweep is not over-fitted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from .. import Classifier, ExemplarTable, SessionPrior
from ..learn import LearnedClassifier
from .confidence import fit_tempering
from .sessions import roughness

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]


class Matcher(Protocol):
    name: str

    def scores(self, queries: F32) -> F64:
        """(N, M) scores of N queries (N, R, B) against the M candidates; lower is better, inf for a
        candidate that shares no element with the query."""
        ...


class _ClassifierMatcher:
    """A :class:`tofmat.Classifier`'s rankings as scores: a candidate outside a ranking shares no
    element with the query (inf)."""

    name: str

    def __init__(self, classifier: Classifier) -> None:
        self.classifier = classifier
        self.n = len(classifier.table.materials)

    def scores(self, queries: F32) -> F64:
        return self.scored(queries)[0]

    def scored(self, queries: F32) -> tuple[F64, F64]:
        """The (N, M) scores and, from the same classification, each query's fit tempering of its
        best match (confidence.fit_tempering): 1 for a matcher without a noise model (Eq. (12)) and
        a query no candidate shares an element with."""
        out = np.full((queries.shape[0], self.n), np.inf)
        fit, valid = np.full(queries.shape[0], math.nan), np.zeros(queries.shape[0])
        vague = np.ones(queries.shape[0])
        by_material = self.classifier.vagueness
        for i, res in enumerate(self.classifier.classify_batch(queries)):
            for r in res.ranking:
                out[i, r.index] = r.distance
            if res.ranking:
                fit[i], valid[i] = res.ranking[0].fit, res.ranking[0].valid
                if by_material is not None:
                    vague[i] = by_material[res.ranking[0].index]
        return out, fit_tempering(fit, valid, vague)


class Eq12Matcher(_ClassifierMatcher):
    """Eq. (12) through :class:`tofmat.Classifier` (float backend): the distance is the score."""

    name = "eq12"

    def __init__(self, table: ExemplarTable) -> None:
        super().__init__(Classifier(table, method="eq12"))


@dataclass(frozen=True)
class SessionParams:
    """The session-robust matcher's settings (tuned on the tuning split only)."""

    offset_sd_mm: tuple[float, ...]  # the prior of a row's offset (per row)
    drift_sd_mm: tuple[
        float, ...
    ] = ()  # priors of a row's drift along depth: Legendre degree 1, 2, ... over the table (mm)
    noise_scale: float = math.sqrt(2.0)  # element noise = this x the candidate's roughness (query + stored) ...
    floor_mm: float = 0.0  # ... combined with this (what the nuisance model leaves unexplained)
    huber_k: float = 3.0  # residuals beyond k noise units count linearly (math.inf: Gaussian)
    iterations: int = 3  # reweighting passes for the outliers


def session_prior(params: SessionParams) -> SessionPrior:
    """The core's :class:`tofmat.SessionPrior` for these settings."""
    drift = [*params.drift_sd_mm, 0.0, 0.0]
    return SessionPrior(
        list(params.offset_sd_mm),
        drift1_sd_mm=drift[0],
        drift2_sd_mm=drift[1],
        noise_scale=params.noise_scale,
        floor_mm=params.floor_mm,
        huber_k=params.huber_k,
        iterations=params.iterations,
    )


class CompiledSessionMatcher(_ClassifierMatcher):
    """The session-robust matcher of the C++ core through :class:`tofmat.Classifier`."""

    name = "session"

    def __init__(self, table: ExemplarTable, params: SessionParams) -> None:
        super().__init__(Classifier(table, method="session", prior=session_prior(params)))


class SessionMatcher:
    """The session-robust matcher, float reference in NumPy (module docstring)."""

    name = "session (NumPy)"

    def __init__(self, table: ExemplarTable, params: SessionParams, noise_mm: F64 | None = None) -> None:
        """``noise_mm`` (M, R): each candidate's bin noise; default the table's stored noise where it
        has a measured value, its roughness (:func:`.sessions.roughness`) elsewhere, as the C++ core."""
        self.table = table
        self.params = params
        self.curves = table.features.astype(np.float64)  # (M, R, B)
        m, r, b = self.curves.shape
        if len(params.offset_sd_mm) != r:
            raise ValueError(f"offset_sd_mm needs {r} values (one per row), got {len(params.offset_sd_mm)}")
        if noise_mm is None:
            sigma = roughness(self.curves)
            stored = table.noise_mm
            if stored is not None:
                sigma = np.where(np.isnan(stored), sigma, stored)
        else:
            sigma = np.asarray(noise_mm, dtype=np.float64)
        if sigma.shape != (m, r):
            raise ValueError(f"noise_mm must be ({m}, {r}), got {sigma.shape}")
        fill = np.nanmedian(sigma) if np.isfinite(sigma).any() else 0.3
        self.sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, fill)
        # The depth coordinate of the slope term: -0.5 .. 0.5 over the table, so slope_sd is the
        # prior change from one end of the table to the other.
        self.x = (np.arange(b, dtype=np.float64) + 0.5) / b - 0.5

    def scores(self, queries: F32, chunk: int = 256) -> F64:
        q = np.asarray(queries, dtype=np.float64)
        if q.ndim != 3 or q.shape[1:] != self.curves.shape[1:]:
            raise ValueError(f"queries must be (N, {self.curves.shape[1]}, {self.curves.shape[2]}), got {q.shape}")
        out = np.empty((q.shape[0], self.curves.shape[0]))
        for i in range(0, q.shape[0], chunk):
            out[i : i + chunk] = self._scores(q[i : i + chunk])
        return out

    def _scores(self, q: F64) -> F64:
        p = self.params
        e = q[:, None, :, :] - self.curves[None, :, :, :]  # (N, M, R, B)
        valid = np.isfinite(e)
        e = np.where(valid, e, 0.0)
        v = (p.noise_scale * self.sigma) ** 2 + p.floor_mm**2  # (M, R) element variance
        sd = np.sqrt(v)[None, :, :, None]
        # Nuisance basis per row: an offset, and Legendre polynomials of depth for the drift; a
        # term whose prior is 0 is left out (it is known to be 0).
        x = 2.0 * self.x
        legendre = [np.ones_like(x), x, 0.5 * (3 * x * x - 1)]
        if len(p.drift_sd_mm) > 2:
            raise ValueError("drift_sd_mm: at most 2 degrees")
        rows = len(p.offset_sd_mm)
        priors = [np.asarray(p.offset_sd_mm, dtype=np.float64)] + [np.full(rows, d) for d in p.drift_sd_mm]
        terms = [j for j, prior_sd in enumerate(priors) if np.all(prior_sd > 0)]
        basis = [legendre[j] for j in terms]
        prior_var = [priors[j] ** 2 for j in terms]
        k = len(basis)
        z = np.abs(e) / sd
        prior: F64 | float = 0.0
        logdet: F64 | float = 0.0
        if k:
            A = np.stack(basis, axis=-1)  # (B, K)
            z, prior, logdet = self._nuisance(e, valid, v, sd, A, prior_var)
        # Huber loss of the residuals (the Gaussian's 0.5 z^2 within k).
        if math.isfinite(p.huber_k):
            rho = np.where(z <= p.huber_k, 0.5 * z * z, p.huber_k * z - 0.5 * p.huber_k**2)
        else:
            rho = 0.5 * z * z
        n = valid.sum(axis=3)  # (N, M, R)
        data = (rho * valid).sum(axis=3) + 0.5 * n * np.log(2.0 * math.pi * v)[None, :, :]
        nll = data + prior + 0.5 * logdet
        # Elements the query has and a candidate lacks: charged what a matching element costs on
        # average (0.5 + the Gaussian's log normaliser), so a gap is no advantage.
        q_has = np.isfinite(q).sum(axis=2)  # (N, R)
        lacking = q_has[:, None, :] - n
        nll = nll + lacking * (0.5 + 0.5 * np.log(2.0 * math.pi * v))[None, :, :]
        total = nll.sum(axis=2)
        total[n.sum(axis=2) == 0] = np.inf
        return np.asarray(total, dtype=np.float64)

    def _nuisance(
        self, e: F64, valid: npt.NDArray[np.bool_], v: F64, sd: F64, A: F64, prior_var: list[F64]
    ) -> tuple[F64, F64, F64]:
        """The nuisance terms' fit (reweighted for outliers): the residuals in noise units, the
        prior's penalty and log det(Sigma_prior P) per (query, candidate, row)."""
        p = self.params
        k = A.shape[1]
        w = valid.astype(np.float64)  # robust weights (1: a Gaussian element, 0: missing)
        for _ in range(max(1, p.iterations)):
            # Weighted normal equations per (query, candidate, row): P beta = b.
            P = np.einsum("nmrb,bk,bl->nmrkl", w, A, A) / v[None, :, :, None, None]
            for j in range(k):
                P[..., j, j] += 1.0 / prior_var[j][None, None, :]
            rhs = np.einsum("nmrb,nmrb,bk->nmrk", w, e, A) / v[None, :, :, None]
            beta = np.linalg.solve(P, rhs[..., None])[..., 0]  # (N, M, R, K)
            resid = e - np.einsum("nmrk,bk->nmrb", beta, A)
            z = np.abs(resid) / sd
            if not math.isfinite(p.huber_k):
                break
            w = np.where(valid, np.minimum(1.0, p.huber_k / np.maximum(z, 1e-12)), 0.0)
        prior = sum(0.5 * beta[..., j] ** 2 / prior_var[j][None, None, :] for j in range(k))
        # Occam: log det(Sigma_prior P) / 2 (integrating the nuisance out).
        root = np.sqrt(np.stack(prior_var, axis=-1))  # (R, K)
        scaled = P * root[None, None, :, :, None] * root[None, None, :, None, :]
        _, logdet = np.linalg.slogdet(scaled)
        return z, np.asarray(prior, dtype=np.float64), np.asarray(logdet, dtype=np.float64)


class LearnedMatcher:
    """A learned model (``tofmat train``) through onnxruntime: the score is -ln p. Queries run one
    at a time, as tofmatd runs them, so that the cost per query compares with the other matchers'."""

    name = "onnx"

    def __init__(self, model: LearnedClassifier) -> None:
        self.model = model

    def scores(self, queries: F32) -> F64:
        return np.concatenate([self.model.scores(q[None]) for q in queries]) if len(queries) else np.zeros((0, 0))
