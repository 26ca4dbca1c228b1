# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The depth camera's geometry: its intrinsics, each pixel's ray, and depth images as points.

A Time-of-Flight camera measures how far light travels along each pixel's ray, so tofmat's depth
images are ranges along the rays (mm), not distances from the image plane: a pixel's 3D point is
its range times its unit ray. The rays come from the intrinsics the camera reports over USB (the
Kinect v2's depth-parameters page: focal lengths, principal point and Brown's distortion), which
tofmatd sends with every depth image (protocol minor 9). Pixel (x, y)'s centre is at
(x + 0.5, y + 0.5) in the intrinsics' coordinates. Points are in the camera's frame, in mm:
x to the right of the image, y down, z along the optical axis.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

# Fixed-point iterations of the undistortion: Brown's model with the Kinect's coefficients
# (|k1| ~ 0.1) converges to float32 precision in under 10 over the whole image.
_UNDISTORT_ITERATIONS = 20


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels of the whole frame, and Brown's distortion coefficients."""

    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy, self.k1, self.k2, self.k3, self.p1, self.p2)
        if not all(np.isfinite(v) for v in values):
            raise ValueError(f"intrinsics must be finite numbers: {values}")
        if not (self.fx > 0 and self.fy > 0):
            raise ValueError(f"focal lengths must be > 0, not fx={self.fx}, fy={self.fy}")

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any]) -> Intrinsics:
        """From a depth event's ``intrinsics`` object (fields a later minor adds are ignored)."""
        return cls(*(float(meta[k]) for k in ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "p1", "p2")))

    def _brown(self, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> tuple[
            npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:  # fmt: skip
        """Brown's model's radial factor and tangential shifts at ideal normalised coordinates."""
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        return (radial, 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
                self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y)  # fmt: skip

    def distort(self, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> tuple[
            npt.NDArray[np.float64], npt.NDArray[np.float64]]:  # fmt: skip
        """Brown's model: ideal normalised coordinates to where the lens puts them."""
        radial, dx, dy = self._brown(x, y)
        return x * radial + dx, y * radial + dy

    def undistort(self, xd: npt.NDArray[np.float64], yd: npt.NDArray[np.float64]) -> tuple[
            npt.NDArray[np.float64], npt.NDArray[np.float64]]:  # fmt: skip
        """The inverse of :meth:`distort`, by fixed-point iteration from the distorted point."""
        x, y = xd.copy(), yd.copy()
        for _ in range(_UNDISTORT_ITERATIONS):
            radial, dx, dy = self._brown(x, y)
            x, y = (xd - dx) / radial, (yd - dy) / radial
        return x, y

    def rays(self, x0: int, y0: int, width: int, height: int) -> npt.NDArray[np.float64]:
        """Unit rays, shape (height, width, 3), of the pixels of the region starting at (x0, y0)."""
        if width < 0 or height < 0:
            raise ValueError(f"region must not have a negative size: {width} x {height}")
        u, v = np.meshgrid(np.arange(x0, x0 + width) + 0.5, np.arange(y0, y0 + height) + 0.5)
        x, y = self.undistort((u - self.cx) / self.fx, (v - self.cy) / self.fy)
        ray = np.stack([x, y, np.ones_like(x)], axis=-1)
        out: npt.NDArray[np.float64] = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
        return out


def range_to_points(range_mm: npt.NDArray[np.floating[Any]], intrinsics: Intrinsics, x0: int = 0,
                    y0: int = 0) -> npt.NDArray[np.float32]:  # fmt: skip
    """Points (height, width, 3) in mm from ranges along the rays (NaN stays NaN: no point there)."""
    if range_mm.ndim != 2:
        raise ValueError(f"a range image must be 2-D, not of shape {range_mm.shape}")
    h, w = range_mm.shape
    rays = intrinsics.rays(x0, y0, w, h)
    points: npt.NDArray[np.float32] = (rays * range_mm.astype(np.float64)[..., None]).astype(np.float32)
    return points
