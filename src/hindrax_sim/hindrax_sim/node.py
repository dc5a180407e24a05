"""ROS 2 node of the virtual pool: steps :class:`~.simulator.Simulator`, publishes /clock and ground truth.

Run alone: ``python -m hindrax_sim.node --ros-args --params-file ros_ws/config/hindrax.yaml``.

Interfaces
----------
Subscribes (default pulse-width source)
    ``thrusters/pulse_width`` (hindrax_msgs/ThrusterPwm): wire pulse widths in thruster order; ``armed``
    false means neutral. The last valid message is held (a real PWM generator keeps its output).
    Messages with the wrong length or non-finite values are ignored with a one-line warning.
Publishes
    ``/clock`` (rosgraph_msgs/Clock) at ``simulation.clock_rate_hz`` of simulated time; ``sim/odometry``
    (nav_msgs/Odometry): pose of base_link in odom (ENU, origin at the pool corner on the surface), twist
    in base_link (FLU), converted with :mod:`hindrax_common.base.frames`; covariances zero (exact ground
    truth); ``sim/wrench`` (geometry_msgs/WrenchStamped, base_link FLU): the true thruster wrench about
    base_link; ``sim/contact`` (diagnostic_msgs/DiagnosticArray): one status per pool face
    (``sim/contact/<face>``, WARN while touching, value ``since_s``), on every change and once per
    simulated second. Ground truth is for evaluation only: no node under test may read ``sim/*``.
Parameters
    The vehicle configuration (``--params-file hindrax.yaml``; or ``config_file``; or the shipped file). Node-specific:
    ``truth_rate_hz`` (simulated-time rate of sim/odometry and sim/wrench, default ``simulation.clock_rate_hz``).

Time: the node steps the model from a timer on the steady (wall) clock, never on its own /clock. With
``simulation.real_time_factor`` r > 0 the simulated time follows ``r`` x the wall time (if the machine cannot
keep up, it re-anchors and warns). With r = 0 it runs as fast as possible: each timer callback advances
one whole /clock period of simulated time and returns to the executor, so that other nodes in the same
SingleThreadedExecutor (e.g. nodes under test using ``use_sim_time``) run between clock ticks and see every
/clock message. (It never stops inside a period: an in-process emulator sampling the vehicle between two
ticks would then see a state ahead of the clock by an amount that depends on the machine's load.)

Lock-step (``add_step_gate(gate)``): a gate is a callable ``gate(t_s) -> bool`` asked at every /clock boundary whether
simulated time may advance past ``t_s``; while one says no, the node does not step (and checks again at its next timer
callback). In one process with the identification node this keeps the control loop on every control tick whatever the
CPU load (a loaded machine otherwise lets the simulation run ahead of the controller, which then overshoots its planned
runs). On its timer, a gate that has refused for :data:`GATE_TIMEOUT_S` of wall time is overridden with a warning, so a
stalled node cannot freeze the simulation; stepped by its caller (:meth:`SimulatorNode.advance_clock_period`, the
lock-step graph of ``hindrax run``) it holds on, warning every :data:`GATE_TIMEOUT_S`: what happens at each simulated
instant then never depends on wall time (the caller's own wall-clock deadlines end a run that stalls).

Python API for in-process device emulators: ``node.simulator`` (its sensor listeners and latest
samples), :meth:`SimulatorNode.add_step_listener`, :meth:`SimulatorNode.add_clock_listener` and the
``pulse_width_source`` argument (:class:`SimulatorNode`)."""
from __future__ import annotations

import math
import sys
import time
from typing import Any, Callable, Sequence

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.qos import QoSProfile
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMsg

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig
from hindrax_common.node_support.node_common import load_node_config, run_node
from hindrax_common.node_support.vehicle_node import VehicleNode
from hindrax_msgs.msg import ThrusterPwm

from .pool import FACES
from .simulator import PulseWidthError, Simulator, fill_odometry, fill_wrench

__all__ = ["SimulatorNode", "PulseWidthSource", "time_msg", "main"]

#: A pulse-width source: () -> widths (n,) in us, or None to keep the previous widths.
PulseWidthSource = Callable[[], "Sequence[float] | None"]
#: Largest lag behind the real-time schedule before re-anchoring, simulated s.
_MAX_LAG_S = 0.5
#: Wall time a step gate may hold the simulation on the node's timer before it is overridden (with a warning), s.
GATE_TIMEOUT_S = 10.0


def time_msg(t_s: float) -> TimeMsg:
    """builtin_interfaces/Time of a simulated time t_s >= 0 (s), rounded to the nanosecond."""
    sec, nsec = divmod(int(round(t_s * 1e9)), 1_000_000_000)
    return TimeMsg(sec=sec, nanosec=nsec)


class SimulatorNode(VehicleNode):
    """Thin rclpy node over :class:`Simulator` (module docstring).

    config: a VehicleConfig (default: from the node's parameters, see
    :func:`~hindrax_common.node_support.node_common.load_node_config`). pulse_width_source: optional callable replacing
    the ThrusterPwm subscription, called before every step: the widths (n,) in us the ESCs see (e.g. decoded from the
    PCA9685 emulator; None keeps the previous ones). simulator: optional prebuilt Simulator (must use ``config``). Other
    keyword arguments go to ``Node``. Raises :class:`ConfigError` for an invalid configuration (logged as one line
    first)."""

    def __init__(self, *, config: VehicleConfig | None = None, pulse_width_source: PulseWidthSource | None = None,
                 simulator: Simulator | None = None, node_name: str = "hindrax_simulator", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        log = self.get_logger()
        self.config = config if config is not None else load_node_config(self)
        self.simulator = simulator if simulator is not None else Simulator(self.config)
        sim = self.config.simulation
        self.real_time_factor = float(sim.real_time_factor)
        self.clock_period_s = 1.0 / float(sim.clock_rate_hz)
        if not self.has_parameter("truth_rate_hz"):
            self.declare_parameter("truth_rate_hz", float(sim.clock_rate_hz), ParameterDescriptor(
                description="rate of the ground-truth topics (sim/odometry, sim/wrench), Hz (default: the clock rate)",
                read_only=True))
        truth_rate = float(self.get_parameter("truth_rate_hz").value)
        if not (math.isfinite(truth_rate) and truth_rate > 0.0):
            log.error(f"truth_rate_hz = {truth_rate}: allowed a positive number; using the clock rate")
            truth_rate = float(sim.clock_rate_hz)
        self.truth_period_s = 1.0 / truth_rate

        self._n = self.simulator.thrusters.n
        self._pulse_widths = np.full(self._n, self.simulator.thrusters.neutral_us)
        self._armed = True
        self._source = pulse_width_source
        self._step_listeners: list[Callable[[Simulator], None]] = []
        self._clock_listeners: list[Callable[[float], None]] = []
        self._gates: list[Callable[[float], bool]] = []
        self._driven_clocks: list = []
        #: False: /clock is not published (every consumer in the process is driven through drive_clock)
        self.publish_clock_topic = True
        self._gate_blocked_since: float | None = None
        self._next_clock = 0.0
        self._next_truth = 0.0
        self._next_contact = 0.0
        self._last_faces: tuple[str, ...] | None = None
        self._last_bad_warning = -math.inf

        self._pub_clock = self.create_publisher(ClockMsg, "/clock", QoSProfile(depth=1))
        self._pub_odom = self.create_publisher(Odometry, "sim/odometry", 10)
        self._pub_wrench = self.create_publisher(WrenchStamped, "sim/wrench", 10)
        self._pub_contact = self.create_publisher(DiagnosticArray, "sim/contact", 10)
        if pulse_width_source is None:
            self.create_subscription(ThrusterPwm, "thrusters/pulse_width", self._on_pulse_width, 10)

        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._wall_anchor = time.monotonic()
        self._sim_anchor = self.simulator.t_s
        period = 0.0 if self.real_time_factor <= 0.0 else \
            max(0.001, min(0.01, self.clock_period_s / self.real_time_factor))
        self._timer = self.create_timer(period, self._on_timer, clock=self._steady)
        self._publish_due()
        log.info(f"virtual pool running: step {self.simulator.step_s * 1e3:g} ms, real-time factor "
                 f"{self.real_time_factor:g} (0 = as fast as possible), /clock at {1 / self.clock_period_s:g} Hz")

    # ------------------------------------------------------------------ API
    def add_step_listener(self, callback: Callable[[Simulator], None]) -> None:
        """Call ``callback(simulator)`` after every integration step."""
        self._step_listeners.append(callback)

    def add_clock_listener(self, callback: Callable[[float], None]) -> None:
        """Call ``callback(t_s)`` at every /clock tick (simulated time ``t_s``, s), after the driven clocks show
        ``t_s`` and /clock is published: the instant an in-process emulator sends what is due, so that a driver
        reading it sees the same time on its own clock."""
        self._clock_listeners.append(callback)

    @property
    def pulse_widths_us(self) -> np.ndarray:
        """The pulse widths currently applied (n,), us."""
        return self._pulse_widths.copy()

    # ------------------------------------------------------------------ input
    def _on_pulse_width(self, msg: ThrusterPwm) -> None:
        pw = np.asarray(msg.pulse_width_us, dtype=float)
        if pw.shape != (self._n,) or not np.all(np.isfinite(pw)):
            self._warn_bad(f"ignored thrusters/pulse_width: need {self._n} finite pulse widths (us), "
                           f"got {pw.size} value(s)")
            return
        self._pulse_widths = pw
        self._armed = bool(msg.armed)

    def _warn_bad(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_bad_warning > 2.0:
            self._last_bad_warning = now
            self.get_logger().warning(text)

    def _poll_source(self) -> None:
        try:
            value = self._source()  # type: ignore[misc]
        except Exception as exc:  # noqa: BLE001 - an emulator fault must not stop the simulation
            self._warn_bad(f"pulse-width source failed: {exc}")
            return
        if value is None:
            return
        pw = np.asarray(value, dtype=float).reshape(-1)
        if pw.shape != (self._n,) or not np.all(np.isfinite(pw)):
            self._warn_bad(f"ignored pulse widths from the source: need {self._n} finite values, got {value!r}")
            return
        self._pulse_widths = pw

    # ------------------------------------------------------------------ stepping
    def _step_once(self) -> None:
        if self._source is not None:
            self._poll_source()
        try:
            self.simulator.step(self._pulse_widths, armed=self._armed)
        except PulseWidthError as exc:  # validated above; kept as a guard
            self._warn_bad(str(exc))
            self._pulse_widths = np.full(self._n, self.simulator.thrusters.neutral_us)
            return
        for cb in self._step_listeners:
            cb(self.simulator)
        self._publish_due()

    def drive_clock(self, clock) -> None:
        """Set the ROS time of ``clock`` (an rclpy ROS_TIME clock with ``use_sim_time`` active, e.g. another node's
        ``get_clock()`` in this process) at every /clock tick, directly: the in-process alternative to each node
        taking /clock from DDS (``rclpy.clock.ROSClock.set_ros_time_override``, what a TimeSource does on each
        /clock message). All driven clocks change together, before any node runs; with every in-process node
        driven, ``publish_clock_topic = False`` saves the /clock messages (a large share of the
        one-process graph's messages)."""
        self._driven_clocks.append(clock)

    def add_step_gate(self, gate: Callable[[float], bool]) -> None:
        """Lock-step with another node: ``gate(t_s)`` must be True for time to advance past ``t_s`` (module
        docstring)."""
        self._gates.append(gate)

    def _gates_open(self, override: bool) -> bool:
        """True when every gate lets the time advance, or (``override``) they have refused for longer than
        :data:`GATE_TIMEOUT_S` of wall time."""
        t = self.simulator.t_s
        if all(g(t) for g in self._gates):
            self._gate_blocked_since = None
            return True
        now = time.monotonic()
        if self._gate_blocked_since is None:
            self._gate_blocked_since = now
        elif now - self._gate_blocked_since > GATE_TIMEOUT_S:
            self.get_logger().warn(f"a step gate held simulated time {t:.2f} s for {GATE_TIMEOUT_S:g} s of wall time; "
                                   + ("stepping on" if override else "holding on"), throttle_duration_sec=10.0)
            self._gate_blocked_since = None
            return override
        return False

    def _at_clock_boundary(self) -> bool:
        t = self.simulator.t_s
        k = round(t / self.clock_period_s)
        return abs(t - k * self.clock_period_s) < 0.25 * self.simulator.step_s

    # ------------------------------------------------------------------ stepping by the caller
    def advance_clock_period(self, override_gates: bool = False) -> bool:
        """Step to the next /clock tick (one whole period), unless a step gate holds the time: returns False then
        (however long it holds, unless ``override_gates``: the node's timer, module docstring). For a caller that
        drives the simulation itself instead of the timer (the node is then not added to an executor;
        :meth:`hindrax_sim.graph.bringup.Graph.spin_once`)."""
        if self._gates and self._at_clock_boundary() and not self._gates_open(override_gates):
            if self.real_time_factor > 0.0:  # the wall clock keeps running: do not try to catch up afterwards
                self._wall_anchor, self._sim_anchor = time.monotonic(), self.simulator.t_s
            return False
        end, dt = self._next_clock, self.simulator.step_s
        while self.simulator.t_s + 0.5 * dt < end:
            self._step_once()
        return True

    def wall_time_until_next_tick_s(self) -> float:
        """Wall time until the next /clock tick is due at ``simulation.real_time_factor`` (<= 0: due now; always 0
        when running as fast as possible). Re-anchors (with a warning) when the simulation lags more than 0.5 s."""
        if self.real_time_factor <= 0.0:
            return 0.0
        now = time.monotonic()
        target = self._sim_anchor + (now - self._wall_anchor) * self.real_time_factor
        if target - self.simulator.t_s > _MAX_LAG_S:
            self._warn_bad(f"simulation cannot keep real_time_factor {self.real_time_factor:g}; re-anchoring")
            self._wall_anchor, self._sim_anchor = now, self.simulator.t_s
            target = self._sim_anchor
        return (self._next_clock - 0.5 * self.simulator.step_s - target) / self.real_time_factor

    def _on_timer(self) -> None:
        start = time.monotonic()
        if self.real_time_factor <= 0.0:
            # one /clock period of simulated time, then back to the executor (other nodes run in between)
            self.advance_clock_period(override_gates=True)
            return
        # whole /clock periods only (module docstring), up to the last tick due on the wall clock
        while self.wall_time_until_next_tick_s() <= 0.0 and self.advance_clock_period(override_gates=True):
            if time.monotonic() - start > 0.05:  # keep the executor responsive
                break

    # ------------------------------------------------------------------ output
    def _publish_due(self) -> None:
        sim = self.simulator
        t = sim.t_s
        eps = 1e-9
        if t + eps >= self._next_clock:
            if self._driven_clocks:
                now = Time(nanoseconds=int(round(t * 1e9)), clock_type=ClockType.ROS_TIME)
                for c in self._driven_clocks:
                    c.set_ros_time_override(now)
            if self.publish_clock_topic:
                self._pub_clock.publish(ClockMsg(clock=time_msg(t)))
            self._next_clock = (math.floor((t + eps) / self.clock_period_s) + 1) * self.clock_period_s
            for cb in self._clock_listeners:
                cb(t)
        if t + eps >= self._next_truth:
            self._publish_truth(t)
            self._next_truth = (math.floor((t + eps) / self.truth_period_s) + 1) * self.truth_period_s
        faces = sim.contact.faces
        if faces != self._last_faces or t + eps >= self._next_contact:
            self._publish_contact(t)
            self._last_faces = faces
            self._next_contact = math.floor(t + eps) + 1.0

    def _publish_truth(self, t: float) -> None:
        sim = self.simulator
        stamp = time_msg(t)
        twist = frames.twist_frd_to_flu(sim.nu)
        odom = fill_odometry(Odometry(), sim.position_ned_m, sim.quaternion_xyzw, twist)
        odom.header.stamp = stamp
        self._pub_odom.publish(odom)
        msg = WrenchStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = "base_link"
        fill_wrench(msg.wrench, frames.wrench_frd_to_flu(sim.wrench_frd))
        self._pub_wrench.publish(msg)

    def _publish_contact(self, t: float) -> None:
        contact = self.simulator.contact
        arr = DiagnosticArray()
        arr.header.stamp = time_msg(t)
        arr.header.frame_id = "odom"
        for face in FACES:
            st = DiagnosticStatus(name=f"sim/contact/{face}", hardware_id="virtual_pool")
            if face in contact.since_s:
                st.level = DiagnosticStatus.WARN
                st.message = "in contact"
                st.values = [KeyValue(key="since_s", value=f"{contact.since_s[face]:.3f}")]
            else:
                st.level = DiagnosticStatus.OK
                st.message = "clear"
            arr.status.append(st)
        self._pub_contact.publish(arr)


def main(args: Sequence[str] | None = None) -> int:
    """Run the simulator node alone (``python -m hindrax_sim.node --ros-args --params-file ...``)."""
    return run_node(SimulatorNode, args)


if __name__ == "__main__":
    sys.exit(main())
