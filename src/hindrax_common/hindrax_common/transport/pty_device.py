"""Serve an I/O-free byte-stream device emulator on a pseudo-terminal; the emulators' fault helper.

What every serial device emulator in this package shares (docs/architecture.md §2, §6):
:class:`PtyDevice` runs one (:class:`ByteStreamEmulator`) behind a Linux pseudo-terminal, so the
*real* pyserial code path of a driver runs against it; :class:`StreamFaults` is the fault injection
of the DVL-75 and Ping1D emulators; :class:`PeriodicSchedule` gives both drift-free output instants.

Why our own code: pyserial's ``loop://`` and ``socket://`` URL handlers do not exercise the
termios, select and fd code path a real ``/dev/ttyUSB*`` uses, and ``socat`` would be an external
process dependency.  ``os.openpty`` + ``tty.setraw`` gives a real tty with no extra dependency.

Linux/POSIX only (pty, termios)."""

from __future__ import annotations

import contextlib
import errno
import math
import os
import random
import select
import shutil
import tempfile
import threading
import time
import tty
from typing import Callable, Iterable, Optional, Protocol, TypeVar, runtime_checkable

from ..process.scheduling import set_this_thread

__all__ = ["ByteStreamEmulator", "StreamFaults", "PeriodicSchedule", "PtyDevice"]

T = TypeVar("T")
_TICK_TOLERANCE_S = 1e-9


@runtime_checkable
class ByteStreamEmulator(Protocol):
    """Contract of an I/O-free serial device emulator (docs/architecture.md §2 layer 2).

    ``feed_host_bytes(data)`` receives bytes the host wrote; ``poll(t_s)`` returns the bytes the
    device sends by time ``t_s`` (seconds on the emulator's clock, non-decreasing between calls). Optional:
    ``next_output_s()``: when the next unprompted output is due (-inf: now; None: not before host bytes)."""

    def feed_host_bytes(self, data: bytes) -> None:  # pragma: no cover - protocol
        ...

    def poll(self, t_s: float) -> bytes:  # pragma: no cover - protocol
        ...


class StreamFaults:
    """Fault injection shared by the byte-stream device emulators, part of their API
    (docs/architecture.md §2). Thread-safe: test code may call it while a PtyDevice thread polls.

    Per-message faults are queued and consumed, in this order of precedence, by the next messages
    passed through :meth:`apply`: drop, truncate, corrupt checksum.  Garbage goes out first at the
    next :meth:`transmit` (the emulator calls it at every poll).

    Args:
        garbage_alphabet: bytes random garbage is drawn from (the DVL emulator uses 0x80-0xFF, i.e.
            line noise that cannot contain ``$`` or LF, so the count a framer reports is exact).
        seed: seed of the private random generator (deterministic tests)."""

    def __init__(self, garbage_alphabet: bytes = bytes(range(256)), seed: int = 0) -> None:
        if not garbage_alphabet:
            raise ValueError("garbage_alphabet must not be empty")
        self._alphabet = bytes(garbage_alphabet)
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._garbage = bytearray()
        self._drop = 0
        self._truncate = 0
        self._corrupt = 0
        self._stuck = False
        self._held: object = None
        self._has_held = False
        self._disconnected = False

    # --- queueing ---------------------------------------------------------------------------
    def inject_garbage(self, data: Optional[bytes] = None, n_bytes: int = 16) -> bytes:
        """Queue garbage bytes for the next poll: ``data`` verbatim, or ``n_bytes`` random bytes
        from the alphabet.  Returns the queued bytes."""
        with self._lock:
            if data is None:
                if n_bytes < 0:
                    raise ValueError("n_bytes must be >= 0")
                data = bytes(self._rng.choice(self._alphabet) for _ in range(n_bytes))
            self._garbage += data
            return bytes(data)

    def drop(self, n_messages: int = 1) -> None:
        """Silently drop the next ``n_messages`` messages (lost lines/frames)."""
        with self._lock:
            self._drop += max(0, int(n_messages))

    def truncate(self, n_messages: int = 1) -> None:
        """Send only the first half of the next ``n_messages`` messages (no terminator), so they
        merge with whatever follows."""
        with self._lock:
            self._truncate += max(0, int(n_messages))

    def corrupt_checksum(self, n_messages: int = 1) -> None:
        """Send the next ``n_messages`` messages with a wrong checksum."""
        with self._lock:
            self._corrupt += max(0, int(n_messages))

    def set_stuck(self, stuck: bool) -> None:
        """While True, :meth:`hold` keeps returning the value it returned last (stuck sensor)."""
        with self._lock:
            self._stuck = bool(stuck)

    def set_disconnected(self, disconnected: bool) -> None:
        """While True the device is silent and deaf (emulators discard input and output)."""
        with self._lock:
            self._disconnected = bool(disconnected)

    @property
    def disconnected(self) -> bool:
        """True while the device is silent (see :meth:`set_disconnected`)."""
        return self._disconnected

    # --- consumption (called by emulators) ------------------------------------------------------
    def hold(self, value: T) -> T:
        """Return ``value``, or while stuck the last value returned before the fault began."""
        with self._lock:
            if self._stuck and self._has_held:
                return self._held  # type: ignore[return-value]
            self._held, self._has_held = value, True
            return value

    def transmit(self, messages: Iterable[bytes], corrupt_checksum: Callable[[bytes], bytes]) -> bytes:
        """The bytes a device sends at one poll: the queued garbage, then each of ``messages``
        through :meth:`apply`; b"" while disconnected (the garbage is taken all the same)."""
        with self._lock:
            garbage = bytes(self._garbage)
            self._garbage.clear()
        if self.disconnected:
            return b""
        return garbage + b"".join(self.apply(m, corrupt_checksum) for m in messages)

    def apply(self, message: bytes, corrupt_checksum: Callable[[bytes], bytes]) -> bytes:
        """Apply the queued per-message fault (if any) to one outgoing message.

        Args:
            message: the complete message as the device would send it.
            corrupt_checksum: protocol-specific function returning ``message`` with a wrong checksum.
        Returns the bytes to actually send (b"" when dropped)."""
        with self._lock:
            if self._drop:
                self._drop -= 1
                return b""
            if self._truncate:
                self._truncate -= 1
                return message[: max(1, len(message) // 2)]
            if self._corrupt:
                self._corrupt -= 1
                return corrupt_checksum(message)
            return message


class PeriodicSchedule:
    """Drift-free periodic instants ``anchor + k * period`` for emulators driven by ``poll(t_s)``.

    Computing each instant from an anchor (instead of adding the period repeatedly) keeps, e.g.,
    exactly 20 messages per second at 20 Hz over any run length.

    Args:
        period_s: tick period, s (> 0)."""

    def __init__(self, period_s: float) -> None:
        self._period_s = 1.0
        self.set_period(period_s)
        self._anchor_s: Optional[float] = None
        self._k = 0

    @property
    def period_s(self) -> float:
        """Current period, s."""
        return self._period_s

    def restart(self, t0_s: float, first_tick_in_periods: int = 1) -> None:
        """Next tick at ``t0_s + first_tick_in_periods * period``."""
        self._anchor_s, self._k = float(t0_s), int(first_tick_in_periods)

    def set_period(self, period_s: float) -> None:
        """Change the period; the next tick already scheduled is kept, later ones use the new one.

        Raises ``ValueError``: non-positive or non-finite period."""
        if not (period_s > 0 and period_s < float("inf")):
            raise ValueError(f"period must be positive and finite, got {period_s}")
        if period_s != self._period_s and getattr(self, "_anchor_s", None) is not None:
            self._anchor_s = self._anchor_s + self._k * self._period_s
            self._k = 0
        self._period_s = float(period_s)

    def next_s(self) -> Optional[float]:
        """The next tick instant (None before :meth:`restart`)."""
        return None if self._anchor_s is None else self._anchor_s + self._k * self._period_s

    def due(self, t_s: float, max_backlog_s: float = float("inf")) -> list:
        """Pop every tick instant <= ``t_s`` (within 1 ns, so float rounding of ``k * period`` never
        moves a tick past a poll at the same nominal instant); ticks older than
        ``t_s - max_backlog_s`` are skipped.  Returns [] before :meth:`restart`."""
        if self._anchor_s is None:
            return []
        out = []
        next_t = self._anchor_s + self._k * self._period_s
        if t_s - next_t > max_backlog_s:
            self._k += max(0, math.floor((t_s - max_backlog_s - next_t) / self._period_s))
        while True:
            next_t = self._anchor_s + self._k * self._period_s
            if next_t > t_s + _TICK_TOLERANCE_S:
                return out
            out.append(next_t)
            self._k += 1


class PtyDevice:
    """Run a :class:`ByteStreamEmulator` behind a pseudo-terminal in a background thread.

    The thread loops every ``poll_period_s`` (wall time), or sooner when the host writes or the emulator's
    ``next_output_s()`` (:class:`ByteStreamEmulator`) falls due: it reads whatever the host wrote to the
    slave side and passes it to ``emulator.feed_host_bytes``, then writes ``emulator.poll(clock())``
    to the master side.  Output that cannot be written (nobody reading, tty buffer full) is dropped
    and counted in :attr:`bytes_dropped`, as on a real UART.  Every emulator call happens with
    :attr:`lock` held, so test code can mutate the emulator safely with ``with device.lock: ...``.
    With ``start=False`` the caller drives the device instead, one :meth:`service` call per tick of
    its own clock (lock-step with a simulator).

    Args:
        emulator: the device emulator.
        clock: callable returning the emulator time in s (default ``time.monotonic``; a simulator
            passes its simulation clock).
        poll_period_s: the longest wall-clock wait of the service loop (a fault set by test code goes out within it).
        link_name: file name of the stable symlink inside a private temporary directory.
        start: start the service thread immediately.
        realtime_priority: > 0: the service thread alone runs ``SCHED_FIFO`` at it
            (:func:`hindrax_common.process.scheduling.set_this_thread`): bytes on time on a loaded machine, as a UART's.
    Raises ``OSError``: if a pty cannot be created."""

    def __init__(self, emulator: ByteStreamEmulator, clock: Callable[[], float] = time.monotonic,
                 poll_period_s: float = 0.002, link_name: str = "tty", start: bool = True,
                 realtime_priority: int = 0) -> None:
        if poll_period_s <= 0:
            raise ValueError("poll_period_s must be positive")
        self.emulator = emulator
        self.clock = clock
        self.poll_period_s = float(poll_period_s)
        #: SCHED_FIFO priority of the service thread (0: the process's); '' or why it was refused.
        self.realtime_priority, self.scheduling_refused = int(realtime_priority), ""
        #: Lock held around every emulator call.
        self.lock = threading.RLock()
        self._dir = tempfile.mkdtemp(prefix="hindrax_pty_")
        self._link = os.path.join(self._dir, link_name)
        self._fd_lock = threading.Lock()
        self._master: Optional[int] = None
        self._slave: Optional[int] = None
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        #: Bytes delivered to / received from the host, and output bytes dropped.
        self.bytes_to_host = 0
        self.bytes_from_host = 0
        self.bytes_dropped = 0
        #: Number of completed :meth:`reconnect` calls.
        self.reconnects = 0
        #: The last exception the emulator raised in the service thread (which keeps running).
        self.last_error: Optional[str] = None
        self._open_pty()
        if start:
            self.start()

    # --- pty management ---------------------------------------------------------------------------
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        name = os.ttyname(slave)
        tmp = self._link + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(name, tmp)
        os.replace(tmp, self._link)
        with self._fd_lock:
            self._master, self._slave = master, slave

    def _close_pty(self) -> None:
        with self._fd_lock:
            master, slave = self._master, self._slave
            self._master = self._slave = None
        if os.path.lexists(self._link):
            os.unlink(self._link)
        for fd in (master, slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)

    @property
    def path(self) -> str:
        """Stable device path the driver opens: a symlink in a private temporary directory,
        re-pointed to the new pty at each :meth:`reconnect`."""
        return self._link

    @property
    def connected(self) -> bool:
        """True while the pty exists."""
        return self._master is not None

    def disconnect(self) -> None:
        """Make the device disappear: close the pty (the host's reads fail with an I/O error) and
        remove the symlink (re-opening fails) until :meth:`reconnect`."""
        self._close_pty()

    def reconnect(self) -> None:
        """Bring the device back on a new pty behind the same :attr:`path`.  No-op if connected."""
        if self._master is None:
            self._open_pty()
            self.reconnects += 1

    # --- service thread ---------------------------------------------------------------------------
    @property
    def threaded(self) -> bool:
        """True while the service thread drives the device (then :meth:`service` is refused)."""
        return self._thread is not None

    def start(self) -> None:
        """Start the service thread (idempotent)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="PtyDevice", daemon=True)
            self._thread.start()

    def _run(self) -> None:
        self.scheduling_refused = set_this_thread(self.realtime_priority)
        while not self._stop.is_set():
            if not self._cycle(self._wait_s(), None, True):
                self._stop.wait(self.poll_period_s)

    def _wait_s(self) -> float:
        """``poll_period_s``, or until the emulator's ``next_output_s()`` (a 10 Hz DVL: 10-30 loops a second, not 500),
        but not after it raised (:attr:`last_error`). The clock is read only to wait: the first poll's is the boot."""
        next_output = getattr(self.emulator, "next_output_s", None)
        if next_output is None or self.last_error is not None:
            return self.poll_period_s
        with self.lock:
            due = next_output()
        if due is None:
            return self.poll_period_s
        return 0.0 if due == -math.inf else min(self.poll_period_s, max(0.0, due - self.clock()))

    def service(self, t_s: Optional[float] = None, deliver: bool = True) -> int:
        """One service cycle, synchronously and without waiting, for a caller that drives the device itself instead of
        the thread (``start=False``; e.g. a simulator at every clock tick, so the bytes go out at the simulated instant
        they are due): take the bytes the host wrote, then write ``emulator.poll(t_s)`` (``t_s`` None: ``clock()``).
        ``deliver=False`` discards the output (counted in :attr:`bytes_dropped`), as a UART nobody listens to. Returns
        the number of bytes delivered.

        Raises ``RuntimeError``: while the service thread runs (one driver of the emulator at a time)."""
        if self._thread is not None:
            raise RuntimeError("PtyDevice.service() needs start=False: the service thread drives this device")
        before = self.bytes_to_host
        self._cycle(0.0, t_s, deliver)
        return self.bytes_to_host - before

    def _cycle(self, wait_s: float, t_s: Optional[float], deliver: bool) -> bool:
        """Read host bytes (waiting up to ``wait_s`` for the first), feed them, poll, write. False
        while the pty is disconnected."""
        # The fd lock is held across select/read so disconnect() cannot close the fd (and the
        # number be reused by another open) underneath this thread.
        with self._fd_lock:
            master = self._master
            data = self._read_host(master, wait_s) if master is not None else b""
        try:
            with self.lock:
                if data:
                    self.bytes_from_host += len(data)
                    self.emulator.feed_host_bytes(data)
                # disconnected: the output is lost
                out = self.emulator.poll(self.clock() if t_s is None else t_s)
        except Exception as exc:  # noqa: BLE001 - keep serving; the error is reported
            self.last_error = repr(exc)
            return master is not None
        if out:
            if deliver:
                self._write(out)
            else:
                self.bytes_dropped += len(out)
        return master is not None

    def _read_host(self, master: int, wait_s: float) -> bytes:
        try:
            ready, _, _ = select.select([master], [], [], wait_s)
            return os.read(master, 4096) if ready else b""
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EIO, errno.EBADF, errno.EINTR):
                return b""
            raise

    def _write(self, out: bytes) -> None:
        with self._fd_lock:
            master = self._master
            if master is None:
                self.bytes_dropped += len(out)
                return
            view = memoryview(out)
            while view:
                try:
                    n = os.write(master, view)
                except OSError as exc:
                    if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EIO, errno.EBADF):
                        self.bytes_dropped += len(view)
                        return
                    raise
                self.bytes_to_host += n
                view = view[n:]

    def close(self) -> None:
        """Stop the thread, close the pty and remove the temporary directory."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close_pty()
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> "PtyDevice":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

