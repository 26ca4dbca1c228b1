# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Protocol versions (docs/protocol.md, Versions): the header carries the major, the hello the minor,
and a client ignores what a later minor adds. A scripted daemon of a later minor sends an event,
a field, a stream and a depth kind this client has never heard of: the client reads on.
"""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scripted_daemon import EVENT, LABEL, frame, scripted_daemon

import tofmat
from tofmat import _tofmat
from tofmat.client import DepthImage, Label, ResetEvent


def test_this_client_says_its_minor_and_the_daemon_says_its_own(start: Any) -> None:
    assert _tofmat.PROTOCOL_VERSION == 1 and _tofmat.PROTOCOL_MINOR >= 4
    d = start("sim:static,material=acryl")
    with d.client() as c:
        assert c.hello["protocol"] == 1 and c.hello["minor"] == _tofmat.PROTOCOL_MINOR


def test_a_client_reads_on_past_what_a_later_minor_added(tmp_path: Path) -> None:
    def script(conn: socket.socket) -> None:
        conn.sendall(frame(EVENT, {"event": "sparkle", "glitter": 3}))  # an event of a later minor
        conn.sendall(frame(EVENT, {**LABEL, "confidence_band": [0.1, 0.9]}))  # a field of a later minor
        depth = np.arange(4, dtype="<f4").tobytes()
        conn.sendall(frame(EVENT, {"event": "depth", "frame": 8, "timestamp_ns": 2, "kind": "corrected", "x0": 0,
                                   "y0": 0, "width": 2, "height": 2, "dtype": "float32"}, depth))  # fmt: skip
        conn.sendall(frame(EVENT, {"event": "reset", "by": "foot_pedal", "timestamp_ns": 3}))

    sock = tmp_path / "later.sock"
    t = scripted_daemon(sock, minor=99, after_subscribe=script)
    with tofmat.Client(sock, reconnect=False) as c:
        assert c.hello["minor"] == 99
        c.subscribe("labels", "sparkles")  # a stream this client does not know, but the daemon offers
        with pytest.raises(ValueError, match="unknown stream"):
            c.subscribe("nothing_anyone_offers")
        events = [c.next_event(5.0) for _ in range(3)]
        assert isinstance(events[0], Label) and events[0].material == "cork"
        assert isinstance(events[1], DepthImage) and events[1].kind == "corrected"
        assert events[1].depth_mm.shape == (2, 2)
        assert isinstance(events[2], ResetEvent) and events[2].by == "foot_pedal"
        assert c.next_event(0.2) is None
    t.join(5.0)


def test_a_daemon_that_predates_minor_versions_is_minor_zero(tmp_path: Path) -> None:
    sock = tmp_path / "older.sock"
    t = scripted_daemon(sock, minor=None)
    with tofmat.Client(sock, reconnect=False) as c:
        assert c.hello["minor"] == 0 and c.role == "control"  # (no role field: every client controls)
    t.join(5.0)


def test_waiting_for_a_depth_image_keeps_the_events_that_came_first(tmp_path: Path) -> None:
    # depth() and label_map() wait for their event; what comes meanwhile is kept, in order.
    depth_meta = {"event": "depth", "frame": 8, "timestamp_ns": 2, "kind": "combined", "x0": 0, "y0": 0,
                  "width": 2, "height": 1, "dtype": "float32"}  # fmt: skip

    def script(conn: socket.socket) -> None:
        conn.sendall(frame(EVENT, LABEL))
        conn.sendall(frame(EVENT, {"event": "reset", "by": "button", "timestamp_ns": 3}))
        conn.sendall(frame(EVENT, depth_meta, np.array([1.0, 2.0], "<f4").tobytes()))
        conn.sendall(frame(EVENT, {**LABEL, "frame": 9}))

    sock = tmp_path / "d.sock"
    t = scripted_daemon(sock, minor=4, after_subscribe=script)
    with tofmat.Client(sock, reconnect=False) as c:
        c.subscribe("labels", "depth")
        image = c.depth("combined", timeout=5.0)
        assert image.frame == 8 and image.depth_mm.tolist() == [[1.0, 2.0]]
        got = [c.next_event(5.0) for _ in range(3)]
        assert isinstance(got[0], Label) and got[0].frame == 7
        assert isinstance(got[1], ResetEvent)
        assert isinstance(got[2], Label) and got[2].frame == 9
        with pytest.raises(tofmat.DaemonTimeoutError):
            c.label_map(timeout=0.2)
    t.join(5.0)
