"""The gateway process refuses a bad setting at start-up with one line naming key, value and allowed range."""
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_drivers.testing import child_env

CONFIG = Path(__file__).resolve().parents[3] / "ros_ws" / "config" / "hindrax.yaml"


@pytest.mark.parametrize("setting, line", [
    ("topside_domain_id:=500", "invalid configuration: topside_domain_id = 500: allowed integer in [0, 101]"),
    ("topside_discovery_range:=WIDE", "topside_discovery_range = 'WIDE': allowed one of LOCALHOST, SUBNET"),
    ("call_timeout_s:=0.0", "call_timeout_s = 0.0: allowed number in [0.1, 30]"),
    ("vehicle.name:=a-b", "vehicle.name = 'a-b': allowed a ROS name token"),
])
def test_bad_setting_stops_the_start_in_one_line(setting, line):
    r = subprocess.run([sys.executable, "-m", "hindrax_drivers.gateway.node", "--ros-args", "--params-file",
                        str(CONFIG), "-p", setting], capture_output=True, text=True, env=child_env(), timeout=60)
    assert r.returncode == 1
    errors = [x for x in r.stderr.splitlines() if x.startswith("invalid configuration")]
    assert len(errors) == 1 and line in errors[0], r.stderr
