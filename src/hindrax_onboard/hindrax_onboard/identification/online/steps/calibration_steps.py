"""Reference steps with known forces or moments, run before the manoeuvres (docs/identification.md §6.1 and §6.4).

Thrust steps (:class:`KnownForceStep`): hold, average the holding force X1 (thrust model, on one body axis); the
operator applies a known force E along that axis; hold again, X2; the operator removes it. At rest the thrust
balances the known force, so s (X1 - X2) = E for a true thrust s times the curve's. Each hold also records the
parts of its holding force made by thrusters turning forward (positive thrust) and in reverse (negative thrust),
P and N (X = P + N), so that :func:`~hindrax_fit.fit.calibration.joint_estimate` can use every hold as the measurement
``s_forward P + s_reverse N + E = R`` of the two rotation directions' scales (docs/identification.md §6.2):

* :class:`Ballast` (the known sinker, weight in water w, ``+z``): the vertical thrusters go from pushing down (the
  vehicle is buoyant) to pushing up: the change is mostly *reverse* thrust;
* :class:`Float` (the known float, net buoyancy b, ``-z``): the vertical thrusters push down harder: *forward*
  thrust only. With the ballast the two vertical directions are measured separately; the holds without either
  are hovers, whose force balances the weighed net buoyancy (one more measurement of the forward scale);
* :class:`LinePull` (a line over a pulley at the pool edge, force F along body ``+x``/``+y``, or ``-x``/``-y`` with
  ``sense=-1``): with the 55-degree layout every horizontal force is made by two thrusters turning forward and two
  in reverse with equal thrust, so a pull in either sense measures the mean of the two horizontal scales, the only
  combination that surge, sway and yaw use.

Attitude steps: :class:`Inclining` (restoring stiffness C of roll or pitch from a known mass at a known arm) and
:class:`TiltDecay` (roll or pitch free decay after a thruster-made tilt).

Durations: :data:`CALIBRATION_SETTLE_S` before and :data:`CALIBRATION_WINDOW_S` of each averaging hold (the
constructors' defaults; a calibration-only test passes shorter ones)."""
from __future__ import annotations

import math

import numpy as np

from ...model.calibration_topic import KNOWN_FORCE_AXES
from ....control.maneuvers import DOF_INDEX
from .base import Step
from .context import CampaignAbort, StepContext, Wrenches

__all__ = ["CALIBRATION_SETTLE_S", "CALIBRATION_WINDOW_S", "TILT_DECAY_ANGLE_RAD", "TILT_DECAY_RAMP_S",
           "TILT_DECAY_HOLD_S", "TILT_DECAY_RECORD_S", "KnownForceStep", "Ballast", "Float", "LinePull",
           "Inclining", "TiltDecay"]

#: Settling time before, and averaging window of, each calibration hold (s).
CALIBRATION_SETTLE_S = 15.0
CALIBRATION_WINDOW_S = 30.0
#: tilt_decay: tilt angle aimed at (rad), ramp and hold before the release, and the recorded decay (s).
TILT_DECAY_ANGLE_RAD = 0.25
TILT_DECAY_RAMP_S = 6.0
TILT_DECAY_HOLD_S = 4.0
TILT_DECAY_RECORD_S = 25.0


def _positive(name: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be > 0, got {value}")
    return float(value)


class KnownForceStep(Step):
    """A thrust scale from a known force (module docstring). Subclasses set the calibration key (one of
    :data:`KNOWN_FORCE_AXES`: group, axis and sense of the known force), the prompts and whether the
    holds keep station (line pulls) or only depth (ballast, float).

    force_n: magnitude of the known force (> 0, N); settle_s / window_s: each hold's settling and averaging time (s).
    The result, in :attr:`~.context.StepContext.calibration` under the key: ``value`` = E / (X1 - X2) and ``std``
    (the single-scale estimate, from the two means' batch-mean std), ``known_force_n`` (magnitude), ``direction``
    (body FRD axis and sense of E), ``group``, ``holding_force_n`` [X1, X2] and ``holding_force_std_n``,
    ``forward_force_n`` [P1, P2] and ``reverse_force_n`` [N1, N2], ``method``. Raises :class:`CampaignAbort` when
    the holding force did not change against the known force."""

    key = ""
    method = ""
    station = False
    #: the messages' words: the load held without, what the holding force must do, the scale's name
    load = "the known force"
    change = "change against the known force"
    scale_name = "thrust scale"

    def __init__(self, force_n: float, settle_s: float = CALIBRATION_SETTLE_S,
                 window_s: float = CALIBRATION_WINDOW_S) -> None:
        self.force_n = _positive(f"{type(self).__name__} force", force_n)
        self.settle_s = _positive("settle_s", settle_s)
        self.window_s = _positive("window_s", window_s)
        self.group, self.axis, self.sense = KNOWN_FORCE_AXES[self.key]

    # texts of one step (subclasses)
    def label(self) -> str:
        return self.name

    def prompts(self) -> tuple[tuple[str, str], tuple[str, str]]:
        """((apply code, apply instruction), (remove code, remove instruction))."""
        raise NotImplementedError  # pragma: no cover

    def _holds(self, ctx: StepContext, duration_s: float, centre) -> Wrenches:
        if self.station:
            return ctx.station(duration_s, centre)
        return ctx.hold(duration_s)

    def _measure(self, ctx: StepContext, centre):
        """Settle, then average: returns (X, std of X, P, N) of the window."""
        yield from self._holds(ctx, self.settle_s, centre)
        t1 = ctx.t_s
        yield from self._holds(ctx, self.window_s, centre)
        return (*ctx.mean_recorded_force(self.axis, t1), *ctx.mean_force_by_direction(self.axis, t1))

    def run(self, ctx: StepContext) -> Wrenches:
        yield from ctx.move_to_centre()
        c = (float(ctx.state.position_ned_m[0]), float(ctx.state.position_ned_m[1]))
        if not self.station:
            ctx.ctrl.depth_setpoint_m = ctx.depth_hold_m
        (apply_code, apply_text), (remove_code, remove_text) = self.prompts()
        head = f"calibration ({self.label()}):"
        ctx.say(f"{head} hold {'station' if self.station else 'depth'} without {self.load}")
        x1, s1, p1, n1 = yield from self._measure(ctx, c)
        yield from ctx.wait_operator(apply_code, apply_text, undo=(remove_code, remove_text))
        x2, s2, p2, n2 = yield from self._measure(ctx, c)
        yield from ctx.wait_operator(remove_code, remove_text)
        yield from self._holds(ctx, self.settle_s, c)
        e = self.sense * self.force_n
        dx = x1 - x2
        scale = e / dx if dx != 0.0 else math.nan
        if not scale > 0.0:
            raise CampaignAbort(f"{head} the holding force did not {self.change} ({x1:.3g} -> {x2:.3g} N)")
        ctx.calibration[self.key] = {
            "value": scale, "std": scale * math.hypot(s1, s2) / abs(dx), "known_force_n": self.force_n,
            "holding_force_n": [x1, x2], "holding_force_std_n": [s1, s2], "method": self.method,
            "direction": ("+" if self.sense > 0 else "-") + "xyz"[self.axis], "group": self.group,
            "forward_force_n": [p1, p2], "reverse_force_n": [n1, n2]}
        ctx.say(f"{head} {self.scale_name} {scale:.4f}")


class Ballast(KnownForceStep):
    """The known sinker (module docstring): weight in water ``force_n`` = (m - rho V) g, along body +z. Mostly
    reverse thrust of the vertical thrusters (the vehicle's holding force turns from down to up)."""

    name = "ballast"
    key = "vertical"
    method = "ballast"
    load = "the ballast"
    change = "rise"
    scale_name = "vertical thrust scale"

    def prompts(self):
        return (("attach_ballast", f"calibration: attach the ballast ({self.force_n:.3g} N in water)"),
                ("remove_ballast", "calibration: remove the ballast"))


class Float(KnownForceStep):
    """The known float (module docstring): net buoyancy ``force_n`` = (rho V - m) g of a sealed float tied to the
    vehicle above its centre of gravity, along body -z. Forward thrust of the vertical thrusters only."""

    name = "float"
    key = "vertical_negative"
    method = "float"
    load = "the float"
    change = "rise downwards"

    def prompts(self):
        return (("attach_float", f"calibration: tie the float ({self.force_n:.3g} N net buoyancy) above the "
                                 "centre of gravity"),
                ("remove_float", "calibration: remove the float"))


class LinePull(KnownForceStep):
    """A known horizontal force along body +x / +y (``axis`` surge / sway, ``sense`` +1) or -x / -y (``sense`` -1)
    through a line over a pulley at the pool edge (module docstring); station kept (DVL position held)."""

    method = "line_pull"
    station = True
    load = "the line"
    change = "change against the line"

    def __init__(self, axis: str, force_n: float, sense: int = 1, settle_s: float = CALIBRATION_SETTLE_S,
                 window_s: float = CALIBRATION_WINDOW_S) -> None:
        if axis not in ("surge", "sway") or sense not in (1, -1):
            raise ValueError(f"LinePull: axis surge or sway and sense +-1, got {axis!r}, {sense!r}")
        self.key = axis if sense > 0 else f"{axis}_negative"
        self.axis_name = axis
        self.name = f"line pull {'+' if sense > 0 else '-'}{'xy'[('surge', 'sway').index(axis)]}"
        super().__init__(force_n, settle_s, window_s)

    def label(self) -> str:
        return f"line pull, {self.axis_name}" + ("" if self.sense > 0 else ", negative")

    def prompts(self):
        sign = "+" if self.sense > 0 else "-"
        return ((f"apply_line_pull_{self.key}",
                 f"calibration: pull the line along {sign}{'xy'[self.axis]} ({self.force_n:.3g} N over the pulley)"),
                (f"release_line_{self.key}", "calibration: release the line"))


class Inclining(Step):
    """Restoring stiffness C of roll or pitch by an inclining test: with that DOF free (no moment
    from the thrusters; depth, position and the other angles held) average the angle a1; the operator hangs the
    test mass (weight in water w) at arm d to starboard (roll: body +y) or forward (pitch: body +x), a moment
    K = w d (roll) or -w d (pitch); average a2; the mass is removed. Equilibrium w d cos(a) = C sin(a) + M0 gives
    C = K / (tan a2 - tan a1) (:func:`~hindrax_onboard.estimation.free_decay.restoring_from_inclining`, two points),
    std from the two means' std. The thrusters only hold the other DOFs, but the moment they realise on the free DOF
    is not exactly the zero commanded (pulse widths near neutral); its change between the two holds, M2 - M1 (thrust
    model, recorded), is added: C = (K + M2 - M1) / (tan a2 - tan a1). It is a few % of K, so a thrust-curve error
    s - 1 moves C by only (s - 1) (M2 - M1) / K. Result in :attr:`~.context.StepContext.inclining` [dof]: value (C,
    N m/rad), std, known_moment_n_m, thruster_moment_n_m [M1, M2], tilt_rad [a1, a2], tilt_std_rad, method."""

    def __init__(self, dof: str, weight_in_water_n: float, arm_m: float, settle_s: float = CALIBRATION_SETTLE_S,
                 window_s: float = CALIBRATION_WINDOW_S) -> None:
        if dof not in ("roll", "pitch"):
            raise ValueError(f"Inclining: roll or pitch, got {dof!r}")
        self.dof = dof
        self.name = f"inclining {dof}"
        self.weight_n = _positive("inclining weight in water", weight_in_water_n)
        self.arm_m = _positive("inclining arm", arm_m)
        self.settle_s = _positive("settle_s", settle_s)
        self.window_s = _positive("window_s", window_s)

    def run(self, ctx: StepContext) -> Wrenches:
        dof = self.dof
        i = DOF_INDEX[dof] - 3
        w, d = self.weight_n, self.arm_m
        moment = w * d if dof == "roll" else -w * d
        where = "to starboard (body +y)" if dof == "roll" else "forward (body +x)"
        yield from ctx.move_to_centre()
        ctx.say(f"inclining ({dof}): {dof} free, without the test mass")
        yield from ctx.hold_free(dof, self.settle_s)
        t1 = ctx.t_s
        yield from ctx.hold_free(dof, self.window_s)
        a1, s1 = ctx.mean_tilt(i, t1)
        m1, ms1 = ctx.mean_recorded_force(i + 3, t1)
        remove = (f"remove_inclining_mass_{dof}", "inclining: remove the test mass")
        yield from ctx.wait_operator(f"attach_inclining_mass_{dof}",
                                     f"inclining: hang the test mass ({w:.3g} N in water) {d:.3g} m {where}",
                                     undo=remove)
        yield from ctx.hold_free(dof, self.settle_s)
        t2 = ctx.t_s
        yield from ctx.hold_free(dof, self.window_s)
        a2, s2 = ctx.mean_tilt(i, t2)
        m2, ms2 = ctx.mean_recorded_force(i + 3, t2)
        yield from ctx.wait_operator(*remove)
        yield from ctx.hold(self.settle_s)
        dt = math.tan(a2) - math.tan(a1)
        total = moment + m2 - m1
        if dt == 0.0 or total / dt <= 0.0:
            raise CampaignAbort(f"inclining ({dof}): the tilt did not follow the test mass ({a1:.4f} -> {a2:.4f} rad)")
        c = total / dt
        ds = math.hypot(s1 / math.cos(a1) ** 2, s2 / math.cos(a2) ** 2)
        ctx.inclining[dof] = {"value": c, "std": abs(c) * math.hypot(ds / dt, math.hypot(ms1, ms2) / total),
                              "known_moment_n_m": moment, "thruster_moment_n_m": [m1, m2],
                              "tilt_rad": [a1, a2], "tilt_std_rad": [s1, s2], "method": "inclining"}
        ctx.say(f"inclining ({dof}): restoring stiffness {c:.3f} N m/rad")


class TiltDecay(Step):
    """Roll or pitch free decay, self-propelled: the vertical thrusters ramp a moment of
    C0 :data:`TILT_DECAY_ANGLE_RAD` (C0 = m g BG of the vehicle file, so the angle reached is only roughly the
    target: the thrust curve need not be right; at most 0.8 of the smaller authority), hold it, then release (zero
    moment on that DOF, the others held) and record :data:`TILT_DECAY_RECORD_S` s; the window goes to
    :attr:`~.context.StepContext.decays`. Rigid + added inertia follow offline from the gyro rate and the inclining
    stiffness (:func:`~hindrax_fit.fit.calibration.decay_inertia`)."""

    def __init__(self, dof: str) -> None:
        if dof not in ("roll", "pitch"):
            raise ValueError(f"TiltDecay: roll or pitch, got {dof!r}")
        self.dof = dof
        self.name = f"tilt decay {dof}"

    def run(self, ctx: StepContext) -> Wrenches:
        dof = self.dof
        k = DOF_INDEX[dof]
        v = ctx.cfg.vehicle
        bg = float(v.centre_of_gravity_frd_m[2]) - float(v.centre_of_buoyancy_frd_m[2])
        c0 = float(ctx.cfg.weight_n) * bg
        moment = min(c0 * TILT_DECAY_ANGLE_RAD, 0.8 * min(ctx.authority[dof]))
        yield from ctx.move_to_centre()
        ctx.say(f"free decay ({dof}): tilt with the vertical thrusters, then release")
        n_ramp = int(round(TILT_DECAY_RAMP_S / ctx.tick_s))
        for i in range(n_ramp + int(round(TILT_DECAY_HOLD_S / ctx.tick_s))):
            w = np.asarray(ctx.ctrl.wrench(ctx.state, (dof,), ctx.tick_s), dtype=float)
            w[k] = moment * min(1.0, i / max(n_ramp, 1))
            yield w
        t0 = ctx.t_s
        yield from ctx.hold_free(dof, TILT_DECAY_RECORD_S)
        ctx.decays[dof] = (t0, ctx.t_s)
        yield from ctx.wait_still(k, 0.05, 8.0)
