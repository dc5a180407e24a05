"""Identification node: the manoeuvre executive of [Hindrax-Drag] (seed 003) §4 as the ``run_identification`` action.

Thin rclpy node over the pure campaign logic (:class:`~.campaign.Campaign`, :mod:`.maneuvers`,
:class:`~.estimators.OnlineDofEstimator`): the same dive, positioning, level ladders, holds, pool-box planning,
limits and online Kalman + RLS run here, fed from the ROS sensor topics instead of the simulator. Only the
plant differs (:class:`RosCampaign`): a tick publishes the wrench to the thrust allocation and waits for the
next tick of the ROS clock; the force in the regression is the thrust model of the pulse widths the ESC node
actually wrote (``thrusters/pulse_width``: wire widths, un-reversed and un-trimmed here, through the
allocation's cubic curves, [Hindrax-Drag] (seed 003) eq. 1, the first-order lag ``thrusters.time_constant_s`` and the thrust
allocation matrix, [Hindrax-Drag] (seed 003) eq. 9), body FRD.

Run alone: ``python -m hindrax_ident.identification.node --ros-args --params-file ros_ws/config/hindrax.yaml``.

Interfaces
----------
Action server ``run_identification`` (hindrax_msgs/action/RunIdentification)
    Goal: ``dofs`` (empty = all six, in SNAME order), ``levels_per_dof`` (0 = ``identification.levels_per_dof``),
    ``level_fractions`` (optional explicit fractions of the DOF's authority, each in (0, 1]). Rejected when
    a goal is running or the goal is invalid (unknown DOF, fraction out of range). The goal fails at once
    when the ESC output is not armed. Feedback at every level change and once per second: DOF, level index
    and count, level command (N or N m, FRD), progress 0-1. Cancel: the manoeuvre stops, the vehicle is
    left at neutral thrust (zero wrench, then no more wrench messages: the allocation's wrench timeout
    keeps it neutral). Result: success, message (abort reason), the final online estimate of every DOF.
Subscribes
    ``dvl/data`` (hindrax_msgs/Dvl: velocity FLU and attitude ENU), ``pressure/fluid_pressure``
    (FluidPressure, Pa), ``imu/data_raw`` (Imu, FLU), ``ping/altitude`` (Range),
    ``thrusters/pulse_width`` (ThrusterPwm, widths written by the ESC node and the armed flag).
Publishes
    ``wrench`` (geometry_msgs/WrenchStamped, base_link FLU) at ``identification.estimate_rate_hz`` while a
    goal runs; ``identification/estimates`` (HydroEstimate, method ``rls``, one per DOF with data) at
    ``identification.publish_rate_hz`` (>= 1 Hz); ``identification/status`` (ManeuverStatus) at every tick
    while a goal runs (phase, DOF, level, progress, message = current step) and at 1 Hz when idle.
Parameters
    The vehicle configuration; node-specific ``dvl_lock_timeout_s`` (default 3.0): a surge or sway run
    aborts when the DVL had no valid velocity for this long (docs/architecture.md §8), and ``tick_timeout_s`` (wall
    time the executor waits for one tick of the executive, default 30).
Safety (docs/architecture.md §8)
    Limits of :meth:`~.campaign.Campaign._check_limits` (depth, altitude, roll, pitch, pool box) plus DVL lock
    and ESC disarm abort the goal; the vehicle is left at neutral thrust at the end, on abort and on cancel.

Threading: the executive runs in a worker thread in strict lock-step with the executor (the executor hands
it the new samples of one tick and waits for its wrench), so the SingleThreadedExecutor remains the only
thread touching rclpy and runs are deterministic for a given sample sequence.
"""
from __future__ import annotations

import math
import queue
import sys
import threading
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np
import rclpy
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import FluidPressure, Imu, Range

from hindrax_drivers import frames
from hindrax_drivers.config import DOFS, ConfigError, VehicleConfig, node_config
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, HydroEstimate, ManeuverStatus, ThrusterPwm

from .campaign import Campaign, CampaignAbort, CampaignRecord
from .estimators import parameter_units
from .maneuvers import DOF_INDEX, level_ladder  # noqa: F401 - level_ladder documented as the default ladder

__all__ = ["IdentificationNode", "RosCampaign", "RosPlant", "samples_from_dvl", "samples_from_imu",
           "sample_from_pressure", "sample_from_range", "thrust_of_written_widths", "hydro_estimate", "main"]

#: Message prefix of the status while the gyro/accelerometer biases are averaged (the vehicle is held still);
#: :mod:`.from_bag` finds the still window by it.
STILL_MESSAGE = "still: averaging gyro and accelerometer bias"


# ============================================================================ ROS message -> sample adapters
def _stamp_s(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def samples_from_dvl(msg) -> list[tuple[str, Any]]:
    """Samples of one hindrax_msgs/Dvl message in the simulator's sample form (:mod:`hindrax_ident.sim.sensors`).

    Returns ``[("dvl75_attitude", ns(stamp_s, roll_rad, pitch_rad, yaw_rad))]`` (NED Euler angles of body FRD,
    via :func:`hindrax_drivers.frames.quaternion_ros_to_marine`; left out when the quaternion is all zero)
    followed by ``("dvl75", ns(stamp_s, velocity_frd_m_s (3,), locked, at_body_origin=True))`` (velocity FLU ->
    FRD; NaN and ``locked`` False without a valid velocity). Works on rclpy and bag-decoded messages alike.

    ``at_body_origin``: the driver publishes the velocity of base_link (it removes the lever arm with the
    ``$DVPDL`` rotation, :mod:`hindrax_drivers.dvl75.report`), unlike the simulator's transducer-velocity
    samples, so :class:`~.maneuvers.SensorState` must not remove it again. (It did: at 1-2 rad/s of pitch
    the surge velocity was 0.18 m x q off, 0.27 m/s rms, and the surge hold pushed the vehicle to 0.28 m/s
    during the pitch runs; measured through the ROS graph in the virtual pool.)

    Times: the header stamp is the velocity's time of validity, the middle of the ``$DVPDL`` interval; the
    attitude comes from the driver's latest ``$DVEXT``, which is the one of the same ping when the DVL sends it
    first (as the emulator does; the real order is undocumented, docs/devices.md §1.3: check a pool capture), i.e.
    measured at the end of that interval: stamp + ``delta_time_s`` / 2 (the stamp when the interval is unknown). A
    50 ms error there shows up in roll and pitch as a restoring moment out of phase, i.e. as damping
    (measured in the virtual pool: roll quadratic damping +14 %, linear damping of the wrong sign).
    """
    t = _stamp_s(msg.header)
    half = 0.5 * float(msg.delta_time_s)
    t_att = t + half if math.isfinite(half) and half > 0.0 else t
    out: list[tuple[str, Any]] = []
    q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w], dtype=float)
    if np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5:
        rpy = frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q))
        out.append(("dvl75_attitude", SimpleNamespace(stamp_s=t_att, roll_rad=float(rpy[0]), pitch_rad=float(rpy[1]),
                                                      yaw_rad=float(rpy[2]))))
    v = np.array([msg.velocity_m_s.x, msg.velocity_m_s.y, msg.velocity_m_s.z], dtype=float)
    locked = bool(msg.velocity_valid) and bool(np.all(np.isfinite(v)))
    out.append(("dvl75", SimpleNamespace(stamp_s=t, velocity_frd_m_s=frames.flu_to_frd(v) if locked
                                         else np.full(3, np.nan), locked=locked, at_body_origin=True)))
    return out


def samples_from_imu(msg, mounting_frd_from_flu: np.ndarray | None = None) -> list[tuple[str, Any]]:
    """``icm20948_gyro`` and ``icm20948_accel`` samples of a sensor_msgs/Imu (base_link FLU).

    The simulator's samples are in the sensor axes, which :class:`~.maneuvers.SensorState` rotates with the
    configured mounting; the driver has already applied it, so the FLU vectors are taken back to sensor axes
    with ``mounting_frd_from_flu`` = R_mount^T (3, 3) (identity when None). Angular rate rad/s, specific
    force m/s^2.
    """
    t = _stamp_s(msg.header)
    r = np.eye(3) if mounting_frd_from_flu is None else mounting_frd_from_flu
    w = r @ np.array([msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z], dtype=float)
    a = r @ np.array([msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z],
                     dtype=float)
    return [("icm20948_gyro", SimpleNamespace(stamp_s=t, angular_rate_rad_s=w)),
            ("icm20948_accel", SimpleNamespace(stamp_s=t, specific_force_m_s2=a))]


def sample_from_pressure(msg) -> tuple[str, Any]:
    """``ms5837`` sample (absolute pressure, Pa) of a sensor_msgs/FluidPressure."""
    return "ms5837", SimpleNamespace(stamp_s=_stamp_s(msg.header), pressure_pa=float(msg.fluid_pressure))


def sample_from_range(msg) -> tuple[str, Any]:
    """``ping1d`` sample of a sensor_msgs/Range: distance (m), valid when finite and within [min, max] range."""
    r = float(msg.range)
    valid = math.isfinite(r) and msg.min_range <= r <= msg.max_range
    return "ping1d", SimpleNamespace(stamp_s=_stamp_s(msg.header), distance_m=r, valid=valid)


def thrust_of_written_widths(cfg: VehicleConfig, curve, written_us: Sequence[float]) -> np.ndarray:
    """Thruster forces (n,) N of the WIRE pulse widths the ESC node wrote (ThrusterPwm of ``thrusters/pulse_width``).

    The ESC applies reversal (2 neutral - w) and trim after the allocation (pca9685/node.py ``EscOutput``);
    both are undone here, then the allocation's thrust curve ([Hindrax-Drag] (seed 003) eq. 1) gives the force along each
    thruster's configured direction. Raises ``ValueError`` for a wrong number of widths.
    """
    w = np.asarray(written_us, dtype=float)
    th = cfg.thrusters.thrusters
    if w.shape != (len(th),):
        raise ValueError(f"{w.size} pulse widths, expected {len(th)}")
    neutral = float(cfg.thrusters.pulse_width_neutral_us)
    trim = np.array([t.trim_us for t in th], dtype=float)
    rev = np.array([t.reversed for t in th], dtype=bool)
    logical = w - trim
    logical = np.where(rev, 2.0 * neutral - logical, logical)
    return np.asarray(curve.thrust_n(logical), dtype=float)


def hydro_estimate(dof: str, estimator, stamp, method: str = "rls") -> HydroEstimate:
    """HydroEstimate of one :class:`~.estimators.OnlineDofEstimator` (RLS value, std, covariance, excitation)."""
    rls = estimator.rls
    units = parameter_units(dof)
    msg = HydroEstimate(dof=dof, method=method)
    msg.header.stamp = stamp
    msg.header.frame_id = "base_link"
    msg.parameter_names = list(estimator.names)
    msg.parameter_units = [units[n] for n in estimator.names]
    msg.values = [float(v) for v in rls.theta]
    msg.std = [float(s) if math.isfinite(s) else -1.0 for s in rls.std]
    cov = np.asarray(rls.covariance, dtype=float)
    msg.covariance = [float(c) if math.isfinite(c) else 0.0 for c in cov.ravel()]
    msg.sample_count = int(rls.n_samples)
    ex = float(rls.excitation_normalised)
    msg.excitation = ex if math.isfinite(ex) else 0.0
    msg.converged = estimator.converged_at_s is not None
    return msg


# ============================================================================ the plant seen from ROS
class _Thrusters:
    def __init__(self, n: int, neutral_us: float) -> None:
        self.pulse_width_us = np.full(n, neutral_us)


class RosPlant:
    """The part of :class:`~hindrax_ident.sim.simulator.Simulator` the campaign uses, backed by ROS.

    ``t_s``: ROS time of the current tick (s); ``step_s``: the tick period (s), so one campaign tick is one
    plant step; ``add_sensor_listener(cb)``: ``cb(device, sample)`` gets every sample handed over by the node;
    ``thrusters.pulse_width_us``: last widths written by the ESC node (wire, us).
    """

    def __init__(self, tick_s: float, n_thrusters: int, neutral_us: float, t0_s: float) -> None:
        self.step_s = float(tick_s)
        self.t_s = float(t0_s)
        self.thrusters = _Thrusters(n_thrusters, neutral_us)
        self._listeners: list = []

    def add_sensor_listener(self, cb) -> None:
        """Register ``cb(device, sample)``."""
        self._listeners.append(cb)

    def deliver(self, samples: Sequence[tuple[str, Any]], not_before_s: float = -math.inf) -> None:
        """Hand samples to the listeners, oldest stamp first (stable).

        A sample stamped before ``not_before_s`` (the previous tick, to which the online filters have already
        been predicted: sensor latency, e.g. the MS5837 stamp of its conversion start or the DVL time of
        validity) is handed over with its stamp moved to ``not_before_s`` (a copy; the messages and the bag
        keep the original stamps, which the offline analysis uses).
        """
        for dev, s in sorted(samples, key=lambda ds: ds[1].stamp_s):
            if s.stamp_s < not_before_s:
                s = SimpleNamespace(**{**vars(s), "stamp_s": not_before_s})
            for cb in self._listeners:
                cb(dev, s)


@dataclass
class TickInput:
    """What the executor hands the executive at a tick: ROS time (s), new samples, written widths, flags."""

    t_s: float
    samples: list
    written_us: np.ndarray | None
    armed: bool
    cancel: bool


class RosCampaign(Campaign):
    """:class:`~.campaign.Campaign` whose plant is the ROS graph (module docstring).

    link: (to_worker, to_ros) queues of the lock-step exchange. fractions: optional explicit level fractions.
    dvl_lock_timeout_s: longest time without a valid DVL velocity during surge/sway manoeuvres.
    """

    def __init__(self, cfg: VehicleConfig, plant: RosPlant, dofs: Sequence[str], levels: int | None,
                 fractions: Sequence[float] | None, link: tuple[queue.Queue, queue.Queue],
                 dvl_lock_timeout_s: float = 3.0) -> None:
        super().__init__(cfg, dofs=dofs, levels=levels, seed=0, sim=plant)
        self.plant = plant
        self.fractions = [float(f) for f in fractions] if fractions else None
        self.to_worker, self.to_ros = link
        self.dvl_lock_timeout_s = float(dvl_lock_timeout_s)
        self.written_us = np.full(len(self.core.names), self.neutral_us)
        self.armed = True
        self.last_dvl_valid_s = plant.t_s
        self.message = ""
        self.progress = self._remember
        self.sim.add_sensor_listener(self._watch_dvl)

    def _remember(self, msg: str) -> None:
        self.message = msg

    def _watch_dvl(self, dev: str, s) -> None:
        if dev == "dvl75" and s.locked:
            self.last_dvl_valid_s = max(self.last_dvl_valid_s, s.stamp_s)

    def ladder(self, dof: str) -> list[float]:
        """The goal's explicit fractions times the DOF's smaller authority, else the configured ladder."""
        if self.fractions:
            return [f * min(self.authority[dof]) for f in self.fractions]
        return super().ladder(dof)

    def tick(self, wrench_frd: np.ndarray) -> None:
        """Publish ``wrench_frd`` (6,) for one tick, wait for the next ROS tick, process its samples, check limits.

        Raises :class:`CampaignAbort` on a limit, a cancel request, a disarmed ESC or DVL lock loss.
        """
        w = np.asarray(wrench_frd, dtype=float)
        f_cmd = thrust_of_written_widths(self.cfg, self.curve, self.written_us)
        self._rec["t"].append(self.plant.t_s)
        self._rec["w"].append(self.matrix @ self.f_lag)
        self._rec["wc"].append(self.matrix @ f_cmd)
        self._rec["active"].append(self._active)
        self._rec["level"].append(self._level)
        self._rec["run"].append(self._run)
        self._rec["pos"].append(np.full(3, np.nan))  # no ground truth from ROS (docs/architecture.md §6)
        self._rec["eul"].append(np.full(3, np.nan))
        self.to_ros.put(("wrench", w))
        inp: TickInput = self.to_worker.get()
        if inp is None:
            raise CampaignAbort("node shutting down")
        dt = max(0.0, inp.t_s - self.plant.t_s)
        previous_tick_s = self.plant.t_s
        self.plant.t_s = inp.t_s
        if self.time_constant_s > 0.0:
            k = math.exp(-dt / self.time_constant_s)
            self.f_lag = f_cmd + (self.f_lag - f_cmd) * k
        else:
            self.f_lag = f_cmd
        if inp.written_us is not None:
            self.written_us = np.asarray(inp.written_us, dtype=float)
            self.plant.thrusters.pulse_width_us = self.written_us.copy()
        self.plant.deliver(inp.samples, previous_tick_s)
        self._process_samples()
        self._update_depth_hold(inp.t_s)
        if self._active >= 0:
            dof = DOFS[self._active]
            if dof in self.online:
                self.online[dof].update(inp.t_s, float((self.matrix @ self.f_lag)[self._active]), self.state)
        if inp.cancel:
            raise CampaignAbort("cancelled")
        if not inp.armed:
            raise CampaignAbort("ESC output disarmed")
        self._check_limits()

    def _check_limits(self) -> None:
        super()._check_limits()
        if self._active in (0, 1) and self.plant.t_s - self.last_dvl_valid_s > self.dvl_lock_timeout_s:
            raise CampaignAbort(f"DVL lock lost for {self.plant.t_s - self.last_dvl_valid_s:.1f} s during "
                                f"{DOFS[self._active]} (dvl_lock_timeout_s {self.dvl_lock_timeout_s:g})")

    def _neutral(self) -> None:
        """Neutral at the end: the node publishes a zero wrench when the executive finishes."""
        self.f_lag = np.zeros_like(self.f_lag)

    def level_position(self) -> tuple[str, int, int, float]:
        """(DOF, level index, level count, level command) of the current tick ('' / 0 / 0 / 0 when none)."""
        if self._active < 0:
            return "", 0, 0, 0.0
        dof = DOFS[self._active]
        ladder = self.levels.get(dof, [])
        last = getattr(self, "_last_level", ("", 0))
        if not math.isfinite(self._level) or not ladder:
            return dof, last[1] if last[0] == dof else 0, len(ladder), 0.0
        i = int(np.argmin([abs(abs(self._level) - lv) for lv in ladder]))
        self._last_level = (dof, i)
        return dof, i, len(ladder), float(self._level)


# ============================================================================ the node
class IdentificationNode(Node):
    """The identification manoeuvre executive as a ROS node (module docstring).

    config: a VehicleConfig (default: from the node's parameters, :func:`node_config`). Other keyword
    arguments go to ``Node``. Raises :class:`ConfigError` for an invalid configuration.
    """

    def __init__(self, *, config: VehicleConfig | None = None, node_name: str = "identification",
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        log = self.get_logger()
        self.config = config if config is not None else node_config(self, on_error=log.error)
        f = self.config.flat
        self.tick_s = 1.0 / float(f["identification.estimate_rate_hz"])
        self.publish_period_s = 1.0 / max(1.0, float(f["identification.publish_rate_hz"]))
        self.dvl_lock_timeout_s = float(self._param("dvl_lock_timeout_s", 3.0))
        self.tick_timeout_s = float(self._param("tick_timeout_s", 30.0))
        from .maneuvers import SensorState  # noqa: F401 - documented dependency
        from hindrax_drivers.icm20948.mounting import mounting_rotation
        self._mount_t = mounting_rotation(f["sensors.icm20948.mounting_rpy_rad"]).T
        self._samples: list = []
        self._seen: set[str] = set()
        self._written: np.ndarray | None = None
        self._armed = False
        self._campaign: RosCampaign | None = None
        self._thread: threading.Thread | None = None
        self._link: tuple[queue.Queue, queue.Queue] | None = None
        self._goal = None
        self._done: Future | None = None
        self._waiting_first = False
        self._last_tick_s: float | None = None  # ROS time of the last control tick answered (step gate)
        self._waiting_sensors_since: float | None = None
        self._last_feedback = (None, -1)
        self._last_feedback_t = -math.inf
        self._last_publish_t = -math.inf
        self._last_idle_status_t = -math.inf
        self.last_record: CampaignRecord | None = None
        self.last_result: str = ""

        self.create_subscription(Dvl, "dvl/data", self._on_dvl, 20)
        self.create_subscription(FluidPressure, "pressure/fluid_pressure", self._on_pressure, 20)
        self.create_subscription(Imu, "imu/data_raw", self._on_imu, 50)
        self.create_subscription(Range, "ping/altitude", self._on_range, 20)
        self.create_subscription(ThrusterPwm, "thrusters/pulse_width", self._on_pwm, 20)
        self.pub_wrench = self.create_publisher(WrenchStamped, "wrench", 10)
        self.pub_estimate = self.create_publisher(HydroEstimate, "identification/estimates", 10)
        self.pub_status = self.create_publisher(ManeuverStatus, "identification/status", 50)
        self._action = ActionServer(self, RunIdentification, "run_identification", execute_callback=self._execute,
                                    goal_callback=self._on_goal, cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        self._timer = self.create_timer(self.tick_s, self._on_tick)
        log.info(f"identification executive ready: action run_identification, ticks at "
                 f"{1.0 / self.tick_s:g} Hz, estimates at {1.0 / self.publish_period_s:g} Hz")

    def _param(self, name: str, default: Any) -> Any:
        if not self.has_parameter(name):
            self.declare_parameter(name, default)
        return self.get_parameter(name).value

    # ------------------------------------------------------------------ inputs
    def _on_dvl(self, msg: Dvl) -> None:
        self._add(samples_from_dvl(msg))

    def _on_imu(self, msg: Imu) -> None:
        self._add(samples_from_imu(msg, self._mount_t))

    def _on_pressure(self, msg: FluidPressure) -> None:
        self._add([sample_from_pressure(msg)])

    def _on_range(self, msg: Range) -> None:
        self._add([sample_from_range(msg)])

    def _on_pwm(self, msg: ThrusterPwm) -> None:
        w = np.asarray(msg.pulse_width_us, dtype=float)
        if w.size == len(self.config.thrusters.thrusters) and np.all(np.isfinite(w)):
            self._written = w
        self._armed = bool(msg.armed)

    def _add(self, samples: list) -> None:
        for dev, s in samples:
            self._seen.add(dev)
        if self._campaign is not None:
            self._samples.extend(samples)

    # ------------------------------------------------------------------ action
    def _on_goal(self, goal) -> GoalResponse:
        if self._goal is not None:
            self.get_logger().warn("run_identification: a goal is already running; rejected")
            return GoalResponse.REJECT
        problem = self._goal_problem(goal)
        if problem:
            self.get_logger().error(f"run_identification: {problem}; rejected")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    @staticmethod
    def _goal_problem(goal) -> str:
        bad = [d for d in goal.dofs if d not in DOFS]
        if bad:
            return f"unknown DOF(s) {bad}; choose from {', '.join(DOFS)}"
        fr = list(goal.level_fractions)
        if any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fr):
            return f"level_fractions must be in (0, 1], got {fr}"
        return ""

    async def _execute(self, goal_handle):
        goal = goal_handle.request
        dofs = list(goal.dofs) or list(DOFS)
        if not self._armed:
            goal_handle.abort()
            return RunIdentification.Result(success=False, message="ESC output not armed: call esc/set_armed first")
        self._goal = goal_handle
        self._done = Future()
        to_worker: queue.Queue = queue.Queue(maxsize=1)
        to_ros: queue.Queue = queue.Queue(maxsize=1)
        self._link = (to_worker, to_ros)
        t0 = self.get_clock().now().nanoseconds * 1e-9
        plant = RosPlant(self.tick_s, len(self.config.thrusters.thrusters),
                         float(self.config.thrusters.pulse_width_neutral_us), t0)
        self._campaign = RosCampaign(self.config, plant, dofs, int(goal.levels_per_dof) or None,
                                     list(goal.level_fractions) or None, self._link, self.dvl_lock_timeout_s)
        self._samples = []
        self._seen_at_start = set(self._seen)
        self._waiting_sensors_since = t0
        self._last_feedback = (None, -1)
        self.get_logger().info(f"run_identification: {', '.join(dofs)}")
        record, error = await self._done
        self._stop_worker()
        self.last_record = record
        campaign = self._campaign
        self._campaign = None
        self._goal = None
        ok = record is not None and not record.aborted and not error
        message = error or ("" if record is None else record.abort_reason) or "campaign complete"
        self.last_result = message
        self._publish_status(ManeuverStatus.PHASE_DONE if ok else ManeuverStatus.PHASE_ABORTED, campaign,
                             message)
        result = RunIdentification.Result(success=ok, message=message)
        if campaign is not None:
            stamp = self.get_clock().now().to_msg()
            result.estimates = [hydro_estimate(d, est, stamp) for d, est in campaign.online.items()
                                if est.rls.n_samples > 0]
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif ok:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        self.get_logger().info(f"run_identification finished: {message}")
        return result

    def _start_worker(self) -> None:
        campaign = self._campaign
        self._last_tick_s = None
        to_ros = self._link[1]

        def work() -> None:
            try:
                rec = campaign.run()
                to_ros.put(("done", rec))
            except Exception as exc:  # noqa: BLE001 - reported as the goal's failure, vehicle left neutral
                to_ros.put(("error", f"{type(exc).__name__}: {exc}"))

        self._thread = threading.Thread(target=work, name="identification-executive", daemon=True)
        self._thread.start()
        self._waiting_first = True

    def _stop_worker(self) -> None:
        if self._thread is not None and self._thread.is_alive() and self._link is not None:
            try:
                self._link[0].put_nowait(None)
            except queue.Full:
                pass
            self._thread.join(timeout=5.0)
        self._thread = None

    # ------------------------------------------------------------------ tick
    def _on_tick(self) -> None:
        now = self.get_clock().now()
        t = now.nanoseconds * 1e-9
        c = self._campaign
        if c is None:
            if t - self._last_idle_status_t >= 1.0:
                self._last_idle_status_t = t
                self._publish_status(ManeuverStatus.PHASE_IDLE, None, "idle")
            return
        if self._thread is None:
            needed = {"ms5837", "dvl75", "dvl75_attitude", "icm20948_gyro", "ping1d"}
            cancel = self._goal is not None and self._goal.is_cancel_requested
            if cancel or t - self._waiting_sensors_since > 30.0:
                self._finish(None, "cancelled" if cancel else f"sensors not publishing: {sorted(needed - self._seen)}")
                return
            if needed <= self._seen:
                c.plant.t_s = t
                self._samples = []
                self._start_worker()
            else:
                self._publish_status(ManeuverStatus.PHASE_POSITIONING, c, "waiting for the sensors")
                return
        to_worker, to_ros = self._link
        if self._waiting_first:
            self._waiting_first = False
        else:
            cancel = self._goal is not None and self._goal.is_cancel_requested
            samples, self._samples = self._samples, []
            to_worker.put(TickInput(t, samples, self._written, self._armed, cancel))
        try:
            kind, payload = to_ros.get(timeout=self.tick_timeout_s)
        except queue.Empty:
            self._finish(None, f"executive did not answer within {self.tick_timeout_s:g} s")
            return
        if kind == "wrench":
            self._last_tick_s = t
            self._publish_wrench(payload, now)
            self._publish_progress(c, t)
        elif kind == "done":
            self._finish(payload, "")
        else:
            self._finish(None, str(payload))

    def clock_may_advance(self, t_s: float) -> bool:
        """Step gate for a simulator in the same process (:meth:`~hindrax_ident.sim.node.SimulatorNode.add_step_gate`):
        False while a manoeuvre runs and the control tick due at simulated time ``t_s`` (s) has not run yet, so
        the simulation never runs ahead of the control loop."""
        if self._campaign is None or self._thread is None or self._last_tick_s is None:
            return True
        return t_s + 1e-6 < self._last_tick_s + self.tick_s

    def _finish(self, record, error: str) -> None:
        self._publish_wrench(np.zeros(6), self.get_clock().now())  # neutral thrust
        self._thread = None if (self._thread is None or not self._thread.is_alive()) else self._thread
        if self._done is not None and not self._done.done():
            self._done.set_result((record, error))

    def _publish_wrench(self, w_frd: np.ndarray, now) -> None:
        w = frames.wrench_frd_to_flu(np.asarray(w_frd, dtype=float))
        m = WrenchStamped()
        m.header.stamp = now.to_msg()
        m.header.frame_id = "base_link"
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(x) for x in w[:3])
        m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(x) for x in w[3:])
        self.pub_wrench.publish(m)

    def _progress_fraction(self, c: RosCampaign) -> float:
        n = max(1, len(c.dofs))
        done = len(c.windows)
        dof, i, count, _ = c.level_position()
        inner = (i + 0.5) / count if (dof and count and dof not in c.windows) else 0.0
        return float(min(1.0, (done + inner) / n))

    def _publish_progress(self, c: RosCampaign, t: float) -> None:
        dof, i, count, cmd = c.level_position()
        if c._run >= 0:
            phase = ManeuverStatus.PHASE_RUNNING
        elif dof:
            phase = ManeuverStatus.PHASE_RETURNING
        else:
            phase = ManeuverStatus.PHASE_POSITIONING
        msg = STILL_MESSAGE if c.state.collecting_gyro_bias else c.message
        self._publish_status(phase, c, msg)
        key = (dof, i, math.copysign(1.0, cmd) if cmd else 0.0)
        if self._goal is not None and (key != self._last_feedback or t - self._last_feedback_t >= 1.0):
            self._last_feedback, self._last_feedback_t = key, t
            fb = RunIdentification.Feedback(dof=dof, level_index=i, level_count=count, level_command=cmd,
                                            progress=self._progress_fraction(c))
            self._goal.publish_feedback(fb)
        if t - self._last_publish_t >= self.publish_period_s - 1e-9:
            self._last_publish_t = t
            stamp = self.get_clock().now().to_msg()
            for d, est in c.online.items():
                if est.rls.n_samples > 0:
                    self.pub_estimate.publish(hydro_estimate(d, est, stamp))

    def _publish_status(self, phase: int, c: RosCampaign | None, message: str) -> None:
        m = ManeuverStatus(phase=phase, message=message)
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "base_link"
        if c is not None:
            dof, i, count, cmd = c.level_position()
            m.dof, m.level_index, m.level_count, m.level_command = dof, i, count, cmd
            m.progress = 1.0 if phase == ManeuverStatus.PHASE_DONE else self._progress_fraction(c)
        self.pub_status.publish(m)

    def close(self) -> None:
        """Stop a running executive (the graph's shutdown path): zero wrench, worker released."""
        if self._campaign is not None:
            self._publish_wrench(np.zeros(6), self.get_clock().now())
        self._stop_worker()


def main(args: list[str] | None = None) -> int:
    """Run the node alone (SingleThreadedExecutor) until SIGINT/SIGTERM. Returns the exit status."""
    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    status = 0
    try:
        node = IdentificationNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except ConfigError as exc:
        print(f"invalid configuration: {exc}", file=sys.stderr)
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
