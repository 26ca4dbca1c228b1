# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Noise-free distortion curves (docs/simulator-model.md, section 4): tofmat.sim.distortion_curves.

The expected values are computed here from the spec's formulas (material responses taken from
Material.response, whose closed forms test_sim_closed_forms.py checks), never from the curve code.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

import tofmat
from tofmat import sim

C_TRUE = 299.792458  # mm/ns
C_DEV = 300.0  # mm/ns
FREQS_MHZ = (80.0, 16.0, 120.0)  # group order
BINS = tofmat.BinSpec.linspace(600.0, 1200.0, 200)  # the real database's bins
SWEEP = np.arange(0, 3801) * 0.25 + 450.0  # the spec's sweep: 450 .. 1400 mm in 0.25 mm


def material(name: str, kind: str, **params: Any) -> sim.Material:
    d: dict[str, Any] = {"name": name, "kind": kind, "albedo": 0.5}
    d.update(params)
    return sim.Material.from_dict(d)


OPAQUE = material("paper", "opaque")
EXPONENTIALS = [
    material("wax", "exponential", subsurface=0.5, tau_ps=200.0),
    material("skin", "exponential", subsurface=1.0, tau_ps=50.0),
    material("foam", "exponential", subsurface=0.3, tau_ps=800.0),
    material("milk", "exponential", subsurface=1.0, tau_ps=1500.0),
]
OTHERS = [
    material("felt", "gamma", subsurface=0.8, tau_ps=300.0, gamma_k=3.0),
    material("sheet", "slab", subsurface=0.8, tau_ps=300.0, thickness_mm=3.0, backing=0.5),
]

HARMONICS = [(2, 0.3), (3, 1.0), (4, -0.7)]  # amplitude 0.05 each; h = 3 cancels in the 3-step decode
MANY_HARMONICS = [(2, 0.3), (3, 1.0), (4, -0.7), (5, 2.0), (7, 0.1)]


def device_with(harmonics: list[tuple[int, float]], amplitude: float = 0.05) -> sim.DeviceProfile:
    d = sim.DeviceProfile.ideal_kinect2().to_dict()
    for f in d["frequencies"]:
        f["harmonics"] = [{"h": h, "amplitude": amplitude, "phase_rad": p} for h, p in harmonics]
    return sim.DeviceProfile.from_dict(d)


def shift_mm(m: sim.Material, freq_mhz: float) -> float:
    """Depth shift of one frequency with the ideal device: d = D' - c/(4 pi f) arg R(f)."""
    r = m.response(freq_mhz * 1e6, 0.0)
    return -C_DEV / (4 * math.pi * freq_mhz * 1e-3) * math.atan2(r.imag, r.real)


# ------------------------------------------------------------------------------------------------
# Spec model, computed here (section 3 and 4)
# ------------------------------------------------------------------------------------------------
def spec_rows_and_combined(
    harmonics: list[tuple[int, float]], amplitude: float, m: sim.Material, ranges: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(rows (2, n), combined (n)) for a device with the given harmonics (otherwise ideal)."""
    g = {1: 1.0 + 0j}
    g.update({h: amplitude * complex(math.cos(p), math.sin(p)) for h, p in harmonics})
    phi = 2 * math.pi * np.arange(3) / 3
    depths = []
    for f in FREQS_MHZ:
        x = 2 * math.pi * f * 1e-3 * (2 * ranges / C_TRUE)  # 2 pi f t
        z = np.zeros(ranges.shape, complex)
        for j in range(3):
            mj = np.zeros(ranges.shape)
            for h, gh in g.items():
                w = gh * np.conj(m.response(h * f * 1e6, 0.0))
                mj += np.real(w * np.exp(1j * h * (x + phi[j])))
            z += mj * np.exp(-1j * phi[j])
        phase = np.mod(np.arctan2(z.imag, z.real), 2 * math.pi)
        depths.append(C_DEV * phase / (4 * math.pi * f * 1e-3))
    d80, d16, d120 = depths
    u16 = d16
    u80 = d80 + 1875.0 * np.round((u16 - d80) / 1875.0)
    u120 = d120 + 1250.0 * np.round((u80 - d120) / 1250.0)
    comb = (80 * u80 + 16 * u16 + 120 * u120) / 216
    return np.stack([d16 - d120, d80 - d120]), comb


def spec_interp(rows: np.ndarray, comb: np.ndarray, centres: np.ndarray) -> np.ndarray:
    assert np.all(np.diff(comb) > 0), "combined depth must grow with range here"
    return np.stack([np.interp(centres, comb, r, left=np.nan, right=np.nan) for r in rows])


def spec_bin(rows: np.ndarray, comb: np.ndarray, edges: np.ndarray) -> np.ndarray:
    idx = np.searchsorted(edges, comb, side="right") - 1
    out = np.full((rows.shape[0], len(edges) - 1), np.nan)
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            out[:, b] = rows[:, sel].mean(axis=1)
    return out


# ------------------------------------------------------------------------------------------------
# Ideal device
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["interp", "bin"])
def test_opaque_material_gives_zero_rows_with_the_ideal_device(method: str) -> None:
    c = sim.distortion_curves(sim.DeviceProfile.ideal_kinect2(), [OPAQUE], BINS, 0.0, method)
    assert c.shape == (1, 2, 200)
    assert c.dtype == np.float32
    assert not np.isnan(c).any(), "every bin of 600..1203 mm is inside the 450..1400 mm sweep"
    assert np.abs(c).max() <= 1e-6  # ~1e-12 in double; float32 keeps it


@pytest.mark.parametrize("method", ["interp", "bin"])
def test_exponential_material_gives_the_closed_form_offset(method: str) -> None:
    # d(f) = D' + s(f), s(f) = -c/(4 pi f) arg R(f): rows d16 - d120 = s16 - s120 and
    # d80 - d120 = s80 - s120, constant in depth. Bound 1e-3 mm: float32 of values up to 55 mm is
    # 4e-6 mm; the shifts are exact to ~1e-12 mm.
    # A bin is NaN only where the sweep does not reach: the combined depth at 450 mm is
    # 450 * 300 / 299.79 + (80 s80 + 16 s16 + 120 s120) / 216, which passes 600 mm for "milk".
    c = sim.distortion_curves(sim.DeviceProfile.ideal_kinect2(), EXPONENTIALS, BINS, 0.0, method)
    centres = np.asarray(BINS.centres_mm)
    for m, curve in zip(EXPONENTIALS, c, strict=True):
        want = (shift_mm(m, 16.0) - shift_mm(m, 120.0), shift_mm(m, 80.0) - shift_mm(m, 120.0))
        comb_start = (
            450.0 * C_DEV / C_TRUE + (80 * shift_mm(m, 80.0) + 16 * shift_mm(m, 16.0) + 120 * shift_mm(m, 120.0)) / 216
        )
        for r in range(2):
            row = curve[r]
            reached = centres > comb_start + BINS.width_mm
            assert not np.isnan(row[reached]).any(), m.name
            assert np.isnan(row[centres < comb_start - BINS.width_mm]).all(), m.name
            ok = ~np.isnan(row)
            assert ok.mean() > 0.9
            assert np.abs(row[ok] - want[r]).max() <= 1e-3, (m.name, r, float(np.abs(row[ok] - want[r]).max()), want[r])
    # The materials span small and large distortions (the check is not of zeros).
    assert abs(shift_mm(EXPONENTIALS[3], 16.0) - shift_mm(EXPONENTIALS[3], 120.0)) > 20.0


def test_exponential_offsets_grow_with_tau() -> None:
    prev = 0.0
    for tau in (10.0, 100.0, 400.0, 1000.0):
        m = material(f"t{tau:g}", "exponential", subsurface=1.0, tau_ps=tau)
        c = sim.distortion_curves(sim.DeviceProfile.ideal_kinect2(), [m], BINS)
        v = float(np.nanmean(c[0, 0]))
        assert v > prev  # 16 MHz is delayed more (in mm) than 120 MHz
        prev = v


def test_incidence_reduces_the_distortion() -> None:
    # Oblique incidence lets less light into the material (Fresnel): a smaller subsurface share.
    m = EXPONENTIALS[0]
    dev = sim.DeviceProfile.ideal_kinect2()
    at0 = sim.distortion_curves(dev, [m], BINS, 0.0)
    at60 = sim.distortion_curves(dev, [m], BINS, 60.0)
    assert np.all(np.abs(at60) < np.abs(at0))


# ------------------------------------------------------------------------------------------------
# A device with harmonics: both methods against the spec computed here, and against each other
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("m", [OPAQUE, EXPONENTIALS[0], EXPONENTIALS[2], *OTHERS], ids=lambda m: m.name)
def test_curves_match_the_spec_model(m: sim.Material) -> None:
    # Same sweep, same decode, same unwrapping, computed independently: the curves agree to
    # float32 (values up to ~100 mm: 1e-5) and double rounding: bound 1e-3 mm.
    dev = device_with(HARMONICS)
    rows, comb = spec_rows_and_combined(HARMONICS, 0.05, m, SWEEP)
    centres, edges = np.asarray(BINS.centres_mm), np.asarray(BINS.edges_mm)
    got_i = sim.distortion_curves(dev, [m], BINS, 0.0, "interp")[0]
    got_b = sim.distortion_curves(dev, [m], BINS, 0.0, "bin")[0]
    want_i, want_b = spec_interp(rows, comb, centres), spec_bin(rows, comb, edges)
    assert np.array_equal(np.isnan(got_i), np.isnan(want_i))
    assert np.array_equal(np.isnan(got_b), np.isnan(want_b))
    assert np.nanmax(np.abs(got_i - want_i)) <= 1e-3
    assert np.nanmax(np.abs(got_b - want_b)) <= 1e-3
    if m is not OPAQUE:
        return
    assert np.nanmax(np.abs(got_i)) > 5.0  # the harmonics do distort an opaque target's rows


@pytest.mark.parametrize("m", [OPAQUE, *EXPONENTIALS, *OTHERS], ids=lambda m: m.name)
def test_interp_and_bin_agree(m: sim.Material) -> None:
    # Harmonics 2, 3, 4 of amplitude 0.05: ripples of up to ~50 mm with slopes up to ~0.3. The bin
    # mean of 12 samples has its centroid within half a step (0.125 mm) of the bin centre, so the
    # two differ by <= 0.125 mm x slope ~ 0.04 mm: bound 0.05 mm.
    dev = device_with(HARMONICS)
    a = sim.distortion_curves(dev, [m], BINS, 0.0, "interp")
    b = sim.distortion_curves(dev, [m], BINS, 0.0, "bin")
    # NaN where the sweep does not reach; at the edge of the reach a partly covered bin has a
    # mean but its centre may be outside: the masks may differ by that one bin.
    assert np.count_nonzero(np.isnan(a) != np.isnan(b)) <= 2
    assert np.isnan(a).mean() < 0.2
    assert np.nanmax(np.abs(a - b)) <= 0.05, float(np.nanmax(np.abs(a - b)))


def test_interp_and_bin_differ_by_at_most_the_slope_times_half_a_step() -> None:
    # With five harmonics of 0.05 the slopes reach ~1 and the 0.05 mm of the previous test is
    # exceeded; the difference must still be the discretisation of the bin mean:
    # |bin - interp| <= 0.15 mm x local |slope| + 0.005 mm, bin by bin.
    dev = device_with(MANY_HARMONICS)
    for m in [OPAQUE, EXPONENTIALS[0], OTHERS[0]]:
        a = sim.distortion_curves(dev, [m], BINS, 0.0, "interp")[0]
        b = sim.distortion_curves(dev, [m], BINS, 0.0, "bin")[0]
        slope = np.abs(np.diff(a, axis=1)) / BINS.width_mm
        local = np.maximum(np.pad(slope, ((0, 0), (1, 0)), mode="edge"), np.pad(slope, ((0, 0), (0, 1)), mode="edge"))
        diff = np.abs(a - b)
        ok = ~np.isnan(diff)
        assert np.all(diff[ok] <= 0.15 * local[ok] + 0.005), m.name


def test_curve_argument_errors() -> None:
    dev = sim.DeviceProfile.ideal_kinect2()
    with pytest.raises(ValueError, match="method"):
        sim.distortion_curves(dev, [OPAQUE], BINS, 0.0, "median")
    out = sim.distortion_curves(dev, [], BINS)
    assert out.shape == (0, 2, 200)
