# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat line-demo`: tofmatd running a simulated sorting line, end to end.

The simulated belt (``--source sim:belt``) carries items of a few materials past a light barrier
on the simulated GPIO chip (``--gpio sim``) and under the simulated camera; tofmatd's sorting line
starts a burst when each item is under the camera, picks its outlet from the label and drives the
outlet's pusher when the item gets there. This watches the ``sort`` and ``line`` streams through
the Python client and prints what a line's operator asks: items per minute, the fraction sorted to
the right outlet (against the simulator's truth), the rejects and why, the timing margin (how long
before its outlet each decision came) and the time from the barrier to the decision.
"""

from __future__ import annotations

import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..client import Client, LineEvent, SortDecision
from ..hw import FakePCA9685Bus
from ..line import Gate
from .live_demo import connect, start_daemon, stop_daemon_or_raise
from .sort_agent import AgentResult, gate_servos, run_sort_agent

FRAME_S = 1.0 / 30.0


@dataclass(frozen=True)
class LineSetup:
    """The simulated line's geometry and the daemon's settings for it.

    Every item lies flat on the belt, so the camera sees each at one depth: the burst's frames cover
    one depth bin of the table, not a sweep. At one depth the simulated camera tells some materials
    apart easily (acryl, copper, fabric, silicone, cork: their features at 900 mm are at least
    4.7 mm apart in the table) and others hardly at all (wood, paper, pvc and cork are at most 1.4 mm
    apart there),
    which is why the demo's mix is the former.
    """

    materials: tuple[str, ...]
    speed_mm_s: float = 500.0
    rate_per_min: float = 60.0
    item_mm: float = 160.0
    width_mm: float = 140.0
    depth_mm: float = 900.0
    camera_mm: float = 300.0  # barrier -> the camera's optical axis
    burst: int = 4  # frames per item
    first_outlet_mm: float = 900.0
    outlet_spacing_mm: float = 200.0
    jitter: float = 0.3
    seed: int = 1
    # mm^2: a label further than this from its material goes to reject. An Eq. (12) bound: the line
    # runs Eq. (12) (--classifier eq12) while it is set, the session matcher with its open set when 0.
    max_distance: float = 50.0
    source_extra: str = ""  # more sim keys, e.g. "unplug_at=150,replug_ms=2000" (the camera lost a while)

    def outlets(self) -> list[tuple[str, float]]:
        """(name, position) of each material's outlet, then the reject outlet's."""
        out = [(m, self.first_outlet_mm + k * self.outlet_spacing_mm) for k, m in enumerate(self.materials)]
        return [*out, ("reject", self.first_outlet_mm + len(self.materials) * self.outlet_spacing_mm)]

    def burst_start_mm(self) -> float:
        """Where the item's leading edge is when its burst starts: the item's middle is under the
        camera in the middle of the burst."""
        travel = self.burst * FRAME_S * self.speed_mm_s
        return self.camera_mm + self.item_mm / 2 - travel / 2

    def source(self) -> str:
        return (f"sim:belt,materials={'+'.join(self.materials)},speed={self.speed_mm_s:g},rate={self.rate_per_min:g},"
                f"item={self.item_mm:g},width={self.width_mm:g},depth={self.depth_mm:g},camera={self.camera_mm:g},"
                f"jitter={self.jitter:g},seed={self.seed}{',' + self.source_extra if self.source_extra else ''}")  # fmt: skip

    def daemon_args(self) -> list[str]:
        args = ["--burst", str(self.burst), "--candidates", ",".join(self.materials), "--gpio", "sim",
                "--line-barrier", "sim:barrier", "--line-barrier-active-low", "--line-barrier-bias", "pull-up",
                "--line-speed", f"{self.speed_mm_s:g}", "--line-camera-mm", f"{self.burst_start_mm():g}",
                "--line-reject", "reject", "--line-alarm", "sim:alarm",
                "--line-max-distance", f"{self.max_distance:g}"]  # fmt: skip
        if self.max_distance > 0:
            args += ["--classifier", "eq12"]
        for name, pos in self.outlets():
            materials = "" if name == "reject" else f",materials={name}"
            args += ["--outlet", f"{name}:position={pos:g},line=sim:push_{name}{materials}"]
        return args


@dataclass
class LineResult:
    seconds: float = 0.0
    decided: list[SortDecision] = field(default_factory=list)
    fired: list[SortDecision] = field(default_factory=list)
    faults: list[LineEvent] = field(default_factory=list)
    status: Mapping[str, object] = field(default_factory=dict)
    gates: AgentResult | None = None  # `tofmat sort` on a simulated PCA9685, when asked for
    gate_chip_errors: int = 0

    @property
    def items(self) -> int:
        return len(self.decided)

    def per_min(self) -> float:
        """Items a minute through the barrier, from the first decided item's edge to the last's."""
        if len(self.decided) < 2:
            return 0.0
        span = self.decided[-1].trigger_ns - self.decided[0].trigger_ns
        return 60e9 * (len(self.decided) - 1) / span if span > 0 else 0.0

    def right(self) -> int:
        """Items sent to their own material's outlet (the simulator's truth)."""
        return sum(1 for d in self.decided if d.truth and d.outlet == d.truth and d.reason == "sorted")

    def right_fraction(self) -> float:
        """Right among the items whose truth is known (an item without one is neither right nor wrong)."""
        known = self.items - self.missing_truth()
        return self.right() / known if known else 0.0

    def missing_truth(self) -> int:
        """Items the simulator's truth did not reach (none once it travels with the item from the barrier)."""
        return sum(1 for d in self.decided if not d.truth)

    def reasons(self) -> Counter[str]:
        return Counter(d.reason for d in self.decided)

    def wrong(self) -> int:
        """Sorted (not rejected) to another material's outlet: the costly mistake."""
        return sum(1 for d in self.decided if d.reason == "sorted" and d.truth and d.outlet != d.truth)

    def margins_ms(self) -> np.ndarray:
        return np.array([d.margin_ms for d in self.decided if d.reason == "sorted"], dtype=float)

    def decision_ms(self) -> np.ndarray:
        return np.array([(d.decided_ns - d.trigger_ns) / 1e6 for d in self.decided if d.material], dtype=float)

    def gates_open_in_time(self) -> tuple[int, int]:
        """(items whose outlet's flap was open when they got there, items pushed at a flap's outlet)."""
        if self.gates is None:
            return 0, 0
        flaps = {m.outlet for _, m in self.gates.moves}
        pushed = [f for f in self.fired if f.outlet in flaps and f.fire_ns is not None]
        ok = sum(1 for f in pushed if f.outlet and f.fire_ns and self.gates.open_when_fired(f.outlet, f.fire_ns))
        return ok, len(pushed)

    def fire_error_ms(self) -> np.ndarray:
        """How late each pusher fired against its plan (the decision's fire_ns)."""
        planned = {d.item: d.fire_ns for d in self.decided if d.fire_ns is not None}
        return np.array([(f.fire_ns - planned[f.item]) / 1e6 for f in self.fired
                         if f.fire_ns is not None and f.item in planned], dtype=float)  # fmt: skip


class _GateAgent:
    """`tofmat sort` beside the line, on a thread: a flap on a servo (a simulated PCA9685, on the
    monotonic clock) in front of each material's outlet, moved for tofmatd's decisions."""

    def __init__(self, socket: Path, setup: LineSetup, result: LineResult) -> None:
        self.bus = FakePCA9685Bus(clock=lambda: time.monotonic_ns() / 1e9)
        self.gates = [Gate(m, k, travel_ms=120.0, hold_ms=100.0) for k, m in enumerate(setup.materials)]
        self.servos = gate_servos(self.bus, self.gates)
        self.socket, self.result = socket, result
        self.stop = threading.Event()
        self.failure: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="tofmat-sort", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            with Client(self.socket, reconnect=False) as c:
                self.result.gates = run_sort_agent(c, self.servos, self.gates, stop=self.stop.is_set)
            self.result.gate_chip_errors = len(self.bus.errors)
        except Exception as e:  # (raised by finish(), on the caller's thread)
            self.failure = e

    def finish(self) -> None:
        self.stop.set()
        self.thread.join(10.0)
        if self.failure is not None:
            raise RuntimeError(f"the gate agent failed: {self.failure}") from self.failure


def run_line(
    table: Path, setup: LineSetup, seconds: float, echo: Callable[[str], None] | None = None, gates: bool = False
) -> LineResult:
    """Runs tofmatd on the simulated line for ``seconds`` after the first item and collects its decisions;
    with ``gates``, `tofmat sort` moves a simulated flap for each material's outlet too."""
    result = LineResult()
    say = echo or (lambda _line: None)
    with tempfile.TemporaryDirectory(prefix="tofmat-line-") as tmp:
        socket, log = Path(tmp) / "tofmatd.sock", Path(tmp) / "tofmatd.log"
        daemon = start_daemon(table, socket, setup.source(), log, profile="sorting", extra=setup.daemon_args())
        agent: _GateAgent | None = None
        try:
            with connect(socket, daemon) as client:
                if gates:
                    agent = _GateAgent(socket, setup, result)
                client.subscribe("sort", "line")
                t_end: float | None = None
                for event in client.events(timeout=10.0):
                    now = time.monotonic()
                    if isinstance(event, SortDecision):
                        if t_end is None:
                            t_end = now + seconds
                        if event.state == "decided":
                            result.decided.append(event)
                            wrong = bool(event.truth) and event.outlet != event.truth and event.reason == "sorted"
                            truth = event.truth or "unknown"
                            say(f"item {event.item:4d}: {event.material or '-':10s} {event.distance:7.2f} mm^2 -> "
                                f"{event.outlet or 'belt end':10s} "
                                f"({event.reason}; truth {truth}{', WRONG' if wrong else ''}; "
                                f"margin {event.margin_ms:.0f} ms)")  # fmt: skip
                        else:
                            result.fired.append(event)
                    elif isinstance(event, LineEvent) and event.kind != "alarm":
                        result.faults.append(event)
                        say(f"line: {event.kind}: {event.message}")
                    if t_end is not None and now >= t_end:
                        break
                result.seconds = seconds
                result.status = client.status()
                if agent is not None:
                    agent.finish()
        finally:
            if agent is not None:
                agent.stop.set()
            stop_daemon_or_raise(daemon, log, say)
    return result


def summary(setup: LineSetup, r: LineResult) -> list[str]:
    def pct(a: np.ndarray, q: float) -> str:
        return f"{np.percentile(a, q):.0f}" if a.size else "-"

    margins, decision, fire = r.margins_ms(), r.decision_ms(), r.fire_error_ms()
    rejects = ", ".join(f"{k} {v}" for k, v in sorted(r.reasons().items()) if k != "sorted") or "none"
    gates = []
    if r.gates is not None:
        ok, pushed = r.gates_open_in_time()
        gates = [f"gates (tofmat sort, simulated PCA9685): {len(r.gates.moves)} flap moves; open when their item "
                 f"arrived {ok} of {pushed}; too late to open {len(r.gates.late)}; chip errors {r.gate_chip_errors}"]  # fmt: skip
    return [
        f"line: {len(setup.materials)} materials at {setup.speed_mm_s:g} mm/s, {setup.rate_per_min:g} items/min "
        f"offered, burst {setup.burst} frames",
        f"items: {r.items} in {r.seconds:.0f} s ({r.per_min():.0f}/min); "
        f"to the right outlet {r.right()} ({100.0 * r.right_fraction():.1f} % of those with a known truth), to a "
        f"wrong one {r.wrong()}; truth unknown {r.missing_truth()}; rejects: {rejects}",
        f"timing margin (fire time - decision): p50 {pct(margins, 50)} ms, p1 {pct(margins, 1)} ms; "
        f"barrier -> decision p50 {pct(decision, 50)} ms, p99 {pct(decision, 99)} ms; "
        f"pushers late against plan p50 {pct(fire, 50) if fire.size else '-'} ms, max {fire.max() if fire.size else 0:.1f} ms",
        *gates,
    ]
