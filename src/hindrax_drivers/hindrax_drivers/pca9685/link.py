"""The ESC node's side of its chip worker (no ROS): what it posts to the chip, what the results mean, how they are
reported.

:class:`ChipLink` posts the core's outputs to the :class:`~.worker.ChipWorker` (never waiting on the bus), hands
each result to :meth:`.core.EscCore.chip_result` and acts on the outcome: the diagnostics state and counters, a
re-initialisation after a read-back mismatch, neutral after a failed thrust write. It schedules the chip's
(re)configuration (:meth:`.core.EscCore.retry_due`) and read-back (every ``readback_interval_s``), and turns a bus
call that has not returned within the worker's bound into a lost chip (UNKNOWN: the node's heartbeat says ERROR)."""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from .core import CONFIGURE, NEUTRAL, OUTPUT_NEUTRAL, OUTPUT_UNKNOWN, READBACK, WRITE, EscCore
from .worker import ChipJob, ChipResult, ChipWorker

__all__ = ["ChipLink"]


class ChipLink:
    """``core``: the ESC's :class:`~.core.EscCore`; ``worker``: its :class:`~.worker.ChipWorker`; ``diag``: the
    node's :class:`~hindrax_common.node_support.node_common.DeviceDiagnostics`; ``log_error(text)``; ``lights_us()``:
    the lights' width now, us; ``readback_interval_s``: ``esc.readback_interval_s``. Methods that take results return
    True when a result changed what is on the chip or its state (the node then publishes ``thrusters/pulse_width``)."""

    def __init__(self, core: EscCore, worker: ChipWorker, diag: Any, log_error: Callable[[str], None],
                 lights_us: Callable[[], float], readback_interval_s: float) -> None:
        self.core, self.worker, self.diag, self._log = core, worker, diag, log_error
        self._lights_us, self.readback_interval_s = lights_us, float(readback_interval_s)
        #: (n,) thruster widths on the chip as the worker confirmed them (decoded from the counts written), us
        self.written = np.full(len(core.output.channels), np.nan)
        self.bus_error = ""  # why the bus could not be opened ('' when it is open)
        self.unknown_entries = self.chip_reinits = self.bus_stalls = 0
        self.last_chip_reinit_monotonic: float | None = None
        self.last_readback = -math.inf
        self.closing = False  # shutdown: results are not taken any more (the ROS context may be gone)
        #: (widths, lights) of the last write or neutral posted, while nothing failed since: an identical write (every
        #: tick holds the same widths) is not posted, so the worker thread wakes only for a change
        self._posted: tuple | None = None

    def post(self, kind: str, widths_us: np.ndarray | None = None, output_state: int = OUTPUT_NEUTRAL,
             reason: str = "") -> bool:
        """Post a job (:mod:`.worker`); without a chip thread it has run: its result is taken at once."""
        lights_us = self._lights_us()
        key = None if widths_us is None else (tuple(np.asarray(widths_us, dtype=float).tolist()), lights_us)
        if kind == WRITE and key == self._posted and self.core.output_state == output_state:
            return False
        if kind != READBACK:
            self._posted = key if kind in (WRITE, NEUTRAL) else None
        self.worker.post(ChipJob(kind, widths_us, lights_us, output_state, reason))
        return not self.worker.threaded and self.take()

    def configure(self) -> bool:
        """(Re)configure the chip at neutral (:meth:`.chip.EscChip.configure`); confirmed when its result comes."""
        self.core.chip_attempt()
        return self.post(CONFIGURE, self.core.output.neutral())

    def neutral(self, reason: str) -> bool:
        """Neutral, written whatever is believed on the chip; never dropped nor overtaken (:mod:`.worker`)."""
        if self.core.neutral_confirmed_at is not None:
            self.diag.set_state("neutral", DiagnosticStatus.WARN if reason.startswith("fault") else
                                DiagnosticStatus.OK, reason)
        return self.post(NEUTRAL, self.core.output.neutral(), OUTPUT_NEUTRAL, reason)

    def take(self) -> bool:
        """Take the worker's results (at each command and tick)."""
        changed = False
        for result in ([] if self.closing else self.worker.results()):
            changed = self._apply(result) or changed
        return changed

    def maintain(self, t: float) -> bool:
        """The safety tick's chip part at steady time ``t``: a stuck bus call, then a due (re)configuration or
        read-back."""
        changed = self.take()
        stuck_s = self.worker.stuck_s()
        if stuck_s:
            if self.core.output_state != OUTPUT_UNKNOWN:  # the next heartbeat says ERROR: the guard stops the outputs
                self.bus_stalls += 1
                self.diag.count("bus_stalled")
                self._report_lost(self.core.chip_lost(f"PCA9685 bus call not returned after {stuck_s:.2f} s (limit "
                                                      f"{self.worker.call_timeout_s:g} s)"))
                return True
            return changed  # nothing more can reach the chip until the call returns
        if self.core.retry_due() and not self.worker.pending(CONFIGURE):
            return self.configure() or changed
        if self.core.neutral_confirmed_at is not None and t - self.last_readback >= self.readback_interval_s:
            self.last_readback = t
            return self.post(READBACK) or changed
        return changed

    def _apply(self, r: ChipResult) -> bool:
        out = self.core.chip_result(r.job.kind, error=r.error, no_bus=r.no_bus, mismatch=r.mismatch, wrote=r.wrote,
                                    written_us=r.written_us, output_state=r.job.output_state)
        self.written = r.written_us
        if r.error:
            self._posted = None
        if r.job.kind == CONFIGURE:
            self.bus_error = r.error if r.no_bus else ""
        if out.count:
            self.diag.count(out.count)
        if out.event == "lost":
            self._report_lost(out.new)
        elif out.event == "confirmed":
            self.last_readback = self.core.neutral_confirmed_at
            self.diag.set_state("holding neutral", DiagnosticStatus.OK, out.message)
        elif out.event == "reinit":  # brown-out, sleep, lost registers: re-initialise at neutral (disarmed)
            self.chip_reinits += 1
            self.last_chip_reinit_monotonic = time.monotonic()
            self.diag.warn("chip_reset", out.message)
            self._log(out.message)
            self.configure()
        elif out.event == "write_failed":
            self._log(f"output fault, writing neutral: {r.error}")
            self.neutral(out.message)
        return bool(r.wrote or r.error or r.job.kind == CONFIGURE or out.event != "done")

    def _report_lost(self, new: bool) -> None:
        """The core has lost the chip (UNKNOWN, disarmed, retry with backoff): log a new outage, report ERROR."""
        if new:
            self.unknown_entries += 1
            self._log(f"output state unknown: {self.core.reason}")
        self.diag.set_state("i2c error", DiagnosticStatus.ERROR, f"{self.core.reason} (output state unknown)")
