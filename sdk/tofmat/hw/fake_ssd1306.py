# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A simulated SSD1306 128x64 OLED on its own I2C bus: parses the command stream and holds the memory.

Independent of the driver (its command table is its own): each write's control byte says whether
commands (0x00) or display data (0x40) follow; commands are decoded with their argument counts;
data lands at the write pointer, which runs along the column window and on to the next page of
the page window, wrapping within the window (horizontal addressing). :meth:`frame` is what the
panel shows. The model knows only the documented configuration of a 128x64 module and refuses
everything else loudly (:class:`~tofmat.hw.FakeChipError` in strict mode, and :attr:`errors`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .._extras import require
from ._fake import FakeI2CDevice, Op

_WIDTH, _PAGES = 128, 8

# opcode -> (name, number of argument bytes). Only commands whose meaning the chip facts give;
# 0x40..0x7F (display start line) are handled apart.
_COMMANDS: dict[int, tuple[str, int]] = {
    0xAE: ("display off", 0),
    0xAF: ("display on", 0),
    0xD5: ("clock divide / oscillator", 1),
    0xA8: ("multiplex ratio", 1),
    0xD3: ("display offset", 1),
    0x8D: ("charge pump", 1),
    0x20: ("addressing mode", 1),
    0xA1: ("segment remap", 0),
    0xC8: ("COM scan remapped", 0),
    0xDA: ("COM pins", 1),
    0x81: ("contrast", 1),
    0xD9: ("pre-charge period", 1),
    0xDB: ("VCOMH level", 1),
    0xA4: ("display follows memory", 0),
    0xA6: ("normal display", 0),
    0x21: ("column range", 2),
    0x22: ("page range", 2),
}

# Settings that change what the panel shows, and the only value of each the model knows. Any other
# value (another panel size, a scroll offset, another addressing mode) is refused, not guessed.
_REQUIRED = {
    "multiplex ratio": 0x3F,
    "display offset": 0x00,
    "start line": 0,
    "charge pump": 0x14,
    "addressing mode": 0x00,
    "COM pins": 0x12,
    "segment remap": 1,
    "COM scan remapped": 1,
}


@dataclass
class _State:
    settings: dict[str, int] = field(default_factory=dict)  # name -> last value
    display_on: bool = False
    column_window: tuple[int, int] | None = None
    page_window: tuple[int, int] | None = None
    column: int = 0
    page: int = 0


class FakeSSD1306Bus(FakeI2CDevice):
    """An :class:`~tofmat.hw.I2CBus` with one simulated SSD1306 128x64 at ``address`` (0x3C).

    The display memory powers up holding noise (``seed``), since nothing defines it, and the
    display off. Refused, each appended to :attr:`errors` (and raised as
    :class:`~tofmat.hw.FakeChipError` in ``strict`` mode): a control byte other than 0x00 / 0x40,
    an unknown command, a command whose arguments do not all come in the same write, a setting
    value the model does not know, display data before the addressing mode and the column and page
    windows are set, and any read (the model has nothing to read).
    """

    chip = "SSD1306"

    def __init__(self, address: int = 0x3C, *, clock: Callable[[], float] | None = None, strict: bool = True,
                 seed: int = 1306) -> None:  # fmt: skip
        super().__init__(address, clock=clock, strict=strict)
        self.memory: npt.NDArray[np.uint8] = np.random.default_rng(seed).integers(0, 256, (_PAGES, _WIDTH), np.uint8)
        self._s = _State()

    # --- what a test looks at -----------------------------------------------------------------

    @property
    def display_on(self) -> bool:
        """Whether the last display on/off command was on (off at power-up)."""
        return self._s.display_on

    @property
    def settings(self) -> dict[str, int]:
        """Every setting commanded so far, by name ("contrast", "addressing mode", ...), with its last value."""
        return dict(self._s.settings)

    @property
    def write_pointer(self) -> tuple[int, int]:
        """(page, column) where the next data byte lands."""
        return self._s.page, self._s.column

    def missing_configuration(self) -> list[str]:
        """The settings that decide what the panel shows and have not been commanded yet."""
        return [name for name in _REQUIRED if name not in self._s.settings]

    def memory_pixels(self) -> npt.NDArray[np.bool_]:
        """The display memory as (64, 128) pixels, row 0 = bit 0 of page 0, whatever the display shows."""
        bits = np.unpackbits(self.memory.reshape(_PAGES, 1, _WIDTH), axis=1, bitorder="little")
        return bits.reshape(_PAGES * 8, _WIDTH).astype(bool)

    def frame(self) -> npt.NDArray[np.bool_]:
        """What the panel shows now: (64, 128) bool, row 0 on top, column 0 on the left.

        All dark while the display is off or the charge pump is not on (the module has no other
        panel supply). Lit but not fully configured is a refused state (see :attr:`errors`).
        """
        dark = np.zeros((_PAGES * 8, _WIDTH), dtype=bool)
        if not self._s.display_on or self._s.settings.get("charge pump") != 0x14:
            return dark
        missing = self.missing_configuration()
        if missing:
            self._violation(f"display on without {', '.join(missing)}: what it shows is not modelled")
            return dark
        # The module's reference orientation is that of segment remap + COM scan remapped (required
        # above): memory column 0 on the left, page 0 bit 0 on the top row.
        return self.memory_pixels()

    def save_png(self, path: str | Path, *, scale: int = 4) -> Path:
        """Write :meth:`frame` as a PNG (lit pixels white on black), ``scale`` times enlarged; returns the path.

        Needs Pillow (``tofmat[hw]``).
        """
        require("PIL", extra="hw", feature="FakeSSD1306Bus.save_png")
        from PIL import Image

        if scale < 1:
            raise ValueError(f"scale must be >= 1, not {scale}")
        pixels = np.where(self.frame(), 255, 0).astype(np.uint8)
        image = Image.fromarray(pixels, mode="L")
        image = image.resize((_WIDTH * scale, _PAGES * 8 * scale), Image.Resampling.NEAREST)
        out = Path(path)
        image.save(out, format="PNG")
        return out

    # --- the chip -----------------------------------------------------------------------------

    def _read(self, op: Op, address: int, register: int, length: int) -> list[int]:
        self._violation(f"{op} at 0x{register:02X}: the model has nothing to read")
        return [0] * length

    def _write(self, op: Op, address: int, register: int, data: list[int]) -> None:
        if register == 0x00:
            self._commands(data)
        elif register == 0x40:
            self._data(data)
        else:
            self._violation(f"control byte 0x{register:02X}: only 0x00 (commands) and 0x40 (data) are modelled")

    def _commands(self, data: list[int]) -> None:
        i = 0
        while i < len(data):
            op = data[i]
            if 0x40 <= op <= 0x7F:
                self._set("start line", op - 0x40)
                i += 1
                continue
            if op not in _COMMANDS:
                self._violation(f"unknown command 0x{op:02X}")
                i += 1
                continue
            name, nargs = _COMMANDS[op]
            args = data[i + 1 : i + 1 + nargs]
            i += 1 + nargs
            if len(args) < nargs:
                # Whether the chip keeps a half-received command across writes is not in the facts.
                self._violation(f"command 0x{op:02X} ({name}) needs {nargs} argument bytes in the same write, "
                                f"got {len(args)}")  # fmt: skip
                return
            self._apply(op, name, args)

    def _set(self, name: str, value: int) -> None:
        known = _REQUIRED.get(name)
        if known is not None and value != known:
            self._violation(f"{name} 0x{value:02X} is not modelled (only 0x{known:02X})")
            return
        self._s.settings[name] = value

    def _apply(self, op: int, name: str, args: list[int]) -> None:
        s = self._s
        if op in (0xAE, 0xAF):
            s.display_on = op == 0xAF
        elif op == 0x21:
            first, last = args
            if not 0 <= first <= last < _WIDTH:
                self._violation(f"column range {first}..{last} is not within 0..{_WIDTH - 1} in order")
                return
            s.column_window, s.column = (first, last), first
        elif op == 0x22:
            first, last = args
            if not 0 <= first <= last < _PAGES:
                self._violation(f"page range {first}..{last} is not within 0..{_PAGES - 1} in order")
                return
            s.page_window, s.page = (first, last), first
        else:
            self._set(name, args[0] if args else 1)

    def _data(self, data: list[int]) -> None:
        s = self._s
        missing = [what for what, ok in (("addressing mode", "addressing mode" in s.settings),
                                         ("column range", s.column_window is not None),
                                         ("page range", s.page_window is not None)) if not ok]  # fmt: skip
        if missing:
            # The facts do not give the power-up addressing mode or windows: data then has no known home.
            self._violation(f"display data before init (no {', '.join(missing)} set yet): {len(data)} bytes dropped")
            return
        assert s.column_window is not None and s.page_window is not None
        for value in data:
            self.memory[s.page, s.column] = value
            s.column += 1
            if s.column > s.column_window[1]:
                s.column = s.column_window[0]
                s.page = s.page + 1 if s.page < s.page_window[1] else s.page_window[0]
