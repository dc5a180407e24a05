"""The ESC's PCA9685 at the register level (no ROS): start-up, read-back and the channel block writes.

:class:`EscChip` holds what the ESC node believes is in the chip's registers and talks to it through an injected
:class:`~hindrax_common.transport.i2c.I2CDevice` (``smbus2`` on the Pi, the emulated bus in tests). Every method
raises :class:`~hindrax_common.transport.i2c.I2CError` when the chip does not answer; what that means for the
outputs (UNKNOWN, disarm, retry) is :class:`.core.EscCore`'s. Registers and sequences: :mod:`.protocol`
(datasheet §7.3, docs/devices.md §5.1)."""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from hindrax_common.transport.i2c import I2CDevice, I2CError
from . import protocol as p

__all__ = ["EscChip", "channel_runs"]

#: mask of the LEDn bytes the chip keeps (reserved H bits 7:5 read 0, datasheet §7.3.3)
_KEPT = (0xFF, 0x1F, 0xFF, 0x1F)


def channel_runs(channels: Sequence[int]) -> list[list[int]]:
    """Consecutive channels (sorted input) in runs of at most 8: one 32-byte SMBus block write or read each."""
    runs: list[list[int]] = []
    for ch in channels:
        if runs and ch == runs[-1][-1] + 1 and len(runs[-1]) < 8:
            runs[-1].append(ch)
        else:
            runs.append([ch])
    return runs


class EscChip:
    """The PCA9685 driving the ESCs and the lights.

    ``address`` (7-bit I2C), ``prescale`` (3..255) and ``oscillator_hz`` (the calibrated oscillator, Hz) give the
    count grid; ``channels`` (n,) are the thrusters' PCA9685 channels in thruster order, ``lights_channel`` the
    lights'; ``reference``: (channel, us) of a constant pulse on a channel no ESC is on, or None. ``raw``: an object
    with ``begin_batch()`` and ``flush()`` (the node's ``raw/pca9685`` recorder), so that
    the transactions of one update go out in one message. :attr:`device` is None until the bus is open.
    :attr:`written` (n,) holds the thruster widths on the chip as decoded from the counts written, us."""

    #: MODE1 as read back from a configured chip: awake, auto-increment, All-Call, no RESTART pending
    EXPECTED_MODE1 = p.MODE1_AI | p.MODE1_ALLCALL

    def __init__(self, address: int, prescale: int, oscillator_hz: float, channels: Sequence[int], lights_channel: int,
                 raw: Any, device: I2CDevice | None = None, reference: tuple[int, float] | None = None) -> None:
        self.address, self.prescale, self.oscillator_hz = int(address), int(prescale), float(oscillator_hz)
        self.channels = [int(c) for c in channels]
        self.lights_channel = int(lights_channel)
        #: (channel, us): a constant pulse written with every update, for the scope (``hindrax esc calibrate``)
        self.reference = reference
        self.raw = raw
        self.device = device
        self.written = np.full(len(self.channels), np.nan)
        self._expected: dict[int, bytes] = {}  # channel -> the 4 LEDn bytes last written
        self._written_key: tuple | None = None  # (widths, lights) known to be on the chip, to skip identical writes

    def forget(self) -> None:
        """What is on the chip is not known any more (a failed transaction): the next write writes every block."""
        self._written_key = None

    def _need_device(self, operation: str) -> I2CDevice:
        if self.device is None:
            raise I2CError(None, "no I2C bus", device_name="pca9685", address=self.address, operation=operation,
                           attempts=0)
        return self.device

    def configure(self, neutral_us: np.ndarray, lights_off_us: float) -> str:
        """Put the chip in a known state with ``neutral_us`` (n,) on the thrusters and the lights off, and read it
        back: '' when confirmed, else the mismatch.

        Order (fault-safe): neutral into the channel registers first (a chip that kept running through a bus outage
        still outputs the last widths written: this ends them before anything else), then MODE2, every output full
        OFF (ALL_LED_OFF_H bit 4: nothing a previous process left can run again), sleep, PRE_SCALE, neutral again
        while asleep, wake, RESTART (:func:`~.protocol.safe_startup_sequence`, datasheet §7.3.1.1: RESTART resumes
        the channel registers, which now hold neutral)."""
        device = self._need_device("write")
        before, after = p.safe_startup_sequence(self.prescale)
        self.forget()
        self.write(neutral_us, lights_off_us)
        device.write_sequence(before)
        self.forget()
        self.write(neutral_us, lights_off_us)
        device.write_sequence(after)
        return self.readback_mismatch()

    def readback_mismatch(self) -> str:
        """Read MODE1, PRE_SCALE and every written channel back; '' when they hold what was written, else why."""
        device = self._need_device("read")
        mode1 = device.read_byte_data(p.MODE1)
        if mode1 != self.EXPECTED_MODE1:
            return f"MODE1 0x{mode1:02x}, expected 0x{self.EXPECTED_MODE1:02x} (chip reset or asleep)"
        prescale = device.read_byte_data(p.PRE_SCALE)
        if prescale != self.prescale:
            return f"PRE_SCALE {prescale}, expected {self.prescale}"
        for run in channel_runs(sorted(self._expected)):
            data = device.read_block(p.led_register(run[0]), 4 * len(run))
            for i, ch in enumerate(run):
                want, got = self._expected[ch], bytes(data[4 * i:4 * i + 4])
                if bytes(b & m for b, m in zip(got, _KEPT)) != bytes(b & m for b, m in zip(want, _KEPT)):
                    return f"channel {ch} registers {got.hex()}, expected {want.hex()}"
        return ""

    def write(self, widths_us: np.ndarray, lights_us: float) -> bool:
        """Write the thruster widths (n,) us and the lights' width, grouped in auto-increment block writes.

        Skips the bus when the same widths are known to be on the chip (the read-back confirms them once per
        ``esc.readback_interval_s``), and, while they are known, a block whose register bytes are the ones last
        written there (the lights between two thrust commands: one block write per command instead of two). After
        :meth:`forget` every block is written. Returns True when it wrote."""
        key = (tuple(np.asarray(widths_us, dtype=float).tolist()), float(lights_us))
        if key == self._written_key:
            return False
        known_on_chip = self._written_key is not None
        device = self._need_device("write")
        per_channel = {ch: float(w) for ch, w in zip(self.channels, widths_us)}
        per_channel[self.lights_channel] = float(lights_us)
        if self.reference is not None:
            per_channel[self.reference[0]] = float(self.reference[1])
        self.raw.begin_batch()
        decoded: dict[int, float] = {}
        for run in channel_runs(sorted(per_channel)):
            block, widths = p.channel_block_for_pulses([per_channel[c] for c in run], self.prescale, self.oscillator_hz)
            decoded.update(zip(run, widths))
            if known_on_chip and block == b"".join(self._expected.get(c, b"") for c in run):
                continue  # these registers already hold exactly these bytes
            self._written_key = None  # unknown until the whole write succeeded
            device.write_block(p.led_register(run[0]), block)
            self._expected.update((c, block[4 * i:4 * i + 4]) for i, c in enumerate(run))
        self.raw.flush()  # (after a failed write the records go out with the next update's)
        self.written = np.array([decoded[ch] for ch in self.channels])
        self._written_key = key
        return True
