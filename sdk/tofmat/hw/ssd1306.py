# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""SSD1306 128x64 monochrome OLED over I2C: the box's front panel, and text rendered for it.

::

    import contextlib
    from tofmat.hw import SSD1306, open_bus, render_text

    with contextlib.closing(open_bus(1)) as bus:
        panel = SSD1306(bus)                       # 0x3C (0x3D when the module's address pad is set)
        panel.init()
        panel.show(render_text(["cork 0.93", "tracking", "tofmatd ok"]))

Every I2C write to the panel starts with a control byte: 0x00 when commands follow, 0x40 when
display data follows. The display memory is 8 pages of 128 columns; each byte is a column of 8
pixels, least significant bit on top.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from typing import TYPE_CHECKING, SupportsIndex

import numpy as np
import numpy.typing as npt

from .._extras import require
from .bus import I2C_BLOCK_MAX, I2CBus, validate_address

if TYPE_CHECKING:  # Pillow is optional (tofmat[hw]): imported where it is used
    from PIL import ImageFont

CONTROL_COMMAND = 0x00
CONTROL_DATA = 0x40
DISPLAY_OFF, DISPLAY_ON = 0xAE, 0xAF
SET_CONTRAST = 0x81
COLUMN_RANGE = 0x21
PAGE_RANGE = 0x22

WIDTH, HEIGHT = 128, 64
PAGES = HEIGHT // 8

#: The configuration :meth:`SSD1306.init` sends, one command (with its arguments) per tuple, before
#: clearing the memory and switching the display on.
INIT_SEQUENCE: tuple[tuple[int, ...], ...] = (
    (DISPLAY_OFF,),
    (0xD5, 0x80),  # display clock divide ratio / oscillator frequency
    (0xA8, 0x3F),  # multiplex ratio: 64 rows
    (0xD3, 0x00),  # display offset 0
    (0x40,),  # display start line 0
    (0x8D, 0x14),  # charge pump on (the module makes its panel voltage from 3.3 V)
    (0x20, 0x00),  # horizontal addressing: the write pointer runs along a page, then to the next page
    (0xA1,),  # segment remap: column 0 on the left of the usual module
    (0xC8,),  # COM scan direction remapped: page 0 at the top
    (0xDA, 0x12),  # COM pins configuration for 64 rows
    (SET_CONTRAST, 0xCF),
    (0xD9, 0xF1),  # pre-charge period
    (0xDB, 0x40),  # VCOMH deselect level
    (0xA4,),  # display follows the memory
    (0xA6,),  # normal (not inverted)
)


class SSD1306:
    """An SSD1306 128x64 OLED on ``bus`` at ``address`` (0x3C, or 0x3D).

    Call :meth:`init` once before :meth:`show`. The object does not own ``bus``.
    Raises ValueError for a reserved or out-of-range address, or another size than 128x64 (the
    only panel the init sequence here configures).
    """

    def __init__(self, bus: I2CBus, address: int = 0x3C, width: int = WIDTH, height: int = HEIGHT) -> None:
        validate_address(address, what="SSD1306")
        if (width, height) != (WIDTH, HEIGHT):
            raise ValueError(f"only {WIDTH}x{HEIGHT} SSD1306 panels are supported, not {width}x{height}")
        self._bus = bus
        self._address = address
        self.width, self.height = width, height
        self._initialised = False

    @property
    def address(self) -> int:
        """The panel's 7-bit I2C address."""
        return self._address

    def _commands(self, *commands: Sequence[int]) -> None:
        """Send ``commands`` (each an opcode with its arguments) in as few writes as the block limit
        allows, never splitting one command's bytes over two writes."""
        batch: list[int] = []
        for command in commands:
            if len(batch) + len(command) > I2C_BLOCK_MAX:
                self._bus.write_i2c_block_data(self._address, CONTROL_COMMAND, batch)
                batch = []
            batch.extend(command)
        if batch:
            self._bus.write_i2c_block_data(self._address, CONTROL_COMMAND, batch)

    def init(self) -> None:
        """Configure the panel (display off first), clear its memory and switch the display on."""
        self._commands(*INIT_SEQUENCE)
        self._initialised = True
        # The memory holds whatever it powered up with: clear it while the display is still off.
        self.show(np.zeros((self.height, self.width), dtype=bool))
        self._commands((DISPLAY_ON,))

    def show(self, image: npt.NDArray[np.bool_] | npt.NDArray[np.uint8]) -> None:
        """Display ``image``: a (64, 128) array of bool or uint8, nonzero = pixel lit, row 0 on top.

        Sends the whole frame: column range 0..127, page range 0..7, then 1024 data bytes in writes
        of at most 32. Raises ValueError for another shape or dtype, RuntimeError before :meth:`init`.
        """
        if not self._initialised:
            raise RuntimeError("SSD1306.show() before init(): call init() once after power-up")
        frame = np.asarray(image)
        if frame.shape != (self.height, self.width):
            raise ValueError(f"image must be {self.height} rows x {self.width} columns, not {frame.shape}")
        if frame.dtype != np.bool_ and frame.dtype != np.uint8:
            raise ValueError(f"image must be a bool or uint8 array (nonzero = lit), not {frame.dtype}")
        self._commands((COLUMN_RANGE, 0, self.width - 1), (PAGE_RANGE, 0, self.height // 8 - 1))
        data = pack_pages(frame != 0).reshape(-1).tolist()
        for i in range(0, len(data), I2C_BLOCK_MAX):
            self._bus.write_i2c_block_data(self._address, CONTROL_DATA, data[i : i + I2C_BLOCK_MAX])

    def clear(self) -> None:
        """Switch every pixel off."""
        self.show(np.zeros((self.height, self.width), dtype=bool))

    def contrast(self, value: SupportsIndex) -> None:
        """Set the contrast (brightness), 0..255. Raises ValueError outside that range."""
        if isinstance(value, bool):
            raise TypeError("contrast must be an integer 0..255, not bool")
        v = operator.index(value)
        if not 0 <= v <= 255:
            raise ValueError(f"contrast must be 0..255, not {v}")
        self._commands((SET_CONTRAST, v))

    def power(self, on: bool) -> None:
        """Switch the display on or off (off keeps the memory: on again shows the same frame)."""
        self._commands((DISPLAY_ON if on else DISPLAY_OFF,))


def pack_pages(pixels: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint8]:
    """(8 n, w) pixels -> (n, w) display-memory bytes: bit k of byte [p, c] is pixel [8 p + k, c]."""
    rows, cols = pixels.shape
    if rows % 8:
        raise ValueError(f"the number of rows must be a multiple of 8, not {rows}")
    pages = pixels.reshape(rows // 8, 8, cols)
    return np.packbits(pages, axis=1, bitorder="little").reshape(rows // 8, cols)


def unpack_pages(memory: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    """(n, w) display-memory bytes -> (8 n, w) pixels (the inverse of :func:`pack_pages`)."""
    pages, cols = memory.shape
    bits = np.unpackbits(memory.reshape(pages, 1, cols), axis=1, bitorder="little")
    return bits.reshape(pages * 8, cols).astype(bool)


# Ascenders, descenders and brackets: the rows any line of text may use.
_TALL_TEXT = "|()[]{}bdfhklgjpqy_0123456789"


def render_text(lines: Sequence[str], *, width: int = WIDTH, height: int = HEIGHT) -> npt.NDArray[np.bool_]:
    """Draw ``lines`` of text, one under the other from the top left, into a (height, width) bool frame.

    Uses Pillow's built-in default font: 5 lines of about 20 characters on 128x64. Line ``i`` lies
    within rows ``i * text_line_height()`` to ``(i + 1) * text_line_height() - 2`` (the last row of
    each line is left blank); what runs past the right edge is cut off. Raises ValueError when the
    lines do not fit the height or a line contains a line break, and
    :class:`~tofmat.MissingExtraError` without Pillow (``tofmat[hw]``).
    """
    require("PIL", extra="hw", feature="tofmat.hw.render_text")
    from PIL import Image, ImageDraw, ImageFont

    if isinstance(lines, str):
        raise TypeError("lines must be a sequence of strings (one per line), not a single string")
    for line in lines:
        if "\n" in line or "\r" in line:
            raise ValueError(f"a line may not contain a line break: {line!r} (pass the lines separately)")
    font = ImageFont.load_default()
    step, top = _line_metrics(font)
    if len(lines) * step > height:
        raise ValueError(f"{len(lines)} lines of {step} px do not fit {height} rows (at most {height // step})")
    image = Image.new("1", (width, height), 0)
    draw = ImageDraw.Draw(image)
    for i, line in enumerate(lines):
        # Shifted up by the font's empty top rows so that a line starts on its band's first row.
        draw.text((0, i * step - top), line, fill=1, font=font)
    return np.array(image, dtype=bool)


def text_line_height() -> int:
    """Rows per line of :func:`render_text` (12 with Pillow's default font): line ``i`` starts at row
    ``i * text_line_height()``. Needs Pillow (``tofmat[hw]``)."""
    require("PIL", extra="hw", feature="tofmat.hw.text_line_height")
    from PIL import ImageFont

    return _line_metrics(ImageFont.load_default())[0]


def _line_metrics(font: ImageFont.ImageFont | ImageFont.FreeTypeFont) -> tuple[int, int]:
    """(rows per line including one blank row, empty rows above the tallest glyphs) of ``font``."""
    _left, top, _right, bottom = font.getbbox(_TALL_TEXT)
    return int(bottom - top) + 1, int(top)
