# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""Diverter gates for tofmatd's sort decisions: when each outlet's flap opens and closes.

A flap on a servo is slow (``travel_ms`` from closed to open), so it must start moving before its
item arrives. tofmatd sends each item's decision (stream ``sort``, state ``decided``) with the time
the item will reach its outlet (``fire_ns``); the gate of that outlet opens ``travel_ms`` before
it and closes ``hold_ms`` after it. Two items for the same outlet close together keep it open. A
decision that comes too late to open in time opens the gate at once and is reported with how late
it is. Pure: no clock, no I/O; :mod:`tofmat.tools.sort_agent` drives the servos.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

from ..client import SortDecision


@dataclass(frozen=True)
class Gate:
    """One outlet's flap: its servo channel, its angles and how slow it is."""

    outlet: str
    channel: int
    open_angle: float = 90.0
    closed_angle: float = 0.0
    travel_ms: float = 150.0
    hold_ms: float = 150.0

    def __post_init__(self) -> None:
        if not self.outlet:
            raise ValueError("a gate needs its outlet's name")
        if not 0 <= self.channel <= 15:
            raise ValueError(f"gate {self.outlet}: channel {self.channel} is not 0..15")
        for name in ("open_angle", "closed_angle", "travel_ms", "hold_ms"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"gate {self.outlet}: {name} must be a number, not {v!r}")
        if self.travel_ms < 0 or self.hold_ms < 0:
            raise ValueError(f"gate {self.outlet}: travel and hold are times >= 0 ms")


def parse_gate(text: str) -> Gate:
    """``OUTLET:channel=N[,open=DEG][,closed=DEG][,travel=MS][,hold=MS]`` (ValueError if not)."""
    name, sep, rest = text.partition(":")
    if not sep or not name:
        raise ValueError(f"gate {text!r}: expected OUTLET:channel=N[,open=DEG][,closed=DEG][,travel=MS][,hold=MS]")
    keys = {"channel": "channel", "open": "open_angle", "closed": "closed_angle", "travel": "travel_ms",
            "hold": "hold_ms"}  # fmt: skip
    values: dict[str, float] = {}
    for part in rest.split(","):
        key, eq, value = part.partition("=")
        if not eq or key not in keys:
            raise ValueError(f"gate {name}: {part!r} is not one of {', '.join(k + '=' for k in keys)}")
        try:
            values[keys[key]] = float(value)
        except ValueError:
            raise ValueError(f"gate {name}: {key}={value!r} is not a number") from None
    if "channel" not in values:
        raise ValueError(f"gate {name}: no channel=N")
    channel = values.pop("channel")
    if channel != int(channel):
        raise ValueError(f"gate {name}: channel must be a whole number")
    return Gate(name, int(channel), **values)


@dataclass(order=True, frozen=True)
class GateMove:
    """Move ``outlet``'s flap open or closed at ``t_ns`` (CLOCK_MONOTONIC)."""

    t_ns: int
    outlet: str = field(compare=False)
    open: bool = field(compare=False)
    item: int = field(compare=False)


class GateSchedule:
    """The gates' moves from tofmatd's decisions, in time order."""

    def __init__(self, gates: list[Gate]) -> None:
        self.gates = {g.outlet: g for g in gates}
        if len(self.gates) != len(gates):
            raise ValueError("two gates for one outlet")
        self._moves: list[GateMove] = []
        self._closes: dict[str, GateMove] = {}  # the close move of each gate that is (to be) open
        self.late: list[tuple[int, str, float]] = []  # (item, outlet, ms late) for decisions too late to open in time

    def decided(self, d: SortDecision, now_ns: int) -> float | None:
        """Plans the gate for one decision; returns how many ms too late it came to open in time
        (None when in time, or when no gate serves its outlet or it has no planned time)."""
        if d.state != "decided" or d.outlet is None or d.fire_ns is None or d.outlet not in self.gates:
            return None
        g = self.gates[d.outlet]
        open_at = d.fire_ns - round(g.travel_ms * 1e6)
        close_at = d.fire_ns + round(g.hold_ms * 1e6)
        late = (now_ns - open_at) / 1e6 if now_ns > open_at else None
        planned = self._closes.get(g.outlet)
        if planned is not None and open_at <= planned.t_ns:
            # Still (to be) open for the item before: stay open for this one too.
            if close_at > planned.t_ns:
                # (By identity: moves compare by time alone, another gate's may share it.)
                self._moves = [m for m in self._moves if m is not planned]
                heapq.heapify(self._moves)
                self._schedule_close(g.outlet, close_at, d.item)
        else:
            heapq.heappush(self._moves, GateMove(max(open_at, now_ns), g.outlet, True, d.item))
            self._schedule_close(g.outlet, close_at, d.item)
        if late is not None:
            self.late.append((d.item, g.outlet, late))
        return late

    def _schedule_close(self, outlet: str, t_ns: int, item: int) -> None:
        move = GateMove(t_ns, outlet, False, item)
        self._closes[outlet] = move
        heapq.heappush(self._moves, move)

    def due(self, now_ns: int) -> list[GateMove]:
        """The moves due by ``now_ns``, oldest first."""
        out = []
        while self._moves and self._moves[0].t_ns <= now_ns:
            m = heapq.heappop(self._moves)
            if not m.open and self._closes.get(m.outlet) is m:
                del self._closes[m.outlet]
            out.append(m)
        return out

    def next_ns(self) -> int | None:
        """When the next move is due (None: nothing planned)."""
        return self._moves[0].t_ns if self._moves else None
