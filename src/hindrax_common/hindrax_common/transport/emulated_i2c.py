"""Emulated I2C bus with the ``smbus2.SMBus`` interface, for tests and simulation.

The onboard I2C drivers talk to an object with the ``smbus2.SMBus`` interface (docs/architecture.md §2): on the
Raspberry Pi that is ``smbus2.SMBus(1)``; in tests and in the simulator it is an :class:`EmulatedI2CBus` holding
register- or command-exact device emulators (MS5837, ICM-20948, AK09916, PCA9685).

Why our own code: smbus2 itself has no emulated adapter, and an emulated bus must model what the Linux i2c-dev driver
does on the wire, so that the real driver code paths run unchanged: every SMBus call is broken into the I2C transactions
the kernel issues (``read_i2c_block_data(addr, reg, n)`` is a 1-byte write of ``reg``, then, after a repeated start, an
``n``-byte read), each device emulator sees exactly what a real slave sees (:class:`I2CDeviceEmulator`), and an address
nobody acknowledges fails with errno 121 as on Linux.

The module also provides :class:`RegisterPointerEmulator`, the shared base of every register-file
device emulator (write = set pointer then data with auto-increment; read = continue from pointer)."""

from __future__ import annotations

import ctypes
import errno
import random
import threading
from typing import Iterable, Mapping, Protocol, runtime_checkable

__all__ = ["I2C_SMBUS_BLOCK_MAX", "I2C_M_RD", "GENERAL_CALL_ADDRESS", "I2CDeviceEmulator",
           "EmulatedI2CBus", "RegisterPointerEmulator", "ManualClock", "remote_io_error"]

#: Maximum length of an SMBus/I2C block transfer through ``read/write_i2c_block_data`` (smbus2 and
#: Linux ``I2C_SMBUS_BLOCK_MAX``).
I2C_SMBUS_BLOCK_MAX = 32
#: ``i2c_msg.flags`` bit marking a read message (Linux ``I2C_M_RD``, as used by smbus2).
I2C_M_RD = 0x0001
#: I2C general-call address (writes only), used e.g. for the PCA9685 software reset (docs/devices.md §5.1).
GENERAL_CALL_ADDRESS = 0x00


def remote_io_error(address: int, detail: str = "") -> OSError:
    """``OSError(errno.EREMOTEIO)`` (121, "Remote I/O error"): what Linux i2c-dev returns when the
    slave at ``address`` does not acknowledge (most adapters, the Raspberry Pi's bcm2835 included);
    ``address`` and ``detail`` (e.g. "injected fault") go into its ``filename``."""
    err = OSError(errno.EREMOTEIO, "Remote I/O error")
    err.filename = f"i2c address 0x{address:02x}" + (f" ({detail})" if detail else "")
    return err


@runtime_checkable
class I2CDeviceEmulator(Protocol):
    """Device side of the emulated bus: one call per I2C transaction.

    ``i2c_write(data)``: one write transaction; ``data[0]`` is the register or command byte, the rest are data bytes.
    ``i2c_read(n)``: one read transaction of ``n`` bytes continuing from the device's internal pointer/state; must
    return exactly ``n`` bytes. Either may raise ``OSError(errno.EREMOTEIO)`` to model a NACK. Optional:
    ``i2c_general_call(data)`` to react to general-call (address 0x00) writes."""

    def i2c_write(self, data: bytes) -> None:  # pragma: no cover - protocol
        """Handle one write transaction (``data[0]`` = register/command)."""

    def i2c_read(self, n: int) -> bytes:  # pragma: no cover - protocol
        """Handle one read transaction of ``n`` bytes."""


def check_byte(name: str, value: int) -> int:
    """``value`` if it is an int in 0..255 (not a bool); ValueError naming ``name`` otherwise."""
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFF:
        raise ValueError(f"{name} must be an int in 0..255, got {value!r}")
    return value


def _check_bytes(name: str, data: Iterable[int]) -> bytes:
    try:
        out = bytes(data)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be bytes or ints in 0..255: {exc}") from None
    return out


class EmulatedI2CBus:
    """An I2C bus with the ``smbus2.SMBus`` method set, backed by device emulators.

    Args:
        devices: mapping 7-bit address -> :class:`I2CDeviceEmulator`.
        fault_rate: probability in [0, 1] that an SMBus call fails with errno 121 before reaching
            the device (seeded, reproducible).
        seed: seed of the fault-injection RNG.

    The smbus2 methods below keep smbus2's signatures (``force`` accepted and ignored).

    Errors: ``OSError(121)`` for an unknown/disconnected address or an injected fault;
    ``OSError(errno.EBADF)`` after ``close()``; ``ValueError`` for out-of-range arguments
    (values not in 0..255, blocks longer than 32 bytes, as smbus2 does for block lengths).

    Thread safety: every SMBus call holds one bus lock for its whole duration (a real adapter serialises transfers the
    same way), so calls from several threads interleave only at call boundaries.

    Source: semantics of Linux i2c-dev/SMBus transfers; smbus2 0.6 API; docs/architecture.md §2."""

    def __init__(
        self,
        devices: Mapping[int, I2CDeviceEmulator] | None = None,
        *,
        fault_rate: float = 0.0,
        seed: int = 0,
    ) -> None:
        self._lock = threading.RLock()
        self._devices: dict[int, I2CDeviceEmulator] = {}
        self._unplugged: set[int] = set()
        self._rng = random.Random(seed)
        self._fault_rate = 0.0
        self._disconnected = False
        self._open = True
        self.fd: int | None = -1
        self.funcs = 0
        self.calls = 0
        self.injected_faults = 0
        self.set_fault_rate(fault_rate)
        for address, device in (devices or {}).items():
            self.add_device(address, device)

    # ----------------------------------------------------------------- configuration / faults
    def add_device(self, address: int, device: I2CDeviceEmulator) -> None:
        """Attach ``device`` at 7-bit ``address`` (1..0x7F). Raises ValueError if taken/invalid."""
        if not isinstance(address, int) or not 0x01 <= address <= 0x7F:
            raise ValueError(f"I2C address must be 0x01..0x7f, got {address!r}")
        if not (hasattr(device, "i2c_write") and hasattr(device, "i2c_read")):
            raise ValueError("device must implement i2c_write(data) and i2c_read(n)")
        with self._lock:
            if address in self._devices:
                raise ValueError(f"I2C address 0x{address:02x} already has a device")
            self._devices[address] = device

    def remove_device(self, address: int) -> None:
        """Detach the device at ``address`` (no-op if none)."""
        with self._lock:
            self._devices.pop(address, None)
            self._unplugged.discard(address)

    @property
    def devices(self) -> dict[int, I2CDeviceEmulator]:
        """Copy of the address -> emulator mapping."""
        with self._lock:
            return dict(self._devices)

    def set_fault_rate(self, fault_rate: float) -> None:
        """Set the fraction (0..1) of SMBus calls failing with errno 121. Raises ValueError."""
        fault_rate = float(fault_rate)
        if not 0.0 <= fault_rate <= 1.0:
            raise ValueError(f"fault_rate must be in [0, 1], got {fault_rate}")
        with self._lock:
            self._fault_rate = fault_rate

    @property
    def fault_rate(self) -> float:
        """Current injected-fault probability per SMBus call."""
        return self._fault_rate

    @property
    def disconnected(self) -> bool:
        """Whole-bus disconnect switch: when True every call fails with errno 121."""
        return self._disconnected

    @disconnected.setter
    def disconnected(self, value: bool) -> None:
        with self._lock:
            self._disconnected = bool(value)

    def set_device_connected(self, address: int, connected: bool) -> None:
        """Unplug (``connected=False``) or re-plug one address; unplugged addresses NACK (121)."""
        with self._lock:
            if connected:
                self._unplugged.discard(address)
            else:
                self._unplugged.add(address)

    # ----------------------------------------------------------------- smbus2 lifecycle
    def open(self, bus: int | str | None = None) -> None:
        """Re-open after ``close()`` (the ``bus`` argument is ignored)."""
        with self._lock:
            self._open = True
            self.fd = -1

    def close(self) -> None:
        """Close the bus; later calls raise ``OSError(EBADF)`` until ``open()``."""
        with self._lock:
            self._open = False
            self.fd = None

    def __enter__(self) -> "EmulatedI2CBus":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # ----------------------------------------------------------------- core
    def _begin(self, address: int) -> None:
        """Checks done at the start of every SMBus call (lock held)."""
        if not self._open:
            raise OSError(errno.EBADF, "Bad file descriptor (emulated I2C bus is closed)")
        if not isinstance(address, int) or isinstance(address, bool) or not 0 <= address <= 0x7F:
            raise ValueError(f"I2C address must be an int in 0..0x7f, got {address!r}")
        self.calls += 1
        if self._disconnected:
            raise remote_io_error(address, "bus disconnected")
        if self._fault_rate > 0.0 and self._rng.random() < self._fault_rate:
            self.injected_faults += 1
            raise remote_io_error(address, "injected fault")

    def _device(self, address: int) -> I2CDeviceEmulator:
        device = self._devices.get(address)
        if device is None or address in self._unplugged:
            raise remote_io_error(address)
        return device

    def _write(self, address: int, data: bytes) -> None:
        if address == GENERAL_CALL_ADDRESS:
            handled = False
            for dev_address, device in self._devices.items():
                handler = getattr(device, "i2c_general_call", None)
                if handler is not None and dev_address not in self._unplugged:
                    handler(bytes(data))
                    handled = True
            if not handled:
                raise remote_io_error(address, "no device answers the general call")
            return
        self._device(address).i2c_write(bytes(data))

    def _read(self, address: int, n: int) -> bytes:
        if address == GENERAL_CALL_ADDRESS:
            raise remote_io_error(address, "general call is write-only")
        data = bytes(self._device(address).i2c_read(n))
        if len(data) != n:
            raise RuntimeError(f"emulator at 0x{address:02x} returned {len(data)} bytes, expected {n}")
        return data

    def _call(self, address: int, write: bytes | None, read: int | None = None) -> bytes:
        """One SMBus call under the bus lock: ``write`` as one write transaction, then a read of
        ``read`` bytes (repeated start); returns the bytes read (b"" without a read)."""
        with self._lock:
            self._begin(address)
            if write is not None:
                self._write(address, write)
            return b"" if read is None else self._read(address, read)

    # ----------------------------------------------------------------- smbus2 API
    def write_quick(self, i2c_addr: int, force: bool | None = None) -> None:
        """SMBus quick command: a zero-length write (address probe)."""
        self._call(i2c_addr, b"")

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        """SMBus send byte: one write transaction of the single byte ``value``."""
        check_byte("value", value)
        self._call(i2c_addr, bytes([value]))

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        """SMBus receive byte: one 1-byte read transaction from the device's current pointer."""
        return self._call(i2c_addr, None, 1)[0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> None:
        """SMBus write byte data: one write transaction ``[register, value]``."""
        check_byte("register", register)
        check_byte("value", value)
        self._call(i2c_addr, bytes([register, value]))

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus read byte data: write ``[register]``, repeated start, read 1 byte."""
        check_byte("register", register)
        return self._call(i2c_addr, bytes([register]), 1)[0]

    def write_word_data(self, i2c_addr: int, register: int, value: int, force: bool | None = None) -> None:
        """SMBus write word data: ``[register, value & 0xFF, value >> 8]`` (little-endian word)."""
        check_byte("register", register)
        if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise ValueError(f"word value must be in 0..65535, got {value!r}")
        self._call(i2c_addr, bytes([register, value & 0xFF, value >> 8]))

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        """SMBus read word data: write ``[register]``, read 2 bytes, return them little-endian.

        Source: SMBus specification; docs/devices.md §3.1 (swap for MSB-first devices)."""
        check_byte("register", register)
        return int.from_bytes(self._call(i2c_addr, bytes([register]), 2), "little")

    def write_i2c_block_data(
        self, i2c_addr: int, register: int, data: Iterable[int], force: bool | None = None
    ) -> None:
        """I2C block write: one write transaction ``[register, *data]``, at most 32 data bytes."""
        check_byte("register", register)
        payload = _check_bytes("data", data)
        if len(payload) > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Data length cannot exceed 32 bytes")
        self._call(i2c_addr, bytes([register]) + payload)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int, force: bool | None = None) -> list[int]:
        """I2C block read: write ``[register]``, repeated start, read ``length`` (1..32) bytes."""
        check_byte("register", register)
        if not isinstance(length, int) or length < 0 or length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Desired block length over 32 bytes" if isinstance(length, int) and length > 32
                             else f"length must be 0..32, got {length!r}")
        return list(self._call(i2c_addr, bytes([register]), length))

    def i2c_rdwr(self, *i2c_msgs: object) -> None:
        """Combined transfer of ``smbus2.i2c_msg`` messages (one ioctl, repeated starts).

        Write messages (``flags & I2C_M_RD == 0``) are delivered with ``i2c_write``; read messages are filled in place
        from ``i2c_read``. Any failure aborts the remaining messages, as the kernel does."""
        with self._lock:
            if not i2c_msgs:
                raise ValueError("i2c_rdwr needs at least one message")
            self._begin(int(getattr(i2c_msgs[0], "addr")))
            for msg in i2c_msgs:
                address = int(getattr(msg, "addr"))
                if not 0 <= address <= 0x7F:
                    raise ValueError(f"I2C address must be 0..0x7f, got {address}")
                length = int(getattr(msg, "len"))
                if int(getattr(msg, "flags")) & I2C_M_RD:
                    data = self._read(address, length)
                    ctypes.memmove(getattr(msg, "buf"), data, length)
                else:
                    self._write(address, ctypes.string_at(getattr(msg, "buf"), length))


class RegisterPointerEmulator:
    """Shared base for register-file device emulators (ICM-20948, AK09916, PCA9685).

    Model of a typical I2C register device: in a write transaction the first byte loads the register pointer and every
    further byte is written at the pointer, which then advances with :meth:`_next_pointer`; a read transaction returns
    bytes from the pointer, advancing the same way. :meth:`_begin_transaction` runs at the start of every transaction
    (used for lazy, clock-driven state updates), :meth:`_end_read` after every read transaction. All state access is
    serialised by ``self._lock``.

    Subclasses implement ``_read_register(reg) -> int``, ``_write_register(reg, value)`` and may
    override ``_next_pointer(reg) -> int`` (default: +1 modulo 256)."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._pointer = 0

    # hooks ------------------------------------------------------------------------------
    def _begin_transaction(self) -> None:
        """Called (lock held) at the start of every transaction. Default: nothing."""

    def _end_read(self) -> None:
        """Called (lock held) after every read transaction. Default: nothing."""

    def _next_pointer(self, register: int) -> int:
        """Pointer after accessing ``register``. Default: auto-increment modulo 256."""
        return (register + 1) & 0xFF

    def _read_register(self, register: int) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def _write_register(self, register: int, value: int) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    # I2CDeviceEmulator -----------------------------------------------------------------
    def i2c_write(self, data: bytes) -> None:
        """One write transaction: ``data[0]`` loads the pointer, the rest are written in order."""
        with self._lock:
            self._begin_transaction()
            if not data:
                return
            self._pointer = data[0]
            for value in data[1:]:
                self._write_register(self._pointer, value)
                self._pointer = self._next_pointer(self._pointer)

    def i2c_read(self, n: int) -> bytes:
        """One read transaction of ``n`` bytes from the pointer (auto-incrementing)."""
        with self._lock:
            self._begin_transaction()
            out = bytearray()
            for _ in range(n):
                out.append(self._read_register(self._pointer) & 0xFF)
                self._pointer = self._next_pointer(self._pointer)
            self._end_read()
            return bytes(out)


class ManualClock:
    """A manually advanced clock for deterministic emulation (tests, lock-step simulation).

    Call it to read the time (s); pass :meth:`sleep` as the ``sleep`` function of an
    :class:`~hindrax_common.transport.i2c.I2CDevice` so that driver waits advance the emulators'
    time instead of blocking. Thread-safe."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._lock = threading.Lock()
        self._t = float(start_s)
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        with self._lock:
            return self._t

    def advance(self, dt_s: float) -> None:
        """Move time forward by ``dt_s`` >= 0 seconds. Raises ValueError for negative steps."""
        if not dt_s >= 0.0:
            raise ValueError(f"cannot advance a clock by {dt_s}")
        with self._lock:
            self._t += float(dt_s)

    def sleep(self, dt_s: float) -> None:
        """Record the requested wait and advance by it (drop-in for ``time.sleep``)."""
        self.sleeps.append(float(dt_s))
        self.advance(dt_s)
