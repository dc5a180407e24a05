"""The one serial transport used by every serial driver (DVL-75, Ping1D): pyserial + reader thread.

docs/architecture.md §2: transports are injected; serial goes through pyserial device paths or URLs (tests and the
simulator use pseudo-terminals so the real pyserial code path runs).  This module owns a port, reads it
in a background thread and hands byte chunks to a callback; drivers stay protocol-only.

The port is opened with ``serial.serial_for_url`` (a device path such as ``/dev/ttyUSB0`` or a pyserial URL), 8N1 (both
devices use 115200 8N1, docs/devices.md §1.1 and §2.1). When it disappears (read/write error, USB unplug, pty closed)
the reader thread closes it and re-opens it with exponential backoff; ``on_connect()`` after every open lets the driver
resend its start-up commands. Callback exceptions are caught and counted: they never kill the reader thread. The raw tap
lets a node record the traffic (docs/architecture.md §7); :meth:`SerialTransport.pump` reads in the caller's thread
instead (a simulator's lock-step: :mod:`hindrax_sim.hardware`).

Why our own code rather than ``serial.threaded.ReaderThread``: that helper ends its thread on the first
error and has no reconnect, state, or tap."""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

import serial

__all__ = ["SerialTransport", "TransportStatus", "SerialTransportError"]


class SerialTransportError(ConnectionError):
    """Raised by :meth:`SerialTransport.write` when the port is not open or the write fails."""


@dataclass(frozen=True)
class TransportStatus:
    """Snapshot of a :class:`SerialTransport`'s state.

    Attributes:
        port: configured device path or URL.
        connected: True while the port is open.
        last_error: text of the most recent error (open, read, write or callback), None if none yet.
        bytes_rx, bytes_tx: byte counters since construction.
        reconnects: successful re-opens after the first connection.
        open_failures: failed open attempts.
        callback_errors: exceptions raised by user callbacks.
        closed: True after :meth:`SerialTransport.close`.
        bytes_handled: received bytes whose raw tap and ``on_data`` callback have returned (``bytes_rx`` counts
            a chunk as soon as it is read); equal to ``bytes_rx`` when the reader has nothing in hand.
        connections: successful opens (1 + reconnects once connected)."""

    port: str
    connected: bool
    last_error: Optional[str]
    bytes_rx: int
    bytes_tx: int
    reconnects: int
    open_failures: int
    callback_errors: int
    closed: bool
    bytes_handled: int = 0
    connections: int = 0


class SerialTransport:
    """Serial port owner with a reader thread, reconnect with backoff, status and a raw tap.

    Args:
        port: device path or pyserial URL.
        baudrate: bit rate (8N1).
        on_data: called from the reader thread (or :meth:`pump`'s) with each received chunk (bytes).
        on_raw: raw tap ``(direction 'rx'|'tx', data, t_monotonic_s)``; 'tx' is called from the writing thread.
        on_connect: called from the reader thread after every successful (re)open.
        on_disconnect: called with the error text when the port is lost (from the reader thread, or
            from the writing thread when a write fails).
        reconnect_initial_s, reconnect_max_s: backoff bounds between open attempts, s.
        read_timeout_s: pyserial read timeout: the longest a read waits for a first byte, s
            (writes: 1 s). :meth:`close` and :meth:`pump` cancel a read in progress
            (``cancel_read``), so it bounds neither; it sets how often an idle reader wakes. 0.5 s:
            at a device's 10 Hz the reader wakes once a message, 11.2-11.8 wake-ups/s and 0.1-0.2 %
            of a core, against 20.8-21.2 and 0.4-0.5 % at 0.05 s (a pty, 10 s of a 45-byte message
            every 0.1 s, 2026-11-29).
        clock: monotonic clock for tap timestamps (default ``time.monotonic``).
        start: start the reader thread immediately (it opens the port itself).
    Raises ``ValueError``: non-positive timing parameters."""

    def __init__(self, port: str, baudrate: int = 115200, *, on_data: Optional[Callable[[bytes], None]] = None,
                 on_raw: Optional[Callable[[str, bytes, float], None]] = None,
                 on_connect: Optional[Callable[[], None]] = None, on_disconnect: Optional[Callable[[str], None]] = None,
                 reconnect_initial_s: float = 0.05, reconnect_max_s: float = 1.0,
                 read_timeout_s: float = 0.5,
                 clock: Callable[[], float] = time.monotonic, start: bool = True) -> None:
        if reconnect_initial_s <= 0 or reconnect_max_s < reconnect_initial_s:
            raise ValueError("need 0 < reconnect_initial_s <= reconnect_max_s")
        if read_timeout_s <= 0:
            raise ValueError("read_timeout_s must be positive")
        self.port = port
        self.baudrate = int(baudrate)
        self.on_data = on_data
        self.on_raw = on_raw
        self.on_connect = on_connect
        self.on_disconnect = on_disconnect
        self.reconnect_initial_s = float(reconnect_initial_s)
        self.reconnect_max_s = float(reconnect_max_s)
        self.read_timeout_s = float(read_timeout_s)
        self.clock = clock
        self._ser: Optional[serial.SerialBase] = None
        self._ser_lock = threading.Lock()  # guards _ser swaps and writes
        self._port_lost = threading.Condition(self._ser_lock)  # notified at a port's close, close()
        # one reader at a time: the thread, or :meth:`pump`'s caller
        self._read_lock = threading.Lock()
        self._caller_reads = False
        self._stats_lock = threading.Lock()
        self._stop = threading.Event()
        self._connected_event = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._ever_connected = False
        self._last_error: Optional[str] = None
        self._bytes_rx = 0
        self._bytes_handled = 0
        self._connections = 0
        self._bytes_tx = 0
        self._reconnects = 0
        self._open_failures = 0
        self._callback_errors = 0
        self._closed = False
        if start:
            self.start()

    # --- public API -------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the reader thread (idempotent).

        Raises ``SerialTransportError``: after :meth:`close`."""
        if self._closed:
            raise SerialTransportError("transport is closed")
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"SerialTransport({self.port})", daemon=True)
            self._thread.start()

    @property
    def connected(self) -> bool:
        """True while the port is open."""
        return self._connected_event.is_set()

    def status(self) -> TransportStatus:
        """Consistent snapshot of counters and state."""
        with self._stats_lock:
            return TransportStatus(self.port, self.connected, self._last_error, self._bytes_rx, self._bytes_tx,
                                   self._reconnects, self._open_failures, self._callback_errors, self._closed,
                                   self._bytes_handled, self._connections)

    def wait_connected(self, timeout_s: float) -> bool:
        """Block until connected or ``timeout_s`` passes; returns :attr:`connected`."""
        return self._connected_event.wait(timeout_s)

    def pump(self, n_bytes: int, timeout_s: float) -> bool:
        """Read and handle received bytes in the calling thread until ``n_bytes`` (counted since construction, as
        ``status().bytes_handled``) have been through the tap and ``on_data``, or ``timeout_s`` of wall time passed
        without a byte (a read in progress may add ``read_timeout_s``); True when they have. The first call takes the
        reading over from the reader thread for good (it then sleeps until the port is lost)."""
        if not self._caller_reads:
            self._caller_reads = True
            ser = self._ser
            if ser is not None and hasattr(ser, "cancel_read"):
                ser.cancel_read()  # a read in progress returns (what it got is handled as usual)
        deadline = time.monotonic() + max(0.0, timeout_s)
        with self._read_lock:
            while self._bytes_handled < n_bytes and time.monotonic() < deadline:
                ser, before = self._ser, self._bytes_handled
                if ser is None or not self._read_chunk(ser):
                    break
                if self._bytes_handled > before:  # a slow driver is no lost byte
                    deadline = time.monotonic() + max(0.0, timeout_s)
        return self._bytes_handled >= n_bytes

    def write(self, data: bytes) -> int:
        """Write all of ``data``; returns the number of bytes written.  Thread-safe.

        Raises ``SerialTransportError``: port not open, or the write failed (the port is then closed and the reader
        thread reconnects)."""
        data = bytes(data)
        failure: Optional[str] = None
        with self._ser_lock:
            ser = self._ser
            if ser is None:
                raise SerialTransportError(f"{self.port}: not connected")
            try:
                n = ser.write(data)
                ser.flush()
            except (serial.SerialException, OSError) as exc:
                failure = f"write failed: {exc}"
                self._note_error(failure)
                self._close_port_locked()  # the reader thread re-opens with backoff
        if failure is not None:
            if self.on_disconnect is not None:
                self._call(self.on_disconnect, failure)
            raise SerialTransportError(f"{self.port}: {failure}")
        n = len(data) if n is None else int(n)
        with self._stats_lock:
            self._bytes_tx += n
        self._tap("tx", data[:n])
        return n

    def close(self) -> None:
        """Stop the reader thread, close the port, join the thread (idempotent)."""
        self._closed = True
        self._stop.set()
        with self._ser_lock:
            ser = self._ser
            self._port_lost.notify_all()
        if ser is not None and hasattr(ser, "cancel_read"):
            with contextlib.suppress(Exception):  # best effort wake-up of a blocked read
                ser.cancel_read()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._thread = None
        with self._ser_lock:
            self._close_port_locked()

    def __enter__(self) -> "SerialTransport":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- internals --------------------------------------------------------------------------------
    def _note_error(self, text: str) -> None:
        with self._stats_lock:
            self._last_error = text

    def _tap(self, direction: str, data: bytes) -> None:
        if self.on_raw is not None and data:
            self._call(self.on_raw, direction, data, self.clock())

    def _call(self, fn: Callable, *args: Any) -> None:
        try:
            fn(*args)
        except Exception as exc:  # noqa: BLE001 - user callbacks must not kill the thread
            with self._stats_lock:
                self._callback_errors += 1
                self._last_error = f"callback {getattr(fn, '__name__', fn)!s} raised {exc!r}"

    def _close_port_locked(self) -> None:
        ser, self._ser = self._ser, None
        self._connected_event.clear()
        self._port_lost.notify_all()
        if ser is not None:
            with contextlib.suppress(Exception):  # port may already be gone
                ser.close()

    def _open(self) -> bool:
        try:
            ser = serial.serial_for_url(self.port, baudrate=self.baudrate, bytesize=serial.EIGHTBITS,
                                        parity=serial.PARITY_NONE, stopbits=serial.STOPBITS_ONE,
                                        timeout=self.read_timeout_s, write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as exc:
            with self._stats_lock:
                self._open_failures += 1
                self._last_error = f"open failed: {exc}"
            return False
        with self._ser_lock:
            if self._stop.is_set():
                ser.close()
                return False
            self._ser = ser
            with self._stats_lock:
                self._connections += 1  # before `connected` turns True: a watcher never sees the old count then
            self._connected_event.set()
        with self._stats_lock:
            if self._ever_connected:
                self._reconnects += 1
            self._ever_connected = True
        if self.on_connect is not None:
            self._call(self.on_connect)
        return True

    def _run(self) -> None:
        delay = self.reconnect_initial_s
        while not self._stop.is_set():
            with self._ser_lock:
                ser = self._ser
                if ser is not None and self._caller_reads:  # pump() reads; this thread re-opens
                    self._port_lost.wait_for(lambda: self._ser is None or self._stop.is_set())
                    continue
            if ser is None:
                if self._open():
                    delay = self.reconnect_initial_s
                else:
                    self._stop.wait(delay)
                    delay = min(delay * 2.0, self.reconnect_max_s)
                continue
            with self._read_lock:
                ok = self._read_chunk(ser)
            if not ok and not self._stop.is_set():
                self._stop.wait(delay)

    def _read_chunk(self, ser: Any) -> bool:
        """Read what ``ser`` has (up to ``read_timeout_s`` for a first byte) for the tap and ``on_data``; False when the
        read failed (the port is then closed, ``on_disconnect`` told)."""
        try:
            data = ser.read(max(1, ser.in_waiting))
            # the rest of a message: one chunk, one callback
            data += ser.read(ser.in_waiting) if data else b""
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            # TypeError/AttributeError: pyserial internals after a concurrent close().
            if self._stop.is_set():
                return False
            text = f"read failed: {exc}"
            self._note_error(text)
            with self._ser_lock:
                if self._ser is ser:
                    self._close_port_locked()
            if self.on_disconnect is not None:
                self._call(self.on_disconnect, text)
            return False
        if data:
            with self._stats_lock:
                self._bytes_rx += len(data)
            self._tap("rx", data)
            if self.on_data is not None:
                self._call(self.on_data, data)
            with self._stats_lock:
                self._bytes_handled += len(data)
        return True
