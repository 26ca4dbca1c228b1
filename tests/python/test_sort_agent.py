# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The diverter agent (`tofmat sort`, issue 17): gates planned from tofmatd's sort decisions so that
each is open when its item arrives, and driven on simulated PCA9685 servos against a live line."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from conftest import Daemon

from tofmat.client import SortDecision
from tofmat.hw import FakePCA9685Bus
from tofmat.line import Gate, GateSchedule, parse_gate
from tofmat.tools.line_demo import LineSetup
from tofmat.tools.sort_agent import gate_servos, run_sort_agent

MS = 1_000_000


def decided(item: int, outlet: str | None, fire_ms: int | None) -> SortDecision:
    return SortDecision("decided", item, 0, outlet, 1.0, outlet, "sorted", 0,
                        None if fire_ms is None else fire_ms * MS, 0.0)  # fmt: skip


def test_gates_are_parsed_with_their_defaults() -> None:
    g = parse_gate("wood:channel=3,travel=120")
    assert g == Gate("wood", 3, 90.0, 0.0, 120.0, 150.0)
    for bad in ("wood", "wood:travel=100", "wood:channel=16", "wood:channel=1.5", "wood:channel=1,speed=3",
                "wood:channel=1,open=fast", ":channel=1", "wood:channel=1,travel=-5"):  # fmt: skip
        with pytest.raises(ValueError):
            parse_gate(bad)


def test_a_gate_opens_its_travel_time_before_the_item_and_closes_after() -> None:
    s = GateSchedule([Gate("wood", 0, travel_ms=150, hold_ms=100), Gate("cork", 1, travel_ms=50, hold_ms=100)])
    assert s.decided(decided(1, "wood", 1000), now_ns=200 * MS) is None
    assert s.decided(decided(2, "cork", 1100), now_ns=300 * MS) is None
    assert s.next_ns() == 850 * MS
    assert s.due(849 * MS) == []
    moves = s.due(1300 * MS)
    assert [(m.t_ns // MS, m.outlet, m.open) for m in moves] == [
        (850, "wood", True), (1050, "cork", True), (1100, "wood", False), (1200, "cork", False)]  # fmt: skip
    assert s.next_ns() is None


def test_items_close_together_keep_their_gate_open() -> None:
    s = GateSchedule([Gate("wood", 0, travel_ms=150, hold_ms=100)])
    s.decided(decided(1, "wood", 1000), 0)
    s.decided(decided(2, "wood", 1200), 0)  # opens at 1050, before the first's close at 1100
    moves = s.due(5000 * MS)
    assert [(m.t_ns // MS, m.open) for m in moves] == [(850, True), (1300, False)]
    s.decided(decided(3, "wood", 2000), 1600 * MS)  # after it closed: a new opening
    assert [(m.t_ns // MS, m.open) for m in s.due(5000 * MS)] == [(1850, True), (2100, False)]


def test_a_decision_too_late_to_open_in_time_opens_at_once_and_is_reported() -> None:
    s = GateSchedule([Gate("wood", 0, travel_ms=150, hold_ms=100)])
    assert s.decided(decided(7, "wood", 1000), now_ns=900 * MS) == pytest.approx(50.0)
    assert [(m.t_ns // MS, m.open) for m in s.due(5000 * MS)] == [(900, True), (1100, False)]
    assert s.late == [(7, "wood", pytest.approx(50.0))]


def test_what_no_gate_serves_is_left_alone() -> None:
    s = GateSchedule([Gate("wood", 0)])
    assert s.decided(decided(1, "reject", 1000), 0) is None
    assert s.decided(decided(2, None, None), 0) is None
    assert s.decided(decided(3, "wood", None), 0) is None  # (the belt stands: no planned time)
    assert s.next_ns() is None
    with pytest.raises(ValueError):
        GateSchedule([Gate("wood", 0), Gate("wood", 1)])


def test_the_agent_has_each_gate_open_when_its_item_arrives(start: object, tmp_path: Path) -> None:
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    materials = ("acryl", "copper", "silicone")
    table = tmp_path / "line.tmx"
    simulated_table(Renderer(load_device(), load_library(), 1), list(materials), database_bins()).save(str(table))
    setup = LineSetup(materials, rate_per_min=90.0)
    d: Daemon = start(setup.source(), "--profile", "sorting", *setup.daemon_args(), table=table)  # type: ignore[operator]
    bus = FakePCA9685Bus(clock=lambda: time.monotonic_ns() / 1e9)
    gates = [Gate(m, k, travel_ms=120, hold_ms=100) for k, m in enumerate(materials)]
    servos = gate_servos(bus, gates)
    with d.client() as c:
        r = run_sort_agent(c, servos, gates, seconds=10.0)
    sorted_items = [f for f in r.fired if f.outlet in servos and f.fire_ns is not None]
    assert r.decisions >= 8 and len(sorted_items) >= 5, (r.decisions, len(sorted_items))
    for f in sorted_items:
        assert f.fire_ns is not None and f.outlet is not None
        assert r.open_when_fired(f.outlet, f.fire_ns), f"gate {f.outlet} was not open for item {f.item}"
    assert r.late == []
    assert bus.errors == []
    # The chip's outputs moved: every gate ends closed (0 degrees: 1000 us).
    for g in gates:
        assert bus.pulse_us(g.channel) == pytest.approx(1000.0, abs=5.0)


def test_the_sort_command_refuses_what_cannot_work(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from tofmat.cli import main

    runner = CliRunner()
    sock = str(tmp_path / "none.sock")
    cases = [
        (["sort", "--address", sock, "--gate", "wood:channel=0"], 2, "--bus N"),
        (["sort", "--address", sock, "--gate", "wood:channel=0", "--bus", "1", "--simulated"], 2, "--bus N"),
        (["sort", "--address", sock, "--gate", "wood:channel=99", "--simulated"], 2, "channel 99"),
        (["sort", "--address", sock, "--gate", "wood:channel=0", "--bus", "7"], 1, "/dev/i2c-7"),
        (["sort", "--address", sock, "--gate", "wood:channel=0", "--simulated"], 1, "none.sock"),
    ]
    for args, code, says in cases:
        r = runner.invoke(main, args)
        assert r.exit_code == code and says in r.output, (args, r.exit_code, r.output)


def test_keeping_a_gate_open_moves_its_own_close_not_another_gates_at_the_same_time() -> None:
    s = GateSchedule([Gate("wood", 0, travel_ms=100, hold_ms=100), Gate("cork", 1, travel_ms=100, hold_ms=100)])
    s.decided(decided(1, "cork", 1000), 0)  # cork closes at 1100
    s.decided(decided(2, "wood", 1000), 0)  # wood closes at 1100 too
    s.decided(decided(3, "wood", 1150), 0)  # wood stays open to 1250
    moves = [(m.t_ns // MS, m.outlet, m.open) for m in s.due(5000 * MS)]
    assert sorted(moves) == [(900, "cork", True), (900, "wood", True), (1100, "cork", False), (1250, "wood", False)]
