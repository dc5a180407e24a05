"""NXP PCA9685 16-channel PWM controller and Basic ESC pulse conventions: pure protocol layer.

Registers and bits (MODE1/MODE2, LEDn_ON/OFF_L/H, ALL_LED, PRE_SCALE), the prescale formula, pulse width <-> ON/OFF
counts, full-ON/full-OFF bits, the sleep / prescale / restart sequence as data, and the ESC conventions (1100-1900 us,
1500 us neutral; these limits, shared with the configuration check, are defined in
:mod:`hindrax_common.base.hardware_limits` and re-exported here). Sources: docs/devices.md §5.1 (NXP datasheet [Q1],
UM10574 [Q2], Adafruit library [Q3]) and §5.2 (Blue Robotics Basic ESC [E1]-[E5]).

Why our own code: the Adafruit CircuitPython PCA9685 stack needs Blinka/busio rather than an ``smbus2.SMBus`` object,
hides the register arithmetic, and computes counts from the *requested* frequency; docs/devices.md §5.1 requires using
the actual prescale and (calibrated) oscillator frequency, which is what every function here takes."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from hindrax_common.base.hardware_limits import (COUNTS_PER_PERIOD, ESC_ARMING_HOLD_S, ESC_DEADBAND_US,
    ESC_MAX_FREQUENCY_HZ, ESC_MAX_US, ESC_MIN_FREQUENCY_HZ, ESC_MIN_US, ESC_NEUTRAL_US, INTERNAL_OSCILLATOR_HZ,
    PRESCALE_MAX, PRESCALE_MIN, Pca9685Error, check_oscillator, check_prescale, esc_prescale, frequency_for_prescale,
    prescale_for_frequency)
from hindrax_common.transport.i2c import RegisterWrite

__all__ = [
    "Pca9685Error", "ChannelRegisters", "led_register", "prescale_for_frequency",
    "frequency_for_prescale", "period_s", "count_duration_us", "pulse_width_to_counts",
    "counts_to_pulse_width_us", "high_time_counts", "channel_bytes_for_pulse", "channel_block_for_pulses",
    "set_frequency_sequence", "startup_sequence", "safe_startup_sequence", "oscillator_from_measurement",
    "esc_prescale",
    # the limits of hindrax_common.base.hardware_limits, re-exported for the driver's users
    "COUNTS_PER_PERIOD", "PRESCALE_MIN", "PRESCALE_MAX", "INTERNAL_OSCILLATOR_HZ", "ESC_MIN_US", "ESC_NEUTRAL_US",
    "ESC_MAX_US", "ESC_DEADBAND_US", "ESC_MIN_FREQUENCY_HZ", "ESC_MAX_FREQUENCY_HZ", "ESC_ARMING_HOLD_S",
]


# ------------------------------------------------------------------------------ addresses
DEFAULT_ADDRESS = 0x40
GENERAL_CALL_ADDRESS = 0x00
#: Software reset: data byte 0x06 written to the general-call address (docs/devices.md §5.1 [Q1 §7.1.4]).
SWRST_DATA = 0x06

# ------------------------------------------------------------------------------ registers
MODE1 = 0x00
MODE2 = 0x01
SUBADR1 = 0x02
SUBADR2 = 0x03
SUBADR3 = 0x04
ALLCALLADR = 0x05
LED0_ON_L = 0x06
LAST_LED_REGISTER = 0x45
ALL_LED_ON_L = 0xFA
ALL_LED_OFF_H = 0xFD
PRE_SCALE = 0xFE
TESTMODE = 0xFF

MODE1_RESTART = 0x80
MODE1_EXTCLK = 0x40
MODE1_AI = 0x20
MODE1_SLEEP = 0x10
MODE1_ALLCALL = 0x01
MODE2_INVRT = 0x10
MODE2_OCH = 0x08
MODE2_OUTDRV = 0x04
#: Bit 4 of LEDn_ON_H (full ON) and LEDn_OFF_H (full OFF).
FULL_BIT = 0x10
#: The channel that carries a constant reference pulse (the configured neutral width) while the oscillator is not
#: measured (``esc.oscillator_calibrated`` false): the thruster channels are then off, and a scope measures this one
#: for ``hindrax esc calibrate``. The chip's last channel: no ESC or light may be on it (config cross-check).
REFERENCE_CHANNEL = 15

#: Reset values (docs/devices.md §5.1; the MODE1 SLEEP default is UNVERIFIED there).
MODE1_RESET = 0x11
MODE2_RESET = 0x04
PRE_SCALE_RESET = 0x1E
SUBADR_RESET = (0xE2, 0xE4, 0xE8)
ALLCALLADR_RESET = 0xE0

NUM_CHANNELS = 16
#: Oscillator start-up wait after clearing SLEEP before RESTART (docs/devices.md §5.1 restart rules).
RESTART_DELAY_S = 500e-6

def led_register(channel: int) -> int:
    """LEDn_ON_L address for channel n = 0..15: 0x06 + 4n (docs/devices.md §5.1)."""
    if not isinstance(channel, int) or isinstance(channel, bool) or not 0 <= channel < NUM_CHANNELS:
        raise Pca9685Error(f"channel must be 0..15, got {channel!r}")
    return LED0_ON_L + 4 * channel


def period_s(prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """PWM period in seconds for the actual prescale and oscillator."""
    return 1.0 / frequency_for_prescale(prescale, oscillator_hz)


def count_duration_us(prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """Duration of one of the 4096 counts in us: (PRE_SCALE + 1) / f_osc * 1e6 (docs/devices.md §5.1)."""
    return (check_prescale(prescale) + 1) / check_oscillator(oscillator_hz) * 1e6


def pulse_width_to_counts(pulse_width_us: float, prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> int:
    """Counts = round(pulse_us * f_osc / ((PRE_SCALE + 1) * 1e6)) (docs/devices.md §5.1 table note).

    Raises ``Pca9685Error``: non-finite or negative pulse, or one that needs more than 4095 counts (use full ON for a
    constant high level)."""
    if not (math.isfinite(pulse_width_us) and pulse_width_us >= 0.0):
        raise Pca9685Error(f"pulse_width_us must be finite and >= 0, got {pulse_width_us}")
    counts = math.floor(pulse_width_us / count_duration_us(prescale, oscillator_hz) + 0.5)
    if counts > COUNTS_PER_PERIOD - 1:
        raise Pca9685Error(f"{pulse_width_us:g} us needs {counts} counts, more than 4095 in the "
                           f"{period_s(prescale, oscillator_hz) * 1e6:.0f} us period")
    return counts


def counts_to_pulse_width_us(counts: float, prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """High time in us of ``counts`` counts (0..4096) at the given prescale and oscillator."""
    if not 0 <= counts <= COUNTS_PER_PERIOD:
        raise Pca9685Error(f"counts must be 0..4096, got {counts}")
    return counts * count_duration_us(prescale, oscillator_hz)


@dataclass(frozen=True)
class ChannelRegisters:
    """The four LEDn registers of one channel, decoded (docs/devices.md §5.1 register map).

    Attributes:
        on_count, off_count: 12-bit counts 0..4095 at which the output goes high / low.
        full_on: LEDn_ON_H bit 4. full_off: LEDn_OFF_H bit 4 (takes precedence)."""

    on_count: int = 0
    off_count: int = 0
    full_on: bool = False
    full_off: bool = False

    def __post_init__(self) -> None:
        for name, value in (("on_count", self.on_count), ("off_count", self.off_count)):
            if not isinstance(value, int) or not 0 <= value < COUNTS_PER_PERIOD:
                raise Pca9685Error(f"{name} must be an int 0..4095, got {value!r}")

    def to_bytes(self) -> bytes:
        """ON_L, ON_H, OFF_L, OFF_H (H bits 3:0 = count bits 11:8, bit 4 = full flag)."""
        return bytes([self.on_count & 0xFF, (self.on_count >> 8) | (FULL_BIT if self.full_on else 0),
                      self.off_count & 0xFF, (self.off_count >> 8) | (FULL_BIT if self.full_off else 0)])

    @classmethod
    def from_bytes(cls, data: bytes | Sequence[int]) -> "ChannelRegisters":
        """Decode 4 register bytes; reserved H bits 7:5 are ignored. Raises Pca9685Error on length."""
        try:
            raw = bytes(data)
        except (TypeError, ValueError):
            raise Pca9685Error(f"expected 4 bytes, got {data!r}") from None
        if len(raw) != 4:
            raise Pca9685Error(f"expected 4 bytes, got {len(raw)}")
        return cls(on_count=raw[0] | ((raw[1] & 0x0F) << 8), off_count=raw[2] | ((raw[3] & 0x0F) << 8),
                   full_on=bool(raw[1] & FULL_BIT), full_off=bool(raw[3] & FULL_BIT))

    @classmethod
    def full_off_setting(cls) -> "ChannelRegisters":
        """Output constantly low (the power-up state, docs/devices.md §0 item 8)."""
        return cls(full_off=True)

    @classmethod
    def full_on_setting(cls) -> "ChannelRegisters":
        """Output constantly high."""
        return cls(full_on=True)


def high_time_counts(setting: ChannelRegisters) -> int:
    """Counts per period the output is high, 0..4096 (docs/devices.md §5.1 output semantics).

    Full OFF wins (0); full ON gives 4096; otherwise ``(OFF - ON) mod 4096``, with ON == OFF
    giving 0 (the measured behaviour quoted in §5.1)."""
    if setting.full_off:
        return 0
    if setting.full_on:
        return COUNTS_PER_PERIOD
    return (setting.off_count - setting.on_count) % COUNTS_PER_PERIOD


def channel_bytes_for_pulse(pulse_width_us: float, prescale: int,
                            oscillator_hz: float = INTERNAL_OSCILLATOR_HZ, on_count: int = 0) -> bytes:
    """The 4 LEDn bytes producing ``pulse_width_us`` (ON at ``on_count``, OFF after the pulse).

    A pulse of 0 counts is encoded as full OFF (never ON == OFF, §5.1).

    Raises ``Pca9685Error``: see :func:`pulse_width_to_counts`; ``on_count`` not 0..4095."""
    counts = pulse_width_to_counts(pulse_width_us, prescale, oscillator_hz)
    if counts == 0:
        return ChannelRegisters.full_off_setting().to_bytes()
    if not isinstance(on_count, int) or not 0 <= on_count < COUNTS_PER_PERIOD:
        raise Pca9685Error(f"on_count must be 0..4095, got {on_count!r}")
    return ChannelRegisters(on_count, (on_count + counts) % COUNTS_PER_PERIOD).to_bytes()


def channel_block_for_pulses(pulse_widths_us: Sequence[float], prescale: int,
                             oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> tuple[bytes, list[float]]:
    """The LEDn bytes of consecutive channels (ON at count 0) for ``pulse_widths_us``, and the widths they give.

    The same counts as :func:`channel_bytes_for_pulse` per channel (half-up rounding, 0 counts = full OFF), for a
    whole auto-increment block at once (the ESC node's hot path). Returns ``(4 * n bytes, n decoded widths us)``.

    Raises ``Pca9685Error``: a non-finite or negative width, or one needing more than 4095 counts."""
    count_us = count_duration_us(prescale, oscillator_hz)
    out = bytearray()
    decoded = []
    for w in pulse_widths_us:
        if not (math.isfinite(w) and w >= 0.0):
            raise Pca9685Error(f"pulse_width_us must be finite and >= 0, got {w}")
        c = math.floor(w / count_us + 0.5)
        if c > COUNTS_PER_PERIOD - 1:
            raise Pca9685Error(f"{w:g} us needs {c} counts, more than 4095 in the "
                               f"{period_s(prescale, oscillator_hz) * 1e6:.0f} us period")
        out += bytes((0, 0, c & 0xFF, c >> 8)) if c else bytes((0, 0, 0, FULL_BIT))
        decoded.append(c * count_us)
    return bytes(out), decoded


def set_frequency_sequence(prescale: int, mode1: int = MODE1_AI | MODE1_ALLCALL) -> list[RegisterWrite]:
    """Sleep, write PRE_SCALE, wake, wait 500 us, RESTART (docs/devices.md §5.1 [Q3][Q1 §7.3.1.1]).

    Args:
        prescale: 3..255.
        mode1: the awake MODE1 value to return to (the "old" value of §5.1, SLEEP/RESTART ignored).

    Returns:
        MODE1 = (mode1 & ~RESTART) | SLEEP; PRE_SCALE = prescale; MODE1 = mode1 (wake), then wait
        :data:`RESTART_DELAY_S`; MODE1 = mode1 | RESTART | AI. PRE_SCALE is only accepted while
        SLEEP = 1, hence the order."""
    check_prescale(prescale)
    awake = mode1 & ~(MODE1_RESTART | MODE1_SLEEP) & 0xFF
    return [
        RegisterWrite(MODE1, awake | MODE1_SLEEP, 0.0, "sleep (PRE_SCALE writable only while asleep)"),
        RegisterWrite(PRE_SCALE, prescale, 0.0, "prescale"),
        RegisterWrite(MODE1, awake, RESTART_DELAY_S, "wake; oscillator start-up"),
        RegisterWrite(MODE1, awake | MODE1_RESTART | MODE1_AI, 0.0, "restart PWM channels"),
    ]


def startup_sequence(prescale: int, mode1: int = MODE1_AI | MODE1_ALLCALL) -> list[RegisterWrite]:
    """MODE2 (totem-pole outputs, the reset value 0x04) then :func:`set_frequency_sequence`.

    Channel registers are not touched: at power-up every channel is full OFF (no pulses, which the
    ESC does not treat as a command, §5.2); the driver then writes 1500 us to every ESC channel."""
    return [RegisterWrite(MODE2, MODE2_OUTDRV, 0.0, "MODE2"), *set_frequency_sequence(prescale, mode1)]


def safe_startup_sequence(prescale: int, mode1: int = MODE1_AI | MODE1_ALLCALL
                          ) -> tuple[list[RegisterWrite], list[RegisterWrite]]:
    """Start-up in two halves, with the channel registers written in between: ``(before, after)``.

    ``before``: MODE2; every output full OFF (ALL_LED_OFF_H = bit 4, one byte to the All-LED registers,
    datasheet §7.3.4: full OFF takes precedence), so no channel is active when SLEEP is set; SLEEP; PRE_SCALE.
    The caller then writes neutral into the channel registers (the chip is asleep: the registers take the
    values, nothing runs). ``after``: wake, wait :data:`RESTART_DELAY_S`, RESTART.

    Why: :func:`startup_sequence` wakes and RESTARTs first, and RESTART resumes whatever the channel registers
    still hold (datasheet §7.3.1.1), e.g. the 1700 us of a previous process that died while armed, until the
    driver writes neutral. Here the registers hold neutral (or full OFF) before RESTART."""
    freq = set_frequency_sequence(prescale, mode1)
    before = [RegisterWrite(MODE2, MODE2_OUTDRV, 0.0, "MODE2"),
              RegisterWrite(ALL_LED_OFF_H, FULL_BIT, 0.0, "every output full OFF before anything can restart"),
              *freq[:2]]
    return before, freq[2:]


def oscillator_from_measurement(measured_us: float, commanded_us: float, prescale: int,
                                 oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """The part's real oscillator frequency, Hz, from one scope reading of a commanded pulse.

    The driver wrote ``counts = round(commanded_us * oscillator_hz / ((PRE_SCALE + 1) 1e6))`` (assumed
    oscillator); the chip holds the output high for ``counts (PRE_SCALE + 1) / f_true`` (datasheet §7.3.5), so
    ``f_true = counts (PRE_SCALE + 1) / (measured_us 1e-6)``. Using the counts actually written (not
    ``commanded_us``) removes the rounding to one count. E.g. 1500 us commanded at 25 MHz, prescale 30: 1210
    counts; a 24.06 MHz part shows 1559.0 us, giving 24.06 MHz back.

    Raises ``Pca9685Error``: non-finite or non-positive reading, or a result outside 20-30 MHz (a wrong channel, trigger
    or unit: real parts measure 23-27 MHz, docs/devices.md §5.1)."""
    if not (math.isfinite(measured_us) and measured_us > 0.0):
        raise Pca9685Error(f"measured pulse must be finite and > 0 us, got {measured_us}")
    counts = pulse_width_to_counts(commanded_us, prescale, oscillator_hz)
    if counts == 0:
        raise Pca9685Error(f"commanded {commanded_us} us is 0 counts: command a pulse, e.g. 1500 us")
    f_true = counts * (check_prescale(prescale) + 1) / (measured_us * 1e-6)
    if not 20e6 <= f_true <= 30e6:
        raise Pca9685Error(f"{measured_us:g} us measured for {commanded_us:g} us commanded gives "
                           f"{f_true / 1e6:.3f} MHz, outside 20-30 MHz: check channel, trigger and units")
    return f_true
