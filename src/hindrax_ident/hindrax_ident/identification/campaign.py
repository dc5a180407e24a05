"""Identification campaign on the simulator (no ROS graph): [Hindrax-Drag] (seed 003) §4 manoeuvres, one DOF at a time.

Sequence: dive to the altitude setpoint (``identification.altitude_setpoint_m``, Ping1D) and settle (the gyro
bias is averaged while still), then for each requested DOF: move to the pool-box centre and run the ladder
of constant levels (:func:`.maneuvers.level_ladder`) with the other DOFs held by
:class:`.maneuvers.HoldController` from sensor samples only:

* surge, sway: alternate +level / -level runs along the body axis (heading held at the start heading);
  a run ends when the dead-reckoned stopping point reaches the :class:`.maneuvers.PoolBox` boundary or after
  ``identification.max_level_duration_s``; the larger room is used first, so both directions are tested.
* heave: down then up within the box depth range, ``heave_repeats`` pairs per level (3); no steady state is
  required (estimated through the transient, docs/architecture.md §5).
* roll, pitch: rotate until the predicted stopping angle reaches ``identification.roll_test_angle_rad`` /
  ``pitch_test_angle_rad``, then return to level ([Hindrax-Drag] (seed 003) §4.2), both directions.
* yaw: one turn (2 pi) per run ([Hindrax-Drag] (seed 003) §4.2: 360 deg rotations), both directions.

Control/estimation rate ``identification.estimate_rate_hz`` (the simulator steps in between). Every tick
records the thrust-model wrench: the thrust of the commanded pulse widths through the allocator's curves
([Hindrax-Drag] (seed 003) eq. 1), passed through the configured first-order lag ``thrusters.time_constant_s`` (exact for the
held command), times the thrust allocation matrix ([Hindrax-Drag] (seed 003) eq. 9), body FRD. Limits (``limits.*``: depth,
altitude, roll, pitch; the pool box grown by half the margin) abort the campaign; at the end or on abort
all thrusters are commanded neutral.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from hindrax_drivers import frames
from hindrax_drivers.allocation.core import AllocationCore
from hindrax_drivers.config import DOFS, VehicleConfig

from ..sim.simulator import Simulator
from .estimators import OnlineDofEstimator, measurement_settings
from .maneuvers import (DOF_INDEX, DepthEstimator, HoldController, PoolBox, SensorState, dof_authority,
                        level_ladder, prior_inertia, wrap_angle)

__all__ = ["CampaignAbort", "CampaignRecord", "Campaign", "run_campaign"]


class CampaignAbort(RuntimeError):
    """A limit was crossed (the message names it); the campaign stops with neutral thrust."""


@dataclass
class CampaignRecord:
    """Everything a campaign produced (arrays per control tick, shape (n,) or (n, k)).

    t_s: tick times (s). wrench_frd: thrust-model wrench at the tick (lagged), (n, 6) N / N m.
    wrench_cmd_frd: wrench of the commanded pulse widths held over the tick (n, 6). active: index of the DOF
    under test (-1 none). level: the test level commanded in a run (NaN outside runs). run_id: run counter
    (-1 outside runs). truth_position_ned_m / truth_euler_rad (n, 3): simulator truth, for tests and plots
    only (never used by control or estimation). sensors: the conditioned sensor log of
    :class:`.maneuvers.SensorState`. windows: DOF -> (t_start, t_end). online: DOF -> OnlineDofEstimator.
    levels / authority: DOF -> ladder (N or N m) / (positive, negative) authority. aborted, abort_reason,
    wall_time_s, tick_s, time_constant_s, seed, gyro_bias_frd_rad_s.
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

    def dof_slice(self, dof: str) -> slice:
        """Tick index range of one DOF's manoeuvres (empty slice when it was not run)."""
        if dof not in self.windows:
            return slice(0, 0)
        t0, t1 = self.windows[dof]
        i0 = int(np.searchsorted(self.t_s, t0, side="left"))
        i1 = int(np.searchsorted(self.t_s, t1, side="right"))
        return slice(i0, i1)


class Campaign:
    """Runs the identification manoeuvres on a :class:`~hindrax_ident.sim.simulator.Simulator` (module docstring).

    cfg: vehicle configuration. dofs: DOFs to test, in order (default all six). levels: levels per DOF
    (default ``identification.levels_per_dof``). seed: simulator seed (default ``simulation.seed``).
    max_level_duration_s: cap of one run (default ``identification.max_level_duration_s``).
    progress: optional callable receiving one-line progress messages. real_time_factor: > 0 paces the
    simulation against the wall clock (0: as fast as possible). sim: an existing simulator (else built).
    heave_repeats: down/up pairs per heave level (heave runs last 1-3 s in the depth available, so each level
    is repeated to collect enough transient data).
    Raises ``ValueError`` for an unknown DOF.
    """

    def __init__(self, cfg: VehicleConfig, dofs: Sequence[str] = DOFS, levels: int | None = None,
                 seed: int | None = None, max_level_duration_s: float | None = None,
                 progress: Callable[[str], None] | None = None, real_time_factor: float = 0.0,
                 sim: Simulator | None = None, heave_repeats: int = 3) -> None:
        bad = [d for d in dofs if d not in DOFS]
        if bad:
            raise ValueError(f"unknown DOF(s) {bad}; choose from {', '.join(DOFS)}")
        self.cfg = cfg
        f = cfg.flat
        self.dofs = list(dofs)
        self.seed = int(f["simulation.seed"] if seed is None else seed)
        self.sim = sim if sim is not None else Simulator(cfg, seed=self.seed)
        self.core = AllocationCore(cfg)
        self.curve = self.core.allocator.curves[0]
        self.matrix = np.asarray(self.core.matrix_frd, dtype=float)
        self.reversed = np.array([t.reversed for t in cfg.thrusters.thrusters], dtype=bool)
        self.neutral_us = float(cfg.thrusters.pulse_width_neutral_us)
        self.time_constant_s = float(cfg.thrusters.time_constant_s)
        rate = float(f["identification.estimate_rate_hz"])
        self.steps_per_tick = max(1, int(round(1.0 / (rate * self.sim.step_s))))
        self.tick_s = self.steps_per_tick * self.sim.step_s
        self.levels_per_dof = levels
        self.heave_repeats = max(1, int(heave_repeats))
        self.max_level_s = float(f["identification.max_level_duration_s"] if max_level_duration_s is None
                                 else max_level_duration_s)
        self.progress = progress or (lambda msg: None)
        self.rtf = float(real_time_factor)
        self.box = PoolBox.from_config(cfg)
        self.authority = {d: dof_authority(self.core, d) for d in DOFS}
        self.ctrl = HoldController(cfg, [min(self.authority[d]) for d in DOFS])
        self.state = SensorState(cfg)
        hv = measurement_settings(cfg, "heave")
        self.depth_estimator = DepthEstimator(hv["std"], hv["accel_std"], hv["accel_jerk_psd"])
        self.online = {d: OnlineDofEstimator(cfg, d) for d in self.dofs}
        self._pending: list = []
        self.sim.add_sensor_listener(lambda dev, s: self._pending.append((dev, s)))
        self.f_lag = np.zeros(len(self.curve_names()))
        self._rec: dict[str, list] = {k: [] for k in ("t", "w", "wc", "active", "level", "run", "pos", "eul")}
        self.windows: dict[str, tuple[float, float]] = {}
        self.levels: dict[str, list[float]] = {}
        self._active = -1
        self._level = math.nan
        self._run = -1
        self._n_runs = 0
        self._wall0 = 0.0
        self._sim0 = 0.0

    def curve_names(self) -> list[str]:
        """Thruster names in allocation order."""
        return list(self.core.names)

    # ------------------------------------------------------------------ one control tick
    def tick(self, wrench_frd: np.ndarray) -> None:
        """Allocate ``wrench_frd`` (6,), command it for one tick, process the new samples, check the limits.

        Raises :class:`CampaignAbort` when a limit is crossed.
        """
        alloc = self.core.allocate(frames.wrench_frd_to_flu(np.asarray(wrench_frd, dtype=float)))
        pw = np.asarray(alloc.pulse_width_us, dtype=float)
        f_cmd = np.asarray(self.curve.thrust_n(pw), dtype=float)  # thrust model of the commanded widths
        t = self.sim.t_s
        self._rec["t"].append(t)
        self._rec["w"].append(self.matrix @ self.f_lag)
        self._rec["wc"].append(self.matrix @ f_cmd)
        self._rec["active"].append(self._active)
        self._rec["level"].append(self._level)
        self._rec["run"].append(self._run)
        self._rec["pos"].append(self.sim.position_ned_m)
        self._rec["eul"].append(self.sim.euler_rad)
        wire = np.where(self.reversed, 2.0 * self.neutral_us - pw, pw)
        self.sim.advance(self.tick_s, wire)
        if self.time_constant_s > 0.0:
            k = math.exp(-self.tick_s / self.time_constant_s)
            self.f_lag = f_cmd + (self.f_lag - f_cmd) * k
        else:
            self.f_lag = f_cmd
        self._process_samples()
        t_new = self.sim.t_s
        self._update_depth_hold(t_new)
        if self._active >= 0:
            dof = DOFS[self._active]
            if dof in self.online:
                self.online[dof].update(t_new, float((self.matrix @ self.f_lag)[self._active]), self.state)
        self._check_limits()
        if self.rtf > 0.0:
            ahead = (self.sim.t_s - self._sim0) / self.rtf - (time.monotonic() - self._wall0)
            if ahead > 0.0:
                time.sleep(ahead)  # pacing against the wall clock only (the --rtf option)

    def _process_samples(self) -> None:
        pending, self._pending = self._pending, []
        for dev, s in pending:
            self.state.on_sample(dev, s)
            self.depth_estimator.on_sample(dev, s.stamp_s, self.state)
            for est in self.online.values():
                est.on_sample(dev, s.stamp_s, self.state)

    def _update_depth_hold(self, t_s: float) -> None:
        """Depth and depth rate of the hold predicted to the tick time ``t_s`` (:class:`DepthEstimator`)."""
        depth, rate = self.depth_estimator.predict_to(t_s)
        if math.isfinite(rate):
            self.ctrl.depth_rate_m_s = rate
            self.ctrl.depth_estimate_m = depth

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

    # ------------------------------------------------------------------ helpers
    def _hold_ticks(self, duration_s: float, free: Sequence[str] = (), extra: np.ndarray | None = None) -> None:
        n = int(round(duration_s / self.tick_s))
        for _ in range(n):
            w = self.ctrl.wrench(self.state, free, self.tick_s)
            if extra is not None:
                w = w + extra
            self.tick(w)

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
        return max(0.0, float(self.sim.t_s) - float(log[-1][0])) if log else 0.0

    def _wait_still(self, k: int, tol: float, max_s: float, free: Sequence[str] = ()) -> None:
        still = 0.0
        t0 = self.sim.t_s
        while self.sim.t_s - t0 < max_s:
            self.tick(self.ctrl.wrench(self.state, free, self.tick_s))
            settled = abs(self._axis_velocity(k)) < tol
            if k in (3, 4):
                settled = settled and abs(float(np.nan_to_num(self.state.rpy_rad[k - 3]))) < 0.05
            if settled:
                still += self.tick_s
                if still >= 0.5:
                    return
            else:
                still = 0.0

    def _dive(self) -> None:
        self.progress("dive to the altitude setpoint and settle")
        alt_sp = float(self.cfg.flat["identification.altitude_setpoint_m"])
        self.ctrl.heading_setpoint_rad = float(self.cfg.flat["pool.start_heading_rad"])
        # first samples
        self.tick(np.zeros(6))
        target = self.box.z_min
        t0 = self.sim.t_s
        self.ctrl.depth_setpoint_m = max(self.state.depth_m, 0.0) if math.isfinite(self.state.depth_m) else 0.0
        while self.sim.t_s - t0 < 25.0:
            st = self.state
            if math.isfinite(st.altitude_m) and math.isfinite(st.depth_m):
                target = float(np.clip(st.depth_m + st.altitude_m - alt_sp, self.box.z_min, self.box.z_max))
            step = 0.25 * self.tick_s
            self.ctrl.depth_setpoint_m += float(np.clip(target - self.ctrl.depth_setpoint_m, -step, step))
            self.tick(self.ctrl.wrench(self.state, (), self.tick_s))
            if abs(target - self.ctrl.depth_setpoint_m) < 1e-6 and abs(self.state.depth_m - target) < 0.03 \
                    and abs(self.ctrl.depth_rate_m_s) < 0.03:
                break
        self.depth_hold_m = target
        self.ctrl.depth_setpoint_m = target
        self._hold_ticks(1.0)
        self.state.start_gyro_bias()
        self._hold_ticks(2.0)
        self.state.finish_gyro_bias()

    def _move_to_centre(self) -> None:
        c = self.box.centre
        self.ctrl.depth_setpoint_m = self.depth_hold_m
        t0 = self.sim.t_s
        while self.sim.t_s - t0 < 40.0:
            p = self.state.position_ned_m
            err_ned = np.array([c[0] - p[0], c[1] - p[1]])
            psi = float(np.nan_to_num(self.state.rpy_rad[2]))
            rot = np.array([[math.cos(psi), math.sin(psi)], [-math.sin(psi), math.cos(psi)]])  # NED -> body
            v_sp = np.clip(0.6 * (rot @ err_ned), -0.25, 0.25)
            self.ctrl.velocity_setpoint_m_s = v_sp
            self.tick(self.ctrl.wrench(self.state, (), self.tick_s))
            speed = float(np.linalg.norm(np.nan_to_num(self.state.velocity_frd_m_s[:2])))
            if np.linalg.norm(err_ned) < 0.15 and speed < 0.05:
                break
        self.ctrl.velocity_setpoint_m_s = np.zeros(2)
        self._hold_ticks(1.0)

    def _start_run(self, dof: str, level: float) -> None:
        self._active = DOF_INDEX[dof]
        self._level = level
        self._run = self._n_runs
        self._n_runs += 1

    def _end_run(self) -> None:
        self._level = math.nan
        self._run = -1

    # ------------------------------------------------------------------ manoeuvres
    def _translation(self, dof: str, ladder: list[float]) -> None:
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
                signs = (1.0, -1.0)  # heave: down, then up (docs/architecture.md §5)
            else:
                signs = (1.0, -1.0) if self.box.room_m(p, axis) >= self.box.room_m(p, -axis) else (-1.0, 1.0)
            for s in signs * repeats:
                self.progress(f"{dof}: level {i + 1}/{len(ladder)} {s * lvl:+.2f} N")
                self._start_run(dof, s * lvl)
                t0 = self.sim.t_s
                while self.sim.t_s - t0 < self.max_level_s:
                    vs = max(0.0, s * self._axis_velocity(k))
                    stop = vs * vs / (2.0 * a_brake) + 0.3 * vs + 0.03
                    if self.box.room_m(self.state.position_ned_m, s * axis) <= stop:
                        break
                    extra = np.zeros(6)
                    extra[k] = s * lvl
                    w = self.ctrl.wrench(self.state, (dof,), self.tick_s) + extra
                    self.tick(w)
                self._end_run()
                if k == 2:
                    v = self._axis_velocity(2)
                    self.ctrl.depth_setpoint_m = float(np.clip(self.state.depth_m + v * abs(v) / (2 * a_brake),
                                                               self.box.z_min, self.box.z_max))
                    self.ctrl.reset_integral()
                self._wait_still(k, 0.05, 6.0)
                self._hold_ticks(0.5)
        if k == 2:
            self.ctrl.depth_setpoint_m = self.depth_hold_m

    def _rotation(self, dof: str, ladder: list[float]) -> None:
        k = DOF_INDEX[dof]
        inertia = prior_inertia(self.cfg, dof)
        alpha = 0.5 * min(self.authority[dof]) / inertia
        if dof == "yaw":
            limit = 2.0 * math.pi
        else:
            limit = float(self.cfg.flat[f"identification.{dof}_test_angle_rad"])
        for i, lvl in enumerate(ladder):
            for s in (1.0, -1.0):
                self.progress(f"{dof}: level {i + 1}/{len(ladder)} {s * lvl:+.2f} N m")
                self._start_run(dof, s * lvl)
                t0 = self.sim.t_s
                turned = 0.0
                prev = float(np.nan_to_num(self.state.rpy_rad[k - 3]))
                while self.sim.t_s - t0 < self.max_level_s:
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
                    extra = np.zeros(6)
                    extra[k] = s * lvl
                    self.tick(self.ctrl.wrench(self.state, (dof,), self.tick_s) + extra)
                self._end_run()
                if dof == "yaw":
                    r = self._axis_velocity(5)
                    self.ctrl.heading_setpoint_rad = wrap_angle(float(np.nan_to_num(self.state.rpy_rad[2]))
                                                                + r * abs(r) / (2.0 * alpha))
                self._wait_still(k, 0.05, 8.0)
                self._hold_ticks(0.5)

    # ------------------------------------------------------------------ the campaign
    def run(self) -> CampaignRecord:
        """Run the campaign; returns the :class:`CampaignRecord` (aborted campaigns too)."""
        self._wall0 = time.monotonic()
        self._sim0 = self.sim.t_s
        aborted, reason = False, ""
        try:
            self._dive()
            for dof in self.dofs:
                self._move_to_centre()
                ladder = self.ladder(dof)
                self.levels[dof] = ladder
                t0 = self.sim.t_s
                self._active = DOF_INDEX[dof]
                if dof in ("surge", "sway", "heave"):
                    self._translation(dof, ladder)
                else:
                    self._rotation(dof, ladder)
                self._active = -1
                self.windows[dof] = (t0, self.sim.t_s)
                self.progress(f"{dof}: done ({self.sim.t_s - t0:.0f} s of pool time)")
        except CampaignAbort as exc:
            aborted, reason = True, str(exc)
            self.progress(f"ABORT: {reason}")
            if self._active >= 0 and DOFS[self._active] not in self.windows:
                self.windows[DOFS[self._active]] = (self._dof_start(), self.sim.t_s)
        finally:
            self._active = -1
            self._end_run()
            self._neutral()
        r = self._rec
        return CampaignRecord(
            t_s=np.asarray(r["t"]), wrench_frd=np.asarray(r["w"]).reshape(-1, 6),
            wrench_cmd_frd=np.asarray(r["wc"]).reshape(-1, 6), active=np.asarray(r["active"], dtype=int),
            level=np.asarray(r["level"], dtype=float), run_id=np.asarray(r["run"], dtype=int),
            truth_position_ned_m=np.asarray(r["pos"]).reshape(-1, 3),
            truth_euler_rad=np.asarray(r["eul"]).reshape(-1, 3), sensors=self.state.log,
            windows=dict(self.windows), online=self.online, levels=self.levels, authority=self.authority,
            aborted=aborted, abort_reason=reason, wall_time_s=time.monotonic() - self._wall0, tick_s=self.tick_s,
            time_constant_s=self.time_constant_s, seed=self.seed,
            final_pulse_width_us=np.array(self.sim.thrusters.pulse_width_us, copy=True))

    def ladder(self, dof: str) -> list[float]:
        """Levels of one DOF (N or N m): :func:`.maneuvers.level_ladder` of the DOF's smaller authority."""
        return level_ladder(self.cfg, min(self.authority[dof]), self.levels_per_dof)

    def _dof_start(self) -> float:
        act = np.asarray(self._rec["active"])
        idx = np.flatnonzero(act == self._active)
        return float(self._rec["t"][idx[0]]) if idx.size else self.sim.t_s

    def _neutral(self) -> None:
        """Command neutral pulse widths on every thruster (end of campaign or abort)."""
        neutral = np.full(len(self.core.names), self.neutral_us)
        self.sim.step(neutral)
        self.f_lag = np.zeros_like(self.f_lag)


def run_campaign(cfg: VehicleConfig, **kwargs) -> CampaignRecord:
    """Build a :class:`Campaign` with ``kwargs`` and run it."""
    return Campaign(cfg, **kwargs).run()
