"""PD/PI holds without a model: the baseline that ``hindrax control evaluate`` compares the model-based law with.

:class:`LegacyPDHold`: gains from the vehicle file's
a-priori rigid + added inertia, k_p = I w_n^2, k_d = 2 zeta w_n I (zeta = 1), the derivative on the measured rate (not
on the error), a depth integral 0.5 m w_n^3 clipped to +-0.5 m s, the net-buoyancy feed-forward, a proportional
velocity hold -1.5 w_n m (v - v_sp), no damping feedforward and no reference model. Same interface as
:class:`~hindrax_onboard.control.maneuvers.HoldController`, so both can drive the same loop."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig
from hindrax_common.base.frames import wrap_angle

from ..vehicle.state import finite_or_zeros
from .model import prior_inertia

__all__ = ["LegacyPDHold"]


class LegacyPDHold:
    """The previous holds (module docstring): ``wrench(state, free)`` returns the FRD wrench (6,) holding every DOF not
    in ``free`` from a :class:`~hindrax_onboard.vehicle.state.SensorState` (depth on ``depth_estimate_m`` and
    ``depth_rate_m_s`` when set, else the latest depth), each hold limited to ``hold_fraction`` of the axis
    authority (6,)."""

    def __init__(self, cfg: VehicleConfig, authority: Sequence[float], natural_frequency_rad_s: float = 2.0,
                 hold_fraction: float = 0.6) -> None:
        self.authority = np.asarray(authority, dtype=float)
        self.inertia = np.array([prior_inertia(cfg, d) for d in DOFS])
        self.wn = float(natural_frequency_rad_s)
        self.hold_fraction = float(hold_fraction)
        self.net_buoyancy_n = float(cfg.buoyancy_n - cfg.weight_n)  # FRD force holding depth (down)
        self.depth_setpoint_m = math.nan
        self.heading_setpoint_rad = 0.0
        self.velocity_setpoint_m_s = np.zeros(2)
        self.attitude_setpoint_rad = np.zeros(2)
        self._depth_integral = 0.0
        self.depth_rate_m_s = 0.0
        self.depth_estimate_m = math.nan

    def reset_integral(self) -> None:
        """Clear the depth integrator."""
        self._depth_integral = 0.0

    def note_allocation(self, requested_frd, achieved_frd) -> None:
        """Ignored: this law had no allocation feedback (its integral is clipped instead)."""

    def wrench(self, st, free: Sequence[str] = (), dt_s: float = 0.02, velocity_gain: float = 1.5,
               t_s: float | None = None) -> np.ndarray:
        """FRD wrench (6,) of the holds (N, N m) for the DOFs not in ``free`` (``t_s`` is not used)."""
        w = np.zeros(6)
        wn, zeta = self.wn, 1.0
        lim = self.hold_fraction * self.authority
        rates = finite_or_zeros(st.rates_frd_rad_s)
        rpy = finite_or_zeros(st.rpy_now())
        for k, dof in enumerate(("surge", "sway")):
            if dof not in free:
                v = st.velocity_frd_m_s[k]
                if np.isfinite(v):
                    w[k] = -velocity_gain * wn * self.inertia[k] * (v - self.velocity_setpoint_m_s[k])
        depth = self.depth_estimate_m if math.isfinite(self.depth_estimate_m) else st.depth_m
        if "heave" not in free and math.isfinite(self.depth_setpoint_m) and math.isfinite(depth):
            m = self.inertia[2]
            err = self.depth_setpoint_m - depth
            self._depth_integral = float(np.clip(self._depth_integral + err * dt_s, -0.5, 0.5))
            w[2] = (self.net_buoyancy_n + m * wn * wn * err - 2.0 * zeta * wn * m * self.depth_rate_m_s
                    + 0.5 * m * wn ** 3 * self._depth_integral)
        for k, dof in ((3, "roll"), (4, "pitch")):
            if dof not in free:
                i = self.inertia[k]
                w[k] = (i * wn ** 2 * (self.attitude_setpoint_rad[k - 3] - rpy[k - 3])
                        - 2.0 * zeta * wn * i * rates[k - 3])
        if "yaw" not in free:
            i = self.inertia[5]
            w[5] = i * wn * wn * wrap_angle(self.heading_setpoint_rad - rpy[2]) - 2.0 * zeta * wn * i * rates[2]
        for k in range(6):
            w[k] = float(np.clip(w[k], -lim[k], lim[k]))
        return w
