# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Fit the forward model (docs/simulator-model.md, model_np.py) to the real Kinect v2 database.

Shared device parameters (per-frequency harmonics up to ``CalibrationConfig.group_hmax``, tap
saturation, step gains and offsets, scale errors; sections 2.1 and 3.1 of the spec) and
per-material response parameters are fitted so that the simulated relative distortions (rows
d16 - d120 and d80 - d120 against the combined depth) match the database's curves, with one
nuisance offset per material and row and one session state per material and group (each material
was captured in its own session; the state moves the waveform's harmonics along a fitted drift
direction, spec section 2.2; ``session_drift=False`` fits the offsets only).

Every setting of a run is a field of ``CalibrationConfig`` (defaults: the shipped fit's), passed
to ``calibrate(table, config=..., progress=...)`` and recorded in the result and in the written
device profile. The command line is ``tofmat sim calibrate``.

Staged fit (scipy.optimize.least_squares, finite differences with a block-sparse Jacobian):

1. device: ``restarts`` random restarts of the low harmonics (``harmonics_low``, fitted in
   Cartesian form ``a e^{i psi}``, with a small ridge that picks the least-amplitude solution
   among near-degenerate harmonic pairs) on two pseudo-curves, the median of the typical
   (near-opaque) materials and the median of the translucent group; the best restart goes on to
   all harmonics (``group_hmax``) with the tap saturation;
2. per material, device fixed: kind selection among exponential / gamma / double / slab (a
   nominal 1 mm layer with a fitted path factor unless the thickness is known), several starting
   points each; the per-sample noise of section 4.1 for curves that show the 120 MHz wrap
   inside the averaging (fakeleather);
3. joint refinement of the device (harmonics, session drift direction, saturation sharpness,
   full wells W_80 and W_120, step gains, step offsets, scale errors), all materials and their
   session states (started at random, N(0, session_prior)), in passes that reweight each
   material by 1 / rms^weight_exp (rms clipped to [weight_floor_mm, weight_cap_mm]) so that the
   fit aims at the median of the per-material rms rather than at the worst curves; the pass with
   the lowest median is kept;
4. gauge: the median per-capture offsets are moved into the device's decode offsets and the
   median session state into the harmonics (``regauge``, exact); then, for every round after the
   first, ``kind_cycles`` times (2) (every kind again, warm starts), (3) and (4), and a report in
   ``bin`` mode (the database's averaging, 0.25 mm sweep).

``tofmat sim calibrate --db shared/data/tanaka2017_kinect2_db --out <dir>`` writes
``<dir>/data/devices/kinect2_tanaka2017.json``, ``<dir>/data/materials/tanaka2017.json``,
``<dir>/data/materials/tanaka2017_fit_log.txt`` and ``<dir>/data/materials/tanaka2017_fit.png``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeAlias, TypedDict, cast

import numpy as np

from .._extras import require, require_pyplot
from .._progress import Progress
from . import model_np as M
from .model_np import ComplexArray, FloatArray

# What needs the ``sim`` extra here: the fit (scipy, imported where it is used) and its figure (matplotlib).
FEATURE = "the simulator's calibration (tofmat.sim.calibrate)"

_LOG = logging.getLogger(__name__)

# A state key: the parameter's name, then its indices (group, harmonic / step, or material).
StateKey: TypeAlias = tuple[str, *tuple[int, ...]]
State: TypeAlias = dict[StateKey, float]

# ---------------------------------------------------------------------------------------------
# Constants of the model and of the database (not settings of a run)
# ---------------------------------------------------------------------------------------------
THIN_ACRYLICS = {"acryl1mm": 1.0, "acryl2mm": 2.0, "acryl3mm": 3.0}  # the database's known thicknesses
ACRYLIC_N = 1.49
HMAX = 32  # highest harmonic of the device model (spec section 2.1; the C++ simulator's limit)
GROUPS = (80, 16, 120)
# fitted harmonics: h = 3k cancel with ideal step gains; each group up to its CalibrationConfig.group_hmax
HARMONICS_FIT = tuple(h for h in range(2, HMAX + 1) if h % 3)
# Sweep of the database's own averaging (the 'bin' mode of the curves): 0.25 mm steps
DATABASE_GRID = (450.0, 1400.0, 0.25)
SESSION_KEYS = ("t0", "t1", "t2")  # t_80, t_16, t_120 of a capture

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


# ---------------------------------------------------------------------------------------------
# Configuration of a run
# ---------------------------------------------------------------------------------------------
Grid: TypeAlias = tuple[float, float, float]  # sweep start, stop and step (mm)


@dataclass(frozen=True)
class CalibrationConfig:
    """Every setting of a calibration run; the defaults are the shipped fit's (docs/simulator.md).

    ``calibrate`` takes one, the result carries it (``CalibrationResult.config``) and
    ``write_outputs`` records it in the device profile's ``fit`` block (``to_dict``).
    """

    restarts: int = 3
    """Stage 1: random restarts of the low harmonics' fit (multimodal in their phases)."""
    rounds: int = 2
    """Rounds of per-material kind selection and joint refinement (round 1, then ``kind_cycles`` cycles per further round)."""
    seed: int = 0
    """Seed of the random restarts and of the session states' random start."""
    # The 16 MHz correlation waveform has the sharpest features (its fitted amplitudes still grow
    # at h = 25, and acryl / silicone / whiteglass show 300-400 mm bumps = 9375 / 3k mm, k ~ 8-10).
    group_hmax: tuple[int, int, int] = (19, 32, 19)
    """Highest fitted harmonic per group (80, 16, 120 MHz); above it a group's harmonics stay 0 (at most HMAX = 32)."""
    harmonics_low: tuple[int, ...] = (2, 4, 5, 7)
    """Stage 1: the low harmonics fitted from random starts before all harmonics are freed."""
    saturation: bool = True
    """Tap full-well saturation (spec section 3.1) with fitted full wells and albedos; False: the linear model."""
    session_drift: bool = True
    """A drift direction of the waveform per group and a session state per capture and group (spec 2.2); False: offsets only."""
    session_prior: float = 1.0
    """Standard deviation of the session states' prior N(0, s^2) and of their random start."""
    drift_ridge: float = 10.0
    """Ridge on the drift direction's coordinates, times sqrt(number of curves)."""
    ridge: float = 10.0
    """Ridge on the harmonics' Cartesian coordinates, times sqrt(number of curves)."""
    offset_prior_mm: float = 10.0
    """Standard deviation (mm) of the prior on the per-capture row offsets: levels must come from the model."""
    # The rows are smooth on the 3 mm bins: a 3 mm sweep changes the per-material rms by < 0.001 mm
    # against 1.5 mm, and the saturation dominates the cost of an evaluation.
    fit_grid: Grid = (450.0, 1400.0, 3.0)
    """Range sweep (start, stop, step mm) of the per-material and joint fits ('interp' mode)."""
    device_grid: Grid = (450.0, 1400.0, 3.0)
    """Range sweep of the stage-1 device fit on the two median curves."""
    report_grid: Grid = DATABASE_GRID
    """Range sweep of the reported rms and the figure ('bin' mode: the database's averaging)."""
    device_nfev: tuple[int, int] = (80, 150)
    """Stage 1: function evaluations of each low-harmonic restart and of the best restart on all harmonics."""
    material_nfev: int = 40
    """Stage 2: function evaluations per material, kind and starting point."""
    slab_all: bool = True
    """Every material may be a slab (a nominal-thickness layer with a fitted path factor); False: only known thicknesses."""
    slab_nominal_mm: float = 1.0
    """Thickness (mm) of a slab whose thickness is not known (its path factor sets the round trip)."""
    joint_step_gains: bool = True
    """Joint stage: free step gains g_1, g_2 per group (g_0 = 1 is a gauge)."""
    joint_step_offsets: bool = True
    """Joint stage: free step offsets o_1, o_2 per group (o_0 = 0 is a gauge)."""
    joint_scale_errors: bool = True
    """Joint stage: free scale errors s_80, s_16 (s_120 = 0 is a gauge)."""
    joint_full_wells: bool = True
    """Joint stage: free full wells W_80, W_120 (W_16 = 1 is the albedo's unit; with ``saturation`` only)."""
    joint_drift: bool = True
    """Joint stage: free drift direction of the waveform (with ``session_drift`` only)."""
    # The joint fit is far from converged after one pass; it plateaus after a few passes, and a new
    # kind choice (the next cycle) moves it on.
    joint_passes: tuple[int, ...] = (2, 5)
    """Joint passes per round (round k uses entry min(k, last)); the pass with the lowest median rms is kept."""
    joint_nfev: int = 30
    """Function evaluations per joint pass (then the materials are reweighted)."""
    # 1/sqrt(rms) (~ the sum of the rms) let the few curves a kernel cannot represent (fakeleather's
    # noise, copper) steer the shared device; a steeper weight aims at the median. The floor stops
    # curves already at the bin noise (~0.4 mm) from taking over, the cap keeps the worst in play.
    weight_exp: float = 1.5
    """Joint stage: material weight 1 / clip(rms, floor, cap)^weight_exp (aims at the median rms)."""
    weight_floor_mm: float = 0.45
    """Floor of the weights' rms (mm): curves at the bin noise do not take over."""
    weight_cap_mm: float = 1.5
    """Cap of the weights' rms (mm): the worst curves stay in play."""
    kind_reselect: bool = True
    """Rounds after the first choose every material's kind again (warm starts); False: refit the chosen kind."""
    kind_cycles: int = 2
    """Cycles of (kind selection, joint passes, gauge) per round after the first."""

    def __post_init__(self) -> None:
        def bad(msg: str) -> ValueError:
            return ValueError(f"CalibrationConfig: {msg}")

        for name in ("restarts", "rounds", "material_nfev", "joint_nfev", "kind_cycles"):
            if int(getattr(self, name)) < 1:
                raise bad(f"{name} must be >= 1")
        if self.seed < 0:
            raise bad("seed must be >= 0")
        if len(self.group_hmax) != 3 or not all(2 <= h <= HMAX for h in self.group_hmax):
            raise bad(f"group_hmax must be three harmonics in 2..{HMAX}")
        if not self.harmonics_low or not all(2 <= h <= HMAX for h in self.harmonics_low):
            raise bad(f"harmonics_low must be harmonics in 2..{HMAX}")
        if len(self.device_nfev) != 2 or min(self.device_nfev) < 1:
            raise bad("device_nfev must be two counts >= 1")
        if not self.joint_passes or min(self.joint_passes) < 0:
            raise bad("joint_passes must be counts >= 0")
        for name in ("fit_grid", "device_grid", "report_grid"):
            g = getattr(self, name)
            if len(g) != 3 or not (g[0] < g[1] and g[2] > 0):
                raise bad(f"{name} must be (start, stop, step) with start < stop and step > 0")
        for name in ("session_prior", "drift_ridge", "offset_prior_mm", "slab_nominal_mm", "weight_floor_mm"):
            if not float(getattr(self, name)) > 0.0:
                raise bad(f"{name} must be > 0")
        if self.ridge < 0.0 or self.weight_exp < 0.0 or self.weight_cap_mm < self.weight_floor_mm:
            raise bad("ridge and weight_exp must be >= 0 and weight_cap_mm >= weight_floor_mm")

    def to_dict(self) -> dict[str, Any]:
        """The fields as JSON values (tuples as lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}


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


def state_to_device(st: State, config: CalibrationConfig, name: str = "kinect2_tanaka2017") -> dict[str, Any]:
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
            "full_well": float(10.0 ** st[("lw", g)]) if config.saturation else None,
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


def _device_arrays(st: State, config: CalibrationConfig) -> _DeviceArrays:
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
        "full_well": np.array([10.0 ** st[("lw", g)] if config.saturation else np.inf for g in range(3)]),
        "sat_p": st[("satp",)],
    }


def state_to_material(st: State, i: int, name: str, kind: str, config: CalibrationConfig) -> dict[str, Any]:
    thick = THIN_ACRYLICS.get(name, config.slab_nominal_mm if kind == "slab" else 0.0)
    n = ACRYLIC_N if name.startswith("acryl") else 1.5
    mat: dict[str, Any] = {
        "name": name, "kind": kind, "albedo": float(10.0 ** st[("lr", i)]) if config.saturation else 1.0, "subsurface": 0.0, "tau_ps": 100.0,
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
def regauge(st: State, idx: Sequence[int], config: CalibrationConfig) -> tuple[float, float]:
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
    if config.session_drift:  # the nominal waveform is the median session's: G_h += t_med dG_h (exact)
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
    """Vectorised residuals of a set of curves against the model (interp mode), under ``config``
    (its model switches, priors and ridges); the sweep is ``grid`` (default: ``config.fit_grid``)."""

    def __init__(
        self,
        Y: FloatArray,
        names: Sequence[str],
        bins: tuple[float, float, int],
        config: CalibrationConfig,
        grid: Grid | None = None,
    ) -> None:
        self.config = config
        self.Y = np.asarray(Y, float)  # (M, 2, B), NaN missing
        self.names = list(names)
        self.bins = bins
        self.centres = bins[0] + bins[1] * (np.arange(bins[2]) + 0.5)
        self.D = M.sweep_grid(*(config.fit_grid if grid is None else grid))
        self.A = (M.RANGE_REF_MM / self.D) ** 2
        self.valid = np.isfinite(self.Y)
        self.ridge = config.ridge
        self.weights = np.ones(len(self.Y))

    # -- forward ---------------------------------------------------------------------------
    def curves(self, st: State, kinds: Sequence[str], idx: Sequence[int]) -> FloatArray:
        cfg = self.config
        dev = _device_arrays(st, cfg)
        Rh = np.stack([
            M.material_harmonic_responses(state_to_material(st, i, self.names[i], kinds[i], cfg), dev)
            for i in idx
        ])  # fmt: skip
        G: ComplexArray = dev["G"]
        if cfg.session_drift:  # every capture in its own session (section 2.2): G per material
            t = np.array([[st[(k, i)] for k in SESSION_KEYS] for i in idx])
            G = G[None] + t[:, :, None] * dev["dG"][None]
        if cfg.saturation:
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
            pen += [st[("o0", i)] / self.config.offset_prior_mm, st[("o1", i)] / self.config.offset_prior_mm]
        for k in self.harm_pairs:
            hx, hy = st[k], st[("hy", *k[1:])]
            pen += [self.ridge_w * hx, self.ridge_w * hy,
                    100.0 * max(0.0, math.hypot(hx, hy) - 0.5)]  # fmt: skip
        drift_w = self.config.drift_ridge * math.sqrt(len(self.idx))
        prior = self.config.session_prior
        pen += [st[k] / prior if k[0] in SESSION_KEYS else drift_w * st[k] for k in self.pen_keys]
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


def _dev_keys(config: CalibrationConfig, harm: Sequence[int] = HARMONICS_FIT, delta: bool = False,
              scale: bool = False, gain: bool = False, off: bool = False, sat: bool | None = None,
              full_well: bool = False, drift: bool = False) -> list[StateKey]:  # fmt: skip
    """Free device parameters (harmonics up to ``config.group_hmax``; the saturation sharpness
    with ``sat``, default ``config.saturation``). Gauges: delta_120 = 0 (a common range shift is
    unobservable), s_120 = 0, g_0 = 1, o_0 = 0 (the common mode of o_j cancels in the decode).
    With free per-capture offsets and free harmonic phases, the deltas are pure gauge too (see
    regauge)."""
    hmax = config.group_hmax
    keys: list[StateKey] = []
    for g in range(3):
        for h in harm:
            if h <= hmax[g]:
                keys += [("hx", g, h), ("hy", g, h)]
        if delta and GROUPS[g] != 120:
            keys.append(("delta", g))
        if scale and GROUPS[g] != 120:
            keys.append(("s", g))
        if gain:
            keys += [("gain", g, 1), ("gain", g, 2)]
        if off:
            keys += [("off", g, 1), ("off", g, 2)]
        if full_well and config.saturation and GROUPS[g] != 16:  # gauge: W_16 = 1 (the albedo's unit)
            keys.append(("lw", g))
        if drift and config.session_drift:
            for h in harm:
                if h <= hmax[g]:
                    keys += [("dx", g, h), ("dy", g, h)]
    if config.saturation if sat is None else sat:
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
    Y: FloatArray, bins: tuple[float, float, int], config: CalibrationConfig, rng: np.random.Generator,
    log: Callable[[str], None], keep: int = 1, step: Callable[[str], None] | None = None,
) -> list[State]:  # fmt: skip
    """Device harmonics from two pseudo-materials: the median curve of the typical (near-opaque)
    materials and the median curve of the translucent group (started with a ~1.5 ns
    subsurface response). The second curve separates the harmonics h = 3k - 1 and 3k + 1,
    which the opaque curves alone constrain only through their difference. ``config.restarts``
    random starts of ``config.harmonics_low``, the best ``keep`` go on to all harmonics;
    ``step`` is told after each of these fits."""
    ym, _ = typical_median(Y)
    tg = translucent_group(Y, ym)
    curves_ = [ym] + ([np.nanmedian(Y[tg], axis=0)] if len(tg) >= 2 else [])
    names = ["typical", "translucent"][: len(curves_)]
    prob = Problem(np.stack(curves_), names, bins, config, grid=config.device_grid)
    kinds = ["exponential"] * len(names)
    idx = list(range(len(names)))
    nfev_low, nfev_all = config.device_nfev
    h_low = max(config.harmonics_low)
    low = []
    for r in range(config.restarts):
        st = _default_state(names)
        for g in range(3):
            for h in config.harmonics_low:
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
        prob.setup(st, kinds, idx, _dev_keys(config, config.harmonics_low, sat=False), free)
        res = prob.solve(max_nfev=nfev_low)
        rms = prob.rms(prob.st, kinds, idx)
        log(
            f"  restart {r:2d} (h <= {h_low}): rms "
            + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, rms, strict=True))
            + f" mm (cost {res.cost:.1f})"
        )
        low.append((float(res.cost), prob.st))
        if step:
            step(f"device restart {r + 1}/{config.restarts}")
    # the multimodal part is the low harmonics' phases: only the best restarts go on to all
    # harmonics with the tap saturation (the expensive fit)
    low.sort(key=lambda t: t[0])
    out = []
    for r, (_, st) in enumerate(low[:keep]):
        free = {i: ("b", "lt", "o0", "o1") + (("lr",) if config.saturation else ()) for i in idx}
        prob.setup(st, kinds, idx, _dev_keys(config), free)
        res = prob.solve(max_nfev=nfev_all)
        rms = prob.rms(prob.st, kinds, idx)
        log(
            f"  best {r + 1}, all harmonics: rms "
            + ", ".join(f"{n} {v:.3f}" for n, v in zip(names, rms, strict=True))
            + f" mm (cost {res.cost:.1f})"
        )
        out.append((float(res.cost), prob.st))
        if step:
            step("device, all harmonics")
    out.sort(key=lambda t: t[0])
    return [s for _, s in out]


def joint_refine(
    prob: Problem, st: State, kinds: Sequence[str], idx: Sequence[int],
    mat_free: Mapping[int, Sequence[str]], passes: int, log: Callable[[str], None],
    step: Callable[[str], None] | None = None,
) -> State:  # fmt: skip
    """Stage 3: device and materials together, ``passes`` passes of ``prob.config.joint_nfev``
    evaluations, iteratively reweighted (``weight_exp``); returns the pass with the lowest median
    per-material rms (the weighted cost and the median need not fall together). ``step`` is told
    after each pass."""
    cfg = prob.config
    dev_free = _dev_keys(cfg, HARMONICS_FIT, gain=cfg.joint_step_gains, off=cfg.joint_step_offsets,
                         scale=cfg.joint_scale_errors, full_well=cfg.joint_full_wells, drift=cfg.joint_drift)  # fmt: skip
    rms = prob.rms(st, kinds, idx)
    best = (float(np.median(rms)), dict(st))
    for k in range(passes):
        prob.weights = np.ones(len(prob.Y))
        prob.weights[list(idx)] = 1.0 / np.clip(rms, cfg.weight_floor_mm, cfg.weight_cap_mm) ** cfg.weight_exp
        prob.setup(st, kinds, idx, dev_free, mat_free)
        res = prob.solve(max_nfev=cfg.joint_nfev)
        st = prob.st
        prob.weights = np.ones(len(prob.Y))
        rms = prob.rms(st, kinds, idx)
        med = float(np.median(rms))
        log(f"  joint pass {k + 1}/{passes}: cost {res.cost:.1f}, median rms {med:.3f} mm, "
            f"max {rms.max():.3f} mm ({res.nfev} evaluations)")  # fmt: skip
        if med < best[0]:
            best = (med, dict(st))
        if step:
            step(f"joint pass {k + 1}/{passes}")
    return best[1]


def fit_material(
    prob: Problem, st: State, kinds: list[str], i: int, candidates: Sequence[str],
    with_noise: bool,
    starts: Sequence[tuple[float, float, float]] = (
        (1.0, 0.3, -1.0), (2.0, 0.6, -0.4), (3.2, 0.4, -0.2)),
) -> tuple[str, State, float, dict[str, float]]:  # fmt: skip
    """Device fixed: the best kind and parameters of material i (several starting points, each
    ``prob.config.material_nfev`` evaluations)."""
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
                    + (("lr",) if prob.config.saturation else ()))  # fmt: skip
            prob.setup(s, ks, [i], [], {i: free})
            prob.solve(max_nfev=prob.config.material_nfev)
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
    """What ``calibrate`` fitted, with the configuration it ran under."""

    device: dict[str, Any]
    materials: list[dict[str, Any]]
    offsets_mm: dict[str, list[float]]
    rms_mm: dict[str, float]  # 'bin' mode on config.report_grid (the database's averaging)
    rms_interp_mm: dict[str, float]  # 'interp' mode (the fit's objective)
    median_rms_mm: float
    runtime_s: float
    config: CalibrationConfig  # the run's settings (recorded in the written device profile)
    kind_scores: dict[str, dict[str, float]] = field(default_factory=dict)
    log: list[str] = field(default_factory=list)
    # per-capture session states (t_80, t_16, t_120) of section 2.2; {}: fitted without drift
    sessions: dict[str, list[float]] = field(default_factory=dict)
    bins: tuple[float, float, int] | None = None  # the database's bins (start mm, width mm, count)


def _table_arrays(table: Any) -> tuple[FloatArray, list[str], tuple[float, float, int]]:
    Y = np.asarray(table.features, float)
    names = list(table.materials)
    b = table.bins
    return Y, names, (float(b.start_mm), float(b.width_mm), int(b.count))


def simulated_curves(
    device: dict[str, Any], materials: Sequence[dict[str, Any]], offsets: dict[str, list[float]],
    bins: tuple[float, float, int], mode: str = "bin", grid: Grid = DATABASE_GRID,
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


def calibration_steps(config: CalibrationConfig, n_materials: int, n_noisy: int = 0) -> int:
    """The steps ``calibrate`` reports to its progress callback: the stage-1 restarts and the
    best one's fit on all harmonics, every material's kind selection and every joint pass of each
    cycle, the refit of the ``n_noisy`` noise-wrap materials, and the report."""
    schedule = [0] + [r for r in range(1, config.rounds) for _ in range(config.kind_cycles)]
    passes = sum(config.joint_passes[min(r, len(config.joint_passes) - 1)] for r in schedule)
    return config.restarts + 1 + len(schedule) * n_materials + passes + n_noisy + 1


def calibrate(
    table: Any,
    *,
    config: CalibrationConfig | None = None,
    progress: Progress | None = None,
) -> CalibrationResult:
    """Staged fit of device + per-material parameters to ``table`` (a tofmat.ExemplarTable, or
    anything with its ``features``, ``materials`` and ``bins``) under ``config`` (default:
    ``CalibrationConfig()``, the shipped fit's settings).

    ``progress(done, total, what)`` is told after every step (``calibration_steps``); the log
    lines go to the result's ``log`` and to the ``tofmat.sim.calibrate`` logger at INFO."""
    config = CalibrationConfig() if config is None else config
    t0 = time.time()
    logs: list[str] = []

    def log(msg: str) -> None:
        line = f"[{time.time() - t0:7.1f}s] {msg}"
        logs.append(line)
        _LOG.info("%s", line)

    Y, names, bins = _table_arrays(table)
    nm = len(names)
    rng = np.random.default_rng(config.seed)
    allidx = list(range(nm))
    noisy = {i for i in allidx if _wants_noise(Y[i], bins)}
    done = 0
    total = calibration_steps(config, nm, len(noisy))

    def step(what: str) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, what)

    log("config: " + json.dumps(config.to_dict()))
    # ---- stage 1: device from the typical median curve ------------------------------------
    log(f"stage 1: device harmonics, {config.restarts} restarts on the typical median curve")
    dev_st = stage_device(Y, bins, config, rng, log, step=step)[0]
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
    prob = Problem(Y, names, bins, config)
    kinds = ["exponential"] * nm
    _init_offsets(prob, st, kinds, allidx)
    if config.session_drift:  # random session states: with dG = 0 and t = 0 both gradients vanish
        for i in allidx:
            for key in SESSION_KEYS:
                st[(key, i)] = float(rng.normal(0.0, config.session_prior))
    log("  materials with the 120 MHz wrap in the averaging: "
        + (", ".join(names[i] for i in sorted(noisy)) or "none"))  # fmt: skip

    kind_scores: dict[str, dict[str, float]] = {}
    # rounds after the first run kind_cycles cycles of (kind selection, joint passes, gauge)
    schedule = [0] + [r for r in range(1, config.rounds) for _ in range(config.kind_cycles)]
    for rnd in schedule:
        # ---- stage 2: per-material kinds, device fixed -----------------------------------
        log(f"round {rnd + 1}: stage 2, per-material kind selection (device fixed)")
        for i in allidx:
            name = names[i]
            cand = ["exponential", "gamma", "double"] + (
                ["slab"] if config.slab_all or name in THIN_ACRYLICS else [])  # fmt: skip
            if rnd == 0:
                kind, st_i, rms_i, scores = fit_material(prob, st, kinds, i, cand, i in noisy)
            elif config.kind_reselect:  # every kind again against the refined device, warm starts
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
            step(f"round {rnd + 1}: {name}")
        # ---- stage 3: joint ----------------------------------------------------------------
        log(f"round {rnd + 1}: stage 3, joint refinement")
        mat_free = {
            i: KIND_PARAMS[kinds[i]] + ("o0", "o1") + (("noise",) if i in noisy else ())
            + (("lr",) if config.saturation else ()) + (SESSION_KEYS if config.session_drift else ())
            for i in allidx
        }  # fmt: skip
        passes = config.joint_passes[min(rnd, len(config.joint_passes) - 1)]
        st = joint_refine(prob, st, kinds, allidx, mat_free, passes, log, step=step)
        o0, o1 = regauge(st, allidx, config)
        log(f"  gauge: moved median offsets ({o0:.2f}, {o1:.2f}) mm into the decode offsets")

    # the decode-offset gauge moves d_120 by a few mm: refit the noise-wrap materials' own terms
    for i in sorted(noisy):
        _, st_i, rms_i, _ = fit_material(prob, st, kinds, i, [kinds[i]], True, starts=())
        for p in MAT_BOUNDS:
            st[(p, i)] = st_i[(p, i)]
        log(f"  {names[i]}: refit after the gauge, rms {rms_i:.3f} mm")
        step(f"refit {names[i]}")

    # ---- report -------------------------------------------------------------------------------
    device = state_to_device(st, config)
    materials = [state_to_material(st, i, names[i], kinds[i], config) for i in allidx]
    offsets = {names[i]: [float(st[("o0", i)]), float(st[("o1", i)])] for i in allidx}
    sessions = ({names[i]: [float(st[(k, i)]) for k in SESSION_KEYS] for i in allidx}
                if config.session_drift else {})  # fmt: skip
    sim_bin = simulated_curves(device, materials, offsets, bins, "bin", config.report_grid, sessions=sessions)
    rms_bin = rms_per_material(sim_bin, Y)
    rms_int = prob.rms(st, kinds, allidx)
    runtime = time.time() - t0
    log(f"done: median rms (bin) {np.median(rms_bin):.3f} mm, max {rms_bin.max():.3f} mm")
    step("report")
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
        config=config,
        bins=bins,
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
        f"Kinect v2 of the Tanaka et al. 2017 database, fitted by tofmat.sim.calibrate to the {len(result.materials)} "
        "real curves (docs/simulator-model.md with its extensions: harmonics to h = "
        + "/".join(str(h) for h in result.config.group_hmax)
        + ", tap "
        "full-well saturation with full_well in units of the 16 MHz tap signal of an albedo-1 "
        "target at range_ref_mm, signal_scale per group, decode offsets carrying the common row "
        "levels). camera/noise/pixel_phase/signal are not fitted (copied from the ideal profile)."
    )
    device["fit"] = {
        "source": f"tofmat.sim.calibrate against shared/data/tanaka2017_kinect2_db ({len(result.materials)} materials)",
        "median_rms_mm": result.median_rms_mm,
        "runtime_s": result.runtime_s,
        "gauges": "delta_120 = 0, s_120 = 0, step_gain[0] = 1, step_offset[0] = 0, full_well_16 = 1; "
        "the median per-capture offsets are carried by decode_offset_rad",
        **({"bins": list(result.bins)} if result.bins is not None else {}),
        "h_max": HMAX,
        "config": result.config.to_dict(),  # every setting of the run (tofmat.sim.calibrate.CalibrationConfig)
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
                           result.config.report_grid, sessions=result.sessions)  # fmt: skip
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
