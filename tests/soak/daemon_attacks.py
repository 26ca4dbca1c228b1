#!/usr/bin/env python3
# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Attacks on tofmatd while a well-behaved subscriber is measured (issue 16: no client can stall,
crash, blind or take over the box).

    python3 tests/soak/daemon_attacks.py bench [--seconds 10] [--attacks flood,token_guess]
    python3 tests/soak/daemon_attacks.py soak [--seconds 1800] [--json soak.json]

Both start their own tofmatd (the SDK's binary) on the simulated camera at 30 frames/s, on a
temporary Unix socket and on TCP 127.0.0.1:<free port> with a token file, and subscribe to its
labels with tofmat.Client. `bench` runs a quiet period and then each attack alone, and prints one
Markdown table (figures only: it never fails on timing). `soak` rotates through the attacks, a few
at a time, with a Unix and a TCP subscriber, and exits 1 when the daemon died, a label came late,
or the daemon's memory or file descriptors grew (the criteria are printed with the figures).

Every attack runs in its own process (this file, `_attack NAME`), so that its busy loops do not
take the measuring process's GIL; it talks only to the daemon's own socket or to 127.0.0.1, and
it stops on SIGTERM, when this process goes away, or after its own time limit. See README.md.
"""

from __future__ import annotations

import argparse
import errno
import json
import math
import os
import pwd
import random
import secrets
import select
import shlex
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

import tofmat
from tofmat.client import daemon_binary, sim_data_dir

# --- the scene and the criteria -------------------------------------------------------------

SCENE_MATERIALS = ["cork", "paper", "acryl", "pvc"]
SCENE_FRAMES, SCENE_GAP = 30, 6
SCENE = f"sim:sweep,materials={'+'.join(SCENE_MATERIALS)},frames={SCENE_FRAMES},gap={SCENE_GAP}"  # realtime: 30/s
TABLE_MATERIALS = ["cork", "paper", "acryl", "pvc", "wood", "plaster", "mdf", "polystyrene"]
FRAME_MS = 1000.0 / 30.0
GAP_LIMIT_MS = 100.0  # soak: the longest gap between labels that the scene does not explain
RSS_GROWTH_LIMIT = 0.10  # soak: from the 60-s sample to the end
FD_GROWTH_LIMIT = 16  # soak: from before the first attack to after the last
FRESH_CLIENT_LIMIT_S = 2.0  # a new client connects and gets status() within this
DEFAULT_SLOTS = 80  # idle_slots / tcp_unauth: more than the daemon's 64 connections
OTHER_UID = 12345  # run as root, the Unix attacks run as users from here on (unused ones), in the socket's group
ATTACKER_TCP_SOURCE = "127.0.0.2"  # TCP attacks connect to 127.0.0.1 from here: another peer than the good client

# --- the wire format, by hand (firmware/protocol/include/tofmat/protocol/wire.hpp) ------------

HEADER = struct.Struct("<4sHBBI")  # magic, version, type, flags, payload length
MAGIC, VERSION = b"TMAT", 1
HELLO, REQUEST, REPLY, EVENT = 1, 2, 3, 4
MAX_PAYLOAD = 4 * 1024 * 1024

Address = str | tuple[str, int]  # a Unix socket path, or ("127.0.0.1", port)


def encode(kind: int, meta: dict[str, Any], blob: bytes = b"") -> bytes:
    """One message: the 12-byte header, the metadata length, the JSON metadata, the blob."""
    m = json.dumps(meta, separators=(",", ":")).encode()
    return HEADER.pack(MAGIC, VERSION, kind, 0, 4 + len(m) + len(blob)) + struct.pack("<I", len(m)) + m + blob


def request(rid: int, cmd: str, args: dict[str, Any] | None = None) -> bytes:
    return encode(REQUEST, {"id": rid, "cmd": cmd, "args": args or {}})


class Closed(ConnectionError):
    """The daemon closed the connection."""


class WireError(Exception):
    """The daemon sent something that is not a message of protocol version 1."""


@dataclass
class Message:
    kind: int
    meta: dict[str, Any]
    blob: bytes


def check_target(address: Address) -> None:
    """Attacks go to the daemon's own Unix socket or to the loopback address, nowhere else."""
    if isinstance(address, tuple) and address[0] != "127.0.0.1":
        raise ValueError(f"refusing to attack {address[0]}: only 127.0.0.1")


def open_socket(address: Address, timeout: float, source: str = "") -> socket.socket:
    """A connection to `address`; TCP from the loopback address `source` when given."""
    check_target(address)
    s = socket.socket(socket.AF_INET if isinstance(address, tuple) else socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(timeout)
    try:
        if source and isinstance(address, tuple):
            s.bind((source, 0))
        s.connect(address)
    except BaseException:
        s.close()
        raise
    return s


class RawConnection:
    """A connection that speaks the protocol by hand: what a well-behaved client never does."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._buf = bytearray()
        self._next_id = 1
        self.server_hello: dict[str, Any] = {}

    @classmethod
    def open(cls, address: Address, timeout: float = 2.0, source: str = "") -> RawConnection:
        return cls(open_socket(address, timeout, source))

    def close(self) -> None:
        self.sock.close()

    def _fill(self, deadline: float) -> None:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError("no message from tofmatd in time")
        self.sock.settimeout(remaining)
        chunk = self.sock.recv(65536)
        if not chunk:
            raise Closed("tofmatd closed the connection")
        self._buf += chunk

    def read(self, timeout: float) -> Message:
        deadline = time.monotonic() + timeout
        while len(self._buf) < HEADER.size:
            self._fill(deadline)
        magic, version, kind, flags, length = HEADER.unpack_from(self._buf)
        if magic != MAGIC or version != VERSION or flags != 0 or not 4 <= length <= MAX_PAYLOAD:
            raise WireError(f"bad header {bytes(self._buf[: HEADER.size])!r}")
        while len(self._buf) < HEADER.size + length:
            self._fill(deadline)
        (meta_len,) = struct.unpack_from("<I", self._buf, HEADER.size)
        if meta_len > length - 4:
            raise WireError("metadata longer than the payload")
        start = HEADER.size + 4
        meta = json.loads(bytes(self._buf[start : start + meta_len]))
        blob = bytes(self._buf[start + meta_len : HEADER.size + length])
        del self._buf[: HEADER.size + length]
        if not isinstance(meta, dict):
            raise WireError("metadata is not an object")
        return Message(kind, meta, blob)

    def call(self, cmd: str, args: dict[str, Any] | None = None, timeout: float = 5.0) -> dict[str, Any]:
        """Sends one request and returns its reply's metadata (events in between are skipped)."""
        rid = self._next_id
        self._next_id += 1
        self.sock.settimeout(timeout)
        self.sock.sendall(request(rid, cmd, args))
        deadline = time.monotonic() + timeout
        while True:
            m = self.read(deadline - time.monotonic())
            if m.kind == REPLY and m.meta.get("id") == rid:
                return m.meta

    def handshake(self, token: str | None = None, timeout: float = 5.0) -> dict[str, Any]:
        """The daemon's hello, then ours; returns the reply (``ok`` false when refused)."""
        hello = self.read(timeout)
        if hello.kind != HELLO:
            raise WireError(f"expected the daemon's hello, got type {hello.kind}")
        self.server_hello = hello.meta
        args: dict[str, Any] = {"protocol": VERSION, "client": "daemon_attacks"}
        if token is not None:
            args["token"] = token
        return self.call("hello", args, timeout)


def reply_code(reply: dict[str, Any]) -> str:
    return "accepted" if reply.get("ok") else str(reply.get("code", "?"))


# --- attacks (each runs in its own process: `daemon_attacks.py _attack NAME --config JSON`) ----


@dataclass
class AttackConfig:
    socket_path: str
    tcp_port: int
    token: str
    table_dir: str  # the daemon's table directory (the folder of its --table)
    table_name: str  # its table's file name there
    outside_dir: str  # a folder outside the table directory
    second_daemon: list[str]  # a second tofmatd's command line on the same socket
    log_dir: str
    max_seconds: float  # the attack stops by itself after this
    slots: int = DEFAULT_SLOTS
    other_uid: int | None = None  # run the attacks marked as_other_user as this user (root only)
    tcp_source: str = ""  # TCP attacks connect from this loopback address


class Attack:
    """One attack: `setup` (as the starting user), then `threads` workers until `stop` is set."""

    name: ClassVar[str] = ""
    case: ClassVar[str] = ""  # issue 16's case
    summary: ClassVar[str] = ""
    threads: ClassVar[int] = 1
    engaged_by: ClassVar[tuple[str, ...]] = ("connections",)  # counts (prefixes) that show it got to act

    def __init__(self, cfg: AttackConfig, stop: threading.Event) -> None:
        self.cfg, self.stop = cfg, stop
        self.counts: Counter[str] = Counter()
        self.peaks: dict[str, float] = {}
        self.notes: dict[str, str] = {}
        self._lock = threading.Lock()
        self.started = time.monotonic()

    @property
    def unix(self) -> Address:
        return self.cfg.socket_path

    @property
    def tcp(self) -> Address:
        return ("127.0.0.1", self.cfg.tcp_port)

    def open_tcp(self, timeout: float = 2.0) -> RawConnection:
        return RawConnection.open(self.tcp, timeout, self.cfg.tcp_source)

    def count(self, key: str, n: int = 1) -> None:
        with self._lock:
            self.counts[key] += n

    def peak(self, key: str, value: float) -> None:
        with self._lock:
            self.peaks[key] = max(self.peaks.get(key, value), value)

    def setup(self) -> None:
        pass

    def teardown(self) -> None:
        pass

    as_other_user: ClassVar[bool] = False  # a local user in the socket's group, not the daemon's

    def drop_privileges(self) -> None:
        """Run as root, an attack `as_other_user` becomes cfg.other_uid with the socket's group."""
        uid = self.cfg.other_uid
        if not self.as_other_user:
            return
        if uid is None or os.geteuid() != 0:
            self.notes["as"] = f"uid {os.geteuid()}, the daemon's user"
            return
        gid = os.stat(self.cfg.socket_path).st_gid
        os.setgroups([])
        os.setgid(gid)
        os.setuid(uid)
        self.notes["as"] = f"uid {uid} gid {gid}"

    def worker(self, index: int) -> None:
        raise NotImplementedError

    def _guarded(self, index: int) -> None:
        try:
            self.worker(index)
        except Exception as e:
            self.notes[f"worker{index}_crashed"] = f"{type(e).__name__}: {e}"

    def run(self) -> None:
        threads = [threading.Thread(target=self._guarded, args=(i,), daemon=True) for i in range(self.threads)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()

    def headline(self, seconds: float) -> str:
        return ", ".join(f"{k} {v}" for k, v in sorted(self.counts.items()))

    def result(self) -> dict[str, Any]:
        seconds = max(time.monotonic() - self.started, 1e-9)
        engaged = any(v > 0 for k, v in self.counts.items() for p in self.engaged_by if k.startswith(p))
        return {"attack": self.name, "seconds": round(seconds, 2), "counts": dict(self.counts),
                "peaks": self.peaks, "notes": self.notes, "headline": self.headline(seconds),
                "engaged": engaged}  # fmt: skip


def _error_name(e: BaseException) -> str:
    if isinstance(e, OSError) and e.errno is not None and not isinstance(e, Closed):
        return errno.errorcode.get(e.errno, str(e.errno))
    return type(e).__name__


class Flood(Attack):
    name, case, threads = "flood", "1", 2
    as_other_user = True
    summary = "after hello, pipelines `status` requests as fast as the socket takes them and never reads"

    def worker(self, index: int) -> None:
        one = request(1, "status")  # the same id: every request has the same length
        batch = one * 256
        while not self.stop.is_set():
            try:
                conn = RawConnection.open(self.unix)
                if not conn.handshake(timeout=2.0).get("ok"):
                    conn.close()
                    self.count("hello_refused")
                    self.stop.wait(0.05)
                    continue
            except (OSError, WireError) as e:
                self.count(f"connect_{_error_name(e)}")
                self.stop.wait(0.05)
                continue
            self.count("connections")
            conn.sock.settimeout(0.2)
            view, offset = memoryview(batch), 0
            try:
                while not self.stop.is_set():
                    try:
                        n = conn.sock.send(view[offset:])
                    except TimeoutError:
                        continue  # the socket is full: the daemon reads no faster
                    self.count("bytes", n)
                    offset = (offset + n) % len(batch)
            except OSError:
                self.count("closed_by_daemon")
            finally:
                conn.close()

    def headline(self, seconds: float) -> str:
        sent = self.counts["bytes"] // len(request(1, "status"))
        return (f"{sent / seconds:.0f} req/s written, {self.counts['connections']} conns, "
                f"{self.counts['closed_by_daemon']} closed by daemon")  # fmt: skip


class LoadTable(Attack):
    name, case = "load_table", "2"
    summary = ("`load_table` of a FIFO inside and outside the table directory, `../../etc/shadow`, "
               "`/etc/shadow`, a symlink out of the directory (to a file and to a FIFO), in a loop")  # fmt: skip

    def setup(self) -> None:
        tag = f"attack{os.getpid()}"
        table_dir, outside = Path(self.cfg.table_dir), Path(self.cfg.outside_dir)
        self.fifo_in, self.fifo_out = table_dir / f"{tag}-fifo.tmx", outside / f"{tag}-fifo.tmx"
        self.secret = outside / f"{tag}-secret.tmx"
        self.link, self.link_fifo = table_dir / f"{tag}-link.tmx", table_dir / f"{tag}-link-fifo.tmx"
        os.mkfifo(self.fifo_in)
        os.mkfifo(self.fifo_out)
        self.secret.write_bytes((table_dir / self.cfg.table_name).read_bytes())
        self.link.symlink_to(self.secret)
        self.link_fifo.symlink_to(self.fifo_out)
        self.names = {self.fifo_in.name: "fifo_in", str(self.fifo_out): "fifo_out", "../../etc/shadow": "dotdot_shadow",
                      "/etc/shadow": "etc_shadow", self.link.name: "link_out", self.link_fifo.name: "link_fifo_out",
                      f"../{outside.name}/{self.secret.name}": "dotdot_file"}  # fmt: skip

    def teardown(self) -> None:
        for p in (self.fifo_in, self.fifo_out, self.secret, self.link, self.link_fifo):
            p.unlink(missing_ok=True)

    def unblock_fifos(self) -> None:
        """A daemon stuck opening a FIFO for reading gets a writer, and with it EOF."""
        for p in (self.fifo_in, self.fifo_out):
            try:
                os.close(os.open(p, os.O_WRONLY | os.O_NONBLOCK))
                self.count("fifo_had_a_reader")
            except OSError:
                pass

    def paths(self) -> dict[str, str]:
        """Path sent -> its label in the counts."""
        return self.names

    def worker(self, index: int) -> None:
        conn: RawConnection | None = None
        k = 0
        paths = list(self.paths().items())
        while not self.stop.is_set():
            if conn is None:
                try:
                    conn = RawConnection.open(self.unix)
                    conn.handshake(timeout=2.0)
                    self.count("connections")
                except (OSError, WireError) as e:
                    self.count(f"connect_{_error_name(e)}")
                    conn = None
                    self.stop.wait(0.05)
                    continue
            path, label = paths[k % len(paths)]
            k += 1
            t0 = time.monotonic()
            try:
                reply = conn.call("load_table", {"path": path}, timeout=5.0)
                code = reply_code(reply)
                self.peak("max_reply_ms", (time.monotonic() - t0) * 1000.0)
                self.count(code)
                self.count(f"{label}:{code}")
                self.notes.setdefault(label, f"{code}: {str(reply.get('error', ''))[:160]}")
            except TimeoutError:
                self.count("no_reply_5s")
                self.notes[f"no_reply:{path}"] = "no reply within 5 s"
                self.unblock_fifos()
                conn.close()
                conn = None
            except (OSError, WireError):
                self.count("closed")
                conn.close()
                conn = None
        if conn is not None:
            conn.close()

    def headline(self, seconds: float) -> str:
        c = self.counts
        n = sum(v for k, v in c.items() if ":" not in k and k not in ("connections", "no_reply_5s", "closed",
                                                                         "fifo_had_a_reader")
                and not k.startswith("connect_"))  # fmt: skip
        by_path = " ".join(f"{label}={'+'.join(sorted(k.split(':')[1] for k in c if k.startswith(label + ':')))}"
                           for label in self.paths().values())  # fmt: skip
        trouble = " ".join(f"{k}={c[k]}" for k in ("no_reply_5s", "closed", "fifo_had_a_reader") if c[k])
        return (f"{n / seconds:.0f} replies/s, max reply {self.peaks.get('max_reply_ms', 0.0):.1f} ms; "
                f"{by_path} {trouble}").rstrip()  # fmt: skip


class BigFolder(LoadTable):
    name, case = "big_folder", "3"
    summary = "a folder of 300 small `.npy` files in the table directory, `load_table`d in a loop"

    def setup(self) -> None:
        self.folder = Path(self.cfg.table_dir) / f"attack{os.getpid()}-big"
        self.folder.mkdir()
        curve = np.zeros((2, 4), np.float32)
        for i in range(300):
            np.save(self.folder / f"m{i:03}.npy", curve)

    def teardown(self) -> None:
        for p in self.folder.iterdir():
            p.unlink()
        self.folder.rmdir()

    def unblock_fifos(self) -> None:
        pass

    def paths(self) -> dict[str, str]:
        return {self.folder.name: "relative", str(self.folder): "absolute"}


class SecondDaemon(Attack):
    name, case = "second_daemon", "5"
    engaged_by = ("started",)
    summary = "starts a second tofmatd on the same socket path, again and again; checks the first still answers"

    def setup(self) -> None:
        self.inode = os.stat(self.cfg.socket_path).st_ino
        self.log = Path(self.cfg.log_dir) / f"second-daemon-{os.getpid()}.log"

    def worker(self, index: int) -> None:
        with self.log.open("ab") as log:
            while not self.stop.is_set():
                p = subprocess.Popen(self.cfg.second_daemon, stdout=log, stderr=subprocess.STDOUT)
                self.count("started")
                try:
                    rc = p.wait(10)
                    self.count("refused" if rc != 0 else "exit_0")
                    self.count(f"exit_{rc}")
                except subprocess.TimeoutExpired:
                    self.count("still_running_10s")  # it took the socket, or hangs
                    p.send_signal(signal.SIGTERM)
                    try:
                        p.wait(10)
                    except subprocess.TimeoutExpired:
                        p.kill()
                        p.wait()
                try:
                    if os.stat(self.cfg.socket_path).st_ino != self.inode:
                        self.count("socket_file_replaced")
                        self.inode = os.stat(self.cfg.socket_path).st_ino
                except FileNotFoundError:
                    self.count("socket_file_removed")
                try:
                    conn = RawConnection.open(self.unix, 2.0)
                    try:
                        conn.read(2.0)  # the first daemon's hello
                    finally:
                        conn.close()
                    self.count("first_answers")
                except (Closed, ConnectionResetError):
                    self.count("first_full")  # it answers, but closes at once: no slot free
                except (OSError, WireError) as e:
                    self.count(f"first_silent_{_error_name(e)}")
                self.stop.wait(0.2)
        lines = self.log.read_text(errors="replace").splitlines()
        reasons = [ln for ln in lines if "socket" in ln or "listening" in ln]
        if reasons:
            self.notes["refusal"] = reasons[-1][-200:]

    def headline(self, seconds: float) -> str:
        c = self.counts
        return (f"{c['started']} started, {c['refused']} refused, {c['still_running_10s']} still running, "
                f"first answered {c['first_answers']} (full {c['first_full']}, "
                f"silent {sum(v for k, v in c.items() if k.startswith('first_silent'))}), "
                f"socket replaced {c['socket_file_replaced']}, removed {c['socket_file_removed']}")  # fmt: skip


class Slots(Attack):
    """Holds `slots` connections open, re-opening any the daemon closes."""

    address_kind: ClassVar[str] = "unix"
    do_hello: ClassVar[bool] = True
    engaged_by = ("opened",)

    def open_one(self) -> socket.socket | None:
        try:
            if self.do_hello:
                conn = RawConnection.open(self.unix) if self.address_kind == "unix" else self.open_tcp()
                if not conn.handshake(timeout=2.0).get("ok"):
                    conn.close()
                    self.count("hello_refused")
                    return None
                sock = conn.sock
            else:
                sock = (open_socket(self.unix, 2.0) if self.address_kind == "unix"
                        else open_socket(self.tcp, 2.0, self.cfg.tcp_source))  # fmt: skip
            self.count("opened")
            sock.setblocking(False)
            return sock
        except (Closed, ConnectionResetError):
            self.count("refused")  # accepted and closed at once: the daemon is full
        except (OSError, WireError) as e:
            self.count(f"connect_{_error_name(e)}")
        return None

    def _reap(self, socks: list[socket.socket | None], opened: list[float], timeout: float) -> int:
        """Closes the connections the daemon closed (within `timeout`); how many."""
        live = [s for s in socks if s is not None]
        readable, _, _ = select.select(live, [], [], timeout) if live else ([], [], [])
        now, closed = time.monotonic(), 0
        for s in readable:
            try:
                data = s.recv(65536)  # (the hello of a connection that did not send its own)
            except BlockingIOError:
                continue
            except OSError:
                data = b""
            if not data:
                i = socks.index(s)
                self.count("refused" if now - opened[i] < 0.5 else "closed_by_daemon")
                s.close()
                socks[i] = None
                closed += 1
        return closed

    def worker(self, index: int) -> None:
        socks: list[socket.socket | None] = [None] * self.cfg.slots
        opened = [0.0] * self.cfg.slots
        try:
            while not self.stop.is_set():
                for i, s in enumerate(socks):
                    if s is None and not self.stop.is_set():
                        socks[i], opened[i] = self.open_one(), time.monotonic()
                missing = socks.count(None)
                closed = self._reap(socks, opened, 0.2) + self._reap(socks, opened, 0.0)  # (late closes too)
                # Held: open for half a second at least (a full daemon accepts and closes at once).
                now = time.monotonic()
                held = sum(1 for s, t in zip(socks, opened, strict=True) if s is not None and now - t >= 0.5)
                self.peak("held", held)
                if closed or missing:
                    self.stop.wait(0.2)  # re-open at a bounded rate
        finally:
            for s in socks:
                if s is not None:
                    s.close()

    def headline(self, seconds: float) -> str:
        c = self.counts
        extra = " ".join(f"{k}={v}" for k, v in sorted(c.items()) if k.startswith(("connect_", "hello_")))
        return (f"held {self.peaks.get('held', 0):.0f} of {self.cfg.slots}, {c['opened']} opened, "
                f"{c['refused']} refused, {c['closed_by_daemon']} closed by daemon {extra}").rstrip()  # fmt: skip


class IdleSlots(Slots):
    name, case = "idle_slots", "7a"
    as_other_user = True
    summary = f"{DEFAULT_SLOTS} Unix connections that say hello and then sit idle, re-opened when closed"


class TcpUnauth(Slots):
    name, case = "tcp_unauth", "7b"
    summary = f"{DEFAULT_SLOTS} TCP connections that never send hello, re-opened when closed"
    address_kind, do_hello = "tcp", False


class TokenGuess(Attack):
    name, case, threads = "token_guess", "7c", 2
    engaged_by = ("answered",)
    summary = "TCP hello with a wrong token, in a loop as fast as the daemon answers"

    def worker(self, index: int) -> None:
        while not self.stop.is_set():
            try:
                conn = self.open_tcp()
            except OSError as e:
                self.count(f"connect_{_error_name(e)}")
                self.stop.wait(0.01)
                continue
            try:
                code = reply_code(conn.handshake(token=secrets.token_hex(16), timeout=2.0))
                self.count("answered" if code == "auth" else f"answer_{code}")
            except TimeoutError:
                self.count("no_answer_2s")
            except Closed:
                self.count("closed_without_answer")
            except (OSError, WireError) as e:
                self.count(f"error_{_error_name(e)}")
            finally:
                conn.close()

    def headline(self, seconds: float) -> str:
        c = self.counts
        rest = " ".join(f"{k}={v}" for k, v in sorted(c.items()) if k != "answered")
        return f"{c['answered'] / seconds:.0f} tries/s answered ({c['answered']}) {rest}".rstrip()


class ConnectClose(Attack):
    name, case, threads = "connect_close", "7d", 2
    engaged_by = ("connects",)
    as_other_user = True
    summary = "connects to the Unix socket and closes at once, in a loop"

    def worker(self, index: int) -> None:
        while not self.stop.is_set():
            try:
                open_socket(self.unix, 1.0).close()
                self.count("connects")
            except OSError as e:
                self.count(f"error_{_error_name(e)}")
                self.stop.wait(0.001)

    def headline(self, seconds: float) -> str:
        errors = " ".join(f"{k}={v}" for k, v in sorted(self.counts.items()) if k != "connects")
        return f"{self.counts['connects'] / seconds:.0f} connects/s {errors}".rstrip()


class Control(Attack):
    name, case, threads = "control", "8", 2
    engaged_by = ("unix:set_", "unix:reset:", "unix:load_table:", "tcp:set_", "tcp:reset:", "tcp:load_table:")
    as_other_user = True
    summary = ("set_profile / set_roi / set_candidates / reset / load_table, 20 a second, over Unix as a "
               "user other than the daemon's (in the socket's group) and over TCP with the token")  # fmt: skip

    def commands(self) -> list[tuple[str, dict[str, Any]]]:
        return [("set_profile", {"name": "segmentation"}), ("set_roi", {"x0": 0, "y0": 0, "x1": 16, "y1": 16}),
                ("set_candidates", {"materials": ["cork"]}), ("reset", {}),
                ("load_table", {"path": self.cfg.table_name}), ("set_profile", {"name": "sorting"})]  # fmt: skip

    def worker(self, index: int) -> None:
        transport = "unix" if index == 0 else "tcp"
        token = None if index == 0 else self.cfg.token
        conn: RawConnection | None = None
        k = 0
        while not self.stop.is_set():
            if conn is None:
                try:
                    conn = RawConnection.open(self.unix) if index == 0 else self.open_tcp()
                    code = reply_code(conn.handshake(token=token, timeout=2.0))
                    if code != "accepted":
                        self.count(f"{transport}:hello_{code}")
                        conn.close()
                        conn = None
                        self.stop.wait(0.5)
                        continue
                except (OSError, WireError) as e:
                    self.count(f"{transport}:connect_{_error_name(e)}")
                    conn = None
                    self.stop.wait(0.2)
                    continue
            cmd, args = self.commands()[k % len(self.commands())]
            k += 1
            try:
                code = reply_code(conn.call(cmd, args, timeout=5.0))
                self.count(f"{transport}:{code}")
                self.count(f"{transport}:{cmd}:{code}")
            except (OSError, WireError):
                self.count(f"{transport}:closed")
                conn.close()
                conn = None
            self.stop.wait(0.05)
        if conn is not None:
            conn.close()

    def headline(self, seconds: float) -> str:
        c = self.counts
        parts = []
        for t in ("unix", "tcp"):
            other = " ".join(f"{key.split(':')[1]}={v}" for key, v in sorted(c.items())
                             if key.startswith(f"{t}:") and key.count(":") == 1
                             and key not in (f"{t}:accepted", f"{t}:permission"))  # fmt: skip
            parts.append(f"{t}: refused {c[f'{t}:permission']} / accepted {c[f'{t}:accepted']}"
                         + (f" / {other}" if other else ""))  # fmt: skip
        return "; ".join(parts)


ATTACKS: dict[str, type[Attack]] = {a.name: a for a in (Flood, LoadTable, BigFolder, SecondDaemon, IdleSlots, TcpUnauth,
                                                        TokenGuess, ConnectClose, Control)}  # fmt: skip


def attack_main(name: str, cfg: AttackConfig) -> int:
    """The body of an attack process: ready on stdout, then its result as one JSON line on stop."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    parent = os.getppid()
    attack = ATTACKS[name](cfg, stop)
    attack.setup()
    try:
        attack.drop_privileges()
        print("ready", flush=True)
        runner = threading.Thread(target=attack.run, daemon=True)
        runner.start()
        deadline = time.monotonic() + cfg.max_seconds
        while not stop.wait(0.2):
            if time.monotonic() > deadline or os.getppid() != parent:
                stop.set()
        runner.join(20)
        if runner.is_alive():
            attack.notes["stuck"] = "a worker did not stop within 20 s"
    finally:
        try:
            attack.teardown()
        except OSError as e:
            attack.notes["teardown"] = str(e)
    print(json.dumps(attack.result()), flush=True)
    return 0


class AttackProcess:
    """An attack in its own process, started and stopped from the measuring one."""

    def __init__(self, name: str, cfg: AttackConfig, log: Path) -> None:
        self.name = name
        self._log = log
        self._stderr = log.open("ab")
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "_attack", name, "--config",
                                      json.dumps(asdict(cfg))], stdout=subprocess.PIPE, stderr=self._stderr,
                                     text=True)  # fmt: skip
        # An ordinary user's niceness (0), whatever --client-nice gave the harness. (Set from here:
        # a preexec_fn is not safe in a process with threads, as the harness is.)
        os.setpriority(os.PRIO_PROCESS, self.proc.pid, 0)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if line != "ready":
            self.proc.kill()
            self.proc.wait()
            self._stderr.close()
            raise RuntimeError(f"attack {name} did not start (see {log})")

    def terminate(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)

    def stop(self) -> dict[str, Any]:
        self.terminate()
        try:
            out, _ = self.proc.communicate(timeout=40)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
        self._stderr.close()
        for line in reversed(out.splitlines()):
            if line.startswith("{"):
                result: dict[str, Any] = json.loads(line)
                return result
        tail = self._log.read_text(errors="replace")[-600:] if self._log.exists() else ""
        return {"attack": self.name, "seconds": 0.0, "counts": {}, "peaks": {}, "notes": {"error": "no result"},
                "headline": f"no result (exit {self.proc.returncode}); its stderr ends: {tail!r}"}  # fmt: skip


# --- the daemon under test ------------------------------------------------------------------


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def make_sim_table(path: Path) -> None:
    """The simulated camera's own table of a few materials (as tests/python/test_daemon.py's sim_table)."""
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    r = Renderer(load_device(), load_library(), 1)
    simulated_table(r, TABLE_MATERIALS, database_bins()).save(str(path))


def say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


class DaemonUnderTest:
    """tofmatd on the simulated camera: a Unix socket, TCP on 127.0.0.1 with a token, a log file."""

    def __init__(self, workdir: Path, extra_args: Sequence[str], nice: int = 0) -> None:
        self.workdir = workdir
        self.nice = nice  # the daemon's niceness (the box's unit gives tofmatd Nice=-5)
        # Other users (the control attack's) reach the socket through the folder; the socket's
        # mode and group decide the rest.
        workdir.chmod(0o755)
        self.table_dir = workdir / "tables"
        self.table_dir.mkdir()
        self.outside_dir = workdir / "outside"
        self.outside_dir.mkdir()
        self.table = self.table_dir / "sim.tmx"
        make_sim_table(self.table)
        self.socket = workdir / "tofmatd.sock"
        self.log = workdir / "tofmatd.log"
        self.token = secrets.token_hex(16)  # 32 characters
        self.token_file = workdir / "token"
        fd = os.open(self.token_file, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(self.token + "\n")
        self.port = free_port()
        self.extra_args = list(extra_args)
        self.proc: subprocess.Popen[bytes] | None = None
        self.deaths: list[str] = []
        self._log_offset = 0
        self._log_lines = 0

    def command(self, second: bool = False) -> list[str]:
        cmd = [str(daemon_binary()), "--source", SCENE, "--table", str(self.table), "--socket", str(self.socket),
               "--sim-data", str(sim_data_dir())]  # fmt: skip
        if not second:  # (a second daemon without TCP: its failure is the socket's)
            cmd += ["--tcp", f"127.0.0.1:{self.port}", "--token-file", str(self.token_file)]
        return cmd + self.extra_args

    @property
    def tcp_address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def start(self) -> None:
        with self.log.open("ab") as log:
            self.proc = subprocess.Popen(self.command(), stdout=log, stderr=subprocess.STDOUT)
        # Absolute, whatever the harness's own (--client-nice); set from here: a preexec_fn is not
        # safe in a process with threads.
        os.setpriority(os.PRIO_PROCESS, self.proc.pid, self.nice)
        deadline = time.monotonic() + 30.0
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"tofmatd exited with {self.proc.returncode} at start:\n{self.log_tail()}")
            try:
                with tofmat.Client(self.socket, timeout=2.0, reconnect=False) as c:
                    c.status()
                return
            except (tofmat.ClientError, OSError):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"tofmatd did not answer within 30 s:\n{self.log_tail()}") from None
                time.sleep(0.1)

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None and self.proc.poll() is None else None

    def alive(self) -> bool:
        return self.pid is not None

    def check_alive(self, during: str) -> bool:
        """Restarts a daemon that died, saying so loudly; True when it had to."""
        if self.proc is None or self.proc.poll() is None:
            return False
        why = f"tofmatd DIED during {during} (exit status {self.proc.returncode})"
        self.deaths.append(why)
        say(f"\n!!!!!!!! {why}; its last log lines:\n{self.log_tail()}\n!!!!!!!! restarting it\n")
        self.start()
        return True

    def stop(self) -> int | None:
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def log_tail(self, n: int = 15) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])
        except FileNotFoundError:
            return "(no log)"

    def rss_kb(self) -> int | None:
        pid = self.pid
        if pid is None:
            return None
        try:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
        except OSError:
            pass
        return None

    def cpu_s(self) -> float | None:
        """CPU time the daemon used so far (user + system), in seconds."""
        pid = self.pid
        if pid is None:
            return None
        try:
            rest = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            return (int(rest[11]) + int(rest[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, IndexError, ValueError):
            return None

    def fds(self) -> int | None:
        pid = self.pid
        try:
            return len(os.listdir(f"/proc/{pid}/fd")) if pid is not None else None
        except OSError:
            return None

    def log_size(self) -> tuple[int, int]:
        """(bytes, lines) of the log, read incrementally."""
        try:
            with self.log.open("rb") as f:
                f.seek(self._log_offset)
                data = f.read()
        except FileNotFoundError:
            return 0, 0
        self._log_offset += len(data)
        self._log_lines += data.count(b"\n")
        return self._log_offset, self._log_lines

    def status(self) -> dict[str, Any] | None:
        try:
            with tofmat.Client(self.socket, timeout=2.0, reconnect=False) as c:
                return c.status()
        except (tofmat.ClientError, OSError):
            return None

    def attack_config(self, max_seconds: float, slots: int, other_uid: int | None) -> AttackConfig:
        return AttackConfig(socket_path=str(self.socket), tcp_port=self.port, token=self.token,
                            table_dir=str(self.table_dir), table_name=self.table.name,
                            outside_dir=str(self.outside_dir), second_daemon=self.command(second=True),
                            log_dir=str(self.workdir), max_seconds=max_seconds, slots=slots,
                            other_uid=other_uid, tcp_source=tcp_source())  # fmt: skip


def tcp_source() -> str:
    """ATTACKER_TCP_SOURCE where it can be bound (Linux routes all of 127/8 to lo), else none."""
    try:
        with socket.socket() as s:
            s.bind((ATTACKER_TCP_SOURCE, 0))
        return ATTACKER_TCP_SOURCE
    except OSError:
        return ""


def attacker_uids(args: argparse.Namespace) -> dict[str, int]:
    """Run as root: an unused uid for each attack, so that attacks running together are different
    users (a per-user limit of the daemon then bounds each, not all of them together)."""
    if args.same_user or os.geteuid() != 0:
        return {}
    uids: dict[str, int] = {}
    for name in ATTACKS:
        uids[name] = unused_uid(max(uids.values(), default=OTHER_UID - 1) + 1)
    return uids


def unused_uid(start: int = OTHER_UID) -> int:
    uid = start
    while True:
        try:
            pwd.getpwuid(uid)
        except KeyError:
            return uid
        uid += 1


# --- measuring --------------------------------------------------------------------------------


@dataclass
class LabelRecord:
    arrival: float  # time.monotonic() when the subscriber read it
    latency_ms: float  # the frame's arrival in the daemon to this client (label.latency_ms)
    frame: int
    timestamp_ns: int  # the daemon's frame time (CLOCK_MONOTONIC)
    state: str


class BackgroundThread:
    """What the harness's measuring threads share: `_run` on a daemon thread from start() until
    stop() sets `_stop` (and waits up to JOIN_S for it), and a lock for what it collects."""

    JOIN_S = 5.0

    def __init__(self, name: str) -> None:
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(self.JOIN_S)

    def _run(self) -> None:
        raise NotImplementedError


class Subscriber(BackgroundThread):
    """A well-behaved client on its own thread: tofmat.Client's label stream, every label timed."""

    JOIN_S = 10.0

    def __init__(self, address: str, token: str | None = None, name: str = "unix") -> None:
        self.address, self.token, self.name = address, token, name
        self.records: list[LabelRecord] = []
        self.errors: Counter[str] = Counter()
        self.reconnects = 0
        super().__init__(f"subscriber-{name}")

    def start(self, wait_s: float = 30.0) -> None:
        super().start()
        deadline = time.monotonic() + wait_s
        while not self.records:
            if time.monotonic() > deadline:
                raise RuntimeError(f"subscriber {self.name}: no label within {wait_s} s ({dict(self.errors)})")
            time.sleep(0.05)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                client = tofmat.Client(self.address, token=self.token, timeout=5.0, reconnect=True,
                                       reconnect_timeout=10.0)  # fmt: skip
            except (tofmat.ClientError, OSError) as e:
                self.errors[f"connect {type(e).__name__}"] += 1
                self._stop.wait(0.2)
                continue
            try:
                with client:
                    while not self._stop.is_set():
                        try:
                            for label in client.labels(timeout=1.0):
                                r = LabelRecord(time.monotonic(), label.latency_ms, label.frame, label.timestamp_ns,
                                                label.state)  # fmt: skip
                                with self._lock:
                                    self.records.append(r)
                                if self._stop.is_set():
                                    break
                        except tofmat.DaemonTimeoutError:
                            self.errors["no label for 1 s"] += 1
                    self.reconnects += client.reconnects
            except (tofmat.ClientError, OSError) as e:
                self.errors[type(e).__name__] += 1
                self._stop.wait(0.2)

    def window(self, t0: float, t1: float) -> list[LabelRecord]:
        with self._lock:
            return [r for r in self.records if t0 <= r.arrival <= t1]

    def before(self, t: float) -> LabelRecord | None:
        with self._lock:
            earlier = [r for r in self.records[-200:] if r.arrival < t]
        return earlier[-1] if earlier else None


@dataclass
class LabelStats:
    labels: int = 0
    seconds: float = 0.0
    rate: float = 0.0
    p50_ms: float = float("nan")
    p99_ms: float = float("nan")
    max_ms: float = float("nan")
    gap_ms: float = float("nan")  # longest wait for a label that the scene does not explain (below)
    raw_gap_ms: float = float("nan")  # longest wait for any label, the scene's empty frames included
    missed_frames: int = 0  # frames with a target in view that gave no label
    camera_fps: float = float("nan")  # the camera's frames a second over the window (by its frame numbers and clock)
    source_gap_ms: float = float("nan")  # longest frame interval while tracking, by the daemon's frame clock
    # The longest time the harness itself was not run (HostStallWitness) during the longest gap or the
    # slowest label's wait: what of those two figures is the harness's own doing, at most.
    host_stall_ms: float = 0.0
    gap_end: float = float(
        "nan"
    )  # when the longest gap ended (time.monotonic of the label after it, or the window's end)


def label_stats(records: Sequence[LabelRecord], t0: float, t1: float, before: LabelRecord | None = None,
                witness: HostStallWitness | None = None) -> LabelStats:  # fmt: skip
    """Figures of the labels that arrived in [t0, t1].

    The sweep labels every frame while a target is in view (`tracking`, then one `no_target` when
    it leaves) and then nothing for its empty frames. So `gap_ms` is, between consecutive labels:
    the arrival gap after a `tracking` label (the next frame's label is due 33 ms later), and after a
    `no_target` label the arrival gap less the daemon's own frame time between the two (the empty
    frames are the scene's, not a stall), plus one frame. A window that ends without a label counts
    up to its end in the same way (after `no_target`, less the scene's gap)."""
    s = LabelStats(labels=len(records), seconds=t1 - t0)
    s.rate = len(records) / s.seconds if s.seconds > 0 else 0.0
    if len(records) >= 2 and records[-1].timestamp_ns > records[0].timestamp_ns:
        s.camera_fps = (records[-1].frame - records[0].frame) / (
            (records[-1].timestamp_ns - records[0].timestamp_ns) * 1e-9
        )
    if records:
        lat = np.array([r.latency_ms for r in records])
        s.p50_ms, s.p99_ms, s.max_ms = (float(np.percentile(lat, 50)), float(np.percentile(lat, 99)),
                                        float(lat.max()))  # fmt: skip
    chain: list[LabelRecord] = ([before] if before is not None else []) + list(records)
    gaps, raw, source, starts, ends = [], [], [], [], []
    last_arrival = t0
    for a, b in pairwise(chain):
        gap = (b.arrival - a.arrival) * 1000.0
        if a.state == "tracking":
            gaps.append(gap)
            starts.append(a.arrival)
            ends.append(b.arrival)
            s.missed_frames += max(b.frame - a.frame - 1, 0)
            source.append((b.timestamp_ns - a.timestamp_ns) * 1e-6)
        else:
            gaps.append(gap - (b.timestamp_ns - a.timestamp_ns) * 1e-6 + FRAME_MS)
            starts.append(a.arrival)
            ends.append(b.arrival)
        raw.append((b.arrival - max(a.arrival, t0)) * 1000.0)
    if chain:
        last = chain[-1]
        tail = (t1 - last.arrival) * 1000.0
        gaps.append(tail if last.state == "tracking" else tail - SCENE_GAP * FRAME_MS)
        starts.append(last.arrival)
        ends.append(t1)
        last_arrival = last.arrival
    else:
        gaps.append((t1 - t0) * 1000.0)
        starts.append(t0)
        ends.append(t1)
    raw.append((t1 - max(last_arrival, t0)) * 1000.0)
    s.gap_ms, s.raw_gap_ms = max(gaps), max(raw)
    worst = int(np.argmax(gaps))
    s.gap_end = ends[worst]
    s.source_gap_ms = max(source, default=float("nan"))
    if witness is not None:
        s.host_stall_ms = witness.longest_ms(starts[worst], ends[worst])
        if records:
            slowest = max(records, key=lambda r: r.latency_ms)
            waited = witness.longest_ms(slowest.arrival - slowest.latency_ms * 1e-3, slowest.arrival)
            s.host_stall_ms = max(s.host_stall_ms, waited)
    return s


@dataclass
class Sample:
    t: float  # seconds since the run started
    rss_kb: int | None
    fds: int | None
    log_bytes: int
    log_lines: int
    cpu_s: float | None = None  # the daemon's CPU time so far


def cpu_percent(a: Sample, b: Sample) -> float:
    """The daemon's CPU use between two samples, in % of one core (NaN across a restart)."""
    if a.cpu_s is None or b.cpu_s is None or b.cpu_s < a.cpu_s or b.t <= a.t:
        return float("nan")
    return (b.cpu_s - a.cpu_s) / (b.t - a.t) * 100.0


class Sampler(BackgroundThread):
    """The daemon's RSS, open file descriptors and log size, every `interval` seconds."""

    def __init__(self, daemon: DaemonUnderTest, interval: float, t_start: float) -> None:
        self.daemon, self.interval, self.t_start = daemon, interval, t_start
        self.samples: list[Sample] = []
        super().__init__("sampler")

    def sample(self) -> Sample:
        b, n = self.daemon.log_size()
        s = Sample(time.monotonic() - self.t_start, self.daemon.rss_kb(), self.daemon.fds(), b, n, self.daemon.cpu_s())
        with self._lock:
            self.samples.append(s)
        return s

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self.sample()

    def between(self, t0: float, t1: float) -> list[Sample]:
        a, b = t0 - self.t_start, t1 - self.t_start
        with self._lock:
            return [s for s in self.samples if a <= s.t <= b]


class HostStallWitness(BackgroundThread):
    """The harness's own scheduling: a thread that asks to wake every 5 ms and keeps each time it woke
    more than 10 ms late. The subscriber's thread is in this process, so such a stall (the machine or
    this process not run: a virtual machine's host taking its cores, memory reclaim) delays its labels
    as much, and is none of the daemon's doing; a stall in tofmatd does not delay this thread."""

    PERIOD_S, LATE_S = 0.005, 0.010

    def __init__(self) -> None:
        self.stalls: list[tuple[float, float]] = []  # (start, end), time.monotonic()
        super().__init__("stall-witness")

    def _run(self) -> None:
        t = time.monotonic()
        while not self._stop.wait(self.PERIOD_S):
            now = time.monotonic()
            if now - t > self.PERIOD_S + self.LATE_S:
                with self._lock:
                    self.stalls.append((t + self.PERIOD_S, now))
            t = now

    def longest_ms(self, t0: float, t1: float) -> float:
        """The longest stall that overlaps [t0, t1] (0 when none), whole."""
        with self._lock:
            return max(((b - a) * 1000.0 for a, b in self.stalls if b >= t0 and a <= t1), default=0.0)


class FreshClientProbe(BackgroundThread):
    """Every `interval` s: can a new tofmat.Client connect and get status() within 2 s?"""

    JOIN_S = 10.0

    def __init__(self, socket_path: Path, interval: float = 1.0) -> None:
        self.socket_path, self.interval = socket_path, interval
        self.ok = 0
        self.tries = 0
        self.worst_s = 0.0
        self.failures: Counter[str] = Counter()
        super().__init__("probe")

    def _run(self) -> None:
        while not self._stop.wait(self.interval if self.tries else 0.5):
            t0 = time.monotonic()
            reason = ""
            try:
                with tofmat.Client(self.socket_path, timeout=FRESH_CLIENT_LIMIT_S, reconnect=False) as c:
                    c.status()
            except (tofmat.ClientError, OSError) as e:
                reason = type(e).__name__
            dt = time.monotonic() - t0
            self.tries += 1
            self.worst_s = max(self.worst_s, dt)
            if not reason and dt > FRESH_CLIENT_LIMIT_S:
                reason = "slower than 2 s"
            if reason:
                self.failures[reason] += 1
            else:
                self.ok += 1

    def text(self) -> str:
        if not self.tries:
            return "-"
        why = ", ".join(f"{k} {v}" for k, v in self.failures.most_common())
        return f"{self.ok}/{self.tries}" + (f" ({why})" if why else "")


def settle(daemon: DaemonUnderTest, clients: int, timeout: float = 10.0) -> None:
    """Waits until the daemon holds no more connections than our own (an attack's are gone)."""
    deadline = time.monotonic() + timeout
    s: dict[str, Any] | None = None
    while time.monotonic() < deadline:
        s = daemon.status()
        if s is not None and int(s["clients"]["clients"]) <= clients + 1:  # (+1: this status client)
            return
        time.sleep(0.25)
    say(
        f"  (the daemon still holds {s['clients']['clients'] if s else '?'} connections after {timeout:.0f} s; "
        f"we hold {clients})"
    )


def restore(daemon: DaemonUnderTest, baseline: dict[str, Any]) -> list[str]:
    """Puts back what a control attack changed (as the daemon's own user); returns what was changed."""
    now = daemon.status()
    if now is None:
        return ["(no status)"]
    changed = [k for k in ("profile", "roi", "candidates") if now[k] != baseline[k]]
    if now["table"]["path"] != baseline["table"]["path"]:
        changed.append("table")
    if changed:
        with tofmat.Client(daemon.socket, timeout=5.0, reconnect=False) as c:
            c.set_profile(baseline["profile"])
            c.set_roi(*baseline["roi"])
            c.set_candidates(list(baseline["candidates"]))
            if "table" in changed:
                c.load_table(baseline["table"]["path"])
            c.reset()
    return changed


# --- bench ---------------------------------------------------------------------------------------

GAP_NOTE = (
    f"worst gap: the longest wait for a label beyond the scene's own empty frames (the sweep labels every "
    f"frame with a target and sends one no_target when it leaves, then nothing for its {SCENE_GAP} empty "
    f"frames, {SCENE_GAP * FRAME_MS:.0f} ms; raw gap: any label, those included); source gap: the longest "
    f"interval between consecutive tracked frames by the daemon's own frame clock (near the worst gap: the "
    f"lateness came before serving, e.g. the simulated camera, which renders inside tofmatd, short of CPU)"
)


@dataclass
class BenchRow:
    attack: str
    case: str
    stats: LabelStats
    p99_ratio: float
    peak_rss_mb: float
    fds_first: int
    fds_max: int
    log_lines_added: int
    log_bytes_added: int
    fresh_client: str
    headline: str
    frames_dropped: int | None = None  # by the daemon's queue during the attack (status before and after)
    cpu_pct: float = float("nan")  # the daemon's CPU use during the attack, % of one core
    result: dict[str, Any] = field(default_factory=dict)
    changed: list[str] = field(default_factory=list)  # daemon settings the attack changed
    died: bool = False
    server: dict[str, int] = field(default_factory=dict)  # the daemon's client counters over the attack (server_status)


def run_phase(daemon: DaemonUnderTest, sub: Subscriber, sampler: Sampler, witness: HostStallWitness, name: str | None,
              seconds: float, args: argparse.Namespace, uids: dict[str, int]) -> BenchRow:  # fmt: skip
    ta = time.monotonic()
    sample0 = sampler.sample()
    log0 = daemon.log_size()
    status0 = daemon.status()
    proc = None
    if name is not None:
        cfg = daemon.attack_config(seconds + 30.0, args.slots, uids.get(name))
        proc = AttackProcess(name, cfg, daemon.workdir / f"attack-{name}.stderr")
    probe = FreshClientProbe(daemon.socket)
    probe.start()
    t0 = time.monotonic()
    before = sub.before(t0)
    died = False
    end = t0 + seconds
    while time.monotonic() < end:
        time.sleep(min(0.5, max(end - time.monotonic(), 0.0)))
        died = died or not daemon.alive()
    t1 = time.monotonic()
    probe.stop()
    result = proc.stop() if proc is not None else {}
    sample1 = sampler.sample()
    log1 = daemon.log_size()
    status1 = daemon.status()
    dropped = (
        int(status1["frames_dropped"]) - int(status0["frames_dropped"])
        if status0 is not None and status1 is not None and status1["uptime_s"] > status0["uptime_s"]
        else None
    )
    server = ({k: int(v) - int(status0["clients"].get(k, 0)) for k, v in status1["clients"].items()
               if isinstance(v, int) and k not in ("clients", "unix_clients", "tcp_clients")}
              if dropped is not None and status0 is not None and status1 is not None else {})  # fmt: skip
    stats = label_stats(sub.window(t0, t1), t0, t1, before, witness)
    samples = sampler.between(ta, time.monotonic())
    rss = [s.rss_kb for s in samples if s.rss_kb is not None]
    fds = [s.fds for s in samples if s.fds is not None]
    return BenchRow(attack=name or "(quiet)", case=ATTACKS[name].case if name else "", stats=stats, p99_ratio=1.0,
                    peak_rss_mb=max(rss) / 1024.0 if rss else float("nan"), fds_first=fds[0] if fds else -1,
                    fds_max=max(fds) if fds else -1, log_lines_added=log1[1] - log0[1],
                    log_bytes_added=log1[0] - log0[0], fresh_client=probe.text(),
                    headline=str(result.get("headline", "")), frames_dropped=dropped,
                    cpu_pct=cpu_percent(sample0, sample1), result=result, died=died, server=server)  # fmt: skip


def finite(x: float, digits: int) -> float | None:
    """A rounded figure, or None (JSON null) where there was nothing to measure."""
    return None if math.isnan(x) else round(x, digits)


def jsonable(x: Any) -> Any:
    """NaN as null: the files are strict JSON."""
    if isinstance(x, float) and math.isnan(x):
        return None
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    return x


def num(x: float, digits: int) -> str:
    """A figure, or "-" where there was nothing to measure (no label in the window)."""
    return "-" if math.isnan(x) else f"{x:.{digits}f}"


def format_bench(rows: Sequence[BenchRow]) -> str:
    out = [("| attack | case | labels/s | p50 ms | p99 ms | p99 / quiet p99 | worst gap ms | source gap ms | "
            "raw gap ms | frames dropped | daemon CPU % | peak RSS MB | fds (start/max) | log lines added | "
            "fresh client <= 2 s | attack |"),
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|"]  # fmt: skip
    for r in rows:
        s = r.stats
        note = r.headline
        if r.result and not r.result.get("engaged", True):
            note = "never got a connection or an answer; " + note
        if "as" in r.result.get("notes", {}):
            note += f" [as {r.result['notes']['as']}]"
        if r.changed:
            note += f"; CHANGED {', '.join(r.changed)}"
        if r.died:
            note = "**DAEMON DIED**; " + note
        out.append(f"| {r.attack} | {r.case} | {s.rate:.1f} | {num(s.p50_ms, 2)} | {num(s.p99_ms, 2)} | "
                   f"{num(r.p99_ratio, 2)} | {s.gap_ms:.0f} | {num(s.source_gap_ms, 0)} | {s.raw_gap_ms:.0f} | "
                   f"{'-' if r.frames_dropped is None else r.frames_dropped} | {num(r.cpu_pct, 0)} | "
                   f"{num(r.peak_rss_mb, 1)} | "
                   f"{r.fds_first}/{r.fds_max} | {r.log_lines_added} | {r.fresh_client} | "
                   f"{note.replace('|', '/')} |")  # fmt: skip
    return "\n".join(out)


def bench(args: argparse.Namespace) -> int:
    names = [a.strip() for a in args.attacks.split(",") if a.strip()] if args.attacks else list(ATTACKS)
    for n in names:
        if n not in ATTACKS:
            raise SystemExit(f"unknown attack {n!r}; one of {', '.join(ATTACKS)}")
    uids = attacker_uids(args)
    with tempfile.TemporaryDirectory(prefix="tofmat-attacks-") as tmp:
        daemon = DaemonUnderTest(Path(tmp), args.daemon_args, args.daemon_nice)
        t_start = time.monotonic()
        sampler = Sampler(daemon, 1.0, t_start)
        witness = HostStallWitness()
        sub = Subscriber(str(daemon.socket))
        rows: list[BenchRow] = []
        try:
            witness.start()
            daemon.start()
            sub.start()
            sampler.start()
            baseline = daemon.status()
            assert baseline is not None
            time.sleep(2.0)  # warm up
            say(f"bench: tofmatd {daemon.pid}, {args.seconds} s a phase: quiet, then {', '.join(names)}")
            for name in [None, *names]:
                settle(daemon, clients=1)
                row = run_phase(daemon, sub, sampler, witness, name, args.seconds, args, uids)
                if daemon.check_alive(name or "the quiet run"):
                    row.died = True
                    sub.errors["daemon restarted"] += 1
                else:
                    row.changed = restore(daemon, baseline)
                row.p99_ratio = row.stats.p99_ms / rows[0].stats.p99_ms if rows else 1.0
                rows.append(row)
                say(f"  {row.attack}: {row.stats.rate:.1f} labels/s, p99 {row.stats.p99_ms:.2f} ms, "
                    f"gap {row.stats.gap_ms:.0f} ms (the harness's own longest stall {row.stats.host_stall_ms:.0f} ms); "
                    f"{row.headline}")  # fmt: skip
        finally:
            sub.stop()
            sampler.stop()
            witness.stop()
            rc = daemon.stop()
        table = format_bench(rows)
        print(table)
        print()
        print(f"tofmatd exit status at the end: {rc}; deaths: {len(daemon.deaths)}"
              + "".join(f"\n  - {d}" for d in daemon.deaths))  # fmt: skip
        print(GAP_NOTE)
        if args.json:
            Path(args.json).write_text(json.dumps(jsonable({"rows": [asdict(r) for r in rows], "deaths": daemon.deaths,
                                                            "exit_status": rc}), indent=2, default=str))  # fmt: skip
    return 0


# --- soak -----------------------------------------------------------------------------------------


def soak_schedule(names: Sequence[str], phases: int, at_once: int, rng: random.Random) -> list[list[str]]:
    """`phases` sets of `at_once` attacks: every attack in turn, in a shuffled order each round."""
    order: list[str] = []
    out: list[list[str]] = []
    for _ in range(phases):
        group: list[str] = []
        while len(group) < min(at_once, len(names)):
            if not order:
                order = list(names)
                rng.shuffle(order)
            n = order.pop()
            if n not in group:
                group.append(n)
            elif len(set(order) - set(group)) == 0:
                order = []
        out.append(group)
    return out


def soak(args: argparse.Namespace) -> int:
    names = [a.strip() for a in args.attacks.split(",") if a.strip()] if args.attacks else list(ATTACKS)
    for n in names:
        if n not in ATTACKS:
            raise SystemExit(f"unknown attack {n!r}; one of {', '.join(ATTACKS)}")
    uids = attacker_uids(args)
    rng = random.Random(args.seed)
    phases = max(1, round(args.seconds / args.phase_seconds))
    schedule = soak_schedule(names, phases, args.at_once, rng)
    totals: dict[str, Counter[str]] = {}
    ran_as: dict[str, str] = {}
    crowded: list[str] = []  # attacks that never got a connection or an answer in a phase
    phase_lines: list[dict[str, Any]] = []
    bounds: list[tuple[float, float]] = []  # each phase's window (time.monotonic)
    changes: list[str] = []
    with tempfile.TemporaryDirectory(prefix="tofmat-soak-") as tmp:
        daemon = DaemonUnderTest(Path(tmp), args.daemon_args, args.daemon_nice)
        t_start = time.monotonic()
        sampler = Sampler(daemon, 10.0, t_start)
        witness = HostStallWitness()
        subs = [Subscriber(str(daemon.socket), name="unix"),
                Subscriber(daemon.tcp_address, token=daemon.token, name="tcp")]  # fmt: skip
        try:
            witness.start()
            daemon.start()
            for s in subs:
                s.start()
            baseline = daemon.status()
            assert baseline is not None
            time.sleep(2.0)
            first = sampler.sample()  # before any attack
            sampler.start()
            t_attacks = time.monotonic()
            say(f"soak: tofmatd {daemon.pid}, {args.seconds} s in {phases} phases of {args.phase_seconds} s, "
                f"{args.at_once} attacks at once; subscribers on {daemon.socket} and {daemon.tcp_address}")  # fmt: skip
            for k, group in enumerate(schedule):
                phase_end = t_attacks + (k + 1) * args.seconds / phases
                p0 = time.monotonic()
                smp0 = sampler.sample()
                procs = [AttackProcess(n, daemon.attack_config(args.phase_seconds + 60.0, args.slots, uids.get(n)),
                                       daemon.workdir / f"attack-{n}.stderr") for n in group]  # fmt: skip
                died = False
                while time.monotonic() < phase_end:
                    time.sleep(min(1.0, max(phase_end - time.monotonic(), 0.0)))
                    if daemon.check_alive(f"soak phase {k + 1} ({', '.join(group)})"):
                        died = True
                for p in procs:  # all at once: none gets the others' freed slots to itself
                    p.terminate()
                results = [p.stop() for p in procs]
                for r in results:
                    if not r.get("engaged", True):
                        crowded.append(f"phase {k + 1}: {r['attack']} (with {', '.join(group)})")
                    totals.setdefault(r["attack"], Counter()).update(r["counts"])
                    if "as" in r["notes"]:
                        ran_as[r["attack"]] = r["notes"]["as"]
                if not died and not daemon.check_alive(f"soak phase {k + 1} ({', '.join(group)})"):
                    changed = restore(daemon, baseline)
                    if changed:
                        changes.append(f"phase {k + 1} ({', '.join(group)}): {', '.join(changed)}")
                p1 = time.monotonic()
                bounds.append((p0, p1))
                st = [label_stats(s.window(p0, p1), p0, p1, s.before(p0), witness) for s in subs]
                smp = sampler.sample()
                line = {"phase": k + 1, "t": round(p1 - t_start), "attacks": group,
                        "labels_per_s": [round(x.rate, 1) for x in st], "p99_ms": [finite(x.p99_ms, 2) for x in st],
                        "gap_ms": [round(x.gap_ms) for x in st],
                        "source_gap_ms": [finite(x.source_gap_ms, 0) for x in st],
                        "cpu_pct": finite(cpu_percent(smp0, smp), 1), "rss_kb": smp.rss_kb, "fds": smp.fds,
                        "results": [r["headline"] for r in results]}  # fmt: skip
                phase_lines.append(line)
                say(f"  phase {k + 1}/{phases} t={line['t']} s [{', '.join(group)}]: labels/s {line['labels_per_s']}, "
                    f"p99 {line['p99_ms']} ms, gap {line['gap_ms']} ms (source {line['source_gap_ms']}), daemon "
                    f"CPU {line['cpu_pct']} %, RSS {(smp.rss_kb or 0) / 1024:.1f} MB, fds {smp.fds}")  # fmt: skip
            t_end_attacks = time.monotonic()
            settle(daemon, clients=len(subs), timeout=15.0)
            time.sleep(1.0)
            last = sampler.sample()  # after the last attack, its connections gone
            t_end = time.monotonic()
            end_status = daemon.status()
        finally:
            for s in subs:
                s.stop()
            sampler.stop()
            witness.stop()
            rc = daemon.stop()
        stats = {s.name: label_stats(s.window(t_attacks, t_end), t_attacks, t_end, s.before(t_attacks), witness)
                 for s in subs}  # fmt: skip
        samples = sampler.samples
        rss = [s.rss_kb for s in samples if s.rss_kb is not None]
        fds = [s.fds for s in samples if s.fds is not None]
        at60 = next((s for s in samples if s.t >= (t_attacks - t_start) + 60.0 and s.rss_kb is not None), first)
        rss_growth = (last.rss_kb or 0) / at60.rss_kb - 1.0 if at60.rss_kb else float("nan")
        fd_growth = (last.fds or 0) - (first.fds or 0)
        gap = max(s.gap_ms for s in stats.values())
        # Where the longest gap ended: in which phase (its attacks), or after the last.
        worst = max(stats.values(), key=lambda s: s.gap_ms)
        gap_phase = next(
            (
                f"phase {k + 1} ({', '.join(schedule[k])})"
                for k, b in enumerate(bounds)
                if b[0] <= worst.gap_end <= b[1]
            ),
            "outside the phases (after the last attack)",
        )
        gap_where = f"{worst.gap_end - t_attacks:.1f} s after the first attack, {gap_phase}"
        failures = []
        if daemon.deaths or rc not in (0, None):
            failures.append(f"the daemon died ({len(daemon.deaths)} times; exit status at the end {rc})")
        if gap > GAP_LIMIT_MS:
            source = max((s.source_gap_ms for s in stats.values() if not math.isnan(s.source_gap_ms)), default=math.nan)
            failures.append(f"the longest gap between labels was {gap:.0f} ms (> {GAP_LIMIT_MS:.0f} ms; the longest "
                            f"between tracked frames by the daemon's frame clock: {num(source, 0)} ms; the harness's own "
                            f"longest stall {worst.host_stall_ms:.0f} ms), ending "
                            f"{gap_where}")  # fmt: skip
        if rss_growth > RSS_GROWTH_LIMIT:
            failures.append(f"RSS grew by {rss_growth * 100:.1f} % from the 60-s sample to the end "
                            f"(> {RSS_GROWTH_LIMIT * 100:.0f} %)")  # fmt: skip
        if fd_growth > FD_GROWTH_LIMIT:
            failures.append(f"open fds grew by {fd_growth} (> {FD_GROWTH_LIMIT})")
        summary = {
            "seconds": round(t_end_attacks - t_attacks, 1),
            "phases": phase_lines,
            "subscribers": {k: asdict(v) for k, v in stats.items()},
            "worst_gap_at": gap_where,
            "subscriber_errors": {s.name: dict(s.errors) for s in subs},
            "rss_kb": {
                "first": first.rss_kb,
                "at_60s": at60.rss_kb,
                "last": last.rss_kb,
                "max": max(rss, default=None),
            },
            "fds": {"first": first.fds, "last": last.fds, "max": max(fds, default=None)},
            "log": {"bytes": last.log_bytes, "lines": last.log_lines},
            "daemon_cpu_pct": cpu_percent(first, last),
            "attacks": {k: dict(v) for k, v in totals.items()},
            "attacks_ran_as": ran_as,
            "attacks_crowded_out": crowded,
            "settings_changed": changes,
            "deaths": daemon.deaths,
            "exit_status": rc,
            "samples": [asdict(s) for s in samples],
            "failures": failures,
            "daemon_status": end_status,
        }
        print(format_soak(summary, stats))
        if args.json:
            Path(args.json).write_text(json.dumps(jsonable(summary), indent=2, default=str))
    return 1 if failures else 0


def format_soak(summary: dict[str, Any], stats: dict[str, LabelStats]) -> str:
    rss, fds = summary["rss_kb"], summary["fds"]

    def mb(kb: int | None) -> str:
        return f"{kb / 1024:.1f}" if kb is not None else "-"

    lines = [
        f"## soak: {summary['seconds']} s of attacks, {len(summary['phases'])} phases",
        "",
        (
            "| subscriber | labels | labels/s | p50 ms | p99 ms | max ms | worst gap ms | source gap ms | "
            "raw gap ms | frames missed while tracking |"
        ),
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in stats.items():
        lines.append(f"| {name} | {s.labels} | {s.rate:.1f} | {num(s.p50_ms, 2)} | {num(s.p99_ms, 2)} | "
                     f"{num(s.max_ms, 1)} | {s.gap_ms:.0f} | {num(s.source_gap_ms, 0)} | {s.raw_gap_ms:.0f} | "
                     f"{s.missed_frames} |")  # fmt: skip
    lines += ["", (f"RSS MB: first {mb(rss['first'])}, at 60 s {mb(rss['at_60s'])}, last {mb(rss['last'])}, "
                   f"max {mb(rss['max'])}; fds: first {fds['first']}, last {fds['last']}, max {fds['max']}; "
                   f"log: {summary['log']['bytes']} bytes, {summary['log']['lines']} lines; daemon CPU "
                   f"{num(summary['daemon_cpu_pct'], 0)} % of a core")]  # fmt: skip
    d = summary.get("daemon_status") or {}
    if d:
        lines += ["", (f"daemon at the end: frames processed {d.get('frames_processed')}, dropped "
                       f"{d.get('frames_dropped')}, skipped {d.get('frames_skipped')}, fps {d.get('fps')}; "
                       f"clients {json.dumps(d.get('clients'))}")]  # fmt: skip
    lines += ["", "| attack | totals |", "|---|---|"]
    for name, counts in sorted(summary["attacks"].items()):
        who = summary["attacks_ran_as"].get(name)
        lines.append(f"| {name}{f' (as {who})' if who else ''} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(counts.items()))} |")  # fmt: skip
    if summary["attacks_crowded_out"]:
        lines += ["", "Attacks that never got a connection or an answer (the others took the slots; not tested there):"]
        lines += [f"- {c}" for c in summary["attacks_crowded_out"]]
    if summary["settings_changed"]:
        lines += ["", "Settings changed by attacks (restored afterwards):"]
        lines += [f"- {c}" for c in summary["settings_changed"]]
    if summary["deaths"]:
        lines += ["", "DAEMON DEATHS:"] + [f"- {d}" for d in summary["deaths"]]
    lines += ["", GAP_NOTE, "", (f"criteria: no death; worst gap <= {GAP_LIMIT_MS:.0f} ms; RSS growth from the "
                                 f"60-s sample to the end <= {RSS_GROWTH_LIMIT * 100:.0f} %; fd growth <= "
                                 f"{FD_GROWTH_LIMIT} (before the first attack to after the last)")]  # fmt: skip
    lines.append("FAIL: " + "; ".join(summary["failures"]) if summary["failures"] else "PASS")
    return "\n".join(lines)


# --- command line ---------------------------------------------------------------------------------


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    sub = p.add_subparsers(dest="command", required=True)

    def common(q: argparse.ArgumentParser, seconds: float) -> None:
        q.add_argument(
            "--seconds",
            type=float,
            default=seconds,
            help="bench: of each phase (quiet, then each attack); soak: of all the attacks",
        )
        q.add_argument("--attacks", default="", help=f"comma-separated, of: {', '.join(ATTACKS)} (default all)")
        q.add_argument(
            "--daemon-arg",
            dest="daemon_arg",
            action="append",
            default=[],
            metavar="ARGS",
            help="extra tofmatd arguments, split like a shell would: --daemon-arg='--idle-timeout 30'",
        )
        q.add_argument("--slots", type=int, default=DEFAULT_SLOTS, help="connections of idle_slots and tcp_unauth")
        q.add_argument(
            "--daemon-nice",
            type=int,
            default=0,
            help="run tofmatd at this niceness (the box's systemd unit: -5; needs root below 0)",
        )
        q.add_argument(
            "--client-nice",
            type=int,
            default=0,
            help="run the measured subscribers at this niceness, as a box's own services are "
            "(the attacks stay at 0; needs root below 0)",
        )
        q.add_argument("--json", default="", help="write the figures to this file")
        q.add_argument(
            "--same-user",
            action="store_true",
            help=f"run as root, the Unix attacks still run as root (default: as uid {OTHER_UID}+)",
        )

    common(sub.add_parser("bench", help="each attack alone against a measured subscriber"), 10.0)
    s = sub.add_parser("soak", help="attacks in rotation; exit 1 if the criteria fail")
    common(s, 1800.0)
    s.add_argument("--phase-seconds", type=float, default=30.0, help="how long one set of attacks runs")
    s.add_argument("--at-once", type=int, default=3, help="attacks running together")
    s.add_argument("--seed", type=int, default=16, help="of the order of the attacks")
    a = sub.add_parser("_attack", help=argparse.SUPPRESS)
    a.add_argument("name", choices=sorted(ATTACKS))
    a.add_argument("--config", required=True)
    args = p.parse_args(argv)
    if args.command != "_attack":
        args.daemon_args = [x for arg in args.daemon_arg for x in shlex.split(arg)]
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    if args.command == "_attack":
        return attack_main(args.name, AttackConfig(**json.loads(args.config)))
    run: Callable[[argparse.Namespace], int] = bench if args.command == "bench" else soak
    if args.client_nice:
        os.setpriority(os.PRIO_PROCESS, 0, args.client_nice)  # (AttackProcess sets each attack back to 0)
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
