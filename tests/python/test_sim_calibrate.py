# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The shipped calibration (firmware/sim/data: kinect2_tanaka2017 + tanaka2017) against the real
database, through both implementations of the model, the calibration tool's outputs and errors, and
the calibration itself on a small synthetic problem whose parameters are known.

The figures recorded in the files' "fit" blocks (and quoted in docs/simulator.md) must be what the
shipped parameters actually give: recomputed here from the real curves, with the NumPy model the fit
used and with the C++ simulator that renders frames.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

import tofmat
from tofmat import sim
from tofmat.cli import main
from tofmat.sim import calibrate as cal
from tofmat.sim import model_np

DATA = Path(__file__).resolve().parents[2] / "firmware" / "sim" / "data"


def shipped() -> tuple[dict[str, Any], dict[str, Any]]:
    dev = json.loads((DATA / "devices" / "kinect2_tanaka2017.json").read_text())
    lib = json.loads((DATA / "materials" / "tanaka2017.json").read_text())
    return dev, lib


@pytest.fixture(scope="module")
def real(db_dir: Path) -> tuple[np.ndarray, list[str], tuple[float, float, int]]:
    return cal._table_arrays(tofmat.ExemplarTable.from_npy_dir(db_dir))


def test_shipped_library_covers_the_database_and_loads(real: Any) -> None:
    _, names, _ = real
    dev, lib = shipped()
    assert dev["noise"]["read_noise"] > 0 and dev["noise"]["shot_gain"] > 0  # renders with noise
    assert sorted(m["name"] for m in lib["materials"]) == sorted(names)
    assert lib["device"] == dev["name"]
    assert sim.load_device("kinect2_tanaka2017").name == "kinect2_tanaka2017"
    assert len(sim.load_library("tanaka2017")) == 29


def test_recorded_rms_is_what_the_shipped_parameters_give(real: Any) -> None:
    Y, names, bins = real
    dev, lib = shipped()
    mats = {m["name"]: m for m in lib["materials"]}
    offsets = {n: mats[n]["fit"]["offsets_mm"] for n in names}
    # every capture's session state (spec 2.2): the shipped device drifts in every group
    sessions = {n: mats[n]["fit"]["session"] for n in names}
    assert all(len(t) == 3 and all(math.isfinite(x) for x in t) for t in sessions.values())
    assert all(g.get("session_drift") for g in dev["frequencies"])
    numpy_curves = cal.simulated_curves(dev, [mats[n] for n in names], offsets, bins, "bin", sessions=sessions)
    rms = cal.rms_per_material(numpy_curves, Y)
    for n, r in zip(names, rms, strict=True):
        assert r == pytest.approx(mats[n]["fit"]["rms_mm"], abs=1e-6), n
    assert float(np.median(rms)) == pytest.approx(dev["fit"]["median_rms_mm"], abs=1e-6)
    # the states carry part of the fit: the nominal waveform alone fits worse
    nominal = cal.rms_per_material(cal.simulated_curves(dev, [mats[n] for n in names], offsets, bins, "bin"), Y)
    assert float(np.median(nominal)) > float(np.median(rms)) + 0.05

    # The C++ simulator (what renders frames) gives the same curves: within float32 rounding.
    device = sim.load_device("kinect2_tanaka2017")
    library = sim.load_library("tanaka2017")
    cpp = np.stack([
        np.asarray(sim.distortion_curves(device.in_session(tuple(sessions[n])), [library[n]],
                                         tofmat.BinSpec(*bins), 0.0, "bin"), float)[0]
        for n in names
    ])  # fmt: skip
    cpp += np.array([offsets[n] for n in names])[:, :, None]
    rms_cpp = cal.rms_per_material(cpp, Y)
    assert np.max(np.abs(rms_cpp - rms)) < 1e-3


def test_calibrate_cli_rejects_bad_input(tmp_path: Path) -> None:
    r = CliRunner().invoke(main, ["sim", "calibrate", "--db", str(tmp_path / "missing")])
    assert r.exit_code == 2 and "does not exist" in r.output
    r = CliRunner().invoke(main, ["sim", "calibrate", "--db", str(tmp_path), "--restarts", "0"])
    assert r.exit_code == 2 and "'--restarts': 0 is not in the range 1<=x<=100" in r.output
    r = CliRunner().invoke(main, ["sim", "calibrate", "--db", str(tmp_path)])
    assert r.exit_code == 2 and "Error: " in r.output and "Traceback" not in r.output
    (tmp_path / "bad.npy").write_bytes(b"\x93NUMPY garbage")
    r = CliRunner().invoke(main, ["sim", "calibrate", "--db", str(tmp_path)])
    assert r.exit_code == 2 and "Error: " in r.output and "Traceback" not in r.output


def test_write_outputs_gives_files_the_simulator_loads(tmp_path: Path) -> None:
    dev, lib = shipped()
    mats = [{k: v for k, v in m.items() if k != "fit"} for m in lib["materials"]]
    res = cal.CalibrationResult(
        device={k: v for k, v in dev.items() if k not in ("fit", "notes", "camera", "noise", "pixel_phase", "signal")},
        materials=mats,
        offsets_mm={m["name"]: m["fit"]["offsets_mm"] for m in lib["materials"]},
        rms_mm={m["name"]: m["fit"]["rms_mm"] for m in lib["materials"]},
        rms_interp_mm={m["name"]: m["fit"]["rms_interp_mm"] for m in lib["materials"]},
        median_rms_mm=dev["fit"]["median_rms_mm"],
        runtime_s=1.0,
        config=cal.CalibrationConfig(),
        log=["test"],
        sessions={m["name"]: m["fit"]["session"] for m in lib["materials"]},
    )
    paths = cal.write_outputs(res, tmp_path)
    d = sim.DeviceProfile.load(paths["device"], str(tmp_path))
    m = sim.MaterialLibrary.load(paths["materials"], str(tmp_path))
    assert d.name == "kinect2_tanaka2017" and len(m) == len(mats)
    # the blocks the fit does not determine come from the ideal profile: never a noise-free device
    written_dev = json.loads(Path(paths["device"]).read_text())
    ideal = json.loads((DATA / "devices" / "ideal_kinect2.json").read_text())
    for k in ("camera", "noise", "pixel_phase", "signal"):
        assert written_dev[k] == ideal[k], k
    written = json.loads(Path(paths["materials"]).read_text())
    assert written["version"] == 2 and all("rms_mm" in x["fit"] for x in written["materials"])
    assert [x["fit"]["session"] for x in written["materials"]] == [m["fit"]["session"] for m in lib["materials"]]
    assert [g.get("session_drift") for g in written_dev["frequencies"]] == [
        g.get("session_drift") for g in dev["frequencies"]
    ]
    assert Path(paths["log"]).read_text().strip() == "test"
    assert written_dev["fit"]["config"] == cal.CalibrationConfig().to_dict()  # the run's settings, recorded
    # A parameter the simulator refuses makes the tool fail at once, not when someone renders.
    res.materials = [dict(mats[0], albedo=-1.0), *mats[1:]]
    with pytest.raises(tofmat.FormatError, match="albedo"):
        cal.write_outputs(res, tmp_path / "bad")
    assert math.isfinite(res.median_rms_mm)


def test_calibrate_cli_builds_the_config(db_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`tofmat sim calibrate` turns its options into a CalibrationConfig and passes a progress callback."""
    seen: dict[str, Any] = {}

    class Stop(Exception):
        pass

    def fake(table: Any, *, config: cal.CalibrationConfig, progress: Any) -> None:
        seen.update(config=config, progress=progress, n=len(table.materials))
        raise Stop

    monkeypatch.setattr(cal, "calibrate", fake)
    args = ["sim", "calibrate", "--db", str(db_dir), "--out", str(tmp_path), "--restarts", "5", "--rounds", "1"]
    CliRunner().invoke(main, [*args, "--seed", "7", "--no-session-drift"])
    assert seen["config"] == cal.CalibrationConfig(restarts=5, rounds=1, seed=7, session_drift=False)
    assert seen["n"] == 29 and callable(seen["progress"])
    assert not hasattr(cal, "main")  # one command line: `tofmat sim calibrate`


def test_calibration_config_rejects_bad_settings() -> None:
    for bad in ({"restarts": 0}, {"group_hmax": (7, 40, 7)}, {"fit_grid": (1400.0, 450.0, 3.0)}, {"joint_passes": ()}):
        with pytest.raises(ValueError, match="CalibrationConfig"):
            cal.CalibrationConfig(**bad)
    assert cal.CalibrationConfig().to_dict()["group_hmax"] == [19, 32, 19]


# ---------------------------------------------------------------------------------------------
# The calibration on a synthetic problem with known parameters
# ---------------------------------------------------------------------------------------------
# Six materials rendered by the model (model_np, through the same state <-> JSON mapping the fit
# uses) from chosen device and material parameters, in the database's bins and 'bin' mode (the
# fit itself works in 'interp' mode on a 3 mm sweep: a model error of ~0.01 mm), without noise.
# Three near-opaque materials give the stage-1 device fit its typical median curve, two
# translucent ones its translucent pseudo-curve (the pipeline's design for the real database).
SYN_BINS = (600.0, 600.0 / 199.0, 200)
SYN_MATERIALS = {  # name: kind, subsurface b, tau_ps, gamma_k, albedo
    "tile": ("exponential", 0.10, 300.0, 1.0, 0.40),
    "wood": ("exponential", 0.08, 600.0, 1.0, 0.40),
    "paper": ("exponential", 0.45, 450.0, 1.0, 0.35),
    "foam": ("gamma", 0.85, 650.0, 2.2, 0.30),
    "glass": ("exponential", 0.60, 900.0, 1.0, 0.35),
    "resin": ("exponential", 0.42, 2000.0, 1.0, 0.42),
}
SYN_HARMONICS = {  # group (80, 16, 120 MHz) -> harmonic -> (amplitude, phase rad); the others 0
    0: {2: (0.043, 0.12), 4: (0.045, -0.13), 5: (0.039, 1.52), 7: (0.032, 1.40)},
    1: {2: (0.050, 1.65), 4: (0.040, -0.76), 5: (0.058, -2.50), 7: (0.043, -1.45)},
    2: {2: (0.045, 2.68), 4: (0.015, 1.72), 5: (0.045, -3.02), 7: (0.023, -3.13)},
}
SYN_FULL_WELL = (0.9, 1.0, 0.68)  # W_80, W_16 (= 1: the albedo's unit), W_120: every group saturates
SYN_SHARPNESS = 20.0
SYN_OFFSETS = {"tile": (1.0, -0.5), "wood": (-0.5, 0.2), "paper": (-2.0, 0.3), "foam": (0.5, 0.8),
               "glass": (3.0, -1.0), "resin": (-3.0, -0.6)}  # fmt: skip
# A small run: harmonics to h = 7, two restarts, two rounds (the second chooses every kind again
# against the refined device: the first round's choice is made against the stage-1 device only).
# Joint passes of 150 evaluations: the assertions below hold over the seeds 0-3 (worst: albedo
# 3.3 % off (paper), 80/120 MHz harmonics 0.0007 off, median rms 0.014 mm; measured with
# tofmat.sim.calibrate on this problem, seed varied), so another CPU's roundoff, which can send the
# fit down another restart's path, stays inside them. With 60 evaluations seeds 1-3 ended at 4.2-5.2 %
# (paper's albedo) and a CI machine at 5.3 % (foam's) and 0.0054.
# Session drift off: with one capture per material a session state cannot be told from the
# material (docs/simulator.md). Step gains, step offsets and scale errors stay at their ideal
# values: free, they trade with the near-opaque materials' kernels (tile's b goes 0.1 -> 0.3 at
# the same 0.02 mm curve rms), a near-gauge that six curves do not resolve.
SYN_CONFIG = cal.CalibrationConfig(
    restarts=2, rounds=2, kind_cycles=1, seed=0, group_hmax=(7, 7, 7), session_drift=False,
    joint_passes=(2, 2), joint_nfev=150, joint_step_gains=False, joint_step_offsets=False,
    joint_scale_errors=False, ridge=1.0,
)  # fmt: skip


def synthetic_truth() -> tuple[dict[str, Any], list[dict[str, Any]]]:
    names = list(SYN_MATERIALS)
    st = cal._default_state(names)
    for g, hs in SYN_HARMONICS.items():
        for h, (a, p) in hs.items():
            st[("hx", g, h)], st[("hy", g, h)] = a * math.cos(p), a * math.sin(p)
    for g, w in enumerate(SYN_FULL_WELL):
        st[("lw", g)] = math.log10(w)
    st[("satp",)] = SYN_SHARPNESS
    for i, (_, b, tau, k, albedo) in enumerate(SYN_MATERIALS.values()):
        st[("b", i)], st[("lt", i)], st[("lk", i)], st[("lr", i)] = (
            b,
            math.log10(tau),
            math.log10(k),
            math.log10(albedo),
        )
    device = cal.state_to_device(st, SYN_CONFIG, "synthetic")
    materials = [cal.state_to_material(st, i, n, m[0], SYN_CONFIG) for i, (n, m) in enumerate(SYN_MATERIALS.items())]
    return device, materials


@pytest.fixture(scope="module")
def synthetic() -> tuple[dict[str, Any], list[dict[str, Any]], cal.CalibrationResult, list[Any]]:
    device, materials = synthetic_truth()
    offsets = {n: list(o) for n, o in SYN_OFFSETS.items()}
    Y = cal.simulated_curves(device, materials, offsets, SYN_BINS, "bin")
    table = tofmat.ExemplarTable(list(SYN_MATERIALS), Y, tofmat.BinSpec(*SYN_BINS), [(16, 120), (80, 120)])
    calls: list[Any] = []
    result = cal.calibrate(table, config=SYN_CONFIG, progress=lambda d, t, w: calls.append((d, t, w)))
    return device, materials, result, calls


def test_synthetic_calibration_fits_the_curves(synthetic: Any) -> None:
    _, _, res, calls = synthetic
    assert res.config is SYN_CONFIG and res.log[0].endswith("config: " + json.dumps(SYN_CONFIG.to_dict()))
    assert all(r < 0.05 for r in res.rms_mm.values()), res.rms_mm  # 'bin' mode, against the curves
    assert res.median_rms_mm < 0.03
    # the progress protocol: every step counted, the total known from the start
    total = cal.calibration_steps(SYN_CONFIG, len(SYN_MATERIALS))
    assert [c[0] for c in calls] == list(range(1, total + 1)) and {c[1] for c in calls} == {total}


def test_synthetic_calibration_recovers_the_materials(synthetic: Any) -> None:
    _, truth, res, _ = synthetic
    fitted = {m["name"]: m for m in res.materials}
    for t in truth:
        f = fitted[t["name"]]
        # the kind: the true one, or for an exponential the gamma kernel near k = 1 (which is the
        # exponential; the kind rule keeps the gamma when it fitted 3 % better before the last
        # joint passes)
        if t["kind"] == "exponential" and f["kind"] == "gamma":
            assert 0.8 < f["gamma_k"] < 1.25, (t["name"], f["gamma_k"])
        else:
            assert f["kind"] == t["kind"], (t["name"], f["kind"])
        # the albedo (seen through the taps' saturation, in units of the 16 MHz full well)
        assert f["albedo"] == pytest.approx(t["albedo"], rel=0.05), t["name"]
        if t["subsurface"] >= 0.4:  # a strong subsurface term: b and tau (and gamma's k)
            assert f["subsurface"] == pytest.approx(t["subsurface"], abs=0.05), t["name"]
            assert f["tau_ps"] == pytest.approx(t["tau_ps"], rel=0.1), t["name"]
            if t["kind"] == "gamma":
                assert f["gamma_k"] == pytest.approx(t["gamma_k"], rel=0.1), t["name"]
        else:
            # near-opaque (b <= 0.1, omega tau < 1 at most harmonics): the kernel is close to a pure
            # delay b tau, which moves the three depths alike (the rows hardly change); b and tau
            # themselves trade at ~0.01 mm of curve (tile came out at b 0.095-0.51, tau 68-341 ps over
            # the seeds 0-3). What is identifiable is a short mean delay: near-opaque.
            assert f["subsurface"] * f["tau_ps"] < 100.0, (t["name"], f["subsurface"], f["tau_ps"])


def test_synthetic_calibration_recovers_the_device(synthetic: Any) -> None:
    truth, _, res, _ = synthetic
    for f_mhz, w in zip((80.0, 16.0, 120.0), SYN_FULL_WELL, strict=True):
        assert model_np._group(res.device, f_mhz)["full_well"] == pytest.approx(w, rel=0.05), f_mhz
    assert res.device["saturation"]["sharpness"] == pytest.approx(SYN_SHARPNESS, rel=0.1)
    # 80 and 120 MHz harmonics, each within 0.005 of the true complex G_h (amplitudes 0.015-0.045).
    # At 16 MHz the pairs h = 3k - 1, 3k + 1 alias onto the same frequency of the decoded phase and
    # the kernels barely tell them apart (h f <= 112 MHz): moving both by the same amount is a
    # near-null direction of the fit (singular values 1e-4..5e-3 of the largest at the truth), so
    # they are not asserted one by one.
    for f_mhz in (80.0, 120.0):
        got = model_np.harmonic_vector(model_np._group(res.device, f_mhz), 7)
        want = model_np.harmonic_vector(model_np._group(truth, f_mhz), 7)
        assert np.max(np.abs(got - want)) < 0.005, (f_mhz, np.round(got - want, 4))
