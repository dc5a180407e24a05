"""Deployment files that can be checked without Docker: entry point behaviour, compose devices/network,
udev names matching the vehicle configuration."""
import os
import re
import subprocess
from pathlib import Path

import yaml

from hindrax_drivers.config import default_config_path, load_config

DOCKER = Path(__file__).resolve().parents[1] / "docker"


def run_entrypoint(tmp_path, args, **env):
    ros = tmp_path / "ros_setup.bash"
    ros.write_text("export FAKE_ROS_SOURCED=1\n")
    ws = tmp_path / "ws_setup.bash"
    ws.write_text("export FAKE_WS_SOURCED=1\n")
    bindir = tmp_path / "bin"
    bindir.mkdir(exist_ok=True)
    fake = bindir / "hindrax"
    fake.write_text("#!/usr/bin/env bash\necho \"ARGS=$*\"\necho \"RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE\"\n"
                    "echo \"DOMAIN=$ROS_DOMAIN_ID\"\necho \"SOURCED=$FAKE_ROS_SOURCED$FAKE_WS_SOURCED\"\n")
    fake.chmod(0o755)
    e = {k: v for k, v in os.environ.items() if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_DOMAIN_ID")}
    e.update(ROS_SETUP=str(ros), WS_SETUP=str(ws), PATH=f"{bindir}:{os.environ['PATH']}", **env)
    return subprocess.run([str(DOCKER / "entrypoint.sh"), *args], capture_output=True, text=True, env=e, timeout=30)


def test_entrypoint_defaults_to_bringup_on_the_tether(tmp_path):
    r = run_entrypoint(tmp_path, [], HINDRAX_CONFIG="/ws/config/x.yaml")
    assert r.returncode == 0, r.stderr
    assert "ARGS=bringup --config /ws/config/x.yaml" in r.stdout
    assert "RANGE=SUBNET" in r.stdout and "DOMAIN=0" in r.stdout and "SOURCED=11" in r.stdout


def test_entrypoint_localhost_for_simulation_and_explicit_command(tmp_path):
    r = run_entrypoint(tmp_path, ["hindrax", "bringup", "--sim", "--config", "/c.yaml"],
                       HINDRAX_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID="42")
    assert r.returncode == 0, r.stderr
    assert "ARGS=bringup --sim --config /c.yaml" in r.stdout  # no second --config
    assert "RANGE=LOCALHOST" in r.stdout and "DOMAIN=42" in r.stdout


def test_entrypoint_rejects_bad_settings(tmp_path):
    r = run_entrypoint(tmp_path, [], HINDRAX_DISCOVERY_RANGE="EVERYWHERE")
    assert r.returncode == 2 and "HINDRAX_DISCOVERY_RANGE=EVERYWHERE" in r.stderr
    r = run_entrypoint(tmp_path, [], ROS_DOMAIN_ID="300")
    assert r.returncode == 2 and "ROS_DOMAIN_ID=300: allowed integer 0-101" in r.stderr


def test_compose_maps_the_configured_devices_with_host_networking():
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    svc = compose["services"]["hindrax"]
    assert svc["network_mode"] == "host"
    devices = {d.split(":")[0] for d in svc["devices"]}
    cfg = load_config(default_config_path())
    assert cfg.get("sensors.dvl75.port") in devices
    assert cfg.get("sensors.ping1d.port") in devices
    for key in ("sensors.ms5837.i2c_bus", "sensors.icm20948.i2c_bus", "esc.i2c_bus"):
        assert f"/dev/i2c-{cfg.get(key)}" in devices
    assert svc["stop_signal"] == "SIGINT"


def test_udev_names_match_the_configuration():
    rules = (DOCKER / "99-hindrax.rules").read_text()
    links = set(re.findall(r'SYMLINK\+="([^"]+)"', rules))
    cfg = load_config(default_config_path())
    assert {Path(cfg.get("sensors.dvl75.port")).name, Path(cfg.get("sensors.ping1d.port")).name} <= links


def test_dockerfile_builds_the_workspace_with_colcon_on_the_ros_image():
    text = (DOCKER / "Dockerfile").read_text()
    assert re.search(r"^FROM ros:jazzy-ros-base", text, re.M)
    assert "colcon build" in text and "ENTRYPOINT [\"/entrypoint.sh\"]" in text
