# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Device profiles and material libraries from Python dicts (tofmat.sim.*.from_dict / to_dict).

Every malformed profile is a tofmat.FormatError (a ValueError) whose message names the key.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import pytest

import tofmat
from tofmat import sim


def minimal_device() -> dict[str, Any]:
    return {"name": "dev", "version": 1, "frequencies": [{"freq_mhz": 80.0}, {"freq_mhz": 16.0}, {"freq_mhz": 120.0}]}


def minimal_library() -> dict[str, Any]:
    return {
        "name": "lib",
        "version": 1,
        "materials": [{"name": "cork", "kind": "exponential", "albedo": 0.5, "subsurface": 0.3, "tau_ps": 200.0}],
    }


def rich_device() -> dict[str, Any]:
    d = minimal_device()
    d["name"] = "rich"
    for g, f in enumerate(d["frequencies"]):
        f.update(
            {
                "scale_error": 1e-4 * (g + 1),
                "phase_offset_rad": 0.1 + 0.37 * g,
                "step_gain": [1.01, 0.99, 1.0 + 1e-7],
                "step_offset": [0.001, -0.002, 1 / 3],
                "harmonics": [{"h": 3, "amplitude": 0.125, "phase_rad": 0.0}],
            }
        )
    d["pixel_phase"] = {
        "mean_rad": [0.1, -0.2, 0.3],
        "radial_rad": [0.01, 0.02, 1 / 7],
        "scatter_rad": 0.003,
        "seed": 12345,
    }
    d["noise"] = {"read_noise": 2.5, "shot_gain": 0.8, "ambient": 11.0}
    d["signal"] = {"counts_at_1m": 2718.28, "saturation": 16000.0}
    d["camera"] = {"width": 320, "height": 240, "fx": 250.5, "fy": 251.25, "cx": 160.125, "cy": 119.875}
    return d


def format_error(fn: Any, arg: dict[str, Any]) -> str:
    with pytest.raises(tofmat.FormatError) as e:
        fn(arg)
    return str(e.value)


def test_format_error_is_a_value_error() -> None:
    assert issubclass(tofmat.FormatError, ValueError)


# ------------------------------------------------------------------------------------------------
# Devices
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "where, key",
    [
        ((), "colour"),
        (("frequencies", 0), "freq"),
        (("frequencies", 2), "gain"),
        (("pixel_phase",), "mean"),
        (("noise",), "read"),
        (("signal",), "counts"),
        (("camera",), "w"),
    ],
)
def test_device_rejects_unknown_keys(where: tuple[Any, ...], key: str) -> None:
    d = minimal_device()
    for k in ("pixel_phase", "noise", "signal", "camera"):
        d[k] = {}
    node: Any = d
    for w in where:
        node = node[w]
    node[key] = 1
    msg = format_error(sim.DeviceProfile.from_dict, d)
    assert f"'{key}'" in msg, msg


def test_device_rejects_unknown_key_in_a_harmonic() -> None:
    d = minimal_device()
    d["frequencies"][1]["harmonics"] = [{"h": 2, "amplitude": 0.1, "phaze": 0.0}]
    assert "phaze" in format_error(sim.DeviceProfile.from_dict, d)


@pytest.mark.parametrize("version", [None, 0, 3, "1", 1.5, True])
def test_device_rejects_wrong_version(version: Any) -> None:
    d = minimal_device()
    if version is None:
        del d["version"]
    else:
        d["version"] = version
    assert "version" in format_error(sim.DeviceProfile.from_dict, d)


@pytest.mark.parametrize("name", [None, 7, ["dev"]])
def test_device_rejects_missing_or_non_string_name(name: Any) -> None:
    d = minimal_device()
    if name is None:
        del d["name"]
    else:
        d["name"] = name
    assert "name" in format_error(sim.DeviceProfile.from_dict, d)


@pytest.mark.parametrize(
    "path, value, key",
    [
        (("frequencies", 0, "freq_mhz"), "80", "freq_mhz"),
        (("frequencies", 1, "scale_error"), None, "scale_error"),
        (("frequencies", 2, "step_gain"), [1, 1], "step_gain"),
        (("frequencies", 2, "step_offset"), [0, "0", 0], "step_offset"),
        (("frequencies", 0, "harmonics"), {"h": 2}, "harmonics"),
        (("frequencies",), {"freq_mhz": 80}, "frequencies"),
        (("frequencies",), [{"freq_mhz": 80}], "frequencies"),
        (("noise",), [1.0], "noise"),
        (("noise", "read_noise"), "2", "read_noise"),
        (("signal", "counts_at_1m"), [3000], "counts_at_1m"),
        (("camera", "width"), "512", "width"),
        (("pixel_phase", "mean_rad"), 0.1, "mean_rad"),
        (("pixel_phase", "seed"), "1", "seed"),
    ],
)
def test_device_rejects_wrong_types(path: tuple[Any, ...], value: Any, key: str) -> None:
    d = minimal_device()
    for k in ("pixel_phase", "noise", "signal", "camera"):
        d[k] = {}
    node: Any = d
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    msg = format_error(sim.DeviceProfile.from_dict, d)
    assert key in msg, msg


@pytest.mark.parametrize("h", [0, 1, 33, -2, 2.5, "2", None])
def test_device_rejects_harmonic_order_outside_2_to_32(h: Any) -> None:
    d = minimal_device()
    entry: dict[str, Any] = {"amplitude": 0.1}
    if h is not None:
        entry["h"] = h
    d["frequencies"][0]["harmonics"] = [entry]
    msg = format_error(sim.DeviceProfile.from_dict, d)
    assert "harmonics" in msg and "h" in msg, msg


@pytest.mark.parametrize("h", range(2, 8))
def test_device_accepts_harmonic_orders_2_to_7(h: int) -> None:
    d = minimal_device()
    d["frequencies"][0]["harmonics"] = [{"h": h, "amplitude": 0.1, "phase_rad": 0.0}]
    out = sim.DeviceProfile.from_dict(d).to_dict()
    amps = {e["h"]: e["amplitude"] for e in out["frequencies"][0]["harmonics"]}
    assert amps[h] == 0.1
    assert all(a == 0.0 for k, a in amps.items() if k != h)


def test_device_rejects_non_finite_numbers() -> None:
    d = minimal_device()
    d["noise"] = {"read_noise": math.nan}
    with pytest.raises(tofmat.FormatError):
        sim.DeviceProfile.from_dict(d)


def test_ideal_device_round_trips() -> None:
    ideal = sim.DeviceProfile.ideal_kinect2()
    d = ideal.to_dict()
    assert d["name"] == "ideal_kinect2"
    assert [f["freq_mhz"] for f in d["frequencies"]] == [80.0, 16.0, 120.0]
    assert sim.DeviceProfile.from_dict(d).to_dict() == d
    json.dumps(d)  # plain JSON types


def test_device_dict_round_trip_is_exact() -> None:
    d = rich_device()
    once = sim.DeviceProfile.from_dict(d).to_dict()
    twice = sim.DeviceProfile.from_dict(copy.deepcopy(once)).to_dict()
    assert twice == once
    # The values given come back unchanged.
    assert once["pixel_phase"] == d["pixel_phase"]
    assert once["noise"] == d["noise"]
    assert once["signal"] == d["signal"]
    assert once["camera"] == d["camera"]
    for a, b in zip(once["frequencies"], d["frequencies"], strict=True):
        for k in ("freq_mhz", "scale_error", "phase_offset_rad", "step_gain", "step_offset"):
            assert a[k] == b[k], k


def test_device_dict_round_trip_of_general_harmonics_is_exact() -> None:
    # Harmonics are stored as (amplitude, phase) and rebuilt with std::polar: what to_dict gives
    # must come back unchanged through from_dict (a fixed point), for general phases too.
    d = minimal_device()
    for g, f in enumerate(d["frequencies"]):
        f["harmonics"] = [
            {"h": h, "amplitude": 0.01 + 0.013 * (h + g), "phase_rad": -3.0 + 0.37 * (h + 6 * g)} for h in range(2, 8)
        ]
    once = sim.DeviceProfile.from_dict(d).to_dict()
    twice = sim.DeviceProfile.from_dict(copy.deepcopy(once)).to_dict()
    assert twice == once
    for a, b in zip(once["frequencies"], d["frequencies"], strict=True):
        for ea, eb in zip(a["harmonics"], b["harmonics"], strict=True):
            assert ea["amplitude"] == pytest.approx(eb["amplitude"], rel=1e-15)
            assert ea["phase_rad"] == pytest.approx(eb["phase_rad"], rel=1e-15, abs=1e-15)


def test_device_seed_round_trips_all_64_bits() -> None:
    d = rich_device()
    for seed in (0, 2**53 + 1, 0xDEADBEEFCAFEF00D, 2**64 - 1):
        d["pixel_phase"]["seed"] = seed
        assert sim.DeviceProfile.from_dict(d).to_dict()["pixel_phase"]["seed"] == seed, hex(seed)


# ------------------------------------------------------------------------------------------------
# Materials and libraries
# ------------------------------------------------------------------------------------------------
def test_library_rejects_unknown_keys() -> None:
    lib = minimal_library()
    lib["materialz"] = []
    assert "materialz" in format_error(sim.MaterialLibrary.from_dict, lib)
    lib = minimal_library()
    lib["materials"][0]["colour"] = "red"
    msg = format_error(sim.MaterialLibrary.from_dict, lib)
    assert "colour" in msg and "materials[0]" in msg
    assert "colour" in format_error(sim.Material.from_dict, {"name": "a", "kind": "opaque", "colour": 1})


@pytest.mark.parametrize(
    "change, key",
    [
        (lambda d: d.pop("version"), "version"),
        (lambda d: d.update(version=3), "version"),
        (lambda d: d.pop("name"), "name"),
        (lambda d: d.update(name=3), "name"),
        (lambda d: d.update(materials={}), "materials"),
        (lambda d: d.update(materials=[]), "materials"),
        (lambda d: d["materials"][0].pop("name"), "name"),
        (lambda d: d["materials"][0].pop("kind"), "kind"),
        (lambda d: d["materials"][0].update(kind="glossy"), "kind"),
        (lambda d: d["materials"][0].update(albedo="0.5"), "albedo"),
        (lambda d: d["materials"][0].update(tau_ps=None), "tau_ps"),
        (lambda d: d["materials"][0].update(albedo=10.5), "albedo"),
        (lambda d: d["materials"][0].update(tau_ps=0.0), "tau_ps"),
        (lambda d: d["materials"].append(dict(d["materials"][0])), "duplicate"),
    ],
)
def test_library_rejects(change: Any, key: str) -> None:
    lib = minimal_library()
    change(lib)
    msg = format_error(sim.MaterialLibrary.from_dict, lib)
    assert key in msg, msg


def test_material_and_library_round_trip() -> None:
    mats = [
        {"name": "o", "kind": "opaque", "albedo": 0.1},
        {"name": "e", "kind": "exponential", "albedo": 0.3, "subsurface": 1 / 3, "tau_ps": 123.456},
        {"name": "g", "kind": "gamma", "albedo": 0.5, "subsurface": 0.9, "tau_ps": 77.0, "gamma_k": 2 / 3},
        {
            "name": "s",
            "kind": "slab",
            "albedo": 0.7,
            "subsurface": 1.0,
            "tau_ps": 10.0,
            "refractive_index": 1 + 1 / 7,
            "thickness_mm": 0.1,
            "path_factor": 1.5,
            "backing": 0.7,
        },
    ]
    lib = sim.MaterialLibrary.from_dict({"name": "lib", "version": 1, "materials": mats})
    assert lib.names == ["o", "e", "g", "s"]
    assert len(lib) == 4
    d = lib.to_dict()
    for given, out in zip(mats, d["materials"], strict=True):
        for k, v in given.items():
            assert out[k] == v, (given["name"], k)
    assert sim.MaterialLibrary.from_dict(d).to_dict() == d
    for m in mats:
        one = sim.Material.from_dict(m)
        assert sim.Material.from_dict(one.to_dict()).to_dict() == one.to_dict()
        assert one.kind == m["kind"]
    assert lib["g"].name == "g"
    with pytest.raises(ValueError):
        lib["marble"]


def test_load_by_path_reports_the_file(tmp_path: Path) -> None:
    bad = minimal_device()
    bad["bogus"] = 1
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(bad))
    with pytest.raises(tofmat.FormatError) as e:
        sim.DeviceProfile.load(str(p), tmp_path)
    assert "bad.json" in str(e.value) and "bogus" in str(e.value)
    (tmp_path / "devices").mkdir()
    (tmp_path / "devices" / "good.json").write_text(json.dumps(minimal_device()))
    assert sim.DeviceProfile.load("good", tmp_path).name == "dev"
    with pytest.raises(OSError):
        sim.DeviceProfile.load("missing", tmp_path)
