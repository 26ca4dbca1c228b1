# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""The I2C bus the drivers talk to: the few smbus2 methods they use, and opening a real bus.

Every driver in :mod:`tofmat.hw` takes an :class:`I2CBus`. A real one is ``smbus2.SMBus``
(:func:`open_bus`); the simulated chips (:class:`~tofmat.hw.FakePCA9685Bus`,
:class:`~tofmat.hw.FakeSSD1306Bus`) are others, so the same driver code runs on the box and in tests.
"""

from __future__ import annotations

import errno
import os
from typing import Protocol

from .._extras import require

#: Most data bytes one SMBus block transfer carries (the Linux i2c-dev limit smbus2 enforces).
I2C_BLOCK_MAX = 32


class I2CBus(Protocol):
    """What the drivers need from an I2C bus: the register-oriented transfers of ``smbus2.SMBus``.

    ``addr`` is a 7-bit device address; ``reg`` the first byte written after it (a register
    address, or for the SSD1306 its control byte). Block transfers carry at most
    :data:`I2C_BLOCK_MAX` bytes. A device that does not answer raises :class:`OSError`.
    """

    # Positional-only, so smbus2's own parameter names (i2c_addr, register) match as well as ours.
    def read_byte_data(self, addr: int, reg: int, /) -> int: ...

    def write_byte_data(self, addr: int, reg: int, value: int, /) -> None: ...

    def read_i2c_block_data(self, addr: int, reg: int, length: int, /) -> list[int]: ...

    def write_i2c_block_data(self, addr: int, reg: int, data: list[int], /) -> None: ...

    def close(self) -> None: ...


def bus_path(bus: int | str) -> str:
    """The device node of ``bus``: ``/dev/i2c-<bus>`` for a number, the path itself otherwise."""
    return f"/dev/i2c-{bus}" if isinstance(bus, int) else bus


def open_bus(bus: int | str) -> I2CBus:
    """Open the I2C bus ``bus`` (a number N for ``/dev/i2c-N``, or a device path) through smbus2.

    Close it when done, e.g. ``with contextlib.closing(open_bus(1)) as bus: ...``.
    Raises :class:`~tofmat.MissingExtraError` when smbus2 is not installed (``tofmat[hw]``),
    :class:`FileNotFoundError` when the device node does not exist (no such bus on this machine),
    :class:`PermissionError` when this user may not open it, :class:`ValueError` for a negative bus
    number.
    """
    if isinstance(bus, bool) or not isinstance(bus, (int, str)):
        raise TypeError(f"bus must be a bus number or a device path, not {type(bus).__name__}")
    if isinstance(bus, int) and bus < 0:
        raise ValueError(f"I2C bus number must be >= 0, not {bus}")
    require("smbus2", extra="hw", feature="tofmat.hw.open_bus (a real I2C bus)")
    from smbus2 import SMBus

    path = bus_path(bus)
    what = f"no I2C bus {bus} on this machine" if isinstance(bus, int) else "no such I2C bus on this machine"
    try:
        return SMBus(bus)
    except FileNotFoundError as e:
        raise FileNotFoundError(
            errno.ENOENT,
            f"{path} does not exist: {what} (enable I2C and the i2c-dev module, "
            f"or use the simulated bus: tofmat.hw.FakePCA9685Bus, tofmat.hw.FakeSSD1306Bus)",
            path,
        ) from e
    except PermissionError as e:
        user = os.environ.get("USER") or "this user"
        raise PermissionError(
            errno.EACCES,
            f"{path}: permission denied for {user} (it needs read and write access to the device node: "
            f"on Raspberry Pi OS, membership of the i2c group, then log in again)",
            path,
        ) from e


def validate_address(address: int, *, what: str) -> int:
    """``address`` if it is a usable 7-bit I2C device address; raises ValueError otherwise.

    The I2C specification reserves 0x00..0x07 (general call, START byte, CBUS, other bus formats,
    high-speed master codes) and 0x78..0x7F (10-bit addressing, device ID): no device may sit there.
    """
    if isinstance(address, bool) or not isinstance(address, int):
        raise ValueError(f"{what} address must be an int, not {type(address).__name__}")
    if not 0x00 <= address <= 0x7F:
        raise ValueError(f"{what} address 0x{address:X} is not a 7-bit I2C address (0x00..0x7F)")
    if address <= 0x07 or address >= 0x78:
        raise ValueError(
            f"{what} address 0x{address:02X} is reserved by the I2C specification "
            f"(0x00..0x07 and 0x78..0x7F); devices use 0x08..0x77"
        )
    return address
