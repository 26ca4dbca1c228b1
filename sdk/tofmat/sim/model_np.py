# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Vectorised NumPy reference implementation of docs/simulator-model.md.

This module is the executable form of the forward-model specification: material kernels
(section 1), the device's per-frequency harmonics, step gains and step offsets (section 2), the
raw samples ``m_j`` and the camera's decode (section 3), hierarchical unwrapping, the combined
depth, the database rows, and curves against the real database (section 4). The C++ simulator
(firmware/sim) computes the same formulas; ``calibrate.py`` fits the parameters below.

Parameters are plain JSON-serialisable dicts:

device::

    {"name": ..., "version": ...,
     "frequencies": [
        {"freq_mhz": 80, "scale_error": 0.0, "phase_offset_rad": 0.0,
         "harmonics": [{"h": 2, "amplitude": a, "phase_rad": psi}, ... h = 2..7],
         "step_gain": [1, 1, 1], "step_offset": [0, 0, 0]},
        {"freq_mhz": 16, ...}, {"freq_mhz": 120, ...}]}

material::

    {"name", "kind": "opaque|exponential|gamma|slab|double", "albedo", "subsurface", "tau_ps",
     "gamma_k", "refractive_index", "thickness_mm", "path_factor", "backing",
     # extensions (docs/simulator-model.md sections 1.1 and 4.1; absent = 0):
     "subsurface2", "tau2_ps", "noise_mm"}

Units: distances in mm, times in ns (``tau_ps`` in ps), angular frequencies in rad/ns.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from typing import Any, TypeAlias, cast

import numpy as np
import numpy.typing as npt

from .._extras import require

FloatArray: TypeAlias = npt.NDArray[np.float64]
ComplexArray: TypeAlias = npt.NDArray[np.complex128]

C_TRUE = 299.792458  # mm/ns, physics (time of flight)
C_DEV = 300.0  # mm/ns, the device's decode (Eq. (1) as the real data was computed)
N_HARM = 7  # harmonics h = 1..7
STEP_PHASES = np.array([0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0])  # phi_j
GROUP_FREQS_MHZ = (80.0, 16.0, 120.0)  # the camera's groups 0, 1, 2
KINDS = ("opaque", "exponential", "gamma", "slab", "double")
# Relative raw signal of the groups (80, 16, 120 MHz): the reciprocal of libfreenect2's
# ab_multiplier_per_frq (1.322581, 1.0, 1.612903), which equalises the groups' amplitudes.
SIGNAL_SCALE_DEFAULT = (1.0 / 1.322581, 1.0, 1.0 / 1.612903)
RANGE_REF_MM = 1000.0  # curves: A = (RANGE_REF_MM / D)^2

MATERIAL_DEFAULTS: dict[str, Any] = {
    "kind": "opaque",
    "albedo": 1.0,
    "subsurface": 0.0,
    "tau_ps": 100.0,
    "gamma_k": 1.0,
    "refractive_index": 1.5,
    "thickness_mm": 0.0,
    "path_factor": 1.0,
    "backing": 0.0,
    "subsurface2": 0.0,
    "tau2_ps": 1000.0,
    "noise_mm": 0.0,
}


# ---------------------------------------------------------------------------------------------
# Section 1: material response
# ---------------------------------------------------------------------------------------------
def unambiguous_range_mm(freq_mhz: float) -> float:
    """C_DEV / (2 f): 1875 mm at 80 MHz, 9375 mm at 16 MHz, 1250 mm at 120 MHz."""
    return C_DEV / (2.0 * freq_mhz * 1e-3)


def material_defaults(material: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(MATERIAL_DEFAULTS)
    out.update({k: v for k, v in material.items() if v is not None})
    return out


def fresnel_b_eff(b: float, n: float, alpha: float | FloatArray) -> FloatArray | np.float64:
    """Schlick: b_eff = min(1, b (1 - F(alpha)) / (1 - F0))."""
    f0 = ((n - 1.0) / (n + 1.0)) ** 2
    f = f0 + (1.0 - f0) * (1.0 - np.cos(alpha)) ** 5
    return np.minimum(1.0, b * (1.0 - f) / (1.0 - f0))


def k_exponential(omega: FloatArray, tau_ns: float) -> ComplexArray:
    return cast(ComplexArray, 1.0 / (1.0 + 1j * omega * tau_ns))


def k_gamma(omega: FloatArray, tau_ns: float, k: float) -> ComplexArray:
    y = omega * tau_ns / k
    return np.exp(-k * (0.5 * np.log1p(y * y) + 1j * np.arctan(y)))


def slab_round_trip_ns(thickness_mm: float, n: float, path_factor: float, alpha: Any = 0.0) -> Any:
    """T = path_factor * 2 * thickness * n / (C_TRUE cos(theta_t)), sin(theta_t) = sin(alpha)/n."""
    sin_t = np.sin(alpha) / n
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin_t * sin_t))
    with np.errstate(divide="ignore"):
        return path_factor * 2.0 * thickness_mm * n / (C_TRUE * cos_t)


def k_slab(omega: FloatArray, tau_ns: float, t_ns: Any, beta: float) -> ComplexArray:
    """Truncated exponential plus the delayed backing; T / tau >= 745 (exp underflows, or grazing
    refraction with n = 1): the exponential."""
    t_ns = np.asarray(t_ns, float)
    far = ~np.isfinite(t_ns) | (t_ns / tau_ns >= 745.0)
    ts = np.where(far, 0.0, t_ns)
    z = ts * (1.0 / tau_ns + 1j * omega)
    e = np.where(far, 0.0, np.exp(-z))
    one_minus = np.where(far, 1.0, -np.expm1(-z))
    return cast(ComplexArray, one_minus / (1.0 + 1j * omega * tau_ns) + beta * e)


def response(material: Mapping[str, Any], omega: Any, alpha: Any = 0.0) -> ComplexArray:
    """R(nu, alpha) for angular frequencies ``omega`` (rad/ns); broadcasts omega and alpha."""
    m = material_defaults(material)
    omega = np.asarray(omega, dtype=float)
    kind = m["kind"]
    rho = float(m["albedo"])
    n = float(m["refractive_index"])
    if kind == "opaque":
        return cast(ComplexArray, rho * np.ones(np.broadcast(omega, np.asarray(alpha)).shape, complex))
    tau = float(m["tau_ps"]) * 1e-3
    b_eff = fresnel_b_eff(float(m["subsurface"]), n, alpha)
    if kind == "exponential":
        k = k_exponential(omega, tau)
    elif kind == "gamma":
        k = k_gamma(omega, tau, float(m["gamma_k"]))
    elif kind == "slab":
        t = slab_round_trip_ns(float(m["thickness_mm"]), n, float(m["path_factor"]), alpha)
        k = k_slab(omega, tau, t, float(m["backing"]))
    elif kind == "double":
        # section 1.1: two exponential components, b and b2 share the Fresnel factor
        b2_eff = fresnel_b_eff(float(m["subsurface2"]), n, alpha)
        tau2 = float(m["tau2_ps"]) * 1e-3
        return rho * ((1.0 - b_eff - b2_eff) + b_eff * k_exponential(omega, tau) + b2_eff * k_exponential(omega, tau2))
    else:
        raise ValueError(f"unknown material kind {kind!r}")
    return rho * ((1.0 - b_eff) + b_eff * k)


# ---------------------------------------------------------------------------------------------
# Section 2: device
# ---------------------------------------------------------------------------------------------
def _group(device: Mapping[str, Any], freq_mhz: float) -> Mapping[str, Any]:
    for g in device["frequencies"]:
        if abs(float(g["freq_mhz"]) - freq_mhz) < 1e-9:
            return cast(Mapping[str, Any], g)
    raise KeyError(f"device has no {freq_mhz} MHz group")


def n_harmonics(device: Mapping[str, Any]) -> int:
    """Highest harmonic listed by any group, drift included (at least 7)."""
    hs = [int(hh["h"]) for g in device["frequencies"]
          for key in ("harmonics", "session_drift") for hh in g.get(key, [])]  # fmt: skip
    return max([N_HARM, *hs])


def harmonic_vector(group: Mapping[str, Any], n_harm: int = N_HARM, key: str = "harmonics") -> ComplexArray:
    """G_h for h = 0..n_harm (index h), G_0 = 0 (unused), G_1 = 1; with key="session_drift" the
    drift direction dG_h of section 2.2 (dG_0 = dG_1 = 0)."""
    g = np.zeros(n_harm + 1, complex)
    if key == "harmonics":
        g[1] = 1.0
    for hh in group.get(key, []):
        h = int(hh["h"])
        if 2 <= h <= n_harm:
            g[h] += float(hh["amplitude"]) * np.exp(1j * float(hh["phase_rad"]))
    return g


def harmonic_list(G: ComplexArray) -> list[dict[str, Any]]:
    """The profile's form of G_h (h >= 2): amplitude and phase, zeros dropped."""
    return [{"h": h, "amplitude": float(abs(G[h])), "phase_rad": float(np.angle(G[h]))}
            for h in range(2, len(G)) if G[h] != 0]  # fmt: skip


def in_session(device: Mapping[str, Any], state: Sequence[float]) -> dict[str, Any]:
    """The device in one capture session (spec section 2.2): G_h + t_f dG_h in every group, with
    ``state`` = (t_80, t_16, t_120). The result has the drift applied and no drift of its own."""
    t = [float(x) for x in state]
    if len(t) != 3 or not all(math.isfinite(x) for x in t):
        raise ValueError("a session state is three finite numbers (t_80, t_16, t_120)")
    out = copy.deepcopy(dict(device))
    nh = n_harmonics(device)
    for g in out["frequencies"]:
        tf = t[GROUP_FREQS_MHZ.index(float(g["freq_mhz"]))]
        G = harmonic_vector(g, nh) + tf * harmonic_vector(g, nh, "session_drift")
        g["harmonics"] = harmonic_list(G)
        g.pop("session_drift", None)
    return out


def device_arrays(device: Mapping[str, Any]) -> dict[str, npt.NDArray[Any]]:
    """The device as arrays over the groups (80, 16, 120 MHz order)."""
    groups = [_group(device, f) for f in GROUP_FREQS_MHZ]
    nh = n_harmonics(device)
    sat = device.get("saturation") or {}
    fw = [g.get("full_well") for g in groups]
    return {
        "scale": np.array([float(g.get("signal_scale", d)) for g, d in zip(groups, SIGNAL_SCALE_DEFAULT, strict=True)]),
        "full_well": np.array([np.inf if w is None else float(w) for w in fw]),
        "sat_p": np.array(float(sat.get("sharpness", 8.0))),
        "f": np.array(GROUP_FREQS_MHZ),
        "s": np.array([float(g.get("scale_error", 0.0)) for g in groups]),
        "delta": np.array([float(g.get("phase_offset_rad", 0.0)) for g in groups]),
        "eps": np.array([float(g.get("decode_offset_rad", 0.0)) for g in groups]),
        "G": np.array([harmonic_vector(g, nh) for g in groups]),
        "gain": np.array([[float(x) for x in g.get("step_gain", [1, 1, 1])] for g in groups]),
        "offset": np.array([[float(x) for x in g.get("step_offset", [0, 0, 0])] for g in groups]),
    }


def ideal_device(name: str = "ideal", version: str = "0") -> dict[str, Any]:
    return {
        "name": name,
        "version": version,
        "range_ref_mm": RANGE_REF_MM,
        "saturation": {"sharpness": 8.0},
        "frequencies": [
            {
                "freq_mhz": f,
                "signal_scale": r,
                "full_well": None,
                "scale_error": 0.0,
                "phase_offset_rad": 0.0,
                "decode_offset_rad": 0.0,
                "harmonics": [{"h": h, "amplitude": 0.0, "phase_rad": 0.0} for h in range(2, N_HARM + 1)],
                "step_gain": [1.0, 1.0, 1.0],
                "step_offset": [0.0, 0.0, 0.0],
            }
            for f, r in zip((80, 16, 120), SIGNAL_SCALE_DEFAULT, strict=True)
        ],
    }


def material_harmonic_responses(material: Mapping[str, Any], dev: Mapping[str, Any], alpha: Any = 0.0) -> ComplexArray:
    """R(h f (1 + s), alpha) for the groups and h = 0..H: shape (3, H + 1) (+ alpha's shape)."""
    h = np.arange(dev["G"].shape[-1])
    omega = 2.0 * math.pi * (dev["f"] * 1e-3 * (1.0 + dev["s"]))[:, None] * h[None, :]
    alpha = np.asarray(alpha, dtype=float)
    return response(material, omega.reshape(omega.shape + (1,) * alpha.ndim), alpha)


# ---------------------------------------------------------------------------------------------
# Section 3: raw samples, decode, unwrap
# ---------------------------------------------------------------------------------------------
def raw_samples_core(
    f_mhz: FloatArray,
    s: FloatArray,
    delta: FloatArray,
    G: ComplexArray,
    gain: FloatArray,
    offset: FloatArray,
    Rh: ComplexArray,
    D_mm: FloatArray,
    A: Any = 1.0,
    delta_p: Any = 0.0,
    scale: Any = None,
    full_well: Any = None,
    sat_p: float = 8.0,
) -> FloatArray:
    """m_j for all groups: returns (..., 3 groups, 3 steps, N) (spec sections 3 and 3.1).

    f_mhz, s, delta: (3,); G: (3, H + 1); gain, offset: (3, 3); Rh: (..., 3, H + 1) =
    R(h f (1 + s)); D_mm: (N,); A: scalar or (N,); scale, full_well: (3,) (None: 1 and no
    saturation). ``Rh[..., 0]`` is R(0) = albedo: the DC that the taps and step offsets see.

    AC_j = A r_f Re{sum_h G_h conj(R_h) e^{i h (theta0 + phi_j)}}, DC = A r_f R(0),
    T+-_j = (DC +- AC_j) / 2, m_j = g_j [N(T+_j) - N(T-_j)] + o_j DC,
    N(T) = T / (1 + (|T| / W_f)^p)^(1/p)   (W_f = inf: N(T) = T).
    """
    t = 2.0 * np.asarray(D_mm, float) / C_TRUE  # ns
    dp = np.asarray(delta_p, float)  # scalar or (N,)
    w = 2.0 * math.pi * f_mhz * 1e-3 * (1.0 + s)  # (3,)
    theta0 = w[:, None] * t[None, :] - delta[:, None] - dp  # (3, N)
    X = G * np.conj(Rh)  # (..., 3, H + 1)
    e1 = np.exp(1j * (theta0[:, None, :] + STEP_PHASES[None, :, None]))  # (3 groups, 3 steps, N)
    acc = np.zeros(X.shape[:-1] + e1.shape[1:], complex)  # (..., 3, 3, N)
    p = np.ones_like(e1)
    for h in range(1, X.shape[-1]):
        p = p * e1
        if np.any(X[..., h] != 0):
            acc = acc + X[..., h][..., None, None] * p
    r = np.ones(3) if scale is None else np.asarray(scale, float)
    amp = np.asarray(A, float) * r[:, None, None]  # (3, 1, N|1)
    ac = amp * acc.real
    dc = amp * np.real(Rh[..., 0])[..., None, None]  # R(0) = albedo
    W = np.full(3, np.inf) if full_well is None else np.asarray(full_well, float)
    if np.all(np.isinf(W)):
        return cast(FloatArray, gain[:, :, None] * ac + offset[:, :, None] * dc)
    Wb = W[:, None, None]
    diff = saturate(0.5 * (dc + ac), Wb, sat_p) - saturate(0.5 * (dc - ac), Wb, sat_p)
    return cast(FloatArray, gain[:, :, None] * diff + offset[:, :, None] * dc)


def saturate(T: FloatArray, W: Any, p: float) -> FloatArray:
    """Soft full-well saturation of a tap, N(T) = T / (1 + (|T| / W)^p)^(1/p); W = inf: T."""
    W = np.asarray(W, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(np.isinf(W), 0.0, np.abs(T) / np.where(np.isinf(W), 1.0, W))
    return T / (1.0 + u**p) ** (1.0 / p)


def decode(m: FloatArray, delta_p: Any = 0.0, eps: Any = None) -> FloatArray:
    """Wrapped per-group depths d_f (mm) from raw samples m (..., 3 groups, 3 steps, N).

    theta_j = p0 - eps_f + phi_j with p0 = -delta_p (the P0 tables) and eps_f the per-group
    decode offset (spec 2.1: the P0 calibration's residual; it adds eps_f to the phase)."""
    dp = np.asarray(delta_p, float)  # scalar or (N,)
    e = np.exp(-1j * (STEP_PHASES[:, None] - dp))  # exp(-i (p0 + phi_j)): (3, N|1)
    z = np.sum(m * e, axis=-2)
    if eps is not None:
        z = z * np.exp(1j * np.asarray(eps, float))[:, None]
    phase = np.mod(np.angle(z), 2.0 * math.pi)
    f = np.array(GROUP_FREQS_MHZ)[:, None] * 1e-3
    return cast(FloatArray, C_DEV * phase / (4.0 * math.pi * f))


def phasor_direct(
    f_mhz: FloatArray,
    s: FloatArray,
    delta: FloatArray,
    G: ComplexArray,
    gain: FloatArray,
    offset: FloatArray,
    Rh: ComplexArray,
    D_mm: FloatArray,
) -> ComplexArray:
    """The decode's a + i b (up to a positive factor) for delta_p = 0 when no tap saturates,
    without forming the samples (for fitting; the phase does not depend on A or the scale).

    Algebraically identical to ``sum_j m_j exp(-i phi_j)`` with m_j from raw_samples_core:
    ``z = sum_h [A_h X_h P^h + B_h conj(X_h P^h)] + R(0) sum_j o_j exp(-i phi_j)``, with
    ``X_h = G_h conj(R_h)``, ``P = exp(i theta0)``, ``A_h = 1/2 sum_j g_j exp(i (h - 1) phi_j)``,
    ``B_h = 1/2 sum_j g_j exp(-i (h + 1) phi_j)``. Returns (..., 3 groups, N).
    """
    t = 2.0 * np.asarray(D_mm, float) / C_TRUE
    w = 2.0 * math.pi * f_mhz * 1e-3 * (1.0 + s)
    P = np.exp(1j * (w[:, None] * t[None, :] - delta[:, None]))  # (3, N)
    X = G * np.conj(Rh)  # (..., 3, H + 1)
    nh = X.shape[-1]
    hh = np.arange(nh)
    ph = STEP_PHASES
    Ah = 0.5 * np.einsum("gj,hj->gh", gain, np.exp(1j * (hh[:, None] - 1) * ph[None, :]))
    Bh = 0.5 * np.einsum("gj,hj->gh", gain, np.exp(-1j * (hh[:, None] + 1) * ph[None, :]))
    z = np.zeros(X.shape[:-1] + P.shape[-1:], complex)
    Pk = np.ones_like(P)
    for h in range(1, nh):
        Pk = Pk * P
        a, b = Ah[:, h], Bh[:, h]
        xa = X[..., h] * a
        xb = np.conj(X[..., h]) * b
        if np.any(xa != 0):
            z = z + xa[..., None] * Pk
        if np.any(xb != 0):
            z = z + xb[..., None] * np.conj(Pk)
    rot = offset @ np.exp(-1j * ph)  # (3,)
    return cast(ComplexArray, z + (np.real(Rh[..., 0]) * rot)[..., None])


def depths_from_phasor(z: ComplexArray, eps: Any = None) -> FloatArray:
    """d_f = C_DEV * wrap(arg z + eps_f) / (4 pi f) for the groups (..., 3, N)."""
    if eps is not None:
        z = z * np.exp(1j * np.asarray(eps, float))[:, None]
    phase = np.mod(np.angle(z), 2.0 * math.pi)
    f = np.array(GROUP_FREQS_MHZ)[:, None] * 1e-3
    return C_DEV * phase / (4.0 * math.pi * f)


def _round_half_up(x: FloatArray) -> FloatArray:
    return np.floor(x + 0.5)


def unwrap_combined(d: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Hierarchical unwrap of wrapped (d80, d16, d120) (..., 3, N) -> (D (..., 3, N), d_comb)."""
    d80, d16, d120 = d[..., 0, :], d[..., 1, :], d[..., 2, :]
    u80, u120 = unambiguous_range_mm(80.0), unambiguous_range_mm(120.0)
    D16 = d16
    D80 = d80 + u80 * _round_half_up((D16 - d80) / u80)
    D120 = d120 + u120 * _round_half_up((D80 - d120) / u120)
    dcomb = (80.0 * D80 + 16.0 * D16 + 120.0 * D120) / 216.0
    return np.stack([D80, D16, D120], axis=-2), dcomb


def expected_wrapped(d: FloatArray, noise_mm: Any) -> FloatArray:
    """Section 4.1: E[wrap(d_f + n_f)], n_f ~ N(0, sigma_f^2), sigma_f = noise_mm * 120 / f.

    The database averaged wrapped phases arithmetically; near a wrap (d120 near 1250 mm) the mean
    is pulled towards the middle. Closed form (single wrap each side):
    E = d + U [Q(d / sigma) - Q((U - d) / sigma)], Q(x) = erfc(x / sqrt 2) / 2.
    ``d`` is (..., 3 groups, N); ``noise_mm`` a scalar or an array of shape ``d.shape[:-2]``.
    """
    noise = np.asarray(noise_mm, float)
    if not np.any(noise > 0.0):
        return d
    require("scipy.special", extra="sim", feature="the NumPy model's wrap noise (tofmat.sim.model_np)")
    from scipy.special import erfc  # type: ignore[import-untyped]  # scipy ships no type stubs

    f = np.array(GROUP_FREQS_MHZ)
    U = (C_DEV / (2e-3 * f))[:, None]  # (3, 1)
    sig = noise[..., None, None] * (120.0 / f)[:, None]  # (..., 3, 1)
    safe = np.where(sig > 0.0, sig, 1.0)

    def q(x: FloatArray) -> FloatArray:
        out: FloatArray = 0.5 * erfc(x / math.sqrt(2.0))
        return out

    corr = U * (q(d / safe) - q((U - d) / safe))
    return d + np.where(sig > 0.0, corr, 0.0)


def simulate(
    device: Mapping[str, Any],
    material: Mapping[str, Any],
    D_mm: Any,
    alpha: float = 0.0,
    A: Any = None,
    delta_p: float = 0.0,
) -> dict[str, FloatArray]:
    """Noise-free forward model along a range sweep (scalar alpha and delta_p).

    ``A`` defaults to the curves' fall-off ``(range_ref_mm / D)^2`` (section 4; the device's
    ``range_ref_mm``, 1000 when absent).
    Returns m (3 groups, 3 steps, N), d (wrapped, (3, N), groups 80/16/120), D (unwrapped),
    dcomb (N,), rows (2, N) = (d16 - d120, d80 - d120).
    """
    dev = device_arrays(device)
    D_mm = np.atleast_1d(np.asarray(D_mm, float))
    if A is None:
        A = (float(device.get("range_ref_mm", RANGE_REF_MM)) / D_mm) ** 2
    Rh = material_harmonic_responses(material, dev, alpha)
    m = raw_samples_core(
        dev["f"], dev["s"], dev["delta"], dev["G"], dev["gain"], dev["offset"], Rh, D_mm, A,
        delta_p, dev["scale"], dev["full_well"], float(dev["sat_p"]),
    )  # fmt: skip
    d = decode(m, delta_p, dev["eps"])
    D, dcomb = unwrap_combined(d)
    rows = np.stack([d[1] - d[2], d[0] - d[2]])
    return {"m": m, "d": d, "D": D, "dcomb": dcomb, "rows": rows}


# ---------------------------------------------------------------------------------------------
# Section 4: curves against the real database
# ---------------------------------------------------------------------------------------------
def bin_edges(start_mm: float, width_mm: float, count: int) -> FloatArray:
    return cast(FloatArray, start_mm + width_mm * np.arange(count + 1))


def sweep_grid(start_mm: float = 450.0, stop_mm: float = 1400.0, step_mm: float = 0.25) -> FloatArray:
    n = round((stop_mm - start_mm) / step_mm)
    return cast(FloatArray, start_mm + step_mm * np.arange(n + 1))


def rows_from_depths(d: FloatArray, noise_mm: float = 0.0) -> FloatArray:
    """Rows (2, N) from wrapped depths (3, N); with noise_mm > 0 the wrapped depths are replaced by
    their expectation under per-sample noise (section 4.1)."""
    de = expected_wrapped(d, noise_mm)
    return np.stack([de[1] - de[2], de[0] - de[2]])


def curve_from_sweep(
    dcomb: FloatArray,
    rows: FloatArray,
    bins: tuple[float, float, int],
    mode: str = "interp",
    accumulator: str = "numpy",
) -> FloatArray:
    """(2, count) curve from a sweep. mode 'interp' (smooth, for fitting) or 'bin' (average of
    samples per bin, as the real database; NaN where a bin has no sample)."""
    start, width, count = bins
    if mode == "interp":
        centres = start + width * (np.arange(count) + 0.5)
        order = np.argsort(dcomb, kind="stable")
        x = dcomb[order]
        out = np.stack([np.interp(centres, x, r[order], left=np.nan, right=np.nan) for r in rows])
        return out
    if mode != "bin":
        raise ValueError("mode must be 'interp' or 'bin'")
    if accumulator == "core":
        import tofmat  # the C++ core's DepthBinAccumulator

        acc = tofmat.DepthBinAccumulator(tofmat.BinSpec(start, width, count), 2)
        acc.add_many(dcomb, np.ascontiguousarray(rows.T, dtype=np.float32))
        return acc.query().astype(float)
    idx = np.floor((dcomb - start) / width).astype(np.int64)
    ok = (idx >= 0) & (idx < count) & np.isfinite(dcomb)
    cnt = np.bincount(idx[ok], minlength=count).astype(float)
    out = np.full((2, count), np.nan)
    for r in range(2):
        s = np.bincount(idx[ok], weights=rows[r][ok], minlength=count)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[r] = np.where(cnt > 0, s / cnt, np.nan)
    return out


def curve(
    device: Mapping[str, Any],
    material: Mapping[str, Any],
    bins: tuple[float, float, int] = (600.0, 600.0 / 199.0, 200),
    mode: str = "interp",
    grid: tuple[float, float, float] = (450.0, 1400.0, 0.25),
    offsets_mm: Sequence[float] = (0.0, 0.0),
    accumulator: str = "numpy",
    session: Sequence[float] | None = None,
) -> FloatArray:
    """Simulated database curve (2, count) of a material at incidence 0 (section 4), in the
    capture session ``session`` (section 2.2; None: the device's nominal waveform)."""
    if session is not None:
        device = in_session(device, session)
    D = sweep_grid(*grid)
    sim = simulate(device, material, D)
    rows = rows_from_depths(sim["d"], float(material_defaults(material)["noise_mm"]))
    out = curve_from_sweep(sim["dcomb"], rows, bins, mode, accumulator)
    return cast(FloatArray, out + np.asarray(offsets_mm, float)[:, None])
