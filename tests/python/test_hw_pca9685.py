# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
"""tofmat.hw.PCA9685 and Servo against the simulated chip (FakePCA9685Bus), and opening a real bus.

The fake models the PCA9685 at register level from the chip's facts (its register constants are its
own): what is checked here is what the chip would do with the driver's traffic, not the traffic.
"""

from __future__ import annotations

import errno
import math
from pathlib import Path

import pytest

from tofmat.hw import PCA9685, FakeChipError, FakePCA9685Bus, ManualClock, Servo, open_bus

ADDR = 0x40
MODE1, MODE2, PRE_SCALE = 0x00, 0x01, 0xFE
RESTART, AI, SLEEP = 0x80, 0x20, 0x10
OUTDRV = 0x04


def led(channel: int) -> int:
    return 0x06 + 4 * channel


@pytest.fixture
def clock() -> ManualClock:
    return ManualClock(start_s=100.0)


@pytest.fixture
def bus(clock: ManualClock) -> FakePCA9685Bus:
    return FakePCA9685Bus(clock=clock)


@pytest.fixture
def pca(bus: FakePCA9685Bus, clock: ManualClock) -> PCA9685:
    return PCA9685(bus, delay=clock.sleep)


@pytest.fixture
def pca50(pca: PCA9685) -> PCA9685:
    pca.set_frequency(50)
    return pca


def period_us(bus: FakePCA9685Bus) -> float:
    return 1e6 / bus.frequency_hz()


# --- the simulated chip on its own -----------------------------------------------------------


def test_fake_powers_up_asleep_with_every_channel_full_off(bus: FakePCA9685Bus) -> None:
    assert bus.read_byte_data(ADDR, MODE1) == 0x11  # SLEEP | ALLCALL
    assert bus.read_byte_data(ADDR, MODE2) == 0x04
    assert bus.read_byte_data(ADDR, PRE_SCALE) == 0x1E
    assert all(bus.read_byte_data(ADDR, led(ch) + 3) == 0x10 for ch in range(16))
    assert bus.pulses_us() == (None,) * 16
    assert bus.asleep and not bus.restart_pending
    assert bus.frequency_hz() == pytest.approx(196.9, abs=0.05)


def test_fake_ignores_prescale_written_while_awake(bus: FakePCA9685Bus, clock: ManualClock) -> None:
    bus.write_byte_data(ADDR, MODE1, 0x01)  # wake, no auto-increment
    clock.advance(0.01)
    bus.write_byte_data(ADDR, PRE_SCALE, 121)
    assert bus.prescale == 0x1E
    assert [(w.register, w.value, w.time) for w in bus.ignored_writes] == [(PRE_SCALE, 121, pytest.approx(100.01))]
    bus.write_byte_data(ADDR, MODE1, 0x11)  # asleep: now it takes
    bus.write_byte_data(ADDR, PRE_SCALE, 121)
    assert bus.prescale == 121 and len(bus.ignored_writes) == 1


def test_fake_without_auto_increment_puts_a_block_in_the_first_register(bus: FakePCA9685Bus) -> None:
    bus.write_byte_data(ADDR, MODE1, 0x01)  # awake, AI clear: as a driver that never set AI leaves it
    bus.write_i2c_block_data(ADDR, led(0), [0, 0, 205, 0])  # meant: ON 0, OFF 205
    assert list(bus.registers[led(0) : led(0) + 4]) == [0, 0, 0, 0x10]  # every byte went to LED0_ON_L
    assert bus.pulse_us(0) is None  # still full off: the pulse never arrived
    assert bus.read_i2c_block_data(ADDR, led(0) + 3, 3) == [0x10] * 3  # reads repeat one register too
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI)
    bus.write_i2c_block_data(ADDR, led(0), [0, 0, 205, 0])
    assert bus.counts(0) == (0, 205, False, False)


def test_fake_refuses_auto_increment_past_the_documented_registers(bus: FakePCA9685Bus) -> None:
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI)
    with pytest.raises(FakeChipError, match="runs past 0x45"):
        bus.write_i2c_block_data(ADDR, led(15) + 2, [1, 2, 3])
    with pytest.raises(FakeChipError, match="0x02"):
        bus.read_byte_data(ADDR, 0x02)  # a sub-address register: not modelled
    assert len(bus.errors) == 2


def test_fake_full_off_wins_and_all_led_reaches_every_channel(bus: FakePCA9685Bus, clock: ManualClock) -> None:
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI)
    bus.write_i2c_block_data(ADDR, led(4), [0, 0x10, 0, 0x10])  # full on and full off
    assert bus.pulse_us(4) is None
    bus.write_i2c_block_data(ADDR, 0xFA, [0, 0x10, 0, 0])  # ALL_LED: every channel full on
    assert bus.pulses_us() == (pytest.approx(period_us(bus)),) * 16
    bus.write_byte_data(0x70, 0xFD, 0x10)  # All Call address, ALL_LED_OFF_H: every channel full off
    assert bus.pulses_us() == (None,) * 16


def test_fake_refuses_restart_before_the_oscillator_settles(clock: ManualClock) -> None:
    bus = FakePCA9685Bus(clock=clock, strict=False)
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI)
    bus.write_i2c_block_data(ADDR, led(0), [0, 0, 0, 1])  # a 256-count pulse
    assert bus.pulse_us(0) is not None
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI | SLEEP)
    assert bus.pulse_us(0) is None and bus.read_byte_data(ADDR, MODE1) & RESTART  # restart pending
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI)
    clock.advance(300e-6)
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI | RESTART)
    assert bus.errors and "300.0 us after" in bus.errors[-1]
    assert bus.restart_pending and bus.pulse_us(0) is None  # refused: outputs stay stopped
    clock.advance(200e-6)
    bus.write_byte_data(ADDR, MODE1, 0x01 | AI | RESTART)
    assert len(bus.errors) == 1 and not bus.restart_pending
    assert bus.read_byte_data(ADDR, MODE1) & RESTART == 0  # writing 1 cleared it
    assert bus.pulse_us(0) == pytest.approx(256 * period_us(bus) / 4096)


def test_fake_does_not_answer_at_another_address(bus: FakePCA9685Bus) -> None:
    with pytest.raises(OSError) as e:
        bus.read_byte_data(0x41, MODE1)
    assert e.value.errno == errno.ENXIO and "0x41" in str(e.value)
    assert bus.history[-1].acked is False and bus.history[-1].address == 0x41


# --- the driver against the chip -------------------------------------------------------------


def test_init_leaves_the_chip_awake_with_auto_increment_and_totem_pole(pca: PCA9685, bus: FakePCA9685Bus,
                                                                       clock: ManualClock) -> None:  # fmt: skip
    mode1 = bus.read_byte_data(ADDR, MODE1)
    assert mode1 & AI and not mode1 & SLEEP and not mode1 & RESTART
    assert bus.read_byte_data(ADDR, MODE2) & OUTDRV
    assert not bus.asleep and bus.errors == [] and bus.ignored_writes == []
    assert sum(clock.slept) >= 500e-6  # it waited for the oscillator it started
    assert pca.frequency == pytest.approx(bus.frequency_hz())  # read back: 196.9 Hz at power-up
    assert bus.pulses_us() == (None,) * 16  # and left the outputs alone


def test_set_frequency_50_hz(pca: PCA9685, bus: FakePCA9685Bus) -> None:
    actual = pca.set_frequency(50)
    assert bus.prescale == 121 == pca.prescale
    assert actual == pca.frequency == pytest.approx(50.03, abs=0.005)
    assert bus.frequency_hz() == pytest.approx(actual)
    assert bus.ignored_writes == []  # PRE_SCALE only ever written while asleep
    assert bus.errors == [] and not bus.asleep and not bus.restart_pending
    assert bus.read_byte_data(ADDR, MODE1) & AI


def test_set_frequency_waits_500_us_before_restart(pca: PCA9685, bus: FakePCA9685Bus, clock: ManualClock) -> None:
    pca.set_pulse_us(5, 1500)  # a running output, which the sleep stops and the restart resumes
    clock.advance(1.0)
    start = len(bus.history)
    pca.set_frequency(50)
    mode1_writes = [t for t in bus.history[start:] if t.op == "write_byte" and t.register == MODE1]
    woke = next(t for t in mode1_writes if not t.data[0] & SLEEP)
    restart = next(t for t in mode1_writes if t.data[0] & RESTART)
    assert restart.time - woke.time >= 500e-6
    assert bus.errors == []
    # Channel 5 went quiet during the change and came back at the restart with the new period. It
    # keeps its counts, so its pulse grew with the period (set the frequency before the pulses).
    changes = bus.output_changes(5)
    assert changes[-2][1] is None and changes[-1][0] == restart.time
    assert changes[-1][1] == pytest.approx(bus.counts(5)[1] * period_us(bus) / 4096) == pytest.approx(5905, abs=1)


def test_a_driver_that_does_not_wait_is_caught(bus: FakePCA9685Bus) -> None:
    pca = PCA9685(bus, delay=lambda seconds: None)  # the fake clock does not move: no wait at all
    with pytest.raises(FakeChipError, match=r"0\.0 us after the oscillator was woken"):
        pca.set_frequency(50)


def test_frequency_outside_the_prescale_range_is_refused(pca: PCA9685, bus: FakePCA9685Bus) -> None:
    assert pca.set_frequency(24) == pytest.approx(24.0, abs=0.1) and bus.prescale == 253
    assert pca.set_frequency(1526) == pytest.approx(1525.9, abs=0.1) and bus.prescale == 3
    before = len(bus.history)
    for hz in (20, 1800, 0, -50, math.inf, math.nan):
        with pytest.raises(ValueError):
            pca.set_frequency(hz)
    with pytest.raises(ValueError, match=r"prescale 304, outside 3\.\.255"):
        pca.set_frequency(20)
    assert len(bus.history) == before  # refused before touching the chip


@pytest.mark.parametrize(("us", "counts"), [(1000, 205), (1500, 307), (2000, 410)])
def test_servo_pulses_at_50_hz(pca50: PCA9685, bus: FakePCA9685Bus, us: float, counts: int) -> None:
    assert pca50.set_pulse_us(7, us) == counts
    assert bus.counts(7) == (0, counts, False, False)
    pulse = bus.pulse_us(7)
    assert pulse is not None and abs(pulse - us) <= period_us(bus) / 4096  # within one count


def test_count_limits(pca50: PCA9685, bus: FakePCA9685Bus) -> None:
    pca50.set_pwm(0, 0, 4095)
    assert bus.pulse_us(0) == pytest.approx(4095 * period_us(bus) / 4096)
    pca50.set_pwm(0, 4095, 0)  # high from the last count across the period's end: one count
    assert bus.pulse_us(0) == pytest.approx(period_us(bus) / 4096)
    for on, off in ((-1, 0), (0, 4096), (4096, 0), (0, -1)):
        with pytest.raises(ValueError, match=r"0\.\.4095"):
            pca50.set_pwm(0, on, off)
    for ch in (-1, 16):
        with pytest.raises(ValueError, match=r"channel must be 0\.\.15"):
            pca50.set_pwm(ch, 0, 100)
    with pytest.raises(TypeError):
        pca50.set_pwm(0, 0, 204.8)  # type: ignore[arg-type]
    longest = 4095 * period_us(bus) / 4096
    assert pca50.set_pulse_us(1, longest) == 4095
    with pytest.raises(ValueError, match="does not fit the period"):
        pca50.set_pulse_us(1, 20_000)
    for bad in (-1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            pca50.set_pulse_us(1, bad)
    assert pca50.set_pulse_us(1, 0) == 0 and bus.pulse_us(1) is None  # no pulse at all: full off
    assert bus.errors == []


def test_full_on_and_full_off(pca50: PCA9685, bus: FakePCA9685Bus) -> None:
    pca50.set_pulse_us(3, 1500)
    pca50.set_full_on(3)
    assert bus.counts(3)[2:] == (True, False) and bus.registers[led(3) + 1] & 0x10
    assert bus.pulse_us(3) == pytest.approx(period_us(bus))
    pca50.set_full_off(3)
    assert bus.counts(3)[2:] == (False, True) and bus.registers[led(3) + 3] & 0x10
    assert bus.pulse_us(3) is None
    pca50.set_pwm(3, 0, 205)  # counts clear both bits again
    assert bus.counts(3) == (0, 205, False, False)


def test_auto_increment_is_what_makes_the_block_writes_work(pca50: PCA9685, bus: FakePCA9685Bus) -> None:
    pca50.set_pulse_us(2, 1500)
    # Without MODE1.AI (as if the driver had never set it) the same call leaves garbage behind.
    bus.write_byte_data(ADDR, MODE1, bus.read_byte_data(ADDR, MODE1) & ~AI)
    pca50.set_pulse_us(2, 2000)
    assert bus.counts(2) == (410 >> 8, 307, False, False)  # all four bytes went to ON_L: the last (OFF_H) stayed
    assert bus.pulse_us(2) != pytest.approx(2000, abs=10)


def test_sleep_and_wake(pca50: PCA9685, bus: FakePCA9685Bus, clock: ManualClock) -> None:
    pca50.set_pulse_us(0, 1000)
    clock.advance(2.0)
    pca50.sleep()
    assert bus.asleep and bus.pulse_us(0) is None and bus.restart_pending
    clock.advance(3.0)
    pca50.wake()
    assert not bus.asleep and not bus.restart_pending and bus.errors == []
    assert bus.pulse_us(0) == pytest.approx(1000, abs=5)
    # When the output changed, from the log: on when set, off at the sleep 2 s later, on again
    # 500 us after the wake 3 s after that (the clock started at 100 s; each wake waited 500 us).
    times = [(t, p is not None) for t, p in bus.output_changes(0)]
    assert times == [(pytest.approx(100.001), True), (pytest.approx(102.001), False),
                     (pytest.approx(105.0015), True)]  # fmt: skip


def test_a_new_driver_resumes_a_chip_left_asleep(pca50: PCA9685, bus: FakePCA9685Bus, clock: ManualClock) -> None:
    pca50.set_pulse_us(9, 1200)
    pca50.sleep()
    again = PCA9685(bus, delay=clock.sleep)  # e.g. the daemon restarted
    assert again.frequency == pytest.approx(50.03, abs=0.005)
    assert bus.pulse_us(9) == pytest.approx(1200, abs=5) and bus.errors == []


def test_servo_calibration(pca50: PCA9685, bus: FakePCA9685Bus) -> None:
    gate = Servo(pca50, 4, min_us=900, max_us=2100, min_angle=-45, max_angle=45)
    for angle, us in ((-45, 900), (0, 1500), (45, 2100), (22.5, 1800)):
        assert gate.move_to(angle) == pytest.approx(us)
        pulse = bus.pulse_us(4)
        assert pulse is not None and abs(pulse - us) <= period_us(bus) / 4096
        assert gate.angle == angle
    before = len(bus.history)
    for angle in (-45.1, 46, math.nan):
        with pytest.raises(ValueError, match=r"outside the calibrated range|finite"):
            gate.move_to(angle)
    assert len(bus.history) == before and gate.angle == 22.5  # refused, not clamped: the chip untouched
    gate.release()
    assert bus.pulse_us(4) is None and gate.angle is None
    reversed_servo = Servo(pca50, 5, min_us=2000, max_us=1000)  # mounted the other way round
    reversed_servo.move_to(0)
    assert bus.counts(5)[1] == 410


def test_servo_calibration_is_validated(pca50: PCA9685) -> None:
    with pytest.raises(ValueError, match="min_angle"):
        Servo(pca50, 0, min_angle=90, max_angle=90)
    with pytest.raises(ValueError, match="could not move"):
        Servo(pca50, 0, min_us=1500, max_us=1500)
    with pytest.raises(ValueError, match="> 0 us"):
        Servo(pca50, 0, min_us=-1)
    with pytest.raises(ValueError, match="channel"):
        Servo(pca50, 16)


def test_addresses(bus: FakePCA9685Bus, clock: ManualClock) -> None:
    for address, match in ((0x70, "All Call"), (0x00, "reserved"), (0x05, "reserved"), (0x78, "reserved"),
                           (0x80, "7-bit"), (-1, "7-bit")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            PCA9685(bus, address)
    with pytest.raises(OSError) as e:
        PCA9685(bus, 0x41, delay=clock.sleep)  # nobody there
    assert e.value.errno == errno.ENXIO and "0x41: no answer" in str(e.value)
    other = FakePCA9685Bus(address=0x41, clock=clock)
    assert PCA9685(other, 0x41, delay=clock.sleep).address == 0x41


# --- a real bus ------------------------------------------------------------------------------


def test_open_bus_without_an_i2c_bus_fails_clearly() -> None:
    number = next(n for n in range(1, 256) if not Path(f"/dev/i2c-{n}").exists())  # 1 on the build machines
    with pytest.raises(FileNotFoundError) as e:
        open_bus(number)
    message = str(e.value)
    assert f"/dev/i2c-{number} does not exist: no I2C bus {number} on this machine" in message
    assert "simulated bus" in message and e.value.filename == f"/dev/i2c-{number}"
    with pytest.raises(FileNotFoundError, match="/dev/i2c-tofmat-none does not exist"):
        open_bus("/dev/i2c-tofmat-none")
    with pytest.raises(ValueError, match=">= 0"):
        open_bus(-1)
