"""The ESC's chip I/O worker: the one thread that owns the PCA9685's bus (no ROS).

The ESC node's executor thread sends ``esc/heartbeat`` and runs the safety tick; it never waits on the bus. It posts
what the chip should hold (:meth:`ChipWorker.post`: a :class:`ChipJob`) and, at its next callback, takes what the
chip confirmed (:meth:`ChipWorker.results`: :class:`ChipResult`). The worker runs the jobs in order on an
:class:`~.chip.EscChip`, opening the bus first when it is not open.

Queue rules (one test each in ``test/test_esc_worker.py``):

* the newest thrust write replaces a pending one (a backlog of commands behind a slow bus costs one write);
* a neutral or a configure is never dropped nor overtaken: the thrust writes pending before it are dropped, those
  posted after it run after it (a disarm reaches the chip before any later thrust);
* a read-back or a configure already pending is not queued twice.

A bus call that has not returned after ``call_timeout_s`` is a fault the node acts on (:meth:`ChipWorker.stuck_s`; the
heartbeat then says ERROR and the output guard's /OE stops the outputs, docs/watchdog.md): the worker itself cannot
abandon a call that hangs. ``threaded=False`` runs each job in the posting thread instead (a lock-step simulation, whose
chip writes must land at the simulated instant of the command); the jobs, their order and their results are the same."""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from hindrax_common.transport.i2c import I2CDevice, I2CError
from .chip import EscChip
from .core import CONFIGURE, NEUTRAL, READBACK, WRITE

__all__ = ["BUS_CALL_TIMEOUT_S", "CONFIGURE", "WRITE", "NEUTRAL", "READBACK", "ChipJob", "ChipResult", "ChipWorker"]

#: the default of ``esc.bus_call_timeout_s`` (the vehicle file sets it): a bus call that has not returned after this
#: long is a fault, s: the output guard's ESC-heartbeat timeout is 0.2 s (``esc.guard_heartbeat_timeout_s``), so the
#: ERROR heartbeat that follows at the next 25 Hz beat (40 ms) reaches it no later than silence would; a PCA9685 block
#: write takes 0.9 ms at 400 kHz, an emulated-bus round trip 7-10 ms on a loaded machine
BUS_CALL_TIMEOUT_S = 0.15



@dataclass
class ChipJob:
    """What the chip should do: ``kind`` (:data:`.core.CONFIGURE`, ``WRITE``, ``NEUTRAL``, ``READBACK``), the thruster
    widths ``widths_us`` (n,) and the lights' ``lights_us`` (us; unused by a read-back), the ``output_state`` the widths
    give, and ``reason`` (text the node reports with it). ``seq`` is set by :meth:`ChipWorker.post` (increasing)."""

    kind: str
    widths_us: np.ndarray | None = None
    lights_us: float = 0.0
    output_state: int = 0
    reason: str = ""
    seq: int = 0


@dataclass
class ChipResult:
    """A job done: ``error`` ('' or the :class:`~hindrax_common.transport.i2c.I2CError` or open failure text),
    ``no_bus`` (the bus could not be opened), ``mismatch`` ('' or what the read-back found), ``wrote`` (the widths
    went to the chip), ``written_us`` (n,) the thruster widths on the chip decoded from the counts (after the job),
    ``duration_s`` (wall time of the job, s)."""

    job: ChipJob
    error: str = ""
    no_bus: bool = False
    mismatch: str = ""
    wrote: bool = False
    written_us: np.ndarray | None = None
    duration_s: float = 0.0


class _TimedBus:
    """The bus, with the start time of the call in progress kept for :meth:`ChipWorker.stuck_s`."""

    def __init__(self, bus: Any, worker: "ChipWorker") -> None:
        self._bus, self._worker = bus, worker

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._bus, name)
        if not callable(attr):
            return attr

        def call(*args: Any, **kwargs: Any) -> Any:
            self._worker._call_since = self._worker.clock()
            try:
                return attr(*args, **kwargs)
            finally:
                self._worker._call_since = None
        return call


class ChipWorker:
    """Runs :class:`ChipJob` on ``chip`` (module docstring).

    ``open_bus()`` returns an SMBus-like object or raises ``OSError``/``ImportError`` (called in the worker when the
    chip has no device); ``raw_tap`` is the device's raw tap; ``clock``: steady time, s."""

    def __init__(self, chip: EscChip, open_bus: Callable[[], Any], raw_tap: Any = None, *, threaded: bool = True,
                 call_timeout_s: float = BUS_CALL_TIMEOUT_S, clock: Callable[[], float] = time.monotonic) -> None:
        self.chip, self._open_bus, self._raw_tap = chip, open_bus, raw_tap
        self.threaded, self.call_timeout_s, self.clock = bool(threaded), float(call_timeout_s), clock
        self._pending: deque[ChipJob] = deque()
        self._results: deque[ChipResult] = deque()
        self._cv = threading.Condition()
        self._running: ChipJob | None = None
        self._call_since: float | None = None
        self._checked_at: float | None = None  # the clock at the previous stuck_s() call
        self._deferred_since: float | None = None  # the call whose judgement one late check put off
        self._seq = 0
        self._stop = False
        self._thread: threading.Thread | None = None
        if self.threaded:
            self._thread = threading.Thread(target=self._loop, name="esc-chip-io", daemon=True)
            self._thread.start()

    def use_bus(self, bus: Any) -> None:
        """Give the chip its device on ``bus`` (an injected bus; before the first job)."""
        self.chip.device = I2CDevice(_TimedBus(bus, self), self.chip.address, "pca9685", raw_tap=self._raw_tap)

    # ------------------------------------------------------------------ the node's side
    def post(self, job: ChipJob) -> ChipJob:
        """Queue ``job`` by the queue rules (module docstring); returns it with its ``seq``. Never waits on the bus
        (with ``threaded=False`` it runs the job before returning)."""
        with self._cv:
            self._seq += 1
            job.seq = self._seq
            pending = self._pending
            if job.kind == WRITE:
                if pending and pending[-1].kind == WRITE:
                    pending.pop()  # the newest command wins
                pending.append(job)
            elif job.kind == READBACK:
                if not any(j.kind in (READBACK, CONFIGURE) for j in pending):
                    pending.append(job)
            elif job.kind == NEUTRAL:  # thrust before it is dropped; the neutral itself is never dropped
                kept = [j for j in pending if j.kind in (CONFIGURE, READBACK)]
                pending.clear()
                pending.extend(kept + [job])
            elif not any(j.kind == CONFIGURE for j in pending):  # CONFIGURE writes neutral first, then reads back
                pending.clear()
                pending.append(job)
            self._cv.notify()
        if not self.threaded:
            self.run_pending()
        elif job.kind == NEUTRAL:
            time.sleep(0)  # release the GIL now: the worker writes the neutral without waiting for a switch interval
        return job

    def results(self) -> list[ChipResult]:
        """The results since the last call, in job order."""
        with self._cv:
            out = list(self._results)
            self._results.clear()
        return out

    def pending(self, kind: str | None = None) -> bool:
        """True while a job (of ``kind``, or any) is queued or running."""
        with self._cv:
            jobs = list(self._pending) + ([self._running] if self._running is not None else [])
        return any(kind is None or j.kind == kind for j in jobs)

    def stuck_s(self) -> float:
        """How long the bus call in progress has run, s, when that is longer than ``call_timeout_s``; else 0.

        Called regularly by the node (every tick and command). When this caller was itself away for longer than
        ``call_timeout_s`` since its previous call (its process not scheduled: the worker thread, in the same
        process, had no turn either, and its reply may be waiting in the socket), the first overdue verdict on a
        call is put off to the next call; a second one is not. A bus that hangs is so reported at most one check
        later, and a process that was merely not scheduled is not taken for a dead bus (an ESC process stopped for
        0.8 s on a loaded machine was, and disarmed)."""
        now = self.clock()
        previous, self._checked_at = self._checked_at, now
        since = self._call_since
        if since is None:
            return 0.0
        age = now - since
        if age <= self.call_timeout_s:
            return 0.0
        if previous is not None and now - previous > self.call_timeout_s and self._deferred_since != since:
            self._deferred_since = since
            return 0.0
        return age

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no job is queued or running (a shutdown's neutral; tests). False when ``timeout_s`` passed."""
        end = time.monotonic() + timeout_s
        with self._cv:
            while self._pending or self._running is not None:
                left = end - time.monotonic()
                if left <= 0.0:
                    return False
                self._cv.wait(min(left, 0.05))
        return True

    def stop(self, timeout_s: float = 1.0) -> None:
        """Stop the thread after the queued jobs (waits up to ``timeout_s``; a hung call is left behind)."""
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    # ------------------------------------------------------------------ the worker's side
    def _loop(self) -> None:
        while True:
            with self._cv:
                while not self._pending and not self._stop:
                    self._cv.wait()
                if not self._pending:
                    return
            self.run_pending()

    def run_pending(self) -> None:
        """Run the queued jobs in order (the worker thread; the poster with ``threaded=False``)."""
        while True:
            with self._cv:
                if not self._pending or self._running is not None:
                    return
                job = self._running = self._pending.popleft()
            result = self._run(job)
            with self._cv:
                self._running = None
                self._results.append(result)
                self._cv.notify_all()

    def _run(self, job: ChipJob) -> ChipResult:
        start = time.monotonic()
        result = ChipResult(job)
        chip = self.chip
        try:
            if chip.device is None:
                try:
                    self.use_bus(self._open_bus())
                except (OSError, ImportError) as exc:
                    result.error, result.no_bus = f"no I2C bus: {exc}", True
                    return result
            if job.kind == CONFIGURE:
                result.mismatch = chip.configure(job.widths_us, job.lights_us)
                result.wrote = True
            elif job.kind == READBACK:
                chip.raw.begin_batch()  # raw/pca9685: the reads join the 0.1 s batches of the writes
                try:
                    result.mismatch = chip.readback_mismatch()
                finally:
                    chip.raw.flush()
            else:
                if job.kind == NEUTRAL:
                    chip.forget()  # neutral must reach the chip even if it is believed to be there
                result.wrote = chip.write(job.widths_us, job.lights_us)
        except I2CError as exc:
            chip.forget()
            result.error = str(exc)
        finally:
            result.written_us = chip.written.copy()
            result.duration_s = time.monotonic() - start
        return result
