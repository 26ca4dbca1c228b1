# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""What the front panel shows: five lines of text, from tofmatd's events and status.

The lines, top to bottom::

    copper                  the label (or "no target", "unknown", or why there is none)
    p 0.93 next wood        its confidence (the session matcher) and the runner-up; with Eq. (12):
                            "d 4.1 next x3.2", its distance, mm^2, and the runner-up's over it
    handheld 30 fps         the profile and the frame rate (from status)
    camera streaming        the camera's state (device events), or the daemon being away
    reset by button         for a few seconds after the accumulation was reset; "simulated"
                            when the frames are the simulator's

"next x3.2" is the panel's confidence: how much further the second-best material is than the best
(x1.0: a tie; large: no doubt). A distance is a property of the match, not a probability, so the
panel does not dress it up as a percentage.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..client import DeviceEvent, Event, Label, ResetEvent

COLUMNS = 21  # characters of Pillow's default font on 128 columns
RESET_SHOWN_NS = 3_000_000_000  # how long "reset by ..." stays up
STALE_LABEL_NS = 2_000_000_000  # a label older than this (and no newer event) is shown as stale


def _fit(text: str) -> str:
    return text if len(text) <= COLUMNS else text[: COLUMNS - 1] + "~"


@dataclass
class PanelView:
    connected: bool = False
    away_reason: str = "starting"
    profile: str = ""
    fps: float = 0.0
    simulated: bool = False
    device: str = ""
    label: Label | None = None
    label_ns: int = 0
    reset_by: str | None = None
    reset_ns: int = 0
    resets: int = 0
    seen: dict[str, int] = field(default_factory=dict)  # events taken, by kind

    # --- what happened -------------------------------------------------------------------
    def daemon_status(self, status: Mapping[str, Any]) -> None:
        self.connected = True
        self.profile = str(status.get("profile", ""))
        self.fps = float(status.get("fps", 0.0) or 0.0)
        self.simulated = bool(status.get("simulated", False))
        device = status.get("device")
        if isinstance(device, dict) and "state" in device:
            self.device = str(device["state"])

    def daemon_away(self, reason: str) -> None:
        self.connected = False
        self.away_reason = reason
        self.label = None

    def event(self, e: Event, now_ns: int) -> None:
        kind = type(e).__name__
        self.seen[kind] = self.seen.get(kind, 0) + 1
        if isinstance(e, Label):
            self.label, self.label_ns = e, now_ns
        elif isinstance(e, DeviceEvent):
            self.device = e.state
            if e.state != "streaming":
                self.label = None
        elif isinstance(e, ResetEvent):
            self.reset_by, self.reset_ns, self.resets = e.by, now_ns, self.resets + 1
            self.label = None  # the accumulation is empty: the last label no longer holds

    # --- what is shown -------------------------------------------------------------------
    def lines(self, now_ns: int) -> list[str]:
        if not self.connected:
            return [_fit("tofmatd away"), _fit(self.away_reason), "", "", ""]
        top, detail = self._label_lines(now_ns)
        rate = f"{self.profile} {self.fps:.0f} fps" if self.profile else ""
        camera = f"camera {self.device}" if self.device else ""
        if self.reset_by is not None and now_ns - self.reset_ns < RESET_SHOWN_NS:
            note = f"reset by {self.reset_by}"
        else:
            note = "simulated" if self.simulated else ""
        return [_fit(s) for s in (top, detail, rate, camera, note)]

    def _label_lines(self, now_ns: int) -> tuple[str, str]:
        e = self.label
        if e is None:
            return ("waiting" if self.device == "streaming" else "no camera"), ""
        if e.state == "unknown":  # no material explains it: the nearest, for the eye
            top, detail = "unknown", (f"near {e.ranking[0].material}" if e.ranking else "")
        elif e.state == "no_target" or not e.material:
            return "no target", ""
        elif e.fit is not None and e.confidence is not None:  # the session matcher: its probability
            top, detail = e.material, f"p {e.confidence:.2f}"
            if len(e.ranking) > 1:
                detail += f" next {e.ranking[1].material}"
        else:  # Eq. (12): the distance and how much further the runner-up is
            top, detail = e.material, f"d {e.distance:.1f}"
            if len(e.ranking) > 1 and e.distance > 0:
                detail += f" next x{e.ranking[1].distance / e.distance:.1f}"
            elif len(e.ranking) > 1:
                detail += " next x>99"
        if now_ns - self.label_ns > STALE_LABEL_NS and e.state != "final":
            detail += " old"
        return top, detail
