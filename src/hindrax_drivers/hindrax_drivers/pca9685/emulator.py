"""NXP PCA9685 device emulator (register-exact, default address 0x40), for tests and simulation.

Models docs/devices.md §5.1:

* reset values MODE1 = 0x11, MODE2 = 0x04, PRE_SCALE = 0x1E, every LEDn full OFF; reserved H bits
  7:5 read 0; ALL_LED registers are write-only and write all 16 channels; TestMode (0xFF) and 0x46..0xF9 ignore writes;
* auto-increment only with MODE1.AI, wrapping 0x45 -> 0x00 and 0xFE -> 0x00;
* PRE_SCALE written only while SLEEP, values below 3 forced to 3;
* SLEEP/RESTART [Q1 §7.3.1.1]: sleeping with a channel active sets RESTART and stops the outputs,
  which stay stopped after wake until RESTART is written 1 or a PWM register is written; EXTCLK set
  only while sleeping, cleared only by a reset;
* software reset through the general call (0x00, data 0x06, ``i2c_general_call``);
* :meth:`Pca9685Emulator.pulse_width_us`: the high time each channel produces (0 when sleeping,
  stopped or full OFF, the period when full ON, inverted with MODE2.INVRT);
* a write log ``(t_s, register, value)`` per data byte;
* /OE (active low, §7.4): ``output_enable_line`` (``is_high()``; None = tied low); while high every
  output carries no pulse.

Not modelled: sub-addresses and All-Call decoding, OUTNE, OCH (updates apply at STOP), the
oscillator's 500 us start-up, update at the end of the cycle."""

from __future__ import annotations

import collections
import time
from dataclasses import dataclass
from typing import Callable, Sequence

from hindrax_common.transport.emulated_i2c import RegisterPointerEmulator
from . import protocol as p

__all__ = ["from_config", "Pca9685Emulator", "WriteLogEntry"]


@dataclass(frozen=True)
class WriteLogEntry:
    """One register byte written over I2C: clock time (s), register address, value."""

    t_s: float
    register: int
    value: int


class Pca9685Emulator(RegisterPointerEmulator):
    """Register-exact PCA9685 (see module docstring).

    Args:
        oscillator_hz: the part's real internal oscillator frequency (nominal 25 MHz; real parts
            23-27 MHz, docs/devices.md §5.1) used to decode pulse widths.
        clock: clock for the write log timestamps, s.
        external_clock_hz: frequency used once EXTCLK is latched (None: keep ``oscillator_hz``).
        output_enable_line: the /OE line (``is_high()``: outputs off), or None (tied low: always enabled)."""

    def __init__(self, oscillator_hz: float = p.INTERNAL_OSCILLATOR_HZ, clock: Callable[[], float] = time.monotonic,
                 external_clock_hz: float | None = None, output_enable_line=None) -> None:
        super().__init__()
        self.output_enable_line = output_enable_line
        if not oscillator_hz > 0.0:
            raise ValueError(f"oscillator_hz must be > 0, got {oscillator_hz}")
        self.oscillator_hz = float(oscillator_hz)
        self.external_clock_hz = external_clock_hz
        self.clock = clock
        self.write_log: collections.deque[WriteLogEntry] = collections.deque(maxlen=100_000)
        self._widths: tuple = (None, [])  # (what pulse_widths_us computed them from, widths)
        self._power_on_reset()

    # ------------------------------------------------------------------ state
    def _power_on_reset(self) -> None:
        self._regs = bytearray(256)
        self._regs[p.MODE1] = p.MODE1_RESET
        self._regs[p.MODE2] = p.MODE2_RESET
        self._regs[p.SUBADR1:p.SUBADR3 + 1] = bytes(p.SUBADR_RESET)
        self._regs[p.ALLCALLADR] = p.ALLCALLADR_RESET
        for channel in range(p.NUM_CHANNELS):
            self._regs[p.led_register(channel) + 3] = p.FULL_BIT
        self._regs[p.PRE_SCALE] = p.PRE_SCALE_RESET
        self._restart_pending = False
        self._extclk = False
        self._pointer = 0

    def reset(self) -> None:
        """Power-on / software reset: every register to its reset value."""
        with self._lock:
            self._power_on_reset()

    def i2c_general_call(self, data: bytes) -> None:
        """General-call write: data 0x06 is SWRST (docs/devices.md §5.1); other data are ignored."""
        if bytes(data[:1]) == bytes([p.SWRST_DATA]):
            self.reset()

    @property
    def mode1(self) -> int:
        """MODE1 as read over I2C (with RESTART and EXTCLK state)."""
        with self._lock:
            return self._read_register(p.MODE1)

    @property
    def prescale(self) -> int:
        """Current PRE_SCALE."""
        with self._lock:
            return self._regs[p.PRE_SCALE]

    @property
    def sleeping(self) -> bool:
        """MODE1.SLEEP."""
        with self._lock:
            return bool(self._regs[p.MODE1] & p.MODE1_SLEEP)

    @property
    def effective_oscillator_hz(self) -> float:
        """Clock driving the prescaler: the external clock once EXTCLK is latched, else the oscillator."""
        if self._extclk and self.external_clock_hz:
            return float(self.external_clock_hz)
        return self.oscillator_hz

    def channel_registers(self, channel: int) -> p.ChannelRegisters:
        """Decoded LEDn registers of ``channel``."""
        base = p.led_register(channel)
        with self._lock:
            return p.ChannelRegisters.from_bytes(self._regs[base:base + 4])

    def _any_active(self) -> bool:
        return any(not (self._regs[p.led_register(c) + 3] & p.FULL_BIT) for c in range(p.NUM_CHANNELS))

    # ------------------------------------------------------------------ outputs
    def period_s(self) -> float:
        """Actual PWM period from PRE_SCALE and the effective oscillator, s."""
        with self._lock:
            return p.COUNTS_PER_PERIOD * (self._regs[p.PRE_SCALE] + 1) / self.effective_oscillator_hz

    def pulse_width_us(self, channel: int) -> float:
        """High time per period that ``channel`` actually outputs, in us (docs/devices.md §5.1).

        0 while /OE is high (no signal), while sleeping, while stopped awaiting RESTART, or when full OFF; the
        full period when full ON; (OFF - ON) mod 4096 counts otherwise; with MODE2.INVRT the complement."""
        if self.outputs_disabled():
            return 0.0
        with self._lock:
            period_us = self.period_s() * 1e6
            if self._regs[p.MODE1] & p.MODE1_SLEEP or self._restart_pending:
                high = 0.0
            else:
                high = p.high_time_counts(self.channel_registers(channel)) / p.COUNTS_PER_PERIOD * period_us
            if self._regs[p.MODE2] & p.MODE2_INVRT:
                return period_us - high
            return high

    def pulse_widths_us(self, channels: Sequence[int]) -> list[float]:
        """:meth:`pulse_width_us` of each of ``channels``, us, computed again only when what they depend on changed
        (the registers, RESTART, the clock, /OE): the virtual pool asks at every integration step."""
        disabled = self.outputs_disabled()
        with self._lock:
            key = (bytes(self._regs), self._restart_pending, self.effective_oscillator_hz, disabled, tuple(channels))
            if key != self._widths[0]:
                self._widths = (key, [self.pulse_width_us(c) for c in channels])
            return list(self._widths[1])

    def outputs_disabled(self) -> bool:
        """True while the /OE line reads high (every output off, OUTNE = 00: low), datasheet §7.4."""
        line = self.output_enable_line
        return line is not None and bool(line.is_high())

    # ------------------------------------------------------------------ register file
    def _next_pointer(self, register: int) -> int:
        """Auto-increment per docs/devices.md §5.1 (only with MODE1.AI = 1)."""
        if not self._regs[p.MODE1] & p.MODE1_AI:
            return register
        if register == p.LAST_LED_REGISTER or register >= p.PRE_SCALE:
            return 0x00
        return register + 1

    def _read_register(self, register: int) -> int:
        if register == p.MODE1:
            value = self._regs[p.MODE1] & ~(p.MODE1_RESTART | p.MODE1_EXTCLK)
            return value | (p.MODE1_RESTART if self._restart_pending else 0) | (p.MODE1_EXTCLK if self._extclk else 0)
        if p.ALL_LED_ON_L <= register <= p.ALL_LED_OFF_H or register == p.TESTMODE:
            return 0
        return self._regs[register]

    def _write_led_byte(self, register: int, value: int) -> None:
        offset = (register - p.LED0_ON_L) % 4
        # H registers: bits 3:0 count, bit 4 full flag; reserved bits 7:5 read 0.
        self._regs[register] = value & 0x1F if offset in (1, 3) else value

    def _write_register(self, register: int, value: int) -> None:
        self.write_log.append(WriteLogEntry(float(self.clock()), register, value))
        regs = self._regs
        if register == p.MODE1:
            was_sleeping = bool(regs[p.MODE1] & p.MODE1_SLEEP)
            sleep = bool(value & p.MODE1_SLEEP)
            if value & p.MODE1_EXTCLK and was_sleeping:
                self._extclk = True
            if sleep and not was_sleeping and self._any_active():
                self._restart_pending = True
            elif value & p.MODE1_RESTART and self._restart_pending and not sleep:
                self._restart_pending = False
            regs[p.MODE1] = value & ~(p.MODE1_RESTART | p.MODE1_EXTCLK) & 0xFF
        elif register == p.PRE_SCALE:
            if regs[p.MODE1] & p.MODE1_SLEEP:
                regs[p.PRE_SCALE] = max(p.PRESCALE_MIN, value)
        elif p.LED0_ON_L <= register <= p.LAST_LED_REGISTER:
            self._write_led_byte(register, value)
            self._restart_pending = False
        elif p.ALL_LED_ON_L <= register <= p.ALL_LED_OFF_H:
            offset = register - p.ALL_LED_ON_L
            for channel in range(p.NUM_CHANNELS):
                self._write_led_byte(p.led_register(channel) + offset, value)
            self._restart_pending = False
        elif register == p.MODE2:
            regs[p.MODE2] = value & 0x1F  # bits 7:5 reserved
        elif register in (p.SUBADR1, p.SUBADR2, p.SUBADR3, p.ALLCALLADR):
            regs[register] = value
        # 0x46..0xF9 reserved and 0xFF TestMode: ignored


def from_config(config, truth: None, clock: Callable[[], float], seed: int = 0) -> Pca9685Emulator:
    """The PCA9685 at the configured ``esc.oscillator_hz`` on ``clock`` (s); no truth (devices.py factory)."""
    return Pca9685Emulator(oscillator_hz=config.esc.oscillator_hz, clock=clock)
