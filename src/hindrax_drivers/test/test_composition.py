"""Composed processes (hindrax_drivers.composition): each group's nodes exist and keep their own names in one
process (the installed group executable), a group ends cleanly on SIGINT, and a bad node list is refused."""
from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import pytest
import rclpy

from hindrax_drivers.composition import GROUPS, NODE_CLASSES, main, node_factories
from hindrax_drivers.config import default_config_path
from hindrax_drivers.testing import child_env, python_executable, ros_context, wait_until


def test_every_group_names_known_nodes_once_and_unknown_nodes_are_refused(capsys):
    assert set(GROUPS) == {"i2c_sensors_node", "serial_sensors_node", "actuation_node"}
    seen = [n for nodes in GROUPS.values() for n in nodes]
    assert len(seen) == len(set(seen)) and set(seen) <= set(NODE_CLASSES)
    for nodes in GROUPS.values():
        assert all(isinstance(f, type) for f in node_factories(nodes))
    # the ESC is built last in its group, so it is closed first on exit (neutral before anything else goes)
    assert GROUPS["actuation_node"][-1] == "esc"
    with pytest.raises(ValueError, match="unknown node 'gps'"):
        node_factories(["esc", "gps"])
    assert main(["composition", "esc,gps"]) == 2
    assert "unknown node 'gps'" in capsys.readouterr().err


@pytest.mark.ros
def test_i2c_sensors_group_runs_both_nodes_under_their_own_names_and_exits_0_on_sigint():
    # the installed console script; no /dev/i2c-1 here: both drivers keep running and report it (as alone)
    script = Path(python_executable()).with_name("i2c_sensors_node")
    proc = subprocess.Popen([str(script), "--ros-args", "--params-file", str(default_config_path())],
                            env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with ros_context() as ctx:
            probe = rclpy.create_node("composition_probe", context=ctx)
            wait_until(lambda: proc.poll() is None and {"ms5837", "icm20948"} <= set(probe.get_node_names()),
                       30, None, "both nodes in the graph")

            def topics(node: str) -> set[str]:
                return {t for t, _ in probe.get_publisher_names_and_types_by_node(node, "/")}

            # a node is discovered before its publishers: wait for each node's own topic under its own name
            wait_until(lambda: "/pressure/fluid_pressure" in topics("ms5837") and "/imu/data_raw" in topics("icm20948"),
                       30, None, "each node's publishers under its own name")
            assert "/imu/data_raw" not in topics("ms5837") and "/pressure/fluid_pressure" not in topics("icm20948")
            probe.destroy_node()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) == 0, proc.stdout.read()
    finally:
        if proc.poll() is None:
            proc.kill()
