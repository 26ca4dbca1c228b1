# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Fit the forward model (docs/simulator-model.md, model_np.py) to the real Kinect v2 database.

Shared device parameters (per-frequency harmonics up to GROUP_HMAX, tap saturation, step gains
and offsets, scale errors; sections 2.1 and 3.1 of the spec) and
per-material response parameters are fitted so that the simulated relative distortions (rows
d16 - d120 and d80 - d120 against the combined depth) match the 29 real curves, with one nuisance
offset per material and row and one session state per material and group (each material was
captured in its own session; the state moves the waveform's harmonics along a fitted drift
direction, spec section 2.2; SESSION_DRIFT = False fits the offsets only).

Staged fit (scipy.optimize.least_squares, finite differences with a block-sparse Jacobian):

1. device: random restarts of the low harmonics h <= 7 (fitted in Cartesian form
   ``a e^{i psi}``, with a small ridge that picks the least-amplitude solution among
   near-degenerate harmonic pairs) on two pseudo-curves, the median of the typical (near-opaque)
   materials and the median of the translucent group; the best restart goes on to all harmonics
   (GROUP_HMAX) with the tap saturation;
2. per material, device fixed: kind selection among exponential / gamma / double / slab (a
   nominal 1 mm layer with a fitted path factor unless the thickness is known), several starting
   points each; the per-sample noise of section 4.1 for curves that show the 120 MHz wrap
   inside the averaging (fakeleather);
3. joint refinement of the device (harmonics, session drift direction, saturation sharpness,
   full wells W_80 and W_120, step gains, step offsets, scale errors), all materials and their
   session states (started at random, N(0, SESSION_PRIOR)), in passes that reweight each
   material by 1 / rms^WEIGHT_EXP (rms clipped to [WEIGHT_FLOOR_MM, WEIGHT_CAP_MM]) so that the
   fit aims at the median of the per-material rms rather than at the worst curves; the pass with
   the lowest median is kept;
4. gauge: the median per-capture offsets are moved into the device's decode offsets and the
   median session state into the harmonics (``regauge``, exact); then KIND_CYCLES times (2) (every kind again, warm starts), (3) and (4),
   and a report in ``bin`` mode (the database's averaging, 0.25 mm sweep).

Re-run: ``python -m tofmat.sim.calibrate --db shared/data/tanaka2017_kinect2_db --out <dir>``
writes ``<dir>/data/devices/kinect2_tanaka2017.json``, ``<dir>/data/materials/tanaka2017.json``
and ``<dir>/data/materials/tanaka2017_fit.png``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeAlias, TypedDict, cast

import numpy as np

from .._extras import require, require_pyplot
from . import model_np as M
from .model_np import ComplexArray, FloatArray

# What needs the ``sim`` extra here: the fit (scipy, imported where it is used) and its figure (matplotlib).
FEATURE = "the simulator's calibration (tofmat.sim.calibrate)"

# A state key: the parameter's name, then its indices (group, harmonic / step, or material).
StateKey: TypeAlias = tuple[str, *tuple[int, ...]]
State: TypeAlias = dict[StateKey, float]

# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------
THIN_ACRYLICS = {"acryl1mm": 1.0, "acryl2mm": 2.0, "acryl3mm": 3.0}
ACRYLIC_N = 1.49
# Every kind is a candidate for every material: a slab (a scattering layer on a backing) for a
# material whose thickness is not known gets this nominal thickness, and the fitted path factor
# sets its round-trip time (T = path_factor * 2 * thickness * n / c, 10 ps .. 3 ns)
SLAB_ALL = True
SLAB_NOMINAL_MM = 1.0
HMAX = 32  # highest harmonic of the device model (spec section 2.1; the C++ simulator's limit)
# highest fitted harmonic per group (80, 16, 120 MHz): the 16 MHz correlation waveform has the
# sharpest features (its fitted amplitudes still grow at h = 25, and acryl / silicone /
# whiteglass show 300-400 mm bumps = 9375 / 3k mm, k ~ 8-10); above these the harmonics stay 0
# (listed in the profile with amplitude 0)
GROUP_HMAX = (19, 32, 19)
HARMONICS_LOW = (2, 4, 5, 7)
HARMONICS_FIT = tuple(h for h in range(2, HMAX + 1) if h % 3)  # h = 3k cancel (ideal gains)
GROUPS = (80, 16, 120)
RIDGE = 10.0  # ridge on the harmonics' Cartesian coordinates, times sqrt(number of curves)
OFFSET_PRIOR_MM = 10.0  # prior on the per-capture offsets: levels must come from the model
# sweeps of the fit (interp mode): the rows are smooth on the 3 mm bins (a 3 mm sweep changes
# the per-material rms by < 0.001 mm against 1.5 mm) and the saturation dominates the cost
FIT_GRID = (450.0, 1400.0, 3.0)
COARSE_GRID = (450.0, 1400.0, 3.0)
REPORT_GRID = (450.0, 1400.0, 0.25)
SATURATION = True  # spec section 3.1 (tap full well); False: the linear model
# device terms beyond the harmonics freed in the joint stage (section 2: step gains g_j, step
# offsets o_j, scale errors s_f)
# and full wells W_80, W_120 (W_16 = 1 is the albedo's unit)
JOINT_DEVICE_EXTRAS = {"gain": True, "off": True, "scale": True, "full_well": True, "drift": True}
# Session drift (spec section 2.2): each capture session's waveform is G_h + t_f dG_h, dG a
# shared direction per group (device, fitted in the joint stage with DRIFT_RIDGE), t_f per
# capture and group (nuisance, prior N(0, SESSION_PRIOR^2), like the offsets). False: no drift.
SESSION_DRIFT = True
SESSION_KEYS = ("t0", "t1", "t2")  # t_80, t_16, t_120 of a capture
SESSION_PRIOR = 1.0
DRIFT_RIDGE = 10.0  # times sqrt(number of curves), as RIDGE
# Joint fit: material weight 1 / clip(rms, floor, cap)^WEIGHT_EXP, recomputed before every pass
# (iteratively reweighted). 1/sqrt(rms) (~ sum of rms) let the few curves a kernel cannot
# represent (fakeleather's noise, copper) steer the shared device; a steeper weight aims at the
# median; the floor stops curves already at the bin noise (~0.4 mm) from taking over, the cap
# keeps the worst curves in play (the 2 mm bound).
WEIGHT_FLOOR_MM = 0.45
WEIGHT_CAP_MM = 1.5
WEIGHT_EXP = 1.5
# Joint passes per round (each max JOINT_NFEV function evaluations, then reweighted): the joint
# fit is far from converged after one pass; the state with the lowest median rms is kept.
JOINT_PASSES = (2, 5)
# rounds after the first: choose each material's kind again against the refined device, then
# the joint passes, KIND_CYCLES times (the joint fit plateaus after a few passes; a new kind
# choice moves it on)
KIND_RESELECT = True
KIND_CYCLES = 2
JOINT_NFEV = 30

DEV_BOUNDS = {
    "hx": (-0.5, 0.5), "hy": (-0.5, 0.5), "delta": (-math.pi, math.pi), "s": (-0.02, 0.02),
    "gain": (0.8, 1.2), "off": (-0.5, 0.5), "satp": (2.0, 100.0), "lw": (-1.5, 1.5),
    "dx": (-0.5, 0.5), "dy": (-0.5, 0.5),
}  # fmt: skip
MAT_BOUNDS = {
    "b": (0.0, 1.0), "lt": (-1.0, 3.5), "lk": (-1.0, 1.3), "beta": (0.0, 1.0), "lpf": (0.0, 2.5),
    "w": (0.0, 1.0), "lt2": (-1.0, 3.5), "noise": (0.0, 80.0), "lr": (-2.5, 1.5), "o0": (-400.0, 400.0),
    "o1": (-400.0, 400.0), "t0": (-6.0, 6.0), "t1": (-6.0, 6.0), "t2": (-6.0, 6.0),
}  # fmt: skip
KIND_PARAMS = {
    "opaque": (),
    "exponential": ("b", "lt"),
    "gamma": ("b", "lt", "lk"),
    "slab": ("b", "lt", "beta", "lpf"),
    "double": ("b", "lt", "w", "lt2"),
}
KIND_ORDER = ("exponential", "gamma", "slab", "double")  # simplest first


def _log(msg: str) -> None:
    print(msg, flush=True)


# ---------------------------------------------------------------------------------------------
# State (a flat dict of named parameters) <-> JSON dicts
# ---------------------------------------------------------------------------------------------
def _default_state(names: Sequence[str]) -> State:
    st: State = {}
    for g in range(3):
        for h in range(2, HMAX + 1):
            st[("hx", g, h)] = 0.0
            st[("hy", g, h)] = 0.0
            st[("dx", g, h)] = 0.0  # session drift direction dG_h (section 2.2)
            st[("dy", g, h)] = 0.0
        st[("delta", g)] = 0.0
        st[("s", g)] = 0.0
        for j in range(3):
            st[("gain", g, j)] = 1.0
            st[("off", g, j)] = 0.0
        st[("eps", g)] = 0.0  # decode offset (rad)
        st[("lw", g)] = 0.0  # log10 full well (gauge: the 16 MHz group's is 1)
    st[("satp",)] = 8.0
    for i, _ in enumerate(names):
        st.update({
            ("b", i): 0.3, ("lt", i): 2.0, ("lk", i): 0.0, ("beta", i): 0.0, ("lpf", i): 0.5,
            ("w", i): 0.3, ("lt2", i): 3.0, ("noise", i): 0.0, ("o0", i): 0.0, ("o1", i): 0.0,
            ("lr", i): -0.5, ("t0", i): 0.0, ("t1", i): 0.0, ("t2", i): 0.0,
        })  # fmt: skip
    return st


def state_to_device(st: State, name: str = "kinect2_tanaka2017") -> dict[str, Any]:
    freqs = []
    for g, f in enumerate(GROUPS):
        harm = []
        for h in range(2, HMAX + 1):
            x, y = st[("hx", g, h)], st[("hy", g, h)]
            harm.append({"h": h, "amplitude": float(math.hypot(x, y)),
                         "phase_rad": float(math.atan2(y, x)) if (x or y) else 0.0})  # fmt: skip
        drift = M.harmonic_list(np.array([0.0, 0.0] + [
            st[("dx", g, h)] + 1j * st[("dy", g, h)] for h in range(2, HMAX + 1)]))  # fmt: skip
        freqs.append({
            "freq_mhz": f,
            "signal_scale": float(M.SIGNAL_SCALE_DEFAULT[g]),
            "full_well": float(10.0 ** st[("lw", g)]) if SATURATION else None,
            "scale_error": float(st[("s", g)]),
            "phase_offset_rad": float(st[("delta", g)]),
            "decode_offset_rad": float(st[("eps", g)]),
            "harmonics": harm,
            "step_gain": [float(st[("gain", g, j)]) for j in range(3)],
            "step_offset": [float(st[("off", g, j)]) for j in range(3)],
            **({"session_drift": drift} if drift else {}),
        })  # fmt: skip
    return {"name": name, "version": 2, "range_ref_mm": M.RANGE_REF_MM,
            "saturation": {"sharpness": float(st[("satp",)])}, "frequencies": freqs}  # fmt: skip


def device_to_state(dev: dict[str, Any], st: State) -> None:
    for g, f in enumerate(GROUPS):
        grp = M._group(dev, float(f))
        G = M.harmonic_vector(grp, HMAX)
        dG = M.harmonic_vector(grp, HMAX, "session_drift")
        for h in range(2, HMAX + 1):
            st[("hx", g, h)] = float(G[h].real)
            st[("hy", g, h)] = float(G[h].imag)
            st[("dx", g, h)] = float(dG[h].real)
            st[("dy", g, h)] = float(dG[h].imag)
        st[("delta", g)] = float(grp.get("phase_offset_rad", 0.0))
        st[("eps", g)] = float(grp.get("decode_offset_rad", 0.0))
        st[("s", g)] = float(grp.get("scale_error", 0.0))
        for j in range(3):
            st[("gain", g, j)] = float(grp.get("step_gain", [1, 1, 1])[j])
            st[("off", g, j)] = float(grp.get("step_offset", [0, 0, 0])[j])
        fw = grp.get("full_well")
        # null (no saturation): the fit always saturates, so a well far above any signal (1e6)
        st[("lw", g)] = math.log10(float(fw)) if fw else 6.0
    st[("satp",)] = float((dev.get("saturation") or {}).get("sharpness", 8.0))


class _DeviceArrays(TypedDict):
    """The device as arrays over the groups (as model_np.device_arrays; sat_p a float)."""

    f: FloatArray
    s: FloatArray
    delta: FloatArray
    eps: FloatArray
    G: ComplexArray
    dG: ComplexArray
    gain: FloatArray
    offset: FloatArray
    scale: FloatArray
    full_well: FloatArray
    sat_p: float


def _device_arrays(st: State) -> _DeviceArrays:
    G = np.zeros((3, HMAX + 1), complex)
    G[:, 1] = 1.0
    dG = np.zeros((3, HMAX + 1), complex)
    for g in range(3):
        for h in range(2, HMAX + 1):
            G[g, h] = st[("hx", g, h)] + 1j * st[("hy", g, h)]
            dG[g, h] = st[("dx", g, h)] + 1j * st[("dy", g, h)]
    return {
        "f": np.array(GROUPS, float),
        "s": np.array([st[("s", g)] for g in range(3)]),
        "delta": np.array([st[("delta", g)] for g in range(3)]),
        "eps": np.array([st[("eps", g)] for g in range(3)]),
        "G": G,
        "dG": dG,
        "gain": np.array([[st[("gain", g, j)] for j in range(3)] for g in range(3)]),
        "offset": np.array([[st[("off", g, j)] for j in range(3)] for g in range(3)]),
        "scale": np.array(M.SIGNAL_SCALE_DEFAULT),
        "full_well": np.array([10.0 ** st[("lw", g)] if SATURATION else np.inf for g in range(3)]),
        "sat_p": st[("satp",)],
    }


def state_to_material(st: State, i: int, name: str, kind: str) -> dict[str, Any]:
    thick = THIN_ACRYLICS.get(name, SLAB_NOMINAL_MM if kind == "slab" else 0.0)
    n = ACRYLIC_N if name.startswith("acryl") else 1.5
    mat: dict[str, Any] = {
        "name": name, "kind": kind, "albedo": float(10.0 ** st[("lr", i)]) if SATURATION else 1.0, "subsurface": 0.0, "tau_ps": 100.0,
        "gamma_k": 1.0, "refractive_index": n, "thickness_mm": thick, "path_factor": 1.0,
        "backing": 0.0, "subsurface2": 0.0, "tau2_ps": 1000.0,
        "noise_mm": float(st[("noise", i)]),
    }  # fmt: skip
    if kind == "opaque":
        return mat
    b = float(st[("b", i)])
    mat["subsurface"] = b
    mat["tau_ps"] = float(10.0 ** st[("lt", i)])
    if kind == "gamma":
        mat["gamma_k"] = float(10.0 ** st[("lk", i)])
    elif kind == "slab":
        mat["backing"] = float(st[("beta", i)])
        mat["path_factor"] = float(10.0 ** st[("lpf", i)])
    elif kind == "double":
        w = float(st[("w", i)])
        mat["subsurface"] = b * (1.0 - w)
        mat["subsurface2"] = b * w
        mat["tau2_ps"] = float(10.0 ** st[("lt2", i)])
    return mat


# ---------------------------------------------------------------------------------------------
# Gauge: move the common row levels into the device (spec section 4.2)
# ---------------------------------------------------------------------------------------------
def regauge(st: State, idx: Sequence[int]) -> tuple[float, float]:
    """Move the median per-capture offsets (row0, row1) into the device's decode offsets eps_f.

    Levels c_f with c16 - c120 = o0, c80 - c120 = o1 and 80 c80 + 16 c16 + 120 c120 = 0 (the
    combined depth is unchanged): eps_f += 2 pi c_f / U_f. The decode offset acts after the
    samples are formed, so this is exact (also with saturation); only the noise-wrap expectation
    of section 4.1 moves with d_120 (by |c120|, a few mm)."""
    o0 = float(np.median([st[("o0", i)] for i in idx]))
    o1 = float(np.median([st[("o1", i)] for i in idx]))
    c120 = -(80.0 * o1 + 16.0 * o0) / 216.0
    c = [o1 + c120, o0 + c120, c120]  # groups 80, 16, 120
    for g, f in enumerate(GROUPS):
        st[("eps", g)] += 2.0 * math.pi * c[g] / M.unambiguous_range_mm(float(f))
    for i in idx:
        st[("o0", i)] -= o0
        st[("o1", i)] -= o1
    if SESSION_DRIFT:  # the nominal waveform is the median session's: G_h += t_med dG_h (exact)
        for g, k in enumerate(SESSION_KEYS):
            t_med = float(np.median([st[(k, i)] for i in idx]))
            for h in range(2, HMAX + 1):
                st[("hx", g, h)] += t_med * st[("dx", g, h)]
                st[("hy", g, h)] += t_med * st[("dy", g, h)]
            for i in idx:
                st[(k, i)] -= t_med
    return o0, o1


# ---------------------------------------------------------------------------------------------
# The least-squares problem
# ---------------------------------------------------------------------------------------------
class Problem:
    """Vectorised residuals of a set of curves against the model (interp mode)."""

    def __init__(
        self,
        Y: FloatArray,
        names: Sequence[str],
        bins: tuple[float, float, int],
        grid: tuple[float, float, float] = FIT_GRID,
        ridge: float = RIDGE,
    ) -> None:
        self.Y = np.asarray(Y, float)  # (M, 2, B), NaN missing
        self.names = list(names)
        self.bins = bins
        self.centres = bins[0] + bins[1] * (np.arange(bins[2]) + 0.5)
        self.D = M.sweep_grid(*grid)
        self.A = (M.RANGE_REF_MM / self.D) ** 2
        self.valid = np.isfinite(self.Y)
        self.ridge = ridge
        self.weights = np.ones(len(self.Y))

    # -- forward ---------------------------------------------------------------------------
    def curves(self, st: State, kinds: Sequence[str], idx: Sequence[int]) -> FloatArray:
        dev = _device_arrays(st)
        Rh = np.stack([
            M.material_harmonic_responses(state_to_material(st, i, self.names[i], kinds[i]), dev)
            for i in idx
        ])  # fmt: skip
        G: ComplexArray = dev["G"]
        if SESSION_DRIFT:  # every capture in its own session (section 2.2): G per material
            t = np.array([[st[(k, i)] for k in SESSION_KEYS] for i in idx])
            G = G[None] + t[:, :, None] * dev["dG"][None]
        if SATURATION:
            m = M.raw_samples_core(
                dev["f"], dev["s"], dev["delta"], G, dev["gain"], dev["offset"], Rh,
                self.D, self.A, 0.0, dev["scale"], dev["full_well"], float(dev["sat_p"]),
            )  # fmt: skip
            d = M.decode(m, 0.0, dev["eps"])
        else:
            z = M.phasor_direct(dev["f"], dev["s"], dev["delta"], G, dev["gain"], dev["offset"], Rh, self.D)
            d = M.depths_from_phasor(z, dev["eps"])
        _, dcomb = M.unwrap_combined(d)
        noise = np.array([st[("noise", i)] for i in idx])
        de = M.expected_wrapped(d, noise)
        rows = np.stack([de[:, 1] - de[:, 2], de[:, 0] - de[:, 2]], axis=1)  # (M, 2, N)
        out = np.empty((len(idx), 2, self.bins[2]))
        for k in range(len(idx)):
            x = dcomb[k]
            if np.all(np.diff(x) > 0):
                xs, r = x, rows[k]
            else:
                o = np.argsort(x, kind="stable")
                xs, r = x[o], rows[k][:, o]
            for row in range(2):
                out[k, row] = np.interp(self.centres, xs, r[row], left=np.nan, right=np.nan)
        return out

    # -- parameter vector --------------------------------------------------------------------
    def setup(
        self,
        st: State,
        kinds: Sequence[str],
        idx: Sequence[int],
        dev_free: Sequence[StateKey],
        mat_free: Mapping[int, Sequence[str]],
    ) -> None:
        self.st = dict(st)
        self.kinds = list(kinds)
        self.idx = list(idx)
        keys: list[StateKey] = list(dev_free)
        for i in self.idx:
            keys += [(p, i) for p in mat_free.get(i, ())]
        self.keys = keys
        self.lo = np.array([self._bounds(k)[0] for k in keys])
        self.hi = np.array([self._bounds(k)[1] for k in keys])
        self.masks = [self.valid[i] for i in self.idx]
        sizes = [int(mk.sum()) for mk in self.masks]
        self.row_start = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        n_data = int(self.row_start[-1])
        self.harm_pairs = [k for k in dev_free if k[0] == "hx"]
        pos = {k: c for c, k in enumerate(keys)}
        # priors on the free session states and ridge on the free drift coordinates
        self.pen_keys: list[StateKey] = [(k, i) for i in self.idx for k in SESSION_KEYS if (k, i) in pos]
        self.pen_keys += [k for k in dev_free if k[0] in ("dx", "dy")]
        n_pen = 2 * len(self.idx) + 3 * len(self.harm_pairs) + len(self.pen_keys)
        self.n_res = n_data + n_pen
        require("scipy.sparse", extra="sim", feature=FEATURE)
        from scipy.sparse import lil_matrix  # type: ignore[import-untyped]  # scipy ships no type stubs

        sp = lil_matrix((self.n_res, len(keys)), dtype=int)
        dev_cols = [c for c, k in enumerate(keys) if k[0] in DEV_BOUNDS]
        for a, i in enumerate(self.idx):
            r0, r1 = self.row_start[a], self.row_start[a + 1]
            cols = dev_cols + [c for c, k in enumerate(keys) if k[0] in MAT_BOUNDS and k[1] == i]  # type: ignore[misc]  # material keys are (name, i)
            for c in cols:
                sp[r0:r1, c] = 1
            for j, p in enumerate(("o0", "o1")):
                if (p, i) in pos:
                    sp[n_data + 2 * a + j, pos[(p, i)]] = 1
        base = n_data + 2 * len(self.idx)
        for q, k in enumerate(self.harm_pairs):
            ky = ("hy", *k[1:])
            for r in range(3):
                sp[base + 3 * q + r, pos[k]] = 1
                if ky in pos:
                    sp[base + 3 * q + r, pos[ky]] = 1
        base += 3 * len(self.harm_pairs)
        for q, k in enumerate(self.pen_keys):
            sp[base + q, pos[k]] = 1
        self.sparsity = sp.tocsr()
        self.ridge_w = self.ridge * math.sqrt(len(self.idx))

    @staticmethod
    def _bounds(k: StateKey) -> tuple[float, float]:
        return DEV_BOUNDS[k[0]] if k[0] in DEV_BOUNDS else MAT_BOUNDS[k[0]]

    def x0(self) -> FloatArray:
        x = np.array([self.st[k] for k in self.keys], float)
        span = self.hi - self.lo
        return cast(FloatArray, np.clip(x, self.lo + 1e-9 * span, self.hi - 1e-9 * span))

    def apply(self, x: FloatArray) -> State:
        st = dict(self.st)
        st.update(zip(self.keys, map(float, x), strict=True))
        return st

    def residuals(self, x: FloatArray) -> FloatArray:
        st = self.apply(x)
        sim = self.curves(st, self.kinds, self.idx)
        res = []
        for a, i in enumerate(self.idx):
            off = np.array([st[("o0", i)], st[("o1", i)]])[:, None]
            r = (sim[a] + off - self.Y[i])[self.masks[a]]
            r = np.where(np.isfinite(r), r, 50.0)  # sweep does not cover: large
            res.append(self.weights[i] * r)
        pen = []
        for i in self.idx:
            pen += [st[("o0", i)] / OFFSET_PRIOR_MM, st[("o1", i)] / OFFSET_PRIOR_MM]
        for k in self.harm_pairs:
            hx, hy = st[k], st[("hy", *k[1:])]
            pen += [self.ridge_w * hx, self.ridge_w * hy,
                    100.0 * max(0.0, math.hypot(hx, hy) - 0.5)]  # fmt: skip
        drift_w = DRIFT_RIDGE * math.sqrt(len(self.idx))
        pen += [st[k] / SESSION_PRIOR if k[0] in SESSION_KEYS else drift_w * st[k] for k in self.pen_keys]
        return np.concatenate([*res, np.array(pen)])

    def solve(self, max_nfev: int = 200) -> Any:
        require("scipy.optimize", extra="sim", feature=FEATURE)
        from scipy.optimize import least_squares  # type: ignore[import-untyped]  # scipy ships no type stubs

        r = least_squares(
            self.residuals, self.x0(), bounds=(self.lo, self.hi), jac_sparsity=self.sparsity,
            method="trf", x_scale="jac", max_nfev=max_nfev, ftol=1e-9, xtol=1e-9, gtol=1e-9,
        )  # fmt: skip
        self.st = self.apply(r.x)
        return r

    def rms(self, st: State, kinds: Sequence[str], idx: Sequence[int]) -> FloatArray:
        sim = self.curves(st, kinds, idx)
        out = []
        for a, i in enumerate(idx):
            off = np.array([st[("o0", i)], st[("o1", i)]])[:, None]
            r = (sim[a] + off - self.Y[i])[self.valid[i]]
            r = np.where(np.isfinite(r), r, 50.0)
            out.append(float(np.sqrt(np.mean(r * r))))
        return np.array(out)


def _dev_keys(harm: Sequence[int] = HARMONICS_FIT, delta: bool = False, scale: bool = False,
              gain: bool = False, off: bool = False, sat: bool = SATURATION,
              full_well: bool = False, drift: bool = False) -> list[StateKey]:  # fmt: skip
    """Free device parameters. Gauges: delta_120 = 0 (a common range shift is unobservable),
    s_120 = 0, g_0 = 1, o_0 = 0 (the common mode of o_j cancels in the decode). With free
    per-capture offsets and free harmonic phases, the deltas are pure gauge too (see regauge)."""
    keys: list[StateKey] = []
    for g in range(3):
        for h in harm:
            if h <= GROUP_HMAX[g]:
                keys += [("hx", g, h), ("hy", g, h)]
        if delta and GROUPS[g] != 120:
            keys.append(("delta", g))
        if scale and GROUPS[g] != 120:
            keys.append(("s", g))
        if gain:
            keys += [("gain", g, 1), ("gain", g, 2)]
        if off:
            keys += [("off", g, 1), ("off", g, 2)]
        if full_well and GROUPS[g] != 16:  # gauge: W_16 = 1 (the albedo's unit)
            keys.append(("lw", g))
        if drift and SESSION_DRIFT:
            for h in harm:
                if h <= GROUP_HMAX[g]:
                    keys += [("dx", g, h), ("dy", g, h)]
    if sat:
        keys.append(("satp",))
    return keys


def _init_offsets(prob: Problem, st: State, kinds: Sequence[str], idx: Sequence[int]) -> None:
    sim = prob.curves(st, kinds, idx)
    for a, i in enumerate(idx):
        for row in range(2):
            d = prob.Y[i, row] - sim[a, row]
            d = d[np.isfinite(d)]
            st[(f"o{row}", i)] = float(np.clip(np.median(d), -390, 390)) if d.size else 0.0


def typical_median(Y: FloatArray, frac: float = 0.5) -> tuple[FloatArray, list[int]]:
    """Median curve of the materials closest to the overall median (offsets removed)."""
    med = np.nanmedian(Y, axis=0)
    dev = []
    for y in Y:
        d = y - med
        d = d - np.nanmedian(d, axis=1, keepdims=True)
        dev.append(float(np.sqrt(np.nanmean(d * d))))
    keep = sorted(np.argsort(dev)[: max(3, round(frac * len(Y)))].tolist())
    return np.nanmedian(Y[keep], axis=0), keep


# ---------------------------------------------------------------------------------------------
# Stages
# ---------------------------------------------------------------------------------------------
def translucent_group(Y: FloatArray, typical: FloatArray) -> list[int]:
    """Materials whose rows sit well above the typical curve (subsurface delays of ~ns)."""
    out = []
    for i, y in enumerate(Y):
        d = np.nanmedian(y - typical, axis=1)
        if d[0] > 15.0 and d[1] > 3.0:
            out.append(i)
    return out


def stage_device(
    Y: FloatArray, bins: tuple[float, float, int], restarts: int, rng: np.random.Generator,
    log: Callable[[str], None], keep: int = 1,
) -> list[State]:  # fmt: skip
    """Device harmonics from two pseudo-materials: the median curve of the typical (near-opaque)
    materials and the median curve of the translucent group (started with a ~1.5 ns
    subsurface response). The second curve separates the harmonics h = 3k - 1 and 3k + 1,
    which the opaque curves alone constrain only through their difference."""
    ym, _ = typical_median(Y)
    tg = translucent_group(Y, ym)
    curves_ = [ym] + ([np.nanmedian(Y[tg], axis=0)] if len(tg) >= 2 else [])
    names = ["typical", "translucent"][: len(curves_)]
    prob = Problem(np.stack(curves_), names, bins, grid=COARSE_GRID)
    kinds = ["exponential"] * len(names)
    idx = list(range(len(names)))
    low = []
    for r in range(restarts):
        st = _default_state(names)
        for g in range(3):
            for h in HARMONICS_LOW:
                a = rng.uniform(0.0, 0.1)
                p = rng.uniform(0, 2 * math.pi)
                st[("hx", g, h)], st[("hy", g, h)] = a * math.cos(p), a * math.sin(p)
        st[("b", 0)] = rng.uniform(0.05, 0.4)
        st[("lt", 0)] = rng.uniform(0.5, 2.5)
        if len(idx) > 1:
            st[("b", 1)] = rng.uniform(0.3, 0.7)
            st[("lt", 1)] = rng.uniform(2.9, 3.3)
        for i in idx:
            st[("lr", i)] = -1.5  # start unsaturated
        _init_offsets(prob, st, kinds, idx)
        free: dict[int, tuple[str, ...]] = {i: ("b", "lt", "o0", "o1") for i in idx}
        prob.setup(st, kinds, idx, _dev_keys(HARMONICS_LOW, sat=False), free)
        res = prob.solve(max_nfev=80)
        rms = prob.rms(prob.st, kinds, idx)
        log(
            f"  restart {r:2d} (h <= 7): rms "
            + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, rms, strict=True))
            + f" mm (cost {res.cost:.1f})"
        )
        low.append((float(res.cost), prob.st))
    # the multimodal part is the low harmonics' phases: only the best restarts go on to all
    # harmonics with the tap saturation (the expensive fit)
    low.sort(key=lambda t: t[0])
    out = []
    for r, (_, st) in enumerate(low[:keep]):
        free = {i: ("b", "lt", "o0", "o1") + (("lr",) if SATURATION else ()) for i in idx}
        prob.setup(st, kinds, idx, _dev_keys(HARMONICS_FIT), free)
        res = prob.solve(max_nfev=150)
        rms = prob.rms(prob.st, kinds, idx)
        log(
            f"  best {r + 1}, all harmonics: rms "
            + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, rms, strict=True))
            + f" mm (cost {res.cost:.1f})"
        )
        out.append((float(res.cost), prob.st))
    out.sort(key=lambda t: t[0])
    return [s for _, s in out]


def joint_refine(
    prob: Problem, st: State, kinds: Sequence[str], idx: Sequence[int],
    mat_free: Mapping[int, Sequence[str]], passes: int, nfev: int, log: Callable[[str], None],
) -> State:  # fmt: skip
    """Stage 3: device and materials together, iteratively reweighted (WEIGHT_EXP); returns the
    pass with the lowest median per-material rms (the weighted cost and the median need not
    fall together)."""
    rms = prob.rms(st, kinds, idx)
    best = (float(np.median(rms)), dict(st))
    for k in range(passes):
        prob.weights = np.ones(len(prob.Y))
        prob.weights[list(idx)] = 1.0 / np.clip(rms, WEIGHT_FLOOR_MM, WEIGHT_CAP_MM) ** WEIGHT_EXP
        prob.setup(st, kinds, idx, _dev_keys(HARMONICS_FIT, **JOINT_DEVICE_EXTRAS), mat_free)
        res = prob.solve(max_nfev=nfev)
        st = prob.st
        prob.weights = np.ones(len(prob.Y))
        rms = prob.rms(st, kinds, idx)
        med = float(np.median(rms))
        log(f"  joint pass {k + 1}/{passes}: cost {res.cost:.1f}, median rms {med:.3f} mm, "
            f"max {rms.max():.3f} mm ({res.nfev} evaluations)")  # fmt: skip
        if med < best[0]:
            best = (med, dict(st))
    return best[1]


def fit_material(
    prob: Problem, st: State, kinds: list[str], i: int, candidates: Sequence[str],
    with_noise: bool, nfev: int = 40,
    starts: Sequence[tuple[float, float, float]] = (
        (1.0, 0.3, -1.0), (2.0, 0.6, -0.4), (3.2, 0.4, -0.2)),
) -> tuple[str, State, float, dict[str, float]]:  # fmt: skip
    """Device fixed: the best kind and parameters of material i (several starting points)."""
    scores: dict[str, float] = {}
    fits: dict[str, State] = {}
    for kind in candidates:
        kb: tuple[float, State] | None = None
        trial = [(st["lt", i], st["b", i], st["lr", i]), *list(starts)]
        for lt, b0, lr in trial:
            s = dict(st)
            s[("lt", i)], s[("b", i)], s[("lr", i)] = lt, b0, lr
            if kind == "gamma":
                s[("lk", i)] = -0.3 if kinds[i] != "gamma" else st[("lk", i)]
            if kind == "slab" and kinds[i] != "slab":  # (warm: keep the slab's own terms)
                s[("beta", i)], s[("lpf", i)] = 0.3, 1.0
            if kind == "double" and kinds[i] != "double":
                s[("w", i)], s[("lt2", i)] = 0.3, min(lt + 1.5, 4.5)
            if with_noise and s[("noise", i)] < 5.0:
                s[("noise", i)] = 25.0
            ks = list(kinds)
            ks[i] = kind
            free = (KIND_PARAMS[kind] + ("o0", "o1") + (("noise",) if with_noise else ())
                    + (("lr",) if SATURATION else ()))  # fmt: skip
            prob.setup(s, ks, [i], [], {i: free})
            prob.solve(max_nfev=nfev)
            rms = float(prob.rms(prob.st, ks, [i])[0])
            if kb is None or rms < kb[0]:
                kb = (rms, prob.st)
        assert kb is not None
        scores[kind], fits[kind] = kb
    best = min(scores.values())
    chosen = next(k for k in KIND_ORDER if k in scores and scores[k] <= 1.03 * best + 0.01)
    return chosen, fits[chosen], scores[chosen], scores


@dataclass
class CalibrationResult:
    device: dict[str, Any]
    materials: list[dict[str, Any]]
    offsets_mm: dict[str, list[float]]
    rms_mm: dict[str, float]  # 'bin' mode, 0.25 mm sweep (the database's averaging)
    rms_interp_mm: dict[str, float]  # 'interp' mode (the fit's objective)
    median_rms_mm: float
    runtime_s: float
    kind_scores: dict[str, dict[str, float]] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)
    # per-capture session states (t_80, t_16, t_120) of section 2.2; {}: fitted without drift
    sessions: dict[str, list[float]] = field(default_factory=dict)


def _table_arrays(table: Any) -> tuple[FloatArray, list[str], tuple[float, float, int]]:
    Y = np.asarray(table.features, float)
    names = list(table.materials)
    b = table.bins
    return Y, names, (float(b.start_mm), float(b.width_mm), int(b.count))


def simulated_curves(
    device: dict[str, Any], materials: Sequence[dict[str, Any]], offsets: dict[str, list[float]],
    bins: tuple[float, float, int], mode: str = "bin", grid: tuple[float, float, float] = REPORT_GRID,
    sessions: Mapping[str, Sequence[float]] | None = None,
) -> FloatArray:  # fmt: skip
    """Every material's curve with its capture's offsets and session state (when given)."""
    sessions = sessions or {}
    return np.stack([
        M.curve(device, m, bins, mode, grid, offsets.get(m["name"], (0.0, 0.0)),
                session=sessions.get(m["name"]))
        for m in materials
    ])  # fmt: skip


def rms_per_material(sim: FloatArray, Y: FloatArray) -> FloatArray:
    out = []
    for s, y in zip(sim, Y, strict=True):
        v = np.isfinite(y)
        r = (s - y)[v]
        r = np.where(np.isfinite(r), r, 50.0)
        out.append(float(np.sqrt(np.mean(r * r))))
    return np.array(out)


def _wants_noise(y: FloatArray, bins: tuple[float, float, int]) -> bool:
    """The 120 MHz wrap inside the averaging: both rows rise together by tens of mm within the
    last ~60 mm of the range (row0 - row1, which does not involve d120, stays smooth)."""
    v = np.isfinite(y[0]) & np.isfinite(y[1])
    centres = bins[0] + bins[1] * (np.arange(bins[2]) + 0.5)
    if v.sum() < 20:
        return False
    far = v & (centres > centres[v].max() - 40.0)
    mid = v & (centres > centres[v].max() - 200.0) & (centres < centres[v].max() - 100.0)
    rise1 = np.mean(y[1][far]) - np.mean(y[1][mid])
    rise0 = np.mean(y[0][far]) - np.mean(y[0][mid])
    diff = np.mean((y[0] - y[1])[far]) - np.mean((y[0] - y[1])[mid])
    return bool(rise1 > 20.0 and rise0 > 20.0 and abs(diff) < 0.5 * rise1)


def calibrate(
    table: Any,
    restarts: int = 3,
    seed: int = 0,
    rounds: int = 2,
    progress: Callable[[str], None] | None = None,
) -> CalibrationResult:
    """Staged fit of device + per-material parameters to ``table`` (a tofmat.ExemplarTable)."""
    t0 = time.time()
    logs: list[str] = []

    def log(msg: str) -> None:
        line = f"[{time.time() - t0:7.1f}s] {msg}"
        logs.append(line)
        (progress or _log)(line)

    Y, names, bins = _table_arrays(table)
    nm = len(names)
    rng = np.random.default_rng(seed)
    allidx = list(range(nm))

    # ---- stage 1: device from the typical median curve ------------------------------------
    log(f"stage 1: device harmonics, {restarts} restarts on the typical median curve")
    dev_st = stage_device(Y, bins, restarts, rng, log)[0]
    st = _default_state(names)
    for k, v in dev_st.items():
        if k[0] in DEV_BOUNDS:
            st[k] = v
    tg = set(translucent_group(Y, typical_median(Y)[0]))
    for i in allidx:
        src = 1 if (i in tg and ("b", 1) in dev_st) else 0
        for p in ("b", "lt", "lr"):
            st[(p, i)] = dev_st[(p, src)]
    log("  translucent group: " + ", ".join(names[i] for i in sorted(tg)))
    prob = Problem(Y, names, bins, grid=FIT_GRID)
    kinds = ["exponential"] * nm
    _init_offsets(prob, st, kinds, allidx)
    if SESSION_DRIFT:  # random session states: with dG = 0 and t = 0 both gradients vanish
        for i in allidx:
            for key in SESSION_KEYS:
                st[(key, i)] = float(rng.normal(0.0, SESSION_PRIOR))
    noisy = {i for i in allidx if _wants_noise(Y[i], bins)}
    log("  materials with the 120 MHz wrap in the averaging: "
        + (", ".join(names[i] for i in sorted(noisy)) or "none"))  # fmt: skip

    kind_scores: dict[str, dict[str, float]] = {}
    # rounds after the first run KIND_CYCLES cycles of (kind selection, joint passes, gauge)
    schedule = [0] + [r for r in range(1, rounds) for _ in range(KIND_CYCLES)]
    for rnd in schedule:
        # ---- stage 2: per-material kinds, device fixed -----------------------------------
        log(f"round {rnd + 1}: stage 2, per-material kind selection (device fixed)")
        for i in allidx:
            name = names[i]
            cand = ["exponential", "gamma", "double"] + (["slab"] if SLAB_ALL or name in THIN_ACRYLICS else [])
            if rnd == 0:
                kind, st_i, rms_i, scores = fit_material(prob, st, kinds, i, cand, i in noisy)
            elif KIND_RESELECT:  # every kind again against the refined device, warm starts
                kind, st_i, rms_i, scores = fit_material(prob, st, kinds, i, cand, i in noisy,
                                                         starts=())  # fmt: skip
            else:  # warm start of the chosen kind only
                kind, st_i, rms_i, scores = fit_material(prob, st, kinds, i, [kinds[i]], i in noisy, starts=())
                scores = {**kind_scores.get(name, {}), kind: rms_i}
            kind_scores[name] = scores
            kinds[i] = kind
            for p in MAT_BOUNDS:
                st[(p, i)] = st_i[(p, i)]
            log(f"  {name:12s} {kind:11s} rms {rms_i:6.3f}  "
                + " ".join(f"{k[:3]}={v:.3f}" for k, v in scores.items()))  # fmt: skip
        # ---- stage 3: joint ----------------------------------------------------------------
        log(f"round {rnd + 1}: stage 3, joint refinement")
        mat_free = {
            i: KIND_PARAMS[kinds[i]] + ("o0", "o1") + (("noise",) if i in noisy else ())
            + (("lr",) if SATURATION else ()) + (SESSION_KEYS if SESSION_DRIFT else ())
            for i in allidx
        }  # fmt: skip
        passes = JOINT_PASSES[min(rnd, len(JOINT_PASSES) - 1)]
        st = joint_refine(prob, st, kinds, allidx, mat_free, passes, JOINT_NFEV, log)
        o0, o1 = regauge(st, allidx)
        log(f"  gauge: moved median offsets ({o0:.2f}, {o1:.2f}) mm into the decode offsets")

    # the decode-offset gauge moves d_120 by a few mm: refit the noise-wrap materials' own terms
    for i in sorted(noisy):
        _, st_i, rms_i, _ = fit_material(prob, st, kinds, i, [kinds[i]], True, starts=())
        for p in MAT_BOUNDS:
            st[(p, i)] = st_i[(p, i)]
        log(f"  {names[i]}: refit after the gauge, rms {rms_i:.3f} mm")

    # ---- report -------------------------------------------------------------------------------
    device = state_to_device(st)
    materials = [state_to_material(st, i, names[i], kinds[i]) for i in allidx]
    offsets = {names[i]: [float(st[("o0", i)]), float(st[("o1", i)])] for i in allidx}
    sessions = ({names[i]: [float(st[(k, i)]) for k in SESSION_KEYS] for i in allidx}
                if SESSION_DRIFT else {})  # fmt: skip
    sim_bin = simulated_curves(device, materials, offsets, bins, "bin", sessions=sessions)
    rms_bin = rms_per_material(sim_bin, Y)
    rms_int = prob.rms(st, kinds, allidx)
    runtime = time.time() - t0
    log(f"done: median rms (bin) {np.median(rms_bin):.3f} mm, max {rms_bin.max():.3f} mm")
    return CalibrationResult(
        device=device,
        materials=materials,
        offsets_mm=offsets,
        sessions=sessions,
        rms_mm={names[i]: float(rms_bin[i]) for i in allidx},
        rms_interp_mm={names[i]: float(rms_int[i]) for i in allidx},
        median_rms_mm=float(np.median(rms_bin)),
        runtime_s=runtime,
        kind_scores=kind_scores,
        log=logs,
        config={
            "restarts": restarts,
            "seed": seed,
            "rounds": rounds,
            "bins": list(bins),
            "h_max": HMAX,
            "group_h_max": list(GROUP_HMAX),
            "ridge": RIDGE,
            "offset_prior_mm": OFFSET_PRIOR_MM,
            "weight": {"exp": WEIGHT_EXP, "floor_mm": WEIGHT_FLOOR_MM, "cap_mm": WEIGHT_CAP_MM},
            "joint_passes": list(JOINT_PASSES),
            "joint_nfev": JOINT_NFEV,
            "kind_cycles": KIND_CYCLES,
            "session_drift": SESSION_DRIFT,
            "session_prior": SESSION_PRIOR,
            "drift_ridge": DRIFT_RIDGE,
        },
    )


# ---------------------------------------------------------------------------------------------
# Outputs
# ---------------------------------------------------------------------------------------------
def write_outputs(result: CalibrationResult, out_dir: str | os.PathLike[str], table: Any = None,
                  db_path: str | None = None,
                  template_device: str | None = None) -> dict[str, str]:  # fmt: skip
    """Device JSON, material library JSON (with a "fit" block per material) and the plot grid."""
    out_dir = os.fspath(out_dir)
    dev_path = os.path.join(out_dir, "data", "devices", "kinect2_tanaka2017.json")
    mat_path = os.path.join(out_dir, "data", "materials", "tanaka2017.json")
    png_path = os.path.join(out_dir, "data", "materials", "tanaka2017_fit.png")
    os.makedirs(os.path.dirname(dev_path), exist_ok=True)
    os.makedirs(os.path.dirname(mat_path), exist_ok=True)
    device = dict(result.device)
    device["version"] = 2
    # blocks of the simulator's profile that this fit does not determine (camera intrinsics, noise,
    # per-pixel phase, signal level): taken from the ideal profile shipped with the package
    from . import data_dir

    tpl_path = template_device or os.fspath(data_dir() / "devices" / "ideal_kinect2.json")
    with open(tpl_path) as fh:  # (missing: an error, never a silently noise-free profile)
        tpl = json.load(fh)
    for k in ("camera", "noise", "pixel_phase", "signal"):
        if k in tpl and k not in device:
            device[k] = tpl[k]
    device["notes"] = (
        "Kinect v2 of the Tanaka et al. 2017 database, fitted by tofmat.sim.calibrate to the 29 "
        "real curves (docs/simulator-model.md with its extensions: harmonics to h = "
        + "/".join(str(h) for h in GROUP_HMAX)
        + ", tap "
        "full-well saturation with full_well in units of the 16 MHz tap signal of an albedo-1 "
        "target at range_ref_mm, signal_scale per group, decode offsets carrying the common row "
        "levels). camera/noise/pixel_phase/signal are not fitted (copied from the ideal profile)."
    )
    device["fit"] = {
        "source": "tofmat.sim.calibrate against shared/data/tanaka2017_kinect2_db (29 materials)",
        "median_rms_mm": result.median_rms_mm,
        "runtime_s": result.runtime_s,
        "gauges": "delta_120 = 0, s_120 = 0, step_gain[0] = 1, step_offset[0] = 0, full_well_16 = 1; "
        "the median per-capture offsets are carried by decode_offset_rad",
        **result.config,
    }
    with open(dev_path, "w") as fh:
        json.dump(device, fh, indent=2)
        fh.write("\n")
    mats = []
    for m in result.materials:
        mm = dict(m)
        mm["fit"] = {
            "rms_mm": result.rms_mm[m["name"]],
            "rms_interp_mm": result.rms_interp_mm[m["name"]],
            "offsets_mm": result.offsets_mm[m["name"]],
            **({"session": result.sessions[m["name"]]} if m["name"] in result.sessions else {}),
            "kind_scores_rms_mm": result.kind_scores.get(m["name"], {}),
            "albedo_note": "seen by the curves only through tap saturation: the relative signal in "
            "units of the 16 MHz taps' full well at range_ref_mm, not an optical albedo",
        }
        mats.append(mm)
    lib = {
        "name": "tanaka2017",
        "version": 2,
        "device": device["name"],
        "notes": "fitted with the device in data/devices/kinect2_tanaka2017.json; offsets_mm are "
        "per-capture nuisance offsets (row0, row1) of the real database, not material properties",
        "materials": mats,
    }
    with open(mat_path, "w") as fh:
        json.dump(lib, fh, indent=2)
        fh.write("\n")
    paths = {"device": dev_path, "materials": mat_path}
    # The simulator must read what the fit wrote (strict keys, ranges): fail here, not later.
    from . import DeviceProfile, MaterialLibrary

    DeviceProfile.load(dev_path, out_dir)
    MaterialLibrary.load(mat_path, out_dir)
    log_path = os.path.join(out_dir, "data", "materials", "tanaka2017_fit_log.txt")
    with open(log_path, "w") as fh:
        fh.write("\n".join(result.log) + "\n")
    paths["log"] = log_path
    if table is None and db_path is not None:
        import tofmat

        table = tofmat.ExemplarTable.from_npy_dir(db_path)
    if table is not None:
        plot_fit(result, table, png_path)
        paths["plot"] = png_path
    return paths


def plot_fit(result: CalibrationResult, table: Any, path: str) -> None:
    require_pyplot(extra="sim", feature=FEATURE)
    import matplotlib.pyplot as plt

    Y, names, bins = _table_arrays(table)
    centres = bins[0] + bins[1] * (np.arange(bins[2]) + 0.5)
    mats = {m["name"]: m for m in result.materials}
    sim = simulated_curves(result.device, [mats[n] for n in names], result.offsets_mm, bins, "bin",
                           sessions=result.sessions)  # fmt: skip
    ncol = 5
    nrow = math.ceil(len(names) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.0 * ncol, 3.0 * nrow), sharex=True)
    for k, name in enumerate(names):
        ax = axes.flat[k]
        for row, (c_real, c_sim) in enumerate((("tab:blue", "navy"), ("tab:orange", "darkred"))):
            ax.plot(centres, Y[k, row], ".", ms=2, color=c_real, label=f"real row{row}")
            ax.plot(centres, sim[k, row], "-", lw=0.9, color=c_sim, label=f"sim row{row}")
        m = mats[name]
        ax.set_title(f"{name} ({m['kind']}) rms {result.rms_mm[name]:.2f} mm", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for k in range(len(names), nrow * ncol):
        axes.flat[k].axis("off")
    axes.flat[0].legend(fontsize=6)
    fig.suptitle(f"real (dots) vs simulated (lines), rows d16-d120 and d80-d120 [mm]; "
                 f"median rms {result.median_rms_mm:.2f} mm")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--db", default="/work/shared/data/tanaka2017_kinect2_db")
    ap.add_argument("--out", default=".")
    ap.add_argument("--restarts", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=2)
    a = ap.parse_args(argv)
    import tofmat

    try:  # the fit (scipy) and its figure (matplotlib): fail before the long run, in one line
        require("scipy.optimize", extra="sim", feature="python -m tofmat.sim.calibrate")
        require_pyplot(extra="sim", feature="python -m tofmat.sim.calibrate")
    except tofmat.MissingExtraError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    table = tofmat.ExemplarTable.from_npy_dir(a.db)
    res = calibrate(table, restarts=a.restarts, seed=a.seed, rounds=a.rounds)
    paths = write_outputs(res, a.out, table)
    for k, v in paths.items():
        print(f"wrote {k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
