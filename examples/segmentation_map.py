# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Fetch one per-pixel label map from tofmatd and count the pixels of each material.

Switches the daemon to the segmentation profile (and back afterwards; --expect only checks that
it is in it, for a client that may only read), takes the next label map as a numpy array, prints
the pixels per material and, with --png, saves it in colour (needs Pillow, which matplotlib brings too):

    tofmatd --source sim:regions,materials=acryl+cork+paper --table sim.tmx --socket /tmp/tofmatd.sock &
    python examples/segmentation_map.py --address /tmp/tofmatd.sock --png map.png
"""

from __future__ import annotations

import argparse
import colorsys
import os
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt

import tofmat
from tofmat.client import DEFAULT_SOCKET, LabelMap


def palette(n: int) -> npt.NDArray[np.uint8]:
    """n colours that differ in hue (golden-ratio steps round the colour wheel)."""
    rgb = [colorsys.hsv_to_rgb((0.6180339887 * i) % 1.0, 0.7, 0.95) for i in range(n)]
    return (np.array(rgb, np.float64).reshape(n, 3) * 255).round().astype(np.uint8)


def pixel_counts(m: LabelMap) -> dict[str, int]:
    """Pixels of each material that has any, and those with no label."""
    counts = np.bincount(m.labels.ravel(), minlength=256)
    out = {name: int(counts[i]) for i, name in enumerate(m.materials) if counts[i] > 0}
    out["(no label)"] = int(counts[LabelMap.NO_LABEL])
    return out


def save_png(m: LabelMap, path: Path) -> bool:
    """Writes the map in colour (black: no label) with Pillow; False when Pillow is not there. (matplotlib
    writes its PNGs with Pillow too, so it is no way round a missing Pillow.)"""
    try:
        from PIL import Image
    except ImportError:
        return False
    rgb: npt.NDArray[np.uint8] = np.zeros((*m.labels.shape, 3), np.uint8)
    labelled = m.labels != LabelMap.NO_LABEL
    rgb[labelled] = palette(len(m.materials))[m.labels[labelled]]
    Image.fromarray(rgb).save(path)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--address", default=os.environ.get("TOFMAT_SOCKET", DEFAULT_SOCKET),
                        help="tofmatd's Unix socket or HOST:PORT (default: $TOFMAT_SOCKET or %(default)s)")  # fmt: skip
    parser.add_argument(
        "--expect", action="store_true", help="do not switch the profile: fail unless it is segmentation"
    )
    parser.add_argument("--png", type=Path, help="also save the map as this PNG (needs Pillow)")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the map")
    args = parser.parse_args(argv)

    try:
        with tofmat.Client(args.address) as client:
            before = client.status()["profile"]
            if before != "segmentation" and args.expect:
                print(f"segmentation_map.py: tofmatd is in the {before} profile, not segmentation", file=sys.stderr)
                return 1
            if before != "segmentation":
                client.set_profile("segmentation")  # needs control (NotPermittedError otherwise)
                print(f"profile {before} -> segmentation")
            try:
                m = client.label_map(timeout=args.timeout)
            finally:
                if before != "segmentation":
                    client.set_profile(before)
                    print(f"profile back to {before}")
    except tofmat.ClientError as e:
        print(f"segmentation_map.py: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # the profile was put back on the way out
        return 130

    height, width = m.labels.shape
    extra = f", truth accuracy {100 * m.truth_accuracy:.1f} %" if m.truth_accuracy is not None else ""
    print(f"label map of frame {m.frame}: {width} x {height} = {m.labels.size} pixels"
          f"{' (simulated' + extra + ')' if m.simulated else ''}")  # fmt: skip
    counts = pixel_counts(m)
    for name, n in counts.items():
        print(f"  {name:<14s} {n:7d}  {100 * n / m.labels.size:5.1f} %")
    if len(counts) <= len(m.materials):
        print(f"  ({len(m.materials) + 1 - len(counts)} other materials: no pixel)")
    if args.png is not None:
        if not save_png(m, args.png):
            print(f"{args.png} not saved: it needs Pillow (pip install pillow; matplotlib brings it too)")
        else:
            colours = palette(len(m.materials))
            legend = ", ".join(f"{name} #{colours[m.materials.index(name)].tobytes().hex()}" for name in counts
                               if name in m.materials)  # fmt: skip
            print(f"saved {args.png}: {legend}, black = no label")
    return 0


if __name__ == "__main__":
    sys.exit(main())
