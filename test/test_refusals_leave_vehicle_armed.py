"""A tool that refuses to run beside a live vehicle leaves the vehicle as it was: the refusal comes before the tool
creates any node or publisher of its own (vehicle_graph.refuse_before_start, the player's window before its first
publisher).

The vehicle's emulated layout (ESC, supervisor and output guard each in its own process, the PCA9685 and its /OE line
served by this process: :mod:`hindrax_tools.benchmarks.safety`), armed at 1700 us; then each
refused tool is started
on the vehicle's domain and must exit 1 naming the vehicle while thrust stays on. Before, ``bag play
--safety-topics`` and ``bringup --sim`` created their heartbeat publishers first and the ESC disarmed 0.9-1.5 s
after each start.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.serialization import serialize_message

from hindrax_bringup.recording.writer import BagWriter
from hindrax_common.testing import wait_until
from hindrax_tools.benchmarks.participant_churn import hardware_priority
from hindrax_tools.benchmarks.safety import running_layout

pytestmark = [pytest.mark.vehicle_launch, pytest.mark.ros]

#: (tool arguments, the refusal's start after "hindrax <tool>: refused: ROS domain N already has ")
TOOLS = {
    "bag_play": (["bag", "play", "{bag}", "--safety-topics", "--loop"], "hindrax bag play: refused"),
    "bringup_sim": (["bringup", "--sim"], "hindrax bringup: refused"),
    "run": (["run", "--dofs", "surge", "--levels", "1", "--out", "{tmp}/run"], "hindrax run: refused"),
}


@pytest.fixture(scope="module")
def layout():
    with running_layout("hindrax-refusals-", int(os.environ["ROS_DOMAIN_ID"])) as lay:
        yield lay


def _heartbeat_bag(path: Path) -> Path:
    """1 s of both safety heartbeats at 20 Hz, as a vehicle's bag holds them."""
    with BagWriter(path) as w:
        for topic in ("/supervisor/heartbeat", "/esc/heartbeat"):
            w.add_topic(topic, "diagnostic_msgs/msg/DiagnosticStatus")
        for i in range(20):
            for topic in ("/supervisor/heartbeat", "/esc/heartbeat"):
                w.write(topic, 10**18 + i * 50_000_000, serialize_message(DiagnosticStatus(
                    level=DiagnosticStatus.OK, name=topic, values=[KeyValue(key="seq", value=str(i))])))
    return path


@pytest.mark.parametrize("tool", list(TOOLS))
def test_a_refused_tool_does_not_disarm_the_vehicle(layout, tool, tmp_path):
    lay, hw = layout, layout.hw
    args, refusal = TOOLS[tool]
    bag = _heartbeat_bag(tmp_path / "bag")
    args = [a.format(bag=bag, tmp=tmp_path) for a in args]
    lay.armed_at_1700()
    hindrax = str(Path(sys.executable).with_name("hindrax"))
    # the emulated hardware real-time while the tool runs, as the benches run it (the vehicle's /OE line is never
    # starved by a CPU load; this process's starved line held a guard tick 0.22 s at load 24); the tool is not
    with hardware_priority(), open(tmp_path / "stderr", "w") as errf:
        proc = subprocess.Popen([hindrax, *args], env=lay.env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=errf)
        try:
            wait_until(lambda: proc.poll() is not None or hw.stopped_at is not None, 180, None, f"{tool} refusing")
            stopped_while_running = hw.stopped_at is not None
            wait_until(lambda: proc.poll() is not None, 180, None, f"{tool} exiting")
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    err = (tmp_path / "stderr").read_text().strip().splitlines()
    assert proc.returncode == 1 and err and err[-1].startswith(refusal), err
    assert not stopped_while_running and not lay.disarmed_after_arm, (
        f"{tool} disarmed the vehicle before refusing: channel 0 {hw.emu.pulse_width_us(0):.1f} us, /OE high "
        f"{hw.line.is_high()}; ESC said {lay._last_log_line('esc', 'disarming')!r}")
    assert hw.thrust() and hw.emu.pulse_width_us(0) > 1690.0


def test_use_sim_time_set_while_armed_is_refused_by_every_safety_process(layout):
    """Issue 71.5: ``ros2 param set /output_guard use_sim_time true`` while armed froze the guard's and the ESC's
    timers (thrust 100 % for 3-8 s, the guard reporting OK). Every vehicle node's rclpy built-ins are read-only: each
    of the ESC, supervisor and guard refuses it through its parameter service, and the vehicle stays armed."""
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    lay, hw = layout, layout.hw
    lay.armed_at_1700()
    sim_time = ParameterMsg(name="use_sim_time", value=ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                                      bool_value=True))
    for node in ("esc", "supervisor", "output_guard"):
        client = lay.probe.create_client(SetParameters, f"/{node}/set_parameters")
        wait_until(client.service_is_ready, 30, None, f"{node}'s parameter service")
        future = client.call_async(SetParameters.Request(parameters=[sim_time]))
        wait_until(future.done, 30, None, f"{node}'s answer")
        (result,) = future.result().results
        assert not result.successful and "read-only" in result.reason, (node, result.reason)
        lay.probe.destroy_client(client)
    assert not lay.disarmed_after_arm and hw.thrust() and hw.emu.pulse_width_us(0) > 1690.0
