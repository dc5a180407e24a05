"""Controller node: depth or altitude, heading and surge/sway velocity holds as one more ``wrench`` source.

A thin rclpy node over :class:`~.loop.HoldLoop` (the campaign's sensor conditioning) and
:class:`~hindrax_onboard.control.maneuvers.HoldController` (the model-based law of :mod:`.law`, the
model of :mod:`.model`). The ESC, the thrust allocation and the supervisor are unchanged: the
controller publishes a ``wrench`` like the identification node or a pilot, and the allocation turns
it into pulse widths. Run alone: ``ros2 run hindrax_onboard controller_node --ros-args --params-file
hindrax.yaml -p model_file:=identification.yaml``.

Interfaces, and who owns ``wrench``: docs/control.md §3. The controller publishes only while **enabled**, which it
never is at start-up; it **yields** (disables itself, saying why in ``controller/status`` and the log) when
``identification/status`` reports a running goal, when a ``wrench`` message it did not send arrives, when the ESC
output is disarmed (``esc/output_state``), or when its depth or attitude is older than ``control.sensor_timeout_s``,
or when its own tick came later than twice ``thrusters.wrench_timeout_s`` on the steady clock ("controller starved
for ...": the CPU is short; then it publishes one zero wrench). Enabling again is always an explicit request
(``controller/hold``, ``controller/enable``).

It also publishes ``odom`` (nav_msgs/Odometry) and ``odom -> base_link`` on ``/tf`` at 10 Hz (REP-105,
:mod:`.odometry`) while its sensor streams are open; a malformed ``esc/output_state`` reads as disarmed.

CPU (docs/control.md §3 items 6-7): the tick runs at ``control.rate_hz`` only while enabled, every
:data:`ODOM_PERIOD_S` while disabled, every :data:`GOAL_TICK_S` while an identification goal runs.

Parameters: the vehicle configuration (``control.*``) and ``model_file`` (string, read-only, default
"": identification.yaml to take the model from, "" = the vehicle file); a file that cannot be used
stops the start-up with one line naming ``model_file``, never the vehicle file's model in its place."""
from __future__ import annotations

import math
import sys
from collections import deque
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TransformStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from sensor_msgs.msg import FluidPressure, Imu, Range
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, ConfigError, ConfigIssue, VehicleConfig
from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos, read_esc_state
from hindrax_common.cdr.lean_cdr import cdr_decoder
from hindrax_common.node_support.liveness import TickGaps, starvation, starved_stop_s
from hindrax_drivers.icm20948.mounting import mounting_rotation
from hindrax_common.node_support.node_common import load_node_config, run_node, sensor_input_qos
from hindrax_common.node_support.vehicle_node import VehicleNode
from hindrax_msgs.msg import AllocationStatus, ControllerStatus, ControlSetpoint, Dvl, ManeuverStatus

from .maneuvers import HoldController, dof_authority
from ..vehicle.signals import sample_from_pressure, sample_from_range, samples_from_dvl, samples_from_imu
from .law import ControlSettings
from .loop import HoldLoop
from ..vehicle.state import finite_or_zero
from .model import ModelFileError, load_model, model_from_config
from .odometry import odometry_estimate

__all__ = ["ControllerNode", "main", "RUNNING_PHASES"]

#: identification/status phases during which the identification node owns ``wrench``.
RUNNING_PHASES = frozenset({ManeuverStatus.PHASE_POSITIONING, ManeuverStatus.PHASE_RUNNING,
                            ManeuverStatus.PHASE_RETURNING})
#: Period of controller/status when nothing changes, s.
STATUS_PERIOD_S = 0.5
#: period of ``odom`` and the ``odom -> base_link`` transform on ``/tf`` (s): 10 Hz, enough for a 3D view
ODOM_PERIOD_S = 0.1
#: while disabled, one ``imu/data_raw`` message in this many is conditioned (51 Hz -> 10 Hz: the odometry's rate); the
#: others are taken as bytes and dropped undecoded. Enabled, every one is (module docstring, "CPU")
IDLE_IMU_EVERY = 5
#: tick period (s) while an identification goal runs: the tick then only takes the goal's phase
#: (``identification/status``) and publishes ``controller/status`` (every :data:`STATUS_PERIOD_S`); the streams are
#: closed. The goal's end is seen within 0.2 s (the streams open then; enabling waits for their first samples anyway,
#: :meth:`ControllerNode._refusal`)
GOAL_TICK_S = 0.2


class ControllerNode(VehicleNode):
    """The controller as a ROS node (module docstring). config: a VehicleConfig (default: the node's parameters);
    model_file: overrides the ``model_file`` parameter. Raises :class:`ConfigError` for an invalid configuration."""

    def __init__(self, *, config: VehicleConfig | None = None, node_name: str = "controller",
                 model_file: str | None = None, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        log = self.get_logger()
        self.config = config if config is not None else load_node_config(self)
        self.settings = ControlSettings.from_config(self.config)
        if not self.has_parameter("model_file"):
            self.declare_parameter("model_file", "" if model_file is None else model_file, ParameterDescriptor(
                description="identification.yaml to take the control model from ('' = the vehicle file)",
                read_only=True, additional_constraints="a readable identification.yaml, or ''"))
        path = self.get_parameter("model_file").value if model_file is None else model_file
        if not isinstance(path, str):
            issue = ConfigIssue("model_file", path, "a path string or ''")
            raise ConfigError([issue], f"parameters of {self.get_name()}")
        try:
            self.model = load_model(path, self.config) if path else model_from_config(self.config)
        except ModelFileError as exc:  # never a silent fallback to the vehicle file
            issue = ConfigIssue("model_file", path, f"a readable identification.yaml of this vehicle ({exc})")
            raise ConfigError([issue], f"parameters of {self.get_name()}") from exc
        for note in self.model.notes:
            log.warn(note)
        core = AllocationCore(self.config)
        authority = [dof_authority(core, d) for d in DOFS]
        s = self.settings
        self.hold = HoldController(self.config, authority, s.depth_bandwidth_rad_s, s.hold_fraction, self.model,
                                   s.velocity_bandwidth_rad_s / s.depth_bandwidth_rad_s, settings=s)
        self.tick_s = 1.0 / s.rate_hz
        self.loop = HoldLoop(self.config, self.hold, self.tick_s)
        self._mount_t = mounting_rotation(self.config.sensors.icm20948.mounting_rpy_rad).T
        self._pending: list = []
        self._decode_imu = cdr_decoder(Imu)
        self._last_sample_s: dict[str, float] = {}
        self.enabled = False
        self.message = "disabled (start-up)"
        self._armed = False  # the last esc/output_state says armed
        self._armed_seen = False  # an esc/output_state arrived
        self.esc_state_malformed = 0  # esc/output_state messages without a valid state (read as disarmed)
        self._ident_running = False
        self._own = deque(maxlen=200)
        self._setpoint: ControlSetpoint | None = None
        self._last_wrench = np.zeros(6)
        self._last_status_s = -math.inf
        self._last_odom_s = -math.inf
        self._last_tick_s: float | None = None
        self.tick_gaps = TickGaps()  # steady-clock gaps between ticks (a starved tick, _on_tick)
        self._report = self.hold.core.gain_report()
        self._streams: list = []
        self._enabled_streams: list = []  # subscribed while enabled (_open_enabled_streams)
        self._open_streams()
        self.create_subscription(ManeuverStatus, "identification/status", self._on_ident_status, 20)
        self.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, self._on_esc_state, esc_state_qos())
        self.create_subscription(ControlSetpoint, "controller/setpoint", self._on_setpoint, 10)
        self.pub_wrench = self.create_publisher(WrenchStamped, "wrench", 10)
        self.pub_status = self.create_publisher(ControllerStatus, "controller/status", 10)
        # the estimate for ROS tools (REP-105): nav_msgs/Odometry and the odom -> base_link transform
        self.pub_odom = self.create_publisher(Odometry, "odom", 10)
        self.pub_tf = self.create_publisher(TFMessage, "/tf", 10)
        self.create_service(Trigger, "controller/hold", self._on_hold)
        self.create_service(SetBool, "controller/enable", self._on_enable)
        # one tick timer runs at a time (:meth:`_retime`): control.rate_hz while enabled, ODOM_PERIOD_S while disabled,
        # GOAL_TICK_S while an identification goal runs
        self._tick_timer = self.create_timer(self.tick_s, self._on_tick, autostart=False)
        self._idle_timer = self.create_timer(ODOM_PERIOD_S, self._on_tick)
        self._goal_timer = self.create_timer(GOAL_TICK_S, self._on_tick, autostart=False)
        for line in self._report:
            log.info(line)
        log.info(f"controller ready (disabled): model {self.model.source}, {s.rate_hz:g} Hz")  # last: it is ready

    # ------------------------------------------------------------------ inputs
    def _open_streams(self) -> None:
        """Subscribe to the streams only a controller that may be enabled needs: the four sensor topics (about 80
        messages/s in the pool layout). The first IMU message after opening is conditioned (:meth:`_on_imu`)."""
        self._imu_count = IDLE_IMU_EVERY - 1
        sub, qos = self.create_subscription, sensor_input_qos(20)
        self._streams = [
            sub(Dvl, "dvl/data", lambda m: self._add(samples_from_dvl(m)), qos),
            sub(FluidPressure, "pressure/fluid_pressure", lambda m: self._add([sample_from_pressure(m)]), qos),
            sub(Imu, "imu/data_raw", self._on_imu, sensor_input_qos(50), raw=True),
            sub(Range, "ping/altitude", lambda m: self._add([sample_from_range(m)]), qos)]

    def _open_enabled_streams(self) -> None:
        """Subscribe to what only an enabled controller reads: ``wrench`` (other writers: a pilot's message makes it
        yield) and ``allocation/status`` (anti-windup); a disabled controller ignored both, and the pilot's 50 Hz
        stream cost it a callback per message."""
        if not self._enabled_streams:
            sub = self.create_subscription
            self._enabled_streams = [
                sub(AllocationStatus, "allocation/status", self._on_allocation, 20),
                sub(WrenchStamped, "wrench", self._on_wrench, 50)]

    def _close_enabled_streams(self) -> None:
        for sub in self._enabled_streams:
            self.destroy_subscription(sub)
        self._enabled_streams = []

    def _close_streams(self) -> None:
        """Drop the streams while an identification goal runs (the controller cannot be enabled then), and forget the
        conditioned state: after the goal the hold starts from fresh samples, and ``_refusal`` says "no data yet"
        until they arrive (docs/control.md §3)."""
        for sub in self._streams:
            self.destroy_subscription(sub)
        self._streams = []
        self._pending = []
        self._last_sample_s.clear()
        self.loop = HoldLoop(self.config, self.hold, self.tick_s)

    def _now_s(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _add(self, samples: list) -> None:
        now = self._now_s()
        for dev, _s in samples:
            self._last_sample_s[dev] = now
        self._pending.extend(samples)

    def _on_imu(self, data: bytes) -> None:
        """``imu/data_raw`` as CDR bytes: every message while enabled, one in :data:`IDLE_IMU_EVERY` while disabled."""
        self._imu_count += 1
        if self.enabled or self._imu_count >= IDLE_IMU_EVERY:
            self._imu_count = 0
            self._add(samples_from_imu(self._decode_imu(data), self._mount_t))

    def _on_esc_state(self, msg: DiagnosticStatus) -> None:
        state = read_esc_state(msg)
        if state is None:
            self.esc_state_malformed += 1
        self._armed = state is not None and state[1]  # unknown: the ESC says armed=false, and the controller yields
        self._armed_seen = True
        if self.enabled and not self._armed:
            self._disable("yielded: the ESC output is disarmed", zero=False)

    def _on_allocation(self, msg: AllocationStatus) -> None:
        if not self.enabled or msg.rejected:
            return
        req = frames.wrench_flu_to_frd(_wrench6(msg.requested_wrench))
        ach = frames.wrench_flu_to_frd(_wrench6(msg.achieved_wrench))
        self.hold.note_allocation(req, ach)

    def _on_ident_status(self, msg: ManeuverStatus) -> None:
        running = msg.phase in RUNNING_PHASES
        if running and self.enabled:
            self._disable("yielded: an identification goal is running", zero=False)
        if running and self._streams:
            self._close_streams()
        elif not running and not self._streams:
            self._open_streams()
        self._ident_running = running
        self._retime()

    def _retime(self) -> None:
        """Run the one tick timer of the node's state, cancel the others (module docstring, "CPU")."""
        want = self._goal_timer if self._ident_running else self._tick_timer if self.enabled else self._idle_timer
        for timer in (self._tick_timer, self._idle_timer, self._goal_timer):
            if timer is not want:
                timer.cancel()
            elif timer.is_canceled():
                timer.reset()

    def _on_wrench(self, msg: WrenchStamped) -> None:
        if self.enabled and _key(msg) not in self._own:
            self._disable("yielded: another source publishes wrench (pilot)", zero=False)

    def _on_setpoint(self, msg: ControlSetpoint) -> None:
        bad = [n for n in ("depth_m", "altitude_m", "heading_rad", "surge_m_s", "sway_m_s")
               if not math.isfinite(getattr(msg, n))]
        needed = {ControlSetpoint.VERTICAL_DEPTH: "depth_m", ControlSetpoint.VERTICAL_ALTITUDE: "altitude_m"}
        if msg.vertical_mode not in (0, 1, 2) or (msg.vertical_mode in needed and needed[msg.vertical_mode] in bad) \
                or (msg.hold_heading and "heading_rad" in bad) or (msg.hold_velocity and
                                                                  ({"surge_m_s", "sway_m_s"} & set(bad))):
            self.get_logger().error(f"controller/setpoint rejected: vertical_mode {msg.vertical_mode}, "
                                    f"non-finite {', '.join(bad) or 'none'}")
            return
        self._setpoint = msg
        self._apply_setpoint(msg)
        self._publish_status(force=True)

    def _apply_setpoint(self, msg: ControlSetpoint) -> None:
        h = self.hold
        h.depth_setpoint_m = float(msg.depth_m) if msg.vertical_mode == ControlSetpoint.VERTICAL_DEPTH else math.nan
        h.altitude_setpoint_m = (float(msg.altitude_m) if msg.vertical_mode == ControlSetpoint.VERTICAL_ALTITUDE
                                 else math.nan)
        h.heading_setpoint_rad = float(msg.heading_rad) if msg.hold_heading else math.nan
        # base_link (FLU) velocity -> body FRD: sway is to port (left) in FLU
        h.velocity_setpoint_m_s = (np.array([float(msg.surge_m_s), -float(msg.sway_m_s)]) if msg.hold_velocity
                                   else np.full(2, np.nan))

    # ------------------------------------------------------------------ services
    def _refusal(self) -> str:
        if self._ident_running:
            return "an identification goal is running (it owns wrench)"
        if not (self._armed_seen and self._armed):
            return "the ESC output is not armed (esc/set_armed)"
        missing = [d for d in ("ms5837", "dvl75_attitude", "icm20948_gyro") if d not in self._last_sample_s]
        if missing:
            return f"no data yet from {', '.join(missing)}"
        return ""

    def _hold_current(self) -> None:
        st = self.loop.state
        depth, _rate = self.loop.depth.predict_to(self._now_s())
        msg = ControlSetpoint()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "base_link"
        altitude_mode = self._setpoint is not None and self._setpoint.vertical_mode == ControlSetpoint.VERTICAL_ALTITUDE
        if altitude_mode and math.isfinite(st.altitude_m):
            msg.vertical_mode, msg.altitude_m = ControlSetpoint.VERTICAL_ALTITUDE, float(st.altitude_m)
        else:
            msg.vertical_mode = ControlSetpoint.VERTICAL_DEPTH
            msg.depth_m = float(depth if math.isfinite(depth) else st.depth_m)
        msg.hold_heading, msg.heading_rad = True, finite_or_zero(st.rpy_now()[2])
        msg.hold_velocity, msg.surge_m_s, msg.sway_m_s = True, 0.0, 0.0
        self._setpoint = msg
        self._apply_setpoint(msg)

    def _on_hold(self, _request, response):
        return self._answer_enable(response, "holding the current state", "not holding", hold=True)

    def _on_enable(self, request, response):
        if request.data:
            hold = self._setpoint is None
            return self._answer_enable(response, "enabled", "not enabled", hold)
        if self.enabled:
            self._disable("disabled on request", zero=True)
        response.success, response.message = True, self.message
        return response

    def _answer_enable(self, response, why: str, refused: str, hold: bool):
        """Enable (first holding the current state when ``hold``) unless :meth:`_refusal` says why not."""
        refusal = self._refusal()
        if refusal:
            response.success, response.message = False, f"{refused}: {refusal}"
            return response
        if hold:
            self._hold_current()
        self._enable(why)
        response.success, response.message = True, self.message
        return response

    def _enable(self, why: str) -> None:
        self.hold.core.reset()  # references start from the measured state, integrators empty
        self.enabled = True
        self.message = why
        self._open_enabled_streams()
        self._last_tick_s = self._now_s()  # the step gate lets the clock reach the control timer's first tick
        self._retime()
        self.get_logger().info(f"controller: {why}")
        self._publish_status(force=True)

    def _disable(self, why: str, zero: bool) -> None:
        self.enabled = False
        self.message = why
        self._close_enabled_streams()
        self._retime()
        if why.startswith(("yielded", "stopped")):
            self.get_logger().warn(f"controller: {why}")
        else:
            self.get_logger().info(f"controller: {why}")
        if zero:
            self._publish_wrench(np.zeros(6))
        self._publish_status(force=True)

    # ------------------------------------------------------------------ control tick
    def _on_tick(self) -> None:
        t = self._now_s()
        self.loop.add(self._pending)
        self._pending = []
        self._last_tick_s = t
        gap_s = self.tick_gaps.tick()
        # on the wall clock only (simulated time may stand): a starved tick is said, and beyond
        # liveness.starved_stop_s the hold stops with it
        starved = "" if self.get_clock().ros_time_is_active else starvation("controller", gap_s, self.tick_s)
        if self.enabled and starved:
            self.get_logger().warn(starved, throttle_duration_sec=5.0)
        if self.enabled:
            stale = [d for d in ("ms5837", "dvl75_attitude") if t - self._last_sample_s.get(d, -math.inf)
                     > self.settings.sensor_timeout_s]
            limit_s = starved_stop_s(self.config.thrusters.wrench_timeout_s)
            if starved and gap_s > limit_s:
                self._disable(f"stopped: {starved[:-1]}, beyond {limit_s:g} s: twice thrusters.wrench_timeout_s)",
                              zero=True)
            elif stale:
                self._disable(f"stopped: no {', '.join(stale)} for {self.settings.sensor_timeout_s:g} s", zero=True)
            else:
                w = self.loop.wrench(t)
                if np.all(np.isfinite(w)):
                    self._publish_wrench(w)
                else:
                    self._disable("stopped: the law gave a non-finite wrench", zero=True)
        self._publish_status()
        self._publish_odometry(t)

    def _publish_odometry(self, t: float) -> None:
        """``odom`` (nav_msgs/Odometry, frame ``odom``, child ``base_link``) and the same pose on ``/tf``, every
        :data:`ODOM_PERIOD_S`, from the conditioned sensors (:mod:`.odometry`); nothing before the first depth and
        attitude. A twist without DVL lock is zero with its covariance's first element -1 (unknown)."""
        if t - self._last_odom_s < ODOM_PERIOD_S - 0.5 * self.tick_s:  # a tick early by its jitter counts
            return
        st = self.loop.state
        est = odometry_estimate(st.position_ned_m, st.rpy_now(), st.velocity_frd_m_s, st.rates_frd_rad_s)
        if est is None:
            return
        self._last_odom_s = t
        stamp = self.get_clock().now().to_msg()
        m = Odometry()
        m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, "odom", "base_link"
        p, q = m.pose.pose.position, m.pose.pose.orientation
        p.x, p.y, p.z = (float(x) for x in est.position_enu_m)
        q.x, q.y, q.z, q.w = (float(x) for x in est.orientation_xyzw)
        lin, ang = m.twist.twist.linear, m.twist.twist.angular
        lin.x, lin.y, lin.z = (float(x) for x in est.linear_flu_m_s)
        ang.x, ang.y, ang.z = (float(x) for x in est.angular_flu_rad_s)
        if not est.velocity_known:
            m.twist.covariance[0] = -1.0
        self.pub_odom.publish(m)
        tf = TransformStamped(header=m.header, child_frame_id="base_link")  # the same pose
        tr = tf.transform.translation
        tr.x, tr.y, tr.z = p.x, p.y, p.z
        tf.transform.rotation = q
        self.pub_tf.publish(TFMessage(transforms=[tf]))

    def clock_may_advance(self, t_s: float) -> bool:
        """Step gate for a simulator in the same process: False while enabled and the tick due at ``t_s`` has not
        run yet (the simulation never runs ahead of the control loop)."""
        if not self.enabled or self._last_tick_s is None:
            return True
        return t_s + 1e-6 < self._last_tick_s + self.tick_s

    def _publish_wrench(self, w_frd: np.ndarray) -> None:
        w = frames.wrench_frd_to_flu(np.asarray(w_frd, dtype=float))
        m = WrenchStamped()
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "base_link"
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(x) for x in w[:3])
        m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(x) for x in w[3:])
        self._own.append(_key(m))
        self._last_wrench = w
        self.pub_wrench.publish(m)

    def _publish_status(self, force: bool = False) -> None:
        t = self._now_s()
        if not force and t - self._last_status_s < STATUS_PERIOD_S - 0.5 * self.tick_s:
            return
        self._last_status_s = t
        h, st = self.hold, self.loop.state
        m = ControllerStatus(enabled=self.enabled, message=self.message)
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "base_link"
        sp = self._setpoint
        m.vertical_mode = 0 if sp is None else int(sp.vertical_mode)
        m.depth_setpoint_m = float(h.depth_setpoint_m)
        m.altitude_setpoint_m = float(h.altitude_setpoint_m)
        m.heading_setpoint_rad = float(h.heading_setpoint_rad)
        v = np.asarray(h.velocity_setpoint_m_s, dtype=float)
        m.surge_setpoint_m_s, m.sway_setpoint_m_s = float(v[0]), float(-v[1])
        depth, _ = self.loop.depth.predict_to(t)
        m.depth_m = float(depth)
        m.altitude_m = float(st.altitude_m)
        m.heading_rad = float(st.rpy_now()[2])
        w = self._last_wrench
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = (float(x) for x in w[:3])
        m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (float(x) for x in w[3:])
        m.model_source = self.model.source
        m.gain_report = list(self._report)
        self.pub_status.publish(m)

    def close(self) -> None:
        """Shutdown path: while enabled, one zero wrench (the allocation's timeout would also stop the thrusters)."""
        if self.enabled:
            self._disable("stopped: node shutting down", zero=True)


def _wrench6(w) -> np.ndarray:
    return np.array([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z], dtype=float)


def _key(msg: WrenchStamped) -> tuple:
    """Identity of a wrench message: its stamp and values (a foreign writer would have to match all of them)."""
    return (msg.header.stamp.sec, msg.header.stamp.nanosec) + tuple(round(float(x), 9) for x in _wrench6(msg.wrench))


def main(args: list[str] | None = None) -> int:
    """Run the node alone until SIGINT/SIGTERM (:func:`hindrax_common.node_support.node_common.run_node`). Returns the
    exit status (1 on an invalid configuration)."""
    return run_node(ControllerNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
