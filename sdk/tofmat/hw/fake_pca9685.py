# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""A simulated PCA9685 on its own I2C bus, modelled at register level, for tests and the simulated box.

It follows the chip's documented rules, independently of the driver (its register constants are
its own, so a wrong constant in the driver shows up as wrong behaviour here): power-up values,
PRE_SCALE writable only in sleep, auto-increment only with MODE1.AI, the oscillator stopped while
asleep, RESTART pending after a sleep and refused less than 500 us after waking, full on / full
off bits with full off winning. Where the chip's behaviour is not documented the model refuses
(a :class:`~tofmat.hw.FakeChipError` in strict mode) instead of guessing; each such place says so.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from ._fake import FakeI2CDevice, Op, Transaction

# The register map and bits, written down again here from the chip's facts (not imported from the driver).
_MODE1, _MODE2 = 0x00, 0x01
_LED_FIRST, _LED_LAST = 0x06, 0x45  # LED0_ON_L .. LED15_OFF_H
_ALL_LED_FIRST, _ALL_LED_LAST = 0xFA, 0xFD  # ALL_LED_ON_L .. ALL_LED_OFF_H
_PRE_SCALE = 0xFE
_RESTART, _EXTCLK, _AI, _SLEEP, _ALLCALL = 0x80, 0x40, 0x20, 0x10, 0x01
_INVRT = 0x10
_FULL = 0x10
_ALL_CALL_ADDRESS = 0x70
_OSCILLATOR_HZ = 25e6
_SETTLE_S = 500e-6
# Float time stamps (seconds since some epoch) lose nanoseconds; a wait of exactly 500 us must pass.
_TOLERANCE_S = 1e-9

# Runs of registers that auto-increment walks through. The facts at hand do not say where the
# register address goes after LED15_OFF_H (0x45) or ALL_LED_OFF_H (0xFD), nor cover 0x02..0x05 and
# 0x46..0xF9, so a transfer that reaches past a run is refused rather than wrapped by a guess.
_RUNS = ((_MODE1, _MODE2), (_LED_FIRST, _LED_LAST), (_ALL_LED_FIRST, _ALL_LED_LAST), (_PRE_SCALE, _PRE_SCALE))


def _run_of(register: int) -> tuple[int, int] | None:
    for first, last in _RUNS:
        if first <= register <= last:
            return first, last
    return None


@dataclass(frozen=True)
class PCA9685Transaction(Transaction):
    """A transfer on :class:`FakePCA9685Bus`, with every channel's output right after it."""

    pulses_us: tuple[float | None, ...]  #: :meth:`FakePCA9685Bus.pulse_us` of channels 0..15 after the transfer


@dataclass(frozen=True)
class IgnoredWrite:
    """A write the chip accepted on the bus but did not act on."""

    time: float
    register: int
    value: int
    reason: str


class FakePCA9685Bus(FakeI2CDevice):
    """An :class:`~tofmat.hw.I2CBus` with one simulated PCA9685 at ``address`` (0x40).

    ``clock`` is the time function (seconds; ``time.monotonic`` by default, a
    :class:`~tofmat.hw.ManualClock` in tests). In ``strict`` mode a broken rule raises
    :class:`~tofmat.hw.FakeChipError` at once; either way it is appended to :attr:`errors`.
    Writes the chip ignores (PRE_SCALE while awake) land in :attr:`ignored_writes`, and every
    transfer with the outputs after it in :attr:`history`. A transfer to another address raises
    ``OSError(ENXIO)``, as a real bus does when nobody acknowledges.

    What the model leaves out: the external clock (EXTCLK), inverted outputs (INVRT), the
    sub-addresses and software reset; using them is refused. Output changes take effect at the end
    of each transfer.
    """

    chip = "PCA9685"

    def __init__(self, address: int = 0x40, *, clock: Callable[[], float] | None = None,
                 strict: bool = True) -> None:  # fmt: skip
        super().__init__(address, clock=clock, strict=strict)
        self.registers = bytearray(256)
        # Power-up: asleep with All Call on, totem-pole outputs, every channel full off, ~200 Hz.
        self.registers[_MODE1] = _SLEEP | _ALLCALL
        self.registers[_MODE2] = 0x04
        for ch in range(16):
            self.registers[_LED_FIRST + 4 * ch + 3] = _FULL
        self.registers[_PRE_SCALE] = 0x1E
        self._restart_pending = False  # the RESTART bit as read: set by a sleep that stopped running outputs
        self._woke_at: float | None = None  # when SLEEP was last cleared; None while asleep
        self.ignored_writes: list[IgnoredWrite] = []

    # --- what a test looks at -----------------------------------------------------------------

    @property
    def asleep(self) -> bool:
        """MODE1.SLEEP: the oscillator is off and every output with it."""
        return bool(self.registers[_MODE1] & _SLEEP)

    @property
    def restart_pending(self) -> bool:
        """MODE1.RESTART as read: outputs stopped by a sleep wait for a RESTART (modelled as off meanwhile)."""
        return self._restart_pending

    @property
    def woke_at(self) -> float | None:
        """The clock's time when the oscillator was last started; None while asleep."""
        return self._woke_at

    def peek(self, register: int) -> int:
        """A register as a read would return it, without a bus transfer (MODE1 with its RESTART bit)."""
        if register == _MODE1:
            return self.registers[_MODE1] | (_RESTART if self._restart_pending else 0)
        return self.registers[register]

    @property
    def prescale(self) -> int:
        """The PRE_SCALE register."""
        return self.registers[_PRE_SCALE]

    def frequency_hz(self) -> float:
        """The PWM frequency the prescale gives with the internal 25 MHz oscillator."""
        return _OSCILLATOR_HZ / (4096 * (self.prescale + 1))

    def counts(self, channel: int) -> tuple[int, int, bool, bool]:
        """Channel ``channel``'s (ON count, OFF count, full on, full off) as the registers hold them."""
        if not 0 <= channel < 16:
            raise ValueError(f"channel must be 0..15, not {channel}")
        on_l, on_h, off_l, off_h = self.registers[_LED_FIRST + 4 * channel : _LED_FIRST + 4 * channel + 4]
        return on_l | (on_h & 0x0F) << 8, off_l | (off_h & 0x0F) << 8, bool(on_h & _FULL), bool(off_h & _FULL)

    def pulse_us(self, channel: int) -> float | None:
        """How long channel ``channel`` is high per period now, in microseconds.

        None when there is no pulse: the channel is full off, or the oscillator is stopped (asleep,
        or woken but not yet restarted). A full-on channel is high for the whole period.
        """
        on, off, full_on, full_off = self.counts(channel)
        if self.asleep or self._restart_pending or full_off:  # full off wins over full on
            return None
        period_us = 1e6 / self.frequency_hz()
        if full_on:
            return period_us
        # High from count ON to count OFF, across the period's end when OFF < ON. ON == OFF is not
        # documented in the facts at hand; modelled as no high time at all.
        return ((off - on) % 4096) * period_us / 4096

    def pulses_us(self) -> tuple[float | None, ...]:
        """:meth:`pulse_us` of channels 0..15."""
        return tuple(self.pulse_us(ch) for ch in range(16))

    def output_changes(self, channel: int) -> list[tuple[float, float | None]]:
        """(time, new pulse width) for each transfer after which ``channel``'s output differed from before,
        starting from the power-up output (full off)."""
        changes: list[tuple[float, float | None]] = []
        last: float | None = None
        for t in self.history:
            if isinstance(t, PCA9685Transaction) and t.pulses_us[channel] != last:
                last = t.pulses_us[channel]
                changes.append((t.time, last))
        return changes

    # --- the chip -----------------------------------------------------------------------------

    def _log(self, op: Op, address: int, register: int, data: Sequence[int], acked: bool) -> Transaction:
        t = PCA9685Transaction(self.clock(), op, address, register, tuple(data), acked, self.pulses_us())
        self.history.append(t)
        return t

    def _answers(self, address: int, op: Op) -> bool:
        # With ALLCALL set the chip also takes writes sent to the All Call address; reads there are
        # for no one chip to answer, and the model refuses them.
        if address == _ALL_CALL_ADDRESS and self.registers[_MODE1] & _ALLCALL:
            if op.startswith("read"):
                self._violation("read from the All Call address 0x70: every PCA9685 on the bus would answer")
            return True
        return address == self.address

    def _registers_of(self, start: int, count: int) -> list[int]:
        """The register each byte of a transfer of ``count`` bytes starting at ``start`` lands in."""
        if not self.registers[_MODE1] & _AI:
            return [start] * count  # without auto-increment every byte goes to the first register
        regs = [start + i for i in range(count)]
        run = _run_of(start)
        if run is not None and regs and regs[-1] > run[1]:
            self._violation(
                f"auto-increment from 0x{start:02X} over {count} bytes runs past 0x{run[1]:02X}; where the "
                f"register address goes next is not in the chip facts the model follows"
            )
            regs = [r for r in regs if r <= run[1]]
        return regs

    def _read(self, op: Op, address: int, register: int, length: int) -> list[int]:
        values = []
        for reg in self._registers_of(register, length):
            if _run_of(reg) is None:
                self._violation(f"read of register 0x{reg:02X}, which the model does not cover")
                values.append(0)
            elif _ALL_LED_FIRST <= reg <= _ALL_LED_LAST:
                self._violation(f"read of ALL_LED register 0x{reg:02X}: what it reads back is not modelled")
                values.append(0)
            else:
                values.append(self.peek(reg))
        return values

    def _write(self, op: Op, address: int, register: int, data: list[int]) -> None:
        for reg, value in zip(self._registers_of(register, len(data)), data, strict=True):
            self._write_register(reg, value)

    def _write_register(self, reg: int, value: int) -> None:
        if reg == _MODE1:
            self._write_mode1(value)
        elif reg == _MODE2:
            if value & _INVRT:
                self._violation("MODE2.INVRT (inverted outputs) is not modelled")
            self.registers[_MODE2] = value
        elif _LED_FIRST <= reg <= _LED_LAST:
            self.registers[reg] = value
        elif _ALL_LED_FIRST <= reg <= _ALL_LED_LAST:
            # An ALL_LED register stands for the same register of all 16 channels.
            for ch in range(16):
                self.registers[_LED_FIRST + 4 * ch + reg - _ALL_LED_FIRST] = value
        elif reg == _PRE_SCALE:
            if self.asleep:
                self.registers[_PRE_SCALE] = value
            else:
                self.ignored_writes.append(IgnoredWrite(self.clock(), reg, value, "PRE_SCALE written while awake"))
        else:
            self._violation(f"write of register 0x{reg:02X}, which the model does not cover")

    def _write_mode1(self, value: int) -> None:
        now = self.clock()
        was_asleep = self.asleep
        if value & _EXTCLK:
            self._violation("MODE1.EXTCLK (external clock) is not modelled")
            value &= ~_EXTCLK
        # Bit 7 is not stored: reading it shows whether a restart is pending; writing 1 is the restart.
        self.registers[_MODE1] = value & ~_RESTART
        if not was_asleep and self.asleep:
            self._woke_at = None
            self._restart_pending = True  # outputs stopped while running: they wait for a restart
        elif was_asleep and not self.asleep:
            self._woke_at = now
        if not value & _RESTART:
            return  # writing 0 to RESTART has no effect
        if self.asleep:
            self._violation("RESTART written while SLEEP = 1: the oscillator is off, nothing can restart")
            return
        assert self._woke_at is not None  # the chip powers up asleep, so being awake means it was woken
        since = now - self._woke_at
        if since < _SETTLE_S - _TOLERANCE_S:
            self._violation(
                f"RESTART written {since * 1e6:.1f} us after the oscillator was woken; it needs at least "
                f"{_SETTLE_S * 1e6:.0f} us (restart refused)"
            )
            return
        self._restart_pending = False
