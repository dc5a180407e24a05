"""Issue 74.2: a second vehicle started on a domain in use refuses to start, before arming is possible.

Two vehicle graphs on one ROS domain, safety processes only, as the safety benchmark lays them out
(:mod:`hindrax_tools.benchmarks.safety`: the ESC on an emulated PCA9685 with /OE, the supervisor, each its own
process): the first vehicle's ESC and supervisor run; the second's exit 1 with one line naming what they found.
Before, they started, and their heartbeats mixed into the first vehicle's safety graph (its outputs were cut). A
supervisor started after the first one was killed (SIGKILL: its endpoints stay on the graph until its participant's
lease ends) is not refused: a respawn starts.
"""
from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from hindrax_test_support.helpers import fresh_domain

from hindrax_common.testing import child_env, ros_context, wait_until
from hindrax_common.transport.shared_emulation import SOCKET_ENV
from hindrax_tools.benchmarks.safety import PROCESSES, _config_file, _Hardware

pytestmark = [pytest.mark.vehicle_launch, pytest.mark.ros]

WAIT_S = 60.0


def test_a_second_vehicles_esc_and_supervisor_refuse_to_start(tmp_path):
    from hindrax_msgs.msg import Heartbeat
    from rclpy.executors import SingleThreadedExecutor

    from hindrax_common.node_support.liveness import heartbeat_qos

    procs: list[subprocess.Popen] = []
    hardware: dict[str, _Hardware] = {}
    with fresh_domain() as did, ros_context(did) as ctx:
        def start(vehicle: str, name: str) -> subprocess.Popen:
            folder = tmp_path / vehicle
            folder.mkdir(exist_ok=True)
            if vehicle not in hardware:
                hardware[vehicle] = _Hardware(str(folder / "emulation.sock"), feed=False)
            hw = hardware[vehicle]
            config = _config_file(folder, feed=False)
            proc = subprocess.Popen([sys.executable, "-m", PROCESSES[name], "--ros-args", "--params-file", config],
                                    env=child_env(ROS_DOMAIN_ID=str(did), **{SOCKET_ENV: hw.server.path}),
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            procs.append(proc)
            return proc

        import rclpy

        node = rclpy.create_node("second_vehicle_probe", context=ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        beats: dict[str, list] = {"esc": [], "supervisor": []}
        for kind in beats:
            node.create_subscription(Heartbeat, f"/{kind}/heartbeat", beats[kind].append, heartbeat_qos())
        spin = lambda: executor.spin_once(timeout_sec=0.05)  # noqa: E731
        try:
            first = {name: start("first", name) for name in ("esc", "supervisor")}
            wait_until(lambda: all(beats.values()), WAIT_S, spin, "the first vehicle's heartbeats")
            second = {name: start("second", name) for name in ("esc", "supervisor")}
            for name, proc in second.items():
                wait_until(lambda p=proc: p.poll() is not None, WAIT_S, spin, f"the second {name} ended")
                err = proc.stderr.read().strip()
                assert proc.returncode == 1 and len(err.splitlines()) == 1, (proc.returncode, err)
                assert err == (f"refused: {name}: ROS domain {did} already has a live {name} ({name}, heartbeat on "
                               f"/{name}/heartbeat); refusing to start a second vehicle on it (one ROS_DOMAIN_ID "
                               "per vehicle)"), err
            assert all(p.poll() is None for p in first.values())  # the first vehicle runs on
            # a killed supervisor's endpoint stays on the graph: its successor starts (the launch's respawn)
            first["supervisor"].send_signal(signal.SIGKILL)
            first["supervisor"].wait(10)
            beats["supervisor"].clear()
            successor = start("first", "supervisor")
            wait_until(lambda: beats["supervisor"] or successor.poll() is not None, WAIT_S, spin,
                       "the successor's heartbeat")
            assert successor.poll() is None, successor.stderr.read()
        finally:
            for proc in procs:
                if proc.poll() is None:
                    proc.send_signal(signal.SIGINT)
            for proc in procs:
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            executor.shutdown()
            node.destroy_node()
            for hw in hardware.values():
                hw.server.close()
