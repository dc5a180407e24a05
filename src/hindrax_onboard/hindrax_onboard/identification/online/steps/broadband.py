"""One broadband run per DOF instead of its ladder: :class:`BroadbandRun`.

The signal (Schroeder multisine, m-sequence PRBS or log chirp, :mod:`..excitation`) drives the DOF under test
through the :class:`~..excitation.BoxShaping` of its displacement from the pool-box centre, the other DOFs held;
the DOF is identified by the same output-error fit as a ladder (:func:`~hindrax_fit.fit.campaign_fit.identify_dof`)."""
from __future__ import annotations

import math

import numpy as np

from ...model.dof_model import truth_parameters
from ..excitation import BROADBAND, BoxShaping, design_band, design_signal
from hindrax_common.base.frames import wrap_angle

from ....control.maneuvers import DOF_INDEX, prior_inertia, tilt_test_angle_rad
from ....vehicle.state import finite_or_zero, finite_or_zeros
from .base import DofStep
from .context import StepContext, Wrenches

__all__ = ["BroadbandRun"]


class BroadbandRun(DofStep):
    """One broadband run of ``duration_s`` on ``dof``. kind: one of :data:`~..excitation.BROADBAND`;
    amplitude_fraction: the peak as a fraction of the DOF's smaller authority (0, 1]. Raises ``ValueError`` for
    another kind, a non-positive duration or a fraction outside (0, 1]."""

    def __init__(self, dof: str, kind: str, duration_s: float, amplitude_fraction: float) -> None:
        if kind not in BROADBAND:
            raise ValueError(f"broadband excitation {kind!r}: choose from {', '.join(BROADBAND)}")
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"excitation duration must be > 0 s, got {duration_s}")
        if not (0.0 < amplitude_fraction <= 1.0):
            raise ValueError(f"excitation_amplitude_fraction must be in (0, 1], got {amplitude_fraction}")
        super().__init__(dof, [])
        self.name = f"{dof} {kind}"
        self.kind = kind
        self.duration_s = float(duration_s)
        self.amplitude_fraction = float(amplitude_fraction)

    def design(self, ctx: StepContext):
        """(signal, band, shaping) of the run: amplitude ``amplitude_fraction`` of the DOF's smaller authority, band
        from the vehicle file's inertia and damping (:func:`~..excitation.design_band`, capped by the thruster lag),
        room L from the box centre to the box along the axis (surge/sway: along the start heading, less 0.2 m;
        heave: half the box depth range less 0.05 m; roll/pitch: half the test angle; yaw: pi/2 from the start
        heading), PD bandwidth half the lowest line."""
        dof, k = self.dof, DOF_INDEX[self.dof]
        lim = min(ctx.authority[dof])
        amp = self.amplitude_fraction * lim
        tp = truth_parameters(ctx.cfg, dof)  # the vehicle file's values (the belief, not the pool's truth)
        # heave: the mean of its two directions
        kl, kq = (tp.get(n, 0.5 * (tp.get(n + "_positive", 0.0) + tp.get(n + "_negative", 0.0)))
                  for n in ("linear_damping", "quadratic_damping"))
        m = prior_inertia(ctx.cfg, dof)
        band = design_band(m, kl, kq, amp, ctx.time_constant_s)
        sig = design_signal(self.kind, amp, band, self.duration_s)
        box = ctx.box
        if k < 2:
            psi0 = ctx.ctrl.heading_setpoint_rad
            axis = np.array([math.cos(psi0), math.sin(psi0), 0.0]) if k == 0 else \
                np.array([-math.sin(psi0), math.cos(psi0), 0.0])
            half = max(0.1, box.room_m(box.centre, axis) - 0.2)
        elif k == 2:
            half = max(0.05, 0.5 * (box.z_max - box.z_min) - 0.05)
        elif k == 5:
            half = 0.5 * math.pi
        else:
            # half the test angle: near the roll/pitch natural frequency (inside the band) the restoring moment
            # resonates and the 10 Hz attitude lags, so the braking guard needs the room
            half = 0.5 * float(tilt_test_angle_rad(ctx.cfg, dof))
        shaping = BoxShaping(half, m, lim, math.pi * band.f_min_hz, ctx.tick_s)
        return sig, band, shaping

    def manoeuvre(self, ctx: StepContext) -> Wrenches:
        """The run (module docstring): surge/sway on the dead-reckoned position along the start-heading axis, heave
        on the depth estimate plus the net-buoyancy feed-forward, roll/pitch on the angle, yaw on the heading from
        the start heading; then the DOF is held still again. The record holds one run (``level`` = the total force
        commanded on the axis each tick)."""
        dof, k = self.dof, DOF_INDEX[self.dof]
        sig, band, shaping = self.design(ctx)
        self.levels = [float(sig.amplitude)]
        ctx.levels[dof] = self.levels
        ctrl = ctx.ctrl
        psi0 = ctrl.heading_setpoint_rad
        c = ctx.box.centre
        axis = {0: np.array([math.cos(psi0), math.sin(psi0)]), 1: np.array([-math.sin(psi0), math.cos(psi0)])}
        ctx.say(f"{dof}: {self.kind} excitation {self.duration_s:.0f} s, peak "
                f"{sig.amplitude:.2f}, band {band.f_min_hz:.3f}-{band.f_max_hz:.2f} Hz")
        ctx.start_run(dof, 0.0)
        t0 = ctx.t_s
        st = ctx.state
        while ctx.t_s - t0 < self.duration_s - 1e-9:
            if k < 2:
                e = float(finite_or_zeros(st.position_ned_m[:2] - c[:2]) @ axis[k])
            elif k == 2:
                d = ctrl.depth_estimate_m if math.isfinite(ctrl.depth_estimate_m) else st.depth_m
                e = finite_or_zero(d - c[2])
            elif k == 5:
                e = wrap_angle(finite_or_zero(st.rpy_rad[2]) - psi0)
            else:
                # the 10 Hz attitude extrapolated to now with the gyro rate (as in the rotation ladder)
                e = finite_or_zero(st.rpy_rad[k - 3]) + ctx.axis_velocity(k) * ctx.attitude_age_s()
            f = shaping.force(float(sig.value(ctx.t_s - t0)), e, ctx.axis_velocity(k))
            if k == 2:
                f += ctrl.net_buoyancy_n
            ctx.level = f
            w = np.asarray(ctrl.wrench(st, (dof,), ctx.tick_s), dtype=float)
            w[k] = f
            yield w
        ctx.end_run()
        if k == 2:
            ctrl.depth_setpoint_m = float(np.clip(st.depth_m, ctx.box.z_min, ctx.box.z_max))
            ctrl.reset_integral()
        elif k == 5:
            ctrl.heading_setpoint_rad = finite_or_zero(st.rpy_rad[2])
        yield from ctx.wait_still(k, 0.05, 8.0)
        yield from ctx.hold(0.5)
        if k == 2:
            ctrl.depth_setpoint_m = ctx.depth_hold_m
        elif k == 5:
            ctrl.heading_setpoint_rad = psi0
