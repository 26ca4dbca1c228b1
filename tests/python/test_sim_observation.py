# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A region's observation as the simulated camera's table and the evaluation's sweeps take it
(tofmat.sim.table.roi_observation), on the frames tofmatd bins nothing from."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tofmat.sim import Renderer, load_device, load_library
from tofmat.sim import table as sim_table


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer(load_device(), load_library(), 0)


def test_a_frame_whose_surface_holds_no_pixel_is_no_observation(
    renderer: Renderer, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Valid pixels in two clusters farther apart than the surface's band put the median between
    them, where no pixel lies: surface_mean counts none. That frame is no observation (it was a NaN
    depth, which crashed the evaluation's binning of a sweep), as tofmatd adds nothing from it."""
    p0 = np.asarray(renderer.p0_tables())
    real = sim_table.surface_mean
    seen: list[int] = []

    def empty_surface(frame: Any, centre_mm: float, band_mm: float = 60.0) -> tuple[float, np.ndarray, int]:
        _depth, sums, pixels = real(frame, centre_mm)
        seen.append(pixels)
        return float("nan"), np.zeros_like(sums), 0

    assert sim_table.roi_observation(renderer, p0, "cork", 800.0, 10.0, 1) is not None
    monkeypatch.setattr(sim_table, "surface_mean", empty_surface)
    with np.errstate(all="raise"):  # (no 0 / 0 on the way)
        assert sim_table.roi_observation(renderer, p0, "cork", 800.0, 10.0, 1) is None
    assert seen and seen[0] > 0  # the frame itself had a surface: only the count was taken away


def test_the_surface_is_the_rows_mean_over_its_pixels(renderer: Renderer) -> None:
    p0 = np.asarray(renderer.p0_tables())
    obs = sim_table.roi_observation(renderer, p0, "cork", 800.0, 10.0, 1)
    assert obs is not None
    depth, rows = obs
    assert abs(depth - 800.0) < 130.0  # a target at 800 mm, measured with cork's distortion (tens of mm)
    assert rows.shape == (2,) and np.isfinite(rows).all()
