# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The C++ simulator and the calibration's NumPy model compute the same forward model.

docs/simulator-model.md is the contract; the calibration fits parameters with
tofmat.sim.model_np and the shipped profiles are rendered by the C++ simulator, so every model
term (harmonics up to h = 32, signal scales, tap full-well saturation, decode offsets, the double
kernel, the noise-wrap expectation of section 4.1) must give the same curves in both. A device with
every term switched on is compared curve by curve, for every material kind.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

import tofmat
from tofmat import sim
from tofmat.sim import model_np as M

BINS = (600.0, 600.0 / 199.0, 200)  # the real database's bins (start, width, count)


def full_device(full_well: float | None = 1.0) -> dict[str, Any]:
    """A device with every term of the spec switched on, values of the calibrated magnitude."""
    rng = np.random.default_rng(7)
    drift_rng = np.random.default_rng(8)
    d: dict[str, Any] = {"name": "parity", "version": 2, "range_ref_mm": 1000.0, "saturation": {"sharpness": 12.0},
                         "frequencies": [{"freq_mhz": f, "signal_scale": r}
                                         for f, r in zip((80.0, 16.0, 120.0), M.SIGNAL_SCALE_DEFAULT, strict=True)]}  # fmt: skip
    for g, grp in enumerate(d["frequencies"]):
        grp["harmonics"] = [
            {"h": h, "amplitude": 0.0 if h % 3 == 0 else float(rng.uniform(0.005, 0.08)),
             "phase_rad": float(rng.uniform(-math.pi, math.pi))}
            for h in range(2, 14)
        ]  # fmt: skip
        grp["scale_error"] = [-0.004, 0.001, 0.0][g]
        grp["phase_offset_rad"] = [0.3, -0.2, 0.0][g]
        grp["decode_offset_rad"] = [0.09, -0.01, -0.08][g]
        grp["step_gain"] = [1.0, float(rng.uniform(0.95, 1.05)), float(rng.uniform(0.95, 1.05))]
        grp["step_offset"] = [0.0, float(rng.uniform(-0.05, 0.05)), float(rng.uniform(-0.05, 0.05))]
        grp["full_well"] = full_well
        grp["session_drift"] = [  # (its own generator: the device's other terms stay as they were)
            {"h": h, "amplitude": float(drift_rng.uniform(0.002, 0.02)),
             "phase_rad": float(drift_rng.uniform(-math.pi, math.pi))}
            for h in (2, 4, 5, 7, 11)
        ]  # fmt: skip
    return d


MATERIALS: list[dict[str, Any]] = [
    {"name": "metal", "kind": "opaque", "albedo": 0.9},
    {"name": "wax", "kind": "exponential", "albedo": 0.35, "subsurface": 0.7, "tau_ps": 170.0},
    {"name": "felt", "kind": "gamma", "albedo": 0.3, "subsurface": 0.9, "tau_ps": 460.0, "gamma_k": 2.5},
    {"name": "acrylic", "kind": "gamma", "albedo": 0.33, "subsurface": 0.65, "tau_ps": 1290.0, "gamma_k": 0.46},
    {"name": "sheet", "kind": "slab", "albedo": 0.32, "subsurface": 0.53, "tau_ps": 1320.0,
     "refractive_index": 1.49, "thickness_mm": 2.0, "path_factor": 311.0, "backing": 0.99},
    {"name": "wood", "kind": "double", "albedo": 0.37, "subsurface": 0.45, "tau_ps": 172.0,
     "subsurface2": 0.02, "tau2_ps": 3000.0},
    {"name": "leather", "kind": "gamma", "albedo": 0.56, "subsurface": 0.6, "tau_ps": 620.0, "gamma_k": 1.9,
     "noise_mm": 36.0},
]  # fmt: skip


def cpp_curves(device: dict[str, Any], mats: list[dict[str, Any]], method: str) -> np.ndarray:
    dev = sim.DeviceProfile.from_dict(device)
    ms = [sim.Material.from_dict(m) for m in mats]
    return np.asarray(sim.distortion_curves(dev, ms, tofmat.BinSpec(*BINS), 0.0, method), float)


@pytest.mark.parametrize("full_well", [None, 1.0, 0.3])
@pytest.mark.parametrize("method", ["interp", "bin"])
def test_curves_match_the_numpy_model(full_well: float | None, method: str) -> None:
    device = full_device(full_well)
    got = cpp_curves(device, MATERIALS, method)
    for i, m in enumerate(MATERIALS):
        want = M.curve(device, m, BINS, method)
        if method == "interp" and full_well == 0.3:
            # hard saturation folds the combined depth back on itself for some materials; the two
            # interpolations order such a sweep differently (sort vs walk): compare bin means only
            continue
        assert np.array_equal(np.isnan(want), np.isnan(got[i])), m["name"]
        if full_well != 0.3:
            assert np.isfinite(want).all(), m["name"]
        # the C++ curves are float32: ~2e-5 mm at 300 mm
        err = np.nanmax(np.abs(got[i] - want))
        assert err < 1e-4, f"{m['name']}: worst {err:.2e} mm"


@pytest.mark.parametrize("state", [(0.0, 0.0, 0.0), (1.5, -2.0, 0.7), (-3.0, 0.0, 2.5)])
def test_sessions_match_the_numpy_model(state: tuple[float, float, float]) -> None:
    """Section 2.2: a session moves G_h by t_f dG_h; both implementations give the same device
    and the same curves in it."""
    device = full_device(0.6)
    cpp_dev = sim.DeviceProfile.from_dict(device).in_session(state)
    np_dev = M.in_session(device, state)
    for g_cpp, g_np in zip(cpp_dev.to_dict()["frequencies"], np_dev["frequencies"], strict=True):
        assert "session_drift" not in g_cpp and "session_drift" not in g_np
        np.testing.assert_allclose(M.harmonic_vector(g_cpp, 13), M.harmonic_vector(g_np, 13), atol=1e-15)
    ms = [sim.Material.from_dict(m) for m in MATERIALS]
    got = np.asarray(sim.distortion_curves(cpp_dev, ms, tofmat.BinSpec(*BINS), 0.0, "bin"), float)
    for i, m in enumerate(MATERIALS):
        want = M.curve(device, m, BINS, "bin", session=state)
        assert np.nanmax(np.abs(got[i] - want)) < 1e-4, m["name"]
    if state == (0.0, 0.0, 0.0):  # the nominal waveform: the device as it is
        assert np.array_equal(got, cpp_curves(device, MATERIALS, "bin"), equal_nan=True)
    else:  # the waveform moved: so do the curves
        assert np.nanmax(np.abs(got - cpp_curves(device, MATERIALS, "bin"))) > 0.05


def test_session_states_are_checked() -> None:
    device = full_device()
    for bad in [(0.0, math.nan, 0.0), (math.inf, 0.0, 0.0)]:
        with pytest.raises(ValueError, match="finite"):
            sim.DeviceProfile.from_dict(device).in_session(bad)
        with pytest.raises(ValueError, match="finite"):
            M.in_session(device, bad)
    with pytest.raises(ValueError, match="three"):
        M.in_session(device, (1.0, 2.0))
    with pytest.raises(TypeError):
        sim.DeviceProfile.from_dict(device).in_session((1.0, 2.0))


def test_every_term_changes_the_curves() -> None:
    """The parity above would be vacuous if a term were ignored by both: each one moves the curves."""
    base = full_device(0.6)
    ref = cpp_curves(base, MATERIALS, "bin")
    edits = {
        "harmonic 13": lambda d: d["frequencies"][2]["harmonics"][-1].update(amplitude=0.0),
        "decode offset": lambda d: d["frequencies"][1].update(decode_offset_rad=0.0),
        "signal scale": lambda d: d["frequencies"][1].update(signal_scale=0.5),
        "full well": lambda d: d["frequencies"][1].update(full_well=None),
        "sharpness": lambda d: d["saturation"].update(sharpness=4.0),
        "range_ref_mm": lambda d: d.update(range_ref_mm=800.0),
    }
    for name, edit in edits.items():
        d = copy.deepcopy(base)
        edit(d)
        got = cpp_curves(d, MATERIALS, "bin")
        moved = np.nanmax(np.abs(got - ref))
        assert moved > 0.05, f"{name} moved the curves by only {moved:.3g} mm"
        want = np.stack([M.curve(d, m, BINS, "bin") for m in MATERIALS])
        assert np.nanmax(np.abs(got - want)) < 1e-4, name


def test_noise_wrap_pulls_the_wrapped_means_inwards() -> None:
    """Section 4.1: with per-sample noise the averaged 120 MHz depth is pulled down near its 1250 mm
    wrap (both rows rise at the far end by the same amount), and the 16 MHz depth (sigma 270 mm for
    36 mm at 120 MHz) is pulled up near its 0 wrap (row 0 rises at the near end); row 1 away from the
    ends does not move."""
    device = full_device(None)
    quiet = dict(MATERIALS[-1], noise_mm=0.0)
    a, b = cpp_curves(device, [quiet, MATERIALS[-1]], "interp")
    far = slice(190, 200)  # 1173..1200 mm
    assert np.all(b[:, far] - a[:, far] > 1.0)
    assert np.allclose(b[1, far] - a[1, far], (b[0, far] - a[0, far]) - (b[0, 150] - a[0, 150]), atol=0.05)
    near = b[0, :20] - a[0, :20]  # 16 MHz pulled up near its 0 wrap: 0.3 mm at 600 mm, fading
    assert np.all(near > 0.1) and np.all(np.diff(near) < 0)
    assert np.nanmax(np.abs(b[1, 20:150] - a[1, 20:150])) < 1e-3


def test_rendered_samples_follow_the_tap_model() -> None:
    """A noise-free rendered pixel equals the spec's taps (section 3.1), scaled to counts."""
    device = full_device(0.5)
    device.update({"camera": {"width": 64, "height": 48, "fx": 365.0, "fy": 365.0, "cx": 32.0, "cy": 24.0},
                   "signal": {"counts_at_1m": 3000.0, "saturation": 16320.0}})  # fmt: skip
    mat = MATERIALS[2]
    lib = sim.MaterialLibrary.from_dict({"name": "lib", "version": 2, "materials": [mat]})
    r = sim.Renderer(sim.DeviceProfile.from_dict(device), lib)
    for depth in (700.0, 1000.0, 1150.0):
        t = sim.Target(mat["name"], depth, rect=(0, 0, 64, 48))
        f = r.render(sim.Scene([t]), seed=0, noise=False)
        y, x = 23, 31  # the ray closest to the axis
        rng = float(f.range_mm[y, x])
        cos_inc = depth / rng  # a plane facing the camera: incidence = the ray's angle
        A = cos_inc * (M.RANGE_REF_MM / rng) ** 2
        dev = M.device_arrays(device)
        Rh = M.material_harmonic_responses(mat, dev, math.acos(cos_inc))
        pp = r.pixel_phase()[:, y, x].astype(float)
        m = np.stack([
            M.raw_samples_core(dev["f"][g:g + 1], dev["s"][g:g + 1], dev["delta"][g:g + 1], dev["G"][g:g + 1],
                               dev["gain"][g:g + 1], dev["offset"][g:g + 1], Rh[g:g + 1], np.array([rng]), A,
                               pp[g], dev["scale"][g:g + 1], dev["full_well"][g:g + 1], float(dev["sat_p"]))[0, :, 0]
            for g in range(3)
        ]) * 3000.0  # fmt: skip
        raw = f.raw[:, y, x].reshape(3, 3).astype(float)
        # nearest 11-bit code: spacing 2..64 counts; the waveform and saturation tables err < 0.1 count
        tol = np.maximum(1.0, np.abs(m) / 256.0) + 0.1
        assert np.all(np.abs(raw - m) <= tol), (depth, raw, m)
        assert np.max(np.abs(m)) > 100.0
