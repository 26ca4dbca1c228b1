# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The physically based Kinect v2 simulator (C++ core in firmware/sim).

Device profiles and material libraries are versioned JSON files shipped with
the package and loaded by name::

    from tofmat import sim
    device = sim.load_device("ideal_kinect2")
    library = sim.load_library("examples")
    frame = sim.Renderer(device, library).render(sim.Scene.centred_target("wax", 900.0))
"""

from __future__ import annotations

from pathlib import Path

from .._tofmat import sim as _sim

DeviceProfile = _sim.DeviceProfile
Material = _sim.Material
MaterialLibrary = _sim.MaterialLibrary
Target = _sim.Target
Scene = _sim.Scene
Frame = _sim.Frame
Renderer = _sim.Renderer
distortion_curves = _sim.distortion_curves
stage_sweep = _sim.stage_sweep

# The calibrated profile and library (kinect2_tanaka2017, tanaka2017) are not
# shipped yet; these uncalibrated ones run everywhere.
DEFAULT_DEVICE = "kinect2_tanaka2017"  # calibrated to the real database (docs/simulator.md)
DEFAULT_LIBRARY = "tanaka2017"


def data_dir() -> Path:
    """Folder holding devices/*.json and materials/*.json."""
    installed = Path(__file__).resolve().parent.parent / "sim_data"
    if installed.is_dir():
        return installed
    source = Path(__file__).resolve().parents[3] / "firmware" / "sim" / "data"  # editable install
    if source.is_dir():
        return source
    raise FileNotFoundError(f"simulator data not found (looked in {installed} and {source})")


def load_device(name_or_path: str = DEFAULT_DEVICE) -> DeviceProfile:
    """A device profile by name (data/devices/<name>.json) or path."""
    return DeviceProfile.load(name_or_path, data_dir())


def library_path(name_or_path: str) -> Path:
    """A material library's file: a path as given, or a name's data/materials/<name>.json."""
    p = Path(name_or_path)
    return p if (p.suffix or p.parent != Path(".")) else data_dir() / "materials" / f"{name_or_path}.json"


def load_library(name_or_path: str = DEFAULT_LIBRARY) -> MaterialLibrary:
    """A material library by name (data/materials/<name>.json) or path."""
    return MaterialLibrary.load(name_or_path, data_dir())


__all__ = [
    "DEFAULT_DEVICE",
    "DEFAULT_LIBRARY",
    "DeviceProfile",
    "Frame",
    "Material",
    "MaterialLibrary",
    "Renderer",
    "Scene",
    "Target",
    "data_dir",
    "distortion_curves",
    "library_path",
    "load_device",
    "load_library",
    "stage_sweep",
]
