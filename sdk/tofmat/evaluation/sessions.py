# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""New capture sessions of the 29 real curves: the test inputs of docs/evaluation.md.

A query is what a box in the field measures: a window of consecutive depth bins of one material's
curve, in a capture session that is not the one the table was recorded in. What differs from the
stored curve and is not about the material, with its magnitude taken from a measurement:

- a per-row offset, N(0, s_r) with s_r the robust spread of the per-capture row offsets the
  simulator's calibration fitted (about 2.3 mm on row 0, d16 - d120, and 0.7 mm on row 1);
- the session's waveform (docs/simulator-model.md 2.2): the stored capture's fitted state t_m moved
  by N(0, s_f) per group, s_f the fitted states' robust spread; what that does to the material's
  curve comes from the calibrated simulator, ``curve(t_m + delta) - curve(t_m)`` (a drift along
  depth, several mm over the table for one s_f);
- bin noise with the material's own level: the curve's roughness per row (a robust estimate from
  its second differences), several times larger for fakeleather than for wood;
- dropped bins (NaN) and outlier bins, with the rate and size found in the curves themselves
  (elements more than 5 roughness units from their neighbours' median).

Every draw comes from one seeded generator, so a split (tuning or test) is fixed by its seed.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import ExemplarTable
from ..tools.sweeps import window_starts

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]

OUTLIER_UNITS = 5.0  # an element this many roughness units from its neighbours' median is an outlier
_NEIGHBOURS = 4  # on each side, for that median


def roughness(curves: F64) -> F64:
    """Each curve's bin-to-bin noise per row (M, R), mm: 1.4826 MAD of its second differences over
    sqrt(6) (white noise of sd s has second differences of sd s sqrt(6); a smooth trend has almost
    none). Missing elements (NaN) are skipped; fewer than 5 observed elements give NaN."""
    c = np.asarray(curves, dtype=np.float64)
    out = np.full(c.shape[:2], np.nan)
    for m in range(c.shape[0]):
        for r in range(c.shape[1]):
            v = c[m, r][np.isfinite(c[m, r])]
            if v.size < 5:
                continue
            d2 = np.diff(v, 2)
            out[m, r] = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    return out


def outliers(curves: F64, sigma: F64) -> tuple[float, float]:
    """The share of elements more than :data:`OUTLIER_UNITS` roughness units from the median of
    their neighbours (up to 4 each side), and the rms size of those departures in roughness units:
    the rate and size of outlier bins in the real curves."""
    c = np.asarray(curves, dtype=np.float64)
    z_all: list[float] = []
    n = 0
    for m in range(c.shape[0]):
        for r in range(c.shape[1]):
            s = sigma[m, r]
            if not (math.isfinite(s) and s > 0):
                continue
            v = c[m, r]
            for j in np.flatnonzero(np.isfinite(v)):
                lo, hi = max(0, j - _NEIGHBOURS), min(v.size, j + _NEIGHBOURS + 1)
                nb = np.concatenate([v[lo:j], v[j + 1 : hi]])
                nb = nb[np.isfinite(nb)]
                if nb.size < 2:
                    continue
                n += 1
                z = abs(float(v[j] - np.median(nb))) / s
                if z > OUTLIER_UNITS:
                    z_all.append(z)
    if n == 0:
        return 0.0, 0.0
    size = math.sqrt(float(np.mean(np.square(z_all)))) if z_all else 0.0
    return len(z_all) / n, size


@dataclass(frozen=True)
class SessionModel:
    """How a new session's query departs from the stored curve (module docstring)."""

    offsets_sd_mm: tuple[float, ...]  # per row
    state_sd: tuple[float, float, float]  # the waveform's session state per group (80, 16, 120 MHz)
    drop_p: float  # each element of a window missing with this probability
    outlier_p: float  # each element an outlier with this probability ...
    outlier_units: float  # ... off by N(0, (units x roughness)^2)
    noise_scale: float = 1.0  # bin noise = this x the material's roughness

    def __post_init__(self) -> None:
        values = [*self.offsets_sd_mm, *self.state_sd, self.outlier_units, self.noise_scale]
        if not all(math.isfinite(v) and v >= 0 for v in values):
            raise ValueError(f"session model: spreads and scales must be finite and >= 0, got {self}")
        for name in ("drop_p", "outlier_p"):
            p = getattr(self, name)
            if not (math.isfinite(p) and 0 <= p < 1):
                raise ValueError(f"session model: {name} must be in [0, 1), got {p}")


def scaled_model(model: SessionModel, scale: float) -> SessionModel:
    """``model`` with its session spreads (row offsets and waveform state) times ``scale``, the rest
    as it is. Raises ValueError for a scale that is negative or not finite."""
    if not (scale >= 0.0 and math.isfinite(scale)):
        raise ValueError(f"a session scale must be finite and >= 0, got {scale}")
    return replace(
        model,
        offsets_sd_mm=tuple(scale * v for v in model.offsets_sd_mm),
        state_sd=(scale * model.state_sd[0], scale * model.state_sd[1], scale * model.state_sd[2]),
    )


def calibrated_model(library: Mapping[str, Any], table: ExemplarTable, drop_p: float = 0.05) -> SessionModel:
    """The session model with the calibration's spreads (``library``: a calibrated material
    library's JSON) and the table's own roughness and outliers. ``drop_p``: the share of bins a
    sweep misses (no measurement in the curves for it; 5 % by default, documented as a choice)."""
    from ..sim.evaluate import session_offset_spread, session_state_spread

    sigma = roughness(table.features.astype(np.float64))
    p, size = outliers(table.features.astype(np.float64), sigma)
    return SessionModel(
        offsets_sd_mm=session_offset_spread(dict(library)),
        state_sd=session_state_spread(dict(library)),
        drop_p=drop_p,
        outlier_p=p,
        outlier_units=size,
    )


@dataclass(frozen=True)
class Session:
    """What one capture session does to every curve: row offsets (R,), mm, and the move of the
    waveform's state per group (None: no drift)."""

    offsets_mm: F64
    state_delta: tuple[float, float, float] | None


class CurveSessions:
    """The table's curves in new sessions: :meth:`curve` draws one material's curve in a new session."""

    def __init__(
        self,
        table: ExemplarTable,
        model: SessionModel,
        device: Mapping[str, Any] | None = None,
        library: Mapping[str, Any] | None = None,
    ) -> None:
        """``device``, ``library``: the calibrated simulator's device and material library JSON, for
        the waveform's drift (both needed when ``model.state_sd`` is not zero; a material the library
        does not hold gets no drift, and :attr:`no_drift` names it)."""
        self.table = table
        self.model = model
        self.curves = table.features.astype(np.float64)
        if len(model.offsets_sd_mm) != table.n_rows:
            raise ValueError(
                f"the session model has {len(model.offsets_sd_mm)} row offsets, the table {table.n_rows} rows"
            )
        self.sigma = roughness(self.curves)
        # Materials without a roughness (too few elements) get the median of the others.
        for r in range(table.n_rows):
            col = self.sigma[:, r]
            col[~np.isfinite(col)] = float(np.nanmedian(col)) if np.isfinite(col).any() else 0.3
        self._drift = any(s > 0 for s in model.state_sd)
        self.no_drift: list[str] = []
        self._materials: dict[str, Any] = {}
        self._device = device
        if self._drift:
            if device is None or library is None:
                raise ValueError("a session model with a waveform drift needs the simulator's device and library")
            by_name = {m["name"]: m for m in library.get("materials", [])}
            for name in table.materials:
                if name in by_name and "session" in by_name[name].get("fit", {}):
                    self._materials[name] = by_name[name]
                else:
                    self.no_drift.append(name)
            self._base: dict[str, F64] = {}

    def _bins(self) -> tuple[float, float, int]:
        b = self.table.bins
        return (b.start_mm, b.width_mm, b.count)

    def drift(self, m: int, delta: tuple[float, float, float]) -> F64:
        """What moving material m's session state by ``delta`` does to its curve (R, B), mm."""
        from ..sim import model_np

        name = self.table.materials[m]
        mat = self._materials.get(name)
        if mat is None or self._device is None:
            return np.zeros_like(self.curves[m])
        t0 = [float(x) for x in mat["fit"]["session"]]
        if name not in self._base:
            self._base[name] = model_np.curve(self._device, mat, bins=self._bins(), session=t0)
        moved = model_np.curve(
            self._device, mat, bins=self._bins(), session=[a + b for a, b in zip(t0, delta, strict=True)]
        )
        d = moved - self._base[name]
        return np.asarray(np.where(np.isfinite(d), d, 0.0), dtype=np.float64)

    def session(self, rng: np.random.Generator) -> Session:
        """A new session's departure: its row offsets and, with a waveform drift, its state's move."""
        off = np.array([rng.normal(0.0, s) for s in self.model.offsets_sd_mm])
        delta = None
        if self._drift:
            delta = (
                float(rng.normal(0.0, self.model.state_sd[0])),
                float(rng.normal(0.0, self.model.state_sd[1])),
                float(rng.normal(0.0, self.model.state_sd[2])),
            )
        return Session(off, delta)

    def session_curve(self, m: int, session: Session) -> F64:
        """Material m's curve (R, B) in that session: offsets and drift, before bin noise."""
        out: F64 = self.curves[m] + session.offsets_mm[:, None]
        if session.state_delta is not None:
            out = out + self.drift(m, session.state_delta)
        return out

    def curve(self, m: int, rng: np.random.Generator) -> F64:
        """Material m's curve (R, B) in a new session of its own."""
        return self.session_curve(m, self.session(rng))

    def sweep(self, session: Session, m: int, start: int, length: int, rng: np.random.Generator) -> F32:
        """Material m swept over bins [start, start + length) in ``session``: :meth:`measure` of its
        session curve."""
        return self.measure(m, self.session_curve(m, session), start, length, rng)

    def measure(self, m: int, session_curve: F64, start: int, length: int, rng: np.random.Generator) -> F32:
        """A sweep over bins [start, start + length) of a session's curve: the material's bin noise,
        dropped and outlier bins; NaN outside the window. (R, B) float32."""
        rows, bins = session_curve.shape
        q = np.full((rows, bins), np.nan)
        sl = slice(start, start + length)
        s = self.sigma[m][:, None] * self.model.noise_scale
        part = session_curve[:, sl] + rng.normal(0.0, 1.0, (rows, length)) * s
        out = rng.random((rows, length)) < self.model.outlier_p
        part = part + out * rng.normal(0.0, 1.0, (rows, length)) * s * self.model.outlier_units
        # A dropped bin loses both rows (one depth bin of the sweep saw no pixel).
        drop = rng.random(length) < self.model.drop_p
        part[:, drop] = np.nan
        q[:, sl] = part
        return q.astype(np.float32)


@dataclass(frozen=True)
class Queries:
    """Drawn queries: ``truth[i]`` is the material index of ``queries[i]`` (R, B), a sweep of
    ``lengths[i]`` bins."""

    truth: npt.NDArray[np.int64]
    lengths: npt.NDArray[np.int64]
    queries: F32  # (N, R, B)


def draw_queries(sessions: CurveSessions, lengths: list[int], sessions_per_material: int, seed: int) -> Queries:
    """For every material, ``sessions_per_material`` new sessions; in each, one sweep of every
    length at a random position. A query left with no element (all dropped) is drawn again."""
    table = sessions.table
    if sessions_per_material < 1:
        raise ValueError("sessions_per_material must be at least 1")
    for n in lengths:
        if not 1 <= n <= table.n_bins:
            raise ValueError(f"a sweep length must be 1..{table.n_bins}, got {n}")
    rng = np.random.default_rng(seed)
    truth: list[int] = []
    lens: list[int] = []
    qs: list[F32] = []
    for m in range(len(table.materials)):
        for _ in range(sessions_per_material):
            c = sessions.curve(m, rng)
            for n in lengths:
                starts = window_starts(table, m, n)
                if starts.size == 0:
                    continue
                while True:
                    start = int(starts[rng.integers(0, starts.size)])
                    q = sessions.measure(m, c, start, n, rng)
                    # Both rows missing where the table misses the element too: count common ones.
                    if (np.isfinite(q) & np.isfinite(table.features[m])).any():
                        break
                truth.append(m)
                lens.append(n)
                qs.append(q)
    return Queries(np.array(truth, dtype=np.int64), np.array(lens, dtype=np.int64), np.stack(qs))
