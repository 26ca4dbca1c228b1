# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""What the simulated I2C chips share: a bus that answers at one address, its transaction log,
rule violations, and a clock tests can step by hand."""

from __future__ import annotations

import errno
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, NoReturn

from .bus import I2C_BLOCK_MAX

Op = Literal["read_byte", "write_byte", "read_block", "write_block"]


class FakeChipError(Exception):
    """A simulated chip saw something its rules forbid or its model does not cover.

    Raised by a fake bus in strict mode (the default) at the offending transfer, so a test fails
    where the driver broke the rule; the message is also appended to the fake's ``errors``.
    """


@dataclass(frozen=True)
class Transaction:
    """One transfer on a simulated bus, as logged in a fake's ``history``."""

    time: float  #: the fake's clock when the transfer ended (seconds)
    op: Op
    address: int  #: 7-bit address the transfer was sent to
    register: int  #: first byte after the address (register address or control byte)
    data: tuple[int, ...]  #: bytes written, or bytes read back
    acked: bool  #: False when no device answered at ``address`` (the transfer raised OSError)


class ManualClock:
    """A time function that only moves when told to: pass it as a fake's ``clock`` and its
    :meth:`sleep` as a driver's ``delay``, and waits take no real time yet are measured exactly."""

    def __init__(self, start_s: float = 0.0) -> None:
        # Integer nanoseconds, so 500 us waited reads back as exactly 500 us.
        self._ns = round(start_s * 1e9)
        self.slept: list[float] = []  #: every duration passed to :meth:`sleep` (seconds)

    def __call__(self) -> float:
        """The current time in seconds."""
        return self._ns / 1e9

    def advance(self, seconds: float) -> None:
        """Move the clock forward by ``seconds`` (>= 0)."""
        if seconds < 0:
            raise ValueError(f"a clock cannot go back ({seconds} s)")
        self._ns += round(seconds * 1e9)

    def sleep(self, seconds: float) -> None:
        """What ``time.sleep`` would do to this clock: advance it by ``seconds``."""
        self.slept.append(seconds)
        self.advance(seconds)


class FakeI2CDevice:
    """Base of the simulated chips: one device at ``address`` on its own bus.

    Implements the :class:`~tofmat.hw.I2CBus` methods: checks transfers as smbus2 and the kernel
    would (byte values, the 32-byte block limit, no ACK at another address), logs each in
    :attr:`history` and hands the rest to the subclass.
    """

    chip = "I2C device"

    def __init__(self, address: int, *, clock: Callable[[], float] | None = None, strict: bool = True) -> None:
        self.address = address
        self.clock: Callable[[], float] = clock if clock is not None else time.monotonic
        self.strict = strict
        self.history: list[Transaction] = []  #: every transfer, oldest first
        self.errors: list[str] = []  #: every rule the traffic broke, oldest first
        self.closed = False

    # --- for subclasses -----------------------------------------------------------------------

    def _violation(self, message: str) -> None:
        """Record a broken rule; raise :class:`FakeChipError` in strict mode."""
        self.errors.append(f"{self.clock():.6f} s: {message}")
        if self.strict:
            raise FakeChipError(f"{self.chip} at 0x{self.address:02X}: {message}")

    def _answers(self, address: int, op: Op) -> bool:
        """Whether this device acknowledges ``address`` for ``op`` (its own address; subclasses add more)."""
        return address == self.address

    def _log(self, op: Op, address: int, register: int, data: Sequence[int], acked: bool) -> Transaction:
        t = Transaction(self.clock(), op, address, register, tuple(data), acked)
        self.history.append(t)
        return t

    def _read(self, op: Op, address: int, register: int, length: int) -> list[int]:
        raise NotImplementedError

    def _write(self, op: Op, address: int, register: int, data: list[int]) -> None:
        raise NotImplementedError

    # --- the bus ------------------------------------------------------------------------------

    def _check(self, op: Op, address: int, register: int, data: Sequence[int] = ()) -> None:
        if self.closed:
            raise OSError(errno.EBADF, "the simulated I2C bus is closed")
        for name, v in (("address", address), ("register", register)):
            if not isinstance(v, int) or not 0 <= v <= (0x7F if name == "address" else 0xFF):
                raise ValueError(f"I2C {name} out of range: {v!r}")
        if len(data) > I2C_BLOCK_MAX:
            raise ValueError(f"Data length cannot exceed {I2C_BLOCK_MAX} bytes")  # smbus2's words
        for v in data:
            if not isinstance(v, int) or not 0 <= v <= 0xFF:
                raise ValueError(f"I2C data bytes must be 0..255, not {v!r}")
        if not self._answers(address, op):
            self._log(op, address, register, data, acked=False)
            self._nack(address)

    def _nack(self, address: int) -> NoReturn:
        raise OSError(
            errno.ENXIO,
            f"{os.strerror(errno.ENXIO)}: no device acknowledges 0x{address:02X} "
            f"(the simulated {self.chip} is at 0x{self.address:02X})",
        )

    def read_byte_data(self, addr: int, reg: int, /) -> int:
        """Read one byte from register ``reg`` of the device at ``addr``."""
        self._check("read_byte", addr, reg)
        value = self._read("read_byte", addr, reg, 1)
        self._log("read_byte", addr, reg, value, acked=True)
        return value[0]

    def write_byte_data(self, addr: int, reg: int, value: int, /) -> None:
        """Write ``value`` to register ``reg`` of the device at ``addr``."""
        self._check("write_byte", addr, reg, [value])
        self._write("write_byte", addr, reg, [value])
        self._log("write_byte", addr, reg, [value], acked=True)

    def read_i2c_block_data(self, addr: int, reg: int, length: int, /) -> list[int]:
        """Read ``length`` (at most 32) bytes starting at register ``reg``."""
        if length > I2C_BLOCK_MAX:
            raise ValueError(f"Desired block length over {I2C_BLOCK_MAX} bytes")  # smbus2's words
        if length < 0:
            raise ValueError(f"block length must be >= 0, not {length}")
        self._check("read_block", addr, reg)
        data = self._read("read_block", addr, reg, length)
        self._log("read_block", addr, reg, data, acked=True)
        return data

    def write_i2c_block_data(self, addr: int, reg: int, data: Sequence[int], /) -> None:
        """Write ``data`` (at most 32 bytes) starting at register ``reg``."""
        payload = list(data)
        self._check("write_block", addr, reg, payload)
        self._write("write_block", addr, reg, payload)
        self._log("write_block", addr, reg, payload, acked=True)

    def close(self) -> None:
        """Close the simulated bus: later transfers raise OSError (EBADF), as on a closed smbus2 bus."""
        self.closed = True
