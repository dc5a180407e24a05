"""The thrust-allocation node's core, shared verbatim with ``hindrax allocate`` and ``hindrax thruster-test``.

Input: a wrench in base_link (FLU, N and N m, about the CG). The core converts it to body FRD
(:mod:`hindrax_common.base.frames`), allocates with the configuration's :class:`ThrustAllocator`
(weighted pseudo-inverse, saturation handling, cubic-curve inversion: [Hindrax-Drag] eqs. 1 and 9), and returns
per-thruster forces, pulse widths and the achieved wrench back in base_link.

A wrench asking more than ``thrusters.max_wrench_excess_ratio`` times what the thrusters can produce on some axis
(:meth:`AllocationCore.wrench_capacity_frd`) is rejected (:class:`InvalidWrenchError`: the node commands neutral
with the reason) rather than saturated: 1e30 N is a unit or scaling fault, not a request for full thrust.

Thruster reversal and trim (``thrusters.<t>.reversed``/``trim_us``) are applied by the ESC output, not here:
the pulse widths below are what the thrust curves need, in the thrusters' configured directions."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig
from .allocator import AllocationResult, InvalidWrenchError
from .from_config import allocator_from_config


@dataclass(frozen=True)
class FluAllocation:
    """One allocation in ROS terms.

    requested_wrench_flu / achieved_wrench_flu: (6,) [Fx Fy Fz Tx Ty Tz] in base_link, N and N m. force_n (n,): thrust
    of each thruster at its pulse width (curve output). pulse_width_us (n,). scale: uniform scale in (0, 1] (priority
    mode: smallest group factor). saturated (n,) bool. frd: the underlying :class:`AllocationResult` in body FRD."""

    requested_wrench_flu: np.ndarray
    achieved_wrench_flu: np.ndarray
    force_n: np.ndarray
    pulse_width_us: np.ndarray
    scale: float
    saturated: np.ndarray
    frd: AllocationResult

    def to_json_dict(self) -> dict:
        """The keys `hindrax allocate` prints."""
        return {
            "force_n": [round(float(x), 6) for x in self.force_n],
            "pulse_width_us": [round(float(x), 3) for x in self.pulse_width_us],
            "achieved_wrench": [round(float(x), 6) for x in self.achieved_wrench_flu],
            "scale": round(float(self.scale), 6),
            "saturated": [bool(x) for x in self.saturated],
        }


class AllocationCore:
    """Wrench (base_link FLU) -> thruster forces and pulse widths, from a vehicle configuration.

    The allocator (matrix, pseudo-inverse, curves) is built once here and rebuilt only by
    :meth:`reconfigure`, never per wrench. Raises :class:`InvalidWrenchError` for a NaN/inf or
    malformed wrench; :meth:`neutral` gives the all-neutral pulse widths to command instead."""

    def __init__(self, cfg: VehicleConfig):
        self.reconfigure(cfg)

    def reconfigure(self, cfg: VehicleConfig) -> None:
        """Rebuild the allocator from a (new) configuration."""
        self.cfg = cfg
        self.allocator = allocator_from_config(cfg)
        self.names = cfg.thrusters.names
        self.neutral_us = cfg.thrusters.pulse_width_neutral_us
        self.max_excess_ratio = float(cfg.thrusters.max_wrench_excess_ratio)
        lower, upper = self.allocator.force_limits_n()
        b = self.allocator.matrix
        self._capacity = (np.minimum(b * lower, b * upper).sum(axis=1), np.maximum(b * lower, b * upper).sum(axis=1))

    def wrench_capacity_frd(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lowest, highest)`` (6,) each axis of the body FRD wrench can reach, N and N m: for axis k the extremes
        of ``sum_i B[k, i] F_i`` over the force box ``lower_i <= F_i <= upper_i`` (each thruster at the limit
        that pushes that axis most; the other axes left free), so no allocation reaches beyond them."""
        return self._capacity

    def excess_problem(self, wrench_frd: np.ndarray) -> str:
        """Why the FRD wrench (6,) is beyond ``max_wrench_excess_ratio`` times the capacity ('' when it is not).
        An axis no thruster moves (capacity 0 both ways) is not checked: nothing can be produced there."""
        low, high = self.wrench_capacity_frd()
        reach = np.where(wrench_frd >= 0.0, high, -low)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(reach > 0.0, np.abs(wrench_frd) / np.where(reach > 0.0, reach, 1.0), 0.0)
        k = int(np.argmax(ratio))
        if ratio[k] > self.max_excess_ratio:
            axis = ("X", "Y", "Z", "K", "M", "N")[k]
            unit = "N" if k < 3 else "N m"
            return (f"wrench beyond what the thrusters can produce: FRD {axis} {wrench_frd[k]:.6g} {unit} is "
                    f"{ratio[k]:.3g} times the {reach[k]:.4g} {unit} reachable (thrusters.max_wrench_excess_ratio "
                    f"{self.max_excess_ratio:g})")
        return ""

    @property
    def matrix_frd(self) -> np.ndarray:
        """Thrust allocation matrix (6, n), body FRD about the CG."""
        return self.allocator.matrix

    def neutral(self) -> np.ndarray:
        """(n,) neutral pulse widths, us."""
        return np.full(len(self.names), self.neutral_us)

    def allocate(self, wrench_flu) -> FluAllocation:
        """Allocate a base_link wrench [Fx Fy Fz Tx Ty Tz] (N, N m). Raises InvalidWrenchError."""
        try:
            w = np.asarray(wrench_flu, dtype=float)
        except (TypeError, ValueError):
            w = None
        if w is None or w.shape != (6,) or not np.isfinite(w).all():
            raise InvalidWrenchError(f"wrench must be 6 finite numbers (N, N m), got {wrench_flu!r}")
        w_frd = frames.wrench_flu_to_frd(w)
        excess = self.excess_problem(w_frd)
        if excess:
            raise InvalidWrenchError(excess)
        result = self.allocator.allocate(w_frd)
        return FluAllocation(
            requested_wrench_flu=w,
            achieved_wrench_flu=frames.wrench_frd_to_flu(result.achieved_wrench),
            force_n=result.force_n,
            pulse_width_us=result.pulse_width_us,
            scale=result.scale,
            saturated=result.saturated,
            frd=result,
        )

    def test_pulse_widths(self, force_n) -> np.ndarray:
        """Pulse widths (n,) us for per-thruster forces ``force_n`` (n,) N, each through its own curve, without the
        allocation (``hindrax thruster-test``: one thruster at a time). Raises :class:`InvalidWrenchError` for the
        wrong count, a non-finite force or one beyond the thruster's limits (a fault, not a saturation)."""
        try:
            f = np.asarray(force_n, dtype=float)
        except (TypeError, ValueError):
            f = None
        n = len(self.names)
        if f is None or f.shape != (n,) or not np.isfinite(f).all():
            raise InvalidWrenchError(f"test forces must be {n} finite numbers (N), got {force_n!r}")
        lower, upper = self.allocator.force_limits_n()
        if np.any(f < lower) or np.any(f > upper):
            raise InvalidWrenchError(f"test forces {f.tolist()} N beyond the thrusters' limits "
                                     f"{lower.tolist()}..{upper.tolist()} N")
        return np.array([float(c.pulse_width_us(x)) for c, x in zip(self.allocator.curves, f)])

    def thruster_wrench_flu(self, index: int, force_n: float) -> np.ndarray:
        """Wrench (base_link FLU) thruster ``index`` alone produces at ``force_n``: B[:, i] F, converted."""
        return frames.wrench_frd_to_flu(self.matrix_frd[:, index] * force_n)

