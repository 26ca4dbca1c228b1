# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A scripted tofmatd for the client's tests: frames built by hand (docs/protocol.md, Framing), and a
daemon on a Unix socket that answers the hello and the commands, then runs a test's script."""

from __future__ import annotations

import json
import socket
import struct
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

HELLO, REQUEST, REPLY, EVENT = 1, 2, 3, 4


def frame(kind: int, meta: dict[str, Any], blob: bytes = b"") -> bytes:
    return raw_frame(kind, json.dumps(meta).encode(), blob)


def raw_frame(kind: int, meta: bytes, blob: bytes = b"") -> bytes:
    """A frame whose metadata is these bytes as they are (JSON or not, UTF-8 or not)."""
    payload = struct.pack("<I", len(meta)) + meta + blob
    return b"TMAT" + struct.pack("<HBBI", 1, kind, 0, len(payload)) + payload


def read_message(conn: socket.socket) -> dict[str, Any]:
    def exactly(n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = conn.recv(n - len(data))
            if not chunk:
                raise ConnectionError("client went away")
            data += chunk
        return data

    header = exactly(12)
    (length,) = struct.unpack("<I", header[8:12])
    payload = exactly(length)
    (meta_len,) = struct.unpack("<I", payload[:4])
    return dict(json.loads(payload[4 : 4 + meta_len]))


LABEL = {"event": "label", "frame": 7, "timestamp_ns": 1, "profile": "handheld", "state": "tracking",
         "material": "cork", "index": 0, "distance": 1.5, "valid": 9, "bins_covered": 1,
         "ranking": [{"material": "cork", "distance": 1.5}]}  # fmt: skip


def scripted_daemon(
    path: Path,
    minor: int | None,
    after_subscribe: Callable[[socket.socket], None] = lambda _conn: None,
    on_request: Callable[[socket.socket, dict[str, Any]], bool] = lambda _conn, _req: False,
    hello_result: dict[str, Any] | None = None,
) -> threading.Thread:
    """A daemon of protocol 1.`minor` (None: one that predates minor versions and roles) that answers
    hello and subscribe, then runs the script. ``on_request`` sees every request after the hello
    first: True when it answered (or chose not to). ``hello_result`` replaces fields of the hello's reply."""
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen(1)

    def serve() -> None:
        conn, _ = server.accept()
        with conn, server:
            hello: dict[str, Any] = {"protocol": 1, "server": "tofmatd 0.0.9", "capabilities": ["labels"],
                                     "auth_required": False}  # fmt: skip
            result: dict[str, Any] = {"protocol": 1, "client_id": 1}
            if minor is not None:
                hello |= {"minor": minor, "server": "tofmatd 9.9", "capabilities": ["labels", "sparkles", "depth"],
                          "a_later_field": [1, 2]}  # fmt: skip
                result |= {"minor": minor, "role": "control"}
            result |= hello_result or {}
            conn.sendall(frame(HELLO, hello))
            while True:
                try:
                    req = read_message(conn)
                except ConnectionError:
                    return
                if req["cmd"] != "hello" and on_request(conn, req):
                    continue
                answer = {"streams": req["args"]["streams"]} if req["cmd"] == "subscribe" else result
                try:
                    conn.sendall(frame(REPLY, {"id": req["id"], "ok": True, "result": answer, "later": True}))
                except OSError:  # (the client went away: a test's client may close first)
                    return
                if req["cmd"] == "subscribe":
                    after_subscribe(conn)

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return t
