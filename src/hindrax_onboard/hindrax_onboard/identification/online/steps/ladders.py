"""The constant-level ladders of [Hindrax-Drag] §4: one DOF at a time, the other DOFs held.

* :class:`TranslationLadder` (surge, sway, heave): surge and sway alternate +level / -level runs along the body axis
  (heading held at the start heading); a run ends when the dead-reckoned stopping point reaches the
  :class:`~....control.maneuvers.PoolBox` boundary or after ``max_level_s``; the larger room is used first, so both
  directions are tested. Heave: down then up within the box depth range,
  ``identification.heave_repeats`` pairs per level (default 3; no steady state needed:
  identified through the transient).
* :class:`RotationLadder` (roll, pitch, yaw): roll and pitch rotate until the predicted stopping angle reaches
  ``identification.roll_test_angle_rad`` / ``pitch_test_angle_rad`` and return to level ([Hindrax-Drag] §4.2);
  yaw turns once (2 pi) per run ([Hindrax-Drag] §4.2: 360 deg rotations); both directions."""
from __future__ import annotations

import math

import numpy as np

from hindrax_common.base.frames import wrap_angle

from ....control.maneuvers import DOF_INDEX, prior_inertia, tilt_test_angle_rad
from ....vehicle.state import finite_or_zero
from .base import DofStep
from .context import StepContext, Wrenches

__all__ = ["TranslationLadder", "RotationLadder", "run_level"]


def run_level(ctx: StepContext, dof: str, level: float) -> Wrenches:
    """One tick: the other DOFs held, ``level`` (N or N m) added on the DOF under test."""
    extra = np.zeros(6)
    extra[DOF_INDEX[dof]] = level
    yield ctx.ctrl.wrench(ctx.state, (dof,), ctx.tick_s) + extra


class TranslationLadder(DofStep):
    """Ladder of surge, sway or heave (module docstring). levels: magnitudes (N); max_level_s: longest run (s);
    heave_repeats: down/up pairs per heave level."""

    def __init__(self, dof: str, levels, max_level_s: float, heave_repeats: int = 3) -> None:
        if dof not in ("surge", "sway", "heave"):
            raise ValueError(f"TranslationLadder: {dof!r} is not surge, sway or heave")
        super().__init__(dof, levels)
        self.name = f"{dof} ladder"
        self.max_level_s = float(max_level_s)
        self.heave_repeats = max(1, int(heave_repeats))

    def manoeuvre(self, ctx: StepContext) -> Wrenches:
        dof, k = self.dof, DOF_INDEX[self.dof]
        psi0 = ctx.ctrl.heading_setpoint_rad
        axis = {0: np.array([math.cos(psi0), math.sin(psi0), 0.0]),
                1: np.array([-math.sin(psi0), math.cos(psi0), 0.0]),
                2: np.array([0.0, 0.0, 1.0])}[k]
        m = prior_inertia(ctx.cfg, dof)
        a_brake = 0.5 * min(ctx.authority[dof]) / m
        repeats = self.heave_repeats if k == 2 else 1
        box = ctx.box
        for i, lvl in enumerate(self.levels):
            p = ctx.state.position_ned_m
            # heave: down, then up; surge and sway: the larger room first
            first = k == 2 or box.room_m(p, axis) >= box.room_m(p, -axis)
            signs = (1.0, -1.0) if first else (-1.0, 1.0)
            for s in signs * repeats:
                ctx.say(f"{dof}: level {i + 1}/{len(self.levels)} {s * lvl:+.2f} N")
                ctx.start_run(dof, s * lvl)
                t0 = ctx.t_s
                while ctx.t_s - t0 < self.max_level_s:
                    vs = max(0.0, s * ctx.axis_velocity(k))
                    stop = vs * vs / (2.0 * a_brake) + 0.3 * vs + 0.03
                    if box.room_m(ctx.state.position_ned_m, s * axis) <= stop:
                        break
                    yield from run_level(ctx, dof, s * lvl)
                ctx.end_run()
                if k == 2:
                    v = ctx.axis_velocity(2)
                    ctx.ctrl.depth_setpoint_m = float(np.clip(ctx.state.depth_m + v * abs(v) / (2 * a_brake),
                                                              box.z_min, box.z_max))
                    ctx.ctrl.reset_integral()
                yield from ctx.wait_still(k, 0.05, 6.0)
                yield from ctx.hold(0.5)
        if k == 2:
            ctx.ctrl.depth_setpoint_m = ctx.depth_hold_m


class RotationLadder(DofStep):
    """Ladder of roll, pitch or yaw (module docstring). levels: magnitudes (N m); max_level_s: longest run (s)."""

    def __init__(self, dof: str, levels, max_level_s: float) -> None:
        if dof not in ("roll", "pitch", "yaw"):
            raise ValueError(f"RotationLadder: {dof!r} is not roll, pitch or yaw")
        super().__init__(dof, levels)
        self.name = f"{dof} ladder"
        self.max_level_s = float(max_level_s)

    def manoeuvre(self, ctx: StepContext) -> Wrenches:
        dof, k = self.dof, DOF_INDEX[self.dof]
        inertia = prior_inertia(ctx.cfg, dof)
        alpha = 0.5 * min(ctx.authority[dof]) / inertia
        limit = 2.0 * math.pi if dof == "yaw" else float(tilt_test_angle_rad(ctx.cfg, dof))
        for i, lvl in enumerate(self.levels):
            for s in (1.0, -1.0):
                ctx.say(f"{dof}: level {i + 1}/{len(self.levels)} {s * lvl:+.2f} N m")
                ctx.start_run(dof, s * lvl)
                t0 = ctx.t_s
                turned = 0.0
                prev = finite_or_zero(ctx.state.rpy_rad[k - 3])
                while ctx.t_s - t0 < self.max_level_s:
                    rate = max(0.0, s * ctx.axis_velocity(k))
                    stop = rate * rate / (2.0 * alpha) + 0.1 * rate
                    ang = finite_or_zero(ctx.state.rpy_rad[k - 3])
                    if dof == "yaw":
                        turned += abs(wrap_angle(ang - prev))
                        prev = ang
                        done = turned + stop >= limit
                    else:
                        # the attitude comes at 10 Hz: extrapolate it to now with the 100 Hz gyro rate (at 2 rad/s
                        # a 100 ms old angle is 0.2 rad short, which let the graph overshoot the pitch limit)
                        ang += ctx.axis_velocity(k) * ctx.attitude_age_s()
                        done = s * ang + stop >= limit
                    if done:
                        break
                    yield from run_level(ctx, dof, s * lvl)
                ctx.end_run()
                if dof == "yaw":
                    r = ctx.axis_velocity(5)
                    ctx.ctrl.heading_setpoint_rad = wrap_angle(finite_or_zero(ctx.state.rpy_rad[2])
                                                               + r * abs(r) / (2.0 * alpha))
                yield from ctx.wait_still(k, 0.05, 8.0)
                yield from ctx.hold(0.5)
