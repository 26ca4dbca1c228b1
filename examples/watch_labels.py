# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Watch tofmatd's live labels: material, Eq. (12) distance and the runner-up of each.

Subscribes to the `labels` stream (handheld or sorting profile) and prints one line a label, for
--count labels (0: until Ctrl-C). Try it on the simulated camera:

    tofmatd --source sim:sweep,materials=cork+paper --table sim.tmx --socket /tmp/tofmatd.sock &
    python examples/watch_labels.py --address /tmp/tofmatd.sock --count 20
"""

from __future__ import annotations

import argparse
import os
import sys

import tofmat
from tofmat.client import DEFAULT_SOCKET, Label


def describe(label: Label) -> str:
    """One line: the best material, its distance and the runner-up with how much farther it is."""
    if label.state == "no_target" or not label.ranking:
        line = f"frame {label.frame:6d}: (no target)"
    else:
        best = label.ranking[0]
        line = f"frame {label.frame:6d}: {label.material} {best.distance:.2f} mm^2"
        if len(label.ranking) > 1:
            second = label.ranking[1]
            ratio = f" (x{second.distance / best.distance:.1f})" if best.distance > 0 else ""
            line += f", runner-up {second.material} {second.distance:.2f} mm^2{ratio}"
        if label.state != "tracking":
            line += f" [{label.state}]"
    if label.truth is not None and label.truth.material:
        line += f" [truth {label.truth.material}]"
    return line


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--address", default=os.environ.get("TOFMAT_SOCKET", DEFAULT_SOCKET),
                        help="tofmatd's Unix socket or HOST:PORT (default: $TOFMAT_SOCKET or %(default)s)")  # fmt: skip
    parser.add_argument("--count", type=int, default=10, help="labels to print; 0 = until Ctrl-C (default %(default)s)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for each label")
    args = parser.parse_args(argv)

    try:
        with tofmat.Client(args.address) as client:
            status = client.status()
            print(f"{status['server']} at {args.address}: profile {status['profile']}, {status['source']}")
            if status["profile"] == "segmentation":
                msg = "the segmentation profile sends label maps, not labels (see segmentation_map.py)"
                print(f"watch_labels.py: {msg}", file=sys.stderr)
                return 1
            for n, label in enumerate(client.labels(timeout=args.timeout), start=1):
                print(describe(label), flush=True)
                if n == args.count:
                    break
    except tofmat.ClientError as e:
        print(f"watch_labels.py: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
