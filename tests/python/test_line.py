# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The sorting line end to end on the simulated belt (issue 17): tofmatd --gpio sim with
--source sim:belt, watched through the Python client's `sort` and `line` streams.

The belt drives the simulated light barrier at the moments its items cross it and the camera
renders them where they are; tofmatd's line starts each item's burst, picks its outlet and drives
the pusher. These check what a line's operator relies on: every item is decided once and pushed
once, at the planned moment, to its own material's outlet or to reject, never silently merged or
lost, and the figures agree with the daemon's own counts.
"""

from __future__ import annotations

import subprocess
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from conftest import Daemon

import tofmat
from tofmat.client import daemon_binary, sim_data_dir
from tofmat.tools.line_demo import LineResult, LineSetup, run_line, summary

MATERIALS = ("acryl", "copper", "silicone")  # (told apart at one depth: tofmat.tools.line_demo.LineSetup)


@pytest.fixture(scope="module")
def line_table(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated camera's own table of the line's materials (tofmat sim table)."""
    from tofmat.sim import Renderer, load_device, load_library
    from tofmat.sim.table import database_bins, simulated_table

    path = tmp_path_factory.mktemp("linetable") / "line.tmx"
    simulated_table(Renderer(load_device(), load_library(), 1), list(MATERIALS), database_bins()).save(str(path))
    return path


@pytest.fixture(scope="module")
def line_run(line_table: Path) -> tuple[LineSetup, LineResult]:
    setup = LineSetup(MATERIALS, speed_mm_s=500.0, rate_per_min=90.0, burst=4, seed=3)
    return setup, run_line(line_table, setup, seconds=12.0, gates=True)


def test_every_item_is_decided_once_and_pushed_once_on_time(line_run: tuple[LineSetup, LineResult]) -> None:
    _setup, r = line_run
    assert r.items >= 12, f"only {r.items} items in 12 s at 90/min"
    items = [d.item for d in r.decided]
    assert items == sorted(set(items)), "an item decided twice, or out of order"
    assert items == list(range(items[0], items[0] + len(items))), "an item number skipped (lost or merged)"
    fired = Counter(f.item for f in r.fired)
    assert max(fired.values()) == 1, "a pusher driven twice for one item"
    # Every decided item reaches its pusher (but the last few, still on the belt at the end).
    assert len(fired) >= len(items) - 4
    late = r.fire_error_ms()
    assert late.size >= 8
    assert late.min() >= -0.01, f"a pusher fired {-late.min():.2f} ms early"
    assert np.percentile(late, 50) < 5.0 and late.max() < 50.0, f"pushers late: {np.percentile(late, [50, 100])} ms"


def test_items_go_to_their_own_outlet_or_to_reject(line_run: tuple[LineSetup, LineResult]) -> None:
    setup, r = line_run
    outlets = {name for name, _ in setup.outlets()}
    for d in r.decided:
        assert d.outlet in outlets, d
        if d.reason == "sorted":
            assert d.outlet == d.material, "sorted to another material's outlet than its label's"
        else:
            assert d.outlet == "reject", d
    # (issue 33) Every item's truth travels with it from the barrier: none is found missing by time.
    assert r.missing_truth() == 0, [d for d in r.decided if not d.truth]
    right = r.right_fraction()
    assert right >= 0.8, f"only {right:.0%} to the right outlet: {r.reasons()}"
    assert r.wrong() <= 1, "items sorted to a wrong material's outlet"
    margins = r.margins_ms()
    assert margins.min() >= 20.0, "a sorted item's decision came under the margin"


def test_the_demos_gates_are_open_when_their_items_arrive(line_run: tuple[LineSetup, LineResult]) -> None:
    # `tofmat sort` beside the line (line-demo's default): a flap per material's outlet on a simulated
    # PCA9685, which records every move; each pushed item found its flap open, none came too late.
    setup, r = line_run
    assert r.gates is not None
    ok, pushed = r.gates_open_in_time()
    assert pushed >= 5 and ok == pushed, (ok, pushed)
    assert r.gates.late == [] and r.gate_chip_errors == 0
    moved = {m.outlet for _, m in r.gates.moves}
    assert moved <= set(setup.materials) and len(moved) >= 2
    assert any(line.startswith("gates (tofmat sort, simulated PCA9685)") for line in summary(setup, r))


def test_the_daemons_counts_agree(line_run: tuple[LineSetup, LineResult]) -> None:
    _, r = line_run
    line = r.status["line"]
    assert line["gpio"] == "sim"
    assert line["items"] >= r.items
    decided = line["sorted"] + line["rejected"]
    assert decided <= line["items"] <= decided + line["on_belt"], "an item neither decided nor on the belt"
    assert line["sorted"] >= sum(1 for d in r.decided if d.reason == "sorted")
    assert line["barrier_glitches"] == 0 and line["barrier_bounces"] == 0


def test_the_camera_lost_mid_run_sends_items_to_reject_until_it_is_back(line_table: Path) -> None:
    # The simulated camera is unplugged 5 s in (frame 150) and plugged back 2.5 s later.
    setup = LineSetup(MATERIALS, rate_per_min=90.0, seed=4, source_extra="unplug_at=150,replug_ms=2500")
    r = run_line(line_table, setup, seconds=14.0)
    reasons = [d.reason for d in r.decided]
    assert "camera_lost" in reasons, reasons
    first_lost = reasons.index("camera_lost")
    assert "sorted" in reasons[:first_lost], "nothing sorted before the camera went"
    assert "sorted" in reasons[first_lost:], "nothing sorted after the camera came back"
    assert any(f.kind == "camera" for f in r.faults)
    assert r.wrong() == 0
    assert r.status["line"]["alarm"] is False, "the alarm stayed on after the camera came back"
    assert r.status["device"]["state"] == "streaming"


def test_a_clients_trigger_is_refused_while_the_barrier_triggers(
    start: Callable[..., Daemon], line_table: Path
) -> None:
    setup = LineSetup(MATERIALS)
    d = start(setup.source(), "--profile", "sorting", *setup.daemon_args(), table=line_table)
    with d.client() as c:
        assert "sort" in c.hello["capabilities"]
        with pytest.raises(tofmat.CommandError, match="light barrier triggers"):
            c.trigger()
        c.subscribe("sort", "line")


def test_the_line_refuses_what_cannot_work(tmp_path: Path, line_table: Path) -> None:
    setup = LineSetup(MATERIALS)
    base = [str(daemon_binary()), "--source", setup.source(), "--table", str(line_table), "--socket",
            str(tmp_path / "s"), "--sim-data", str(sim_data_dir())]  # fmt: skip
    args = setup.daemon_args()
    teak = [a.replace("materials=copper", "materials=teak") for a in args]
    chip_number = [a.replace("sim:barrier", "gpiochip0:17") for a in args]
    for extra, says in ((args, "needs --profile sorting"), (["--profile", "sorting", *teak], "teak"),
                        (["--profile", "sorting", *chip_number], "chip number"),
                        (["--profile", "sorting", "--line-speed", "500"], "need --gpio")):  # fmt: skip
        p = subprocess.run(base + extra, capture_output=True, text=True, timeout=60)
        assert p.returncode != 0 and says in p.stderr + p.stdout, (extra, p.stderr)
    # The board's backend where there is no GPIO: a clear failure naming the line.
    real = [a.replace("sim:", "pinctrl-rp1:") if a.startswith("sim:") or "line=sim:" in a else a for a in args]
    real = [a.replace("line=sim:", "line=pinctrl-rp1:") for a in real]
    real[real.index("sim")] = "libgpiod"
    p = subprocess.run([*base, "--profile", "sorting", *real], capture_output=True, text=True, timeout=60)
    assert p.returncode == 1
    assert "pinctrl-rp1:barrier" in p.stderr and ("no GPIO chip" in p.stderr or "no chip labelled" in p.stderr)


def test_bench_line_reports_the_highest_rate_that_sorts_99_percent_right() -> None:
    # The benchmark's summary on made-up runs: pooled over seeds, the fastest row at >= 99 % right.
    from tofmat.client import SortDecision
    from tofmat.tools.line_bench import Cell, capacity_per_min, format_markdown

    def run(right: int, wrong: int, per_s: float) -> LineResult:
        r = LineResult(seconds=20.0)
        for k in range(right + wrong):
            truth = "acryl" if k < right else "cork"
            r.decided.append(SortDecision("decided", k + 1, round(k * 1e9 / per_s), "acryl", 1.0, "acryl", "sorted",
                                          0, None, 900.0, truth))  # fmt: skip
        return r

    base = LineSetup(("acryl", "cork"), speed_mm_s=500.0)
    assert capacity_per_min(base) == pytest.approx(60 * 500 / 180)
    cells = [Cell(base, 0.6, [run(100, 0, 1.5), run(100, 0, 1.5)]),
             Cell(base, 0.9, [run(199, 1, 2.5), run(100, 0, 2.5)]),  # 299 of 300: 99.7 %
             Cell(base, 1.0, [run(98, 2, 2.75), run(100, 0, 2.75)])]  # 198 of 200: exactly 99 %  # fmt: skip
    out = "\n".join(format_markdown(cells, seeds=2, seconds=20.0))
    assert "| 500 | 4 | 0.90 |" in out and "| 99.7 % | 99.5 % | 1 |" in out
    assert "at least 99 % right up to 165 items/min sorted (offered 60, load 1.00)" in out
    # An item whose truth is missing is neither right nor wrong (it used to count as wrong).
    missing = run(99, 0, 2.5)
    missing.decided.append(SortDecision("decided", 200, 0, "acryl", 1.0, "acryl", "sorted", 0, None, 900.0, None))
    assert missing.missing_truth() == 1 and missing.right_fraction() == 1.0 and missing.wrong() == 0
    assert Cell(base, 0.9, [missing]).right_fraction() == 1.0
    worse = [Cell(base, 1.0, [run(97, 3, 2.75)])]
    assert "below 99 % right at every rate tried" in "\n".join(format_markdown(worse, seeds=1, seconds=20.0))


def test_bench_line_refuses_lists_that_are_not_numbers() -> None:
    from click.testing import CliRunner

    from tofmat.cli import main

    for args, says in ((["--speeds", "fast"], "'--speeds': 'fast': expected comma-separated numbers from 50"),
                       (["--loads", "0.5,-1"], "'--loads': '0.5,-1': expected comma-separated numbers from 0.01"),
                       (["--bursts", "2.5"], "'--bursts': '2.5': expected comma-separated whole numbers from 1"),
                       (["--speeds", ""], "'--speeds': '': expected"), (["--loads", "nan"], "'--loads': 'nan'")):  # fmt: skip
        r = CliRunner().invoke(main, ["bench-line", *args])
        assert r.exit_code == 2 and says in r.output and len(r.output.strip().splitlines()) == 1, (args, r.output)
