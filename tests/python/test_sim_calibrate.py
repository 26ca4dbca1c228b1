# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The shipped calibration (firmware/sim/data: kinect2_tanaka2017 + tanaka2017) against the real
database, through both implementations of the model, and the calibration tool's outputs and errors.

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
    # A parameter the simulator refuses makes the tool fail at once, not when someone renders.
    res.materials = [dict(mats[0], albedo=-1.0), *mats[1:]]
    with pytest.raises(tofmat.FormatError, match="albedo"):
        cal.write_outputs(res, tmp_path / "bad")
    assert math.isfinite(res.median_rms_mm)
