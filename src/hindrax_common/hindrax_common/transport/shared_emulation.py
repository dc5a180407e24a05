"""Emulated I2C bus and GPIO lines shared between processes over a Unix socket (tests and benchmarks).

On the vehicle the ESC node and the output guard are separate processes that share one I2C bus (``/dev/i2c-1``,
the kernel serialises transfers) and the PCA9685 /OE line (a GPIO the guard requests). To test and measure that
layout with emulated devices, one process holds the emulators (:class:`EmulationServer`: an
:class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` and named
:class:`~hindrax_common.transport.gpio.EmulatedGpioLine` objects) and the node processes reach them through
:class:`SharedI2CBus` (the ``smbus2.SMBus`` methods the drivers use) and :class:`SharedGpioLine` (the guard's
``set_high``/``is_high``/``release``/``release_problem``).

Kernel semantics kept: a process that dies loses its line requests: when a client connection closes (the process
exited, was killed, or released the line), every line it drove is released and returns to its pull level (the
vehicle's /OE pull-up: outputs off). A stopped (SIGSTOP) process keeps its connection and so its lines, as the
kernel keeps the requests of a stopped process.

Processes pick the server up through the environment: :data:`SOCKET_ENV` names the socket; with it set,
:func:`open_shared_bus` and :func:`open_shared_line` are what the ESC node and the guard use instead of
``smbus2.SMBus(n)`` and ``gpiod`` (see :func:`hindrax_common.transport.i2c.open_smbus` and
:func:`hindrax_bringup.guard.outputs_off.open_output_enable`).

Why our own code: ``multiprocessing.connection`` (standard library) carries the calls; nothing on PyPI emulates an
I2C adapter and a GPIO chip shared across processes."""
from __future__ import annotations

import contextlib
import os
import threading
from multiprocessing.connection import Client, Listener
from typing import Any, Mapping

from .socket_i2c import SMBUS_METHODS, forward_smbus_methods

__all__ = ["SOCKET_ENV", "EmulationServer", "SharedI2CBus", "SharedGpioLine", "open_shared_bus", "open_shared_line"]

#: environment variable naming the server's Unix socket
SOCKET_ENV = "HINDRAX_EMULATION_SOCKET"

_LINE_METHODS = ("set_high", "is_high", "release", "release_problem")


class EmulationServer:
    """Serves ``bus`` and ``lines`` (name -> EmulatedGpioLine) on the Unix socket ``path``, a thread per client.

    ``lock`` (optional) is held around every bus call (share it with whatever else drives the emulators).
    :meth:`close` stops accepting and removes the socket."""

    def __init__(self, path: str, bus: Any = None, lines: Mapping[str, Any] | None = None,
                 lock: threading.Lock | None = None) -> None:
        self.bus = bus
        self.lines = dict(lines or {})
        self.lock = lock or threading.Lock()
        self.path = path
        self._listener = Listener(path, family="AF_UNIX")
        self._thread = threading.Thread(target=self._accept, name="emulation-accept", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop accepting connections and remove the socket file."""
        with contextlib.suppress(OSError):
            self._listener.close()
        with contextlib.suppress(OSError):
            os.unlink(self.path)

    def _accept(self) -> None:
        while True:
            try:
                conn = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._serve, args=(conn,), name="emulation-client", daemon=True).start()

    def _serve(self, conn: Any) -> None:
        driven: set[str] = set()
        try:
            while True:
                try:
                    target, name, args = conn.recv()
                except (EOFError, OSError):
                    return
                try:
                    if target == "i2c" and name in SMBUS_METHODS and self.bus is not None:
                        with self.lock:
                            result = getattr(self.bus, name)(*args)
                    elif target in self.lines and name in _LINE_METHODS:
                        result = getattr(self.lines[target], name)(*args)
                        if name == "set_high":
                            driven.add(target)
                        elif name == "release":
                            driven.discard(target)
                    else:
                        raise OSError(19, f"no such emulated device/method: {target}.{name}")  # ENODEV
                    reply = (True, result)
                except OSError as exc:
                    reply = (False, (exc.errno, str(exc)))
                except ValueError as exc:
                    reply = (False, (22, str(exc)))  # EINVAL
                try:
                    conn.send(reply)
                except OSError:
                    return
        finally:
            for name in driven:  # the client is gone: the kernel frees its line requests
                self.lines[name].release()
            conn.close()


class _Client:
    def __init__(self, path: str) -> None:
        try:
            self._conn = Client(path, family="AF_UNIX")
        except (OSError, EOFError) as exc:
            raise OSError(getattr(exc, "errno", None) or 2, f"emulation server {path}: {exc}") from exc
        self._lock = threading.Lock()

    def _call(self, target: str, name: str, *args: Any) -> Any:
        with self._lock:
            try:
                self._conn.send((target, name, args))
                ok, value = self._conn.recv()
            except (EOFError, OSError) as exc:
                raise OSError(5, f"emulation server gone: {exc}") from exc  # EIO
        if ok:
            return value
        raise OSError(*value)

    def close(self) -> None:
        """Close the connection (lines this client drove are released by the server)."""
        with contextlib.suppress(OSError):
            self._conn.close()


@forward_smbus_methods
class SharedI2CBus(_Client):
    """Client side of :class:`EmulationServer`'s bus: the ``smbus2.SMBus`` methods the drivers use.

    Raises ``OSError`` with the emulator's errno (121 for a NACK), as ``smbus2`` does."""

    def _bus_call(self, name: str, *args: Any) -> Any:
        return self._call("i2c", name, *args)


class SharedGpioLine(_Client):
    """Client side of one of :class:`EmulationServer`'s lines (``set_high``, ``is_high``, ``release``)."""

    def __init__(self, path: str, name: str, initial_high: bool | None = None) -> None:
        super().__init__(path)
        self.name = name
        if initial_high is not None:
            self.set_high(initial_high)

    def set_high(self, high: bool) -> None:
        self._call(self.name, "set_high", bool(high))

    def is_high(self) -> bool:
        return bool(self._call(self.name, "is_high"))

    def release(self) -> None:
        with contextlib.suppress(OSError):
            self._call(self.name, "release")
        self.close()

    def release_problem(self) -> str:
        return str(self._call(self.name, "release_problem"))


def open_shared_bus() -> SharedI2CBus | None:
    """A :class:`SharedI2CBus` when :data:`SOCKET_ENV` is set, else None (use the real bus)."""
    path = os.environ.get(SOCKET_ENV)
    return SharedI2CBus(path) if path else None


def open_shared_line(name: str, initial_high: bool) -> SharedGpioLine | None:
    """A :class:`SharedGpioLine` named ``name`` when :data:`SOCKET_ENV` is set, else None."""
    path = os.environ.get(SOCKET_ENV)
    return SharedGpioLine(path, name, initial_high) if path else None
