"""Output lines through libgpiod (the ``gpiod`` Python bindings, v2 API), and their emulated stand-in.

Used by the output guard (:mod:`hindrax_bringup.guard`) to drive the PCA9685 /OE pin (docs/architecture.md §8,
docs/devices.md §5.1: /OE is active low; high = every output off, i.e. no pulses, which the Basic ESC treats as stop).

Two objects with the same four methods, ``set_high(bool)``, ``is_high()``, ``release()`` and
``release_problem()`` ("" when a released line returns to its pull, else why not or why that is not known):

* :class:`GpiodLine`: one line requested as an output through ``gpiod.request_lines`` (libgpiod v2). On
  ``release()`` or when the process dies the kernel frees the request. Upstream pinctrl then returns the pin to an
  input, so the level is whatever the board's pull resistor gives: the vehicle wiring puts a pull-up on /OE
  (docs/architecture.md §8), so a dead guard leaves the outputs OFF. The Raspberry Pi kernel, by default, keeps a
  freed output at its last level (raspberrypi/linux pull requests 6117 and 6150): ``persist_gpio_outputs`` of
  ``pinctrl_bcm2835`` / ``pinctrl_rp1`` is Y unless ``dtparam=strict_gpiod`` is in config.txt (the image's
  docs/deployment.md §11 sets it). :meth:`GpiodLine.release_problem` reads that parameter in ``/sys/module``.
* :class:`EmulatedGpioLine`: the same line in memory, with that pull: ``release()`` returns it to the pull level,
  or keeps the driven level with ``persist`` (a Raspberry Pi kernel without ``strict_gpiod``).
  The emulated PCA9685 (:class:`~hindrax_drivers.pca9685.emulator.Pca9685Emulator`) reads it to decide whether
  its outputs carry pulses. :mod:`hindrax_common.transport.shared_emulation` serves it to other processes (a
  dropped connection releases it, as the kernel does for a dead process).

The hardware watchdog on /OE (docs/watchdog.md) has its stand-in here too: :class:`WatchdogFeedLine` is the
feed line the guard toggles (it records its rising edges and runs out ``timeout_s`` after the last one, as the
retriggerable monostable does), and :class:`WatchedOutputEnable` is /OE as the PCA9685 sees it through the OR gate:
high when the guard drives (or releases) its line high, or when the watchdog has run out.

Why a thin wrapper of our own: the guard needs "drive high / drive low / release" and nothing else, and tests
need the same three calls on an emulated line that a register-exact chip emulator honours."""
from __future__ import annotations

import contextlib
import threading
import time
from typing import Callable

__all__ = ["GpiodLine", "EmulatedGpioLine", "WatchdogFeedLine", "WatchedOutputEnable", "release_problem_of"]


#: /sys/module parameters that say whether a freed output keeps its level: (module, parameter, value when it does not)
_RELEASE_PARAMETERS = (("persist_gpio_outputs", "N"), ("strict_gpiod", "Y"))


def release_problem_of(label: str, sys_module: str = "/sys/module") -> str:
    """"" when the kernel returns a freed line of the gpiochip labelled ``label`` (``pinctrl-bcm2711``,
    ``pinctrl-rp1``...) to an input, else one line saying it keeps its level or that this cannot be told (no
    parameter found). Reads ``<sys_module>/pinctrl_{bcm2835,rp1}/parameters/{persist_gpio_outputs,strict_gpiod}``."""
    from pathlib import Path

    module = "pinctrl_rp1" if "rp1" in label else "pinctrl_bcm2835"
    for name, safe in _RELEASE_PARAMETERS:
        path = Path(sys_module) / module / "parameters" / name
        try:
            value = path.read_text().strip()[:1].upper()
        except OSError:
            continue
        if value == safe:
            return ""
        return (f"a freed GPIO keeps its level on this kernel ({module}.{name}={value}): a killed guard would leave "
                "/OE enabled; put dtparam=strict_gpiod in config.txt and reboot (docs/deployment.md §11)")
    return (f"cannot tell whether a freed GPIO of {label or 'this chip'} returns to an input (no {module} "
            "persist_gpio_outputs or strict_gpiod parameter): put dtparam=strict_gpiod in config.txt "
            "(docs/deployment.md §11)")


class GpiodLine:
    """One GPIO line requested as an output with libgpiod v2 (``gpiod.request_lines``).

    Args:
        chip: gpiochip device path, e.g. ``/dev/gpiochip0`` (Raspberry Pi 4 header GPIOs; ``gpiochip4`` on a Pi 5).
        line: line offset on that chip (the BCM GPIO number on a Pi 4).
        initial_high: level driven as soon as the line is requested.
        consumer: label shown by ``gpioinfo``.

    Raises:
        ImportError: the ``gpiod`` bindings are not installed.
        OSError: the chip cannot be opened or the line is busy (another consumer holds it)."""

    def __init__(self, chip: str, line: int, initial_high: bool = True, consumer: str = "hindrax-output-guard"):
        import gpiod
        from gpiod.line import Direction, Value

        self._value = Value
        self.chip, self.line = str(chip), int(line)
        settings = gpiod.LineSettings(direction=Direction.OUTPUT,
                                      output_value=Value.ACTIVE if initial_high else Value.INACTIVE)
        self._request = gpiod.request_lines(self.chip, consumer=consumer, config={self.line: settings})
        self._high = bool(initial_high)
        try:
            with gpiod.Chip(self.chip) as handle:
                self._label = str(handle.get_info().label)
        except OSError:
            self._label = ""

    def release_problem(self) -> str:
        """"" when the kernel returns this line to an input once freed, else why not (:func:`release_problem_of`)."""
        return release_problem_of(self._label)

    def set_high(self, high: bool) -> None:
        """Drive the line high (True) or low (False). Raises OSError when the request is gone."""
        self._request.set_value(self.line, self._value.ACTIVE if high else self._value.INACTIVE)
        self._high = bool(high)

    def is_high(self) -> bool:
        """The level last driven."""
        return self._high

    def release(self) -> None:
        """Free the request (the pin returns to an input: the pull resistor decides the level)."""
        with contextlib.suppress(Exception):  # releasing on shutdown must not raise
            self._request.release()


class EmulatedGpioLine:
    """An emulated output line with a pull resistor (for tests and simulation).

    ``pull_high``: the level of the released line (the vehicle's /OE pull-up: True). ``persist``: a released line
    keeps driving its last level (a Raspberry Pi kernel without ``strict_gpiod``). Starts released. Thread-safe.
    ``driven``: True while someone drives it (after :meth:`set_high`, until :meth:`release` without ``persist``)."""

    def __init__(self, pull_high: bool = True, persist: bool = False) -> None:
        self._lock = threading.Lock()
        self.pull_high, self.persist = bool(pull_high), bool(persist)
        self._driven: bool | None = None  # None: released
        self.changes = 0

    def set_high(self, high: bool) -> None:
        """Drive the line high (True) or low (False)."""
        with self._lock:
            self._driven = bool(high)
            self.changes += 1

    def is_high(self) -> bool:
        """The level on the wire: the driven level, or the pull when released."""
        with self._lock:
            return self.pull_high if self._driven is None else self._driven

    @property
    def driven(self) -> bool:
        """True while the line is driven (not released)."""
        with self._lock:
            return self._driven is not None

    def release(self) -> None:
        """Stop driving: the pull decides the level (what the kernel does when the requesting process dies); with
        ``persist`` the line keeps its driven level."""
        with self._lock:
            if not self.persist:
                self._driven = None
            self.changes += 1

    def release_problem(self) -> str:
        """"" when a released line returns to its pull; else why not."""
        return ("a freed GPIO keeps its level (emulated kernel without strict_gpiod): a killed guard would leave /OE "
                "enabled" if self.persist else "")


class WatchdogFeedLine(EmulatedGpioLine):
    """The hardware watchdog's feed input (docs/watchdog.md) in memory: an :class:`EmulatedGpioLine` with a pull-down
    that records the time of its last rising edge (``clock``, s; ``time.monotonic`` by default, the system-wide
    CLOCK_MONOTONIC, so another process's times compare). The monostable's output is active for ``timeout_s`` after
    each rising edge (retriggered by the next); :meth:`expired` is its inverted output (/Q): True before the first
    edge and once ``timeout_s`` has passed since the last one."""

    def __init__(self, timeout_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(pull_high=False)
        self.timeout_s = float(timeout_s)
        self._clock = clock
        #: clock time of the last rising edge (None: never fed)
        self.last_rise: float | None = None
        self.rises = 0

    def set_high(self, high: bool) -> None:
        """Drive the feed; a low-to-high change retriggers the monostable."""
        was = self.is_high()
        super().set_high(high)
        if high and not was:
            self.last_rise = self._clock()
            self.rises += 1

    def expires_at(self) -> float | None:
        """Clock time at which the monostable runs out without a new edge (None: never fed)."""
        last = self.last_rise
        return None if last is None else last + self.timeout_s

    def expired(self) -> bool:
        """The monostable's /Q: True (outputs to be disabled) unless a rising edge came within ``timeout_s``."""
        end = self.expires_at()
        return end is None or self._clock() >= end


class WatchedOutputEnable:
    """/OE as the PCA9685 sees it with the hardware watchdog fitted (docs/watchdog.md): the OR (74LVC1G32) of the
    guard's /OE line ``oe`` and the watchdog's /Q (``feed.expired()``). Pass it to the emulated chip as its
    ``output_enable_line``; the guard keeps driving ``oe`` and toggling ``feed``."""

    def __init__(self, oe: EmulatedGpioLine, feed: WatchdogFeedLine) -> None:
        self.oe, self.feed = oe, feed

    def is_high(self) -> bool:
        """True: the outputs are disabled (the guard asserts /OE, or the watchdog ran out)."""
        return self.oe.is_high() or self.feed.expired()
