"""Identification node: the ``run_identification`` action over the identification executive.

A thin rclpy node over two pure objects: :class:`~.core.IdentificationCore` (goal checks, the goal's life from
acceptance to the end of its neutral hold, what each tick publishes; table-tested in
``test/test_identification_core.py``) and the :class:`~.executive.Executive` it drives (the dive, positioning, level
ladders, holds, pool-box planning, limits and online Kalman + RLS of [Hindrax-Drag] §4; the same object the in-process
campaign steps on the simulator, :mod:`.campaign`). The node turns the sensor topics into samples
(:mod:`...vehicle.signals`) for the core, and at every tick of its control timer (``identification.estimate_rate_hz``,
ROS clock) turns the core's events into messages (wrench, status, feedback, estimates, calibration results, supervisor
abort, the goal's result). Nothing in a callback waits, and no coroutine runs while a goal does (see "Action execution"
below). The node does not know whether the vehicle is simulated: it sees the same topics from the drivers either way.

The force in the regression is the thrust model of the pulse widths the ESC node actually wrote
(``thrusters/pulse_width``: wire widths, un-reversed and un-trimmed, through the allocation's cubic curves,
[Hindrax-Drag] eq. 1, the first-order lag ``thrusters.time_constant_s`` and the thrust allocation
matrix, [Hindrax-Drag] eq. 9), body FRD.

Run alone: ``python -m hindrax_onboard.identification.online.node --ros-args --params-file ros_ws/config/hindrax.yaml``.

Interfaces
----------
Action server ``run_identification`` (hindrax_msgs/action/RunIdentification)
    Goal: ``dofs`` (empty = all six, in SNAME order), ``levels_per_dof`` (0 =
    ``identification.levels_per_dof``), ``level_fractions`` (optional explicit fractions of the
    DOF's authority, each in (0, 1]), ``calibrate`` (known-force steps after the dive, before the
    ladders: ballast, line_pull, tilt_decay, inclining; the known forces are the ``calibration.*``
    parameters, :func:`~.executive.calibration_forces`, :func:`~.executive.inclining_load`),
    ``calibration_only`` (no ladders). Goals, arming, the start, the feedback's timing and the end
    follow the rules of :mod:`.core` ("Goals", "Armed", "Sensors", "Feedback", "Stop"). Feedback:
    DOF, level index and count, level command (N or N m, FRD), progress 0-1, ``prompt`` (see
    ``identification/continue``). After the end the node publishes no wrench (the allocation's
    wrench timeout keeps the thrusters neutral). Result: success, message (abort reason,
    ``cancelled``; after calibration steps also the thrust scales measured), the final online
    estimate of every DOF.
Service ``identification/continue`` (std_srvs/Trigger)
    The operator's "done": while a calibration step waits (the feedback ``prompt`` and the status ``message``
    read ``[<what>] <instruction>, then call continue``, e.g. ``[attach_ballast] calibration: attach the ballast
    (8.56 N in water), then call continue``), the step goes on (success True, message ``continuing: <what>``);
    otherwise success False with the reason (no goal, or nothing awaited). Nothing waits in the callback.
Subscribes
    ``dvl/data`` (hindrax_msgs/Dvl: velocity FLU and attitude ENU), ``pressure/fluid_pressure`` (FluidPressure, Pa),
    ``imu/data_raw`` (Imu, FLU), ``ping/altitude`` (Range), ``thrusters/pulse_width`` (ThrusterPwm, widths written by
    the ESC node and the armed flag): only while a goal is accepted or runs (see "Inputs"); ``esc/output_state`` (the
    ESC's armed flag, latched, on change; always); ``supervisor/status`` (its ``disarm_cause``: a stop of the thrust,
    and why, for the result; :mod:`.core`; always).
Publishes
    ``wrench`` (geometry_msgs/WrenchStamped, base_link FLU) at ``identification.command_rate_hz``
    (the control tick is ``identification.estimate_rate_hz``; executive module docstring, "Command
    rate") while a goal runs, every tick during the neutral hold that ends it;
    ``identification/estimates`` (HydroEstimate, method ``rls``, one per DOF with data) at
    ``identification.publish_rate_hz`` (>= 1 Hz); ``identification/status`` (ManeuverStatus,
    :mod:`.core` rule "Status"; DONE or ABORTED with the reason at the end); ``supervisor/abort``
    (std_msgs/String, data = the reason) once when a goal aborts on a limit, DVL lock loss or an
    error (not on a cancel or a disarmed ESC output): the safety supervisor
    (:mod:`hindrax_bringup.supervisor.node`) then disarms the ESC and stays tripped until reset;
    ``identification/calibration`` (diagnostic_msgs/DiagnosticArray, reliable, transient local,
    depth 1) when a calibration step ends (ballast, line pull surge / sway, inclining roll / pitch,
    tilt_decay roll / pitch): every step result since the node started, one DiagnosticStatus each,
    KeyValue pairs named with their units (:mod:`..model.calibration_topic`); the recorder
    stores it with the campaign and ``hindrax ident bag`` applies it.
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
    busy loop (docs/architecture.md §11.5).
Inputs
    The five inputs (about 130-180 messages/s) are subscription callbacks on the node's executor, whatever the clock
    (the vehicle, the virtual pool, ``hindrax run`` and the tests take the same path); the samples keep their header
    stamps and the executive orders them by stamp at its tick. They are subscribed when a goal is accepted (the
    goal waits for their first samples, ``sensor_timeout_s``) and dropped when it ends, and the control timer runs
    only then: without a goal the node takes no sensor message and ticks every :data:`~.core.IDLE_STATUS_PERIOD_S`
    (the idle status), so an idle vehicle pays nothing for identification.
Safety (docs/architecture.md §8)
    Limits of the executive (depth, altitude, roll, pitch, pool box) plus DVL lock and ESC disarm abort the
    goal; the vehicle is brought to neutral thrust at the end, on abort and on cancel, before the action ends.
    Aborts other than a cancel or a disarm also trip the safety supervisor (``supervisor/abort``, above).
"""
from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import FluidPressure, Imu, Range
from std_msgs.msg import String
from std_srvs.srv import Trigger

from hindrax_common.base import frames
from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos, read_esc_state
from hindrax_common.cdr.lean_cdr import wrench_stamped_cdr
from hindrax_common.node_support.liveness import TickGaps
from hindrax_common.config import ConfigError, ConfigIssue, VehicleConfig
from hindrax_drivers.icm20948.mounting import mounting_rotation
from hindrax_common.node_support.node_common import load_node_config, log_at, run_node, sensor_input_qos
from hindrax_common.node_support.vehicle_node import VehicleNode
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, HydroEstimate, ManeuverStatus, ThrusterPwm

from ..model import calibration_topic
from ..model.campaign_record import CampaignRecord
from ...vehicle.signals import sample_from_pressure, sample_from_range, samples_from_dvl, samples_from_imu
from ...vehicle.state import finite_or_zero, finite_or_zeros
from ..model.dof_model import parameter_units
from .core import IDLE_STATUS_PERIOD_S, Event, GoalRun, IdentificationCore, goal_problem
from .executive import ExecutiveStatus, command_ticks

__all__ = ["IdentificationNode", "hydro_estimate", "main"]

def hydro_estimate(dof: str, estimator, stamp, method: str = "rls") -> HydroEstimate:
    """HydroEstimate of one :class:`~.estimators.OnlineDofEstimator` (RLS value, std, covariance, excitation).

    ``std`` is :meth:`~.estimators.OnlineDofEstimator.published_std` (:func:`~..model.dof_model.rls_published_std`),
    -1 where that is NaN ("not converged or not trusted": the message's float64 std has no NaN convention).
    ``covariance`` stays the raw RLS one."""
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
    msg.covariance = finite_or_zeros(cov).ravel().tolist()
    msg.sample_count = int(rls.n_samples)
    msg.excitation = finite_or_zero(rls.excitation_normalised)
    msg.converged = estimator.converged_at_s is not None
    return msg


class IdentificationNode(VehicleNode):
    """The identification executive as a ROS node (module docstring).

    config: a VehicleConfig (default: from the node's parameters,
    :func:`~hindrax_common.node_support.node_common.load_node_config`). Other keyword arguments go to ``Node``. Raises
    :class:`ConfigError` for an invalid configuration."""

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
        #: the goal and tick logic (pure, :mod:`.core`); this node turns its events into messages
        self.core = IdentificationCore(self.config, tick_s=self.tick_s, publish_period_s=self.publish_period_s,
                                       dvl_lock_timeout_s=self.dvl_lock_timeout_s,
                                       sensor_timeout_s=self.sensor_timeout_s, stop_timeout_s=self.stop_timeout_s)
        self._ended: dict[bytes, GoalRun] = {}  # goal UUID -> ended run whose result is being delivered
        self.tick_gaps = TickGaps()  # steady-clock gaps between the control ticks of a goal (core.starved)

        # no QoS event handlers (VehicleNode): a missing sensor fails the goal (timeouts, DVL lock)
        self._inputs: list = []  # the sensor subscriptions, open while a goal is accepted or runs
        # the ESC's armed flag while no goal runs (latched, on change; the goal's pulse_width reports carry it too)
        self.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, self._on_esc_state, esc_state_qos())
        self.create_subscription(DiagnosticStatus, "supervisor/status", lambda m: self.core.on_disarm_cause(
            next((kv.value for kv in m.values if kv.key == "disarm_cause"), "")), 10)
        self.pub_wrench = self.create_publisher(WrenchStamped, "wrench", 10)
        self.pub_estimate = self.create_publisher(HydroEstimate, "identification/estimates", 10)
        self.pub_status = self.create_publisher(ManeuverStatus, "identification/status", 50)
        self.pub_abort = self.create_publisher(String, "supervisor/abort", 10)
        # transient local: a recorder or tool that subscribes after the step still gets every result
        latched = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_calibration = self.create_publisher(DiagnosticArray, calibration_topic.TOPIC, latched)
        self._action = ActionServer(self, RunIdentification, "run_identification", execute_callback=self._goal_result,
                                    goal_callback=self._on_goal, handle_accepted_callback=self._on_accepted,
                                    cancel_callback=lambda _goal: CancelResponse.ACCEPT)
        self.create_service(Trigger, "identification/continue", self._on_continue)
        # one timer runs at a time: the control tick while a goal is accepted or runs, the idle status period else
        self._timer = self.create_timer(self.tick_s, self._on_tick, autostart=False)
        self._idle_timer = self.create_timer(IDLE_STATUS_PERIOD_S, self._on_tick)
        command_hz = 1.0 / (self.tick_s * command_ticks(self.config, self.tick_s))
        log.info(f"identification executive ready: action run_identification, ticks at {1.0 / self.tick_s:g} Hz, "
                 f"wrench at {command_hz:g} Hz, estimates at {1.0 / self.publish_period_s:g} Hz")

    def _param(self, name: str, default: float, description: str) -> float:
        """A read-only node parameter (> 0, s). Raises :class:`ConfigError` (one line) for another value."""
        if not self.has_parameter(name):
            self.declare_parameter(name, default, ParameterDescriptor(
                description=description, read_only=True, additional_constraints="allowed a number > 0"))
        value = self.get_parameter(name).value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            issue = ConfigIssue(name, value, "a number > 0")
            raise ConfigError([issue], f"parameters of {self.get_name()}")
        return float(value)

    @property
    def samples_dropped(self) -> int:
        """Sensor samples left out since start for a stamp after the node's clock or long before it (:mod:`.core`)."""
        return self.core.samples_dropped

    @property
    def last_record(self) -> CampaignRecord | None:
        """The campaign record of the last goal that ended (None before)."""
        return self.core.last_record

    # ------------------------------------------------------------------ inputs
    def _set_active(self, active: bool) -> None:
        """Open the sensor subscriptions and the control tick for a goal (``active``), or close them and tick at
        :data:`~.core.IDLE_STATUS_PERIOD_S` when it has ended (module docstring, "Inputs"). Opening forgets the
        previous goal's sensors (:meth:`~.core.IdentificationCore.forget_inputs`): the goal waits for fresh ones."""
        if active == bool(self._inputs):
            return
        if active:
            self.core.forget_inputs()
            self.tick_gaps = TickGaps()  # the control ticks' gaps, from now (core.starved)
            # (type, topic, handler, QoS depth): the depths hold what arrives in 0.4-2 s, many ticks
            # best effort (sensor_input_qos): the writers then run no reliability protocol for this reader
            add = self.core.add_samples
            self._inputs = [self.create_subscription(msg_type, topic, handler, sensor_input_qos(depth))
                            for msg_type, topic, handler, depth in (
                                (Dvl, "dvl/data", lambda m: add(samples_from_dvl(m)), 20),
                                (FluidPressure, "pressure/fluid_pressure",
                                 lambda m: add([sample_from_pressure(m)]), 20),
                                (Imu, "imu/data_raw", lambda m: add(samples_from_imu(m, self._mount_t)), 50),
                                (Range, "ping/altitude", lambda m: add([sample_from_range(m)]), 20),
                                (ThrusterPwm, "thrusters/pulse_width", self._on_pwm, 20))]
        else:
            for sub in self._inputs:
                self.destroy_subscription(sub)
            self._inputs = []
        (self._timer if active else self._idle_timer).reset()
        (self._idle_timer if active else self._timer).cancel()

    def _on_esc_state(self, msg: DiagnosticStatus) -> None:
        state = read_esc_state(msg)
        self.core.armed = state is not None and state[1]  # malformed: disarmed

    def _on_pwm(self, msg: ThrusterPwm) -> None:
        self.core.on_pwm(msg.pulse_width_us, msg.armed)

    # ------------------------------------------------------------------ action
    def _on_goal(self, goal) -> GoalResponse:
        if self.core.busy:
            self.get_logger().warn("run_identification: a goal is already running; rejected")
            return GoalResponse.REJECT
        problem = goal_problem(goal.dofs, goal.calibrate, goal.calibration_only, goal.level_fractions)
        if problem:
            self.get_logger().error(f"run_identification: {problem}; rejected")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _on_accepted(self, goal_handle) -> None:
        """Accepted goal: set it up and return, not executed here (module docstring, "Action
        execution"); the control timer runs it and ends it (:meth:`_end_goal`)."""
        self.get_logger().info(self.core.accept(goal_handle, goal_handle.request, self._now_s()))
        self._set_active(True)

    def _end_goal(self, run: GoalRun) -> None:
        """The goal's end (the core marked it ended): the result is computed and the goal reaches its terminal state
        through ``execute`` with :meth:`_goal_result`, a plain function that returns at once."""
        self._ended[bytes(run.handle.goal_id.uuid)] = run
        self._set_active(False)
        run.handle.execute(self._goal_result)

    def _goal_result(self, goal_handle) -> RunIdentification.Result:
        """Execute callback (plain, returns at once): the ended goal's result and terminal state."""
        run = self._ended.pop(bytes(goal_handle.goal_id.uuid))
        executive = run.executive
        ok, message = self.core.finish(run)
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
        what = None if self.core.run is None else self.core.run.executive.awaiting
        response.success, response.message = self.core.operator_continue()
        if response.success or response.message.startswith("continuing"):
            self.get_logger().info(f"identification/continue: {what}")
        return response

    # ------------------------------------------------------------------ control tick
    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_tick(self) -> None:
        now = self.get_clock().now()
        run = self.core.run
        cancel = run is not None and not run.ended and bool(run.handle.is_cancel_requested)
        # on the wall clock only: simulated time stands while the operator is asked (docs/architecture.md §10)
        gap_s = self.tick_gaps.tick() if self._inputs and not self.get_clock().ros_time_is_active else 0.0
        self._act(self.core.starved(now.nanoseconds * 1e-9, gap_s) + self.core.tick(now.nanoseconds * 1e-9, cancel),
                  now)

    def _act(self, events: list[Event], now) -> None:
        """Do what the core decided, in its order (:class:`~.core.Event`)."""
        log = self.get_logger()
        for ev in events:
            if ev.kind == "status":
                # the core's phase names are ManeuverStatus.PHASE_<NAME>
                phase = getattr(ManeuverStatus, "PHASE_" + ev.data[0].upper())
                self._publish_status(phase, ev.data[1], ev.data[2])
            elif ev.kind == "wrench":
                self._publish_wrench(ev.data[0], now)
            elif ev.kind == "feedback":
                st, prompt = ev.data
                self.core.run.handle.publish_feedback(RunIdentification.Feedback(
                    dof=st.dof, level_index=st.level_index, level_count=st.level_count,
                    level_command=st.level_command, progress=st.progress, prompt=prompt,
                    phase=st.phase, step=st.message))
            elif ev.kind == "estimates":
                stamp = self.get_clock().now().to_msg()
                for d, est in ev.data[0].online.items():
                    if est.rls.n_samples > 0:
                        self.pub_estimate.publish(hydro_estimate(d, est, stamp))
            elif ev.kind == "calibration":
                self.pub_calibration.publish(calibration_topic.calibration_array(
                    ev.data[0], self.get_clock().now().to_msg()))
            elif ev.kind == "abort":
                self.pub_abort.publish(String(data=ev.data[0]))
            elif ev.kind == "log":
                log_at(log, ev.data[0], ev.data[1])
            elif ev.kind == "warn_throttled":
                log.warn(ev.data[0], throttle_duration_sec=5.0)
            elif ev.kind == "end":
                self._end_goal(ev.data[0])

    def clock_may_advance(self, t_s: float) -> bool:
        """Step gate for a simulator in the same process (:meth:`~hindrax_sim.node.SimulatorNode.add_step_gate`):
        False while a goal's control ticks run (manoeuvre and the neutral hold at its end) and the tick due at
        simulated time ``t_s`` (s) has not run yet, so the simulation never runs ahead of the control loop."""
        return self.core.clock_may_advance(t_s)

    def _publish_wrench(self, w_frd: np.ndarray, now) -> None:
        # serialised by rosbags and published as bytes: the command-rate publish without rclpy's object conversion
        # (hindrax_common.cdr.lean_cdr, the measured gain)
        w = frames.wrench_frd_to_flu(np.asarray(w_frd, dtype=float))
        self.pub_wrench.publish(wrench_stamped_cdr(now.nanoseconds, "base_link", w))

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
        run = self.core.close()
        if run is not None:
            self._publish_wrench(np.zeros(6), self.get_clock().now())
            if self.context.ok():
                self._end_goal(self.core.end(run).data[0])
            else:  # SIGINT/SIGTERM already shut the context down: no result can be delivered any more
                run.ended = True


def main(args: list[str] | None = None) -> int:
    """Run the node alone until SIGINT/SIGTERM (:func:`hindrax_common.node_support.node_common.run_node`: a running
    goal is ended by :meth:`IdentificationNode.close`). Returns the exit status (1 on an invalid configuration).

    The process spins the EventsExecutor like every node process (:mod:`hindrax_common.process.ros_process`): the
    action runs no coroutine (module docstring, "Action execution")."""
    return run_node(IdentificationNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
