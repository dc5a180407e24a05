"""What a campaign step sees and does: :class:`StepContext` (pure, no rclpy, no plant).

A step (:class:`~.base.Step`) is a generator over control ticks: each ``yield`` hands out the FRD wrench (6,) of one
tick, and the step resumes once the sequencer (:class:`~hindrax_onboard.identification.online.executive.Executive`) has
conditioned that tick's sensor samples. Between yields the step reads the campaign's state through the context:

* the conditioned sensors (:attr:`state`, :class:`~hindrax_onboard.vehicle.state.SensorState`), the holds (:attr:`ctrl`,
  :class:`~....control.maneuvers.HoldController`, used through its public interface only: setpoints and ``wrench``), the
  pool box (:attr:`box`), each DOF's authority and the allocation model (:attr:`core`, :attr:`matrix`);
* the tick log: the thrust-model wrench of every tick and its parts from the thrusters turning forward (positive
  thrust) and in reverse (:meth:`mean_recorded_force`, :meth:`mean_force_by_direction`);
* the run bookkeeping the record keeps per tick: the DOF under test (:attr:`active`), the commanded test level and
  the run counter (:meth:`start_run`, :meth:`end_run`), and the results of the steps (:attr:`calibration`,
  :attr:`inclining`, :attr:`decays`, :attr:`windows`, :attr:`levels`);
* the operator hand-shake (:meth:`wait_operator`, :attr:`awaiting`, :attr:`prompt`, :meth:`operator_continue`)
  and what it left on the vehicle (:attr:`undo`: a load asked for and not yet removed, for an abort's prompt);
* the motion primitives every step shares (:meth:`hold`, :meth:`station`, :meth:`move_to_centre`,
  :meth:`wait_still`), which are generators too (``yield from ctx.hold(2.0)``).

Frames: body FRD, world NED (docs/architecture.md §3); forces N, moments N m, times s (the plant's clock)."""
from __future__ import annotations

import math
from typing import Callable, Generator, Sequence

import numpy as np

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig

from ....vehicle.state import SensorState, finite_or_zero, finite_or_zeros
from ....control.maneuvers import DOF_INDEX, HoldController, PoolBox, dof_authority

__all__ = ["CampaignAbort", "StepContext", "Wrenches", "CALIBRATION_BLOCK_S"]

Wrenches = Generator[np.ndarray, None, None]

#: Block length of the batch means giving the std of a mean holding force or angle (s; several depth-hold time
#: constants: the holding force is correlated over the hold's time scale, so the per-tick std would be wrong).
CALIBRATION_BLOCK_S = 3.0


class CampaignAbort(RuntimeError):
    """A limit was crossed, the ESC disarmed, the DVL lost or a cancel came (the message says which)."""


class StepContext:
    """The campaign state shared by the sequencer and its steps (module docstring).

    cfg: vehicle configuration; tick_s: control period (s); progress: callable receiving one-line messages."""

    def __init__(self, cfg: VehicleConfig, tick_s: float, progress: Callable[[str], None] | None = None) -> None:
        self.cfg = cfg
        self.tick_s = float(tick_s)
        self._progress = progress or (lambda msg: None)
        #: the allocation model: authority, thrust allocation matrix (6, m) FRD and thrust curve
        self.core = AllocationCore(cfg)
        self.curve = self.core.allocator.curves[0]
        self.matrix = np.asarray(self.core.matrix_frd, dtype=float)
        self.time_constant_s = float(cfg.thrusters.time_constant_s)
        self.box = PoolBox.from_config(cfg)
        self.authority = {d: dof_authority(self.core, d) for d in DOFS}
        self.ctrl = HoldController(cfg, [min(self.authority[d]) for d in DOFS])
        self.state = SensorState(cfg)
        self.t_s = math.nan
        self.message = ""
        self.depth_hold_m = math.nan
        # tick log (one row per control tick, :meth:`log_tick`, in this key order)
        self.rec: dict[str, list] = {k: [] for k in ("t", "w", "wc", "wp", "wn", "fc", "active", "level", "run")}
        # run bookkeeping
        self.active = -1
        self.level = math.nan
        self.run = -1
        self.n_runs = 0
        # results
        self.windows: dict[str, tuple[float, float]] = {}
        self.levels: dict[str, list[float]] = {}
        self.calibration: dict = {}
        self.inclining: dict = {}
        self.decays: dict[str, tuple[float, float]] = {}
        #: what a step waits for the operator to do ("" when not waiting): attach_ballast, remove_ballast, attach_float,
        #: remove_float, apply_line_pull_<surge|sway>[_negative], release_line_<surge|sway>[_negative],
        #: attach_inclining_mass_<dof>, remove_inclining_mass_<dof>
        self.awaiting = ""
        #: the operator's instruction while :attr:`awaiting` ("" otherwise), e.g. 'calibration:
        #: attach the ballast (8.56 N in water), then call continue'
        self.prompt = ""
        self._continue = False
        #: loads asked for and not yet removed: {remove code: instruction}, e.g. {"remove_ballast": "calibration:
        #: remove the ballast"} (:meth:`wait_operator`'s ``undo``); what an abort leaves to undo
        self.undo: dict[str, str] = {}

    # ------------------------------------------------------------------ messages and bookkeeping
    def say(self, msg: str) -> None:
        """Make ``msg`` the current step message and pass it to the progress callable."""
        self.message = msg
        self._progress(msg)

    def log_tick(self, wrench_lag: np.ndarray, wrench_cmd: np.ndarray, wrench_positive: np.ndarray,
                 wrench_negative: np.ndarray, thrust_cmd_n: np.ndarray) -> None:
        """Append one tick: the lagged thrust-model wrench (6,), the commanded one (6,), the lagged wrench's parts
        from positive (forward) and negative (reverse) thrust (6,) each, the commanded thruster forces (m,) N."""
        row = (self.t_s, wrench_lag, wrench_cmd, wrench_positive, wrench_negative, thrust_cmd_n,
               self.active, self.level, self.run)
        for column, value in zip(self.rec.values(), row):
            column.append(value)

    def start_run(self, dof: str, level: float) -> None:
        """A run of ``dof`` at ``level`` (N or N m) begins: the following ticks carry it and a new run id."""
        self.active = DOF_INDEX[dof]
        self.level = level
        self.run = self.n_runs
        self.n_runs += 1

    def end_run(self) -> None:
        """The current run ends (level NaN, run id -1 from the next tick)."""
        self.level = math.nan
        self.run = -1

    # ------------------------------------------------------------------ measurements on the tick log
    def _window(self, key: str, t_from: float) -> np.ndarray:
        t = np.asarray(self.rec["t"])
        return np.asarray(self.rec[key]).reshape(-1, 6)[t >= t_from]

    def _batch_mean(self, x: np.ndarray, what: str) -> tuple[float, float]:
        per = max(1, int(round(CALIBRATION_BLOCK_S / self.tick_s)))
        nb = x.size // per
        if nb < 3:
            raise CampaignAbort(f"{what}: averaging window shorter than three blocks")
        blocks = x[: nb * per].reshape(nb, per).mean(axis=1)
        return float(np.mean(x)), float(np.std(blocks, ddof=1) / math.sqrt(nb))

    def mean_recorded_force(self, k: int, t_from: float) -> tuple[float, float]:
        """Mean of the recorded (lagged) thrust-model force on axis k (0-5, FRD) since ``t_from`` and the std of
        that mean by batch means over :data:`CALIBRATION_BLOCK_S` blocks. Raises :class:`CampaignAbort` for a
        window shorter than three blocks."""
        return self._batch_mean(self._window("w", t_from)[:, k], "calibration")

    def mean_force_by_direction(self, k: int, t_from: float) -> tuple[float, float]:
        """Means since ``t_from`` of the parts of the recorded force on axis k made by thrusters turning forward
        (positive thrust) and in reverse (negative thrust), N; their sum is :meth:`mean_recorded_force`'s mean."""
        return (float(np.mean(self._window("wp", t_from)[:, k])), float(np.mean(self._window("wn", t_from)[:, k])))

    def mean_tilt(self, i: int, t_from: float) -> tuple[float, float]:
        """Mean of the attitude log's angle i (0 roll, 1 pitch; the DVL-75's own IMU) since ``t_from`` and the std
        of that mean by batch means over :data:`CALIBRATION_BLOCK_S` blocks."""
        rows = [(t, a[i]) for t, a in self.state.log["attitude"] if t >= t_from and math.isfinite(a[i])]
        t = np.array([r[0] for r in rows])
        x = np.array([r[1] for r in rows])
        if t.size < 3 or t[-1] - t[0] < 3.0 * CALIBRATION_BLOCK_S:
            raise CampaignAbort("inclining: averaging window shorter than three blocks")
        blocks = [x[(t >= b) & (t < b + CALIBRATION_BLOCK_S)] for b in
                  np.arange(t[0], t[-1] - CALIBRATION_BLOCK_S + 1e-9, CALIBRATION_BLOCK_S)]
        means = np.array([b.mean() for b in blocks if b.size])
        return float(np.mean(x)), float(np.std(means, ddof=1) / math.sqrt(means.size))

    # ------------------------------------------------------------------ sensor helpers
    def axis_velocity(self, k: int) -> float:
        """Velocity on axis k (0-5): DVL body velocity (surge, sway), depth rate (heave), gyro rate; 0 when unknown."""
        st = self.state
        if k < 2:
            return finite_or_zero(st.velocity_frd_m_s[k])
        if k == 2:
            return float(self.ctrl.depth_rate_m_s)
        return finite_or_zero(st.rates_frd_rad_s[k - 3])

    def attitude_age_s(self) -> float:
        """Time since the time of validity of the newest attitude sample, s (0 before the first one)."""
        log = self.state.log["attitude"]
        return max(0.0, float(self.t_s) - float(log[-1][0])) if log else 0.0

    # ------------------------------------------------------------------ motion primitives
    def hold(self, duration_s: float, free: Sequence[str] = ()) -> Wrenches:
        """Hold every DOF not in ``free`` for ``duration_s``."""
        for _ in range(int(round(duration_s / self.tick_s))):
            yield self.ctrl.wrench(self.state, free, self.tick_s)

    def wait_still(self, k: int, tol: float, max_s: float, free: Sequence[str] = ()) -> Wrenches:
        """Hold until axis k's velocity stays below ``tol`` for 0.5 s (roll/pitch: also the angle below 0.05 rad), at
        most ``max_s``."""
        still = 0.0
        t0 = self.t_s
        while self.t_s - t0 < max_s:
            yield self.ctrl.wrench(self.state, free, self.tick_s)
            settled = abs(self.axis_velocity(k)) < tol
            if k in (3, 4):
                settled = settled and abs(finite_or_zero(self.state.rpy_rad[k - 3])) < 0.05
            if settled:
                still += self.tick_s
                if still >= 0.5:
                    return
            else:
                still = 0.0

    def _velocity_to(self, centre) -> None:
        p = self.state.position_ned_m
        err_ned = np.array([centre[0] - p[0], centre[1] - p[1]])
        psi = finite_or_zero(self.state.rpy_rad[2])
        rot = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]])  # NED -> body
        self.ctrl.velocity_setpoint_m_s = np.clip(0.6 * (rot @ finite_or_zeros(err_ned)),
                                                  -0.25, 0.25)
        return err_ned

    def move_to_centre(self) -> Wrenches:
        """Go to the pool-box centre at the dive's depth (velocity setpoint from the dead-reckoned position, at most
        40 s), then hold 1 s."""
        c = self.box.centre
        self.ctrl.depth_setpoint_m = self.depth_hold_m
        t0 = self.t_s
        while self.t_s - t0 < 40.0:
            err_ned = self._velocity_to(c)
            yield self.ctrl.wrench(self.state, (), self.tick_s)
            speed = float(np.linalg.norm(finite_or_zeros(self.state.velocity_frd_m_s[:2])))
            if np.linalg.norm(err_ned) < 0.15 and speed < 0.05:
                break
        self.ctrl.velocity_setpoint_m_s = np.zeros(2)
        yield from self.hold(1.0)

    def station(self, duration_s: float, centre) -> Wrenches:
        """Hold station at ``centre`` (NED x, y) for ``duration_s``: dead-reckoned position -> velocity setpoint (as
        :meth:`move_to_centre`), depth and heading held. Under a constant external force the vehicle settles at a
        constant offset, with zero velocity, so the thrust then balances the force alone (no damping term)."""
        for _ in range(int(round(duration_s / self.tick_s))):
            self._velocity_to(centre)
            yield self.ctrl.wrench(self.state, (), self.tick_s)
        self.ctrl.velocity_setpoint_m_s = np.zeros(2)

    def hold_free(self, dof: str, duration_s: float) -> Wrenches:
        """Hold depth, position and the other attitude for ``duration_s`` with no moment on ``dof`` (roll | pitch):
        the vehicle settles at the angle where its restoring moment balances the external one."""
        k = DOF_INDEX[dof]
        for _ in range(int(round(duration_s / self.tick_s))):
            w = np.asarray(self.ctrl.wrench(self.state, (dof,), self.tick_s), dtype=float)
            w[k] = 0.0
            yield w

    # ------------------------------------------------------------------ operator
    def operator_continue(self) -> bool:
        """The operator's ``continue``: resumes a step waiting in :attr:`awaiting`; False (nothing done) when no
        step waits. :attr:`awaiting` and :attr:`prompt` clear at once, not at the step's next tick: a second
        ``continue`` before that tick (a double press, 9 ms apart in the graph test) finds nothing awaited and is
        refused, instead of being taken for the next prompt's."""
        if not self.awaiting:
            return False
        self._continue = True
        self.awaiting, self.prompt = "", ""
        return True

    def wait_operator(self, what: str, prompt: str, max_s: float = 900.0, undo: tuple[str, str] | None = None,
                      hold: bool = True) -> Wrenches:
        """Hold (all DOFs; ``hold`` False: zero wrench, the thrusters stopped) until :meth:`operator_continue`;
        :attr:`awaiting` is ``what`` and :attr:`prompt` reads ``"<prompt>, then call continue"`` meanwhile. ``undo``:
        (remove code, instruction) of the load this prompt asks for, in :attr:`undo` from the prompt on (the operator
        may have acted before the continue); a continue of ``what`` takes it out of :attr:`undo`. Raises
        :class:`CampaignAbort` after ``max_s``."""
        if undo is not None:
            self.undo[undo[0]] = undo[1]
        self.awaiting, self._continue = what, False
        self.prompt = f"{prompt}, then call continue"
        self.say(self.prompt)
        t0 = self.t_s
        while not self._continue:
            if self.t_s - t0 > max_s:
                raise CampaignAbort(f"no continue within {max_s:g} s ({what})")
            yield self.ctrl.wrench(self.state, (), self.tick_s) if hold else np.zeros(6)
        self._continue = False  # operator_continue cleared awaiting and the prompt
        self.undo.pop(what, None)
        self.say(f"operator continued ({what}): holding")
