"""The first-order lag between the thrust a pulse width commands and the thrust the propeller delivers.

``T dF/dt = F_cmd - F`` with ``T = thrusters.time_constant_s`` (0 = no lag). For a command held constant the solution
is exact: ``F(t0 + s) = F_cmd + (F(t0) - F_cmd) exp(-s / T)``. The
simulator integrates with it, the online executive lags its thrust-model force with it, and the offline fit core
and output error evaluate it at the start, middle and end of each control tick."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ThrustLag"]


@dataclass(frozen=True)
class ThrustLag:
    """First-order thrust lag of time constant ``time_constant_s`` (s, >= 0; 0 = the thrust follows at once).

    Raises:
        ValueError: a negative or non-finite time constant."""

    time_constant_s: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time_constant_s) and self.time_constant_s >= 0.0):
            raise ValueError(f"thrust time constant must be finite and >= 0 s, got {self.time_constant_s}")

    def decay(self, dt_s: float) -> float:
        """exp(-dt / T): the fraction of a thrust error left after ``dt_s`` seconds (0.0 without a lag)."""
        return math.exp(-dt_s / self.time_constant_s) if self.time_constant_s > 0.0 else 0.0

    def advance(self, force, command, dt_s: float):
        """The thrust after ``dt_s`` s of the held ``command`` from ``force`` (arrays broadcast, N or N m)."""
        return command + (force - command) * self.decay(dt_s)

    def over_ticks(self, commands: np.ndarray, tick_s: float, force_start: float | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start, middle, end) of each tick of ``tick_s`` through the lag, for one command per tick (n,), the
        lag state starting at ``force_start`` (None: the first command). Exact for commands held over each tick:
        start[j+1] = c[j] + (start[j] - c[j]) e, a first-order IIR filter."""
        fc = np.asarray(commands, dtype=float)
        if self.time_constant_s <= 0.0:
            return fc, fc, fc
        e_full, e_half = self.decay(tick_s), self.decay(0.5 * tick_s)
        start = np.empty_like(fc)
        s = fc[0] if force_start is None else float(force_start)
        start[0] = s
        if fc.size > 1:
            from scipy import signal  # here: the offline fits call this; the node processes only advance the lag

            start[1:] = signal.lfilter([1.0 - e_full], [1.0, -e_full], fc[:-1], zi=[e_full * s])[0]
        return start, fc + (start - fc) * e_half, fc + (start - fc) * e_full
