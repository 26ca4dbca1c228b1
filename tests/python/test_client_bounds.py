# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The client's side of the socket, against a daemon (or anything on its path) that is hostile: what
tofmat.Client keeps is bounded however much is sent, a command never waits past its timeout, bytes
that are not UTF-8 are a ProtocolError, a hello reply of another major is refused, the CLI's exit
statuses say a failure (1), not a usage error (2), and arbitrary frames raise nothing but ClientErrors.
"""

from __future__ import annotations

import random
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from scripted_daemon import EVENT, LABEL, REPLY, frame, raw_frame, scripted_daemon

import tofmat
from tofmat.cli import main
from tofmat.client import MAX_PENDING_BYTES, MAX_PENDING_EVENTS, DepthImage

DEPTH_META = {"event": "depth", "frame": 1, "timestamp_ns": 1, "kind": "combined", "x0": 0, "y0": 0,
              "width": 512, "height": 424, "dtype": "float32"}  # fmt: skip
DEPTH = frame(EVENT, DEPTH_META, np.zeros((424, 512), "<f4").tobytes())  # 868 KB


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def flood(conn: socket.socket, message: bytes, seconds: float) -> None:
    """Sends message over and over for `seconds`, or until the client goes away."""
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            conn.sendall(message)
    except OSError:
        pass


def test_events_streamed_while_a_command_waits_cannot_grow_the_client(tmp_path: Path) -> None:
    # The daemon answers the hello, then streams depth images in place of the status reply.
    def on_request(conn: socket.socket, req: dict[str, Any]) -> bool:
        if req["cmd"] != "status":
            return False
        flood(conn, DEPTH, 8.0)
        return True

    sock = tmp_path / "flood.sock"
    t = scripted_daemon(sock, minor=10, on_request=on_request)
    with tofmat.Client(sock, timeout=2.0, reconnect=False) as c:
        before = rss_bytes()
        t0 = time.monotonic()
        with pytest.raises(tofmat.DaemonTimeoutError, match="status"):
            c.status()
        waited = time.monotonic() - t0
        grown = rss_bytes() - before
        assert waited < 4.0, f"the stream held status() {waited:.1f} s past its 2 s timeout"
        assert grown < 256 << 20, f"the client grew {grown / 2**20:.0f} MiB"
        assert c.dropped_events > 0
        # What was kept is handed out (depth images; this client did not subscribe, but keeps them).
        assert isinstance(c.next_event(1.0), DepthImage)
    t.join(10.0)


def test_waiting_for_one_event_keeps_a_bounded_number_of_the_others(tmp_path: Path) -> None:
    sock = tmp_path / "kept.sock"
    t = scripted_daemon(sock, minor=10, after_subscribe=lambda conn: flood(conn, DEPTH, 6.0))
    with tofmat.Client(sock, timeout=2.0, reconnect=False) as c:
        c.subscribe("depth:combined", "label_map")  # (one request: the flood starts after its reply)
        before = rss_bytes()
        with pytest.raises(tofmat.DaemonTimeoutError):
            c.label_map(timeout=2.0)  # never comes: every depth image meanwhile is kept, up to the bound
        grown = rss_bytes() - before
        assert grown < 256 << 20, f"the client grew {grown / 2**20:.0f} MiB"
        assert c.dropped_events > 0
        kept = len(c._pending)
        assert kept > 0 and c._pending.bytes <= MAX_PENDING_BYTES, (kept, c._pending.bytes)
        assert all(isinstance(c.next_event(0.0), DepthImage) for _ in range(kept))  # (handed out first)
    t.join(10.0)


def test_bytes_that_are_not_utf8_are_a_protocol_error_that_says_so(tmp_path: Path) -> None:
    def on_request(conn: socket.socket, req: dict[str, Any]) -> bool:
        conn.sendall(raw_frame(REPLY, b'{"id": %d, "ok": true, "result": {"x": "\xff\xfe"}}' % req["id"]))
        return True

    sock = tmp_path / "utf8.sock"
    t = scripted_daemon(sock, minor=10, on_request=on_request)
    with tofmat.Client(sock, reconnect=False) as c, pytest.raises(tofmat.ProtocolError) as err:
        c.status()
    assert "UTF-8" in str(err.value) and "\\xff" in str(err.value)
    t.join(5.0)


def test_a_hello_reply_of_another_major_is_refused(tmp_path: Path) -> None:
    sock = tmp_path / "v99.sock"
    t = scripted_daemon(sock, minor=10, hello_result={"protocol": 99})
    with pytest.raises(tofmat.ProtocolVersionError, match="99"):
        tofmat.Client(sock, reconnect=False)
    t.join(5.0)


def silent_listener(path: Path) -> socket.socket:
    """Accepts connections and never says anything (no hello)."""
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen(4)
    return server


@pytest.mark.parametrize("case", ["timeout", "nothing_listens", "not_utf8", "refused_argument"])
def test_the_cli_exits_1_for_what_the_daemon_did_and_2_for_what_it_refused(tmp_path: Path, case: str) -> None:
    sock = tmp_path / f"{case}.sock"
    server = None
    if case == "timeout":
        server = silent_listener(sock)
    elif case == "not_utf8":
        scripted_daemon(sock, minor=10, on_request=lambda conn, req: bool(conn.sendall(
            raw_frame(REPLY, b'{"id": %d, "ok": true, "result": {"profile": "\xff"}}' % req["id"]))) or True)  # fmt: skip
    elif case == "refused_argument":
        scripted_daemon(sock, minor=10, on_request=lambda conn, req: bool(conn.sendall(frame(REPLY, {
            "id": req["id"], "ok": False, "code": "invalid_argument", "error": "not now"}))) or True)  # fmt: skip
    result = CliRunner().invoke(main, ["status", "--address", str(sock)])
    if server is not None:
        server.close()
    want = 2 if case == "refused_argument" else 1
    assert result.exit_code == want, (result.exit_code, result.output)
    assert "Traceback" not in result.output and result.output.startswith("Error: ")


def random_frame(rng: random.Random, next_id: int) -> bytes:
    """One frame a hostile daemon might send: valid ones, valid ones with fields gone wrong, garbage."""
    choice = rng.randrange(10)
    if choice == 0:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
    if choice == 1:  # a header that claims more than it sends, or more than any bound
        return b"TMAT" + bytes([1, 0, rng.choice([1, 3, 4]), 0]) + rng.randbytes(4)
    if choice == 2:
        return raw_frame(rng.choice([3, 4]), rng.randbytes(rng.randrange(0, 64)))
    if choice == 3:
        return frame(REPLY, {"id": next_id, "ok": rng.random() < 0.5, "code": "failed", "error": "\x1b[2J" * 3})
    if choice == 4:
        return frame(EVENT, {**LABEL, rng.choice(list(LABEL)): rng.choice([None, -1, "x", [], 1e308])})
    if choice == 5:
        w, h = rng.randrange(0, 6), rng.randrange(0, 6)
        blob = rng.randbytes(rng.choice([w * h * 4, rng.randrange(0, 50)]))
        return frame(EVENT, {**DEPTH_META, "width": w, "height": h}, blob)
    if choice == 6:
        return frame(EVENT, {"event": "label_map", "frame": 1, "timestamp_ns": 1, "width": 2, "height": 2,
                             "materials": ["cork"] * rng.randrange(0, 300)}, rng.randbytes(4))  # fmt: skip
    if choice == 7:
        return frame(
            REPLY, {"id": rng.choice([next_id, next_id + 5, -1]), "ok": True, "result": rng.choice([{}, [], 3])}
        )
    if choice == 8:
        return DEPTH
    return frame(EVENT, {"event": rng.choice(["reset", "device", "sort", "line", "later"]), "by": 1})


def test_arbitrary_frames_from_a_daemon_raise_only_client_errors(tmp_path: Path) -> None:
    """The client's fuzz case in Python (the C++ client's is tests/fuzz/fuzz_client.cpp): a daemon that
    answers the hello, then sends random frames; every call ends in a result or a ClientError, and
    what the client keeps stays in its bounds."""
    outcomes: dict[str, int] = {}
    for seed in range(120):
        rng = random.Random(seed)
        sock = tmp_path / f"r{seed}.sock"

        def on_request(conn: socket.socket, req: dict[str, Any], rng: random.Random = rng) -> bool:
            try:
                for _ in range(rng.randrange(1, 12)):
                    conn.sendall(random_frame(rng, req["id"]))
            except OSError:
                pass
            return True

        t = scripted_daemon(sock, minor=10, on_request=on_request)
        try:
            with tofmat.Client(sock, timeout=0.5, reconnect=False) as c:
                try:
                    c.status()
                    while c.next_event(0.05) is not None:
                        pass
                    outcome = "ok"
                except tofmat.ClientError as e:
                    outcome = type(e).__name__
                assert c.dropped_events >= 0
                conn = c._conn
                if conn is not None:
                    assert conn.pending_events <= 1024 and conn.pending_bytes <= 64 << 20
                assert len(c._pending) <= MAX_PENDING_EVENTS and c._pending.bytes <= MAX_PENDING_BYTES
        except tofmat.ClientError as e:
            outcome = type(e).__name__
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
        t.join(5.0)
    # (the script reaches both ends: calls that succeed, and malformed frames refused)
    assert outcomes.get("ProtocolError", 0) > 0 and len(outcomes) >= 2, outcomes
