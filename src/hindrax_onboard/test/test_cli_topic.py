"""``hindrax topic echo``: the README's read-out of the supervisor's status where the ros2 CLI is absent (issue
74.5): the topic's type found on the graph, the message printed as YAML with its fields."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.testing import child_env, ros_context, wait_until

pytestmark = pytest.mark.ros


def test_echo_prints_one_status_as_yaml_and_a_missing_topic_in_one_line():
    import yaml
    from hindrax_test_support.helpers import fresh_domain

    hindrax = str(Path(sys.executable).with_name("hindrax"))
    with fresh_domain() as fresh, ros_context(domain_id=fresh) as ctx:
        node = rclpy.create_node("supervisor_stand_in", context=ctx)
        pub = node.create_publisher(DiagnosticStatus, "/rov/supervisor/status", 10)
        node.create_timer(0.1, lambda: pub.publish(DiagnosticStatus(level=b"\x02", name="supervisor", values=[
            KeyValue(key="disarm_cause", value="no valid DVL velocity")])))
        node.create_publisher(DiagnosticStatus, "/rov/silent", 10)  # on the graph, never sends
        # read, never published
        node.create_subscription(DiagnosticStatus, "/rov/only_read", lambda _m: None, 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        env = child_env(ROS_DOMAIN_ID=str(fresh))
        # the missing and silent topics' timeouts are short: the test waits them out in full
        # (30 s of the suite's tail before)
        topics = (("/rov/supervisor/status", "30"), ("/rov/no_such_topic", "3"),
                  ("/rov/silent", "3"), ("/rov/only_read", "3"))
        runs = [subprocess.Popen([hindrax, "topic", "echo", topic, "--count", "1",
                                  "--timeout", timeout_s], env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for topic, timeout_s in topics]
        try:
            wait_until(lambda: all(p.poll() is not None for p in runs), 120, lambda: ex.spin_once(timeout_sec=0.05),
                       "hindrax topic echo")
        finally:
            for p in runs:
                if p.poll() is None:
                    p.kill()
            ex.shutdown()
            node.destroy_node()
    ok, missing, silent, only_read = [(p.returncode, p.stdout.read(), p.stderr.read())
                                      for p in runs]
    assert ok[0] == 0, ok
    text, end = ok[1].rsplit("---", 1)
    assert end.strip() == ""
    assert yaml.safe_load(text) == {"level": 2, "name": "supervisor", "message": "", "hardware_id": "",
                                    "values": [{"key": "disarm_cause", "value": "no valid DVL velocity"}]}
    assert missing[0] == 1 and missing[2] == ("no topic /rov/no_such_topic within 3 s (is it "
                                              "spelled as the graph has it?)\n"), missing
    # found on the graph, then nothing: the line says whether anything publishes it, and which node
    assert silent[0] == 1, silent
    assert silent[2] == ("no message on /rov/silent within 3 s from its 1 publisher(s) "
                         "(/supervisor_stand_in): is the node sending (a status goes out on a "
                         "change or at its period)?\n"), silent
    assert only_read[0] == 1, only_read
    assert only_read[2] == ("no message on /rov/only_read within 3 s: it has no publisher "
                            "(only readers on the graph)\n"), only_read
