"""An emulated I2C bus served to other processes over a Unix socket: ``/dev/i2c-N`` for a launch layout on a
machine without the hardware (docs/deployment.md §9).

A driver started as its own process (the vehicle's launch layout: ``ros2 launch``, or the project's
:class:`~.process_runner.ProcessRunner` in the pool-day test and ``make bench``) opens its bus with
:func:`~hindrax_common.transport.i2c.open_smbus`. When the environment variable :data:`SOCKET_ENV` names a socket, that
function returns a :class:`SocketI2CBus` connected to it instead of ``smbus2.SMBus(n)``; an :class:`I2CSocketServer` in
another process serves an :class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` (the register-exact MS5837,
ICM-20948 and PCA9685 emulators) there. A transaction is then one request and one answer on the socket (two system calls
and a pickle each way), standing in for the ``ioctl`` of a real ``smbus2.SMBus``.

The failures a driver sees are a real bus's: a socket that does not exist (or refuses) is ``OSError`` from the open,
as a missing ``/dev/i2c-N`` (the bus is "absent"); an address nobody acknowledges is ``OSError`` 121 from the
emulator; a server that goes away mid-run makes every later call fail with ``OSError`` ENODEV, as an i2c-dev
adapter that was removed, until the driver opens the bus again. Never set :data:`SOCKET_ENV` on the vehicle.

Why our own code: the processes must share one emulated bus (the simulator reads the PCA9685's registers the ESC
process writes), and there is no I2C-over-socket adapter in smbus2 or the kernel; ``multiprocessing.connection``
does the framing."""
from __future__ import annotations

import contextlib
import ctypes
import errno
import socket
import threading
from multiprocessing.connection import Client, Listener
from typing import Any

from smbus2 import i2c_msg

from ..process.scheduling import set_this_thread
from .emulated_i2c import I2C_M_RD

__all__ = ["SOCKET_ENV", "SMBUS_METHODS", "I2CSocketServer", "SocketI2CBus", "forward_smbus_methods"]

#: environment variable: path of an :class:`I2CSocketServer` socket that ``open_smbus`` connects to instead of
#: opening ``/dev/i2c-N`` (tests and benchmarks only)
SOCKET_ENV = "HINDRAX_I2C_SOCKET"
#: the ``smbus2.SMBus`` methods a client forwards to the emulated bus
SMBUS_METHODS = ("write_quick", "write_byte", "read_byte", "write_byte_data", "read_byte_data",
                 "write_word_data", "read_word_data", "write_i2c_block_data", "read_i2c_block_data")


def forward_smbus_methods(cls: type) -> type:
    """Class decorator: each of :data:`SMBUS_METHODS` on ``cls`` as
    ``self._bus_call(name, addr, *args)`` (``force`` ignored; block data sent as a list)."""
    def forward(name: str) -> Any:
        def method(self: Any, addr: int, *args: Any, force: Any = None) -> Any:
            return self._bus_call(name, addr, *(a if isinstance(a, int) else list(a) for a in args))
        method.__name__ = method.__qualname__ = name
        return method
    for name in SMBUS_METHODS:
        setattr(cls, name, forward(name))
    return cls


@forward_smbus_methods
class SocketI2CBus:
    """Client side of :class:`I2CSocketServer`: the ``smbus2.SMBus`` methods the drivers use, forwarded.

    Raises ``OSError`` from the constructor when nobody serves ``path`` (ENOENT, ECONNREFUSED), ``OSError`` with the
    emulator's errno for a NACK (as ``smbus2`` does), and ``OSError`` ENODEV once the connection is lost."""

    def __init__(self, path: str) -> None:
        try:
            self._conn = Client(path, family="AF_UNIX")
        except OSError as exc:
            raise OSError(exc.errno, f"emulated I2C bus {path}: {exc.strerror or exc}") from exc
        self.path = path
        self._lock = threading.Lock()
        self._lost = False

    def _bus_call(self, name: str, *args: Any) -> Any:
        with self._lock:
            if self._lost:
                raise OSError(errno.ENODEV, f"emulated I2C bus {self.path}: connection lost")
            try:
                self._conn.send((name, args))
                ok, value = self._conn.recv()
            except (EOFError, OSError) as exc:
                self._lost = True
                raise OSError(errno.ENODEV, f"emulated I2C bus {self.path}: connection lost ({exc!r})") from exc
        if ok:
            return value
        raise OSError(*value)

    def i2c_rdwr(self, *i2c_msgs):
        """``smbus2.i2c_msg`` transfers (ctypes, not picklable) sent as (address, flags, bytes or
        length); the read messages' buffers are filled from the answer, as the kernel fills them."""
        spec = [(int(m.addr), int(m.flags), int(m.len) if m.flags & I2C_M_RD else ctypes.string_at(m.buf, m.len))
                for m in i2c_msgs]
        reads = (m for m in i2c_msgs if m.flags & I2C_M_RD)
        for m, data in zip(reads, self._bus_call("i2c_rdwr", spec)):
            ctypes.memmove(m.buf, data, m.len)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._conn.close()


def _rdwr(bus: Any, spec: list) -> list[bytes]:
    """Run a :meth:`SocketI2CBus.i2c_rdwr` request on ``bus``: its messages as ``smbus2.i2c_msg``;
    returns what the read messages read, in order."""
    msgs = [i2c_msg.read(addr, data) if flags & I2C_M_RD else i2c_msg.write(addr, data) for addr, flags, data in spec]
    bus.i2c_rdwr(*msgs)
    return [bytes(m) for m in msgs if m.flags & I2C_M_RD]


class I2CSocketServer:
    """Serves ``bus`` (an EmulatedI2CBus, or any object with its methods) to :class:`SocketI2CBus` clients at
    ``path``, one thread per connection; every call holds ``lock`` (share it with whatever else drives the
    emulators, e.g. a simulator's stepping). ``realtime_priority`` > 0: the serving threads alone run ``SCHED_FIFO``
    at it (:func:`hindrax_common.process.scheduling.set_this_thread`), so that they answer within the drivers' bus
    deadlines on a loaded machine, as the hardware does. :meth:`close` stops serving: the socket file goes and every
    client's next call fails (a removed adapter)."""

    def __init__(self, bus: Any, path: str, lock: threading.Lock | None = None, realtime_priority: int = 0) -> None:
        self.bus, self.lock, self.path = bus, lock or threading.Lock(), path
        #: ``SCHED_FIFO`` priority of the serving threads (0: they keep the process's scheduling); '' or why refused
        self.realtime_priority, self.scheduling_refused = int(realtime_priority), ""
        self._listener = Listener(path, family="AF_UNIX")
        self._conns: list[Any] = []
        self._conns_lock = threading.Lock()
        self._closed = False
        threading.Thread(target=self._accept, name="i2c-socket-accept", daemon=True).start()

    def close(self) -> None:
        """Stop accepting connections, drop the connected clients and remove the socket file."""
        self._closed = True
        self._listener.close()
        with self._conns_lock:
            conns, self._conns = self._conns, []
        for conn in conns:
            try:  # wake the serving thread and the client: shut the socket down, then close it
                with socket.fromfd(conn.fileno(), socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                    sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            with contextlib.suppress(OSError):
                conn.close()

    def _accept(self) -> None:
        self.scheduling_refused = set_this_thread(self.realtime_priority)  # the serving threads inherit it
        while True:
            try:
                conn = self._listener.accept()
            except OSError:
                return
            with self._conns_lock:
                if self._closed:
                    conn.close()
                    return
                self._conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), name="i2c-socket", daemon=True).start()

    def _serve(self, conn: Any) -> None:
        while True:
            try:
                name, args = conn.recv()
            except (EOFError, OSError):
                return
            try:
                with self.lock:
                    call = getattr(self.bus, name) if name != "i2c_rdwr" else None
                    result = call(*args) if call else _rdwr(self.bus, *args)
                reply = (True, result)
            except OSError as exc:
                reply = (False, (exc.errno, str(exc)))
            try:
                conn.send(reply)
            except OSError:
                return
