# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat sort`: the diverter agent. It follows tofmatd's sort decisions and moves each outlet's
gate (a flap on a servo, on a PCA9685) so that it is open when its item arrives and closed after.

The schedule is :class:`tofmat.line.GateSchedule`; this drives it on the clock tofmatd's times are
on (CLOCK_MONOTONIC) and reports decisions that came too late for a gate to open in time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ..client import Client, LineEvent, SortDecision
from ..hw import PCA9685, I2CBus, Servo
from ..line import Gate, GateMove, GateSchedule

SERVO_HZ = 50  # hobby servos: a pulse every 20 ms


def gate_servos(bus: I2CBus, gates: list[Gate], address: int = 0x40) -> dict[str, Servo]:
    """Each gate's servo, by outlet, on the PCA9685 at ``address`` on ``bus`` (set to 50 Hz)."""
    pca = PCA9685(bus, address)
    pca.set_frequency(SERVO_HZ)
    return {g.outlet: Servo(pca, g.channel) for g in gates}


@dataclass
class AgentResult:
    decisions: int = 0
    moves: list[tuple[int, GateMove]] = field(default_factory=list)  # (monotonic ns when done, move)
    late: list[tuple[int, str, float]] = field(default_factory=list)  # (item, outlet, ms late)
    fired: list[SortDecision] = field(default_factory=list)  # tofmatd's pushers, for comparison

    def open_when_fired(self, outlet: str, fire_ns: int) -> bool:
        """Whether ``outlet``'s gate had last been moved open (not closed) by ``fire_ns``."""
        last = [m for t, m in self.moves if m.outlet == outlet and t <= fire_ns]
        return bool(last) and last[-1].open


def run_sort_agent(
    client: Client,
    servos: dict[str, Servo],
    gates: list[Gate],
    seconds: float | None = None,
    echo: Callable[[str], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> AgentResult:
    """Closes every gate, follows the decisions for ``seconds`` (None: until the daemon goes, or
    ``stop()`` says so, which is asked at least once a second), and closes every gate again when it
    stops."""
    say = echo or (lambda _line: None)
    schedule = GateSchedule(gates)
    result = AgentResult()
    by_outlet = {g.outlet: g for g in gates}
    for g in gates:
        servos[g.outlet].move_to(g.closed_angle)
    try:
        client.subscribe("sort", "line")
        end = None if seconds is None else time.monotonic_ns() + round(seconds * 1e9)
        while (end is None or time.monotonic_ns() < end) and not (stop and stop()):
            now = time.monotonic_ns()
            for move in schedule.due(now):
                g = by_outlet[move.outlet]
                servos[g.outlet].move_to(g.open_angle if move.open else g.closed_angle)
                result.moves.append((time.monotonic_ns(), move))
            wake = schedule.next_ns()
            limit = [x for x in (wake, end) if x is not None]
            timeout = (min(limit) - time.monotonic_ns()) / 1e9 if limit else 1.0
            event = client.next_event(min(max(timeout, 0.0), 1.0))
            if isinstance(event, SortDecision) and event.state == "decided":
                result.decisions += 1
                late = schedule.decided(event, time.monotonic_ns())
                if late is not None:
                    result.late.append((event.item, event.outlet or "", late))
                    say(f"item {event.item}: gate {event.outlet} cannot be open in time ({late:.0f} ms late)")
            elif isinstance(event, SortDecision):
                result.fired.append(event)
            elif isinstance(event, LineEvent) and event.kind != "alarm":
                say(f"line: {event.kind}: {event.message}")
    finally:
        # Stopping (also on Ctrl-C): every gate closed (an open one would take every later item).
        for g in gates:
            servos[g.outlet].move_to(g.closed_angle)
    return result
