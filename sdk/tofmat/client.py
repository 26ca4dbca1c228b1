# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The Python client of tofmatd, built on the C++ client (firmware/protocol) through pybind11.

>>> import tofmat
>>> with tofmat.Client("/run/tofmat/tofmatd.sock") as c:          # or "127.0.0.1:7020", token=...
...     for label in c.labels(timeout=5.0):
...         print(label.material, label.distance, [r.material for r in label.ranking])

The connection, handshake, framing and every bound on what the daemon sends are C++'s; this
module turns events into dataclasses and numpy arrays, keeps the subscriptions, and reconnects
(re-subscribing) when the daemon restarts.
"""

from __future__ import annotations

import json
import os
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, NotRequired, TypedDict, cast, get_args

import numpy as np
import numpy.typing as npt

from . import _tofmat
from ._tofmat import (
    AuthenticationError,
    ClientError,
    CommandError,
    ConnectionClosedError,
    DaemonTimeoutError,
    DaemonUnavailableError,
    NotPermittedError,
    ProtocolError,
    ProtocolVersionError,
)
from .geometry import Intrinsics, range_to_points

DEFAULT_SOCKET = "/run/tofmat/tofmatd.sock"

# What a Client keeps of the events that come while it waits for another (label_map(), depth()),
# for next_event() to hand out later: the oldest are dropped past either bound (Client.dropped_events),
# so nothing a daemon sends can grow a client without end. The C++ connection keeps the events that
# come while a command waits for its reply under bounds of its own (docs/protocol.md, What a client keeps).
MAX_PENDING_EVENTS = 1024
MAX_PENDING_BYTES = 64 << 20

# The names the protocol uses (docs/protocol.md), as types: a checker catches a misspelt one.
Stream = Literal[
    "labels",
    "label_map",
    "device",
    "depth:80",
    "depth:16",
    "depth:120",
    "depth:combined",
    "depth:corrected",
    "sort",
    "line",
    "reset",
]
Profile = Literal["handheld", "segmentation", "sorting"]
Backend = Literal["fixed", "float"]
ClassifierMethod = Literal["eq12", "session"]
DepthKind = Literal["80", "16", "120", "combined", "corrected"]
LabelState = Literal["tracking", "no_target", "out_of_range", "final", "mixed", "unknown"]
DeviceState = Literal["opening", "streaming", "disconnected", "stopped", "failed"]
Role = Literal["read", "control"]

STREAMS: tuple[Stream, ...] = get_args(Stream)


class TableStatus(TypedDict):
    path: str
    materials: list[str]
    bins: int
    bin_start_mm: float
    bin_width_mm: float


class DeviceStatus(TypedDict):
    state: DeviceState
    message: str
    changes: int


class ReloadStatus(TypedDict):
    ok: bool
    path: str
    error: NotRequired[str]


class Status(TypedDict):
    """tofmatd's ``status`` reply (docs/protocol.md, ``status``). A later minor version may add keys;
    the ones here are always there, but for those marked NotRequired."""

    server: str
    profile: Profile
    backend: Backend
    classifier: NotRequired[ClassifierMethod]  # minor 6 on; before it always "eq12"
    roi: list[int]
    candidates: list[str]
    table: TableStatus
    frames_processed: int
    frames_dropped: int
    frames_skipped: int
    processing_errors: int
    last_error: str
    fps: float
    process_ms: float
    source: str
    source_counters: dict[str, Any]
    simulated: bool
    device: DeviceStatus
    clients: dict[str, int]
    uptime_s: float
    last_reload: ReloadStatus | None
    button: NotRequired[dict[str, Any]]
    line: NotRequired[dict[str, Any]]
    target: NotRequired[dict[str, Any]]  # minor 11 on, handheld and sorting: {"state", "depth_mm", "reason"?}


@dataclass(frozen=True)
class Rank:
    material: str
    distance: float  # Eq. (12), mm^2


@dataclass(frozen=True)
class Truth:
    """Ground truth, sent only by a simulated source."""

    material: str  # "" when no target fills the region
    depth_mm: float


@dataclass(frozen=True)
class Label:
    frame: int
    timestamp_ns: int  # CLOCK_MONOTONIC when the daemon had the whole frame
    received_ns: int  # CLOCK_MONOTONIC when this client read it
    profile: Profile
    # "mixed": a sorting burst whose frames disagreed; "unknown": no material fits; "out_of_range": a
    # target at a depth the table's bins miss (status()["target"]["reason"] says so)
    state: LabelState
    material: str | None  # None when state is "no_target", "out_of_range" or "unknown" (the nearest: ranking[0])
    index: int
    distance: float
    valid: int
    bins_covered: int
    ranking: tuple[Rank, ...]
    trigger: int | None
    truth: Truth | None
    simulated: bool  # the frame came from the simulated camera (or a recording of it), not a camera
    # Minor 7 on (None before it, and when no_target): the best match's calibrated probability
    # among the candidates, and its fit under the session matcher's noise model (None with eq12).
    confidence: float | None = None
    fit: float | None = None

    @property
    def latency_ms(self) -> float:
        """From the frame's arrival in the daemon to this client (same host: one clock)."""
        return (self.received_ns - self.timestamp_ns) * 1e-6


@dataclass(frozen=True)
class LabelMap:
    frame: int
    timestamp_ns: int
    received_ns: int
    labels: npt.NDArray[np.uint8]  # (height, width); 255 = no label; the caller's own (writable) copy
    materials: list[str]
    truth_accuracy: float | None  # simulated source: fraction of target pixels labelled right
    simulated: bool  # the frame came from the simulated camera (or a recording of it), not a camera

    NO_LABEL = 255

    @property
    def latency_ms(self) -> float:
        return (self.received_ns - self.timestamp_ns) * 1e-6


@dataclass(frozen=True)
class DepthImage:
    """A depth image over the region the profile decodes: ranges along each pixel's ray (mm, what a
    Time-of-Flight camera measures), NaN where invalid, with the camera's intrinsics when the daemon
    knows them (protocol minor 9; not from a recording made before recordings kept them)."""

    frame: int
    timestamp_ns: int
    kind: DepthKind  # "80", "16", "120" (wrapped), "combined", or "corrected" (for each pixel's material)
    x0: int
    y0: int
    depth_mm: npt.NDArray[np.float32]  # (height, width), NaN where invalid; the caller's own (writable) copy
    intrinsics: Intrinsics | None = None

    @property
    def valid(self) -> npt.NDArray[np.bool_]:
        """(height, width): the pixels with a depth."""
        return np.isfinite(self.depth_mm)

    def points(self, intrinsics: Intrinsics | None = None) -> npt.NDArray[np.float32]:
        """Each pixel's 3D point, (height, width, 3) mm in the camera's frame (x right, y down, z
        forward), NaN where invalid; with the image's own intrinsics unless others are given."""
        k = intrinsics or self.intrinsics
        if k is None:
            raise ValueError(
                "this depth image carries no intrinsics (a daemon before protocol minor 9, or a "
                "recording without them): pass intrinsics=tofmat.Intrinsics(fx, fy, cx, cy)"
            )
        return range_to_points(self.depth_mm, k, self.x0, self.y0)


@dataclass(frozen=True)
class DeviceEvent:
    state: DeviceState
    message: str
    timestamp_ns: int


@dataclass(frozen=True)
class SortDecision:
    """The sorting line's decision for one item (stream "sort"): once when its outlet is chosen
    (``state == "decided"``, ``fire_ns`` planned) and once when the pusher was driven
    (``state == "fired"``). ``reason`` is "sorted" or why it went to reject: too_close, camera_busy,
    camera_lost, no_target, out_of_range, mixed, unknown, not_confident, no_outlet, late, full."""

    state: str
    item: int
    trigger_ns: int  # the light barrier's edge (kernel timestamp, CLOCK_MONOTONIC)
    material: str | None
    distance: float
    outlet: str | None  # None: rejects ride to the belt's end
    reason: str
    decided_ns: int
    fire_ns: int | None  # None: no pusher, or the belt stands
    margin_ms: float  # fire time minus decision time
    truth: str | None = None  # a simulated item's real material ("" when its burst saw none)


@dataclass(frozen=True)
class LineEvent:
    """A fault or alarm change of the sorting line (stream "line")."""

    kind: str  # alarm, late, camera, too_close, camera_busy, missed, full, burst, gpio
    message: str
    alarm: bool  # the alarm output's state after it
    timestamp_ns: int


@dataclass(frozen=True)
class ResetEvent:
    """The accumulation started over (stream "reset"): the front panel's button was pressed
    (``by == "button"``) or a client sent the reset command (``by == "command"``)."""

    by: str
    timestamp_ns: int


Event = Label | LabelMap | DepthImage | DeviceEvent | SortDecision | LineEvent | ResetEvent


def _held_bytes(event: Event) -> int:
    """An event's weight against MAX_PENDING_BYTES: its image, or 1 KiB for one without."""
    if isinstance(event, LabelMap):
        return int(event.labels.nbytes)
    if isinstance(event, DepthImage):
        return int(event.depth_mm.nbytes)
    return 1024


class _PendingEvents:
    """The events kept back for next_event(), oldest first, within MAX_PENDING_EVENTS and
    MAX_PENDING_BYTES: past either the oldest goes, and is counted."""

    def __init__(self) -> None:
        self._events: deque[Event] = deque()
        self.bytes = 0
        self.dropped = 0

    def __len__(self) -> int:
        return len(self._events)

    def append(self, event: Event) -> None:
        self._events.append(event)
        self.bytes += _held_bytes(event)
        while len(self._events) > MAX_PENDING_EVENTS or self.bytes > MAX_PENDING_BYTES:
            self.bytes -= _held_bytes(self._events.popleft())
            self.dropped += 1

    def popleft(self) -> Event:
        event = self._events.popleft()
        self.bytes -= _held_bytes(event)
        return event

    def take_first(self, wanted: Callable[[Event], bool]) -> Event | None:
        for k, event in enumerate(self._events):
            if wanted(event):
                del self._events[k]
                self.bytes -= _held_bytes(event)
                return event
        return None


def _event(meta: dict[str, Any], blob: bytes) -> Event | None:
    """The typed event, or None for an event this client does not know (a later minor version's:
    skipped, as docs/protocol.md's Versions asks of clients)."""
    name = meta["event"]
    now = time.monotonic_ns()
    if name == "label":
        truth = meta.get("truth")
        return Label(
            frame=meta["frame"],
            timestamp_ns=meta["timestamp_ns"],
            received_ns=now,
            profile=meta["profile"],
            state=meta["state"],
            material=meta.get("material") or None,
            index=meta["index"],
            distance=meta["distance"],
            valid=meta["valid"],
            bins_covered=meta["bins_covered"],
            ranking=tuple(Rank(r["material"], r["distance"]) for r in meta["ranking"]),
            trigger=meta.get("trigger"),
            truth=Truth(truth["material"], truth["depth_mm"]) if truth else None,
            simulated=bool(meta.get("simulated", False)),
            confidence=meta.get("confidence"),
            fit=meta.get("fit"),
        )
    if name == "label_map":
        # (a copy: the user's to change; a frame's 217 KB is nothing next to the frame's own work)
        labels = np.frombuffer(blob, np.uint8).reshape(meta["height"], meta["width"]).copy()
        return LabelMap(
            meta["frame"],
            meta["timestamp_ns"],
            now,
            labels,
            list(meta["materials"]),
            meta.get("truth_accuracy"),
            bool(meta.get("simulated", False)),
        )
    if name == "depth":
        depth = np.frombuffer(blob, "<f4").reshape(meta["height"], meta["width"]).astype(np.float32)  # writable
        intrinsics = Intrinsics.from_meta(meta["intrinsics"]) if "intrinsics" in meta else None
        return DepthImage(meta["frame"], meta["timestamp_ns"], meta["kind"], meta["x0"], meta["y0"], depth, intrinsics)
    if name == "device":
        return DeviceEvent(meta["state"], meta["message"], meta["timestamp_ns"])
    if name == "sort":
        return SortDecision(
            state=meta["state"],
            item=meta["item"],
            trigger_ns=meta["trigger_ns"],
            material=meta.get("material") or None,
            distance=meta["distance"],
            outlet=meta.get("outlet") or None,
            reason=meta["reason"],
            decided_ns=meta["decided_ns"],
            fire_ns=meta.get("fire_ns"),
            margin_ms=meta["margin_ms"],
            truth=meta.get("truth"),
        )
    if name == "line":
        return LineEvent(meta["kind"], meta["message"], bool(meta["alarm"]), meta["timestamp_ns"])
    if name == "reset":
        return ResetEvent(meta["by"], meta["timestamp_ns"])
    return None


class Client:
    """A connection to tofmatd by Unix socket path or ``host:port`` (TCP needs ``token``).

    Raises DaemonUnavailableError (nothing listens), DaemonTimeoutError, ProtocolVersionError,
    AuthenticationError; all are ``tofmat.ClientError``. With ``reconnect`` (the default) a lost
    connection is opened again, for up to ``reconnect_timeout`` seconds, and the subscriptions are
    restored, so an iterator survives a daemon restart.
    """

    def __init__(
        self,
        address: str | os.PathLike[str] | None = None,
        *,
        token: str | None = None,
        timeout: float = 5.0,
        reconnect: bool = True,
        reconnect_timeout: float = 30.0,
    ) -> None:
        if timeout <= 0:
            raise ValueError("timeout must be positive")
        self.address = str(address) if address is not None else os.environ.get("TOFMAT_SOCKET", DEFAULT_SOCKET)
        self._token = token or ""
        self._timeout = timeout
        self._reconnect = reconnect
        self._reconnect_timeout = reconnect_timeout
        self._streams: set[str] = set()
        # Events that came while label_map()/depth() waited for theirs: next_event() hands them out first.
        self._pending = _PendingEvents()
        self._dropped_before = 0  # by the connections before a reconnect
        self.reconnects = 0
        self._conn: _tofmat.ClientConnection | None = _tofmat.ClientConnection(self.address, self._token, timeout)

    # --- connection ------------------------------------------------------------------------
    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object | TracebackType) -> None:
        self.close()

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._conn = None

    @property
    def hello(self) -> dict[str, Any]:
        return dict(self._connection().hello)

    @property
    def role(self) -> Role:
        """``"read"`` (subscribe, status) or ``"control"`` (also the commands that change what every
        client gets: profile, ROI, candidates, trigger, reset, load_table). A control command on a
        reading connection raises NotPermittedError."""
        return cast(Role, self._connection().hello["role"])

    @property
    def dropped_events(self) -> int:
        """Events this client dropped because the ones it kept back (while a command waited for its
        reply, or label_map()/depth() for theirs) reached MAX_PENDING_EVENTS or MAX_PENDING_BYTES.
        (What the daemon dropped for a slow client is in its status: ``clients``.)"""
        conn = self._conn.dropped_events if self._conn is not None else 0
        return self._dropped_before + conn + self._pending.dropped

    def _connection(self) -> _tofmat.ClientConnection:
        if self._conn is None:
            raise ConnectionClosedError("the client is closed")
        return self._conn

    def _reopen(self) -> None:
        """Connects again until reconnect_timeout, restoring the subscriptions."""
        deadline = time.monotonic() + self._reconnect_timeout
        delay = 0.05
        if self._conn is not None:
            self._dropped_before += self._conn.dropped_events
        while True:
            try:
                self._conn = _tofmat.ClientConnection(self.address, self._token, self._timeout)
                if self._streams:
                    self._conn.request("subscribe", json.dumps({"streams": sorted(self._streams)}))
                self.reconnects += 1
                return
            except (DaemonUnavailableError, ConnectionClosedError, DaemonTimeoutError):
                if time.monotonic() + delay > deadline:
                    raise
                time.sleep(delay)
                delay = min(delay * 2, 1.0)

    def _call(self, cmd: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        try:
            result: dict[str, Any] = self._connection().request(cmd, json.dumps(args or {}))
            return result
        except ConnectionClosedError:
            if not self._reconnect or self._conn is None:
                raise
            self._reopen()
            result = self._connection().request(cmd, json.dumps(args or {}))
            return result

    # --- commands ----------------------------------------------------------------------------
    def status(self) -> Status:
        """Source, device state, profile, table, frame rate, drops, errors, clients."""
        return cast(Status, self._call("status"))

    def reset(self, session: bool = False) -> None:
        """Forget the accumulated observations (handheld) or the armed burst (sorting). ``session``:
        also start a new session, in which the session matcher learns again how far the session
        moved (protocol minor 10; an older daemon refuses it)."""
        self._call("reset", {"session": True} if session else None)

    def set_profile(self, name: Profile) -> None:
        self._call("set_profile", {"name": name})

    def set_roi(self, x0: int, y0: int, x1: int, y1: int) -> None:
        self._call("set_roi", {"x0": x0, "y0": y0, "x1": x1, "y1": y1})

    def set_candidates(self, materials: list[str] | None) -> None:
        """Restrict the materials considered (None or []: all of the table's)."""
        self._call("set_candidates", {"materials": list(materials or [])})

    def load_table(self, path: str | os.PathLike[str]) -> list[str]:
        """Makes the daemon load another table: a name inside the daemon's table directory
        (`--table-dir`, by default the folder of its `--table`), or an absolute path inside it."""
        materials: list[str] = self._call("load_table", {"path": os.fspath(path)})["materials"]
        return materials

    def latest(self, stream: Stream | str = "labels") -> Event | None:
        """The last event of a stream without images (labels, device, sort, line, reset), whether or
        not this client subscribed to it: the poll beside the watch. None when there was none yet.
        Needs a daemon of protocol 1.5 or later (older ones refuse the command: CommandError)."""
        reply = self._call("latest", {"stream": stream})
        meta = reply.get("event")
        return _event(meta, b"") if meta is not None else None

    def latest_label(self) -> Label | None:
        """The daemon's last label (``latest("labels")``): a client that connects has one at once."""
        event = self.latest("labels")
        return event if isinstance(event, Label) else None

    def trigger(self, burst: int | None = None) -> int:
        """Sorting profile: start a burst now; returns the trigger number its label will carry."""
        trigger: int = self._call("trigger", {"burst": burst} if burst else {})["trigger"]
        return trigger

    # --- streams -----------------------------------------------------------------------------
    def subscribe(self, *streams: Stream | str) -> None:
        """Subscribe to streams: the ones this client knows (``STREAMS``) or any the daemon offers in
        its hello's capabilities (a later minor version's; their events are skipped unless known)."""
        offered = set(self.hello.get("capabilities", []))
        for s in streams:
            if s not in STREAMS and s not in offered:
                raise ValueError(f"unknown stream {s!r}; one of {', '.join(STREAMS)}")
        self._call("subscribe", {"streams": list(streams)})
        self._streams.update(streams)

    def unsubscribe(self, *streams: Stream | str) -> None:
        """Stop the given streams (none given: all of them)."""
        self._call("unsubscribe", {"streams": list(streams)})
        if streams:
            self._streams.difference_update(streams)
        else:
            self._streams.clear()

    def next_event(self, timeout: float | None) -> Event | None:
        """The next event of the subscribed streams, or None if none comes within ``timeout``
        seconds (None: wait for one): for a program that keeps a schedule of its own (tofmat sort)."""
        if self._pending:
            return self._pending.popleft()
        return self._next_from_daemon(timeout)

    def _next_from_daemon(self, timeout: float | None) -> Event | None:
        deadline = None if timeout is None else time.monotonic() + max(0.0, timeout)
        while True:
            left = -1.0 if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                item = self._connection().next_event(left)
            except ConnectionClosedError:
                if not self._reconnect or self._conn is None:
                    raise
                self._reopen()
                continue
            if item is None:
                return None
            event = _event(*item)
            if event is not None:
                return event
            # (an event of a later minor version: skipped, the wait goes on)

    def events(self, timeout: float | None = None) -> Iterator[Event]:
        """Events of the subscribed streams, in order. Raises DaemonTimeoutError when none comes
        within ``timeout`` seconds (None: wait forever)."""
        while True:
            event = self.next_event(timeout)
            if event is None:
                raise DaemonTimeoutError(f"no event from tofmatd within {timeout} s")
            yield event

    def labels(self, timeout: float | None = 5.0) -> Iterator[Label]:
        """Live labels (subscribes to them)."""
        if "labels" not in self._streams:
            self.subscribe("labels")
        for e in self.events(timeout):
            if isinstance(e, Label):
                yield e

    def label_map(self, timeout: float | None = 5.0) -> LabelMap:
        """The next per-pixel label map (segmentation profile). Other events that come meanwhile are
        kept for next_event() and events(), not dropped."""
        if "label_map" not in self._streams:
            self.subscribe("label_map")
        return self._wait_for(lambda e: isinstance(e, LabelMap), timeout)  # type: ignore[return-value]

    def depth(self, kind: DepthKind = "combined", timeout: float | None = 5.0) -> DepthImage:
        """The next depth image of the profile's region: "80", "16", "120", "combined" or "corrected"
        (the combined depth less each labelled pixel's material distortion, NaN where there is no
        label or the table has no distortion for its material: a daemon of protocol minor 9 on).
        Other events that come meanwhile are kept for next_event() and events(), not dropped."""
        stream = f"depth:{kind}"
        if stream not in self._streams:
            self.subscribe(stream)
        return self._wait_for(lambda e: isinstance(e, DepthImage) and e.kind == kind, timeout)  # type: ignore[return-value]

    def _wait_for(self, wanted: Callable[[Event], bool], timeout: float | None) -> Event:
        """The first event (kept back ones first) that is ``wanted``; the others are kept, in order."""
        kept = self._pending.take_first(wanted)
        if kept is not None:
            return kept
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            event = self._next_from_daemon(left)
            if event is None:
                raise DaemonTimeoutError(f"no event from tofmatd within {timeout} s")
            if wanted(event):
                return event
            self._pending.append(event)  # (in order, after those kept before)


def daemon_binary() -> Path:
    """The tofmatd that ships with this package (TOFMAT_DAEMON overrides it)."""
    env = os.environ.get("TOFMAT_DAEMON")
    path = Path(env) if env else Path(__file__).parent / "bin" / "tofmatd"
    if not path.is_file():
        raise FileNotFoundError(f"tofmatd not found at {path} (reinstall the SDK, or set TOFMAT_DAEMON)")
    return path


def sim_data_dir() -> Path:
    from .sim import data_dir

    return data_dir()


__all__ = [
    "MAX_PENDING_BYTES",
    "MAX_PENDING_EVENTS",
    "STREAMS",
    "AuthenticationError",
    "Backend",
    "ClassifierMethod",
    "Client",
    "ClientError",
    "CommandError",
    "ConnectionClosedError",
    "DaemonTimeoutError",
    "DaemonUnavailableError",
    "DepthImage",
    "DepthKind",
    "DeviceEvent",
    "DeviceState",
    "DeviceStatus",
    "Event",
    "Label",
    "LabelMap",
    "LabelState",
    "LineEvent",
    "NotPermittedError",
    "Profile",
    "ProtocolError",
    "ProtocolVersionError",
    "Rank",
    "ReloadStatus",
    "ResetEvent",
    "Role",
    "SortDecision",
    "Status",
    "Stream",
    "TableStatus",
    "Truth",
    "daemon_binary",
]
