# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The box's front panel (issue 17): `tofmat panel` on a simulated SSD1306, tofmatd's reset button
on the simulated GPIO chip.

What is checked is the picture the panel's fake chip ends up holding, pixel for pixel against the
expected text drawn by render_text, and that a press of the button (tofmatd --reset-button, pressed
by the simulated source's presses= key) resets the accumulation once per press and reaches the panel.
"""

from __future__ import annotations

import dataclasses
import re
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from click.testing import CliRunner
from conftest import Daemon

import tofmat
from tofmat.cli import main
from tofmat.client import DeviceEvent, Label, Rank, ResetEvent, daemon_binary, sim_data_dir
from tofmat.hw import SSD1306, FakeSSD1306Bus, render_text
from tofmat.panel import COLUMNS, PanelView
from tofmat.tools.panel_agent import run_panel

SEC = 1_000_000_000
BUTTON = [
    "--gpio",
    "sim",
    "--reset-button",
    "sim:button",
    "--reset-button-active-low",
    "--reset-button-bias",
    "pull-up",
]


def label(material: str | None, distance: float, runner_up: float | None, state: str = "tracking") -> Label:
    ranking = () if material is None else (Rank(material, distance),)
    if runner_up is not None:
        ranking += (Rank("wood", runner_up),)
    return Label(frame=1, timestamp_ns=0, received_ns=0, profile="handheld", state=state, material=material,
                 index=0 if material else -1, distance=distance, valid=100, bins_covered=1, ranking=ranking,
                 trigger=None, truth=None, simulated=True)  # fmt: skip


def streaming_view() -> PanelView:
    v = PanelView()
    v.daemon_status({"profile": "handheld", "fps": 29.8, "simulated": True, "device": {"state": "streaming"}})
    return v


def test_the_view_says_label_confidence_rate_camera_and_resets() -> None:
    v = streaming_view()
    assert v.lines(0) == ["waiting", "", "handheld 30 fps", "camera streaming", "simulated"]
    v.event(label("copper", 4.04, 12.2), 1 * SEC)
    assert v.lines(1 * SEC) == ["copper", "d 4.0 next x3.0", "handheld 30 fps", "camera streaming", "simulated"]
    assert v.lines(4 * SEC)[1] == "d 4.0 next x3.0 old"  # a tracking label nobody renewed
    v.event(ResetEvent("button", 0), 5 * SEC)
    assert v.lines(5 * SEC) == ["waiting", "", "handheld 30 fps", "camera streaming", "reset by button"]
    assert v.lines(8 * SEC)[4] == "simulated"  # the note stays up three seconds
    v.event(label(None, 0.0, None, state="no_target"), 9 * SEC)
    assert v.lines(9 * SEC)[0] == "no target"
    v.event(label("cork", 0.0, 3.0), 9 * SEC)
    assert v.lines(9 * SEC)[1] == "d 0.0 next x>99"  # an exact match: no ratio to divide by
    v.event(DeviceEvent("disconnected", "unplugged", 0), 10 * SEC)
    assert v.lines(10 * SEC)[:4] == ["no camera", "", "handheld 30 fps", "camera disconnected"]
    v.daemon_away("connection lost")
    assert v.lines(11 * SEC) == ["tofmatd away", "connection lost", "", "", ""]
    v.daemon_status({"profile": "sorting", "fps": 30.0, "simulated": False, "device": {"state": "streaming"}})
    v.event(label("a-very-long-material-name-indeed", 1.0, 2.0, state="final"), 12 * SEC)
    top = v.lines(99 * SEC)
    assert len(top[0]) == COLUMNS and top[0].endswith("~") and top[1] == "d 1.0 next x2.0" and top[4] == ""
    # The session matcher's labels: their confidence, and "unknown" with the nearest.
    session = dataclasses.replace(label("cork", -3.5, 2.0), confidence=0.934, fit=0.4)
    v.event(session, 13 * SEC)
    assert v.lines(13 * SEC)[:2] == ["cork", "p 0.93 next wood"]
    v.event(dataclasses.replace(session, state="unknown", material=None, index=-1), 14 * SEC)
    assert v.lines(14 * SEC)[:2] == ["unknown", "near cork"]


def test_the_panels_picture_is_the_text_pixel_for_pixel() -> None:
    bus = FakeSSD1306Bus()
    panel = SSD1306(bus)
    panel.init()
    v = streaming_view()
    v.event(label("copper", 4.04, 12.2), 0)
    v.event(ResetEvent("command", 0), 0)
    panel.show(render_text(v.lines(0)))
    expected = render_text(["waiting", "", "handheld 30 fps", "camera streaming", "reset by command"])
    assert np.array_equal(bus.frame(), expected)
    assert bus.frame()[: 12 * 4].any() and not bus.frame()[12:24].any()  # (line 2 is blank)


def test_the_panel_follows_tofmatd_and_the_button_resets_it(start: Callable[..., Daemon]) -> None:
    # Presses at frames 45 and 52 (233 ms apart: the same finger, under the 500 ms hold-off) and 120.
    d = start("sim:static,material=acryl,presses=45+52+120", *BUTTON)
    d.client().close()  # (listening)
    bus = FakeSSD1306Bus()
    # It runs until the second reset's note has gone again (three seconds after the press at frame
    # 120, about 7 s on a quiet machine); 60 s is the bound on a loaded one.
    r = run_panel(
        lambda: tofmat.Client(d.socket, reconnect=False),
        SSD1306(bus),
        seconds=60.0,
        until=lambda lines, view: view.resets == 2 and lines[4] == "simulated",
    )
    assert r.connects == 1 and r.view is not None and r.shown is not None
    assert r.view.resets == 2, r.view.seen  # one reset per press, the second finger ignored
    with d.client() as c:
        button = c.status()["button"]
        c.subscribe("reset")
        c.reset()  # the command resets too, and says so on the same stream
        event = c.next_event(5.0)
        assert isinstance(event, ResetEvent) and event.by == "command"
    assert button == {"line": "sim:button", "presses": 2, "ignored": 1}
    assert any(lines[4] == "reset by button" for lines in r.drawn)
    # The end: the label, its confidence, the rate, the camera; the reset note gone again.
    assert r.shown[0] == "acryl" and r.shown[3] == "camera streaming" and r.shown[4] == "simulated"
    # The session matcher (tofmatd's default): its confidence and the runner-up.
    assert re.fullmatch(r"p [01]\.\d\d next [a-z0-9]+", r.shown[1]), r.shown
    assert re.fullmatch(r"handheld \d+ fps", r.shown[2]), r.shown
    assert np.array_equal(bus.frame(), render_text(r.shown))


def test_the_panel_waits_for_tofmatd_and_says_so(start: Callable[..., Daemon]) -> None:
    d = start("sim:static,material=acryl")
    d.client().close()
    bus = FakeSSD1306Bus()
    tries: list[float] = []

    def connect() -> tofmat.Client:
        tries.append(time.monotonic())
        if len(tries) < 3:  # the daemon not up yet
            return tofmat.Client("/nonexistent/tofmatd.sock", reconnect=False)
        return tofmat.Client(d.socket, reconnect=False)

    r = run_panel(connect, SSD1306(bus), seconds=0.5)
    assert r.connects == 0
    # The error's first words, cut to the panel's 21 columns.
    assert np.array_equal(bus.frame(), render_text(["tofmatd away", "cannot connect to to~", "", "", ""]))
    r = run_panel(connect, SSD1306(bus), seconds=4.0)
    assert r.connects == 1 and len(tries) == 3
    assert r.shown is not None and r.shown[3] == "camera streaming"
    assert tries[2] - tries[1] >= 0.9  # one try a second, not a busy loop


def test_tofmat_panel_needs_one_display_and_says_which() -> None:
    runner = CliRunner()
    r = runner.invoke(main, ["panel"])
    assert r.exit_code == 2 and "--bus N" in r.output
    r = runner.invoke(main, ["panel", "--bus", "1", "--png", "x.png"])
    assert r.exit_code == 2 and "needs --simulated" in r.output
    r = runner.invoke(main, ["panel", "--simulated", "--oled-address", "sixty"])
    assert r.exit_code == 2 and "--oled-address" in r.output
    # A bus that is not there: one line, not a traceback.
    r = runner.invoke(main, ["panel", "--bus", "97"])
    assert r.exit_code == 1 and "i2c-97" in r.output and "Traceback" not in r.output


def test_tofmat_panel_simulated_writes_its_picture(start: Callable[..., Daemon], tmp_path: Path) -> None:
    d = start("sim:static,material=acryl")
    d.client().close()
    png = tmp_path / "panel.png"
    r = CliRunner().invoke(
        main, ["panel", "--address", str(d.socket), "--simulated", "--seconds", "2", "--png", str(png)]
    )
    assert r.exit_code == 0, r.output
    assert "showing: acryl |" in r.output and png.stat().st_size > 100


def test_the_button_and_its_simulated_presses_refuse_what_cannot_work(tmp_path: Path, sim_table: Path) -> None:
    base = [str(daemon_binary()), "--table", str(sim_table), "--socket", str(tmp_path / "s"),
            "--sim-data", str(sim_data_dir())]  # fmt: skip
    cases = (
        (["--source", "sim:static,presses=30"], 1, "needs --gpio sim"),
        (["--source", "sim:static", "--reset-button", "sim:button"], 2, "need --gpio"),
        (["--source", "sim:static,presses=a"], 1, "presses"),
        # The board's backend where there is no GPIO: a clear failure naming the line.
        (["--source", "sim:static", "--gpio", "libgpiod", "--reset-button", "pinctrl-rp1:GPIO5"], 1, "pinctrl-rp1"),
    )
    for extra, code, says in cases:
        p = subprocess.run(base + extra, capture_output=True, text=True, timeout=60)
        assert p.returncode == code and says in p.stderr + p.stdout, (extra, p.returncode, p.stderr)


def test_the_panels_systemd_unit_starts_a_command_that_parses() -> None:
    import configparser
    import shlex

    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read(Path(__file__).parents[2] / "sdk" / "systemd" / "tofmat-panel.service")
    argv = shlex.split(unit["Service"]["ExecStart"])
    assert argv[0] == "/usr/local/bin/tofmat" and argv[1] == "panel"
    panel = main.get_command(None, "panel")  # type: ignore[arg-type]
    assert panel is not None
    ctx = panel.make_context("panel", argv[2:])  # raises on a flag the command does not have
    assert ctx.params["bus"] == "1" and ctx.params["address"] == "/run/tofmat/tofmatd.sock"
    assert "tofmatd.service" in unit["Unit"]["After"]
