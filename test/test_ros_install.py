"""`make ros-install` as a new user on the vehicle would use it: colcon builds a copy of the workspace, and the
installed executables run from the install space with the installed vehicle file.

Built once per session in a copy of the repository's ros_ws + src (test/conftest.py; about 60 s on the shared 2 cores,
hindrax_msgs' compiles taken from make setup's ccache).
Checks: the vehicle's build installs hindrax_msgs, hindrax_common, hindrax_drivers, hindrax_bringup and hindrax_onboard
only (no fit, simulator or tools: those are the topside's, here the venv's editable installs), every node's console
script is installed in lib/<package>, the install's `hindrax` (hindrax_onboard's) is on PATH after sourcing it, finds
the installed vehicle file without --config, and without hindrax_tools lists the vehicle's commands and answers a
topside one in a line, the launch files, the Foxglove layout and the virtual pool's truth files are in share/ (so the
venv's simulator_node runs on them), installed allocation_node answers a wrench and installed static_tf_node publishes
/tf_static (both started with `--ros-args --params-file <installed hindrax.yaml>`), a driver whose device is absent
keeps running and reports the error on /diagnostics; a topside `colcon build --symlink-install` up to the tools puts the
`hindrax` wrapper on PATH, and colcon at the repository root sees the eight packages and none of the third_party
stand-ins.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from hindrax_common.testing import ros_context, wait_until


@contextlib.contextmanager
def graph():
    """A test node in an isolated context (the domain of ROS_DOMAIN_ID) and a spin-once function."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    with ros_context() as ctx:
        node = rclpy.create_node("install_test", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        try:
            yield ctx, node, lambda: ex.spin_once(timeout_sec=0.05)
        finally:
            ex.shutdown()
            node.destroy_node()

REPO = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
# the colcon build (about 60 s with the machine shared, setup's ccache warm; 120 s or more cold) runs once per session
pytestmark = pytest.mark.timeout(1200)

DRIVER_NODES = ["dvl75_node", "ping1d_node", "ms5837_node", "icm20948_node", "esc_node", "static_tf_node"]
BRINGUP_NODES = ["allocation_node", "recorder_node", "player_node", "supervisor_node", "output_guard_node",
                 "sensors_node", "actuation_node"]  # composed processes (vehicle.launch)
ONBOARD_NODES = ["identification_node", "controller_node", "ident_control_node", "ident_record_node"]
#: what the vehicle's build must not install (topside packages)
TOPSIDE = ("hindrax_fit", "hindrax_sim", "hindrax_tools")


@pytest.fixture(scope="module")
def install(colcon_install):
    """(install dir, environment after sourcing it): the shared build of test/conftest.py."""
    return colcon_install.prefix, dict(colcon_install.env)


def test_every_node_and_hindrax_are_installed(install):
    inst, env = install
    for node in DRIVER_NODES:
        assert os.access(inst / "lib" / "hindrax_drivers" / node, os.X_OK), node
    for node in BRINGUP_NODES:
        assert os.access(inst / "lib" / "hindrax_bringup" / node, os.X_OK), node
    for node in ONBOARD_NODES:
        assert os.access(inst / "lib" / "hindrax_onboard" / node, os.X_OK), node
    installed = sorted(p.name for pkg in ("hindrax_drivers", "hindrax_bringup", "hindrax_onboard")
                       for p in (inst / "lib" / pkg).iterdir())
    print("installed executables:", " ".join(installed))
    # the vehicle's build: no fit, simulator or tools code; its own `hindrax` (hindrax_onboard) and the PATH wrapper
    assert not [p for p in inst.rglob("*") if any(t in p.name for t in TOPSIDE)], "topside code in the install"
    assert os.access(inst / "bin" / "hindrax", os.X_OK) and os.access(inst / "lib" / "hindrax_onboard" / "hindrax",
                                                                     os.X_OK)
    # the installed packages are the ones imported, not the repository's
    r = subprocess.run(["python3", "-c", "import hindrax_common, hindrax_drivers, hindrax_bringup, hindrax_onboard; "
                        "print(hindrax_common.__file__); print(hindrax_drivers.__file__); "
                        "print(hindrax_bringup.__file__); print(hindrax_onboard.__file__)"],
                       env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and all(line.startswith(str(inst)) for line in r.stdout.split()), r.stdout + r.stderr


def test_share_holds_vehicle_file_launch_files_and_layout(install):
    inst, _ = install
    share = inst / "share"
    installed_cfg = share / "hindrax_common" / "config" / "hindrax.yaml"
    assert installed_cfg.read_text() == (REPO / "ros_ws" / "config" / "hindrax.yaml").read_text()
    launches = sorted(p.name for p in share.glob("*/launch/*.launch.xml"))
    assert launches == sorted(p.name for p in REPO.glob("src/*/launch/*.launch.xml")) and launches
    assert list((share / "hindrax_onboard" / "foxglove").glob("*.json"))
    for launch in share.glob("*/launch/*.launch.xml"):
        for node in ET.parse(launch).getroot().iter("node"):
            pkg, exe = node.get("pkg"), node.get("exec")
            if pkg.startswith("hindrax_"):
                assert os.access(inst / "lib" / pkg / exe, os.X_OK), f"{launch.name}: {pkg}/{exe} not installed"


def test_installed_hindrax_is_on_path_and_finds_the_installed_vehicle_file(install, tmp_path):
    inst, env = install
    which = shutil.which("hindrax", path=env["PATH"])
    assert which == str(inst / "bin" / "hindrax")  # the vehicle's command (hindrax_onboard), before the venv's
    r = subprocess.run(["hindrax", "config", "check"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.startswith(f"{inst / 'share' / 'hindrax_common' / 'config' / 'hindrax.yaml'}: OK"), r.stdout


#: runs the installed ``lib/hindrax_onboard/hindrax`` as the vehicle has it: the venv's editable hindrax_tools
#: (topside) hidden from the entry-point lookup, and never imported
_WITHOUT_TOOLS = """
import importlib.metadata as md, runpy, sys
real = md.entry_points
md.entry_points = lambda **kw: [e for e in real(**kw) if e.dist.name != "hindrax_tools"]
sys.argv = sys.argv[1:]
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
finally:
    assert "hindrax_tools" not in sys.modules
"""


def test_the_vehicles_hindrax_lists_its_commands_and_answers_a_topside_one_in_a_line(install, tmp_path):
    inst, env = install
    script = str(inst / "lib" / "hindrax_onboard" / "hindrax")

    def vehicle_hindrax(*args):
        return subprocess.run([sys.executable, "-c", _WITHOUT_TOOLS, script, *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=60)

    r = vehicle_hindrax("--help")
    assert r.returncode == 0, r.stderr
    listed = {line.split()[0] for line in r.stdout.split("COMMAND\n", 1)[1].split("options:")[0].splitlines()
              if line.startswith("    ") and not line.startswith("     ")}
    assert {"config", "health", "keys", "esc", "thruster-test", "arm", "bag", "decode"} <= listed, r.stdout
    assert not {"ident", "run", "pool", "control", "allocate"} & listed, r.stdout
    r = vehicle_hindrax("config", "check")
    assert r.returncode == 0 and r.stdout.startswith(f"{inst / 'share' / 'hindrax_common' / 'config'}"), r.stderr
    r = vehicle_hindrax("ident", "bag", "/var/lib/hindrax/runs/x")
    assert r.returncode == 1 and r.stdout == ""
    assert r.stderr == ("`hindrax ident bag` is not a vehicle command: topside commands run on the topside PC "
                        "(hindrax_tools is not installed here)\n")


def _start(inst, env, exe, *ros_args):
    params = inst / "share" / "hindrax_common" / "config" / "hindrax.yaml"
    return subprocess.Popen([str(exe), "--ros-args", "--params-file", str(params), *ros_args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _stop(*procs):
    out = []
    for p in procs:
        if p.poll() is None:
            p.send_signal(2)
        try:
            out.append(p.communicate(timeout=15)[0])
        except subprocess.TimeoutExpired:
            p.kill()
            out.append(p.communicate()[0])
    return out


def test_installed_allocation_answers_a_wrench_and_static_tf_is_latched(install):
    from geometry_msgs.msg import WrenchStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tf2_msgs.msg import TFMessage

    from hindrax_msgs.msg import ThrusterPwm

    inst, env = install
    with graph() as (ctx, node, spin):
        env = dict(env, ROS_DOMAIN_ID=str(ctx.get_domain_id()))
        alloc = _start(inst, env, inst / "lib" / "hindrax_bringup" / "allocation_node")
        tf = _start(inst, env, inst / "lib" / "hindrax_drivers" / "static_tf_node")
        try:
            pwm, tfs = [], []
            node.create_subscription(ThrusterPwm, "thrusters/command_pulse_width", pwm.append, 10)
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            node.create_subscription(TFMessage, "/tf_static", tfs.append, latched)
            pub = node.create_publisher(WrenchStamped, "wrench", 10)
            wait_until(lambda: pub.get_subscription_count() > 0, 30, spin, "installed allocation_node subscribed")
            w = WrenchStamped()
            w.header.frame_id = "base_link"

            def send():
                w.header.stamp = node.get_clock().now().to_msg()
                w.wrench.force.x = 10.0
                pub.publish(w)
                spin()
            # a wrench delivered late on a loaded machine is stale and answered with neutral
            # (fail closed): send fresh ones until one is answered with thrust
            wait_until(lambda: any(max(m.pulse_width_us) > 1500.0 for m in pwm), 20, send,
                       "thrust from the installed allocation_node")
            assert {len(m.pulse_width_us) for m in pwm} == {8}
            wait_until(lambda: tfs, 20, spin, "/tf_static from the installed static_tf_node")
            children = {t.child_frame_id for t in tfs[-1].transforms}
            assert {"imu_link", "dvl_link", "ping_link", "pressure_link"} | {f"thruster_{i}" for i in range(1, 9)} \
                == children
            assert {t.header.frame_id for t in tfs[-1].transforms} == {"base_link"}
        finally:
            outs = _stop(alloc, tf)
        assert alloc.returncode == 0 and tf.returncode == 0, outs


def test_installed_driver_with_absent_device_keeps_running_and_reports_on_diagnostics(install):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    inst, env = install
    with graph() as (ctx, node, spin):
        env = dict(env, ROS_DOMAIN_ID=str(ctx.get_domain_id()))
        dvl = _start(inst, env, inst / "lib" / "hindrax_drivers" / "dvl75_node",
                     "-p", "sensors.dvl75.port:=/dev/hindrax-absent-dvl")
        baro = _start(inst, env, inst / "lib" / "hindrax_drivers" / "ms5837_node", "-p", "sensors.ms5837.i2c_bus:=29")
        try:
            statuses: dict[str, list] = {}

            def on_diag(msg):
                for s in msg.status:
                    statuses.setdefault(s.name, []).append(s)
            node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 50)

            def bad(word):
                return [s for name, ss in statuses.items() if word in name for s in ss
                        if s.level[0] >= DiagnosticStatus.WARN[0]]
            # repeated reports (the node keeps running and retrying), each one not OK
            wait_until(lambda: len(bad("dvl")) >= 2 and len(bad("ms5837")) >= 2, 30, spin,
                       "absent devices reported on /diagnostics")
            assert dvl.poll() is None and baro.poll() is None
        finally:
            outs = _stop(dvl, baro)
        assert "Traceback" not in "".join(outs), outs


def test_truth_files_are_installed_and_the_installed_simulator_runs(install, tmp_path):
    from rosgraph_msgs.msg import Clock

    inst, env = install
    repo_truth = REPO / "ros_ws" / "config" / "truth"
    installed_truth = inst / "share" / "hindrax_common" / "config" / "truth"
    rel = lambda root: sorted(str(p.relative_to(root)) for p in root.rglob("*.yaml"))  # noqa: E731
    assert rel(installed_truth) == rel(repo_truth) and "scenarios/none.yaml" in rel(installed_truth)
    # a vehicle file mounted elsewhere (the image's HINDRAX_CONFIG): the simulator still finds the installed truth
    mounted = tmp_path / "mounted.yaml"
    shutil.copy2(inst / "share" / "hindrax_common" / "config" / "hindrax.yaml", mounted)
    r = subprocess.run(["python3", "-c", "from hindrax_sim.truth import truth_dir, default_truth_path; "
                        "print(truth_dir()); print(default_truth_path().is_file())"],
                       env=dict(env, HINDRAX_CONFIG=str(mounted)), cwd=tmp_path, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0 and r.stdout.split() == [str(installed_truth), "True"], r.stdout + r.stderr
    with graph() as (ctx, node, spin):
        sim = _start(inst, dict(env, ROS_DOMAIN_ID=str(ctx.get_domain_id())), VENV / "bin" / "simulator_node")
        try:
            clocks = []
            node.create_subscription(Clock, "/clock", clocks.append, 10)
            wait_until(lambda: len(clocks) >= 3 or sim.poll() is not None, 60, spin, "/clock from simulator_node")
            assert sim.poll() is None and len(clocks) >= 3
        finally:
            out = _stop(sim)
        assert sim.returncode == 0 and "TruthError" not in out[0], out


def test_symlink_install_keeps_hindrax_on_path(colcon_tools, tmp_path):
    # a topside colcon build of everything up to the tools (the last --packages-up-to wins); hindrax_msgs (the slow
    # CMake package, not concerned by --symlink-install) comes from the venv, where make setup installed it; the
    # ament_python packages are built with colcon build --symlink-install
    colcon_tools.copy_workspace(tmp_path)
    r = colcon_tools.make_ros_install(tmp_path, "--symlink-install --packages-up-to hindrax_tools "
                                                "--packages-ignore hindrax_msgs")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    prefix = tmp_path / "ros_ws" / "install"
    assert (prefix / "bin" / "hindrax").is_symlink()  # a symlink install: the wrapper must not resolve past it
    env = colcon_tools.sourced_env(prefix)
    assert shutil.which("hindrax", path=env["PATH"]) == str(prefix / "bin" / "hindrax")
    r = subprocess.run(["hindrax", "config", "check"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0 and ": OK" in r.stdout.splitlines()[0], r.stdout + r.stderr


def test_colcon_at_the_repository_root_sees_the_eight_packages_and_no_stand_in():
    # third_party/tf2_msgs would overlay ROS's tf2_msgs with a stand-in lacking what tf2_ros needs
    r = subprocess.run([str(VENV / "bin" / "colcon"), "--log-base", "/dev/null", "list", "--names-only"], cwd=REPO,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert sorted(r.stdout.split()) == ["hindrax_bringup", "hindrax_common", "hindrax_drivers", "hindrax_fit",
                                        "hindrax_msgs", "hindrax_onboard", "hindrax_sim", "hindrax_tools"], r.stdout
    assert (REPO / "third_party" / "COLCON_IGNORE").is_file()
