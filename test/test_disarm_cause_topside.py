"""The cause of a disarm reaches the topside in one line with the next step (supervisor/disarm_cause.py).

The vehicle's emulated safety layout (ESC, supervisor and output guard each in its own process, the PCA9685 and its
/OE line served by this process: :mod:`hindrax_tools.benchmarks.safety`), armed at 1700 us,
with the gateway
process relaying to a topside domain of its own; a probe there reads ``/<vehicle>/supervisor/status`` as the
operator's tools do. Three stops, each from a fresh arming: a tripped limit (a depth beyond
``supervisor.max_depth_m``), a guard silence (the ESC process stopped, SIGSTOP, until the guard has cut the outputs,
then continued: its beats were late, not lost) and a killed ESC (SIGKILL: its last armed state stays latched, only
the guard's beat says that the outputs were silenced). Before, the topside saw the supervisor "within the envelope"
for the last two, and the cause only in the Pi's log.
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from hindrax_test_support.helpers import fresh_domain
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.config import load_config
from hindrax_bringup.gateway.operator_signing import create_key
from hindrax_common.testing import child_process, interrupt, ros_context, wait_until
from hindrax_tools.benchmarks.safety import running_layout

pytestmark = [pytest.mark.vehicle_launch, pytest.mark.ros, pytest.mark.timeout(600)]

WAIT_S = 30.0  # generous: a loaded two-core machine


@pytest.fixture(scope="module")
def topside():
    """(layout, probe on the topside domain, the statuses it read, its executor)."""
    with running_layout("hindrax-cause-", int(os.environ["ROS_DOMAIN_ID"])) as lay, \
            fresh_domain() as top, ros_context(domain_id=top) as ctx, \
            contextlib.ExitStack() as stack:
        name = load_config(lay.config).get("vehicle.name")
        create_key(lay.tmp / "keys" / f"{name}.key")  # the operator's key, on "both sides" (one folder here)
        lay.env = dict(lay.env, HINDRAX_KEYS_DIR=str(lay.tmp / "keys"))
        log = stack.enter_context(open(lay.tmp / "gateway.log", "w"))
        gateway = stack.enter_context(child_process(
            [lay.py, "-m", "hindrax_bringup.gateway.node", "--ros-args", "--params-file", lay.config, "-p",
             f"topside_domain_id:={top}", "-p", "topside_discovery_range:=LOCALHOST"], env=lay.env, stdout=log,
            stderr=subprocess.STDOUT))
        probe = rclpy.create_node("topside_operator", context=ctx)
        seen: list = []
        probe.create_subscription(DiagnosticStatus, f"/{name}/supervisor/status", seen.append, 50)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(probe)
        lay.topside_domain, lay.vehicle_name = top, name
        try:
            yield lay, seen, executor
        finally:
            try:
                interrupt(gateway, 10)
            except subprocess.TimeoutExpired:
                pass  # child_process kills it
            executor.shutdown()
            probe.destroy_node()


def _cause_on_topside(seen: list, executor, *words: str) -> str:
    """Wait until a topside supervisor/status carries a ``disarm_cause`` with every one of ``words``; returns it."""
    def found() -> str:
        for st in reversed(seen):
            cause = next((kv.value for kv in st.values if kv.key == "disarm_cause"), "")
            if cause and all(w in cause for w in words):
                return cause
        return ""
    seen.clear()
    try:
        wait_until(found, WAIT_S, lambda: executor.spin_once(timeout_sec=0.05), f"disarm cause with {words}")
    except Exception as exc:
        last = [next((kv.value for kv in st.values if kv.key == "disarm_cause"), "") for st in seen[-3:]]
        raise AssertionError(f"{exc}; the last causes on the topside: {last}") from exc
    return found()


def test_a_tripped_limit_is_named_on_the_topside(topside):
    lay, seen, executor = topside
    lay.armed_at_1700()
    pub = lay.probe.create_publisher(PoseWithCovarianceStamped, "pressure/depth", 10)
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = lay.probe.get_clock().now().to_msg()
    msg.pose.pose.position.z = -9.0  # 9 m down: beyond any pool's supervisor.max_depth_m
    pub.publish(msg)
    cause = _cause_on_topside(seen, executor, "supervisor: depth 9.00 m beyond supervisor.max_depth_m")
    assert cause.endswith("; next: bring the vehicle back inside the envelope (or fix what the cause names), then "
                          "hindrax reset, hindrax arm"), cause
    lay.probe.destroy_publisher(pub)
    # issue 74.1: the step it names, from the topside through the gateway (signed), printing what it cleared
    reset = subprocess.run([str(Path(sys.executable).with_name("hindrax")), "reset", "--vehicle", lay.vehicle_name],
                           capture_output=True, text=True, timeout=120,
                           env=dict(lay.env, ROS_DOMAIN_ID=str(lay.topside_domain)))
    assert reset.returncode == 0, reset.stderr
    assert reset.stdout.strip() == f"{lay.vehicle_name}: cleared: depth 9.00 m beyond supervisor.max_depth_m " \
        + cause.split("supervisor.max_depth_m ", 1)[1].split("; next:")[0], (reset.stdout, cause)


def test_a_guard_silence_is_named_on_the_topside(topside):
    lay, seen, executor = topside
    lay.armed_at_1700()
    lay.signal("esc", signal.SIGSTOP)
    try:
        wait_until(lambda: lay.hw.stopped_at is not None, WAIT_S, None, "the guard cut the outputs")
    finally:
        lay.signal("esc", signal.SIGCONT)
    cause = _cause_on_topside(seen, executor, "output guard: ESC output state silent for", "(esc/heartbeat)")
    assert "; next: check the ESC process (hindrax health; the launch respawns it), then hindrax arm" in cause


def test_a_killed_esc_is_named_on_the_topside(topside):
    lay, seen, executor = topside
    lay.armed_at_1700()
    lay.kill("esc")
    cause = _cause_on_topside(seen, executor, "output guard: ESC output state silent", "ESC process dead or hung",
                              "; next: check the ESC process")
    assert cause.count("; next: ") == 1
