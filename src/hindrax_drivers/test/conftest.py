"""Fixtures the sensor node tests share (test_ms5837_node.py, test_icm20948_node.py on the emulated I2C bus,
test_dvl75_node.py, test_ping1d_node.py on a pty): the node under test with a probe node in one executor, a simulated
/clock, and the node run as a process (without its bus, or on its device)."""
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from hindrax_common.config import default_config_path
from hindrax_common.testing import child_env, child_process, interrupt, ros_context, wait_until


class NodeProbe:
    """The node under test and a probe node spun by one executor. The :func:`rig` fixture mixes it into the test
    module's ``Rig``, which builds its emulator, bus and node and then calls :meth:`start`."""

    def start(self, ctx, node, diag_name):
        """Spin ``node`` with a new probe node; ``diag`` collects the /diagnostics statuses named ``diag_name``."""
        self.node = node
        self.probe = rclpy.create_node("probe", context=ctx)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(node)
        self.ex.add_node(self.probe)
        self.diag = []
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.diag.extend(
            s for s in m.status if s.name == diag_name), 50)

    def collect(self, msg_type, topic, depth):
        """The list the probe appends each ``topic`` message to."""
        got = []
        self.probe.create_subscription(msg_type, topic, got.append, depth)
        return got

    def spin(self):
        self.ex.spin_once(timeout_sec=0.01)

    def wait(self, predicate, timeout=10.0, message="condition"):
        return wait_until(predicate, timeout, self.spin, message)

    def clock_ticker(self, sim, step_s=0.002):
        """A simulator: each call advances ``sim["t"]`` (s) by ``step_s``, publishes it on /clock and spins once."""
        pub = self.probe.create_publisher(Clock, "/clock", 10)

        def tick():
            sim["t"] += step_s
            sec = int(sim["t"])
            pub.publish(Clock(clock=Time(sec=sec, nanosec=int(round((sim["t"] - sec) * 1e9)))))
            self.spin()
        return tick

    def wall_clock_ticker(self, sim):
        """For an emulator on wall time (a pty's): each call sets ``sim["t"]`` (s) to its value at the first call plus
        the wall time since, publishes it on /clock and spins once."""
        pub = self.probe.create_publisher(Clock, "/clock", 10)
        t0, m0 = sim["t"], time.monotonic()

        def tick():
            sim["t"] = t0 + (time.monotonic() - m0)
            pub.publish(Clock(clock=rclpy.time.Time(nanoseconds=int(sim["t"] * 1e9)).to_msg()))
            self.spin()
        return tick

    @staticmethod
    def quiet_stuck_detector(extra_params):
        """``extra_params`` (rclpy parameters) with ``stuck_limit_samples`` 1000 unless they set it: a constant truth
        gives bit-identical reports (a real sensor's never are), so only a test that sets it sees the detector fire."""
        if any(p.name == "stuck_limit_samples" for p in extra_params):
            return list(extra_params)
        return [*extra_params, Parameter("stuck_limit_samples", value=1000)]

    def close(self):
        self.ex.shutdown()
        self.probe.destroy_node()
        self.node.destroy_node()


@pytest.fixture
def rig(request):
    """``rig(*args, **kwargs)``: the test module's ``Rig(ctx, *args, **kwargs)`` with :class:`NodeProbe` mixed in,
    in an isolated rclpy context; every rig made is closed at the end."""
    cls = type("Rig", (request.module.Rig, NodeProbe), {})
    rigs = []
    with ros_context() as ctx:
        def make(*args, **kwargs):
            rigs.append(cls(ctx, *args, **kwargs))
            return rigs[-1]
        yield make
        for r in rigs:
            r.close()


def run_node_process(cmd, msg_type, topic, enough, what, timeout_s=30.0, **popen):
    """Run ``cmd`` (a node's process) until a probe has ``enough(messages)`` of ``topic`` (``msg_type``) within
    ``timeout_s``; asserts the process is still up then and exits 0 on SIGINT. Returns the messages."""
    popen = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, "text": True, **popen}
    with child_process(cmd, env=child_env(), **popen) as proc, ros_context() as ctx:
        probe = rclpy.create_node("probe_main", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(probe)
        got = []
        probe.create_subscription(msg_type, topic, got.append, 10)
        wait_until(lambda: enough(got) or proc.poll() is not None, timeout_s, lambda: ex.spin_once(timeout_sec=0.05),
                   what)
        assert proc.poll() is None, (proc.stderr or proc.stdout).read()
        ex.shutdown()
        probe.destroy_node()
        assert interrupt(proc, 15) == 0
    return got


@pytest.fixture
def node_process():
    """:func:`run_node_process` (``cmd``, ``msg_type``, ``topic``, ``enough``, ``what``)."""
    return run_node_process


@pytest.fixture
def runs_without_its_bus():
    """``runs_without_its_bus(device)``: ``python -m hindrax_drivers.<device>.node --ros-args --params-file
    hindrax.yaml`` on I2C bus 31, which this machine lacks; asserts that the node stays up, reports ``cannot open I2C
    bus 31`` as an ERROR in /diagnostics, and exits 0 on SIGINT."""
    def run(device):
        cmd = [sys.executable, "-m", f"hindrax_drivers.{device}.node", "--ros-args", "--params-file",
               str(default_config_path()), "-p", f"sensors.{device}.i2c_bus:=31"]
        assert not os.path.exists("/dev/i2c-31")
        run_node_process(cmd, DiagnosticArray, "/diagnostics", lambda got: any(
            "cannot open I2C bus 31" in s.message and s.level == DiagnosticStatus.ERROR for a in got for s in a.status),
            "bus error in diagnostics", 20.0, cwd=Path(__file__).resolve().parents[3], stderr=subprocess.STDOUT)
    return run
