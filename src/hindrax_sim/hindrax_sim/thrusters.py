"""Simulated thrusters: pulse width -> thrust (cubic curves) -> first-order lag -> body wrench. Pure numpy.

* Geometry: ``config.thrusters`` positions (FRD, m, relative to the CG) and unit directions; the thrust
  allocation matrix ``B_cg = [d_i; r_i x d_i]`` (6, n) is :func:`hindrax_bringup.allocation.matrix.
  thrust_allocation_matrix` ([Hindrax-Drag] eq. 9), i.e. the wrench about the CG. The model's reference point is
  the body origin CO with the CG at r_g, so the wrench about CO is ``[F; T_cg + r_g x F]``
  (``matrix_co``; identical when r_g = 0, as in the Hindrax file).
* Thrust: the allocation's :class:`hindrax_common.base.thrust_curve.ThrustCurve`
  (:func:`hindrax_bringup.allocation.from_config.thrust_curve_from_config`: ``thrusters.curve_negative``,
  ``curve_positive``, the pulse-width range and the deadband) ([Hindrax-Drag] eq. 1, Table 2; docs/architecture.md §4).
  The pulse widths are those on the wire (``hindrax_msgs/ThrusterPwm``: what the ESC output wrote). A thruster
  configured ``reversed`` has its pulse width mirrored about neutral by the ESC node and a reversed
  propeller, so its physical thrust along ``direction_frd`` is ``curve(2 P_neutral - P)``. The per-thruster
  ``trim_us`` compensates a real ESC's offset; the simulated ESCs have none, so the trim is not undone.
  Battery sag is not modelled (``voltage_scale`` 1).
* Lag: :class:`hindrax_onboard.vehicle.thrust_lag.ThrustLag` of ``thrusters.time_constant_s``, exact for a command
  held over a step, which the integrator evaluates at its stage times.
* Not modelled: thrust dependence on advance speed and thruster-hull / thruster-thruster interaction
  ([Hindrax-Drag] §6; docs/identification.md §3 C6)."""
from __future__ import annotations

import numpy as np

from hindrax_bringup.allocation.from_config import thrust_curve_from_config
from hindrax_bringup.allocation.matrix import thrust_allocation_matrix
from hindrax_common.config import VehicleConfig

from hindrax_onboard.vehicle.rigid_body import skew
from hindrax_onboard.vehicle.thrust_lag import ThrustLag

__all__ = ["PulseWidthError", "Thrusters"]


class PulseWidthError(ValueError):
    """Pulse widths that are not n finite numbers."""


class Thrusters:
    """The thruster set of a configuration (module docstring).

    Attributes: ``names`` (n,), ``n``, ``matrix_co`` (6, n) thrust allocation matrix about the body
    origin, ``curve`` (ThrustCurve), ``time_constant_s``, ``neutral_us``, ``force_n`` (n,) the
    current (lagged) thrust, ``commanded_force_n`` (n,) the thrust the current pulse widths ask
    for, ``pulse_width_us`` (n,) the current wire pulse widths."""

    def __init__(self, config: VehicleConfig) -> None:
        t = config.thrusters
        self.names = tuple(t.names)
        self.n = len(self.names)
        shift = np.eye(6)
        shift[3:, :3] = skew(config.vehicle.centre_of_gravity_frd_m)  # T_co = T_cg + r_g x F
        self.matrix_co = shift @ thrust_allocation_matrix(t.positions_frd_m, t.directions_frd)
        self.curve = thrust_curve_from_config(config)  # the allocation's curve, the same object type and values
        self.neutral_us = float(t.pulse_width_neutral_us)
        self._reversed = np.array([th.reversed for th in t.thrusters], dtype=bool)
        self.time_constant_s = float(t.time_constant_s)
        self.lag = ThrustLag(self.time_constant_s)
        self.matrix_co.flags.writeable = False
        self.reset()

    def reset(self) -> None:
        """All thrusters stopped: neutral pulse widths, zero thrust."""
        self.pulse_width_us = np.full(self.n, self.neutral_us)
        self.commanded_force_n = np.zeros(self.n)
        self.force_n = np.zeros(self.n)

    def thrust_from_pulse_width(self, pulse_width_us) -> np.ndarray:
        """Steady thrust (n,) in N along each ``direction_frd`` for wire pulse widths (n,) in us.

        A width <= 0 means "no pulses" (e.g. a PCA9685 channel that is off): the ESC stops, 0 N. Reversed
        thrusters are mirrored about neutral (module docstring); out-of-range widths saturate at the curve
        ends. Raises :class:`PulseWidthError` for a wrong length or non-finite values."""
        try:
            pw = np.array(pulse_width_us, dtype=float).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise PulseWidthError(f"pulse widths must be {self.n} numbers (us), got {pulse_width_us!r}") from exc
        if pw.shape != (self.n,) or not np.all(np.isfinite(pw)):
            raise PulseWidthError(f"pulse widths must be {self.n} finite numbers (us) in the order "
                                  f"{', '.join(self.names)}, got {pulse_width_us!r}")
        pw = np.where(pw <= 0.0, self.neutral_us, pw)
        pw = np.where(self._reversed, 2.0 * self.neutral_us - pw, pw)
        return np.asarray(self.curve.thrust_n(pw), dtype=float)

    def command(self, pulse_width_us) -> None:
        """Set new wire pulse widths (n,) in us, held until the next command. Raises
        :class:`PulseWidthError` (and keeps the previous command) for bad widths."""
        self.commanded_force_n = self.thrust_from_pulse_width(pulse_width_us)
        self.pulse_width_us = np.array(pulse_width_us, dtype=float).reshape(-1)

    def advance(self, dt_s: float) -> None:
        """Advance the lagged thrust by ``dt_s`` (exact for the held command)."""
        self.force_n = self.lag.advance(self.force_n, self.commanded_force_n, dt_s)

    def wrench_co(self) -> np.ndarray:
        """Body wrench [X Y Z K M N] (6,) of the current thrust about the body origin, FRD: forces
        in N, moments in N m."""
        return self.matrix_co @ self.force_n
