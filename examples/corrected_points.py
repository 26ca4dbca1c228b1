# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Material-corrected depth as 3D points: how far each material's surface moves once its own depth
distortion (Eq. (8)) is taken off.

Switches tofmatd to the segmentation profile (and back afterwards), takes one frame's label map,
combined depth and corrected depth (the same frame number), turns both depths into points with the
camera's intrinsics (tofmat.DepthImage.points), and prints per material its pixels, the median
distance of its points from the camera before and after the correction, and the median correction.
With --npy it saves the corrected points (N x 3, mm, camera frame: x right, y down, z forward) and
their labels (N) as two .npy files. The daemon's table must carry the materials' depth distortion
(a table recorded with `tofmat sim table` does):

    tofmatd --source sim:regions,materials=acryl+cork+paper --table sim.tmx --socket /tmp/tofmatd.sock &
    python examples/corrected_points.py --address /tmp/tofmatd.sock --npy points
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

import tofmat
from tofmat.client import DEFAULT_SOCKET, DepthImage, LabelMap


def one_frame(c: tofmat.Client, timeout: float) -> tuple[LabelMap, DepthImage, DepthImage]:
    """The label map, combined depth and corrected depth of the next frame that has all three."""
    c.subscribe("label_map", "depth:combined", "depth:corrected")
    seen: dict[int, dict[str, LabelMap | DepthImage]] = {}
    for e in c.events(timeout=timeout):
        if isinstance(e, LabelMap):
            seen.setdefault(e.frame, {})["map"] = e
        elif isinstance(e, DepthImage):
            seen.setdefault(e.frame, {})[e.kind] = e
        else:
            continue
        got = seen.get(e.frame, {})
        if len(got) == 3:
            m, combined, corrected = got["map"], got["combined"], got["corrected"]
            assert isinstance(m, LabelMap) and isinstance(combined, DepthImage) and isinstance(corrected, DepthImage)
            return m, combined, corrected
    raise tofmat.DaemonTimeoutError("no frame with a label map and both depths")  # (events() raises first)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--address", default=os.environ.get("TOFMAT_SOCKET", DEFAULT_SOCKET),
                        help="tofmatd's Unix socket or HOST:PORT (default: $TOFMAT_SOCKET or %(default)s)")  # fmt: skip
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for a frame")
    parser.add_argument("--npy", type=Path, help="save PREFIX_points.npy and PREFIX_labels.npy")
    args = parser.parse_args(argv)
    try:
        with tofmat.Client(args.address) as c:
            before = c.status()["profile"]
            c.set_profile("segmentation")
            try:
                m, combined, corrected = one_frame(c, args.timeout)
            finally:
                c.set_profile(before)
    except tofmat.ClientError as e:
        print(f"corrected_points: {e}", file=sys.stderr)
        return 1
    if combined.intrinsics is None:
        print("corrected_points: the daemon sends no intrinsics (protocol minor 9 on)", file=sys.stderr)
        return 1
    # The label map covers the whole frame; the depth images, the profile's region (the whole frame here).
    h, w = combined.depth_mm.shape
    labels = m.labels[combined.y0 : combined.y0 + h, combined.x0 : combined.x0 + w]
    measured, fixed = combined.points(), corrected.points()
    print(f"frame {m.frame}: distance from the camera, median over each material's corrected pixels")
    print(f"{'material':14s} {'pixels':>7s} {'measured':>10s} {'corrected':>10s} {'correction':>11s}")
    for k, name in enumerate(m.materials):
        on = (labels == k) & corrected.valid
        if not on.any():
            continue
        d0 = np.linalg.norm(measured[on], axis=1)
        d1 = np.linalg.norm(fixed[on], axis=1)
        print(
            f"{name:14s} {int(on.sum()):7d} {np.median(d0):8.1f}mm {np.median(d1):8.1f}mm {np.median(d0 - d1):+9.1f}mm"
        )
    if not corrected.valid.any():
        print("(nothing corrected: the table has no depth distortion for these materials)")
    if args.npy is not None:
        keep = corrected.valid
        np.save(f"{args.npy}_points.npy", fixed[keep])
        np.save(f"{args.npy}_labels.npy", labels[keep])
        print(f"wrote {args.npy}_points.npy and {args.npy}_labels.npy ({int(keep.sum())} points)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
