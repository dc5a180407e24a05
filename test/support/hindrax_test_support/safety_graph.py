"""The ESC node and the safety supervisor on a /clock the test drives: the set-up of the supervisor's graph test
(``hindrax_bringup``) and of the identification-abort test (``hindrax_sim``)."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.executors import ShutdownException, SingleThreadedExecutor, TimeoutException
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, Range
from std_srvs.srv import Trigger

from hindrax_msgs.msg import Dvl, ThrusterPwm
from hindrax_msgs.srv import SetArmed

from hindrax_bringup.supervisor.node import SupervisorNode
from hindrax_common.testing import AllocationStandIn, SafetyHeartbeats, config_parameters, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode

class SafetyGraph:
    """In the rclpy context ``ctx``, on simulated time: the ESC node on an emulated PCA9685 (:attr:`emu`) and the
    supervisor, both with the vehicle-file ``overrides``; a probe node with the output guard's healthy heartbeat (the
    supervisor is real), publishers of /clock and the sensors (:attr:`pubs`: ``clock``, ``dvl``, ``alt``, ``depth``,
    ``imu``, and ``cmd`` of the allocation stand-in, the one commander the ESC accepts), the ``esc/set_armed`` and
    ``supervisor/reset`` clients and the ``supervisor/status`` messages (:attr:`statuses`); one executor. Simulated
    time :attr:`ns` (ns) starts at 1 s and moves only by :meth:`advance`.

    The supervisor's ``clock_stall_timeout_s`` (steady s) is ``clock_stall_timeout_s``: by default 30 s, as the
    simulated launch holds it (``hindrax_sim.graph.bringup.SIMULATED_TIME_HOLD_S``), for the test steps simulated
    time itself and on a loaded machine a step can come more than a rate window late (a fresh clone's suite: 1.1 s)."""

    def __init__(self, ctx: Any, overrides: dict[str, Any], clock_stall_timeout_s: float = 30.0) -> None:
        self.emu = Pca9685Emulator()
        params = config_parameters(overrides) + [Parameter("use_sim_time", value=True)]
        self.esc = EscNode(bus=EmulatedI2CBus({0x40: self.emu}), context=ctx, parameter_overrides=params)
        self.sup = SupervisorNode(context=ctx, parameter_overrides=params + [
            Parameter("clock_stall_timeout_s", value=float(clock_stall_timeout_s))])
        self.probe = rclpy.create_node("probe", context=ctx)
        SafetyHeartbeats(self.probe, supervisor=None)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.nodes: list = []
        for n in (self.esc, self.sup, self.probe):
            self.add(n)
        self.allocation = AllocationStandIn(ctx)
        pub = self.probe.create_publisher
        self.pubs = {"clock": pub(Clock, "/clock", 10), "cmd": self.allocation.pub, "dvl": pub(Dvl, "dvl/data", 10),
                     "alt": pub(Range, "ping/altitude", 10), "imu": pub(Imu, "imu/data_raw", 10),
                     "depth": pub(PoseWithCovarianceStamped, "pressure/depth", 10)}
        self.arm = self.probe.create_client(SetArmed, "esc/set_armed")
        self.reset = self.probe.create_client(Trigger, "supervisor/reset")
        self.statuses: list = []
        self.probe.create_subscription(DiagnosticStatus, "supervisor/status", self.statuses.append, 10)
        self.ns = 1_000_000_000

    def add(self, node: Any) -> Any:
        """Spin ``node`` in the graph's executor too (destroyed by :meth:`close`)."""
        self.ex.add_node(node)
        self.nodes.append(node)
        return node

    def stamp(self, lag_ns: int = 0) -> Any:
        """A header stamp of simulated time now, ``lag_ns`` ns old."""
        stamp = Clock().clock
        stamp.sec, stamp.nanosec = divmod(self.ns - lag_ns, 1_000_000_000)
        return stamp

    def spin_idle(self) -> None:
        """Run callbacks until none is ready (as hindrax_sim.graph.bringup.Graph.spin_until_idle)."""
        for _ in range(10_000):
            try:
                handler, _entity, _node = self.ex.wait_for_ready_callbacks(0.0)
            except (TimeoutException, ShutdownException):
                return
            handler()

    def advance(self, dt_s: float) -> None:
        """Advance /clock by ``dt_s`` s and let every node run."""
        self.ns += int(dt_s * 1e9)
        c = Clock()
        c.clock.sec, c.clock.nanosec = divmod(self.ns, 1_000_000_000)
        self.pubs["clock"].publish(c)
        self.ex.spin_once(timeout_sec=0.01)
        self.spin_idle()

    def spin_once(self) -> None:
        self.ex.spin_once(timeout_sec=0.01)

    def call(self, client: Any, request: Any, spin: Callable[[], Any] | None = None, timeout_s: float = 10.0) -> Any:
        """``client``'s answer to ``request``, spinning with ``spin`` (default: the executor, time held)."""
        fut = client.call_async(request)
        wait_until(fut.done, timeout_s, spin or self.spin_once, "service answer")
        return fut.result()

    def wait_ready(self, step: Callable[[], Any], *also: Callable[[], bool]) -> None:
        """Until every publisher is matched, the services are up and ``also`` hold, calling ``step``."""
        wait_until(lambda: all(p.get_subscription_count() > 0 for p in self.pubs.values())
                   and self.arm.service_is_ready() and self.reset.service_is_ready()
                   and self.sup.esc_client.service_is_ready() and all(c() for c in also), 30, step, "graph ready")

    def wire(self) -> np.ndarray:
        """The eight channels' pulse widths on the emulated chip, us."""
        return np.array([self.emu.pulse_width_us(c) for c in range(8)])

    def arm_with_thrust(self, step: Callable[[], Any], also: Callable[[], bool] = lambda: True) -> None:
        """120 ``step``s of sensors (a whole supervisor rate window at 10 ms steps) before arming, the ESC's shortest
        time at neutral with the guard's OK (GUARD_CONFIRM_S, steady clock; simulated time held), arm, then 1700 us
        commanded until it is on the wire and the supervisor (and ``also``) sees armed."""
        for _ in range(120):
            step()
        wait_until(lambda: self.esc.arming_remaining_s() == 0.0, 5, self.spin_once, "ESC time at neutral")
        assert self.call(self.arm, SetArmed.Request(arm=True)).success

        def thrust() -> None:
            self.pubs["cmd"].publish(ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True))
            step()
        wait_until(lambda: self.wire()[0] > 1690 and self.sup.core.armed and also(), 10, thrust,
                   "armed, thrust on the wire")

    def close(self) -> None:
        self.ex.shutdown()
        for n in (self.allocation.node, *reversed(self.nodes)):
            n.destroy_node()
