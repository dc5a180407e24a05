"""The one I2C access helper used by every I2C driver (MS5837, ICM-20948/AK09916, PCA9685).

:class:`I2CDevice` wraps an object with the ``smbus2.SMBus`` interface (a real ``smbus2.SMBus(1)``
on the Raspberry Pi, or :class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` in tests and
simulation; docs/architecture.md §2) for one slave address and adds what smbus2 does not have:

* retries with exponential backoff on ``OSError`` (typically errno 121 "Remote I/O error", a NACK from a slave that is
  busy, browning out or has a bad connector), with counters of errors, retries and failures for diagnostics;
* a clear :class:`I2CError` (an ``OSError`` carrying the last errno) once retries are exhausted;
* a *raw tap*: a callback ``(kind, address, register, data, t_monotonic_s)`` invoked for every successful transaction,
  so the ROS node can publish the raw register traffic for recording and bag replay (docs/architecture.md §7);
* :class:`RegisterWrite` sequences (the "sequence as data" produced by the protocol modules) executed with their delays.

The sleep function and the clock are injected, so tests run without real waiting."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Optional, Sequence

from .emulated_i2c import I2C_SMBUS_BLOCK_MAX, check_byte
from .socket_i2c import SOCKET_ENV, SocketI2CBus

__all__ = ["BusHandle", "I2CDevice", "I2CError", "I2CStats", "RawTap", "RegisterWrite", "open_smbus"]

#: Raw tap signature: ``(kind, address, register, data, t_monotonic_s)``; ``kind`` is ``"write"`` or ``"read"``;
#: ``register`` is the register/command byte that started the transaction, or ``None`` for a plain read continuing from
#: the device pointer; ``data`` are the data bytes written after the register byte, or the bytes read.
RawTap = Callable[[str, int, Optional[int], bytes, float], None]



class I2CError(OSError):
    """An I2C operation failed after all retries.

    ``errno`` is the errno of the last failure (e.g. 121), ``device_name``/``address``/
    ``operation`` identify the transfer, ``attempts`` is the number of attempts made."""

    def __init__(self, err_no: int | None, message: str, *, device_name: str, address: int,
                 operation: str, attempts: int) -> None:
        super().__init__(err_no, message)
        self.device_name = device_name
        self.address = address
        self.operation = operation
        self.attempts = attempts


@dataclass(frozen=True)
class RegisterWrite:
    """One register write of an initialisation sequence, as data.

    Attributes:
        register: register address (8-bit).
        value: byte to write (0..255).
        delay_after_s: time to wait after the write, in seconds (>= 0).
        note: short human description (which datasheet step), for logs.

    Source: docs/architecture.md §2 (protocol layer: command sequences as data)."""

    register: int
    value: int
    delay_after_s: float = 0.0
    note: str = ""

    def __post_init__(self) -> None:
        if not 0 <= int(self.register) <= 0xFF:
            raise ValueError(f"register must be 0..255, got {self.register}")
        if not 0 <= int(self.value) <= 0xFF:
            raise ValueError(f"value must be 0..255, got {self.value}")
        if not self.delay_after_s >= 0.0:
            raise ValueError(f"delay_after_s must be >= 0, got {self.delay_after_s}")


@dataclass
class I2CStats:
    """Counters of one :class:`I2CDevice`.

    Attributes:
        transactions: successful operations.
        errors: failed attempts (each ``OSError`` caught).
        retries: attempts made after a failure.
        failures: operations abandoned (``I2CError`` raised).
        last_error: text of the last ``OSError`` seen, or None."""

    transactions: int = 0
    errors: int = 0
    retries: int = 0
    failures: int = 0
    last_error: str | None = None

    def diagnostics(self) -> list[tuple[str, Any]]:
        """The counters as (key, value) pairs for a node's /diagnostics (same keys for every I2C device)."""
        return [("i2c_transactions", self.transactions), ("i2c_errors", self.errors), ("i2c_retries", self.retries),
                ("i2c_failures", self.failures), ("i2c_last_error", self.last_error or "")]


def open_smbus(bus_number: int) -> Any:
    """Open ``/dev/i2c-<bus_number>`` with smbus2 (what the nodes use on the Pi when no bus is injected).

    When the environment variable ``HINDRAX_I2C_SOCKET`` is set (tests and benchmarks only, never on the vehicle),
    the emulated bus served at that Unix socket instead (:mod:`.socket_i2c`), whatever the number.
    Raises OSError (or ImportError without smbus2) with a message naming the device file."""
    if os.environ.get(SOCKET_ENV):
        return SocketI2CBus(os.environ[SOCKET_ENV])
    import smbus2

    try:
        return smbus2.SMBus(bus_number)
    except OSError as exc:
        raise OSError(exc.errno, f"cannot open I2C bus {bus_number} (/dev/i2c-{bus_number}): {exc}") from exc


class BusHandle:
    """The bus of one I2C driver node: injected (tests, simulation: used as given, never closed here), or opened
    by the node with :func:`open_smbus` on first use and opened afresh after :meth:`reset`.

    A driver calls :meth:`reset` when a start-up attempt fails, so that its next attempt opens ``/dev/i2c-N``
    again: a bus that was absent at start, or went away and came back (the kernel driver reloaded, the emulated
    bus of a test restarted), is picked up without restarting the process."""

    def __init__(self, bus_number: int, bus: Any = None) -> None:
        self.bus_number = int(bus_number)
        self.owned = bus is None
        """True when the node opens (and closes) the bus itself."""
        self._bus = bus
        self.opens = 0
        """How many times the bus was opened (owned buses)."""

    def get(self) -> Any:
        """The bus, opened now if needed. Raises OSError (or ImportError) when it cannot be opened."""
        if self._bus is None:
            self._bus = open_smbus(self.bus_number)
            self.opens += 1
        return self._bus

    def reset(self) -> bool:
        """Close an owned open bus so that :meth:`get` opens it again; returns True if it did (False for an
        injected bus or one that is not open)."""
        if not self.owned or self._bus is None:
            return False
        with contextlib.suppress(Exception):  # closing a bus must not raise
            self._bus.close()
        self._bus = None
        return True

    def close(self) -> None:
        """Close an owned bus (shutdown)."""
        self.reset()


class I2CDevice:
    """One slave on an SMBus-like bus, with retries, counters and a raw tap.

    Args:
        bus: object with the ``smbus2.SMBus`` interface.
        address: 7-bit address (0..0x7F; 0x00 is the general call, write-only).
        name: device name used in messages and diagnostics (e.g. ``"ms5837"``).
        retries: extra attempts after a failed one (>= 0); total attempts = retries + 1.
        backoff_s: wait before the first retry, doubled for each further retry (>= 0).
        raw_tap: optional :data:`RawTap`, called after every successful transaction.
        sleep: ``sleep(seconds)`` used for backoff and sequence delays (inject a fake in tests).
        clock: monotonic clock in seconds for the raw-tap timestamps.

    Every operation holds ``self.lock`` (an ``RLock``); hold it yourself to make a multi-step
    sequence (bank select + burst read) atomic with respect to other threads.

    Retries cover ``OSError`` only; a ``ValueError`` from bad arguments propagates at once. Note
    that a retried read re-issues the whole transfer; devices with read side effects
    (e.g. the MS5837 ADC, which returns 0 on a second read) must be handled by the driver.

    Raises:
        I2CError: after ``retries + 1`` failed attempts (errno of the last failure).
        ValueError: invalid address, register, value or length."""

    def __init__(
        self,
        bus: Any,
        address: int,
        name: str,
        retries: int = 3,
        backoff_s: float = 0.001,
        raw_tap: RawTap | None = None,
        sleep: Callable[[float], None] = time.sleep,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if not isinstance(address, int) or not 0 <= address <= 0x7F:
            raise ValueError(f"I2C address must be 0..0x7f, got {address!r}")
        if not isinstance(retries, int) or retries < 0:
            raise ValueError(f"retries must be an int >= 0, got {retries!r}")
        if not backoff_s >= 0.0:
            raise ValueError(f"backoff_s must be >= 0, got {backoff_s!r}")
        self.bus = bus
        self.address = address
        self.name = name
        self.retries = retries
        self.backoff_s = float(backoff_s)
        self.raw_tap = raw_tap
        self._sleep = sleep
        self._clock = clock
        self.lock = threading.RLock()
        self.stats = I2CStats()

    # ------------------------------------------------------------------ internals
    def _run(self, operation: str, call: Callable[[], Any]) -> Any:
        """Run ``call`` with retries; return its result. Lock must be held."""
        attempts = 0
        while True:
            attempts += 1
            try:
                result = call()
            except OSError as exc:
                self.stats.errors += 1
                self.stats.last_error = f"{operation}: {exc}"
                if attempts > self.retries:
                    self.stats.failures += 1
                    raise I2CError(
                        exc.errno,
                        f"{self.name}@0x{self.address:02x}: {operation} failed after {attempts} attempt(s): {exc}",
                        device_name=self.name, address=self.address, operation=operation,
                        attempts=attempts,
                    ) from exc
                self.stats.retries += 1
                delay_s = self.backoff_s * (2 ** (attempts - 1))
                if delay_s > 0.0:
                    self._sleep(delay_s)
                continue
            self.stats.transactions += 1
            return result

    def _tap(self, kind: str, register: int | None, data: bytes) -> None:
        if self.raw_tap is not None:
            self.raw_tap(kind, self.address, register, bytes(data), float(self._clock()))

    # ------------------------------------------------------------------ operations
    def write_byte(self, value: int) -> None:
        """Send one command byte (SMBus send byte), e.g. an MS5837 command.

        Raw tap: ``("write", address, value, b"")``."""
        check_byte("value", value)
        with self.lock:
            self._run(f"write_byte(0x{value:02x})", lambda: self.bus.write_byte(self.address, value))
            self._tap("write", value, b"")

    def write_byte_data(self, register: int, value: int) -> None:
        """Write one register: transaction ``[register, value]``.

        Raw tap: ``("write", address, register, bytes([value]))``."""
        check_byte("register", register)
        check_byte("value", value)
        with self.lock:
            self._run(f"write_byte_data(0x{register:02x}, 0x{value:02x})",
                      lambda: self.bus.write_byte_data(self.address, register, value))
            self._tap("write", register, bytes([value]))

    def read_byte_data(self, register: int) -> int:
        """Read one register (write pointer, repeated start, read 1 byte).

        Raw tap: ``("read", address, register, bytes([value]))``."""
        check_byte("register", register)
        with self.lock:
            value = int(self._run(f"read_byte_data(0x{register:02x})",
                                  lambda: self.bus.read_byte_data(self.address, register)))
            self._tap("read", register, bytes([value]))
            return value

    def write_block(self, register: int, data: bytes | Sequence[int]) -> None:
        """Write ``data`` starting at ``register`` in one transaction ``[register, *data]``.

        Up to 32 bytes use ``write_i2c_block_data``; longer writes use ``i2c_rdwr`` (one message).
        Raw tap: ``("write", address, register, data)``."""
        check_byte("register", register)
        payload = bytes(data)
        with self.lock:
            if len(payload) <= I2C_SMBUS_BLOCK_MAX:
                call = lambda: self.bus.write_i2c_block_data(self.address, register, list(payload))  # noqa: E731
            else:
                from smbus2 import i2c_msg  # lazy: only long transfers need it

                call = lambda: self.bus.i2c_rdwr(i2c_msg.write(self.address, bytes([register]) + payload))  # noqa: E731
            self._run(f"write_block(0x{register:02x}, {len(payload)} bytes)", call)
            self._tap("write", register, payload)

    def read_block(self, register: int, length: int) -> bytes:
        """Burst read of ``length`` bytes starting at ``register`` (or after command ``register``).

        Up to 32 bytes use ``read_i2c_block_data``; longer reads use ``i2c_rdwr`` (write + read).
        Raw tap: ``("read", address, register, data)``.

        Returns ``bytes`` of length ``length``."""
        check_byte("register", register)
        if not isinstance(length, int) or length < 1:
            raise ValueError(f"length must be an int >= 1, got {length!r}")
        with self.lock:
            if length <= I2C_SMBUS_BLOCK_MAX:
                def call() -> bytes:
                    return bytes(self.bus.read_i2c_block_data(self.address, register, length))
            else:
                from smbus2 import i2c_msg

                def call() -> bytes:
                    write = i2c_msg.write(self.address, [register])
                    read = i2c_msg.read(self.address, length)
                    self.bus.i2c_rdwr(write, read)
                    return bytes(read)
            data = self._run(f"read_block(0x{register:02x}, {length})", call)
            if len(data) != length:
                raise I2CError(None, f"{self.name}@0x{self.address:02x}: short read {len(data)}/{length}",
                               device_name=self.name, address=self.address, operation="read_block", attempts=1)
            self._tap("read", register, data)
            return data

    def write_sequence(self, writes: Iterable[RegisterWrite]) -> None:
        """Execute register writes in order, sleeping ``delay_after_s`` after each.

        Holds the lock for the whole sequence. Raises :class:`I2CError` on the first write that
        fails after retries (later writes are not attempted)."""
        with self.lock:
            for write in writes:
                self.write_byte_data(write.register, write.value)
                if write.delay_after_s > 0.0:
                    self._sleep(write.delay_after_s)
