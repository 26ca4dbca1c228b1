# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""`tofmat panel`: the standalone box's front panel, an SSD1306 OLED showing tofmatd's label.

It follows tofmatd's ``labels``, ``device`` and ``reset`` streams and its status (the profile and
frame rate, every ``status_every`` seconds) into a :class:`tofmat.panel.PanelView`, and draws the
view whenever its text changes, at most ``max_fps`` times a second (a full frame is 1 KiB on the
I2C bus). When tofmatd is not there (the box is booting, the daemon restarts) the panel says so and
tries again every second: it never exits on its own for that.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from ..client import Client, ClientError
from ..hw import SSD1306, render_text
from ..panel import PanelView


@dataclass
class PanelResult:
    draws: int = 0
    connects: int = 0
    view: PanelView | None = None
    shown: list[str] | None = None  # the lines on the panel at the end
    drawn: deque[list[str]] = field(default_factory=lambda: deque(maxlen=64))  # the last pictures' lines


def run_panel(
    connect: Callable[[], Client],
    display: SSD1306,
    seconds: float | None = None,
    *,
    status_every: float = 2.0,
    max_fps: float = 10.0,
    echo: Callable[[str], None] | None = None,
    until: Callable[[list[str], PanelView], bool] | None = None,
) -> PanelResult:
    """Runs the panel for ``seconds`` (None: until interrupted), or until ``until`` holds for the lines
    just drawn and the view (a script's or a test's end, which then waits on what the panel shows
    rather than on how fast the machine runs); the display is left showing the last lines and blanked
    only by its owner."""
    say = echo or (lambda _line: None)
    view, result = PanelView(), PanelResult()
    result.view = view
    display.init()
    end = None if seconds is None else time.monotonic() + seconds
    client: Client | None = None
    next_status = 0.0
    last_draw = 0.0
    try:
        while end is None or time.monotonic() < end:
            if client is None:
                try:
                    client = connect()
                    client.subscribe("labels", "device", "reset")
                    view.daemon_status(client.status())
                    next_status = time.monotonic() + status_every
                    result.connects += 1
                    say(f"panel: following tofmatd at {client.address}")
                except (ClientError, OSError) as e:
                    if client is not None:
                        client.close()
                    client = None
                    view.daemon_away(str(e).split(":")[0] or type(e).__name__)
            if client is not None:
                try:
                    event = client.next_event(0.1)
                    if event is not None:
                        view.event(event, time.monotonic_ns())
                    if time.monotonic() >= next_status:
                        view.daemon_status(client.status())
                        next_status = time.monotonic() + status_every
                except ClientError as e:
                    say(f"panel: lost tofmatd ({e})")
                    client.close()
                    client = None
                    view.daemon_away("connection lost")
            lines = view.lines(time.monotonic_ns())
            now = time.monotonic()
            if lines != result.shown and now - last_draw >= 1.0 / max_fps:
                display.show(render_text(lines))
                result.shown, result.draws, last_draw = lines, result.draws + 1, now
                result.drawn.append(lines)
                if until is not None and until(lines, view):
                    break
            if client is None:
                time.sleep(min(1.0, max(0.0, end - time.monotonic())) if end is not None else 1.0)
    finally:
        if client is not None:
            client.close()
    return result
