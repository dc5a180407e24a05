"""Identification node: the ``run_identification`` action over the identification executive.

A thin rclpy node over :class:`~.executive.Executive` (pure: the dive, positioning, level ladders, holds, pool-box
planning, limits and online Kalman + RLS of [Hindrax-Drag] §4; the same object the in-process campaign
steps on the simulator, :mod:`.campaign`). The node turns the sensor topics into samples (:mod:`..bag_input.signals`),
and at every tick of its control timer (``identification.estimate_rate_hz``, ROS clock) hands the executive the samples
that came in since the last tick and publishes the wrench it returns. Nothing in a callback waits, and no coroutine
runs while a goal does (see "Action execution" below). The node does not know whether the vehicle is simulated: it
sees the same topics from the drivers either way.

The force in the regression is the thrust model of the pulse widths the ESC node actually wrote
(``thrusters/pulse_width``: wire widths, un-reversed and un-trimmed, through the allocation's cubic curves,
[Hindrax-Drag] eq. 1, the first-order lag ``thrusters.time_constant_s`` and the thrust allocation
matrix, [Hindrax-Drag] eq. 9), body FRD.

Run alone: ``python -m hindrax_ident.identification.online.node --ros-args --params-file ros_ws/config/hindrax.yaml``.

Interfaces
----------
Action server ``run_identification`` (hindrax_msgs/action/RunIdentification)
    Goal: ``dofs`` (empty = all six, in SNAME order), ``levels_per_dof`` (0 = ``identification.levels_per_dof``),
    ``level_fractions`` (optional explicit fractions of the DOF's authority, each in (0, 1]), ``calibrate``
    (known-force steps after the dive, before the ladders: ballast, line_pull, tilt_decay, inclining; the known
    forces are the ``calibration.*`` parameters, :func:`~.executive.calibration_forces`,
    :func:`~.executive.inclining_load`), ``calibration_only`` (no
    ladders). Rejected when a goal is running or the goal is invalid (unknown DOF or step, fraction out of
    range, calibration_only without a step). The goal fails, commanding nothing, when the ESC output has not
    reported armed within :data:`ARMED_GRACE_S` of its acceptance (an operator who arms and starts at once is
    not refused while the armed flag is on its way). Feedback
    at every level change, at every operator prompt and once per second: DOF, level index and count, level
    command (N or N m, FRD), progress 0-1, ``prompt`` (see ``identification/continue``). End (done, abort or cancel):
    the node publishes a zero wrench every tick until the ESC node reports neutral widths (zero thrust on every
    thruster, or disarmed) or ``stop_timeout_s`` has passed, and only then ends the action; afterwards it publishes no
    wrench (the allocation's wrench timeout keeps the thrusters neutral). Result: success, message (abort
    reason, ``cancelled``; after calibration steps also the thrust scales measured), the final online estimate of
    every DOF.
Service ``identification/continue`` (std_srvs/Trigger)
    The operator's "done": while a calibration step waits (the feedback ``prompt`` and the status ``message``
    read ``[<what>] <instruction>, then call continue``, e.g. ``[attach_ballast] calibration: attach the ballast
    (8.56 N in water), then call continue``), the step goes on (success True, message ``continuing: <what>``);
    otherwise success False with the reason (no goal, or nothing awaited). Nothing waits in the callback.
Subscribes
    ``dvl/data`` (hindrax_msgs/Dvl: velocity FLU and attitude ENU), ``pressure/fluid_pressure``
    (FluidPressure, Pa), ``imu/data_raw`` (Imu, FLU), ``ping/altitude`` (Range),
    ``thrusters/pulse_width`` (ThrusterPwm, widths written by the ESC node and the armed flag).
Publishes
    ``wrench`` (geometry_msgs/WrenchStamped, base_link FLU) at ``identification.estimate_rate_hz`` while a
    goal runs; ``identification/estimates`` (HydroEstimate, method ``rls``, one per DOF with data) at
    ``identification.publish_rate_hz`` (>= 1 Hz); ``identification/status`` (ManeuverStatus) while a goal
    runs at once when the phase, DOF, level or message (current step) changes and otherwise at
    :data:`STATUS_PERIOD_S` (2 Hz: the progress of a level), once at its end (DONE or ABORTED
    with the reason) and at 1 Hz when idle; ``supervisor/abort`` (std_msgs/String, data = the reason) once when a
    goal aborts on a limit, DVL lock loss or an error (not on a cancel or a disarmed ESC output): the safety
    supervisor (:mod:`hindrax_drivers.supervisor.node`) then disarms the ESC and stays tripped until reset;
    ``identification/calibration`` (diagnostic_msgs/DiagnosticArray, reliable, transient local, depth 1) when a
    calibration step ends (ballast, line pull surge / sway, inclining roll / pitch, tilt_decay roll / pitch): every
    step result since the node started, one DiagnosticStatus each, KeyValue pairs named with their units
    (:mod:`..bag_input.calibration_topic`); the recorder stores it with the campaign and ``hindrax ident bag`` applies
    it.
Parameters
    The vehicle configuration; node-specific ``dvl_lock_timeout_s`` (default 3.0): a surge or sway run
    aborts when the DVL had no valid velocity for this long (docs/architecture.md §8); ``sensor_timeout_s``
    (default 30): a goal fails when a sensor has not published this long after it was accepted;
    ``stop_timeout_s`` (default 2.0): longest zero-wrench hold at the end while waiting for neutral widths.
Action execution
    An accepted goal is not executed when it is accepted: ``handle_accepted_callback`` sets up the campaign and
    returns, the control timer runs it, and when it ends (done, abort, cancel, after the neutral hold) the timer
    calls the goal handle's ``execute`` with a plain execute callback that returns the result at once. So the
    goal's action status (action_msgs/GoalStatus) reads ACCEPTED while the campaign runs (CANCELING after a
    cancel request), then EXECUTING and its end state together; the feedback, the result and cancelling work as
    for any goal. Why: an execute callback that is a coroutine awaiting the end stays a pending task for the whole
    campaign, and rclpy 7.1's EventsExecutor, which every node process spins, re-queues a pending task at once, a
    busy loop (72 % of a core in the launch layout while a goal ran; docs/architecture.md §11.5). With the
    SingleThreadedExecutor the same coroutine costs about 20 % of a core; without it the node costs about 5 % idle
    and 10-13 % running a goal (docs/architecture.md §10.1).
Inputs
    The five inputs (about 130-180 messages/s) are subscription callbacks on the node's executor, whatever the clock
    (the vehicle, the virtual pool, ``hindrax run`` and the tests take the same path); the samples keep their header
    stamps and the executive orders them by stamp at its tick.
Safety (docs/architecture.md §8)
    Limits of the executive (depth, altitude, roll, pitch, pool box) plus DVL lock and ESC disarm abort the
    goal; the vehicle is brought to neutral thrust at the end, on abort and on cancel, before the action ends.
    Aborts other than a cancel or a disarm also trip the safety supervisor (``supervisor/abort``, above).
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure, Imu, Range
from std_msgs.msg import String
from std_srvs.srv import Trigger

from hindrax_drivers import frames
from hindrax_drivers.lean_cdr import wrench_stamped_cdr
from hindrax_drivers.config import DOFS, ConfigError, ConfigIssue, VehicleConfig
from hindrax_drivers.icm20948.mounting import mounting_rotation
from hindrax_drivers.node_common import load_node_config, run_node
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, HydroEstimate, ManeuverStatus, ThrusterPwm

from ..bag_input import calibration_topic
from ..bag_input.campaign_record import CampaignRecord
from ..bag_input.signals import (
    sample_from_pressure,
    sample_from_range,
    samples_from_dvl,
    samples_from_imu,
    thrust_of_written_widths,
)
from ..fit.dof_model import parameter_units
from .executive import (
    CALIBRATION_STEPS,
    Executive,
    ExecutiveStatus,
    TickInput,
    calibration_forces,
    inclining_load,
    ordered_samples,
)

__all__ = ["IdentificationNode", "hydro_estimate", "main"]

#: sensors that must have published before a goal starts moving the vehicle
NEEDED_SENSORS = frozenset({"ms5837", "dvl75", "dvl75_attitude", "icm20948_gyro", "ping1d"})

#: abort reasons not sent to the safety supervisor (the executive's words): an operator's cancel, and a disarmed
#: ESC output (the thrusters are already stopped, possibly by the supervisor itself)
NOT_SUPERVISOR_ABORTS = frozenset({"cancelled", "ESC output disarmed"})
#: period of ``identification/status`` while a goal runs and nothing changes, s (2 Hz: the progress on a topside
#: display; every change of phase, DOF, level or message goes out at once, so a bag's zero-order hold of the status
#: loses nothing; 10 Hz before, docs/architecture.md §10.1)
STATUS_PERIOD_S = 0.5
#: how long an accepted goal waits for the ESC to report armed on ``thrusters/pulse_width`` (published on every
#: write and at least every 0.1 s, ``hindrax_drivers.pca9685.node``) before it fails, s (ROS time)
ARMED_GRACE_S = 0.5
#: the result message of a goal whose ESC output did not report armed
NOT_ARMED = "ESC output not armed: call esc/set_armed first"
#: a sensor sample stamped further than this after the node's clock is impossible and left out (s): the drivers stamp
#: with their receive time or a device time converted to the ROS clock, both at or before the tick that takes them
FUTURE_STAMP_TOLERANCE_S = 1.0
#: a sample stamped further than this before the previous tick is stale and left out (s): sensor latencies through the
#: graph (a conversion start, a report's time of validity) are tens to hundreds of milliseconds
STALE_STAMP_TOLERANCE_S = 2.0

_PHASES = {"positioning": ManeuverStatus.PHASE_POSITIONING, "running": ManeuverStatus.PHASE_RUNNING,
           "returning": ManeuverStatus.PHASE_RETURNING, "done": ManeuverStatus.PHASE_DONE,
           "aborted": ManeuverStatus.PHASE_ABORTED}


def hydro_estimate(dof: str, estimator, stamp, method: str = "rls") -> HydroEstimate:
    """HydroEstimate of one :class:`~.estimators.OnlineDofEstimator` (RLS value, std, covariance, excitation).

    ``std`` is :meth:`~.estimators.OnlineDofEstimator.published_std`: a number only where the scenario suite
    showed the online value's interval can cover the truth (converged damping of surge, sway, heave and yaw,
    widened by the declared thrust uncertainty, :func:`~..assessment.verdicts.rls_published_std`); -1 means "not
    converged or not trusted" (the message's float64 std has no NaN convention). ``covariance`` stays the raw RLS one.
    """
    rls = estimator.rls
    units = parameter_units(dof)
    msg = HydroEstimate(dof=dof, method=method)
    msg.header.stamp = stamp
    msg.header.frame_id = "base_link"
    msg.parameter_names = list(estimator.names)
    msg.parameter_units = [units[n] for n in estimator.names]
    msg.values = [float(v) for v in rls.theta]
    msg.std = [float(s) if math.isfinite(s) else -1.0 for s in estimator.published_std()]
    cov = np.asarray(rls.covariance, dtype=float)
    msg.covariance = [float(c) if math.isfinite(c) else 0.0 for c in cov.ravel()]
    msg.sample_count = int(rls.n_samples)
    ex = float(rls.excitation_normalised)
    msg.excitation = ex if math.isfinite(ex) else 0.0
    msg.converged = estimator.converged_at_s is not None
    return msg


@dataclass
class _GoalRun:
    """One accepted goal: its handle, executive and end state."""

    handle: Any
    executive: Executive
    accepted_s: float
    written_us: np.ndarray
    stop_since_s: float | None = None
    ended: bool = False
    pwm_count_at_stop: int = 0
    error: str = ""
    record: CampaignRecord | None = None
    status: ExecutiveStatus | None = None
    last_feedback: tuple = field(default_factory=lambda: (None, -1))
    last_feedback_s: float = -math.inf
    calibration_results: int = 0  # step results of this goal already published on identification/calibration


class IdentificationNode(Node):
    """The identification executive as a ROS node (module docstring).

    config: a VehicleConfig (default: from the node's parameters,
    :func:`~hindrax_drivers.node_common.load_node_config`). Other keyword arguments go to ``Node``. Raises
    :class:`ConfigError` for an invalid configuration.
    """

    def __init__(self, *, config: VehicleConfig | None = None, node_name: str = "identification",
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        log = self.get_logger()
        self.config = config if config is not None else load_node_config(self)
        ident = self.config.identification
        self.tick_s = 1.0 / float(ident.estimate_rate_hz)
        self.publish_period_s = 1.0 / max(1.0, float(ident.publish_rate_hz))
        self.dvl_lock_timeout_s = self._param("dvl_lock_timeout_s", 3.0, "longest time without a valid DVL velocity "
                                              "during a surge or sway run before the goal aborts, s")
        self.sensor_timeout_s = self._param("sensor_timeout_s", 30.0, "longest wait for every sensor to publish "
                                            "after a goal is accepted, s")
        self.stop_timeout_s = self._param("stop_timeout_s", 2.0, "longest zero-wrench hold at the end of a goal "
                                          "while waiting for the ESC to report neutral widths, s")
        self._mount_t = mounting_rotation(self.config.sensors.icm20948.mounting_rpy_rad).T
        self._n_thrusters = len(self.config.thrusters.thrusters)
        self._neutral_us = float(self.config.thrusters.pulse_width_neutral_us)
        self._samples: list = []
        self._seen: set[str] = set()
        self._written: np.ndarray | None = None
        self._pwm_count = 0
        #: sensor samples left out since start for a stamp after the node's clock or long before it
        #: (``FUTURE_STAMP_TOLERANCE_S``, ``STALE_STAMP_TOLERANCE_S``)
        self.samples_dropped = 0
        self._armed = False
        self._run: _GoalRun | None = None
        self._ended: dict[bytes, _GoalRun] = {}  # goal UUID -> ended run whose result is being delivered
        self._last_tick_s: float | None = None  # ROS time of the last control tick of a goal (step gate)
        self._last_publish_t = -math.inf
        self._last_idle_status_t = -math.inf
        self._last_status: tuple[float, tuple] = (-math.inf, ())  # (ROS time, key) of the last running status
        self.last_record: CampaignRecord | None = None
        self.last_result: str = ""
        #: step results published on identification/calibration: name -> (name, message, [(key, value)])
        self.calibration_results: dict[str, tuple] = {}

        # no QoS event handlers (rclpy's default incompatible-QoS warning handler of each is visited in Python on
        # every executor spin); a sensor that does not arrive fails the goal (sensor_timeout_s, DVL lock)
        sub_ev = {"event_callbacks": SubscriptionEventCallbacks(use_default_callbacks=False)}
        pub_ev = {"event_callbacks": PublisherEventCallbacks(use_default_callbacks=False)}
        # inputs (type, topic, handler, QoS depth): the depths hold what arrives in 0.4-2 s, many ticks
        inputs = ((Dvl, "dvl/data", self._on_dvl, 20),
                  (FluidPressure, "pressure/fluid_pressure", self._on_pressure, 20),
                  (Imu, "imu/data_raw", self._on_imu, 50), (Range, "ping/altitude", self._on_range, 20),
                  (ThrusterPwm, "thrusters/pulse_width", self._on_pwm, 20))
        for msg_type, topic, handler, depth in inputs:  # callbacks (module docstring, "Inputs")
            self.create_subscription(msg_type, topic, handler, depth, **sub_ev)
        self.pub_wrench = self.create_publisher(WrenchStamped, "wrench", 10, **pub_ev)
        self.pub_estimate = self.create_publisher(HydroEstimate, "identification/estimates", 10, **pub_ev)
        self.pub_status = self.create_publisher(ManeuverStatus, "identification/status", 50, **pub_ev)
        self.pub_abort = self.create_publisher(String, "supervisor/abort", 10, **pub_ev)
        # transient local: a recorder or tool that subscribes after the step still gets every result
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_calibration = self.create_publisher(DiagnosticArray, calibration_topic.TOPIC, latched, **pub_ev)
        self._action = ActionServer(self, RunIdentification, "run_identification", execute_callback=self._goal_result,
                                    goal_callback=self._on_goal, handle_accepted_callback=self._on_accepted,
                                    cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        self.create_service(Trigger, "identification/continue", self._on_continue)
        self._timer = self.create_timer(self.tick_s, self._on_tick)
        log.info(f"identification executive ready: action run_identification, ticks at "
                 f"{1.0 / self.tick_s:g} Hz, estimates at {1.0 / self.publish_period_s:g} Hz")

    def _param(self, name: str, default: float, description: str) -> float:
        """A read-only node parameter (> 0, s). Raises :class:`ConfigError` (one line) for another value."""
        if not self.has_parameter(name):
            self.declare_parameter(name, default, ParameterDescriptor(
                description=description, read_only=True, additional_constraints="allowed a number > 0"))
        value = self.get_parameter(name).value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            issue = ConfigIssue(name, value, "a number > 0")
            self.get_logger().fatal(f"invalid configuration: {issue.line()}")
            raise ConfigError([issue], f"parameters of {self.get_name()}")
        return float(value)

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
        if w.size == self._n_thrusters and np.all(np.isfinite(w)):
            self._written = w
        self._armed = bool(msg.armed)
        self._pwm_count += 1

    def _add(self, samples: list) -> None:
        for dev, _s in samples:
            self._seen.add(dev)
        if self._run is not None:
            self._samples.extend(samples)

    # ------------------------------------------------------------------ action
    def _on_goal(self, goal) -> GoalResponse:
        if self._run is not None:
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
        bad = [c for c in goal.calibrate if c not in CALIBRATION_STEPS]
        if bad:
            return f"unknown calibration step(s) {bad}; choose from {', '.join(CALIBRATION_STEPS)}"
        if goal.calibration_only and not goal.calibrate:
            return "calibration_only without a calibration step"
        fr = list(goal.level_fractions)
        if any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fr):
            return f"level_fractions must be in (0, 1], got {fr}"
        return ""

    def _on_accepted(self, goal_handle) -> None:
        """Accepted goal: set it up and return; the control timer runs it (once the ESC reports armed, within
        :data:`ARMED_GRACE_S`) and ends it (:meth:`_end_goal`).

        The goal is not executed here: its action state stays ACCEPTED while the campaign runs and becomes
        EXECUTING, then SUCCEEDED, ABORTED or CANCELED when it ends (module docstring, "Action execution")."""
        goal = goal_handle.request
        dofs = [] if goal.calibration_only else (list(goal.dofs) or list(DOFS))
        calibrate = list(goal.calibrate)
        w_ballast, f_line = calibration_forces(self.config) if calibrate else (0.0, 0.0)
        incl = inclining_load(self.config) if "inclining" in calibrate else (0.0, 0.0)
        executive = Executive(self.config, dofs, int(goal.levels_per_dof) or None, tick_s=self.tick_s,
                              fractions=list(goal.level_fractions) or None,
                              dvl_lock_timeout_s=self.dvl_lock_timeout_s, calibrate=calibrate,
                              ballast_weight_in_water_n=w_ballast, line_pull_n=f_line, inclining_load_n_m=incl)
        run = _GoalRun(goal_handle, executive, self._now_s(), np.full(self._n_thrusters, self._neutral_us))
        self._samples = []
        self._run = run
        self.get_logger().info(f"run_identification: {', '.join(dofs) or 'no ladders'}"
                               + (f"; calibration {', '.join(calibrate)}" if calibrate else ""))

    def _end_goal(self, run: _GoalRun) -> None:
        """The goal's end, from the control timer: the result is computed and the goal reaches its terminal state
        through ``execute`` with :meth:`_goal_result`, a plain function that returns at once."""
        run.ended = True
        if self._run is run:
            self._run = None
            self._last_tick_s = None
        self._ended[bytes(run.handle.goal_id.uuid)] = run
        run.handle.execute(self._goal_result)

    def _goal_result(self, goal_handle) -> RunIdentification.Result:
        """Execute callback (plain, returns at once): the ended goal's result and terminal state."""
        run = self._ended.pop(bytes(goal_handle.goal_id.uuid))
        executive = run.executive
        self.last_record = run.record
        ok = run.record is not None and not run.record.aborted and not run.error
        message = run.error or ("" if run.record is None else run.record.abort_reason) or "campaign complete"
        if run.record is not None and run.record.calibration:  # the thrust scales measured, for the operator
            message += "; thrust scale " + ", ".join(f"{k} {v['value']:.4f} +- {v['std']:.4f}"
                                                     for k, v in run.record.calibration.items())
        self.last_result = message
        result = RunIdentification.Result(success=ok, message=message)
        if executive.started:
            stamp = self.get_clock().now().to_msg()
            result.estimates = [hydro_estimate(d, est, stamp) for d, est in executive.online.items()
                                if est.rls.n_samples > 0]
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif ok:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        self.get_logger().info(f"run_identification finished: {message}")
        return result

    def _on_continue(self, _request, response):
        """``identification/continue``: resume the calibration step waiting for the operator (module docstring)."""
        run = self._run
        ex = None if run is None else run.executive
        if ex is None or run.ended or run.stop_since_s is not None:
            response.success, response.message = False, "no identification goal is running"
        elif not ex.awaiting:
            response.success, response.message = False, "nothing awaits the operator (no calibration step waits)"
        else:
            what = ex.awaiting
            response.success = ex.operator_continue()
            response.message = f"continuing: {what}"
            self.get_logger().info(f"identification/continue: {what}")
        return response

    @staticmethod
    def operator_prompt(ex: Executive) -> str:
        """The operator prompt of ``ex`` as sent in feedback and status: ``[<awaiting>] <prompt>``, "" when nothing
        waits."""
        return f"[{ex.awaiting}] {ex.prompt}" if ex.awaiting else ""

    # ------------------------------------------------------------------ control tick
    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_tick(self) -> None:
        now = self.get_clock().now()
        t = now.nanoseconds * 1e-9
        run = self._run
        if run is None:
            if t - self._last_idle_status_t >= 1.0:
                self._last_idle_status_t = t
                self._publish_status(ManeuverStatus.PHASE_IDLE, None, "idle")
            return
        if run.ended:
            return
        if run.stop_since_s is not None:
            self._hold_neutral(run, t, now)
            return
        ex = run.executive
        cancel = run.handle.is_cancel_requested
        if not ex.started:
            if not self._armed and not cancel:  # nothing commanded yet: the goal ends without a neutral hold
                if t - run.accepted_s > ARMED_GRACE_S:
                    run.error = NOT_ARMED
                    self._publish_status(ManeuverStatus.PHASE_ABORTED, None, NOT_ARMED)
                    self._end_goal(run)
                else:
                    self._publish_status_throttled(t, ManeuverStatus.PHASE_POSITIONING, None,
                                                   "waiting for the ESC output to report armed")
                return
            if cancel or t - run.accepted_s > self.sensor_timeout_s:
                self._stop(run, t, now, "cancelled" if cancel
                           else f"sensors not publishing: {sorted(NEEDED_SENSORS - self._seen)}")
                return
            if not NEEDED_SENSORS <= self._seen:
                self._publish_status_throttled(t, ManeuverStatus.PHASE_POSITIONING, None, "waiting for the sensors")
                return
            self._samples = []
            w = ex.start(t)
        else:
            samples, self._samples = self._samples, []
            previous = ex.t_s
            valid = ordered_samples(samples, previous, t + FUTURE_STAMP_TOLERANCE_S,
                                    previous - STALE_STAMP_TOLERANCE_S)
            if len(valid) < len(samples):
                self.samples_dropped += len(samples) - len(valid)
                self.get_logger().warn(
                    f"{self.samples_dropped} sensor samples left out, stamped more than {FUTURE_STAMP_TOLERANCE_S} s "
                    f"after or {STALE_STAMP_TOLERANCE_S} s before this node's clock ({t:.3f} s): a publisher on "
                    "another clock?", throttle_duration_sec=5.0)
            w = ex.step(TickInput(t, max(0.0, t - previous), valid, self._armed, cancel))
            if self._written is not None:
                run.written_us = self._written
        self._last_tick_s = t
        self._publish_calibration(run)
        if w is None:
            self._stop(run, t, now, "")
            return
        ex.command(thrust_of_written_widths(self.config, ex.curve, run.written_us))
        self._publish_wrench(w, now)
        self._publish_progress(run, t)

    def _publish_calibration(self, run: _GoalRun) -> None:
        """``identification/calibration`` when the executive has a step result it had not at the last call (a
        calibration step ended): all results since the node started, the new ones replacing older ones of the same
        name (module docstring)."""
        ex = run.executive
        n = len(ex.calibration) + len(ex.inclining) + len(ex.decays)
        if n == run.calibration_results:
            return
        run.calibration_results = n
        for item in calibration_topic.statuses(ex.calibration, ex.inclining, ex.decays):
            self.calibration_results[item[0]] = item
        self.pub_calibration.publish(calibration_topic.calibration_array(
            list(self.calibration_results.values()), self.get_clock().now().to_msg()))
        self.get_logger().info("identification/calibration: " + "; ".join(
            m for _n, m, _kv in self.calibration_results.values()))

    def _stop(self, run: _GoalRun, t: float, now, error: str) -> None:
        """End of the goal: record, final status, zero wrench; the action ends once the thrusters are neutral."""
        run.error = error
        run.stop_since_s = t
        run.pwm_count_at_stop = self._pwm_count
        reason = error
        if run.executive.started:
            run.record = run.executive.record()
            st = run.executive.status()
            phase = ManeuverStatus.PHASE_ABORTED if (error or st.phase == "aborted") else ManeuverStatus.PHASE_DONE
            self._publish_status(phase, st, error or st.message)
            reason = error or (run.record.abort_reason if run.record.aborted else "")
        else:
            self._publish_status(ManeuverStatus.PHASE_ABORTED, None, error)
        if reason and reason not in NOT_SUPERVISOR_ABORTS:
            self.get_logger().error(f"run_identification aborted: {reason}; tripping the safety supervisor")
            self.pub_abort.publish(String(data=reason))
        self._publish_wrench(np.zeros(6), now)
        self._hold_neutral(run, t, now)

    def _hold_neutral(self, run: _GoalRun, t: float, now) -> None:
        """Zero wrench at every tick until the ESC node reported, after the stop, neutral widths (or disarmed), or
        ``stop_timeout_s``; then complete the goal."""
        self._last_tick_s = t
        neutral = False
        if self._pwm_count > run.pwm_count_at_stop:
            if not self._armed:
                neutral = True
            elif self._written is not None:
                f = thrust_of_written_widths(self.config, run.executive.curve, self._written)
                neutral = bool(np.all(np.abs(f) < 1e-9))
        if neutral or t - run.stop_since_s >= self.stop_timeout_s - 1e-9:
            if not neutral:
                self.get_logger().warn(f"run_identification: thrusters not reported neutral within "
                                       f"{self.stop_timeout_s:g} s of the stop")
            self._end_goal(run)
            return
        if t > run.stop_since_s:
            self._publish_wrench(np.zeros(6), now)

    def clock_may_advance(self, t_s: float) -> bool:
        """Step gate for a simulator in the same process (:meth:`~hindrax_ident.sim.node.SimulatorNode.add_step_gate`):
        False while a goal's control ticks run (manoeuvre and the neutral hold at its end) and the tick due at
        simulated time ``t_s`` (s) has not run yet, so the simulation never runs ahead of the control loop."""
        if self._run is None or self._last_tick_s is None:
            return True
        return t_s + 1e-6 < self._last_tick_s + self.tick_s

    def _publish_wrench(self, w_frd: np.ndarray, now) -> None:
        # serialised by rosbags and published as bytes: the 50 Hz publish without rclpy's object conversion
        # (hindrax_drivers.lean_cdr, the measured gain)
        w = frames.wrench_frd_to_flu(np.asarray(w_frd, dtype=float))
        self.pub_wrench.publish(wrench_stamped_cdr(now.nanoseconds, "base_link", w))

    def _publish_progress(self, run: _GoalRun, t: float) -> None:
        ex = run.executive
        st = ex.status()
        prompt = self.operator_prompt(ex)
        self._publish_status_throttled(t, _PHASES[st.phase], st, prompt or st.message)
        key = (st.dof, st.level_index, math.copysign(1.0, st.level_command) if st.level_command else 0.0, prompt)
        if key != run.last_feedback or t - run.last_feedback_s >= 1.0:
            if prompt and prompt != run.last_feedback[-1]:
                self.get_logger().info(f"operator: {prompt}")
            run.last_feedback, run.last_feedback_s = key, t
            run.handle.publish_feedback(RunIdentification.Feedback(
                dof=st.dof, level_index=st.level_index, level_count=st.level_count, level_command=st.level_command,
                progress=st.progress, prompt=prompt))
        if t - self._last_publish_t >= self.publish_period_s - 1e-9:
            self._last_publish_t = t
            stamp = self.get_clock().now().to_msg()
            for d, est in ex.online.items():
                if est.rls.n_samples > 0:
                    self.pub_estimate.publish(hydro_estimate(d, est, stamp))

    def _publish_status_throttled(self, t: float, phase: int, st: ExecutiveStatus | None, message: str) -> None:
        """The running status at ROS time ``t`` (s): at once when phase, DOF, level or message changed, else at
        most every :data:`STATUS_PERIOD_S` (the status is a step signal: a bag's zero-order hold of it,
        :mod:`..bag_input.from_bag`, sees every change at its time)."""
        key = (phase, message) if st is None else (phase, message, st.dof, st.level_index, st.level_command)
        last_t, last_key = self._last_status
        if key == last_key and t - last_t < STATUS_PERIOD_S - 1e-9:
            return
        self._last_status = (t, key)
        self._publish_status(phase, st, message)

    def _publish_status(self, phase: int, st: ExecutiveStatus | None, message: str) -> None:
        m = ManeuverStatus(phase=phase, message=message)
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "base_link"
        if st is not None:
            m.dof, m.level_index, m.level_count, m.level_command = st.dof, st.level_index, st.level_count, \
                st.level_command
            m.progress = 1.0 if phase == ManeuverStatus.PHASE_DONE else st.progress
        self.pub_status.publish(m)

    def close(self) -> None:
        """The graph's shutdown path: a running goal gets a zero wrench and ends ("node shutting down")."""
        run = self._run
        if run is not None and not run.ended:
            self._publish_wrench(np.zeros(6), self.get_clock().now())
            run.error = run.error or "node shutting down"
            if run.record is None and run.executive.started:
                run.record = run.executive.record()
            if self.context.ok():
                self._end_goal(run)
            else:  # SIGINT/SIGTERM already shut the context down: no result can be delivered any more
                run.ended = True


def main(args: list[str] | None = None) -> int:
    """Run the node alone until SIGINT/SIGTERM (:func:`hindrax_drivers.node_common.run_node`: a running goal is
    ended by :meth:`IdentificationNode.close`). Returns the exit status (1 on an invalid configuration).

    The process spins the EventsExecutor like every node process (:mod:`hindrax_drivers.ros_process`): the action
    runs no coroutine (module docstring, "Action execution")."""
    return run_node(IdentificationNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
