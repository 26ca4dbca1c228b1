# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The box's I2C peripherals: the sorting gates' PWM chip and the front panel, and simulated twins.

- :class:`PCA9685` (16-channel 12-bit PWM) and :class:`Servo` (a calibrated servo on one channel)
- :class:`SSD1306` (128x64 OLED) and :func:`render_text` (status lines drawn for it)
- :func:`open_bus`: a real bus (``/dev/i2c-N``) through smbus2; :class:`I2CBus`: what the drivers need
- :class:`FakePCA9685Bus`, :class:`FakeSSD1306Bus`: simulated chips on a bus of their own, modelled at
  register level, which enforce the chips' rules (a broken one raises :class:`FakeChipError`);
  :class:`ManualClock` lets tests measure the drivers' waits without waiting

A real bus needs ``pip install 'tofmat[hw]'`` (smbus2), and so do :func:`render_text` and
:meth:`FakeSSD1306Bus.save_png` (Pillow); the drivers and the simulated chips need only numpy::

    from tofmat.hw import FakePCA9685Bus, PCA9685, Servo

    bus = FakePCA9685Bus()
    pca = PCA9685(bus)
    pca.set_frequency(50)
    Servo(pca, 0).move_to(90)
    bus.pulse_us(0)     # 1498.16: the pulse the chip outputs on channel 0 (307 counts at 50.03 Hz)
"""

from __future__ import annotations

from ._fake import FakeChipError, ManualClock, Transaction
from .bus import I2C_BLOCK_MAX, I2CBus, open_bus
from .fake_pca9685 import FakePCA9685Bus, IgnoredWrite, PCA9685Transaction
from .fake_ssd1306 import FakeSSD1306Bus
from .pca9685 import PCA9685, Servo
from .ssd1306 import SSD1306, render_text, text_line_height

__all__ = [
    "I2C_BLOCK_MAX",
    "PCA9685",
    "SSD1306",
    "FakeChipError",
    "FakePCA9685Bus",
    "FakeSSD1306Bus",
    "I2CBus",
    "IgnoredWrite",
    "ManualClock",
    "PCA9685Transaction",
    "Servo",
    "Transaction",
    "open_bus",
    "render_text",
    "text_line_height",
]
