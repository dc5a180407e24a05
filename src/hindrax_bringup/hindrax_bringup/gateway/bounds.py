"""What the gateway lets through to the vehicle: a campaign goal and a setpoint inside what the vehicle file allows.

Every relayed goal and setpoint is checked here before it reaches an internal node (docs/architecture.md §8.2); a
refusal is one line naming the field and the bound. The identification and controller nodes check their inputs
too; this is the topside's boundary, so that no request from the tether can end a vehicle process or ask for a
depth or speed the vehicle must not reach.

* ``run_identification`` goal: ``dofs`` from :data:`~hindrax_common.config.DOFS`, each once; ``levels_per_dof``
  (0 = ``identification.levels_per_dof``) and ``level_fractions`` (each finite, in (0, 1]) such that the ladders'
  longest time, DOFs x levels x ``identification.max_level_duration_s`` (a broadband excitation: DOFs x
  ``identification.excitation_duration_s``), fits in ``supervisor.max_run_time_s``; at most
  :data:`MAX_CALIBRATION_STEPS` calibration step names of at most :data:`MAX_NAME_CHARS` characters (the
  identification node knows the names).
* ``controller/setpoint``: every number finite; a depth in [0, min(``limits.max_depth_m``, ``pool.depth_m`` -
  ``pool.margin_m``)]; an altitude in [``limits.min_altitude_m``, ``pool.depth_m``]; surge and sway speeds no
  higher than the steady speed the thrusters' capacity gives against the damping (:func:`top_speeds_m_s`).

Pure (numpy through the allocation's capacity); no rclpy: messages are read by attribute."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig

__all__ = ["MAX_CALIBRATION_STEPS", "MAX_NAME_CHARS", "RequestBounds", "top_speeds_m_s"]

#: calibration steps one goal may ask for (there are five kinds; each once is plenty)
MAX_CALIBRATION_STEPS = 8
#: longest DOF or calibration step name accepted, characters
MAX_NAME_CHARS = 32
#: the setpoint's vertical modes (hindrax_msgs/ControlSetpoint VERTICAL_NONE, _DEPTH, _ALTITUDE)
VERTICAL_MODES = (0, 1, 2)


def top_speeds_m_s(cfg: VehicleConfig) -> dict[str, float]:
    """{``surge``, ``sway``: the steady speed, m/s, at which the damping (``hydrodynamics.*``) equals the thrusters'
    smaller capacity of the two directions on that axis (:meth:`~hindrax_bringup.allocation.core.AllocationCore.
    wrench_capacity_frd`)}: linear v + quadratic v^2 = F."""
    low, high = AllocationCore(cfg).wrench_capacity_frd()
    out = {}
    for i, dof in enumerate(("surge", "sway")):
        force = min(-float(low[i]), float(high[i]))
        h = cfg.dof_hydrodynamics(dof)
        lin, quad = min(h.linear_damping_positive, h.linear_damping_negative), \
            min(h.quadratic_damping_positive, h.quadratic_damping_negative)
        out[dof] = force / lin if quad <= 0.0 else (-lin + math.sqrt(lin * lin + 4.0 * quad * force)) / (2.0 * quad)
    return out


@dataclass(frozen=True)
class RequestBounds:
    """The bounds of one vehicle file (module docstring): :meth:`goal_problem` and :meth:`setpoint_problem` return
    "" when a request is inside them, else one line naming the field and the bound."""

    default_levels: int
    level_duration_s: float
    broadband_duration_s: float | None
    max_run_time_s: float
    max_depth_m: float
    min_altitude_m: float
    pool_depth_m: float
    top_speed_m_s: dict

    @classmethod
    def from_config(cls, cfg: VehicleConfig) -> "RequestBounds":
        """The bounds of vehicle file ``cfg`` (needs its ``identification``, ``supervisor``, ``limits``, ``pool``,
        ``hydrodynamics``, ``thrusters`` and ``esc`` sections)."""
        ident, pool = cfg.identification, cfg.pool
        broadband = ident.excitation not in (None, "ladder")
        return cls(int(ident.levels_per_dof), float(ident.max_level_duration_s),
                   float(ident.excitation_duration_s or 60.0) if broadband else None,
                   float(cfg.supervisor.max_run_time_s),
                   min(float(cfg.limits.max_depth_m), float(pool.depth_m) - float(pool.margin_m)),
                   float(cfg.limits.min_altitude_m), float(pool.depth_m), top_speeds_m_s(cfg))

    def goal_problem(self, goal: Any) -> str:
        """Why a ``run_identification`` goal (hindrax_msgs/action/RunIdentification Goal) is refused, "" if not."""
        dofs, steps, fractions = list(goal.dofs), list(goal.calibrate), list(goal.level_fractions)
        for name, values, allowed in (("dofs", dofs, len(DOFS)), ("calibrate", steps, MAX_CALIBRATION_STEPS)):
            if len(values) > allowed or any(len(v) > MAX_NAME_CHARS for v in values):
                return (f"run_identification: {name} has {len(values)} entries: allowed at most {allowed} names of "
                        f"at most {MAX_NAME_CHARS} characters")
        bad = [d for d in dofs if d not in DOFS]
        if bad or len(set(dofs)) != len(dofs):
            return f"run_identification: dofs = {dofs}: allowed each of {', '.join(DOFS)} at most once"
        if any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fractions):
            return "run_identification: level_fractions: allowed each finite in (0, 1]"
        levels = len(fractions) or int(goal.levels_per_dof) or self.default_levels
        n_dofs = 0 if goal.calibration_only else len(dofs) or len(DOFS)
        if self.broadband_duration_s is not None and not fractions and not goal.levels_per_dof:
            run_s, what = n_dofs * self.broadband_duration_s, f"{n_dofs} DOFs x {self.broadband_duration_s:g} s"
        else:
            run_s = n_dofs * levels * self.level_duration_s
            what = f"{n_dofs} DOFs x {levels} levels x {self.level_duration_s:g} s"
        if run_s > self.max_run_time_s:
            return (f"run_identification: {what} = {run_s:g} s: allowed at most supervisor.max_run_time_s = "
                    f"{self.max_run_time_s:g} s (levels_per_dof = {goal.levels_per_dof})")
        return ""

    def setpoint_problem(self, sp: Any) -> str:
        """Why a ``controller/setpoint`` (hindrax_msgs/ControlSetpoint) is refused, "" if not."""
        for key in ("depth_m", "altitude_m", "heading_rad", "surge_m_s", "sway_m_s"):
            if not math.isfinite(getattr(sp, key)):
                return f"controller/setpoint: {key} = {getattr(sp, key)}: allowed a finite number"
        if sp.vertical_mode not in VERTICAL_MODES:
            return f"controller/setpoint: vertical_mode = {sp.vertical_mode}: allowed 0 (none), 1 (depth), 2 (altitude)"
        if sp.vertical_mode == 1 and not 0.0 <= sp.depth_m <= self.max_depth_m:
            return (f"controller/setpoint: depth_m = {sp.depth_m:g}: allowed [0, {self.max_depth_m:g}] m "
                    "(limits.max_depth_m and pool.depth_m - pool.margin_m)")
        if sp.vertical_mode == 2 and not self.min_altitude_m <= sp.altitude_m <= self.pool_depth_m:
            return (f"controller/setpoint: altitude_m = {sp.altitude_m:g}: allowed [{self.min_altitude_m:g}, "
                    f"{self.pool_depth_m:g}] m (limits.min_altitude_m, pool.depth_m)")
        if sp.hold_velocity:
            for key, dof in (("surge_m_s", "surge"), ("sway_m_s", "sway")):
                top = self.top_speed_m_s[dof]
                if abs(getattr(sp, key)) > top:
                    return (f"controller/setpoint: {key} = {getattr(sp, key):g}: allowed |{key}| <= {top:.2f} m/s "
                            "(the thrusters' steady speed against the damping)")
        return ""
