# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmatd against clients of other local users (issue 16, cases 7 and 8).

The daemon runs as this test's user (root in CI); the other user is a forked child that drops to
an unused uid, in the socket's group so that it may connect. It gets the reading role: labels and
status, and `NotPermittedError` for anything that changes what every client gets, unless it is in
the control group. It holds only its own share of the connection slots, and the daemon closes its
idle connections.
"""

from __future__ import annotations

import json
import os
import select
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import Daemon

import tofmat

OTHER_UID = 12345  # no such user here: a plain uid, no supplementary groups
SOURCE = "sim:static,material=cork,depth=900,realtime=1"

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="dropping to another uid takes root (CI runs as root)")


@pytest.fixture
def shared_dir() -> Iterator[Path]:
    """A folder the other user can reach (pytest's own are 0700)."""
    d = Path(tempfile.mkdtemp(prefix="tofmat-access-", dir="/tmp"))
    d.chmod(0o755)
    yield d
    for p in d.iterdir():
        p.unlink()
    d.rmdir()


class OtherUser:
    """`work` run in a forked child as `uid` (OTHER_UID; primary group `gid`): its JSON result comes back
    at once; the child keeps what it opened until `release()`."""

    def __init__(self, work: Callable[[], Any], gid: int = 0, uid: int = OTHER_UID) -> None:
        self._result_r, result_w = os.pipe()
        release_r, self._release_w = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the child: never returns into pytest
            code = 0
            try:
                os.close(self._result_r)
                os.close(self._release_w)
                os.setgroups([])
                os.setgid(gid)
                os.setuid(uid)
                out: dict[str, Any] = {"result": work()}
            except BaseException as e:  # everything goes back to the parent
                out = {"error": f"{type(e).__name__}: {e}"}
                code = 1
            os.write(result_w, json.dumps(out).encode() + b"\n")
            select.select([release_r], [], [], 60.0)
            os._exit(code)
        os.close(result_w)
        os.close(release_r)

    def result(self, timeout: float = 30.0) -> Any:
        data = b""
        deadline = time.monotonic() + timeout
        while not data.endswith(b"\n"):
            ready, _, _ = select.select([self._result_r], [], [], max(0.0, deadline - time.monotonic()))
            assert ready, "the other user's work did not finish"
            chunk = os.read(self._result_r, 65536)
            assert chunk, "the other user's process ended without a result"
            data += chunk
        out = json.loads(data)
        assert "error" not in out, out["error"]
        return out["result"]

    def release(self) -> None:
        os.close(self._release_w)
        os.waitpid(self.pid, 0)
        os.close(self._result_r)


def try_control(c: tofmat.Client) -> dict[str, str]:
    """What each control command gives this client: "ok" or the error's class and code."""
    commands: dict[str, Callable[[], Any]] = {
        "set_profile": lambda: c.set_profile("segmentation"),
        "set_roi": lambda: c.set_roi(0, 0, 10, 10),
        "set_candidates": lambda: c.set_candidates(["cork"]),
        "reset": c.reset,
        "load_table": lambda: c.load_table("sim.tmx"),
        "trigger": c.trigger,
    }
    out: dict[str, str] = {}
    for name, call in commands.items():
        try:
            call()
            out[name] = "ok"
        except tofmat.CommandError as e:
            kinds = [k for k in ("NotPermittedError", "PermissionError") if type(e).__name__ == k or
                     (k == "PermissionError" and isinstance(e, PermissionError))]  # fmt: skip
            out[name] = f"{'+'.join(kinds) or type(e).__name__}:{getattr(e, 'code', '')}"
    return out


def test_another_user_reads_labels_but_may_not_control(start: Callable[..., Daemon], shared_dir: Path,
                                                       sim_table: Path) -> None:  # fmt: skip
    d = start(SOURCE, socket_dir=shared_dir)
    owner = d.client()
    assert owner.role == "control"
    socket_path = str(d.socket)

    def as_reader() -> dict[str, Any]:
        with tofmat.Client(socket_path) as c:
            label = next(iter(c.labels(timeout=10)))
            return {"role": c.role, "label": label.profile, "status": c.status()["profile"],
                    "control": try_control(c)}  # fmt: skip

    other = OtherUser(as_reader)
    got = other.result()
    other.release()
    assert got["role"] == "read" and got["label"] == "handheld" and got["status"] == "handheld"
    # Every control command refused with NotPermittedError (a PermissionError, code "permission").
    assert got["control"] == {k: "NotPermittedError+PermissionError:permission" for k in got["control"]}
    # Nothing it asked for happened; the owner still controls.
    s = owner.status()
    assert s["profile"] == "handheld" and s["clients"]["not_permitted"] == 6
    owner.set_profile("sorting")
    assert owner.status()["profile"] == "sorting"
    owner.close()


def test_the_control_group_may_control(start: Callable[..., Daemon], shared_dir: Path) -> None:
    # The other user's primary group is root's (gid 0): naming that group gives it control.
    d = start(SOURCE, "--control-group", "root", socket_dir=shared_dir)
    d.client().close()  # (listening)
    socket_path = str(d.socket)

    def as_group_member() -> dict[str, Any]:
        with tofmat.Client(socket_path) as c:
            c.set_profile("segmentation")
            return {"role": c.role, "profile": c.status()["profile"]}

    other = OtherUser(as_group_member)
    got = other.result()
    other.release()
    assert got == {"role": "control", "profile": "segmentation"}


def test_one_user_holds_only_its_share_of_the_slots(start: Callable[..., Daemon], shared_dir: Path) -> None:
    # Issue 16, case 7: another user opens every connection it can and sits on them after hello.
    # It gets its share (4); this user's clients still connect and get labels; after the idle
    # timeout its connections are closed.
    d = start(SOURCE, "--max-clients", "8", "--max-clients-per-peer", "4", "--idle-timeout", "2",
              socket_dir=shared_dir)  # fmt: skip
    d.client().close()  # (listening)
    socket_path = str(d.socket)
    held: list[tofmat.Client] = []

    def hog() -> dict[str, int]:
        refused = 0
        for _ in range(12):
            try:
                held.append(tofmat.Client(socket_path, reconnect=False))
            except tofmat.ClientError:
                refused += 1
        return {"held": len(held), "refused": refused}

    other = OtherUser(hog)
    try:
        assert other.result() == {"held": 4, "refused": 8}
        mine = [d.client() for _ in range(4)]
        assert next(iter(mine[0].labels(timeout=10))).simulated
        for c in mine[2:]:
            c.subscribe("device")  # (subscribers are not idle)
        clients = mine[1].status()["clients"]
        assert clients["unix_clients"] == 8 and clients["rejected"] == 8
        # The hog's idle connections go after the timeout (2 s); subscribers, and a client that
        # asks, stay.
        deadline = time.monotonic() + 10.0
        while (clients := mine[1].status()["clients"])["unix_clients"] > 4:
            assert time.monotonic() < deadline, "idle connections were not closed"
            time.sleep(0.2)
        assert clients["idle_closed"] == 4 and mine[1].reconnects == 0
        assert next(iter(mine[0].labels(timeout=10))).simulated
        assert all(c.reconnects == 0 for c in mine)
        for c in mine:
            c.close()
    finally:
        other.release()


def test_readers_cannot_lock_control_out(start: Callable[..., Daemon], shared_dir: Path) -> None:
    # Issue 33: local users who may only read, each within its share, fill what they can; the
    # daemon's own user (control) still gets in, and its commands work.
    d = start(SOURCE, "--max-clients", "12", "--max-clients-per-peer", "4", socket_dir=shared_dir)
    d.client().close()  # (listening)
    socket_path = str(d.socket)

    def subscribe_all() -> dict[str, int]:
        held: list[tofmat.Client] = []
        refused = 0
        for _ in range(4):
            try:
                c = tofmat.Client(socket_path, reconnect=False)
                c.subscribe("labels")
                held.append(c)
            except tofmat.ClientError:
                refused += 1
        globals()["_held"] = held  # (kept open until released)
        return {"held": len(held), "refused": refused}

    readers = [OtherUser(subscribe_all, uid=OTHER_UID + k) for k in range(3)]
    try:
        results = [r.result() for r in readers]
        # 12 slots, 4 kept for control: the readers as a whole hold 8 of them.
        assert sum(r["held"] for r in results) == 8 and sum(r["refused"] for r in results) == 4, results
        mine = [d.client() for _ in range(4)]
        assert all(c.role == "control" for c in mine)
        mine[0].reset()  # (a control command)
        clients = mine[1].status()["clients"]
        assert clients["unix_clients"] == 12 and clients["unix_readers"] == 8
        for c in mine:
            c.close()
    finally:
        for r in readers:
            r.release()
