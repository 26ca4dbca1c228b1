# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Diagnostics behind the session drift (docs/simulator.md, "Each capture's nuisance terms").

With the device fixed at a fit (by default the offsets-only fit of 2026-11-23, git ee163b5), every
material is refitted with a different response family and its per-capture offsets:

  diffusion  K = exp(-beta (sqrt(1 + i w tau) - 1)): a semi-infinite scattering medium (physical)
  mixture    a non-negative mixture of exponentials on a fixed grid of time constants (physical:
             any completely monotone response), started from the fitted kernel (NNLS)
  free       log K piecewise linear in log frequency, complex, --knots knots from 11 MHz to
             2.5 GHz (NOT physical: |K| may exceed 1 and oscillate): an upper bound on what any
             material response could do with this device

    git show ee163b5:firmware/sim/data/devices/kinect2_tanaka2017.json > /tmp/dev.json
    git show ee163b5:firmware/sim/data/materials/tanaka2017.json > /tmp/lib.json
    OMP_NUM_THREADS=1 python3 tests/bench/sim_response_diagnostics.py free --knots 16 \
        --device /tmp/dev.json --library /tmp/lib.json      # median 0.693 -> 0.418 mm

Prints each material's rms (interp mode, the fit's objective) with its fitted kind and with the
family, and the medians. Runs 1-3 min on one core.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import warnings
from typing import Any

import numpy as np
from scipy.optimize import nnls  # type: ignore[import-untyped]

import tofmat
from tofmat.sim import calibrate as cal
from tofmat.sim import model_np as M

FAMILY_PARAMS: dict[str, tuple[str, ...]] = {}
_response = M.response
_state_to_material = cal.state_to_material


def install(family: str, knots: int) -> None:
    """Teach model_np and calibrate the family as a material kind (this process only)."""
    grid_lf = np.linspace(-1.95, 0.4, knots)  # log10 GHz
    taus_ns = np.logspace(np.log10(5.0), np.log10(10000.0), 10) * 1e-3

    def response(material: Any, omega: Any, alpha: Any = 0.0) -> Any:
        kind = material.get("kind")
        if kind not in ("diffusion", "mixture", "free"):
            return _response(material, omega, alpha)
        omega = np.asarray(omega, float)
        rho = float(material["albedo"])
        if kind == "diffusion":
            b = float(M.fresnel_b_eff(float(material["subsurface"]), 1.5, alpha))
            tau = float(material["tau_ps"]) * 1e-3
            k = np.exp(-material["beta"] * (np.sqrt(1.0 + 1j * omega * tau) - 1.0))
            return rho * ((1.0 - b) + b * k)
        if kind == "mixture":
            w = np.asarray(material["w"], float)
            k = np.ones_like(omega, dtype=complex)
            for wk, tk in zip(w, taus_ns, strict=True):
                k = k + wk / (1.0 + 1j * omega * tk)
            return rho * k / (1.0 + w.sum())
        lg = np.log10(np.maximum(np.abs(omega) / (2 * math.pi), 1e-9))
        k = np.exp(np.interp(lg, grid_lf, material["kr"]) + 1j * np.interp(lg, grid_lf, material["ki"]))
        return rho * np.where(omega != 0, k, 1.0)

    def state_to_material(st: cal.State, i: int, name: str, kind: str, config: cal.CalibrationConfig) -> dict[str, Any]:
        if kind not in ("diffusion", "mixture", "free"):
            return _state_to_material(st, i, name, kind, config)
        mat = _state_to_material(st, i, name, "exponential", config)
        mat["kind"] = kind
        if kind == "diffusion":
            mat["beta"] = 10.0 ** st[("ld", i)]
        elif kind == "mixture":
            mat["w"] = [10.0 ** st[(f"mw{k}", i)] for k in range(len(taus_ns))]
        else:
            mat["kr"] = [st[(f"kr{k}", i)] for k in range(knots)]
            mat["ki"] = [st[(f"ki{k}", i)] for k in range(knots)]
        return mat

    M.response = response
    cal.state_to_material = state_to_material
    cal.MAT_BOUNDS["lt"] = (-1.0, 5.0)
    cal.MAT_BOUNDS["ld"] = (-3.0, 1.5)
    FAMILY_PARAMS["diffusion"] = ("b", "lt", "ld")
    for k in range(len(taus_ns)):
        cal.MAT_BOUNDS[f"mw{k}"] = (-4.0, 3.0)
    FAMILY_PARAMS["mixture"] = tuple(f"mw{k}" for k in range(len(taus_ns)))
    for k in range(knots):
        cal.MAT_BOUNDS[f"kr{k}"] = (-12.0, 3.0)
        cal.MAT_BOUNDS[f"ki{k}"] = (-12.0, 3.0)
    FAMILY_PARAMS["free"] = tuple(f"kr{k}" for k in range(knots)) + tuple(f"ki{k}" for k in range(knots))

    def starts(st: cal.State, i: int, mat: dict[str, Any]) -> list[cal.State]:
        """Starting points of the family for material i (from its fitted kernel)."""
        out = []
        if family == "diffusion":
            lt0, b0 = st[("lt", i)], st[("b", i)]
            for lt, ld, b in [(lt0 + 0.3, 0.0, b0), (lt0 + 1.0, -0.7, b0), (lt0 + 2.0, -1.5, b0),
                              (lt0, 0.5, b0), (lt0 + 1.0, -0.7, 0.9)]:  # fmt: skip
                s = dict(st)
                s[("lt", i)], s[("ld", i)], s[("b", i)] = min(lt, 4.9), ld, b
                out.append(s)
        elif family == "mixture":
            nus = np.concatenate([f * 1e-3 * np.arange(1, 20) for f in (80.0, 16.0, 120.0)])
            om = 2 * math.pi * nus
            kf = _response(mat, om) / mat["albedo"]
            a = np.stack([1.0 / (1.0 + 1j * om * t) - kf for t in taus_ns], 1)
            w, _ = nnls(np.vstack([a.real, a.imag]), np.concatenate([(kf - 1).real, (kf - 1).imag]))
            s = dict(st)
            for k, x in enumerate(np.log10(np.clip(w, 1e-4, 1e3))):
                s[(f"mw{k}", i)] = float(np.clip(x, -3.99, 2.99))
            out.append(s)
        else:
            lnk = np.log(_response(mat, 2 * math.pi * 10.0**grid_lf) / mat["albedo"])
            im = np.unwrap(lnk.imag)
            s = dict(st)
            for k in range(knots):
                s[(f"kr{k}", i)] = float(np.clip(lnk[k].real, -11.9, 2.9))
                s[(f"ki{k}", i)] = float(np.clip(im[k], -11.9, 2.9))
            out.append(s)
        return out

    globals()["_starts"] = starts


def fitted_state(names: list[str], dev: dict[str, Any], lib: dict[str, Any]) -> tuple[cal.State, list[str]]:
    mats = {m["name"]: m for m in lib["materials"]}
    st = cal._default_state(names)
    cal.device_to_state(dev, st)
    kinds = []
    for i, n in enumerate(names):
        m = mats[n]
        kinds.append(m["kind"])
        b = m["subsurface"] + m.get("subsurface2", 0.0)
        st[("b", i)], st[("lt", i)] = b, math.log10(m["tau_ps"])
        st[("lk", i)], st[("beta", i)] = math.log10(m["gamma_k"]), m["backing"]
        st[("lpf", i)] = math.log10(m["path_factor"])
        st[("w", i)] = m.get("subsurface2", 0.0) / b if b > 0 else 0.3
        st[("lt2", i)] = math.log10(m.get("tau2_ps", 1000.0))
        st[("noise", i)], st[("lr", i)] = m.get("noise_mm", 0.0), math.log10(m["albedo"])
        st[("o0", i)], st[("o1", i)] = m["fit"]["offsets_mm"]
        for k, t in zip(cal.SESSION_KEYS, m["fit"].get("session", (0.0, 0.0, 0.0)), strict=True):
            st[(k, i)] = t
    return st, kinds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("family", choices=("diffusion", "mixture", "free"))
    ap.add_argument("--knots", type=int, default=16, help="free: knots in log frequency")
    ap.add_argument("--device", required=True)
    ap.add_argument("--library", required=True)
    ap.add_argument("--db", default=os.environ.get("TOFMAT_DB_DIR", "../shared/data/tanaka2017_kinect2_db"))
    a = ap.parse_args()
    warnings.filterwarnings("ignore")
    install(a.family, a.knots)
    y, names, bins = cal._table_arrays(tofmat.ExemplarTable.from_npy_dir(a.db))
    with open(a.device) as fh:
        dev = json.load(fh)
    with open(a.library) as fh:
        lib = json.load(fh)
    config = cal.CalibrationConfig(session_drift=any(g.get("session_drift") for g in dev["frequencies"]))
    st, kinds = fitted_state(names, dev, lib)
    idx = list(range(len(names)))
    prob = cal.Problem(y, names, bins, config)
    noisy = {i for i in idx if cal._wants_noise(y[i], bins)}
    base = prob.rms(st, kinds, idx)
    got = []
    for i in idx:
        best = math.inf
        for s in globals()["_starts"](st, i, _state_to_material(st, i, names[i], kinds[i], config)):
            ks = list(kinds)
            ks[i] = a.family
            free = FAMILY_PARAMS[a.family] + ("o0", "o1", "lr") + (("noise",) if i in noisy else ())
            prob.setup(s, ks, [i], [], {i: free})
            prob.solve(max_nfev=80 if a.family != "diffusion" else 40)
            best = min(best, float(prob.rms(prob.st, ks, [i])[0]))
        got.append(best)
        print(f"{names[i]:12s} {kinds[i]:11s} {base[i]:.3f}  {a.family} {best:.3f}", flush=True)
    g = np.array(got)
    print(
        f"median: fitted kinds {np.median(base):.3f} mm, {a.family} {np.median(g):.3f} mm, "
        f"the better of the two per material {np.median(np.minimum(g, base)):.3f} mm"
    )


if __name__ == "__main__":
    main()
