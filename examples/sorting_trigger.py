# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Trigger a sorting burst by hand and print its decision.

In the sorting profile tofmatd classifies nothing until a trigger; then `burst` frames of the ROI
give one `label` event carrying the trigger's number (state `final`, `mixed` when the frames
disagree, `no_target` when they saw nothing). This switches the daemon to sorting (and back
afterwards; --expect only checks it), sends --count triggers and prints each decision:

    tofmatd --source sim:static,material=acryl --table sim.tmx --socket /tmp/tofmatd.sock &
    python examples/sorting_trigger.py --address /tmp/tofmatd.sock --count 3 --burst 6
"""

from __future__ import annotations

import argparse
import os
import sys

import tofmat
from tofmat.client import DEFAULT_SOCKET, Label


def decision(label: Label) -> str:
    """One line: the trigger, the burst's state, material, distance and runner-up."""
    line = f"trigger {label.trigger}: {label.state}"
    if label.material is not None:
        line += f" {label.material}, distance {label.distance:.2f} mm^2"
        if len(label.ranking) > 1:
            line += f", runner-up {label.ranking[1].material} {label.ranking[1].distance:.2f} mm^2"
    if label.truth is not None:
        line += f" [truth {label.truth.material or 'nothing'}]"
    return line


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--address", default=os.environ.get("TOFMAT_SOCKET", DEFAULT_SOCKET),
                        help="tofmatd's Unix socket or HOST:PORT (default: $TOFMAT_SOCKET or %(default)s)")  # fmt: skip
    parser.add_argument("--expect", action="store_true", help="do not switch the profile: fail unless it is sorting")
    parser.add_argument("--count", type=int, default=1, help="triggers to send, one after another (default 1)")
    parser.add_argument("--burst", type=int, help="frames per burst, 1..300 (default: the daemon's --burst)")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for each decision")
    args = parser.parse_args(argv)

    try:
        with tofmat.Client(args.address) as client:
            before = client.status()["profile"]
            if before != "sorting" and args.expect:
                print(f"sorting_trigger.py: tofmatd is in the {before} profile, not sorting", file=sys.stderr)
                return 1
            if before != "sorting":
                client.set_profile("sorting")  # needs control (NotPermittedError otherwise)
                print(f"profile {before} -> sorting")
            try:
                client.subscribe("labels")  # before the trigger, so that its label cannot be missed
                for _ in range(args.count):
                    n = client.trigger(args.burst)  # refused while a sorting line's light barrier triggers
                    label = next(lb for lb in client.labels(timeout=args.timeout) if lb.trigger == n)
                    print(decision(label), flush=True)
            finally:
                if before != "sorting":
                    client.set_profile(before)
                    print(f"profile back to {before}")
    except tofmat.ClientError as e:
        print(f"sorting_trigger.py: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # the profile was put back on the way out
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
