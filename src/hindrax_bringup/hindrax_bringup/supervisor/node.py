"""Safety supervisor node: disarms the ESC output when the vehicle leaves its safe envelope.

Thin rclpy wrapper of :class:`~hindrax_bringup.supervisor.core.SupervisorCore` (the checks and their keys are documented
there). On a breach it calls ``esc/set_armed`` with ``arm=False`` (the ESC node writes neutral on every channel in that
service callback, i.e. at once, well within one output period), latches the reason, says why on ``supervisor/status``
and in ``/diagnostics`` (level ERROR), and disarms again whenever the ESC reports armed while the breach is latched.

Subscribes (ROS time of arrival is used for rates and run time, the header stamps for freshness; ``use_sim_time``
supported)
    ``dvl/data`` (hindrax_msgs/Dvl: attitude, velocity for the dead reckoning), ``ping/altitude``
    (sensor_msgs/Range), ``pressure/depth`` (geometry_msgs/PoseWithCovarianceStamped, ``position.z = -depth``),
    ``imu/data_raw`` (sensor_msgs/Imu: rate, freshness and the accelerometer's tilt; taken as serialised bytes, see
    "CPU"), ``esc/output_state`` (the ESC's armed flag and output state, latched:
    :mod:`hindrax_common.node_support.esc_state`; unknown after armed counts as armed; a dead ESC's last state stays,
    so the supervisor keeps watching the envelope as if armed), ``supervisor/abort``
    (std_msgs/String: any node trips the supervisor with a reason, e.g. the identification node when it aborts
    a manoeuvre on a limit), ``guard/heartbeat`` (the output guard's reason while it silences the outputs: read
    for the disarm cause only, :mod:`.disarm_cause`).
Services
    ``supervisor/estop`` (std_srvs/Trigger): operator emergency stop: trip and disarm now.
    ``supervisor/reset`` (std_srvs/Trigger): clear the latched breach (the ESC must then be armed again; a disarm
    request still in flight, :attr:`SupervisorNode.disarm_future`, may land after a very quick re-arm).
Publishes
    ``supervisor/heartbeat`` (hindrax_msgs/Heartbeat with ``boot_id`` and ``seq``:
    :class:`~hindrax_common.node_support.liveness.HeartbeatPublisher`) at every check
    (``supervisor.check_rate_hz``, steady clock): level OK within the envelope, ERROR with the latched reason. The
    ESC refuses to arm and disarms without a fresh OK one; the output guard silences the outputs without one
    (docs/architecture.md §8). It is the supervisor's independent stop path: a dead or hung supervisor stops
    heartbeating, which they act on within ``esc.heartbeat_timeout_s`` and ``esc.guard_heartbeat_timeout_s``.
    ``supervisor/status`` (diagnostic_msgs/DiagnosticStatus: level OK or ERROR, message = the breach reason, values
    = the supervised quantities and, once the thrust stopped, ``disarm_cause``: ``<process>: <cause>; next:
    <step>``, :mod:`.disarm_cause`) on every change and at 1 Hz; ``/diagnostics`` (``hindrax/supervisor``).
CPU (README "Performance on the Pi")
    A :class:`~hindrax_common.node_support.vehicle_node.VehicleNode` (no QoS event handlers): a sensor that
    stops reaching the supervisor, for a QoS mismatch or any other reason, trips the
    ``supervisor.min_rate.*`` checks (where not 0).
    Every input is a subscription callback on the node's executor, whatever the clock (the vehicle, the virtual
    pool and the tests take the same path): each sample is counted at the ROS time of its arrival and can trip at
    once; an ESC that reports armed while the supervisor is tripped is disarmed from that callback.
    ``imu/data_raw`` (51-102 Hz) comes as its CDR bytes: the freshness check compares them (stamp aside) to find a
    sensor repeating itself, and only the specific force is decoded, with rosbags
    (:func:`hindrax_common.cdr.lean_cdr.cdr_decoder`).
Time
    The checks run on a steady-clock timer; sample times are ROS time (``use_sim_time`` supported). A backward step
    of ROS time is detected at the next check or sample, whichever reads the time first, reported (``/diagnostics``
    warning ``clock_step``) and the stored times are shifted by the step, so no check goes blind and a sample taken
    after the step is not shifted again; ROS time standing still for ``clock_stall_timeout_s`` (default
    ``supervisor.rate_window_s``) of steady time while armed trips (:meth:`.core.SupervisorCore.stall_check`).
Configuration
    ``supervisor.*`` and ``pool.*`` of the vehicle file (``--ros-args --params-file ros_ws/config/hindrax.yaml``);
    the read-only node parameter ``clock_stall_timeout_s``."""
from __future__ import annotations

import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import Imu, Range
from std_msgs.msg import String
from std_srvs.srv import Trigger

from hindrax_msgs.msg import Dvl, Heartbeat
from hindrax_msgs.srv import SetArmed

from hindrax_common.base import frames
from hindrax_common.node_support.esc_state import (ESC_STATE_TOPIC, OUTPUT_UNKNOWN, armed_after, esc_state_qos,
    read_esc_state)
from hindrax_common.cdr.lean_cdr import cdr_decoder, read_heartbeat
from hindrax_common.node_support.liveness import (HEARTBEAT_NAMES, ClockStepMonitor, HeartbeatPublisher, TickGaps,
    heartbeat_ok, heartbeat_qos)
from hindrax_common.config.sections.supervisor import CLOCK_STALL_TIMEOUT
from hindrax_common.node_support.node_common import (DeviceDiagnostics, DiagnosticsPublisher, load_node_config,
    run_node, sensor_input_qos)
from hindrax_common.config.node_parameters import declare_node_parameter
from hindrax_common.node_support.vehicle_node import VehicleNode
from .core import SupervisorCore, SupervisorLimits
from .disarm_cause import DisarmCauses

__all__ = ["SupervisorNode", "main"]

#: QoS depth of ``imu/data_raw``: 0.5 s at 102 Hz, room for an executor held up on a loaded machine (a sample lost
#: in the queue lowers the rate the ``supervisor.min_rate.imu_hz`` check sees)
IMU_QUEUE_DEPTH = 50


class SupervisorNode(VehicleNode):
    """The safety supervisor (see the module docstring)."""

    #: its process refuses to start beside another live supervisor
    #: (:func:`hindrax_common.node_support.vehicle_graph.refuse_live_peer`)
    START_CHECK = "supervisor"

    def __init__(self, **kwargs: Any):
        super().__init__("supervisor", **kwargs)
        cfg = load_node_config(self, ("supervisor", "pool"))
        # ROS time standing still this long (steady s) while armed trips: parameter ``clock_stall_timeout_s``
        self.core = SupervisorCore(SupervisorLimits.from_config(cfg, float(declare_node_parameter(
            self, "clock_stall_timeout_s", CLOCK_STALL_TIMEOUT, cfg.supervisor.rate_window_s))))
        #: why the thrust last stopped, for the operator (``disarm_cause`` of the status)
        self.causes = DisarmCauses()
        self._decode_imu = cdr_decoder(Imu)
        self.diag = DeviceDiagnostics("hindrax/supervisor", "supervisor", self._now_s)
        self.diag.set_state("ok", DiagnosticStatus.OK, "within the envelope")
        self.last_breach_time_s: float | None = None
        self._status_dirty = True
        self.disarm_future = None  # the last esc/set_armed(arm=False) request
        self.heartbeat = HeartbeatPublisher(self, "supervisor")
        self.clock_monitor = ClockStepMonitor(self._now_s)
        self.pub_status = self.create_publisher(DiagnosticStatus, "supervisor/status", 10)
        # the sensors best effort (sensor_input_qos): a lost sample only lowers the rate the check counts
        self.create_subscription(Dvl, "dvl/data", self.on_dvl, sensor_input_qos(10))
        self.create_subscription(Range, "ping/altitude", self.on_altitude, sensor_input_qos(10))
        self.create_subscription(PoseWithCovarianceStamped, "pressure/depth", self.on_depth, sensor_input_qos(10))
        self.create_subscription(Imu, "imu/data_raw", self.on_imu, sensor_input_qos(IMU_QUEUE_DEPTH), raw=True)
        self.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, self.on_esc, esc_state_qos())
        self.create_subscription(String, "supervisor/abort", self.on_abort, 10)
        self.create_subscription(Heartbeat, HEARTBEAT_NAMES["guard"], self.on_guard, heartbeat_qos(), raw=True)
        self.create_service(Trigger, "supervisor/estop", self.on_estop)
        self.create_service(Trigger, "supervisor/reset", self.on_reset)
        self.esc_client = self.create_client(SetArmed, "esc/set_armed")
        self.tick_gaps = TickGaps()  # how late the check (and its heartbeat) ran, on /diagnostics
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=lambda: [*self.core.values(self._now_s()),
                                                                                  *self.tick_gaps.report()])
        self.create_timer(1.0 / cfg.supervisor.check_rate_hz, self.on_check,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_timer(1.0, self._publish_status)

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs
    def on_dvl(self, msg: Dvl) -> None:
        t = self._sample_time_s()
        q = np.array([msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w], dtype=float)
        rpy = None  # the driver's all-zero quaternion: the report has no attitude (no $DVEXT), never "level"
        if np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5:
            e = frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q))
            rpy = (float(e[0]), float(e[1]), float(e[2]))
        v = np.array([msg.velocity_m_s.x, msg.velocity_m_s.y, msg.velocity_m_s.z], dtype=float)
        valid = bool(msg.velocity_valid) and bool(np.all(np.isfinite(v)))
        content = (*v, *q, msg.altitude_m, *msg.beam_range_m, *msg.beam_velocity_m_s)  # all but the header
        self._handle(self.core.on_dvl(t, frames.flu_to_frd(v) if valid else None, _stamp_s(msg.header.stamp), rpy,
                                      tuple(float(x) for x in content)))

    def on_altitude(self, msg: Range) -> None:
        self._handle(self.core.on_altitude(self._sample_time_s(), float(msg.range), _stamp_s(msg.header.stamp)))

    def on_depth(self, msg: PoseWithCovarianceStamped) -> None:
        self._handle(self.core.on_depth(self._sample_time_s(), -float(msg.pose.pose.position.z),
                                        _stamp_s(msg.header.stamp)))

    def on_imu(self, data: bytes) -> None:
        """One ``imu/data_raw`` sample (CDR bytes), counted at the node's time now: its stamp and bytes (stamp aside:
        the 4-byte encapsulation and the 8-byte stamp lead the message) for freshness, its specific force for the tilt
        the roll and pitch limits use without a fresh DVL attitude (decoded with rosbags)."""
        t = self._sample_time_s()
        try:
            msg = self._decode_imu(data)
        except Exception:  # noqa: BLE001 - malformed bytes: not a sample (counted, never a crash)
            self.diag.count("malformed_imu")
            return
        a = msg.linear_acceleration
        self._handle(self.core.on_imu(t, _stamp_s(msg.header.stamp), bytes(data[12:]),
                                      frames.flu_to_frd(np.array([a.x, a.y, a.z], dtype=float))))

    def on_esc(self, msg: DiagnosticStatus) -> None:
        """An ``esc/output_state``: an output state that became unknown while armed may still be thrusting, so the
        checks go on (:func:`~hindrax_common.node_support.esc_state.armed_after`); a malformed one is counted and read
        as unknown."""
        state = read_esc_state(msg)
        if state is None:
            self.diag.count("esc_state_malformed")
            state = (OUTPUT_UNKNOWN, False)
        armed = armed_after(self.core.armed, *state)
        if armed != self.core.armed:
            self._status_dirty = True
        self._cause(lambda: self.causes.on_armed(armed, next((kv.value for kv in msg.values if kv.key == "reason"),
                                                              "")))
        self.core.set_armed(self._sample_time_s(), armed)
        self._disarm()

    def on_guard(self, data: bytes) -> None:
        """A ``guard/heartbeat`` (its CDR bytes): its reason while it silences the outputs names a disarm
        (:mod:`.disarm_cause`); bytes that are not a heartbeat are ignored."""
        beat = read_heartbeat(data)
        if beat is not None:
            self._cause(lambda: self.causes.on_guard(heartbeat_ok(beat), beat.message))

    def _cause(self, update) -> None:
        """Apply ``update`` to :attr:`causes`; a new cause line is published at once."""
        before = self.causes.line
        update()
        if self.causes.line != before:
            if self.causes.line:
                self.get_logger().warn(f"thrust stopped: {self.causes.line}")
            self._status_dirty = True

    def on_abort(self, msg: String) -> None:
        self._cause(lambda: self.causes.on_starved(msg.data))  # the starvation behind an earlier stop, if it is one
        self._handle(self.core.trip(f"abort requested: {msg.data}"))

    def on_estop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        new = self.core.trip("operator e-stop (supervisor/estop)")
        self._handle(new)
        response.success = True
        was = "tripped" if new else "already tripped"
        response.message = f"{was}: {self.core.tripped}; disarm requested"
        return response

    def on_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        was = self.core.tripped
        self.core.reset()
        self.diag.set_state("ok", DiagnosticStatus.OK, "within the envelope")
        self._status_dirty = True
        self._publish_status()
        response.success = True
        response.message = f"cleared: {was}" if was else "was not tripped"
        return response

    def _sample_time_s(self) -> float:
        """ROS time now (s), for a sample or a check, after re-basing the supervised times when ROS time stepped
        back since the last reading: a sample taken between a step and the next check is then stored in the new
        time base and not shifted a second time (which gave a spurious "no valid DVL velocity for <step> s")."""
        step = self.clock_monitor.check()
        if step:
            self.core.shift_time(step)
            self.diag.count("clock_step")
            self.diag.warn("clock_step", f"ROS time stepped back {-step:.3f} s; supervised times shifted by it")
            self.get_logger().warn(f"ROS time stepped back {-step:.3f} s: checks re-based")
            self.diagnostics.publish()  # at once: its timer runs on the ROS time that just jumped
        return self._now_s()

    def on_check(self) -> None:
        self.tick_gaps.tick()
        self._sample_time_s()  # a backward step of ROS time: re-base first
        self._handle(self.core.stall_check(self.clock_monitor.stalled_for_s()))
        self._handle(self.core.check(self._now_s()))
        self._disarm()
        if self._status_dirty:
            self._publish_status()
        self._publish_heartbeat()

    def _publish_heartbeat(self) -> None:
        tripped = self.core.tripped
        self.heartbeat.publish(not tripped, tripped or "within the envelope")

    # ------------------------------------------------------------------ breach
    def _handle(self, reason: str) -> None:
        """A new breach (non-empty ``reason``): disarm (even if the ESC is not known to be armed), report."""
        if not reason:
            return
        self.causes.on_trip(reason)
        self.last_breach_time_s = self._now_s()
        self.diag.count("breach")
        self.diag.set_state("tripped", DiagnosticStatus.ERROR, reason)
        self.get_logger().error(f"supervisor breach: {reason}; disarming the ESC")
        self._status_dirty = True
        self._publish_heartbeat()  # the ESC and the guard act on it at once
        self._disarm(breach=True)
        self._publish_status()

    def _disarm(self, breach: bool = False) -> None:
        """``esc/set_armed(arm=False)`` when the core says it is due (:meth:`.core.SupervisorCore.disarm_due`)."""
        if not self.core.disarm_due(time.monotonic(), breach):
            return
        if not self.esc_client.service_is_ready():
            self.get_logger().error("esc/set_armed not available: cannot disarm", throttle_duration_sec=1.0)
            return
        self.disarm_future = self.esc_client.call_async(SetArmed.Request(arm=False))

    def _publish_status(self) -> None:
        t = self._now_s()
        tripped = self.core.tripped
        st = DiagnosticStatus(level=DiagnosticStatus.ERROR if tripped else DiagnosticStatus.OK,
                              name="hindrax/supervisor", message=tripped or "within the envelope",
                              hardware_id="supervisor")
        cause = [("disarm_cause", self.causes.line)] if self.causes.line else []
        st.values = [KeyValue(key=k, value=v) for k, v in self.core.values(t) + cause]
        self.pub_status.publish(st)
        self.diag.published()
        self._status_dirty = False


def _stamp_s(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` (rclpy or rosbags object) in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def main(args=None) -> int:
    """``python -m hindrax_bringup.supervisor.node --ros-args --params-file ros_ws/config/hindrax.yaml``."""
    return run_node(SupervisorNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
