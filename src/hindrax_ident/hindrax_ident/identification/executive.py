"""The identification executive: [Hindrax-Drag] §4 manoeuvres, one control tick at a time (pure, no rclpy).

One object runs the whole campaign logic (dive, positioning, level ladders, holds, pool-box planning, limits, the
online Kalman + RLS) for both plants: the simulator stepped in-process (:class:`~.campaign.Campaign`, ``hindrax
ident campaign``) and the ROS graph (:class:`~.node.IdentificationNode`, on the vehicle or in the virtual pool).
It never sees the plant, only what a control computer sees, and it never waits: the caller drives it.

Driving it (one control tick of ``tick_s``)::

    w = ex.start(t0_s)                          # first wrench (FRD, N / N m)
    while w is not None:
        ex.command(thrust_n)                    # thruster forces (n,) N commanded for w: records the tick
        ...                                     # the plant runs for one tick
        w = ex.step(TickInput(t_s, elapsed_s, samples, armed, cancel))   # None once finished
    record = ex.record()

``thrust_n`` is the thrust model of what goes to the thrusters for this tick: in-process the thrust curve
([Hindrax-Drag] eq. 1) of the pulse widths the allocation gives for ``w``; on the graph that of
the widths the ESC node last reported writing (:func:`~.signals.thrust_of_written_widths`). The recorded force
is that thrust through the first-order lag ``thrusters.time_constant_s`` over the elapsed time (exact for a
command held over the tick), times the thrust allocation matrix ([Hindrax-Drag] eq. 9), body FRD.

Sequence (docs/identification.md): dive to the altitude setpoint (``identification.altitude_setpoint_m``,
Ping1D) and settle (the gyro and accelerometer biases are averaged while still), then for each requested DOF:
move to the pool-box centre and run the ladder of constant levels (:func:`.maneuvers.level_ladder`, or the
goal's explicit fractions of the DOF's authority) with the other DOFs held by :class:`.maneuvers.HoldController`:

* surge, sway: alternate +level / -level runs along the body axis (heading held at the start heading); a run
  ends when the dead-reckoned stopping point reaches the :class:`.maneuvers.PoolBox` boundary or after
  ``identification.max_level_duration_s``; the larger room is used first, so both directions are tested.
* heave: down then up within the box depth range, ``heave_repeats`` pairs per level (no steady state needed:
  estimated through the transient).
* roll, pitch: rotate until the predicted stopping angle reaches ``identification.roll_test_angle_rad`` /
  ``pitch_test_angle_rad``, then return to level ([Hindrax-Drag] §4.2), both directions.
* yaw: one turn (2 pi) per run ([Hindrax-Drag] §4.2: 360 deg rotations), both directions.

With ``identification.excitation`` (or the ``excitation`` argument) ``multisine``, ``prbs`` or ``chirp`` instead of
the default ``ladder``, each DOF gets one broadband run of ``identification.excitation_duration_s`` instead of its
ladder (:meth:`Executive._excite`, signals and pool-box shaping in :mod:`.excitation`), identified by the same
output-error fit.

Stops (:class:`CampaignAbort`, the record says why): a limit (``limits.*``: depth, altitude, roll, pitch; the
pool box grown by half ``pool.margin_m``), no valid DVL velocity for ``dvl_lock_timeout_s`` during surge or sway,
the ESC output disarmed, a cancel request. The caller then commands neutral thrust.

The manoeuvres are written as one generator (each ``yield`` hands out the wrench of one tick and resumes with
the next tick's conditioned samples), so the sequence reads as a procedure and no thread or queue is needed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Callable, Generator, Iterable, Sequence

import numpy as np

from hindrax_drivers.allocation.core import AllocationCore
from hindrax_drivers.config import DOFS, VehicleConfig

from .estimators import OnlineDofEstimator, measurement_settings, truth_parameters
from .excitation import BROADBAND, DEFAULT_AMPLITUDE_FRACTION, EXCITATIONS, BoxShaping, design_band, design_signal
from .maneuvers import (DOF_INDEX, DepthEstimator, HoldController, PoolBox, SensorState, dof_authority,
                        level_ladder, prior_inertia, wrap_angle)
from .signals import STILL_MESSAGE

__all__ = ["CampaignAbort", "CampaignRecord", "Executive", "ExecutiveStatus", "TickInput", "ordered_samples",
           "CALIBRATION_STEPS", "calibration_forces"]

#: Known-force calibration steps the executive can run before the ladders (issue 17 item 1).
CALIBRATION_STEPS = ("ballast", "line_pull", "tilt_decay", "inclining")


def calibration_forces(cfg: VehicleConfig) -> tuple[float, float]:
    """(ballast weight in water (m - rho V) g, line pull force), N, from the vehicle file's ``calibration.*`` keys
    (``ballast_mass_kg``, ``ballast_volume_m3``, ``line_pull_force_n``; validated there: the ballast sinks)."""
    f = cfg.flat
    w = (float(f["calibration.ballast_mass_kg"]) - float(f["calibration.ballast_volume_m3"])
         * float(cfg.water_density_kg_m3)) * float(cfg.gravity_m_s2)
    return w, float(f["calibration.line_pull_force_n"])


def inclining_load(cfg: VehicleConfig) -> tuple[float, float]:
    """(test mass weight in water (m - rho V) g, N; its arm from the centre line, m) of the inclining step, from
    ``calibration.inclining_mass_kg``, ``calibration.inclining_volume_m3`` and ``calibration.inclining_arm_m``."""
    f = cfg.flat
    w = (float(f["calibration.inclining_mass_kg"]) - float(f["calibration.inclining_volume_m3"])
         * float(cfg.water_density_kg_m3)) * float(cfg.gravity_m_s2)
    return w, float(f["calibration.inclining_arm_m"])


#: tilt_decay: tilt angle aimed at (rad), ramp and hold before the release, and the recorded decay (s).
TILT_DECAY_ANGLE_RAD = 0.25
TILT_DECAY_RAMP_S = 6.0
TILT_DECAY_HOLD_S = 4.0
TILT_DECAY_RECORD_S = 25.0
#: Settling time before, and averaging window of, each calibration hold (s).
CALIBRATION_SETTLE_S = 15.0
CALIBRATION_WINDOW_S = 30.0
#: Block length of the batch means giving the std of the mean holding force (s; several depth-hold time constants).
CALIBRATION_BLOCK_S = 3.0

Wrenches = Generator[np.ndarray, None, None]


class CampaignAbort(RuntimeError):
    """A limit was crossed, the ESC disarmed, the DVL lost or a cancel came (the message says which)."""


@dataclass
class CampaignRecord:
    """Everything a campaign produced (arrays per control tick, shape (n,) or (n, k)).

    t_s: tick times (s). wrench_frd: thrust-model wrench at the tick (lagged), (n, 6) N / N m.
    wrench_cmd_frd: wrench of the commanded thrust held over the tick (n, 6). active: index of the DOF
    under test (-1 none). level: the test level commanded in a run (NaN outside runs). run_id: run counter
    (-1 outside runs). truth_position_ned_m / truth_euler_rad (n, 3): simulator truth, for tests and plots
    only (never used by control or estimation; NaN on the ROS graph). sensors: the conditioned sensor log of
    :class:`.maneuvers.SensorState`. windows: DOF -> (t_start, t_end). online: DOF -> OnlineDofEstimator.
    levels / authority: DOF -> ladder (N or N m) / (positive, negative) authority. aborted, abort_reason,
    wall_time_s, tick_s, time_constant_s, seed, final_pulse_width_us.
    """

    t_s: np.ndarray
    wrench_frd: np.ndarray
    wrench_cmd_frd: np.ndarray
    active: np.ndarray
    level: np.ndarray
    run_id: np.ndarray
    truth_position_ned_m: np.ndarray
    truth_euler_rad: np.ndarray
    sensors: dict
    windows: dict
    online: dict
    levels: dict
    authority: dict
    aborted: bool
    abort_reason: str
    wall_time_s: float
    tick_s: float
    time_constant_s: float
    seed: int
    final_pulse_width_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: known-force calibration results (:meth:`Executive._ballast`): {"vertical": {value, std, known_force_n,
    #: holding_force_n, holding_force_std_n, method}}; empty without a calibration step
    calibration: dict = field(default_factory=dict)
    #: roll/pitch free decays (:meth:`Executive._tilt_decay`): DOF -> (t_release, t_end), s
    decays: dict = field(default_factory=dict)
    #: inclining steps (:meth:`Executive._inclining`): DOF -> {value (C, N m/rad), std, known_moment_n_m,
    #: tilt_rad [without, with the mass], tilt_std_rad, method}; empty without the step
    inclining: dict = field(default_factory=dict)

    def dof_slice(self, dof: str) -> slice:
        """Tick index range of one DOF's manoeuvres (empty slice when it was not run)."""
        if dof not in self.windows:
            return slice(0, 0)
        t0, t1 = self.windows[dof]
        i0 = int(np.searchsorted(self.t_s, t0, side="left"))
        i1 = int(np.searchsorted(self.t_s, t1, side="right"))
        return slice(i0, i1)


@dataclass
class TickInput:
    """What the plant hands the executive at a control tick.

    t_s: time of the tick (s, the plant's clock). elapsed_s: time the last command was held (s; the lag of the
    recorded force runs over it). samples: new sensor samples ``(device, sample)`` in the simulator's form
    (:mod:`hindrax_ident.sim.sensors`, or :mod:`.signals` from ROS messages), in the order to condition them.
    armed: the ESC output is armed. cancel: the operator asked to stop.
    """

    t_s: float
    elapsed_s: float
    samples: Sequence[tuple[str, Any]] = ()
    armed: bool = True
    cancel: bool = False


@dataclass
class ExecutiveStatus:
    """Where the campaign is: phase ``"positioning"`` (dive, moving, settling), ``"running"`` (a level is
    commanded) or ``"returning"`` (between runs of a DOF), or ``"done"`` / ``"aborted"``; the DOF under test
    ('' when none), level index and count, level command (N or N m, FRD; 0 outside runs), progress 0-1 and
    the current step's message."""

    phase: str
    dof: str
    level_index: int
    level_count: int
    level_command: float
    progress: float
    message: str


def ordered_samples(samples: Iterable[tuple[str, Any]], not_before_s: float = -math.inf) -> list[tuple[str, Any]]:
    """Samples sorted by stamp (stable), each stamped before ``not_before_s`` moved to it (a copy).

    For samples that arrive late (sensor latency through a graph: the MS5837 stamp of its conversion start, the
    DVL time of validity): the online filters have already been predicted to the previous tick, ``not_before_s``;
    the messages and the bag keep the original stamps, which the offline analysis uses."""
    out = []
    for dev, s in sorted(samples, key=lambda ds: ds[1].stamp_s):
        if s.stamp_s < not_before_s:
            s = SimpleNamespace(**{**vars(s), "stamp_s": not_before_s})
        out.append((dev, s))
    return out


class Executive:
    """The identification campaign as a tick-driven state machine (module docstring).

    cfg: vehicle configuration. dofs: DOFs to test, in order (default all six). levels: levels per DOF (default
    ``identification.levels_per_dof``). tick_s: control period (s). fractions: optional explicit level fractions
    of the DOF's smaller authority (each in (0, 1]), instead of the configured ladder. max_level_duration_s: cap
    of one run (default ``identification.max_level_duration_s``). heave_repeats: down/up pairs per heave level.
    dvl_lock_timeout_s: longest time without a valid DVL velocity during surge or sway. progress: optional
    callable receiving one-line messages as the campaign moves on. calibrate: known-force steps to run after the
    dive, before the ladders (:data:`CALIBRATION_STEPS`); ``ballast`` needs ``ballast_weight_in_water_n`` (> 0,
    N: (m - rho V) g of the ballast), ``line_pull`` needs ``line_pull_n`` (> 0, N: the horizontal force of the line
    over the pulley, e.g. the weight of a hanging mass); ``inclining`` needs ``inclining_load_n_m`` (weight in water
    of the test mass > 0 N, its arm > 0 m: :func:`inclining_load`). While a step waits for the operator,
    :attr:`awaiting` names what to do and :meth:`operator_continue` resumes it.
    excitation: ``ladder`` (default: ``identification.excitation``, else ladder) or a broadband signal of
    :data:`~.excitation.BROADBAND`; excitation_duration_s: length of that run per DOF (default
    ``identification.excitation_duration_s``, else 60 s); excitation_amplitude_fraction: its peak as a fraction of
    the DOF's smaller authority.
    Raises ``ValueError`` for an unknown DOF, a fraction outside (0, 1] or a tick_s that is not > 0, an unknown
    calibration step or a missing ballast weight, an unknown excitation or a non-positive duration.
    """

    def __init__(self, cfg: VehicleConfig, dofs: Sequence[str] = DOFS, levels: int | None = None, *,
                 tick_s: float, fractions: Sequence[float] | None = None, max_level_duration_s: float | None = None,
                 heave_repeats: int = 3, dvl_lock_timeout_s: float = 3.0,
                 progress: Callable[[str], None] | None = None, calibrate: Sequence[str] = (),
                 ballast_weight_in_water_n: float = 0.0, line_pull_n: float = 0.0,
                 inclining_load_n_m: Sequence[float] = (0.0, 0.0), excitation: str | None = None,
                 excitation_duration_s: float | None = None,
                 excitation_amplitude_fraction: float = DEFAULT_AMPLITUDE_FRACTION) -> None:
        bad = [d for d in dofs if d not in DOFS]
        if bad:
            raise ValueError(f"unknown DOF(s) {bad}; choose from {', '.join(DOFS)}")
        if fractions and any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fractions):
            raise ValueError(f"level fractions must be in (0, 1], got {list(fractions)}")
        if not (math.isfinite(tick_s) and tick_s > 0.0):
            raise ValueError(f"tick_s must be > 0, got {tick_s}")
        bad = [c for c in calibrate if c not in CALIBRATION_STEPS]
        if bad:
            raise ValueError(f"unknown calibration step(s) {bad}; choose from {', '.join(CALIBRATION_STEPS)}")
        if "ballast" in calibrate and not (math.isfinite(ballast_weight_in_water_n) and ballast_weight_in_water_n > 0):
            raise ValueError("ballast_weight_in_water_n must be > 0 N for the ballast step, "
                             f"got {ballast_weight_in_water_n}")
        if "line_pull" in calibrate and not (math.isfinite(line_pull_n) and line_pull_n > 0):
            raise ValueError(f"line_pull_n must be > 0 N for the line_pull step, got {line_pull_n}")
        if "inclining" in calibrate and not (len(inclining_load_n_m) == 2 and all(
                math.isfinite(x) and x > 0 for x in inclining_load_n_m)):
            raise ValueError(f"inclining_load_n_m must be (weight in water > 0 N, arm > 0 m) for the inclining step, "
                             f"got {inclining_load_n_m}")
        self.inclining_load_n_m = tuple(float(x) for x in inclining_load_n_m)
        self.inclining: dict = {}
        self.calibrate = list(calibrate)
        self.ballast_weight_in_water_n = float(ballast_weight_in_water_n)
        self.line_pull_n = float(line_pull_n)
        # broadband excitation instead of the ladder (issue 18 item 5; :meth:`_excite`, :mod:`.excitation`)
        fl = cfg.flat
        self.excitation = str(fl.get("identification.excitation", "ladder") if excitation is None else excitation)
        if self.excitation not in EXCITATIONS:
            raise ValueError(f"excitation {self.excitation!r}: choose from {', '.join(EXCITATIONS)}")
        self.excitation_duration_s = float(fl.get("identification.excitation_duration_s", 60.0)
                                           if excitation_duration_s is None else excitation_duration_s)
        if not (math.isfinite(self.excitation_duration_s) and self.excitation_duration_s > 0):
            raise ValueError(f"excitation_duration_s must be > 0 s, got {self.excitation_duration_s}")
        if not (0.0 < excitation_amplitude_fraction <= 1.0):
            raise ValueError(f"excitation_amplitude_fraction must be in (0, 1], got {excitation_amplitude_fraction}")
        self.excitation_amplitude_fraction = float(excitation_amplitude_fraction)
        #: what a calibration step waits for the operator to do ("" when not waiting): attach_ballast,
        #: remove_ballast, apply_line_pull_surge / _sway (line along the body's +x / +y), release_line_surge / _sway
        self.awaiting = ""
        #: the operator's instruction while :attr:`awaiting` ("" otherwise), e.g. "calibration: attach the ballast
        #: (8.56 N in water), then call continue"
        self.prompt = ""
        self._continue = False
        self.calibration: dict = {}
        self.decays: dict[str, tuple[float, float]] = {}
        self.cfg = cfg
        f = cfg.flat
        self.dofs = list(dofs)
        self.tick_s = float(tick_s)
        self.levels_per_dof = levels
        self.fractions = [float(x) for x in fractions] if fractions else None
        self.heave_repeats = max(1, int(heave_repeats))
        self.max_level_s = float(f["identification.max_level_duration_s"] if max_level_duration_s is None
                                 else max_level_duration_s)
        self.dvl_lock_timeout_s = float(dvl_lock_timeout_s)
        self._progress = progress or (lambda msg: None)
        #: the allocation model: authority, thrust allocation matrix and thrust curve (the in-process plant
        #: also allocates with it)
        self.core = AllocationCore(cfg)
        self.curve = self.core.allocator.curves[0]
        self.matrix = np.asarray(self.core.matrix_frd, dtype=float)
        self.time_constant_s = float(cfg.thrusters.time_constant_s)
        self.box = PoolBox.from_config(cfg)
        self.authority = {d: dof_authority(self.core, d) for d in DOFS}
        self.ctrl = HoldController(cfg, [min(self.authority[d]) for d in DOFS])
        self.state = SensorState(cfg)
        hv = measurement_settings(cfg, "heave")
        self.depth_estimator = DepthEstimator(hv["std"], hv["accel_std"], hv["accel_jerk_psd"])
        self.online = {d: OnlineDofEstimator(cfg, d) for d in self.dofs}
        n = len(self.core.names)
        self.f_lag = np.zeros(n)
        self._f_cmd = np.zeros(n)
        self._rec: dict[str, list] = {k: [] for k in ("t", "w", "wc", "active", "level", "run")}
        self.windows: dict[str, tuple[float, float]] = {}
        self.levels: dict[str, list[float]] = {}
        self.t_s = math.nan
        self.message = ""
        self.last_dvl_valid_s = math.nan
        self.finished = False
        self.aborted = False
        self.abort_reason = ""
        self.depth_hold_m = math.nan
        self._active = -1
        self._level = math.nan
        self._run = -1
        self._n_runs = 0
        self._last_level = ("", 0)
        self._gen: Wrenches | None = None

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
        self.t_s = float(t_s)
        self.last_dvl_valid_s = self.t_s
        self._gen = self._campaign()
        return self._resume()

    def command(self, thrust_n: np.ndarray) -> None:
        """Record the current tick with the thruster forces (n,) N commanded for the wrench just returned."""
        f_cmd = np.asarray(thrust_n, dtype=float)
        self._rec["t"].append(self.t_s)
        self._rec["w"].append(self.matrix @ self.f_lag)
        self._rec["wc"].append(self.matrix @ f_cmd)
        self._rec["active"].append(self._active)
        self._rec["level"].append(self._level)
        self._rec["run"].append(self._run)
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
        self.t_s = float(inp.t_s)
        if self.time_constant_s > 0.0:
            k = math.exp(-float(inp.elapsed_s) / self.time_constant_s)
            self.f_lag = self._f_cmd + (self.f_lag - self._f_cmd) * k
        else:
            self.f_lag = self._f_cmd
        for dev, s in inp.samples:
            self.state.on_sample(dev, s)
            self.depth_estimator.on_sample(dev, s.stamp_s, self.state)
            for est in self.online.values():
                est.on_sample(dev, s.stamp_s, self.state)
            if dev == "dvl75" and s.locked:
                self.last_dvl_valid_s = max(self.last_dvl_valid_s, s.stamp_s)
        depth, rate = self.depth_estimator.predict_to(self.t_s)
        if math.isfinite(rate):
            self.ctrl.depth_rate_m_s = rate
            self.ctrl.depth_estimate_m = depth
        if self._active >= 0:
            dof = DOFS[self._active]
            if dof in self.online:
                self.online[dof].update(self.t_s, float((self.matrix @ self.f_lag)[self._active]), self.state)
        try:
            if inp.cancel:
                raise CampaignAbort("cancelled")
            if not inp.armed:
                raise CampaignAbort("ESC output disarmed")
            self._check_limits()
        except CampaignAbort as exc:
            self._abort(str(exc))
            return None
        return self._resume()

    def _resume(self) -> np.ndarray | None:
        try:
            return np.asarray(next(self._gen), dtype=float)
        except StopIteration:
            self._finish()
        except CampaignAbort as exc:
            self._abort(str(exc))
        return None

    def _abort(self, reason: str) -> None:
        self.aborted, self.abort_reason = True, reason
        self._say(f"ABORT: {reason}")
        if self._active >= 0 and DOFS[self._active] not in self.windows:
            self.windows[DOFS[self._active]] = (self._dof_start(), self.t_s)
        if self._gen is not None:
            self._gen.close()
        self._finish()

    def _finish(self) -> None:
        self.finished = True
        self.awaiting, self.prompt = "", ""  # nothing waits for the operator any more
        self._active = -1
        self._end_run()
        self.f_lag = np.zeros_like(self.f_lag)  # the caller commands neutral thrust

    def _say(self, msg: str) -> None:
        self.message = msg
        self._progress(msg)

    def record(self, *, truth_position_ned_m: np.ndarray | None = None, truth_euler_rad: np.ndarray | None = None,
               wall_time_s: float = math.nan, seed: int = 0,
               final_pulse_width_us: np.ndarray | None = None) -> CampaignRecord:
        """The :class:`CampaignRecord` so far (the truth arrays, when the plant has them, are NaN otherwise)."""
        r = self._rec
        n = len(r["t"])
        nan3 = np.full((n, 3), np.nan)
        return CampaignRecord(
            t_s=np.asarray(r["t"]), wrench_frd=np.asarray(r["w"]).reshape(-1, 6),
            wrench_cmd_frd=np.asarray(r["wc"]).reshape(-1, 6), active=np.asarray(r["active"], dtype=int),
            level=np.asarray(r["level"], dtype=float), run_id=np.asarray(r["run"], dtype=int),
            truth_position_ned_m=(nan3 if truth_position_ned_m is None
                                  else np.asarray(truth_position_ned_m).reshape(-1, 3)),
            truth_euler_rad=nan3.copy() if truth_euler_rad is None else np.asarray(truth_euler_rad).reshape(-1, 3),
            sensors=self.state.log, windows=dict(self.windows), online=self.online, levels=self.levels,
            authority=self.authority, aborted=self.aborted, abort_reason=self.abort_reason, wall_time_s=wall_time_s,
            tick_s=self.tick_s, time_constant_s=self.time_constant_s, seed=int(seed),
            final_pulse_width_us=np.zeros(0) if final_pulse_width_us is None else np.asarray(final_pulse_width_us),
            calibration={k: dict(v) for k, v in self.calibration.items()}, decays=dict(self.decays),
            inclining={k: dict(v) for k, v in self.inclining.items()})

    # ------------------------------------------------------------------ status
    def level_position(self) -> tuple[str, int, int, float]:
        """(DOF, level index, level count, level command) of the current tick ('' / 0 / 0 / 0.0 when none)."""
        if self._active < 0:
            return "", 0, 0, 0.0
        dof = DOFS[self._active]
        ladder = self.levels.get(dof, [])
        last = self._last_level
        if not math.isfinite(self._level) or not ladder:
            return dof, last[1] if last[0] == dof else 0, len(ladder), 0.0
        i = int(np.argmin([abs(abs(self._level) - lv) for lv in ladder]))
        self._last_level = (dof, i)
        return dof, i, len(ladder), float(self._level)

    def progress_fraction(self) -> float:
        """Fraction 0-1 of the campaign done: DOFs finished plus the middle of the current level."""
        n = max(1, len(self.dofs))
        dof, i, count, _ = self.level_position()
        inner = (i + 0.5) / count if (dof and count and dof not in self.windows) else 0.0
        return float(min(1.0, (len(self.windows) + inner) / n))

    def status(self) -> ExecutiveStatus:
        """:class:`ExecutiveStatus` of the current tick."""
        dof, i, count, cmd = self.level_position()
        if self.finished:
            phase = "aborted" if self.aborted else "done"
            message = self.abort_reason if self.aborted else "campaign complete"
        else:
            phase = "running" if self._run >= 0 else ("returning" if dof else "positioning")
            message = STILL_MESSAGE if self.state.collecting_gyro_bias else self.message
        progress = 1.0 if phase == "done" else self.progress_fraction()
        return ExecutiveStatus(phase, dof, i, count, cmd, progress, message)

    # ------------------------------------------------------------------ checks
    def _check_limits(self) -> None:
        f = self.cfg.flat
        st = self.state
        if math.isfinite(st.depth_m) and st.depth_m > f["limits.max_depth_m"]:
            raise CampaignAbort(f"depth {st.depth_m:.2f} m beyond limits.max_depth_m {f['limits.max_depth_m']:g}")
        if math.isfinite(st.altitude_m) and st.altitude_m < f["limits.min_altitude_m"]:
            raise CampaignAbort(f"altitude {st.altitude_m:.2f} m below limits.min_altitude_m "
                                f"{f['limits.min_altitude_m']:g}")
        roll, pitch = st.rpy_rad[0], st.rpy_rad[1]
        if math.isfinite(roll) and abs(roll) > f["limits.max_roll_rad"]:
            raise CampaignAbort(f"roll {roll:.2f} rad beyond limits.max_roll_rad {f['limits.max_roll_rad']:g}")
        if math.isfinite(pitch) and abs(pitch) > f["limits.max_pitch_rad"]:
            raise CampaignAbort(f"pitch {pitch:.2f} rad beyond limits.max_pitch_rad {f['limits.max_pitch_rad']:g}")
        p = st.position_ned_m
        tol = 0.5 * float(f["pool.margin_m"])
        b = self.box
        if not (b.x_min - tol <= p[0] <= b.x_max + tol and b.y_min - tol <= p[1] <= b.y_max + tol):
            raise CampaignAbort(f"dead-reckoned position ({p[0]:.2f}, {p[1]:.2f}) m left the pool box")
        if self._active in (0, 1) and self.t_s - self.last_dvl_valid_s > self.dvl_lock_timeout_s:
            raise CampaignAbort(f"DVL lock lost for {self.t_s - self.last_dvl_valid_s:.1f} s during "
                                f"{DOFS[self._active]} (dvl_lock_timeout_s {self.dvl_lock_timeout_s:g})")

    # ------------------------------------------------------------------ helpers
    def _hold(self, duration_s: float, free: Sequence[str] = ()) -> Wrenches:
        for _ in range(int(round(duration_s / self.tick_s))):
            yield self.ctrl.wrench(self.state, free, self.tick_s)

    def _axis_velocity(self, k: int) -> float:
        st = self.state
        if k < 2:
            v = st.velocity_frd_m_s[k]
            return float(v) if math.isfinite(v) else 0.0
        if k == 2:
            return float(self.ctrl.depth_rate_m_s)
        return float(np.nan_to_num(st.rates_frd_rad_s[k - 3]))

    def _attitude_age_s(self) -> float:
        """Time since the time of validity of the newest attitude sample, s (0 before the first one)."""
        log = self.state.log["attitude"]
        return max(0.0, float(self.t_s) - float(log[-1][0])) if log else 0.0

    def _wait_still(self, k: int, tol: float, max_s: float, free: Sequence[str] = ()) -> Wrenches:
        still = 0.0
        t0 = self.t_s
        while self.t_s - t0 < max_s:
            yield self.ctrl.wrench(self.state, free, self.tick_s)
            settled = abs(self._axis_velocity(k)) < tol
            if k in (3, 4):
                settled = settled and abs(float(np.nan_to_num(self.state.rpy_rad[k - 3]))) < 0.05
            if settled:
                still += self.tick_s
                if still >= 0.5:
                    return
            else:
                still = 0.0

    def _dive(self) -> Wrenches:
        self._say("dive to the altitude setpoint and settle")
        alt_sp = float(self.cfg.flat["identification.altitude_setpoint_m"])
        self.ctrl.heading_setpoint_rad = float(self.cfg.flat["pool.start_heading_rad"])
        yield np.zeros(6)  # first samples
        target = self.box.z_min
        t0 = self.t_s
        self.ctrl.depth_setpoint_m = max(self.state.depth_m, 0.0) if math.isfinite(self.state.depth_m) else 0.0
        while self.t_s - t0 < 25.0:
            st = self.state
            if math.isfinite(st.altitude_m) and math.isfinite(st.depth_m):
                target = float(np.clip(st.depth_m + st.altitude_m - alt_sp, self.box.z_min, self.box.z_max))
            step = 0.25 * self.tick_s
            self.ctrl.depth_setpoint_m += float(np.clip(target - self.ctrl.depth_setpoint_m, -step, step))
            yield self.ctrl.wrench(self.state, (), self.tick_s)
            if abs(target - self.ctrl.depth_setpoint_m) < 1e-6 and abs(self.state.depth_m - target) < 0.03 \
                    and abs(self.ctrl.depth_rate_m_s) < 0.03:
                break
        self.depth_hold_m = target
        self.ctrl.depth_setpoint_m = target
        yield from self._hold(1.0)
        self.state.start_gyro_bias()
        yield from self._hold(2.0)
        self.state.finish_gyro_bias()

    def _move_to_centre(self) -> Wrenches:
        c = self.box.centre
        self.ctrl.depth_setpoint_m = self.depth_hold_m
        t0 = self.t_s
        while self.t_s - t0 < 40.0:
            p = self.state.position_ned_m
            err_ned = np.array([c[0] - p[0], c[1] - p[1]])
            psi = float(np.nan_to_num(self.state.rpy_rad[2]))
            rot = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]])  # NED -> body
            self.ctrl.velocity_setpoint_m_s = np.clip(0.6 * (rot @ err_ned), -0.25, 0.25)
            yield self.ctrl.wrench(self.state, (), self.tick_s)
            speed = float(np.linalg.norm(np.nan_to_num(self.state.velocity_frd_m_s[:2])))
            if np.linalg.norm(err_ned) < 0.15 and speed < 0.05:
                break
        self.ctrl.velocity_setpoint_m_s = np.zeros(2)
        yield from self._hold(1.0)

    def _start_run(self, dof: str, level: float) -> None:
        self._active = DOF_INDEX[dof]
        self._level = level
        self._run = self._n_runs
        self._n_runs += 1

    def _end_run(self) -> None:
        self._level = math.nan
        self._run = -1

    def _run_level(self, dof: str, level: float) -> Wrenches:
        """Hold the other DOFs and add ``level`` on the DOF under test for one tick."""
        extra = np.zeros(6)
        extra[DOF_INDEX[dof]] = level
        yield self.ctrl.wrench(self.state, (dof,), self.tick_s) + extra

    # ------------------------------------------------------------------ manoeuvres
    def _translation(self, dof: str, ladder: list[float]) -> Wrenches:
        k = DOF_INDEX[dof]
        psi0 = self.ctrl.heading_setpoint_rad
        axis = {0: np.array([math.cos(psi0), math.sin(psi0), 0.0]),
                1: np.array([-math.sin(psi0), math.cos(psi0), 0.0]),
                2: np.array([0.0, 0.0, 1.0])}[k]
        m = prior_inertia(self.cfg, dof)
        a_brake = 0.5 * min(self.authority[dof]) / m
        repeats = self.heave_repeats if k == 2 else 1
        for i, lvl in enumerate(ladder):
            p = self.state.position_ned_m
            if k == 2:
                signs = (1.0, -1.0)  # heave: down, then up
            else:
                signs = (1.0, -1.0) if self.box.room_m(p, axis) >= self.box.room_m(p, -axis) else (-1.0, 1.0)
            for s in signs * repeats:
                self._say(f"{dof}: level {i + 1}/{len(ladder)} {s * lvl:+.2f} N")
                self._start_run(dof, s * lvl)
                t0 = self.t_s
                while self.t_s - t0 < self.max_level_s:
                    vs = max(0.0, s * self._axis_velocity(k))
                    stop = vs * vs / (2.0 * a_brake) + 0.3 * vs + 0.03
                    if self.box.room_m(self.state.position_ned_m, s * axis) <= stop:
                        break
                    yield from self._run_level(dof, s * lvl)
                self._end_run()
                if k == 2:
                    v = self._axis_velocity(2)
                    self.ctrl.depth_setpoint_m = float(np.clip(self.state.depth_m + v * abs(v) / (2 * a_brake),
                                                               self.box.z_min, self.box.z_max))
                    self.ctrl.reset_integral()
                yield from self._wait_still(k, 0.05, 6.0)
                yield from self._hold(0.5)
        if k == 2:
            self.ctrl.depth_setpoint_m = self.depth_hold_m

    def _rotation(self, dof: str, ladder: list[float]) -> Wrenches:
        k = DOF_INDEX[dof]
        inertia = prior_inertia(self.cfg, dof)
        alpha = 0.5 * min(self.authority[dof]) / inertia
        limit = 2.0 * math.pi if dof == "yaw" else float(self.cfg.flat[f"identification.{dof}_test_angle_rad"])
        for i, lvl in enumerate(ladder):
            for s in (1.0, -1.0):
                self._say(f"{dof}: level {i + 1}/{len(ladder)} {s * lvl:+.2f} N m")
                self._start_run(dof, s * lvl)
                t0 = self.t_s
                turned = 0.0
                prev = float(np.nan_to_num(self.state.rpy_rad[k - 3]))
                while self.t_s - t0 < self.max_level_s:
                    rate = max(0.0, s * self._axis_velocity(k))
                    stop = rate * rate / (2.0 * alpha) + 0.1 * rate
                    ang = float(np.nan_to_num(self.state.rpy_rad[k - 3]))
                    if dof == "yaw":
                        turned += abs(wrap_angle(ang - prev))
                        prev = ang
                        done = turned + stop >= limit
                    else:
                        # the attitude comes at 10 Hz: extrapolate it to now with the 100 Hz gyro rate (at 2 rad/s
                        # a 100 ms old angle is 0.2 rad short, which let the graph overshoot the pitch limit)
                        ang += self._axis_velocity(k) * self._attitude_age_s()
                        done = s * ang + stop >= limit
                    if done:
                        break
                    yield from self._run_level(dof, s * lvl)
                self._end_run()
                if dof == "yaw":
                    r = self._axis_velocity(5)
                    self.ctrl.heading_setpoint_rad = wrap_angle(float(np.nan_to_num(self.state.rpy_rad[2]))
                                                                + r * abs(r) / (2.0 * alpha))
                yield from self._wait_still(k, 0.05, 8.0)
                yield from self._hold(0.5)

    def operator_continue(self) -> bool:
        """The operator's ``continue``: resumes a calibration step waiting in :attr:`awaiting`; False (nothing
        done) when no step waits."""
        if not self.awaiting:
            return False
        self._continue = True
        return True

    def _wait_operator(self, what: str, prompt: str, max_s: float = 900.0) -> Wrenches:
        """Hold (all DOFs) until :meth:`operator_continue`; aborts after ``max_s``."""
        self.awaiting, self._continue = what, False
        self.prompt = f"{prompt}, then call continue"
        self._say(self.prompt)
        t0 = self.t_s
        while not self._continue:
            if self.t_s - t0 > max_s:
                raise CampaignAbort(f"no continue within {max_s:g} s ({what})")
            yield self.ctrl.wrench(self.state, (), self.tick_s)
        self.awaiting, self._continue, self.prompt = "", False, ""
        self._say(f"operator continued ({what}): holding")

    def _mean_holding_force(self, k: int, t_from: float) -> tuple[float, float]:
        """Mean of the recorded (lagged) thrust-model force on axis k since ``t_from`` and the std of that mean by
        batch means (blocks of :data:`CALIBRATION_BLOCK_S`: the holding force is correlated over the depth hold's
        time scale, so the per-tick std would be wrong either way)."""
        t = np.asarray(self._rec["t"])
        x = np.asarray(self._rec["w"]).reshape(-1, 6)[t >= t_from, k]
        per = max(1, int(round(CALIBRATION_BLOCK_S / self.tick_s)))
        nb = x.size // per
        if nb < 3:
            raise CampaignAbort("calibration: averaging window shorter than three blocks")
        blocks = x[: nb * per].reshape(nb, per).mean(axis=1)
        return float(np.mean(x)), float(np.std(blocks, ddof=1) / math.sqrt(nb))

    def _ballast(self) -> Wrenches:
        """Vertical thrust scale from a known ballast (issue 17 item 1): hold depth, average the holding force Z1;
        the operator attaches the ballast (weight in water w); hold again, Z2. The thrust-model force changes by
        Z1 - Z2 = w / s for a true thrust s times the curve's, so s = w / (Z1 - Z2) (FRD: z down), std from the
        two means' std. Then the ballast is removed before the ladders."""
        w = self.ballast_weight_in_water_n
        yield from self._move_to_centre()
        self.ctrl.depth_setpoint_m = self.depth_hold_m
        self._say("calibration (ballast): hold depth without the ballast")
        yield from self._hold(CALIBRATION_SETTLE_S)
        t1 = self.t_s
        yield from self._hold(CALIBRATION_WINDOW_S)
        z1, s1 = self._mean_holding_force(2, t1)
        yield from self._wait_operator("attach_ballast", f"calibration: attach the ballast ({w:.3g} N in water)")
        yield from self._hold(CALIBRATION_SETTLE_S)
        t2 = self.t_s
        yield from self._hold(CALIBRATION_WINDOW_S)
        z2, s2 = self._mean_holding_force(2, t2)
        yield from self._wait_operator("remove_ballast", "calibration: remove the ballast")
        yield from self._hold(CALIBRATION_SETTLE_S)
        dz = z1 - z2
        if not dz > 0.0:
            raise CampaignAbort(f"calibration (ballast): the holding force did not rise ({z1:.3g} -> {z2:.3g} N)")
        scale = w / dz
        self.calibration["vertical"] = {
            "value": scale, "std": scale * math.hypot(s1, s2) / dz, "known_force_n": w,
            "holding_force_n": [z1, z2], "holding_force_std_n": [s1, s2], "method": "ballast"}
        self._say(f"calibration (ballast): vertical thrust scale {scale:.4f}")

    def _station(self, duration_s: float, centre) -> Wrenches:
        """Hold station at ``centre`` (NED x, y) for ``duration_s``: dead-reckoned position -> velocity setpoint (as
        :meth:`_move_to_centre`), depth and heading held. Under a constant external force the vehicle settles at a
        constant offset, with zero velocity, so the thrust then balances the force alone (no damping term)."""
        for _ in range(int(round(duration_s / self.tick_s))):
            p = self.state.position_ned_m
            err_ned = np.array([centre[0] - p[0], centre[1] - p[1]])
            psi = float(np.nan_to_num(self.state.rpy_rad[2]))
            rot = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]])  # NED -> body
            self.ctrl.velocity_setpoint_m_s = np.clip(0.6 * (rot @ np.nan_to_num(err_ned)), -0.25, 0.25)
            yield self.ctrl.wrench(self.state, (), self.tick_s)
        self.ctrl.velocity_setpoint_m_s = np.zeros(2)

    def _line_pull(self, axis: str) -> Wrenches:
        """Horizontal thrust scale from a known line pull along the body's +x (surge) or +y (sway) axis (issue 17
        item 1): hold station, average the holding force X1; the operator applies the line; hold station again, X2;
        s = F / (X1 - X2), std from the two means' std (as :meth:`_ballast`)."""
        k = 0 if axis == "surge" else 1
        f = self.line_pull_n
        yield from self._move_to_centre()
        c = (float(self.state.position_ned_m[0]), float(self.state.position_ned_m[1]))
        self._say(f"calibration (line pull, {axis}): hold station without the line")
        yield from self._station(CALIBRATION_SETTLE_S, c)
        t1 = self.t_s
        yield from self._station(CALIBRATION_WINDOW_S, c)
        x1, s1 = self._mean_holding_force(k, t1)
        yield from self._wait_operator(f"apply_line_pull_{axis}",
                                       f"calibration: pull the line along +{'xy'[k]} ({f:.3g} N over the pulley)")
        yield from self._station(CALIBRATION_SETTLE_S, c)
        t2 = self.t_s
        yield from self._station(CALIBRATION_WINDOW_S, c)
        x2, s2 = self._mean_holding_force(k, t2)
        yield from self._wait_operator(f"release_line_{axis}", "calibration: release the line")
        yield from self._station(CALIBRATION_SETTLE_S, c)
        dx = x1 - x2
        if not dx > 0.0:
            raise CampaignAbort(f"calibration (line pull, {axis}): the holding force did not change against the "
                                f"line ({x1:.3g} -> {x2:.3g} N)")
        scale = f / dx
        self.calibration[axis] = {
            "value": scale, "std": scale * math.hypot(s1, s2) / dx, "known_force_n": f,
            "holding_force_n": [x1, x2], "holding_force_std_n": [s1, s2], "method": "line_pull"}
        self._say(f"calibration (line pull, {axis}): thrust scale {scale:.4f}")

    def _tilt_decay(self, dof: str) -> Wrenches:
        """Roll or pitch free decay, self-propelled (issue 17 item 3): the vertical thrusters ramp a moment of
        C0 :data:`TILT_DECAY_ANGLE_RAD` (C0 = m g BG of the vehicle file, so the angle reached is only roughly the
        target: the thrust curve need not be right), hold it, then release (zero moment on that DOF, the others
        held) and record :data:`TILT_DECAY_RECORD_S` s; the window goes to :attr:`decays`. Rigid + added inertia
        follow offline from the gyro rate and the inclining stiffness (:func:`~.calibration.decay_inertia`)."""
        k = DOF_INDEX[dof]
        f = self.cfg.flat
        bg = float(f["vehicle.centre_of_gravity_frd_m"][2]) - float(f["vehicle.centre_of_buoyancy_frd_m"][2])
        c0 = float(self.cfg.weight_n) * bg
        moment = min(c0 * TILT_DECAY_ANGLE_RAD, 0.8 * min(self.authority[dof]))
        yield from self._move_to_centre()
        self._say(f"free decay ({dof}): tilt with the vertical thrusters, then release")
        n_ramp = int(round(TILT_DECAY_RAMP_S / self.tick_s))
        for i in range(n_ramp + int(round(TILT_DECAY_HOLD_S / self.tick_s))):
            w = np.asarray(self.ctrl.wrench(self.state, (dof,), self.tick_s), dtype=float)
            w[k] = moment * min(1.0, i / max(n_ramp, 1))
            yield w
        t0 = self.t_s
        for _ in range(int(round(TILT_DECAY_RECORD_S / self.tick_s))):
            w = np.asarray(self.ctrl.wrench(self.state, (dof,), self.tick_s), dtype=float)
            w[k] = 0.0
            yield w
        self.decays[dof] = (t0, self.t_s)
        yield from self._wait_still(k, 0.05, 8.0)

    def _hold_tilt_free(self, dof: str, duration_s: float) -> Wrenches:
        """Hold depth, position and the other attitude for ``duration_s`` with no moment on ``dof`` (roll | pitch):
        the vehicle settles at the angle where its restoring moment balances the external one."""
        k = DOF_INDEX[dof]
        for _ in range(int(round(duration_s / self.tick_s))):
            w = np.asarray(self.ctrl.wrench(self.state, (dof,), self.tick_s), dtype=float)
            w[k] = 0.0
            yield w

    def _mean_tilt(self, i: int, t_from: float) -> tuple[float, float]:
        """Mean of the attitude log's angle i (0 roll, 1 pitch; the DVL-75's own IMU) since ``t_from`` and the std of
        that mean by batch means over :data:`CALIBRATION_BLOCK_S` blocks (as :meth:`_mean_holding_force`)."""
        rows = [(t, a[i]) for t, a in self.state.log["attitude"] if t >= t_from and math.isfinite(a[i])]
        t = np.array([r[0] for r in rows])
        x = np.array([r[1] for r in rows])
        if t.size < 3 or t[-1] - t[0] < 3.0 * CALIBRATION_BLOCK_S:
            raise CampaignAbort("inclining: averaging window shorter than three blocks")
        blocks = [x[(t >= b) & (t < b + CALIBRATION_BLOCK_S)] for b in
                  np.arange(t[0], t[-1] - CALIBRATION_BLOCK_S + 1e-9, CALIBRATION_BLOCK_S)]
        means = np.array([b.mean() for b in blocks if b.size])
        return float(np.mean(x)), float(np.std(means, ddof=1) / math.sqrt(means.size))

    def _inclining(self, dof: str) -> Wrenches:
        """Restoring stiffness C of roll or pitch by an inclining test (issue 17 item 3): with that DOF free (no
        moment from the thrusters; depth, position and the other angles held) average the angle a1; the operator
        hangs the test mass (weight in water w) at arm d to starboard (roll: body +y) or forward (pitch: body +x),
        a moment K = w d (roll) or -w d (pitch); average a2; the mass is removed. Equilibrium w d cos(a) = C sin(a)
        + M0 gives C = K / (tan a2 - tan a1) (:func:`~hindrax_ident.estimation.free_decay.restoring_from_inclining`,
        two points), std from the two means' std. The thrusters only hold the other DOFs, but the moment they realise
        on the free DOF is not exactly the zero commanded (pulse widths near neutral); its change between the two
        holds, M2 - M1 (thrust model, recorded), is added: C = (K + M2 - M1) / (tan a2 - tan a1). It is a few % of
        K, so a thrust-curve error s - 1 moves C by only (s - 1) (M2 - M1) / K."""
        i = DOF_INDEX[dof] - 3
        w, d = self.inclining_load_n_m
        moment = w * d if dof == "roll" else -w * d
        where = "to starboard (body +y)" if dof == "roll" else "forward (body +x)"
        yield from self._move_to_centre()
        self._say(f"inclining ({dof}): {dof} free, without the test mass")
        yield from self._hold_tilt_free(dof, CALIBRATION_SETTLE_S)
        t1 = self.t_s
        yield from self._hold_tilt_free(dof, CALIBRATION_WINDOW_S)
        a1, s1 = self._mean_tilt(i, t1)
        m1, ms1 = self._mean_holding_force(i + 3, t1)
        yield from self._wait_operator(f"attach_inclining_mass_{dof}",
                                       f"inclining: hang the test mass ({w:.3g} N in water) {d:.3g} m {where}")
        yield from self._hold_tilt_free(dof, CALIBRATION_SETTLE_S)
        t2 = self.t_s
        yield from self._hold_tilt_free(dof, CALIBRATION_WINDOW_S)
        a2, s2 = self._mean_tilt(i, t2)
        m2, ms2 = self._mean_holding_force(i + 3, t2)
        yield from self._wait_operator(f"remove_inclining_mass_{dof}", "inclining: remove the test mass")
        yield from self._hold(CALIBRATION_SETTLE_S)
        dt = math.tan(a2) - math.tan(a1)
        total = moment + m2 - m1
        if dt == 0.0 or total / dt <= 0.0:
            raise CampaignAbort(f"inclining ({dof}): the tilt did not follow the test mass ({a1:.4f} -> {a2:.4f} rad)")
        c = total / dt
        ds = math.hypot(s1 / math.cos(a1) ** 2, s2 / math.cos(a2) ** 2)
        self.inclining[dof] = {"value": c, "std": abs(c) * math.hypot(ds / dt, math.hypot(ms1, ms2) / total),
                               "known_moment_n_m": moment, "thruster_moment_n_m": [m1, m2],
                               "tilt_rad": [a1, a2], "tilt_std_rad": [s1, s2], "method": "inclining"}
        self._say(f"inclining ({dof}): restoring stiffness {c:.3f} N m/rad")

    def _campaign(self) -> Wrenches:
        yield from self._dive()
        if "inclining" in self.calibrate:
            for dof in ("roll", "pitch"):
                yield from self._inclining(dof)
        if "tilt_decay" in self.calibrate:
            for dof in ("roll", "pitch"):
                yield from self._tilt_decay(dof)
        if "ballast" in self.calibrate:
            yield from self._ballast()
        if "line_pull" in self.calibrate:
            for axis in ("surge", "sway"):
                yield from self._line_pull(axis)
        for dof in self.dofs:
            yield from self._move_to_centre()
            ladder = self.ladder(dof)
            self.levels[dof] = ladder
            t0 = self.t_s
            self._active = DOF_INDEX[dof]
            if self.excitation in BROADBAND:
                yield from self._excite(dof)
            elif dof in ("surge", "sway", "heave"):
                yield from self._translation(dof, ladder)
            else:
                yield from self._rotation(dof, ladder)
            self._active = -1
            self.windows[dof] = (t0, self.t_s)
            self._say(f"{dof}: done ({self.t_s - t0:.0f} s of pool time)")

    def excitation_design(self, dof: str):
        """(signal, band, shaping) of the broadband run of one DOF (:mod:`.excitation`): amplitude
        ``excitation_amplitude_fraction`` of the DOF's smaller authority, band from the vehicle file's inertia and
        damping (:func:`~.excitation.design_band`, capped by the thruster lag), room L from the box centre to the
        box along the axis (surge/sway: along the start heading, less 0.2 m; heave: half the box depth range less
        0.05 m; roll/pitch: half the test angle; yaw: pi/2 from the start heading), PD bandwidth half the lowest
        line."""
        k = DOF_INDEX[dof]
        lim = min(self.authority[dof])
        amp = self.excitation_amplitude_fraction * lim
        tp = truth_parameters(self.cfg, dof)  # the vehicle file's values (the belief, not the pool's truth)
        kq = tp.get("quadratic_damping", 0.5 * (tp.get("quadratic_damping_positive", 0.0)
                                               + tp.get("quadratic_damping_negative", 0.0)))
        kl = tp.get("linear_damping", 0.5 * (tp.get("linear_damping_positive", 0.0)
                                            + tp.get("linear_damping_negative", 0.0)))
        m = prior_inertia(self.cfg, dof)
        band = design_band(m, kl, kq, amp, self.time_constant_s)
        sig = design_signal(self.excitation, amp, band, self.excitation_duration_s)
        if k < 2:
            psi0 = self.ctrl.heading_setpoint_rad
            axis = np.array([math.cos(psi0), math.sin(psi0), 0.0]) if k == 0 else \
                np.array([-math.sin(psi0), math.cos(psi0), 0.0])
            half = max(0.1, self.box.room_m(self.box.centre, axis) - 0.2)
        elif k == 2:
            half = max(0.05, 0.5 * (self.box.z_max - self.box.z_min) - 0.05)
        elif k == 5:
            half = 0.5 * math.pi
        else:
            # half the test angle: near the roll/pitch natural frequency (inside the band) the restoring moment
            # resonates and the 10 Hz attitude lags, so the braking guard needs the room (full angle overshot the
            # pitch limit in a first in-process trial)
            half = 0.5 * float(self.cfg.flat[f"identification.{dof}_test_angle_rad"])
        shaping = BoxShaping(half, m, lim, math.pi * band.f_min_hz, self.tick_s)
        return sig, band, shaping

    def _excite(self, dof: str) -> Wrenches:
        """One broadband run of ``excitation_duration_s`` on ``dof`` (issue 18 item 5) instead of the ladder: the
        other DOFs held, the DOF under test gets the signal through the :class:`~.excitation.BoxShaping` of its
        displacement from the box centre (surge/sway: dead-reckoned position along the start-heading axis; heave:
        depth estimate, plus the net-buoyancy feed-forward; roll/pitch: angle; yaw: heading from the start
        heading); then the DOF is held still again. The record holds one run (``level`` = the total force
        commanded on the axis each tick); the DOF is identified by the output-error fit
        (:func:`~.estimators.identify_dof`) like a ladder."""
        k = DOF_INDEX[dof]
        sig, band, shaping = self.excitation_design(dof)
        self.levels[dof] = [float(sig.amplitude)]
        psi0 = self.ctrl.heading_setpoint_rad
        c = self.box.centre
        axis = {0: np.array([math.cos(psi0), math.sin(psi0)]), 1: np.array([-math.sin(psi0), math.cos(psi0)])}
        self._say(f"{dof}: {self.excitation} excitation {self.excitation_duration_s:.0f} s, peak "
                  f"{sig.amplitude:.2f}, band {band.f_min_hz:.3f}-{band.f_max_hz:.2f} Hz")
        self._start_run(dof, 0.0)
        t0 = self.t_s
        while self.t_s - t0 < self.excitation_duration_s - 1e-9:
            if k < 2:
                e = float(np.nan_to_num(self.state.position_ned_m[:2] - c[:2]) @ axis[k])
            elif k == 2:
                d = self.ctrl.depth_estimate_m if math.isfinite(self.ctrl.depth_estimate_m) else self.state.depth_m
                e = float(np.nan_to_num(d - c[2]))
            elif k == 5:
                e = wrap_angle(float(np.nan_to_num(self.state.rpy_rad[2])) - psi0)
            else:
                # the 10 Hz attitude extrapolated to now with the gyro rate (as in :meth:`_rotation`)
                e = float(np.nan_to_num(self.state.rpy_rad[k - 3])) + self._axis_velocity(k) * self._attitude_age_s()
            f = shaping.force(float(sig.value(self.t_s - t0)), e, self._axis_velocity(k))
            if k == 2:
                f += self.ctrl.net_buoyancy_n
            self._level = f
            w = np.asarray(self.ctrl.wrench(self.state, (dof,), self.tick_s), dtype=float)
            w[k] = f
            yield w
        self._end_run()
        if k == 2:
            self.ctrl.depth_setpoint_m = float(np.clip(self.state.depth_m, self.box.z_min, self.box.z_max))
            self.ctrl.reset_integral()
        elif k == 5:
            self.ctrl.heading_setpoint_rad = float(np.nan_to_num(self.state.rpy_rad[2]))
        yield from self._wait_still(k, 0.05, 8.0)
        yield from self._hold(0.5)
        if k == 2:
            self.ctrl.depth_setpoint_m = self.depth_hold_m
        elif k == 5:
            self.ctrl.heading_setpoint_rad = psi0

    def ladder(self, dof: str) -> list[float]:
        """Levels of one DOF (N or N m): the explicit fractions times the DOF's smaller authority, else
        :func:`.maneuvers.level_ladder` of it."""
        if self.fractions:
            return [x * min(self.authority[dof]) for x in self.fractions]
        return level_ladder(self.cfg, min(self.authority[dof]), self.levels_per_dof)

    def _dof_start(self) -> float:
        act = np.asarray(self._rec["active"])
        idx = np.flatnonzero(act == self._active)
        return float(self._rec["t"][idx[0]]) if idx.size else self.t_s
