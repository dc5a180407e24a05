"""``hindrax health``: exit 1 listing what is missing when the vehicle is not there, a clear line for a bad launch
argument; ``hindrax bringup`` without --sim says the vehicle runs the launch file. (The READY path, against the
whole launch layout on emulated devices, is in test/test_pool_day.py.)"""
from __future__ import annotations

import subprocess

import pytest
from hindrax_test_support.helpers import fresh_domain

from hindrax_common.testing import child_env, python_executable

pytestmark = pytest.mark.ros


def hindrax(*args: str, timeout: float = 60, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([python_executable(), "-m", "hindrax_tools.cli", *args],
                          env=child_env(**env),
                          capture_output=True, text=True, timeout=timeout)


def test_health_without_a_vehicle_says_so_in_one_line_naming_the_domain():
    """Issue 45.4: nothing running -> one short line naming the domain (was 17 FAIL lines and a summary)."""
    # A ROS domain of its own, reserved like the workers' (conftest.py): nothing else this worker ran (an
    # in-process node of another test, a process a failed test left behind) can be mistaken for the vehicle.
    with fresh_domain() as domain:
        r = hindrax("health", "--launch", "hindrax_onboard/pool_test.launch.xml", "output_dir:=/tmp/x", "--timeout",
                    "1.5", ROS_DOMAIN_ID=str(domain))
        quiet = hindrax("health", "--quiet", "--timeout", "0.5", ROS_DOMAIN_ID=str(domain))
    assert r.returncode == 1, r.stdout + r.stderr
    assert r.stdout.splitlines() == [
        f"NOT READY: no node of hindrax_onboard/pool_test.launch.xml seen on ROS_DOMAIN_ID={domain} (this machine "
        "only, UDP on 127.0.0.1) within 1.5 s: is the vehicle running, on this domain? (from the topside: "
        "docs/deployment.md §6)"]
    assert quiet.returncode == 1 and len(quiet.stdout.splitlines()) == 1


def test_health_refuses_an_undeclared_launch_argument_in_one_line():
    r = hindrax("health", "recrod:=true", "--timeout", "0.5")
    assert r.returncode == 1 and r.stderr.count("\n") == 1
    assert "recrod not declared" in r.stderr and "record" in r.stderr


def test_bringup_without_sim_says_the_vehicle_runs_the_launch_file():
    from hindrax_tools.commands.bringup import VEHICLE_NOTICE

    assert "ros2 launch hindrax_bringup vehicle.launch.xml" in VEHICLE_NOTICE
    help_text = hindrax("bringup", "--help").stdout
    assert "the vehicle runs the launch" in " ".join(help_text.split())
    # a configuration error stops it after the notice (no hardware is opened here)
    r = hindrax("bringup", "--config", "/nonexistent/hindrax.yaml", timeout=60)
    assert r.returncode != 0 and r.stderr.startswith(VEHICLE_NOTICE)
