# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""PCA9685 16-channel 12-bit PWM driver over I2C, and a calibrated servo on one of its channels.

The sorting line's gates are hobby servos on a PCA9685 (hardware PWM: no software-timing jitter)::

    import contextlib
    from tofmat.hw import PCA9685, Servo, open_bus

    with contextlib.closing(open_bus(1)) as bus:
        pca = PCA9685(bus)            # wakes the chip, totem-pole outputs, register auto-increment
        pca.set_frequency(50)         # servos: 50 Hz (actually 50.03 Hz, prescale 121)
        gate = Servo(pca, 0, min_us=900, max_us=2100)
        gate.move_to(90)
        gate.release()                # output constantly low: the servo goes limp
"""

from __future__ import annotations

import errno
import logging
import math
import operator
import time
from collections.abc import Callable
from typing import SupportsIndex

from .bus import I2CBus, validate_address

log = logging.getLogger("tofmat.hw")

# Registers and bits (PCA9685 register map).
MODE1 = 0x00
MODE2 = 0x01
LED0_ON_L = 0x06  # LEDn_ON_L, ON_H, OFF_L, OFF_H at LED0_ON_L + 4 n
PRE_SCALE = 0xFE
RESTART = 0x80
EXTCLK = 0x40
AI = 0x20
SLEEP = 0x10
ALLCALL = 0x01
OUTDRV = 0x04
FULL = 0x10  # bit 4 of ON_H (full on) and of OFF_H (full off; off wins)

DEFAULT_ADDRESS = 0x40
ALL_CALL_ADDRESS = 0x70
CHANNELS = 16
MAX_COUNT = 4095  # 12-bit counter: 4096 counts per period
OSCILLATOR_HZ = 25_000_000
PRESCALE_MIN, PRESCALE_MAX = 3, 255
#: The oscillator needs this long after SLEEP is cleared before RESTART may be written.
OSCILLATOR_SETTLE_S = 500e-6


def prescale_for(hz: float) -> int:
    """PRE_SCALE value for an output frequency of ``hz``: round(25 MHz / (4096 hz)) - 1 (not range-checked)."""
    return round(OSCILLATOR_HZ / (4096 * hz)) - 1


def frequency_of(prescale: int) -> float:
    """Output frequency (Hz) that PRE_SCALE value ``prescale`` gives with the internal 25 MHz oscillator."""
    return OSCILLATOR_HZ / (4096 * (prescale + 1))


#: The output frequencies PRE_SCALE can reach (about 1526 Hz at 3 down to 24 Hz at 255).
FREQUENCY_RANGE_HZ = (frequency_of(PRESCALE_MAX), frequency_of(PRESCALE_MIN))


def _integer(value: SupportsIndex, what: str) -> int:
    if isinstance(value, bool):
        raise TypeError(f"{what} must be an integer, not bool")
    try:
        return operator.index(value)
    except TypeError:
        raise TypeError(f"{what} must be an integer, not {type(value).__name__} {value!r}") from None


def _finite(value: float, what: str) -> float:
    if isinstance(value, (bool, str, bytes)):
        raise TypeError(f"{what} must be a number, not {type(value).__name__} {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{what} must be a number, not {type(value).__name__} {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{what} must be finite, not {v}")
    return v


class PCA9685:
    """One PCA9685 on ``bus`` at 7-bit ``address`` (0x40 with A5..A0 low; each address pin adds its bit).

    The constructor configures the chip: totem-pole outputs (MODE2 OUTDRV), register
    auto-increment (MODE1 AI, which every multi-byte write here relies on) and the oscillator
    running. A chip an earlier process put to sleep is woken and restarted, so its channels
    continue with what they were set to; the PWM frequency is left as it is (:attr:`frequency`
    reads it back) until :meth:`set_frequency`.

    ``delay`` is how the driver waits for the oscillator (``time.sleep``; tests pass a fake
    clock's). The object does not own ``bus``: close the bus yourself.

    Raises ValueError for an address outside 0x08..0x77 or the All Call address 0x70, and
    OSError when no device answers at ``address`` (or a kernel driver holds it).
    """

    def __init__(self, bus: I2CBus, address: int = DEFAULT_ADDRESS, *,
                 delay: Callable[[float], None] = time.sleep) -> None:  # fmt: skip
        validate_address(address, what="PCA9685")
        if address == ALL_CALL_ADDRESS:
            # Enabled at power-up on every PCA9685: a read there would have all chips answer at once.
            raise ValueError(
                "PCA9685 address 0x70 is the All Call address every PCA9685 answers at power-up; "
                "use the chip's own address (0x40 + its A5..A0 pins)"
            )
        self._bus = bus
        self._address = address
        self._delay = delay
        try:
            mode1 = self._read(MODE1)
        except OSError as e:
            raise OSError(e.errno, self._no_answer(e)) from e
        self._write(MODE2, OUTDRV)
        self._wake(mode1, extra=AI)
        self._prescale = self._read(PRE_SCALE)
        log.debug("PCA9685 at 0x%02X ready (was MODE1 0x%02X), %.2f Hz", address, mode1, self.frequency)

    def _no_answer(self, e: OSError) -> str:
        where = f"PCA9685 at 0x{self._address:02X}"
        if e.errno == errno.EBUSY:
            return (f"{where}: the address is claimed by a kernel driver (a device-tree overlay binding the chip "
                    f"to the PWM subsystem?): {e.strerror}")  # fmt: skip
        return f"{where}: no answer on the bus ({e.strerror}); check wiring, power and the A5..A0 address pins"

    # --- register access ----------------------------------------------------------------------

    def _read(self, reg: int) -> int:
        return self._bus.read_byte_data(self._address, reg)

    def _write(self, reg: int, value: int) -> None:
        self._bus.write_byte_data(self._address, reg, value)

    def _wake(self, mode1: int, *, extra: int = 0) -> None:
        """Write MODE1 = ``mode1`` without SLEEP (plus ``extra`` bits); then, if the chip was asleep or
        a restart was pending, wait for the oscillator and restart the outputs if the chip asks for it."""
        # RESTART is masked in every plain write: writing it as 1 is the restart itself.
        awake = (mode1 & ~(RESTART | SLEEP) | extra) & 0xFF
        self._write(MODE1, awake)
        if not mode1 & (SLEEP | RESTART):
            return
        # (Also when already awake with a restart pending: we cannot know how long ago it woke.)
        self._delay(OSCILLATOR_SETTLE_S)
        if self._read(MODE1) & RESTART:
            self._write(MODE1, awake | RESTART)

    # --- frequency ----------------------------------------------------------------------------

    @property
    def address(self) -> int:
        """The chip's 7-bit I2C address."""
        return self._address

    @property
    def prescale(self) -> int:
        """The PRE_SCALE register's value (3..255 once :meth:`set_frequency` set it)."""
        return self._prescale

    @property
    def frequency(self) -> float:
        """The actual PWM frequency in Hz, from the prescale (50.03 Hz after ``set_frequency(50)``)."""
        return frequency_of(self._prescale)

    def set_frequency(self, hz: float) -> float:
        """Set the PWM frequency of all 16 channels to the nearest the chip can make; returns it (Hz).

        The prescale can only change while the chip sleeps, so the outputs pause: sleep, write the
        prescale, restore MODE1, wait 500 us for the oscillator, restart. A chip put to sleep with
        :meth:`sleep` stays asleep (with the new frequency) until :meth:`wake`. Channels keep their
        counts, so their pulse widths scale with the period: set the frequency before the pulses.
        Raises ValueError when ``hz`` is not finite or outside about 24..1526 Hz (prescale 3..255).
        """
        hz = _finite(hz, "frequency")
        if hz <= 0:
            raise ValueError(f"frequency must be > 0 Hz, not {hz}")
        prescale = prescale_for(hz)
        if not PRESCALE_MIN <= prescale <= PRESCALE_MAX:
            lo, hi = FREQUENCY_RANGE_HZ
            raise ValueError(
                f"frequency {hz:g} Hz needs prescale {prescale}, outside {PRESCALE_MIN}..{PRESCALE_MAX}: "
                f"the PCA9685 makes {lo:.1f}..{hi:.1f} Hz"
            )
        mode1 = self._read(MODE1) & ~RESTART
        self._write(MODE1, mode1 | SLEEP)
        self._write(PRE_SCALE, prescale)
        self._write(MODE1, mode1)
        if not mode1 & SLEEP:
            self._delay(OSCILLATOR_SETTLE_S)
            self._write(MODE1, mode1 | RESTART | AI)
        self._prescale = prescale
        log.debug("PCA9685 at 0x%02X: %.2f Hz (prescale %d)", self._address, self.frequency, prescale)
        return self.frequency

    # --- outputs ------------------------------------------------------------------------------

    def _channel(self, channel: SupportsIndex) -> int:
        ch = _integer(channel, "channel")
        if not 0 <= ch < CHANNELS:
            raise ValueError(f"channel must be 0..{CHANNELS - 1}, not {ch}")
        return ch

    def _write_channel(self, channel: int, on: int, off: int) -> None:
        # One transfer of the channel's four registers (ON_L, ON_H, OFF_L, OFF_H): with auto-increment
        # the chip takes them together, so the output never runs a half-updated ON/OFF pair.
        data = [on & 0xFF, on >> 8, off & 0xFF, off >> 8]
        self._bus.write_i2c_block_data(self._address, LED0_ON_L + 4 * channel, data)

    def set_pwm(self, channel: SupportsIndex, on: SupportsIndex, off: SupportsIndex) -> None:
        """Drive ``channel`` (0..15) high at count ``on`` and low at count ``off`` of each 4096-count period.

        Clears the channel's full-on and full-off bits. Equal ``on`` and ``off`` is a degenerate
        setting: use :meth:`set_full_off` for a constantly low output.
        Raises ValueError for a channel outside 0..15 or a count outside 0..4095.
        """
        ch = self._channel(channel)
        counts = []
        for name, value in (("on", on), ("off", off)):
            c = _integer(value, f"{name} count")
            if not 0 <= c <= MAX_COUNT:
                raise ValueError(f"{name} count must be 0..{MAX_COUNT} (12 bits), not {c}")
            counts.append(c)
        self._write_channel(ch, counts[0], counts[1])

    def set_full_on(self, channel: SupportsIndex) -> None:
        """Drive ``channel`` constantly high (ON_H bit 4; OFF_H bit 4 cleared, since full off wins)."""
        self._write_channel(self._channel(channel), FULL << 8, 0)

    def set_full_off(self, channel: SupportsIndex) -> None:
        """Drive ``channel`` constantly low (OFF_H bit 4): a servo there gets no pulses and goes limp."""
        self._write_channel(self._channel(channel), 0, FULL << 8)

    def counts_for(self, pulse_us: float) -> int:
        """The OFF count (with ON = 0) of a ``pulse_us`` pulse at the current frequency: round(us f 4096 / 1e6).

        Raises ValueError when ``pulse_us`` is negative, not finite, or longer than 4095 counts.
        """
        us = _finite(pulse_us, "pulse width")
        if us < 0:
            raise ValueError(f"pulse width must be >= 0 us, not {us:g}")
        counts = round(us * self.frequency * 4096 / 1e6)
        if counts > MAX_COUNT:
            longest = MAX_COUNT * 1e6 / (self.frequency * 4096)
            raise ValueError(
                f"pulse of {us:g} us does not fit the period at {self.frequency:.2f} Hz "
                f"(at most {longest:.0f} us = {MAX_COUNT} counts)"
            )
        return counts

    def set_pulse_us(self, channel: SupportsIndex, pulse_us: float) -> int:
        """Make ``channel`` output a pulse of ``pulse_us`` microseconds each period; returns its counts.

        A pulse that rounds to 0 counts sets the channel full off (constantly low).
        Raises ValueError for a bad channel or a pulse that is negative or longer than the period.
        """
        ch = self._channel(channel)
        counts = self.counts_for(pulse_us)
        if counts == 0:
            self.set_full_off(ch)
        else:
            self._write_channel(ch, 0, counts)
        return counts

    # --- power --------------------------------------------------------------------------------

    def sleep(self) -> None:
        """Stop the oscillator: every output goes off until :meth:`wake` (the settings are kept)."""
        self._write(MODE1, (self._read(MODE1) & ~RESTART) | SLEEP)

    def wake(self) -> None:
        """Start the oscillator after :meth:`sleep` and resume the outputs where they were (waits 500 us)."""
        mode1 = self._read(MODE1)
        if mode1 & SLEEP:
            self._wake(mode1)


class Servo:
    """A hobby servo on one PCA9685 channel, calibrated by its pulse widths at two angles.

    ``min_us`` is the pulse that puts the horn at ``min_angle`` and ``max_us`` the one for
    ``max_angle`` (measure them per servo: typical servos span 750..2250 us, and commanding past
    their mechanical stops makes them stall). ``min_us`` may exceed ``max_us`` for a servo that
    turns the other way. Angles in between map linearly. Set the PCA9685 to a servo frequency
    (``set_frequency(50)``) first.

    Raises ValueError for a bad channel, non-finite or non-positive pulse widths, equal pulse
    widths, or ``min_angle >= max_angle``.
    """

    def __init__(self, pca: PCA9685, channel: int, min_us: float = 1000.0, max_us: float = 2000.0,
                 min_angle: float = 0.0, max_angle: float = 180.0) -> None:  # fmt: skip
        self._pca = pca
        self._channel = pca._channel(channel)
        self.min_us = _finite(min_us, "min_us")
        self.max_us = _finite(max_us, "max_us")
        self.min_angle = _finite(min_angle, "min_angle")
        self.max_angle = _finite(max_angle, "max_angle")
        if self.min_us <= 0 or self.max_us <= 0:
            raise ValueError(f"servo pulse widths must be > 0 us, not {self.min_us:g} and {self.max_us:g}")
        if self.min_us == self.max_us:
            raise ValueError(f"min_us and max_us are both {self.min_us:g} us: the servo could not move")
        if not self.min_angle < self.max_angle:
            raise ValueError(f"min_angle ({self.min_angle:g}) must be below max_angle ({self.max_angle:g})")
        self._angle: float | None = None

    @property
    def channel(self) -> int:
        """The PCA9685 channel the servo is on."""
        return self._channel

    @property
    def angle(self) -> float | None:
        """The last angle moved to; None before the first move and after :meth:`release`."""
        return self._angle

    def pulse_us_for(self, angle: float) -> float:
        """The calibrated pulse width for ``angle``.

        Raises ValueError when ``angle`` is outside ``min_angle..max_angle``: an angle beyond the
        calibrated end points is refused, not clamped, because it means the caller's geometry is
        wrong, and silently parking the gate at an end point would sort items into the wrong bin.
        """
        a = _finite(angle, "angle")
        if not self.min_angle <= a <= self.max_angle:
            raise ValueError(
                f"angle {a:g} is outside the calibrated range {self.min_angle:g}..{self.max_angle:g} degrees "
                f"of the servo on channel {self._channel}"
            )
        t = (a - self.min_angle) / (self.max_angle - self.min_angle)
        return self.min_us + t * (self.max_us - self.min_us)

    def move_to(self, angle: float) -> float:
        """Command the servo to ``angle``; returns the pulse width sent (us).

        Raises ValueError outside the calibrated range (see :meth:`pulse_us_for`) or when the pulse
        does not fit the PCA9685's current period.
        """
        us = self.pulse_us_for(angle)
        self._pca.set_pulse_us(self._channel, us)
        self._angle = float(angle)
        return us

    def release(self) -> None:
        """Stop sending pulses (channel full off): the servo stops holding its position."""
        self._pca.set_full_off(self._channel)
        self._angle = None
