# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Numerical stability of the material responses' closed forms (docs/simulator-model.md, 1).

`tofmat.sim.Material.response(freq_hz, incidence_deg)` (C++ doubles) against mpmath evaluations
of the same closed forms at 50 significant digits, over tau = 1 ps .. 100 ns, frequencies up to
1e11 Hz (f * tau up to 1e4), subsurface fraction 0 and 1, albedo 1e-6 .. 1.

Bound: relative error of the complex value <= 1e-12 (REL_TOL). A correct double evaluation errs
by a few ulps per operation, amplified by the conditioning of the closed form: <= k for the gamma
kernel (k <= 20 here: ~1e-14), <= 1 for the exponential. For exponential and gamma the reference
therefore takes the exact inputs (tau_ps * 1e-12, 2 pi f in 50 digits).

The slab's exp(-i omega T) is the exception: its phase omega T reaches 1e4 rad, and one rounding of
T (unavoidable: T is computed from thickness, n, path factor and c) moves it by 1e4 * 1.1e-16 =
1e-12 rad: conditioning of the problem, not an error of the evaluation. So the slab's reference
takes T/tau, omega T and omega tau as the doubles the implementation forms (the same IEEE
operations in the same order, reproduced here), and measures only the evaluation.
"""

from __future__ import annotations

import math
from typing import Any

import mpmath
import pytest
from mpmath import mp

from tofmat import sim

mp.dps = 50

REL_TOL = 1e-12
C_TRUE_MM_PER_S = 299.792458e9

TAU_PS = [1.0, 10.0, 100.0, 1e3, 1e4, 1e5]  # 1 ps .. 100 ns
FREQS_HZ = [0.0, 1e3, 1e6, 16e6, 80e6, 120e6, 840e6, 1e9, 1e10, 1e11]  # f * tau up to 1e11 * 1e-7 = 1e4
ALBEDOS = [1e-6, 0.37, 1.0]
GAMMA_K = [0.5, 1.0, 3.0, 20.0]


def material(kind: str, **params: Any) -> sim.Material:
    d: dict[str, Any] = {"name": "m", "kind": kind}
    d.update(params)
    return sim.Material.from_dict(d)


def rel_err(got: complex, want: mpmath.mpc) -> float:
    return float(abs(mpmath.mpc(got.real, got.imag) - want) / abs(want))


def assert_close(got: complex, want: mpmath.mpc, what: str) -> None:
    assert math.isfinite(got.real) and math.isfinite(got.imag), f"{what}: {got}"
    if abs(want) < mpmath.mpf("1e-290"):  # below double's normal range: only tiny and finite
        assert abs(got) < 1e-280, f"{what}: {got} vs {want}"
        return
    e = rel_err(got, want)
    assert e <= REL_TOL, f"{what}: relative error {e:.3g} (got {got}, want {complex(want)})"


def omega_exact(freq_hz: float) -> mpmath.mpf:
    return 2 * mp.pi * mpmath.mpf(freq_hz)


def tau_exact(tau_ps: float) -> mpmath.mpf:
    return mpmath.mpf(tau_ps) * mpmath.mpf(10) ** -12


def fresnel_b_eff(b: float, n: float, incidence_deg: float) -> mpmath.mpf:
    """The spec's rule: F = F0 + (1 - F0)(1 - cos a)^5, b_eff = min(1, b (1 - F) / (1 - F0))."""
    a = mpmath.mpf(incidence_deg) * mp.pi / 180
    f0 = ((mpmath.mpf(n) - 1) / (mpmath.mpf(n) + 1)) ** 2
    f = f0 + (1 - f0) * (1 - mpmath.cos(a)) ** 5
    return min(mpmath.mpf(1), mpmath.mpf(b) * (1 - f) / (1 - f0))


def response_ref(albedo: float, b_eff: mpmath.mpf, k: mpmath.mpc) -> mpmath.mpc:
    return mpmath.mpf(albedo) * ((1 - b_eff) + b_eff * k)


# ------------------------------------------------------------------------------------------------
# Kernels at normal incidence (b_eff = b exactly there)
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("albedo", ALBEDOS)
@pytest.mark.parametrize("subsurface", [0.0, 1.0])
def test_exponential_against_mpmath(albedo: float, subsurface: float) -> None:
    for tau_ps in TAU_PS:
        m = material("exponential", albedo=albedo, subsurface=subsurface, tau_ps=tau_ps)
        for f in FREQS_HZ:
            x = omega_exact(f) * tau_exact(tau_ps)
            k = 1 / mpmath.mpc(1, x)
            assert_close(
                m.response(f, 0.0),
                response_ref(albedo, mpmath.mpf(subsurface), k),
                f"exponential tau {tau_ps} ps f {f} Hz albedo {albedo} b {subsurface}",
            )


@pytest.mark.parametrize("gamma_k", GAMMA_K)
@pytest.mark.parametrize("albedo", ALBEDOS)
@pytest.mark.parametrize("subsurface", [0.0, 1.0])
def test_gamma_against_mpmath(gamma_k: float, albedo: float, subsurface: float) -> None:
    for tau_ps in TAU_PS:
        m = material("gamma", albedo=albedo, subsurface=subsurface, tau_ps=tau_ps, gamma_k=gamma_k)
        for f in FREQS_HZ:
            y = omega_exact(f) * tau_exact(tau_ps) / mpmath.mpf(gamma_k)
            k = mpmath.power(mpmath.mpc(1, y), -mpmath.mpf(gamma_k))  # principal branch = the spec's form
            assert_close(
                m.response(f, 0.0),
                response_ref(albedo, mpmath.mpf(subsurface), k),
                f"gamma k {gamma_k} tau {tau_ps} ps f {f} Hz albedo {albedo} b {subsurface}",
            )


def test_gamma_principal_branch_is_the_spec_form() -> None:
    # The spec computes exp(-k (0.5 log1p(y^2) + i atan y)); mpmath's power is that branch.
    for y in (mpmath.mpf("1e-8"), mpmath.mpf(3), mpmath.mpf("1e4")):
        for k in (mpmath.mpf("0.5"), mpmath.mpf(20)):
            a = mpmath.power(mpmath.mpc(1, y), -k)
            b = mpmath.exp(-k * (mpmath.log1p(y * y) / 2 + 1j * mpmath.atan(y)))
            assert abs(a - b) <= mpmath.mpf("1e-45") * abs(b)


def test_gamma_k1_is_the_exponential() -> None:
    for tau_ps in TAU_PS:
        g = material("gamma", albedo=1.0, subsurface=1.0, tau_ps=tau_ps, gamma_k=1.0)
        e = material("exponential", albedo=1.0, subsurface=1.0, tau_ps=tau_ps)
        for f in FREQS_HZ:
            a, b = g.response(f, 0.0), e.response(f, 0.0)
            assert abs(a - b) <= 1e-14 * abs(b), (tau_ps, f, a, b)


# The slab: arguments as the implementation forms them (see the module docstring).
def slab_args(
    tau_ps: float, thickness_mm: float, n: float, path_factor: float, freq_hz: float, incidence_deg: float
) -> tuple[float, float, float]:
    """(T/tau, omega T, omega tau) as doubles, in material_response's order of operations."""
    alpha = incidence_deg * math.pi / 180.0
    sin_t = math.sin(alpha) / n
    cos_t = math.sqrt(max(0.0, 1.0 - sin_t * sin_t))
    transit = path_factor * 2.0 * thickness_mm * n / (C_TRUE_MM_PER_S * cos_t)
    omega = (2.0 * math.pi) * freq_hz
    tau = tau_ps * 1e-12
    return transit / tau, omega * transit, omega * tau


def slab_ref(t_over_tau: float, omega_t: float, omega_tau: float, backing: float) -> mpmath.mpc:
    z = mpmath.mpc(t_over_tau, omega_t)
    e = mpmath.exp(-z)
    return (1 - e) / mpmath.mpc(1, omega_tau) + mpmath.mpf(backing) * e


SLAB_CASES = [
    # thickness_mm, n, path_factor: T = path_factor * 2 * thickness * n / c
    (1e-9, 1.5, 1.0),  # T = 1e-20 s: T/tau 1e-8 .. 1e-13 (the expm1 path)
    (1e-4, 1.5, 1.0),  # T = 1e-15 s
    (0.1, 1.5, 1.0),  # T = 1e-12 s
    (1.0, 1.33, 3.0),  # T = 2.7e-11 s
    (20.0, 1.5, 1.0),  # T = 2e-10 s
    (1e3, 2.0, 1e4),  # T = 1.3e-4 s: T/tau >= 1300, backing term underflows to 0
]


@pytest.mark.parametrize("thickness_mm, n, path_factor", SLAB_CASES)
@pytest.mark.parametrize("backing", [0.0, 0.5, 3.0])
@pytest.mark.parametrize("albedo", [1e-6, 1.0])
def test_slab_against_mpmath(thickness_mm: float, n: float, path_factor: float, backing: float, albedo: float) -> None:
    for tau_ps in TAU_PS:
        m = material(
            "slab",
            albedo=albedo,
            subsurface=1.0,
            tau_ps=tau_ps,
            refractive_index=n,
            thickness_mm=thickness_mm,
            path_factor=path_factor,
            backing=backing,
        )
        for f in FREQS_HZ:
            for inc in (0.0, 45.0):
                tt, wt, wtau = slab_args(tau_ps, thickness_mm, n, path_factor, f, inc)
                b_eff = fresnel_b_eff(1.0, n, inc)
                want = response_ref(albedo, b_eff, slab_ref(tt, wt, wtau, backing))
                assert_close(
                    m.response(f, inc),
                    want,
                    f"slab d {thickness_mm} n {n} pf {path_factor} beta {backing} tau {tau_ps} f {f} inc {inc}",
                )


def test_slab_tiny_transit_has_no_cancellation() -> None:
    # T/tau = 1e-13 and no backing: K ~ T/tau / (1 + i omega tau) ~ 1e-13. Computing
    # 1 - exp(-z) directly would keep ~3 digits; the bound 1e-12 needs expm1.
    m = material("slab", albedo=1.0, subsurface=1.0, tau_ps=1e5, refractive_index=1.5, thickness_mm=1e-9, backing=0.0)
    tt, wt, wtau = slab_args(1e5, 1e-9, 1.5, 1.0, 120e6, 0.0)
    assert tt < 1e-12
    got = m.response(120e6, 0.0)
    assert abs(got) < 1e-12
    assert rel_err(got, slab_ref(tt, wt, wtau, 0.0)) <= REL_TOL
    naive = (1 - complex(math.exp(-tt) * math.cos(-wt), math.exp(-tt) * math.sin(-wt))) / complex(1, wtau)
    assert rel_err(naive, slab_ref(tt, wt, wtau, 0.0)) > 1e-6  # the cancellation the test guards against


def test_slab_huge_transit_backing_underflows_cleanly() -> None:
    # T/tau ~ 1e8: exp(-z) is 0 in double; the slab equals the exponential (backing invisible).
    for backing in (0.0, 10.0):
        s = material(
            "slab",
            albedo=1.0,
            subsurface=1.0,
            tau_ps=1.0,
            refractive_index=2.0,
            thickness_mm=1e3,
            path_factor=1e4,
            backing=backing,
        )
        e = material("exponential", albedo=1.0, subsurface=1.0, tau_ps=1.0)
        for f in FREQS_HZ:
            a, b = s.response(f, 0.0), e.response(f, 0.0)
            assert math.isfinite(a.real) and math.isfinite(a.imag)
            assert abs(a - b) <= 1e-15 * abs(b), (f, a, b)


def test_zero_subsurface_is_exactly_the_albedo() -> None:
    for kind, extra in (
        ("opaque", {}),
        ("exponential", {"tau_ps": 50.0}),
        ("gamma", {"tau_ps": 50.0}),
        ("slab", {"tau_ps": 50.0, "thickness_mm": 1.0}),
    ):
        m = material(kind, albedo=0.42, subsurface=0.0, **extra)
        for f in FREQS_HZ:
            for inc in (0.0, 60.0):
                assert m.response(f, inc) == complex(0.42, 0.0)


# ------------------------------------------------------------------------------------------------
# Incidence: the Fresnel (Schlick) share
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("incidence_deg", [0.0, 45.0, 85.0])
@pytest.mark.parametrize("n", [1.0, 1.5, 2.5])
@pytest.mark.parametrize("b", [0.3, 1.0])
def test_b_eff_follows_the_fresnel_rule(incidence_deg: float, n: float, b: float) -> None:
    # omega tau = 2 pi * 1e10 * 1e-8 ~ 628: K ~ -i/628, so R/albedo ~ 1 - b_eff and b_eff is
    # recovered as (1 - R/albedo) / (1 - K) with K from mpmath. Bound 1e-12 (absolute, on b_eff <= 1).
    albedo, tau_ps, f = 0.8, 1e4, 1e10
    m = material("exponential", albedo=albedo, subsurface=b, tau_ps=tau_ps, refractive_index=n)
    k = 1 / mpmath.mpc(1, omega_exact(f) * tau_exact(tau_ps))
    r = m.response(f, incidence_deg)
    b_eff_measured = (1 - mpmath.mpc(r.real, r.imag) / albedo) / (1 - k)
    want = fresnel_b_eff(b, n, incidence_deg)
    assert abs(b_eff_measured - want) <= 1e-12, (complex(b_eff_measured), float(want))
    assert abs(b_eff_measured.imag) <= 1e-12
    assert_close(r, response_ref(albedo, want, k), f"R at {incidence_deg} deg")
    if incidence_deg == 0.0:
        assert abs(want - b) < 1e-40  # b_eff = b at normal incidence
    else:
        assert want < b  # less light enters at oblique incidence


def test_b_eff_values() -> None:
    # Spot values of the rule for n = 1.5 (F0 = 0.04), written out.
    f0 = 0.04
    for deg, b in ((45.0, 1.0), (85.0, 0.5)):
        c = math.cos(math.radians(deg))
        expect = b * (1 - (f0 + (1 - f0) * (1 - c) ** 5)) / (1 - f0)
        assert float(fresnel_b_eff(b, 1.5, deg)) == pytest.approx(expect, rel=1e-14)
    # b = 1: b_eff = (1 - F) / (1 - F0) = 1 - (1 - cos a)^5 for any n.
    assert float(fresnel_b_eff(1.0, 1.5, 85.0)) == pytest.approx(1 - (1 - math.cos(math.radians(85))) ** 5, rel=1e-14)


@pytest.mark.parametrize("kind", ["exponential", "gamma", "slab"])
@pytest.mark.parametrize("n", [1.0, 1.5])
def test_never_nan_at_grazing_incidence(kind: str, n: float) -> None:
    # At 90 degrees F = 1 and b_eff = 0: R is the albedo. validate() accepts n = 1, for which the
    # slab's cos(theta_t) = 0 gives an infinite transit time; the response must stay finite.
    m = material(kind, albedo=0.8, subsurface=1.0, tau_ps=100.0, refractive_index=n, thickness_mm=1.0, backing=0.3)
    for inc in (89.0, 89.999, 90.0):
        r = m.response(120e6, inc)
        assert math.isfinite(r.real) and math.isfinite(r.imag), f"{kind} n={n} at {inc} deg: {r}"
    assert abs(m.response(120e6, 90.0) - 0.8) < 1e-12
