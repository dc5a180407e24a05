"""Thrust-allocation node: ``geometry_msgs/WrenchStamped`` (base_link, FLU) -> thruster commands.

Subscribes
    ``wrench`` (geometry_msgs/WrenchStamped): requested wrench about the CG, base_link, N and N m.
    ``thrusters/test_forces`` (hindrax_msgs/ThrusterForces): per-thruster forces, N, put through each thruster's
    curve without the allocation (``hindrax thruster-test``): the ESC takes commands from this node only
    (:func:`hindrax_drivers.pca9685.core.command_source_fault`), so the thruster test comes through here. The same
    staleness rule as for wrenches applies to either stream.
Publishes
    ``thrusters/command_pulse_width`` (hindrax_msgs/ThrusterPwm): pulse widths for the ESC node, us.
    ``thrusters/forces`` (hindrax_msgs/ThrusterForces): thrust each thruster will produce, N. ``allocation/status``
    (hindrax_msgs/AllocationStatus): requested and achieved wrench (base_link), scale, per-thruster saturation,
    rejection reason. Pulse widths go out for every wrench; forces and status (display and bag) at most every
    :data:`STATUS_PERIOD_S` (5 Hz) with the latest allocation, and at once when rejected, the saturated thrusters or the
    kind of rejection change. The latest one is always sent: a held one goes out from the stale-check timer once the
    period has passed.

A NaN/inf wrench, a wrench with an empty frame_id or in another frame than ``base_link``, one without a
stamp (0: its age cannot be checked), a stale one (stamp older than ``thrusters.wrench_timeout_s`` by the node's
clock) or one stamped more than ``thrusters.wrench_future_margin_s`` in the future is rejected: the node commands
neutral (1500 us) and the status says why. If no wrench arrives for ``wrench_timeout_s`` the node commands neutral once
and reports ``stale``; the ESC node's watchdog is the second line of defence (docs/architecture.md §8).

The core (:class:`~hindrax_bringup.allocation.core.AllocationCore`) is built at start-up and rebuilt only
when a parameter changes, never per message. The thruster keys (geometry, curves, trims, limits, wrench timeout) are
applied while running; a change is refused while the ESC is armed or has not reported its state
(:class:`~hindrax_common.node_support.esc_state.ArmedWatch`), with the reason. Configuration: the vehicle file as ROS
parameters (``--ros-args --params-file ros_ws/config/hindrax.yaml``). Time: ROS time (``use_sim_time`` supported)."""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import Vector3, Wrench, WrenchStamped

from hindrax_msgs.msg import AllocationStatus, ThrusterForces, ThrusterPwm

from hindrax_common.node_support.esc_state import ArmedWatch
from hindrax_common.cdr.lean_cdr import cdr_decoder, prepare, thruster_pwm_encode, thruster_pwm_lean
from hindrax_common.node_support.liveness import heartbeat_qos
from hindrax_common.node_support.node_common import load_node_config, run_node, time_from_ns
from hindrax_common.node_support.vehicle_node import VehicleNode
from .allocator import InvalidWrenchError
from .core import AllocationCore

BASE_FRAME = "base_link"
#: least interval between two ``thrusters/forces`` / ``allocation/status`` without a change of state, s (5 Hz: a topside
#: display, the controller's anti-windup; a change of saturation or rejection goes out at once)
STATUS_PERIOD_S = 0.2
STATUS_PERIOD_NS = int(STATUS_PERIOD_S * 1e9)


def wrench_header_problem(frame_id: str, stamp_ns: int, now_ns: int, timeout_s: float, future_margin_s: float) -> str:
    """Why a wrench's header is refused ('' when it is fine): frame_id must be ``base_link`` (an empty one is not
    taken as base_link), the stamp non-zero, not older than ``timeout_s`` and not more than ``future_margin_s``
    ahead of ``now_ns`` (all ROS time)."""
    if frame_id != BASE_FRAME:
        return (f"wrench frame_id {frame_id!r} is not {BASE_FRAME!r}" if frame_id else
                f"wrench frame_id is empty (expected {BASE_FRAME!r})")
    if stamp_ns <= 0:
        return "wrench stamp is 0: its age cannot be checked"
    age_s = (now_ns - stamp_ns) * 1e-9
    if age_s > timeout_s:
        return f"stale wrench: {age_s:.3f} s old (limit {timeout_s:g} s)"
    if -age_s > future_margin_s:
        return (f"wrench stamped {-age_s:.3f} s in the future (limit thrusters.wrench_future_margin_s "
                f"{future_margin_s:g} s)")
    return ""


def _wrench_msg(w: np.ndarray) -> Wrench:
    fx, fy, fz, tx, ty, tz = np.asarray(w, dtype=float).tolist()
    return Wrench(force=Vector3(x=fx, y=fy, z=fz), torque=Vector3(x=tx, y=ty, z=tz))


#: Vehicle keys the allocation reads: thrusters, the CG the moments are taken about, the PCA9685 timing that
#: sets the pulse-width step (hindrax_bringup.allocation.from_config).
ALLOCATION_KEYS = ("thrusters", "vehicle.centre_of_gravity_frd_m", "esc.oscillator_hz", "esc.pwm_frequency_hz")


class ThrustAllocationNode(VehicleNode):
    """ROS wrapper of :class:`AllocationCore` (see the module docstring for topics and behaviour)."""

    def __init__(self, **kwargs: Any):
        super().__init__("thrust_allocation", **kwargs)
        # Thruster geometry, curves and weights are applied while running (ros2 param set); the PCA9685
        # timing that sets the pulse-width step and the CG need a restart. Not while armed (esc/output_state).
        self.armed = ArmedWatch()
        cfg = load_node_config(self, ALLOCATION_KEYS, dynamic=("thrusters",), on_change=self.on_configuration,
                               locked=self.armed.refusal)
        self.armed.subscribe(self)
        self.core = AllocationCore(cfg)
        self.timeout_s = cfg.thrusters.wrench_timeout_s
        self.future_margin_s = cfg.thrusters.wrench_future_margin_s
        #: the heartbeats' liveliness contract (1 s lease), which the ESC's subscription requires: a dead allocation
        #: stops counting as a live commander after 1 s (:func:`hindrax_drivers.pca9685.core.command_source_fault`)
        self.pub_pwm = self.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", heartbeat_qos())
        self.pub_forces = self.create_publisher(ThrusterForces, "thrusters/forces", 10)
        self.pub_status = self.create_publisher(AllocationStatus, "allocation/status", 10)
        #: ``wrench`` is taken as CDR bytes and decoded by rosbags (:mod:`hindrax_common.cdr.lean_cdr`: a lighter 50 Hz
        #: path than rclpy's message objects); :meth:`on_wrench` reads fields only, so it takes either form
        self._decode_wrench = cdr_decoder(WrenchStamped)
        prepare(ThrusterPwm)  # the commands' encoder: now, not in the first wrench's callback (lean_cdr.prepare)
        self.undecodable = 0
        self.create_subscription(WrenchStamped, "wrench", self.on_wrench_cdr, 10, raw=True)
        self.create_subscription(ThrusterForces, "thrusters/test_forces", self.on_test_forces, 10)
        #: ROS time of the last wrench received, ns (None before the first)
        self.last_wrench_ns: int | None = None
        self.stale_reported = True  # nothing to report before the first wrench
        self._held: tuple | None = None  # what the next forces and status carry, not yet published
        self._last_status_key: tuple = ()
        self._last_status_ns = -(1 << 62)
        #: the stale check, restarted by every wrench: it wakes the process only when wrenches stop (a held status
        #: then goes out from it), not 10 times a second beside the 50 Hz wrenches (docs/architecture.md §10.1), and
        #: it sleeps once the stop is reported and nothing is held (idle, it finds nothing to do)
        self.stale_timer = self.create_timer(max(0.02, self.timeout_s / 5.0), self.check_stale, autostart=False)

    # -- parameters: rebuild the core when a validated change of the thruster keys arrives
    def on_configuration(self, cfg) -> None:
        """Apply a validated configuration change (called by the parameter callback; raise to refuse)."""
        self.core.reconfigure(cfg)
        self.timeout_s = cfg.thrusters.wrench_timeout_s
        self.future_margin_s = cfg.thrusters.wrench_future_margin_s

    # -- wrench path
    def on_wrench_cdr(self, data: bytes) -> None:
        """A ``wrench`` as received (CDR bytes): decoded, then :meth:`on_wrench`. Bytes that do not decode as a
        ``WrenchStamped`` (a raw publisher's bug) are counted in :attr:`undecodable` and rejected: neutral."""
        try:
            msg = self._decode_wrench(data)
        except Exception as exc:  # noqa: BLE001 - rosbags raises several types for malformed CDR
            self.undecodable += 1
            self.reject(None, np.zeros(6), f"undecodable wrench ({len(data)} bytes: {type(exc).__name__})")
            return
        self.on_wrench(msg)

    def _input_arrived(self, now_ns: int) -> None:
        """A wrench or test forces came at ``now_ns`` (ns, the node's clock): the stale check starts over."""
        self.last_wrench_ns = now_ns
        self.stale_reported = False
        self.stale_timer.reset()

    def on_wrench(self, msg: WrenchStamped) -> None:
        """One wrench: an rclpy ``WrenchStamped`` or rosbags' decoding of one (fields are only read)."""
        now_ns = self.get_clock().now().nanoseconds
        f, t = msg.wrench.force, msg.wrench.torque
        w = np.array([f.x, f.y, f.z, t.x, t.y, t.z])
        self._input_arrived(now_ns)
        stamp = msg.header.stamp
        reason = wrench_header_problem(msg.header.frame_id, stamp.sec * 1_000_000_000 + stamp.nanosec, now_ns,
                                       self.timeout_s, self.future_margin_s)
        if reason:
            self.reject(msg, w, reason, now_ns)
            return
        try:
            result = self.core.allocate(w)
        except InvalidWrenchError as exc:
            self.reject(msg, w, str(exc), now_ns)
            return
        self.publish(msg, result.pulse_width_us, result.force_n, w, result.achieved_wrench_flu, result.scale,
                     result.saturated, rejected=False,
                     reason="saturated: scaled" if bool(np.any(result.saturated)) else "", now_ns=now_ns)

    def on_test_forces(self, msg: ThrusterForces) -> None:
        """Per-thruster test forces (``hindrax thruster-test``): widths from each curve, or neutral and the reason."""
        now_ns = self.get_clock().now().nanoseconds
        self._input_arrived(now_ns)
        n = len(self.core.names)
        try:
            widths = self.core.test_pulse_widths(msg.force_n)
        except InvalidWrenchError as exc:
            self.reject(None, np.zeros(6), f"thruster test: {exc}", now_ns)
            return
        force = np.asarray(msg.force_n, dtype=float)
        self.publish(None, widths, force, np.zeros(6), np.zeros(6), 1.0, np.zeros(n, bool), rejected=False,
                     reason="thruster test", now_ns=now_ns)

    def reject(self, msg: WrenchStamped | None, requested: np.ndarray, reason: str, now_ns: int | None = None) -> None:
        """Command neutral and report why (``now_ns``: ROS time of the decision, ns; read when None)."""
        self.get_logger().warn(f"wrench rejected: {reason}", throttle_duration_sec=1.0)
        n = len(self.core.names)
        req = np.where(np.isfinite(requested), requested, 0.0)
        self.publish(msg, self.core.neutral(), np.zeros(n), req, np.zeros(6), 0.0, np.zeros(n, bool),
                     rejected=True, reason=reason, now_ns=now_ns)

    def check_stale(self) -> None:
        now_ns = self.get_clock().now().nanoseconds
        if self._held is not None and now_ns - self._last_status_ns >= STATUS_PERIOD_NS:
            self._send_status(now_ns)
        if self.last_wrench_ns is not None and not self.stale_reported:
            age_s = (now_ns - self.last_wrench_ns) * 1e-9
            if age_s > self.timeout_s:
                self.stale_reported = True
                self.reject(None, np.zeros(6), f"stale: no wrench for {age_s:.3f} s (limit {self.timeout_s:g} s)",
                            now_ns)
        if self.stale_reported and self._held is None:
            self.stale_timer.cancel()  # nothing left to check or send: the next wrench restarts it

    def publish(self, msg: WrenchStamped | None, pulse_width_us: np.ndarray, force_n: np.ndarray,
                requested: np.ndarray, achieved: np.ndarray, scale: float, saturated: np.ndarray,
                rejected: bool, reason: str, now_ns: int | None = None) -> None:
        """Send the command on ``thrusters/command_pulse_width`` and hold the forces and
        status; they are sent now when the state changed or :data:`STATUS_PERIOD_S` has passed, else later by
        :meth:`check_stale`. The held messages are built only when sent (at most 10 Hz of the 50 Hz commands)."""
        if now_ns is None:
            now_ns = self.get_clock().now().nanoseconds
        if msg is not None and (msg.header.stamp.sec or msg.header.stamp.nanosec):
            stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        else:
            stamp_ns = now_ns
        # the command's CDR is published as bytes (50 Hz without an rclpy object, hindrax_common.cdr.lean_cdr)
        self.pub_pwm.publish(thruster_pwm_encode(thruster_pwm_lean(stamp_ns, BASE_FRAME, pulse_width_us, not rejected)))
        saturated = np.asarray(saturated, dtype=bool)
        self._held = (stamp_ns, np.asarray(force_n, dtype=float), np.asarray(requested, dtype=float),
                      np.asarray(achieved, dtype=float), float(scale), saturated, rejected, reason)
        key = (rejected, saturated.tobytes(), reason.split(":", 1)[0])
        if key != self._last_status_key or now_ns - self._last_status_ns >= STATUS_PERIOD_NS:
            self._last_status_key = key
            self._send_status(now_ns)

    def _send_status(self, now_ns: int) -> None:
        """Build and publish the held forces and status (ROS time ``now_ns``, ns)."""
        if self._held is None:
            return
        stamp_ns, force_n, requested, achieved, scale, saturated, rejected, reason = self._held
        self._held = None
        stamp = time_from_ns(stamp_ns)  # the command's stamp
        self._last_status_ns = now_ns
        forces = ThrusterForces(force_n=force_n.tolist())
        forces.header.stamp, forces.header.frame_id = stamp, BASE_FRAME
        st = AllocationStatus(requested_wrench=_wrench_msg(requested), achieved_wrench=_wrench_msg(achieved),
                              scale=scale, thruster_saturated=saturated.tolist(),
                              saturated=bool(saturated.any()), rejected=rejected, reason=reason)
        st.header.stamp, st.header.frame_id = stamp, BASE_FRAME
        self.pub_forces.publish(forces)
        self.pub_status.publish(st)


def main(args=None) -> int:
    """``python -m hindrax_bringup.allocation.node --ros-args --params-file ros_ws/config/hindrax.yaml``."""
    return run_node(ThrustAllocationNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
