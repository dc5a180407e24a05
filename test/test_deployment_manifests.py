"""What rosdep and Docker on the vehicle rely on, checked here: each package.xml lists what its package imports
(with rosdep keys), the workspace's own pip keys are defined in rosdep.yaml, the image registers them and puts
`hindrax` with the ROS environment in every process (`docker exec` included), and the container records by
default (into its runs folder, a host folder)."""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
DOCKER = REPO / "docker"

#: imported top-level module -> rosdep key (ROS packages and our own map to their own name)
ROSDEP_KEY = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "serial": "python3-serial", "yaml": "python3-yaml",
    "matplotlib": "python3-matplotlib", "smbus2": "python3-smbus2", "mcap": "python3-mcap-pip",
    "mcap_ros2": "mcap-ros2-support", "filterpy": "python3-filterpy-pip",
    "rosbags": "python3-rosbags-pip", "pytest": "python3-pytest", "hypothesis": "python3-hypothesis",
    "gpiod": "python3-gpiod-pip", "lxml": "python3-lxml", "ruamel": "python3-ruamel.yaml",
}
#: keys of rosdistro's rosdep/python.yaml used here (checked against ros/rosdistro, 2026-11): apt or pip there
ROSDISTRO_KEYS = {"python3-numpy", "python3-scipy", "python3-serial", "python3-yaml", "python3-matplotlib",
                  "python3-smbus2", "python3-filterpy-pip", "python3-rosbags-pip", "mcap-ros2-support",
                  "python3-pytest", "python3-hypothesis", "python3-lxml", "python3-ruamel.yaml"}
ROS_PACKAGES = {"rclpy", "ament_index_python", "builtin_interfaces", "rcl_interfaces", "std_msgs", "std_srvs",
                "geometry_msgs", "sensor_msgs", "nav_msgs", "diagnostic_msgs", "rosgraph_msgs", "tf2_msgs",
                "domain_coordinator", "action_msgs", "unique_identifier_msgs", "hindrax_msgs", "hindrax_common",
                "hindrax_drivers", "hindrax_bringup", "hindrax_onboard", "hindrax_fit", "hindrax_sim", "hindrax_tools",
                "sros2"}
#: the Python packages, in their dependency order (msgs <- common <- drivers <- bringup <- onboard <- fit <- sim <-
#: tools)
PACKAGES = ("hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard", "hindrax_fit", "hindrax_sim",
            "hindrax_tools")
#: the repository's helpers of tests only (test/support, on every test's path through pytest.ini): no package ships
#: them, so no package.xml names them
TEST_SUPPORT = {"hindrax_test_support"}
#: development tools inside a package that drive a higher package (none today; a package dependency back would be
#: a cycle)
DEV_TOOLS: set[str] = set()


def imports(files) -> set[str]:
    out: set[str] = set()
    for f in files:
        if str(f.relative_to(REPO / "src")) in DEV_TOOLS:
            continue
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                out |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                out.add(node.module.split(".")[0])
    return {m for m in out if m not in sys.stdlib_module_names and m != "__future__"}


def depends(pkg: str) -> dict[str, set[str]]:
    root = ET.parse(REPO / "src" / pkg / "package.xml").getroot()
    return {tag: {e.text.strip() for e in root.iter(tag)} for tag in
            ("exec_depend", "test_depend", "depend", "build_depend", "buildtool_depend")}


def key_of(module: str) -> str:
    if module in ROS_PACKAGES:
        return module
    assert module in ROSDEP_KEY, f"import {module}: add its rosdep key to package.xml and to this table"
    return ROSDEP_KEY[module]


def test_each_package_xml_lists_what_its_package_imports():
    for i, pkg in enumerate(PACKAGES):
        deps = depends(pkg)
        run_keys = deps["exec_depend"] | deps["depend"]
        code = imports((REPO / "src" / pkg / pkg).rglob("*.py")) - {pkg}
        missing = sorted(key_of(m) for m in code if key_of(m) not in run_keys)
        assert not missing, f"{pkg}/package.xml lacks exec_depend {missing}"
        # the drivers' tests also drive the graph and the hindrax command (higher packages): a test_depend on them
        # would be a cycle for colcon, which orders packages by test dependencies too
        higher = set(PACKAGES[i + 1:])
        tests = imports((REPO / "src" / pkg / "test").rglob("*.py")) - {pkg} - higher - TEST_SUPPORT
        missing = sorted(key_of(m) for m in tests if key_of(m) not in run_keys | deps["test_depend"])
        assert not missing, f"{pkg}/package.xml lacks test_depend {missing}"
        # no dependency on a higher package (the order of PACKAGES)
        assert not (run_keys | deps["test_depend"]) & higher, f"{pkg}/package.xml depends on a higher package"


def test_every_key_is_a_ros_package_a_rosdistro_key_or_defined_in_rosdep_yaml():
    rosdep = yaml.safe_load((REPO / "rosdep.yaml").read_text())
    requirements = {re.split(r"[<>=\[ ]", line.strip())[0].lower() for line in
                    (REPO / "requirements.txt").read_text().splitlines() if line.strip() and not line.startswith("#")}
    used = set()
    for pkg in PACKAGES:
        for keys in depends(pkg).values():
            used |= keys
    ours = used - ROS_PACKAGES - ROSDISTRO_KEYS
    assert ours and ours <= set(rosdep), sorted(ours - set(rosdep))
    # rosdistro's keys are redefined only where they install from PyPI (to pin them), never an apt key
    shadowed = set(rosdep) & ROSDISTRO_KEYS
    assert all(k.endswith("-pip") or k == "mcap-ros2-support" for k in shadowed), sorted(shadowed)
    pins = dict(line.strip().lower().split("==") for line in (REPO / "constraints.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    for key in set(rosdep):
        for os_name in ("ubuntu", "debian"):
            packages = rosdep[key][os_name]["pip"]["packages"]
            names = {p.split("==")[0].lower() for p in packages}
            assert packages and names <= requirements, (key, packages)
            # issue 45.5: the Pi installs the versions the tests ran with (constraints.txt), not PyPI's newest
            for p in packages:
                name, _, version = p.partition("==")
                assert version and version == pins[name.lower()], (key, p, pins.get(name.lower()))


def test_dockerfile_uses_rosdep_yaml_and_puts_hindrax_with_ros_in_every_process():
    text = (DOCKER / "Dockerfile").read_text()
    assert "COPY rosdep.yaml /etc/ros/rosdep/hindrax.yaml" in text
    assert 'yaml file:///etc/ros/rosdep/hindrax.yaml" > /etc/ros/rosdep/sources.list.d/' in text
    assert "rosdep install --from-paths src --ignore-src" in text
    # the config symlink of hindrax_common resolves inside the image
    link = os.readlink(REPO / "src" / "hindrax_common" / "config")
    assert link == "../../ros_ws/config" and "COPY ros_ws/config /ws/ros_ws/config" in text
    assert "COPY docker/hindrax-exec.sh /usr/local/bin/hindrax" in text
    assert "/etc/profile.d/hindrax.sh" in text
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())["services"]["hindrax"]
    # the recordings' root inside the container (HINDRAX_RUNS_DIR) is a host folder
    assert "HINDRAX_RUNS_DIR=/var/lib/hindrax/runs" in text
    assert any(v.endswith(":/var/lib/hindrax/runs") for v in compose["volumes"])


def _fakes(tmp_path):
    ros = tmp_path / "ros_setup.bash"
    ros.write_text("export FAKE_ROS_SOURCED=1\n")
    ws = tmp_path / "ws_setup.bash"
    ws.write_text("export FAKE_WS_SOURCED=1\n")
    cmd = tmp_path / "hindrax"
    cmd.write_text("#!/usr/bin/env bash\necho \"ARGS=$*\"\necho \"RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE\"\n"
                   "echo \"SOURCED=$FAKE_ROS_SOURCED$FAKE_WS_SOURCED\"\necho \"CONFIG=$HINDRAX_CONFIG\"\n")
    cmd.chmod(0o755)
    ros2 = tmp_path / "ros2"
    ros2.write_text("#!/usr/bin/env bash\necho \"ROS2=$*\"\n")
    ros2.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_AUTOMATIC", "ROS_DOMAIN", "HINDRAX"))}
    (tmp_path / "keystore" / "enclaves").mkdir(parents=True)  # SROS2 is on as shipped: the entry point needs one
    env.update(ROS_SETUP=str(ros), WS_SETUP=str(ws), PATH=f"{tmp_path}:{os.environ['PATH']}",
               HINDRAX_RUNS_DIR=str(tmp_path / "runs"), HINDRAX_KEYSTORE=str(tmp_path / "keystore"))
    return cmd, env


def test_docker_exec_hindrax_runs_with_the_containers_ros_environment(tmp_path):
    cmd, env = _fakes(tmp_path)
    mounted = tmp_path / "hindrax.yaml"
    mounted.write_text("a mounted vehicle file\n")
    env.update(HINDRAX_ENTRYPOINT=str(DOCKER / "entrypoint.sh"), HINDRAX_COMMAND=str(cmd),
               HINDRAX_CONFIG=str(mounted))
    r = subprocess.run([str(DOCKER / "hindrax-exec.sh"), "thruster-test", "--help"], env=env, capture_output=True,
                       text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    # a command run on the vehicle joins its internal graph (loopback), not the topside
    assert "ARGS=thruster-test --help" in r.stdout and "RANGE=LOCALHOST" in r.stdout and "SOURCED=11" in r.stdout
    assert f"CONFIG={mounted}" in r.stdout


def test_the_container_records_by_default(tmp_path):
    cmd, env = _fakes(tmp_path)

    def entry(**extra):
        r = subprocess.run([str(DOCKER / "entrypoint.sh")], env=dict(env, ROS_DOMAIN_ID="42", **extra),
                           capture_output=True, text=True, timeout=30)
        assert r.returncode == 0, r.stderr
        return r.stdout
    runs = tmp_path / "runs"
    assert f"ROS2=launch hindrax_bringup vehicle.launch.xml record:=true output_dir:={runs}" in entry()
    assert "record:=false" in entry(HINDRAX_RECORD="0")


def test_default_config_path_follows_hindrax_config(tmp_path, monkeypatch):
    from hindrax_common.config import default_config_path

    f = tmp_path / "vehicle.yaml"
    f.write_text("x")
    monkeypatch.setenv("HINDRAX_CONFIG", str(f))
    assert default_config_path() == f
    monkeypatch.setenv("HINDRAX_CONFIG", str(tmp_path / "missing.yaml"))
    try:
        default_config_path()
    except FileNotFoundError as exc:
        assert "HINDRAX_CONFIG" in str(exc)
    else:
        raise AssertionError("a missing HINDRAX_CONFIG file was accepted")
