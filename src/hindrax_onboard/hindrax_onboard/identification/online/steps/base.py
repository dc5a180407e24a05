"""The step protocol of the campaign sequencer, the dive, and the per-DOF manoeuvre frame.

A :class:`Step` is one self-contained part of a campaign (the dive, a known-force calibration step,
one DOF's ladder or broadband run), run one after the other by the sequencer; :mod:`.context`
describes its ticks and what it sees (never the plant)."""
from __future__ import annotations

import math

import numpy as np

from ....control.maneuvers import DOF_INDEX
from ....vehicle.state import finite_or_zero
from .context import StepContext, Wrenches

__all__ = ["Step", "Confirm", "Dive", "DofStep", "undo_line"]


class Step:
    """One part of a campaign (module docstring). Subclasses set :attr:`name` and implement :meth:`run`."""

    #: short name for messages and plans (e.g. ``ballast``, ``surge ladder``)
    name = "step"

    def run(self, ctx: StepContext) -> Wrenches:  # pragma: no cover - abstract
        """The step's wrenches, one per control tick (module docstring)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"


def undo_line(undo) -> str:
    """One line asking the operator to undo the loads an aborted campaign left (``undo``: (remove code,
    instruction) pairs, :attr:`~.context.StepContext.undo`); '' when there are none."""
    texts = [text.split(": ", 1)[-1] for _code, text in undo]
    return (f"undo: {'; '.join(texts)} (the next campaign asks to confirm it first)") if texts else ""


class Confirm(Step):
    """Before anything moves: the operator confirms that the loads an aborted campaign left are gone (``undo``:
    (remove code, instruction) pairs, e.g. ``("remove_ballast", "calibration: remove the ballast")``), one prompt
    each, thrusters stopped (zero wrench) meanwhile. They are in :attr:`~.context.StepContext.undo` until
    confirmed, so a campaign aborted or cancelled here leaves them to the next one."""

    name = "confirm"

    def __init__(self, undo) -> None:
        self.items = [(str(code), str(text)) for code, text in undo]

    def run(self, ctx: StepContext) -> Wrenches:
        ctx.undo.update(self.items)
        for code, text in self.items:
            yield from ctx.wait_operator(code, f"before this campaign (the last one was aborted): "
                                               f"{text.split(': ', 1)[-1]}", hold=False)


class Dive(Step):
    """Dive to the altitude setpoint (``identification.altitude_setpoint_m``, from the Ping1D altitude and the
    depth; inside the pool box's depth range) with the depth setpoint ramped at 0.25 m/s, at most 25 s, heading
    held at ``pool.start_heading_rad``; then hold 3 s, the gyro and accelerometer biases averaged over the last 2 s
    (:meth:`~hindrax_onboard.vehicle.state.SensorState.start_gyro_bias`; the average includes the body's mean rate
    while the holds keep it, up to about 1.5 mrad/s over 2 s in the virtual pool). Sets
    :attr:`~.context.StepContext.depth_hold_m`."""

    name = "dive"

    def run(self, ctx: StepContext) -> Wrenches:
        ctx.say("dive to the altitude setpoint and settle")
        alt_sp = float(ctx.cfg.identification.altitude_setpoint_m)
        ctx.ctrl.heading_setpoint_rad = float(ctx.cfg.pool.start_heading_rad)
        yield np.zeros(6)  # first samples
        target = ctx.box.z_min
        t0 = ctx.t_s
        st = ctx.state
        ctx.ctrl.depth_setpoint_m = max(finite_or_zero(st.depth_m), 0.0)
        while ctx.t_s - t0 < 25.0:
            if math.isfinite(st.altitude_m) and math.isfinite(st.depth_m):
                target = float(np.clip(st.depth_m + st.altitude_m - alt_sp, ctx.box.z_min, ctx.box.z_max))
            step = 0.25 * ctx.tick_s
            ctx.ctrl.depth_setpoint_m += float(np.clip(target - ctx.ctrl.depth_setpoint_m, -step, step))
            yield ctx.ctrl.wrench(st, (), ctx.tick_s)
            if abs(target - ctx.ctrl.depth_setpoint_m) < 1e-6 and abs(st.depth_m - target) < 0.03 \
                    and abs(ctx.ctrl.depth_rate_m_s) < 0.03:
                break
        ctx.depth_hold_m = target
        ctx.ctrl.depth_setpoint_m = target
        yield from ctx.hold(1.0)
        st.start_gyro_bias()
        yield from ctx.hold(2.0)
        st.finish_gyro_bias()


class DofStep(Step):
    """The frame of one DOF's identification manoeuvre: go to the box centre, mark the DOF under test
    (:attr:`~.context.StepContext.active`), run :meth:`manoeuvre`, then record the DOF's window
    (:attr:`~.context.StepContext.windows`) and its levels (:attr:`~.context.StepContext.levels`: ``levels``, which a
    subclass may replace). dof: one of the six DOFs; levels: the commanded levels (N or N m)."""

    def __init__(self, dof: str, levels) -> None:
        if dof not in DOF_INDEX:
            raise ValueError(f"unknown DOF {dof!r}")
        self.dof = dof
        self.levels = [float(x) for x in levels]

    def manoeuvre(self, ctx: StepContext) -> Wrenches:  # pragma: no cover - abstract
        """The DOF's runs, between the frame's start and end."""
        raise NotImplementedError

    def run(self, ctx: StepContext) -> Wrenches:
        yield from ctx.move_to_centre()
        ctx.levels[self.dof] = self.levels
        t0 = ctx.t_s
        ctx.active = DOF_INDEX[self.dof]
        yield from self.manoeuvre(ctx)
        ctx.active = -1
        ctx.windows[self.dof] = (t0, ctx.t_s)
        ctx.say(f"{self.dof}: done ({ctx.t_s - t0:.0f} s of pool time)")
