"""The identification executive: a small sequencer of campaign steps, one control tick at a time (pure, no rclpy).

The campaign is a list of step objects (:mod:`.steps`): the :class:`~.steps.Dive`, the reference steps with known
forces (:mod:`.steps.calibration_steps`), and per DOF one :class:`~.steps.TranslationLadder` /
:class:`~.steps.RotationLadder` ([Hindrax-Drag] §4) or one :class:`~.steps.BroadbandRun`. The :class:`Executive`
runs them in order on one :class:`~.steps.StepContext` and does what every tick needs whatever the step: the thrust
lag of the recorded force, sensor conditioning, the depth estimate, the online Kalman + RLS of the DOF under test,
and the limit checks. The same object serves both plants: the simulator stepped in-process
(:class:`~.campaign.Campaign`, ``hindrax ident campaign``) and the ROS graph (:class:`~.node.IdentificationNode`, on
the vehicle or in the virtual pool). It never sees the plant, only what a control computer sees, and it never waits:
the caller drives it.

Driving it (one control tick of ``tick_s``)::

    w = ex.start(t0_s)                          # first wrench (FRD, N / N m)
    while w is not None:
        ex.command(thrust_n)                    # thruster forces (n,) N commanded for w: records the tick
        ...                                     # the plant runs for one tick
        w = ex.step(TickInput(t_s, elapsed_s, samples, armed, cancel))   # None once finished
    record = ex.record()

``thrust_n`` is the thrust model of what goes to the thrusters for this tick: in-process the thrust curve
([Hindrax-Drag] eq. 1) of the pulse widths the allocation gives for ``w``; on the graph that of the widths the ESC
node last reported writing (:func:`~...vehicle.signals.thrust_of_written_widths`). The recorded force is that thrust
through the first-order lag ``thrusters.time_constant_s`` over the elapsed time (exact for a command held over the
tick), times the thrust allocation matrix ([Hindrax-Drag] eq. 9), body FRD; the positive (forward) and negative
(reverse) thrust are also lagged apart, so that a calibration step knows which rotation direction held a force,
and the commanded thruster forces go into the record (``thrust_cmd_n``) for the per-direction thrust scales
(:func:`~hindrax_fit.fit.calibration.apply_thrust_calibration`).

Plan (:meth:`Executive.plan`, docs/identification.md §4 and §6): dive; the requested reference steps in a fixed order
(``inclining`` roll, pitch; ``tilt_decay`` roll, pitch; ``ballast``; ``float``; ``line_pull`` +x, +y;
``line_pull_negative`` -x, -y; ``thrust`` = every thrust step, :data:`THRUST_STEPS`); then per requested DOF its
ladder (``identification.levels_per_dof`` levels, or the goal's fractions of the DOF's authority) or, with
``identification.excitation`` (or the ``excitation`` argument) ``multisine``, ``prbs`` or ``chirp``, one broadband run
of ``identification.excitation_duration_s``.

Command rate (``identification.command_rate_hz``, default the tick's rate): the steps' control laws run every tick, and
the wrench :meth:`Executive.start` or :meth:`Executive.step` returns is the law's output of the last command tick, every
:attr:`Executive.command_ticks` ticks, held in between (sample-and-hold); :attr:`Executive.new_command` says whether
this tick's wrench is a new one (the identification node publishes only those). Both plants get the same held command.
Why: on the vehicle each wrench is a message through the allocation, the ESC and the recorder (docs/architecture.md
§10.1), while the samples, the recorded force, the online estimators and the thrust lag stay at the tick's rate.

Stops (:class:`CampaignAbort`, the record says why): a limit (``limits.*``: depth, altitude, roll, pitch; the
pool box grown by half ``pool.margin_m``), no valid DVL velocity for ``dvl_lock_timeout_s`` during surge or sway,
the ESC output disarmed, a cancel request. The caller then commands neutral thrust. A calibration step stopped after
it asked for a load (ballast, float, line, test mass) leaves it in :attr:`Executive.undo`: the aborted status asks
to remove it (:func:`~.steps.undo_line`), and a campaign given it as ``confirm`` first waits, thrusters stopped, for
the operator to confirm each removal (:class:`~.steps.Confirm`)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig, or_default

from ...vehicle.state import DepthEstimator
from ...vehicle.thrust_lag import ThrustLag
from ...vehicle.uncertainty import measurement_settings

from .estimators import OnlineDofEstimator
from .excitation import BROADBAND, DEFAULT_AMPLITUDE_FRACTION, EXCITATIONS
from ...control.maneuvers import level_ladder
from ...vehicle.signals import STILL_MESSAGE
from ..model.campaign_record import CampaignRecord
from .steps import (CALIBRATION_SETTLE_S, CALIBRATION_WINDOW_S, Ballast, BroadbandRun, CampaignAbort, Confirm, Dive,
                    Float, Inclining, LinePull, RotationLadder, Step, StepContext, TiltDecay, TranslationLadder,
                    undo_line)

__all__ = ["CampaignAbort", "Executive", "ExecutiveStatus", "TickInput", "command_ticks", "ordered_samples",
           "CALIBRATION_STEPS", "THRUST_STEPS", "expand_calibration", "calibration_forces", "inclining_load",
           "float_buoyancy"]

#: Reference steps the executive can run before the manoeuvres; ``thrust`` runs every step of :data:`THRUST_STEPS`.
CALIBRATION_STEPS = ("ballast", "line_pull", "tilt_decay", "inclining", "float", "line_pull_negative", "thrust")
#: The steps the per-direction thrust scales need (docs/identification.md §6.1): sinker and float (the vertical
#: thrusters' reverse and forward directions; their hovers against the weighed net buoyancy), line pulls in both
#: senses along surge and sway.
THRUST_STEPS = ("ballast", "float", "line_pull", "line_pull_negative")


def expand_calibration(steps: Iterable[str]) -> list[str]:
    """The step names with ``thrust`` replaced by :data:`THRUST_STEPS`, each name once, in the given order.
    Raises ``ValueError`` for a name not in :data:`CALIBRATION_STEPS`."""
    bad = [s for s in steps if s not in CALIBRATION_STEPS]
    if bad:
        raise ValueError(f"unknown calibration step(s) {bad}; choose from {', '.join(CALIBRATION_STEPS)}")
    out: list[str] = []
    for s in steps:
        for x in (THRUST_STEPS if s == "thrust" else (s,)):
            if x not in out:
                out.append(x)
    return out


def calibration_forces(cfg: VehicleConfig) -> tuple[float, float]:
    """(ballast weight in water (m - rho V) g, line pull force), N, from the vehicle file's ``calibration.*`` keys
    (``ballast_mass_kg``, ``ballast_volume_m3``, ``line_pull_force_n``; validated there: the ballast sinks)."""
    c = cfg.known_forces
    return c.ballast_weight_in_water_n, c.line_pull_force_n


def inclining_load(cfg: VehicleConfig) -> tuple[float, float]:
    """(test mass weight in water (m - rho V) g, N; its arm from the centre line, m) of the inclining step, from
    ``calibration.inclining_mass_kg``, ``calibration.inclining_volume_m3`` and ``calibration.inclining_arm_m``."""
    c = cfg.known_forces
    return c.inclining_weight_in_water_n, c.inclining_arm_m


def float_buoyancy(cfg: VehicleConfig) -> float:
    """Net buoyancy (rho V - m) g of the float step's float, N (``calibration.float_mass_kg``, ``float_volume_m3``);
    0 when the vehicle file has no float."""
    b = cfg.known_forces.float_net_buoyancy_n
    return 0.0 if b is None else float(b)


@dataclass
class TickInput:
    """What the plant hands the executive at a control tick.

    t_s: time of the tick (s, the plant's clock). elapsed_s: time the last command was held (s; the lag of the
    recorded force runs over it). samples: new sensor samples ``(device, sample)`` in the simulator's form
    (:mod:`hindrax_sim.sensors`, or :mod:`...vehicle.signals` from ROS messages), in the order to condition them.
    armed: the ESC output is armed. cancel: the operator asked to stop."""

    t_s: float
    elapsed_s: float
    samples: Sequence[tuple[str, Any]] = ()
    armed: bool = True
    cancel: bool = False


@dataclass
class ExecutiveStatus:
    """Where the campaign is: phase ``"positioning"`` (dive, moving, settling), ``"running"`` (a level is commanded) or
    ``"returning"`` (between runs of a DOF), or ``"done"`` / ``"aborted"``; the DOF under test ('' when none), level
    index and count, level command (N or N m, FRD; 0 outside runs), progress 0-1 and the current step's message."""

    phase: str
    dof: str
    level_index: int
    level_count: int
    level_command: float
    progress: float
    message: str


def ordered_samples(samples: Iterable[tuple[str, Any]], not_before_s: float = -math.inf,
                    not_after_s: float = math.inf, drop_before_s: float = -math.inf) -> list[tuple[str, Any]]:
    """Samples sorted by stamp (stable), each stamped before ``not_before_s`` moved to it (a copy), those stamped
    after ``not_after_s`` or before ``drop_before_s`` (s) left out.

    For samples that arrive late (sensor latency through a graph: the MS5837 stamp of its conversion start, the DVL time
    of validity), the online filters have already been predicted to the previous tick, ``not_before_s``; the messages
    and the bag keep the original stamps. Samples outside [``drop_before_s``, ``not_after_s``] cannot be valid (a
    publisher on another clock, such as a second graph on the same ROS domain; :mod:`.core`'s tolerances); the caller
    counts those left out (``len(samples) - len(result)``)."""
    out = []
    for dev, s in sorted(samples, key=lambda ds: ds[1].stamp_s):
        if not drop_before_s <= s.stamp_s <= not_after_s:
            continue
        if s.stamp_s < not_before_s:
            s = SimpleNamespace(**{**vars(s), "stamp_s": not_before_s})
        out.append((dev, s))
    return out


def _positive(x: float) -> bool:
    return math.isfinite(x) and x > 0


def command_ticks(cfg: VehicleConfig, tick_s: float, command_rate_hz: float | None = None) -> int:
    """Control ticks of ``tick_s`` (s) a wrench command is held for (module docstring, "Command rate"):
    ``round(1 / (rate * tick_s))``, at least 1, with ``command_rate_hz`` (Hz) or else ``identification.command_rate_hz``
    of ``cfg``, else every tick. Raises ``ValueError`` for a rate that is not finite and > 0."""
    rate = or_default(cfg.identification.command_rate_hz, 1.0 / tick_s) if command_rate_hz is None \
        else command_rate_hz
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"command_rate_hz must be > 0 Hz, got {rate}")
    return max(1, round(1.0 / (float(rate) * tick_s)))


class Executive:
    """The identification campaign as a tick-driven sequencer of steps (module docstring).

    cfg: vehicle configuration. dofs: DOFs to test, in order (default all six). levels: levels per DOF (default
    ``identification.levels_per_dof``). tick_s: control period (s). fractions: optional explicit level fractions
    of the DOF's smaller authority (each in (0, 1]), instead of the configured ladder. max_level_duration_s: cap
    of one run (default ``identification.max_level_duration_s``). heave_repeats: down/up pairs
    per heave level (default ``identification.heave_repeats``, 3 when absent). dvl_lock_timeout_s:
    longest time without a valid DVL velocity during surge or sway. progress: optional
    callable receiving one-line messages as the campaign moves on. calibrate: reference steps to run after the
    dive, before the manoeuvres (:data:`CALIBRATION_STEPS`); ``ballast`` needs ``ballast_weight_in_water_n`` (> 0,
    N: (m - rho V) g of the ballast), ``line_pull`` and ``line_pull_negative`` need ``line_pull_n`` (> 0, N: the
    horizontal force of the line over the pulley), ``float`` needs ``float_buoyancy_n`` (> 0, N: (rho V - m) g of the
    float; default :func:`float_buoyancy` of the vehicle file), ``inclining`` needs ``inclining_load_n_m`` (weight in
    water of the test mass > 0 N, its arm > 0 m: :func:`inclining_load`). While a step waits for the operator,
    :attr:`awaiting` names what to do and :meth:`operator_continue` resumes it.
    excitation: ``ladder`` (default: ``identification.excitation``, else ladder) or a broadband signal of
    :data:`~.excitation.BROADBAND`; excitation_duration_s: length of that run per DOF (default
    ``identification.excitation_duration_s``, else 60 s); excitation_amplitude_fraction: its peak as a fraction of
    the DOF's smaller authority. steps: run these :class:`~.steps.Step` objects instead of :meth:`plan` (a test of
    one step: ``[Dive(), Ballast(w, settle_s=3, window_s=9)]``). command_rate_hz: rate of new wrench commands
    (module docstring, "Command rate"; default ``identification.command_rate_hz``, else every tick); a command is
    held for :func:`command_ticks` ticks. confirm: (remove code, instruction) pairs an aborted campaign left
    (its :attr:`undo`): the operator confirms each first, thrusters stopped (module docstring, "Stops").
    Raises ``ValueError`` for an unknown DOF, a fraction outside (0, 1] or a tick_s that is not > 0, an unknown
    calibration step or a missing known force, an unknown excitation or a non-positive duration or command rate."""

    def __init__(self, cfg: VehicleConfig, dofs: Sequence[str] = DOFS, levels: int | None = None, *,
                 tick_s: float, fractions: Sequence[float] | None = None, max_level_duration_s: float | None = None,
                 heave_repeats: int | None = None, dvl_lock_timeout_s: float = 3.0,
                 progress: Callable[[str], None] | None = None, calibrate: Sequence[str] = (),
                 ballast_weight_in_water_n: float = 0.0, line_pull_n: float = 0.0,
                 inclining_load_n_m: Sequence[float] = (0.0, 0.0), excitation: str | None = None,
                 excitation_duration_s: float | None = None,
                 excitation_amplitude_fraction: float = DEFAULT_AMPLITUDE_FRACTION,
                 float_buoyancy_n: float | None = None, steps: Sequence[Step] | None = None,
                 command_rate_hz: float | None = None, confirm: Sequence[tuple[str, str]] = ()) -> None:
        bad = [d for d in dofs if d not in DOFS]
        if bad:
            raise ValueError(f"unknown DOF(s) {bad}; choose from {', '.join(DOFS)}")
        if fractions and any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fractions):
            raise ValueError(f"level fractions must be in (0, 1], got {list(fractions)}")
        if not (math.isfinite(tick_s) and tick_s > 0.0):
            raise ValueError(f"tick_s must be > 0, got {tick_s}")
        calibrate = expand_calibration(calibrate)
        if float_buoyancy_n is None:
            float_buoyancy_n = float_buoyancy(cfg) if "float" in calibrate else 0.0
        if "ballast" in calibrate and not _positive(ballast_weight_in_water_n):
            raise ValueError("ballast_weight_in_water_n must be > 0 N for the ballast step, "
                             f"got {ballast_weight_in_water_n}")
        for name in ("line_pull", "line_pull_negative"):
            if name in calibrate and not _positive(line_pull_n):
                raise ValueError(f"line_pull_n must be > 0 N for the {name} step, got {line_pull_n}")
        if "float" in calibrate and not _positive(float_buoyancy_n):
            raise ValueError(f"float_buoyancy_n must be > 0 N for the float step (calibration.float_mass_kg and "
                             f"float_volume_m3 of the vehicle file), got {float_buoyancy_n}")
        if "inclining" in calibrate and not (len(inclining_load_n_m) == 2 and all(
                math.isfinite(x) and x > 0 for x in inclining_load_n_m)):
            raise ValueError(f"inclining_load_n_m must be (weight in water > 0 N, arm > 0 m) for the inclining step, "
                             f"got {inclining_load_n_m}")
        self.inclining_load_n_m = tuple(float(x) for x in inclining_load_n_m)
        self.calibrate = list(calibrate)
        self.ballast_weight_in_water_n = float(ballast_weight_in_water_n)
        self.line_pull_n = float(line_pull_n)
        self.float_buoyancy_n = float(float_buoyancy_n)
        ident = cfg.identification
        self.excitation = str(or_default(ident.excitation, "ladder") if excitation is None else excitation)
        if self.excitation not in EXCITATIONS:
            raise ValueError(f"excitation {self.excitation!r}: choose from {', '.join(EXCITATIONS)}")
        self.excitation_duration_s = float(or_default(ident.excitation_duration_s, 60.0)
                                           if excitation_duration_s is None else excitation_duration_s)
        if not (math.isfinite(self.excitation_duration_s) and self.excitation_duration_s > 0):
            raise ValueError(f"excitation_duration_s must be > 0 s, got {self.excitation_duration_s}")
        if not (0.0 < excitation_amplitude_fraction <= 1.0):
            raise ValueError(f"excitation_amplitude_fraction must be in (0, 1], got {excitation_amplitude_fraction}")
        self.excitation_amplitude_fraction = float(excitation_amplitude_fraction)
        self.cfg = cfg
        self.dofs = list(dofs)
        self.tick_s = float(tick_s)
        #: ticks a wrench command is held for (module docstring, "Command rate")
        self.command_ticks = command_ticks(cfg, self.tick_s, command_rate_hz)
        #: whether the wrench of the last start() or step() is a new command (else the held one)
        self.new_command = False
        self._ticks = 0
        self._command: np.ndarray | None = None
        self.levels_per_dof = levels
        self.fractions = [float(x) for x in fractions] if fractions else None
        repeats = or_default(ident.heave_repeats, 3) if heave_repeats is None else heave_repeats
        self.heave_repeats = max(1, int(repeats))
        self.max_level_s = float(ident.max_level_duration_s if max_level_duration_s is None else max_level_duration_s)
        self.dvl_lock_timeout_s = float(dvl_lock_timeout_s)
        #: the state every step shares (sensors, holds, pool box, tick log, results, operator hand-shake)
        self.ctx = StepContext(cfg, self.tick_s, progress)
        hv = measurement_settings(cfg, "heave")
        self.depth_estimator = DepthEstimator(hv["std"], hv["accel_std"], hv["accel_jerk_psd"])
        self.online = {d: OnlineDofEstimator(cfg, d) for d in self.dofs}
        n = len(self.core.names)
        self.f_lag = np.zeros(n)
        self._f_pos = np.zeros(n)   # lagged positive (forward) and negative (reverse) thrust, apart
        self._f_neg = np.zeros(n)
        self._f_cmd = np.zeros(n)
        self.last_dvl_valid_s = math.nan
        self.finished = False
        self.aborted = False
        self.abort_reason = ""
        self._last_level = ("", 0)
        self._gen = None
        #: the steps run by :meth:`start`, in order; first the :class:`~.steps.Confirm` of ``confirm``
        self.steps: list[Step] = list(steps) if steps is not None else self.plan()
        if confirm:
            self.steps.insert(0, Confirm(confirm))
            self.ctx.undo.update(dict(confirm))

    # ------------------------------------------------------------------ the shared state, by name
    #: :class:`~.steps.StepContext` fields read on the executive by name (the context documents them): the conditioned
    #: sensors ``state``, the pool ``box``, the allocation model ``core``, ``curve``, ``matrix``, ``authority``,
    #: ``time_constant_s``, the step results, ``awaiting`` and ``prompt`` (operator), ``message``, ...
    _SHARED = frozenset({"state", "box", "core", "curve", "matrix", "authority", "time_constant_s",
                         "calibration", "inclining", "decays", "windows", "levels", "awaiting",
                         "prompt", "message", "depth_hold_m", "t_s"})

    def __getattr__(self, name: str) -> Any:
        if name in Executive._SHARED:
            return getattr(self.ctx, name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def undo(self) -> list[tuple[str, str]]:
        """Loads asked for and not removed yet: (remove code, instruction) pairs (module docstring, "Stops")."""
        return list(self.ctx.undo.items())

    def operator_continue(self) -> bool:
        """The operator's ``continue``: resumes a calibration step waiting in :attr:`awaiting`; False (nothing
        done) when no step waits."""
        return self.ctx.operator_continue()

    # ------------------------------------------------------------------ the plan
    def ladder(self, dof: str) -> list[float]:
        """Levels of one DOF (N or N m): the explicit fractions times the DOF's smaller authority, else
        :func:`...control.maneuvers.level_ladder` of it."""
        if self.fractions:
            return [x * min(self.authority[dof]) for x in self.fractions]
        return level_ladder(self.cfg, min(self.authority[dof]), self.levels_per_dof)

    def dof_step(self, dof: str) -> Step:
        """The manoeuvre step of one DOF: its broadband run with a broadband :attr:`excitation`, else its ladder."""
        if self.excitation in BROADBAND:
            return BroadbandRun(dof, self.excitation, self.excitation_duration_s, self.excitation_amplitude_fraction)
        if dof in ("surge", "sway", "heave"):
            return TranslationLadder(dof, self.ladder(dof), self.max_level_s, self.heave_repeats)
        return RotationLadder(dof, self.ladder(dof), self.max_level_s)

    def plan(self) -> list[Step]:
        """The steps of the campaign (module docstring): dive, the reference steps of :attr:`calibrate` in their
        fixed order, one manoeuvre step per DOF. The calibration holds last ``calibration.hold_settle_s`` and
        ``hold_window_s`` of the vehicle file, else :data:`CALIBRATION_SETTLE_S` and :data:`CALIBRATION_WINDOW_S`
        (this module's values when the plan is made)."""
        cal = self.calibrate
        c = self.cfg.calibration
        hold = {"settle_s": or_default(c.hold_settle_s, CALIBRATION_SETTLE_S),
                "window_s": or_default(c.hold_window_s, CALIBRATION_WINDOW_S)} if cal else {}
        out: list[Step] = [Dive()]
        if "inclining" in cal:
            out += [Inclining(d, *self.inclining_load_n_m, **hold) for d in ("roll", "pitch")]
        if "tilt_decay" in cal:
            out += [TiltDecay(d) for d in ("roll", "pitch")]
        if "ballast" in cal:
            out.append(Ballast(self.ballast_weight_in_water_n, **hold))
        if "float" in cal:
            out.append(Float(self.float_buoyancy_n, **hold))
        for name, sense in (("line_pull", 1), ("line_pull_negative", -1)):
            if name in cal:
                out += [LinePull(axis, self.line_pull_n, sense, **hold) for axis in ("surge", "sway")]
        return out + [self.dof_step(d) for d in self.dofs]

    # ------------------------------------------------------------------ driving
    @property
    def started(self) -> bool:
        """True once :meth:`start` ran."""
        return self._gen is not None

    def start(self, t_s: float) -> np.ndarray | None:
        """Begin the campaign at time ``t_s`` (s); returns the first wrench (6,) FRD. Raises ``RuntimeError``
        when already started."""
        if self._gen is not None:
            raise RuntimeError("the executive has already started")
        self.ctx.t_s = float(t_s)
        self.last_dvl_valid_s = self.ctx.t_s
        self._gen = self._campaign()
        self._ticks = 0
        return self._hold(self._resume())

    def _campaign(self):
        for step in self.steps:
            yield from step.run(self.ctx)

    def command(self, thrust_n: np.ndarray) -> None:
        """Record the current tick with the thruster forces (n,) N commanded for the wrench just returned."""
        f_cmd = np.asarray(thrust_n, dtype=float)
        m = self.matrix
        self.ctx.log_tick(m @ self.f_lag, m @ f_cmd, m @ self._f_pos, m @ self._f_neg, f_cmd)
        self._f_cmd = f_cmd

    def step(self, inp: TickInput) -> np.ndarray | None:
        """One control tick: lag the commanded thrust over ``inp.elapsed_s``, condition ``inp.samples``, update the
        depth estimate and the online estimator of the DOF under test, check cancel, arming and limits; returns the
        next wrench (6,) FRD, or None once the campaign has finished (done or aborted: :attr:`aborted`,
        :attr:`abort_reason`). Raises ``RuntimeError`` before :meth:`start`."""
        if self._gen is None:
            raise RuntimeError("call start() first")
        if self.finished:
            return None
        ctx = self.ctx
        ctx.t_s = float(inp.t_s)
        fc = self._f_cmd
        fp, fn = np.maximum(fc, 0.0), np.minimum(fc, 0.0)
        lag, dt = ThrustLag(self.time_constant_s), float(inp.elapsed_s)
        self.f_lag = lag.advance(self.f_lag, fc, dt)
        self._f_pos = lag.advance(self._f_pos, fp, dt)
        self._f_neg = lag.advance(self._f_neg, fn, dt)
        st = ctx.state
        for dev, s in inp.samples:
            st.on_sample(dev, s)
            self.depth_estimator.on_sample(dev, s.stamp_s, st)
            for est in self.online.values():
                est.on_sample(dev, s.stamp_s, st)
            if dev == "dvl75" and s.locked:
                self.last_dvl_valid_s = max(self.last_dvl_valid_s, s.stamp_s)
        depth, rate = self.depth_estimator.predict_to(ctx.t_s)
        if math.isfinite(rate):
            ctx.ctrl.depth_rate_m_s = rate
            ctx.ctrl.depth_estimate_m = depth
        if ctx.active >= 0:
            dof = DOFS[ctx.active]
            if dof in self.online:
                self.online[dof].update(ctx.t_s, float((self.matrix @ self.f_lag)[ctx.active]), st)
        try:
            if inp.cancel:
                raise CampaignAbort("cancelled")
            if not inp.armed:
                raise CampaignAbort("ESC output disarmed")
            self._check_limits()
        except CampaignAbort as exc:
            self._abort(str(exc))
            return None
        self._ticks += 1
        return self._hold(self._resume())

    def _hold(self, w: np.ndarray | None) -> np.ndarray | None:
        """The wrench to command this tick (module docstring, "Command rate"): the law's ``w`` on a command tick,
        else the last command; None (finished) at once."""
        self.new_command = w is not None and (self._command is None or self._ticks % self.command_ticks == 0)
        if w is None or self.new_command:
            self._command = w
        return self._command

    def _resume(self) -> np.ndarray | None:
        try:
            return np.asarray(next(self._gen), dtype=float)
        except StopIteration:
            self._finish()
        except CampaignAbort as exc:
            self._abort(str(exc))
        return None

    def _abort(self, reason: str) -> None:
        ctx = self.ctx
        self.aborted, self.abort_reason = True, reason
        ctx.say(f"ABORT: {reason}" + (f"; {undo_line(self.undo)}" if self.undo else ""))
        if ctx.active >= 0 and DOFS[ctx.active] not in ctx.windows:
            ctx.windows[DOFS[ctx.active]] = (self._dof_start(), ctx.t_s)
        if self._gen is not None:
            self._gen.close()
        self._finish()

    def _finish(self) -> None:
        self.finished = True
        self.ctx.awaiting = self.ctx.prompt = ""  # nothing waits for the operator any more
        self.ctx.active = -1
        self.ctx.end_run()
        self.f_lag = np.zeros_like(self.f_lag)  # the caller commands neutral thrust
        self._f_pos = np.zeros_like(self.f_lag)
        self._f_neg = np.zeros_like(self.f_lag)

    def _dof_start(self) -> float:
        act = np.asarray(self.ctx.rec["active"])
        idx = np.flatnonzero(act == self.ctx.active)
        return float(self.ctx.rec["t"][idx[0]]) if idx.size else self.ctx.t_s

    def record(self, *, truth_position_ned_m: np.ndarray | None = None, truth_euler_rad: np.ndarray | None = None,
               wall_time_s: float = math.nan, seed: int = 0,
               final_pulse_width_us: np.ndarray | None = None) -> CampaignRecord:
        """The :class:`~..model.campaign_record.CampaignRecord` so far (the truth arrays, when the plant has them,
        are NaN otherwise)."""
        ctx = self.ctx
        r = ctx.rec
        n = len(r["t"])
        nan3 = np.full((n, 3), np.nan)
        return CampaignRecord(
            t_s=np.asarray(r["t"]), wrench_frd=np.asarray(r["w"]).reshape(-1, 6),
            wrench_cmd_frd=np.asarray(r["wc"]).reshape(-1, 6), active=np.asarray(r["active"], dtype=int),
            level=np.asarray(r["level"], dtype=float), run_id=np.asarray(r["run"], dtype=int),
            truth_position_ned_m=(nan3 if truth_position_ned_m is None
                                  else np.asarray(truth_position_ned_m).reshape(-1, 3)),
            truth_euler_rad=nan3.copy() if truth_euler_rad is None else np.asarray(truth_euler_rad).reshape(-1, 3),
            sensors=ctx.state.log, windows=dict(ctx.windows), online=self.online, levels=ctx.levels,
            authority=ctx.authority, aborted=self.aborted, abort_reason=self.abort_reason, wall_time_s=wall_time_s,
            tick_s=self.tick_s, time_constant_s=self.time_constant_s, seed=int(seed),
            final_pulse_width_us=np.zeros(0) if final_pulse_width_us is None else np.asarray(final_pulse_width_us),
            calibration={k: dict(v) for k, v in ctx.calibration.items()}, decays=dict(ctx.decays),
            inclining={k: dict(v) for k, v in ctx.inclining.items()},
            thrust_cmd_n=np.asarray(r["fc"], dtype=float).reshape(n, len(self.core.names)))

    # ------------------------------------------------------------------ status
    def level_position(self) -> tuple[str, int, int, float]:
        """(DOF, level index, level count, level command) of the current tick ('' / 0 / 0 / 0.0 when none)."""
        ctx = self.ctx
        if ctx.active < 0:
            return "", 0, 0, 0.0
        dof = DOFS[ctx.active]
        ladder = ctx.levels.get(dof, [])
        last = self._last_level
        if not math.isfinite(ctx.level) or not ladder:
            return dof, last[1] if last[0] == dof else 0, len(ladder), 0.0
        i = int(np.argmin([abs(abs(ctx.level) - lv) for lv in ladder]))
        self._last_level = (dof, i)
        return dof, i, len(ladder), float(ctx.level)

    def status(self) -> ExecutiveStatus:
        """:class:`ExecutiveStatus` of the current tick; progress: the DOFs finished plus the middle
        of the current level."""
        dof, i, count, cmd = self.level_position()
        if self.finished:
            phase = "aborted" if self.aborted else "done"
            message = "; ".join(filter(None, (self.abort_reason, undo_line(self.undo)))) if self.aborted \
                else "campaign complete"
        else:
            phase = "running" if self.ctx.run >= 0 else ("returning" if dof else "positioning")
            message = STILL_MESSAGE if self.state.collecting_gyro_bias else self.message
        inner = (i + 0.5) / count if (dof and count and dof not in self.windows) else 0.0
        done = (len(self.windows) + inner) / max(1, len(self.dofs))
        progress = 1.0 if phase == "done" else min(1.0, done)
        return ExecutiveStatus(phase, dof, i, count, cmd, progress, message)

    # ------------------------------------------------------------------ checks
    def _check_limits(self) -> None:
        lim = self.cfg.limits
        st = self.state
        if math.isfinite(st.depth_m) and st.depth_m > lim.max_depth_m:
            raise CampaignAbort(f"depth {st.depth_m:.2f} m beyond limits.max_depth_m {lim.max_depth_m:g}")
        if math.isfinite(st.altitude_m) and st.altitude_m < lim.min_altitude_m:
            raise CampaignAbort(f"altitude {st.altitude_m:.2f} m below limits.min_altitude_m {lim.min_altitude_m:g}")
        roll, pitch = st.rpy_rad[0], st.rpy_rad[1]
        if math.isfinite(roll) and abs(roll) > lim.max_roll_rad:
            raise CampaignAbort(f"roll {roll:.2f} rad beyond limits.max_roll_rad {lim.max_roll_rad:g}")
        if math.isfinite(pitch) and abs(pitch) > lim.max_pitch_rad:
            raise CampaignAbort(f"pitch {pitch:.2f} rad beyond limits.max_pitch_rad {lim.max_pitch_rad:g}")
        p = st.position_ned_m
        tol = 0.5 * float(self.cfg.pool.margin_m)
        b = self.box
        if not (b.x_min - tol <= p[0] <= b.x_max + tol and b.y_min - tol <= p[1] <= b.y_max + tol):
            raise CampaignAbort(f"dead-reckoned position ({p[0]:.2f}, {p[1]:.2f}) m left the pool box")
        active = self.ctx.active
        if active in (0, 1) and self.ctx.t_s - self.last_dvl_valid_s > self.dvl_lock_timeout_s:
            raise CampaignAbort(f"DVL lock lost for {self.ctx.t_s - self.last_dvl_valid_s:.1f} s during "
                                f"{DOFS[active]} (dvl_lock_timeout_s {self.dvl_lock_timeout_s:g})")
