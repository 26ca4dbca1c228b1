# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmat.hw.SSD1306 and render_text against the simulated panel (FakeSSD1306Bus).

The fake decodes the command stream and keeps the display memory as the chip would (its command
table is its own): what is checked is the picture the panel ends up showing, pixel for pixel.
"""

from __future__ import annotations

import errno
from pathlib import Path

import numpy as np
import pytest

from tofmat.hw import SSD1306, FakeChipError, FakeSSD1306Bus, render_text, text_line_height

ADDR = 0x3C
H, W = 64, 128


@pytest.fixture
def bus() -> FakeSSD1306Bus:
    return FakeSSD1306Bus()


@pytest.fixture
def panel(bus: FakeSSD1306Bus) -> SSD1306:
    p = SSD1306(bus)
    p.init()
    return p


def lit_rows(image: np.ndarray) -> set[int]:
    return set(np.flatnonzero(image.any(axis=1)).tolist())


# --- the simulated panel on its own ----------------------------------------------------------


def test_fake_powers_up_dark_with_noise_in_its_memory(bus: FakeSSD1306Bus) -> None:
    assert not bus.display_on and not bus.frame().any()
    assert bus.memory_pixels().mean() == pytest.approx(0.5, abs=0.05)  # undefined contents, not zeros
    assert bus.missing_configuration()  # nothing set yet


def test_fake_refuses_data_before_init(bus: FakeSSD1306Bus) -> None:
    before = bus.memory.copy()
    with pytest.raises(FakeChipError, match="display data before init"):
        bus.write_i2c_block_data(ADDR, 0x40, [0xFF] * 4)
    assert np.array_equal(bus.memory, before) and len(bus.errors) == 1


def test_fake_refuses_what_it_does_not_know() -> None:
    bus = FakeSSD1306Bus(strict=False)
    bus.write_byte_data(ADDR, 0x00, 0xB0)  # a page-addressing command: not in the model
    bus.write_i2c_block_data(ADDR, 0x00, [0xAF, 0x81])  # contrast without its argument in this write
    bus.write_i2c_block_data(ADDR, 0x80, [0xAF])  # control byte with Co set
    bus.write_i2c_block_data(ADDR, 0x00, [0xA8, 0x1F])  # a 32-row multiplex: another panel
    bus.write_i2c_block_data(ADDR, 0x00, [0x21, 100, 20])  # column range backwards
    assert bus.read_byte_data(ADDR, 0x00) == 0  # nothing to read
    assert [e.split(": ", 1)[1] for e in bus.errors] == [
        "unknown command 0xB0",
        "command 0x81 (contrast) needs 1 argument bytes in the same write, got 0",
        "control byte 0x80: only 0x00 (commands) and 0x40 (data) are modelled",
        "multiplex ratio 0x1F is not modelled (only 0x3F)",
        "column range 100..20 is not within 0..127 in order",
        "read_byte at 0x00: the model has nothing to read",
    ]
    assert bus.display_on and "multiplex ratio" not in bus.settings  # the known command before it still took
    with pytest.raises(ValueError, match="32 bytes"):
        bus.write_i2c_block_data(ADDR, 0x40, [0] * 33)  # smbus2's limit
    with pytest.raises(OSError) as e:
        bus.write_byte_data(0x3D, 0x00, 0xAF)
    assert e.value.errno == errno.ENXIO


def test_fake_write_pointer_wraps_within_its_window(bus: FakeSSD1306Bus) -> None:
    bus.write_i2c_block_data(ADDR, 0x00, [0x20, 0x00, 0x21, 10, 12, 0x22, 2, 3])
    assert bus.write_pointer == (2, 10)
    bus.write_i2c_block_data(ADDR, 0x40, [1, 2, 3, 4, 5, 6, 7, 8])
    m = bus.memory
    assert m[2, 10:13].tolist() == [7, 8, 3] and m[3, 10:13].tolist() == [4, 5, 6]
    assert bus.write_pointer == (2, 12)


# --- the driver against the panel ------------------------------------------------------------


def test_init_configures_clears_and_switches_on(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    assert bus.errors == [] and bus.missing_configuration() == []
    assert bus.display_on and bus.settings["contrast"] == 0xCF and bus.settings["charge pump"] == 0x14
    assert not bus.memory.any()  # the power-up noise is gone
    assert not bus.frame().any()
    last = bus.history[-1]
    assert (last.register, last.data) == (0x00, (0xAF,))  # on only after the memory was cleared
    assert all(len(t.data) <= 32 for t in bus.history)


def test_show_a_pattern_pixel_for_pixel(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    rows, cols = np.indices((H, W))
    checker = (rows // 8 + cols // 8) % 2 == 0
    panel.show(checker)
    assert np.array_equal(bus.frame(), checker)
    assert bus.memory[0, 0] == 0xFF and bus.memory[0, 8] == 0x00  # one byte = 8 rows of one column


def test_show_patterns_that_cross_byte_boundaries(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    image = np.zeros((H, W), dtype=np.uint8)
    image[13, :] = 1  # a line inside page 1 (bit 5)
    image[5:20, 3:51] |= 1  # a box across pages 0..2
    image[0, 0] = image[63, 127] = image[31, 64] = 255  # corners and a pixel at the bottom of page 3
    panel.show(image)
    assert np.array_equal(bus.frame(), image != 0)
    assert bus.memory[1, 100] == 1 << 5  # row 13 = page 1, bit 5 (least significant bit on top)
    assert bus.memory[7, 127] == 0x80 and bus.memory[0, 0] == 0x01 and bus.memory[3, 64] == 0x80


def test_a_full_frame_goes_in_32_byte_writes(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    image = np.random.default_rng(7).random((H, W)) < 0.5
    start = len(bus.history)
    panel.show(image)
    sent = bus.history[start:]
    assert (sent[0].register, sent[0].data) == (0x00, (0x21, 0, 127, 0x22, 0, 7))
    data = [t for t in sent if t.register == 0x40]
    assert len(data) == len(sent) - 1 == 32 and all(len(t.data) == 32 for t in data)
    assert sum(len(t.data) for t in data) == 1024
    assert np.array_equal(bus.frame(), image)
    panel.show(~image)  # and again over it
    assert np.array_equal(bus.frame(), ~image)


def test_display_off_shows_nothing(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    image = np.ones((H, W), dtype=bool)
    panel.show(image)
    panel.power(False)
    assert not bus.frame().any() and bus.memory.all()  # dark, but the memory is kept
    panel.power(True)
    assert np.array_equal(bus.frame(), image)


def test_contrast(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    panel.contrast(0x20)
    assert bus.settings["contrast"] == 0x20
    for bad in (-1, 256):
        with pytest.raises(ValueError, match=r"0\.\.255"):
            panel.contrast(bad)


def test_driver_refuses_bad_input(bus: FakeSSD1306Bus) -> None:
    panel = SSD1306(bus)
    with pytest.raises(RuntimeError, match="init"):
        panel.show(np.zeros((H, W), dtype=bool))
    assert bus.history == []
    panel.init()
    for bad in (np.zeros((W, H), dtype=bool), np.zeros((H, W), dtype=np.float32), np.zeros((H, W, 3), np.uint8)):
        with pytest.raises(ValueError):
            panel.show(bad)
    with pytest.raises(ValueError, match="128x64"):
        SSD1306(bus, height=32)
    with pytest.raises(ValueError, match="reserved"):
        SSD1306(bus, address=0x7C)


def test_text_lands_in_its_rows(panel: SSD1306, bus: FakeSSD1306Bus) -> None:
    step = text_line_height()
    lines = ["cork 0.93", "tracking", "tofmatd ok"]
    image = render_text(lines)
    assert image.shape == (H, W) and image.dtype == np.bool_
    for i, line in enumerate(lines):
        band = set(range(i * step, (i + 1) * step - 1))  # the last row of each line stays blank
        alone = render_text([""] * i + [line])
        assert lit_rows(alone) and lit_rows(alone) <= band, line
        assert np.array_equal(image[i * step : (i + 1) * step], alone[i * step : (i + 1) * step])
    assert not image[len(lines) * step :].any()  # nothing below the last line
    # The same line one line lower is the same pixels one line-height lower.
    assert np.array_equal(render_text(["", "tracking"])[step:], render_text(["tracking"])[: H - step])
    panel.show(image)
    assert np.array_equal(bus.frame(), image)
    assert H // step >= 5
    with pytest.raises(ValueError, match="do not fit"):
        render_text(["x"] * (H // step + 1))
    with pytest.raises(ValueError, match="line break"):
        render_text(["two\nlines"])


def test_png_of_the_panel(panel: SSD1306, bus: FakeSSD1306Bus, tmp_path: Path) -> None:
    from PIL import Image

    panel.show(render_text(["cork 0.93", "tracking", "tofmatd ok"]))
    path = bus.save_png(tmp_path / "panel.png", scale=4)
    with Image.open(path) as png:
        assert png.format == "PNG" and png.size == (4 * W, 4 * H)
        pixels = np.array(png.convert("L"))
    assert np.array_equal(pixels[::4, ::4] == 255, bus.frame())
    assert np.array_equal(pixels[3::4, 3::4] == 255, bus.frame())
    assert set(np.unique(pixels).tolist()) == {0, 255}
