# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Tables that hold each material at several angles, and the labels a matcher gives with one.

A table recorded at one angle of the target reads a target at another as a session that moved
(docs/evaluation.md): the curves change with the surface's orientation. The paper's database holds
13 orientations of each material for this. Here the simulated camera records a material at each
of several angles, the exemplars enter one table as separate candidates named ``material@angle``;
the label is the material of the best exemplar, never the angle, and its confidence the sum of
that material's exemplars' probabilities (a mixture of equal weights).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from .. import ClassificationResult, Classifier, ExemplarTable
from .._progress import Progress

if TYPE_CHECKING:
    from ..sim import Renderer

MAX_ENTRIES = 255  # a table's candidates at most (firmware/core exemplar_table.hpp, kMaxMaterials)


def record_angle_table(
    materials: Sequence[str],
    yaws_deg: Sequence[float],
    like: ExemplarTable,
    progress: Progress | None = None,
    renderer: Renderer | None = None,
    distortion: bool = False,
) -> tuple[ExemplarTable, npt.NDArray[np.int64]]:
    """Each of ``materials`` recorded by the simulated camera (``renderer``; default: the default
    device and library) in its nominal session at each of ``yaws_deg`` degrees (as ``tofmat sim table
    --yaw Y`` records one), over ``like``'s bins and rows, with its calibration (and its noise, for its
    own materials); with ``distortion``, each exemplar carries its material's depth distortion at its
    angle. The table's entries are named ``material@Y``, and the second array gives each entry's index
    into ``materials``. Raises ValueError for no angle, an angle repeated, one outside 0..60 degrees,
    or more exemplars than a table holds."""
    from ..sim import Renderer, load_device, load_library
    from ..sim.table import DISTORTION_GRID, simulated_table

    if not yaws_deg:
        raise ValueError("a table of angles needs at least one angle")
    if len(set(yaws_deg)) != len(yaws_deg):
        raise ValueError(f"a table's angles must differ, got {', '.join(f'{y:g}' for y in yaws_deg)}")
    if any(not 0.0 <= y <= 60.0 for y in yaws_deg):
        raise ValueError(f"a table's angles must be 0..60 degrees, got {', '.join(f'{y:g}' for y in yaws_deg)}")
    if len(materials) * len(yaws_deg) > MAX_ENTRIES:
        raise ValueError(
            f"{len(materials)} materials at {len(yaws_deg)} angles are {len(materials) * len(yaws_deg)} exemplars: "
            f"a table holds at most {MAX_ENTRIES}"
        )
    if renderer is None:
        renderer = Renderer(load_device(), load_library(), 0)
    features, distortions = [], []
    for k, yaw in enumerate(yaws_deg):
        if progress:
            progress(k, len(yaws_deg), f"recording the table at {yaw:g} degrees")
        at_yaw = simulated_table(renderer, list(materials), like.bins, yaw_deg=yaw, distortion=distortion)
        features.append(at_yaw.features)
        if at_yaw.distortion_mm is not None:
            distortions.append(at_yaw.distortion_mm)
    names = [f"{m}@{y:g}" for y in yaws_deg for m in materials]
    # (like's noise and calibration, when ``materials`` are its own: what it was calibrated for holds
    # for its materials at any angle, and the rows match it with the single table as they would)
    noise = None
    if like.noise_mm is not None and list(materials) == list(like.materials):
        noise = np.tile(np.asarray(like.noise_mm), (len(yaws_deg), 1))
    table = ExemplarTable(names, np.concatenate(features), like.bins, like.rows, noise)
    if distortions:
        table = table.with_distortion(DISTORTION_GRID, np.concatenate(distortions))
    if like.calibration is not None:
        table = table.with_calibration(like.calibration)
    return table, np.tile(np.arange(len(materials), dtype=np.int64), len(yaws_deg))


def material_labels(
    results: Sequence[ClassificationResult], owner: npt.NDArray[np.int64], n_materials: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Each result's label as a material (index into the materials ``owner`` maps the table's entries
    to) and its confidence: the material of the best exemplar (the paper's nearest neighbour over
    orientations), and the sum of that material's exemplars' probabilities; -1 and 0 for a query no
    candidate shares an element with. (Not the material of the highest sum: the confidence's
    temperatures are tuned to be cautious, flat at short sweeps, and under a flat softmax the
    highest sum is the material nearest on average over its angles, not the one at the query's:
    that lost 10 to 13 points at 10 bins at the table's own angle.)"""
    labels = np.full(len(results), -1, dtype=np.int64)
    conf = np.zeros(len(results))
    for i, res in enumerate(results):
        if not res.ranking:
            continue
        labels[i] = owner[res.ranking[0].index]
        conf[i] = sum(r.probability for r in res.ranking if owner[r.index] == labels[i])
    return labels, conf


def angle_table_labels(
    table: ExemplarTable,
    owner: npt.NDArray[np.int64],
    n_materials: int,
    method: Literal["eq12", "session"],
    queries: np.ndarray,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """``method``'s labels (as shipped: tofmat.Classifier's prior and temperatures) of ``queries`` against
    a table of angles (record_angle_table), as materials, with their confidence."""
    return material_labels(Classifier(table, method=method).classify_batch(queries), owner, n_materials)
