# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The camera's intrinsics from the device to the SDK, depth images as points, and `tofmat snapshot`
(label and depth PNGs, a PLY point cloud read back with trimesh, a reader no one here wrote)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import matplotlib.image
import numpy as np
import pytest
import trimesh
from conftest import Daemon

import tofmat
from tofmat.client import DepthImage
from tofmat.geometry import range_to_points
from tofmat.tools.snapshot import NO_LABEL, Snapshot, SnapshotError, write_snapshot
from tofmat.tools.snapshot import _snapshot as snapshot_of

KINECT_LIKE = tofmat.Intrinsics(365.5, 365.2, 255.5, 211.7, k1=0.09, k2=-0.27, k3=0.1, p1=0.001, p2=-0.002)
SIM = tofmat.Intrinsics(365.0, 365.0, 256.0, 212.0)  # the simulated camera's pinhole (no distortion)
REGIONS = "sim:regions,materials=acryl+cork+paper,near=700,far=1000,realtime=0"  # yaw 10 degrees
COLUMNS = ((16, 168), (180, 332), (344, 496))  # the regions scene's three targets, pixel columns
DEPTHS = (700.0, 850.0, 1000.0)


def test_undistortion_inverts_browns_model_over_the_whole_image() -> None:
    u, v = np.meshgrid(np.arange(512) + 0.5, np.arange(424) + 0.5)
    xd, yd = (u - KINECT_LIKE.cx) / KINECT_LIKE.fx, (v - KINECT_LIKE.cy) / KINECT_LIKE.fy
    x, y = KINECT_LIKE.undistort(xd, yd)
    assert np.abs(x - xd).max() > 0.01  # the corners move: the test would see a missing undistortion
    back = KINECT_LIKE.distort(x, y)
    assert np.abs(back[0] - xd).max() < 1e-9 and np.abs(back[1] - yd).max() < 1e-9


def test_points_are_ranges_along_unit_rays() -> None:
    rng = np.random.default_rng(3)
    ranges = rng.uniform(500, 4000, (24, 32)).astype(np.float32)
    ranges[5, 7] = np.nan
    pts = range_to_points(ranges, SIM, x0=100, y0=50)
    assert pts.shape == (24, 32, 3) and pts.dtype == np.float32
    assert np.isnan(pts[5, 7]).all()
    ok = np.isfinite(ranges)
    np.testing.assert_allclose(np.linalg.norm(pts, axis=-1)[ok], ranges[ok], rtol=1e-6)
    # Pinhole: the point projects back onto its pixel's centre.
    u = SIM.fx * pts[..., 0] / pts[..., 2] + SIM.cx
    v = SIM.fy * pts[..., 1] / pts[..., 2] + SIM.cy
    np.testing.assert_allclose(u[ok], (np.arange(100, 132) + 0.5)[None, :].repeat(24, 0)[ok], atol=1e-3)
    np.testing.assert_allclose(v[ok], (np.arange(50, 74) + 0.5)[:, None].repeat(32, 1)[ok], atol=1e-3)
    # With distortion, the point's projection lands where the lens puts the pixel.
    pk = range_to_points(ranges, KINECT_LIKE, x0=100, y0=50)
    xd, _ = KINECT_LIKE.distort(pk[..., 0] / pk[..., 2], pk[..., 1] / pk[..., 2])
    np.testing.assert_allclose((KINECT_LIKE.fx * xd + KINECT_LIKE.cx)[ok],
                               (np.arange(100, 132) + 0.5)[None, :].repeat(24, 0)[ok], atol=1e-3)  # fmt: skip


def test_bad_intrinsics_and_missing_ones_are_clear_errors() -> None:
    with pytest.raises(ValueError, match="focal"):
        tofmat.Intrinsics(0.0, 365.0, 256.0, 212.0)
    with pytest.raises(ValueError, match="finite"):
        tofmat.Intrinsics(365.0, 365.0, float("nan"), 212.0)
    d = DepthImage(1, 0, "combined", 0, 0, np.ones((2, 2), np.float32))
    with pytest.raises(ValueError, match="no intrinsics"):
        d.points()
    assert d.points(SIM).shape == (2, 2, 3)
    shot = Snapshot(1, "handheld", ["cork"], np.zeros((2, 2), np.uint8), d, False)
    with pytest.raises(SnapshotError, match="--intrinsics"):
        write_snapshot(shot, Path("/nonexistent/never-made"))


def test_points_take_the_corrected_depth_where_there_is_one(tmp_path: Path) -> None:
    measured = np.full((4, 6), 1000.0, np.float32)
    measured[0, 0] = np.nan
    corrected = measured - 20.0
    corrected[1, :] = np.nan  # a row the daemon did not correct (no label, or no distortion there)
    depth = DepthImage(7, 0, "combined", 250, 200, measured, intrinsics=SIM)
    labels = np.zeros((4, 6), np.uint8)
    for fix, want in ((DepthImage(7, 0, "corrected", 250, 200, corrected), 17), (None, 0)):
        out = tmp_path / ("with" if fix else "without")
        write_snapshot(Snapshot(7, "handheld", ["cork"], labels, depth, True, fix), out)
        cloud = trimesh.load(out / "points.ply")
        raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
        fixed = raw["corrected"].astype(bool)
        assert len(cloud.vertices) == 23 and fixed.sum() == want  # (the NaN pixel has no point)
        ranges = np.linalg.norm(np.asarray(cloud.vertices), axis=1)
        np.testing.assert_allclose(ranges[fixed], 980.0, rtol=1e-6)
        np.testing.assert_allclose(ranges[~fixed], 1000.0, rtol=1e-6)
        assert json.loads((out / "snapshot.json").read_text())["points_corrected"] == want
        assert matplotlib.image.imread(out / "corrected.png").ndim == 3
    bad = DepthImage(7, 0, "corrected", 250, 200, corrected[:2])
    with pytest.raises(SnapshotError, match="corrected depth"):  # (checked before the labels are read)
        snapshot_of("handheld", depth, cast(Any, None), bad)


def test_depth_images_carry_the_cameras_intrinsics(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start("sim:static,material=cork,depth=900,realtime=0")
    with d.client() as c:
        img = c.depth("combined", timeout=30)
        assert img.intrinsics == SIM
        assert img.valid.any() and img.points().shape == (*img.depth_mm.shape, 3)
    # A recording keeps them, and its replay sends them.
    rec = tmp_path / "k.tmrec"
    p = subprocess.run([sys.executable, "-m", "tofmat", "record", "--source", "sim:static,material=cork,realtime=0",
                        "-o", str(rec), "--frames", "2"], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    r = start(f"replay:{rec},loop=1", name="replay")
    with r.client() as c:
        assert c.depth("combined", timeout=30).intrinsics == SIM


def _snapshot(address: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tofmat", "snapshot", "--address", str(address), "-o", str(out),
                           "--timeout", "60", *extra], capture_output=True, text=True, timeout=120)  # fmt: skip


def test_snapshot_of_the_segmentation_profile(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start(REGIONS, "--profile", "segmentation", "--candidates", "cork,paper,acryl")
    d.client().close()  # listening
    out = tmp_path / "shot"
    p = _snapshot(d.socket, out)
    assert p.returncode == 0, p.stderr
    meta = json.loads((out / "snapshot.json").read_text())
    names = [m["name"] for m in meta["materials"]]
    assert sorted(names) == ["acryl", "cork", "paper"] and meta["simulated"] is True
    assert meta["intrinsics"]["fx"] == 365.0 and meta["region"] == {"x0": 0, "y0": 0, "width": 512, "height": 424}
    for png in ("labels.png", "depth.png", "corrected.png"):
        img = matplotlib.image.imread(out / png)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 500

    cloud = trimesh.load(out / "points.ply")
    assert isinstance(cloud, trimesh.PointCloud) and len(cloud.vertices) == meta["points"] > 50_000
    raw = cloud.metadata["_ply_raw"]["vertex"]["data"]
    labels, xyz, fixed = raw["label"], np.asarray(cloud.vertices), raw["corrected"].astype(bool)
    rgb = np.stack([raw["red"], raw["green"], raw["blue"]], axis=1)
    for m in meta["materials"]:  # every point of a label has its material's colour
        assert (rgb[labels == m["label"]] == m["rgb"]).all()
    # The table has the materials' depth distortion: every labelled point is at its corrected depth.
    assert meta["points_corrected"] == fixed.sum() == (labels != NO_LABEL).sum() > 50_000
    # Each target is a plane at the scene's yaw (10 degrees) through its depth: the points turn the
    # rays' ranges into that plane (taking the range for z, or no intrinsics, tilts it 12 to 22 degrees),
    # and the correction puts it at the target's true depth (measured, the materials' own distortion
    # moves it by 13 to 30 mm here: Eq. (8)).
    u = SIM.fx * xyz[:, 0] / xyz[:, 2] + SIM.cx - 0.5
    expected = np.array([np.sin(np.radians(10)), 0.0, -np.cos(np.radians(10))])
    for (x0, x1), depth, name in zip(COLUMNS, DEPTHS, ("acryl", "cork", "paper"), strict=True):
        on = (u > x0 + 2) & (u < x1 - 3)
        assert on.sum() > 20_000
        assert np.bincount(labels[on][labels[on] != NO_LABEL]).argmax() == names.index(name)
        pts = xyz[on & fixed]
        centre = pts.mean(axis=0)
        normal = np.linalg.svd(pts - centre, full_matrices=False)[2][2]
        angle = np.degrees(np.arccos(abs(normal @ expected)))
        rms = np.sqrt(np.mean(((pts - centre) @ normal) ** 2))
        assert angle < 5.0 and rms < 2.5, (name, angle, rms)
        assert abs(centre[2] - depth) < 3.0, (name, centre)

    # A second snapshot into the same folder keeps the first unless asked.
    before = (out / "points.ply").read_bytes()
    p = _snapshot(d.socket, out)
    assert p.returncode != 0 and "--overwrite" in p.stderr
    assert (out / "points.ply").read_bytes() == before
    assert _snapshot(d.socket, out, "--overwrite").returncode == 0


def test_snapshot_of_a_region_profile_and_bad_options(start: Callable[..., Daemon], tmp_path: Path,
                                                     sim_table: Path) -> None:  # fmt: skip
    d = start("sim:static,material=cork,depth=900,realtime=0", "--roi", "200,150,312,270")
    d.client().close()
    out = tmp_path / "roi"
    p = _snapshot(d.socket, out, "--intrinsics", "360,360,250,210")
    assert p.returncode == 0, p.stderr
    meta = json.loads((out / "snapshot.json").read_text())
    assert meta["region"] == {"x0": 200, "y0": 150, "width": 112, "height": 120}
    # The region's one label (a static target at one depth fills one depth bin: it need not be right).
    assert len(meta["materials"]) == 1 and meta["materials"][0]["name"] in tofmat.ExemplarTable.load(
        str(sim_table)).materials  # fmt: skip
    assert meta["intrinsics"]["fx"] == 360.0  # the given ones, not the camera's
    cloud = trimesh.load(out / "points.ply")
    assert 0 < len(cloud.vertices) <= 112 * 120
    assert (cloud.metadata["_ply_raw"]["vertex"]["data"]["label"] == 0).all()  # every valid pixel of the region
    for bad, says in ((["--intrinsics", "1,2,3"], "nine"), (["--intrinsics", "0,365,256,212"], "focal")):
        p = _snapshot(d.socket, tmp_path / "bad", *bad)
        assert p.returncode == 2 and says in p.stderr, p.stderr
    p = subprocess.run([sys.executable, "-m", "tofmat", "snapshot", "--address", str(tmp_path / "none.sock"), "-o",
                        str(tmp_path / "x")], capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode != 0 and "none.sock" in p.stderr
