"""The launch-layout benchmark's stand-in for /dev/i2c-1: a driver process's SocketI2CBus talks to an
EmulatedI2CBus in the pool process through I2CSocketServer, with the smbus2 semantics the drivers rely on
(block writes reach the register-exact emulator, reads come back as lists, an absent device is OSError 121)."""
import errno
import threading

import pytest

from hindrax_drivers.pca9685 import protocol as p
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.i2c import I2CDevice
from hindrax_common.transport.socket_i2c import I2CSocketServer, SocketI2CBus


def test_socket_bus_serves_the_emulated_bus(tmp_path):
    emulator = Pca9685Emulator()
    server = I2CSocketServer(EmulatedI2CBus({0x40: emulator}), str(tmp_path / "i2c.sock"), threading.Lock())
    bus = SocketI2CBus(str(tmp_path / "i2c.sock"))
    device = I2CDevice(bus, 0x40, "pca9685", retries=0)
    prescale = p.esc_prescale(50.0, p.INTERNAL_OSCILLATOR_HZ)
    device.write_sequence(p.startup_sequence(prescale))
    device.write_block(p.led_register(0), p.channel_bytes_for_pulse(1700.0, prescale, p.INTERNAL_OSCILLATOR_HZ))
    # the emulator decodes the pulse width from the registers the driver wrote through the socket
    assert emulator.pulse_width_us(0) == pytest.approx(1700.0, abs=5.0)  # one count at 50 Hz: 20 ms / 4096
    # and a burst read returns what the registers hold
    assert device.read_block(p.led_register(0), 4) == p.channel_bytes_for_pulse(1700.0, prescale,
                                                                                p.INTERNAL_OSCILLATOR_HZ)
    # longer than an SMBus block (32 bytes): i2c_rdwr through the socket, both ways (ten channels, 40 bytes)
    block = b"".join(p.channel_bytes_for_pulse(1100.0 + 50.0 * k, prescale, p.INTERNAL_OSCILLATOR_HZ)
                     for k in range(10))
    device.write_block(p.led_register(0), block)
    assert emulator.pulse_width_us(9) == pytest.approx(1550.0, abs=5.0)
    assert device.read_block(p.led_register(0), len(block)) == block
    with pytest.raises(OSError) as exc:
        bus.read_byte_data(0x41, 0x00)  # nobody at 0x41: a NACK, as smbus2 reports it
    assert exc.value.errno == errno.EREMOTEIO
    bus.close()
    server.close()
    assert not (tmp_path / "i2c.sock").exists()


def _values(directory):
    """A parameter-file writer that also keeps what it wrote, to read the values back."""
    import yaml

    from hindrax_bringup.layout.launch_xml import write_parameter_file

    written = []

    def write(values):
        path = write_parameter_file(values, directory)
        written.append(yaml.safe_load(path.read_text())["/**"]["ros__parameters"])
        return path
    return write, written


def test_launch_processes_reads_a_launch_file_as_ros2_launch_would(tmp_path):
    from hindrax_tools.benchmarks.launch_layout import launch_processes, package_share

    inc = tmp_path / "inner.launch.xml"
    inc.write_text('<launch><arg name="rec" default="false" description="d"/><arg name="dir" default="runs" '
                   'description="d"/>'
                   '<node pkg="hindrax_drivers" exec="esc_node" name="esc">'
                   '<param from="$(find-pkg-share hindrax_common)/config/hindrax.yaml"/>'
                   '<remap from="wrench" to="pilot/wrench"/></node>'
                   '<node pkg="hindrax_bringup" exec="recorder_node" name="recorder" if="$(var rec)">'
                   '<param name="output_dir" value="$(var dir)"/></node></launch>')
    outer = tmp_path / "outer.launch.xml"
    outer.write_text(f'<launch><arg name="out" default="x" description="d"/>'
                     f'<include file="{inc}"><arg name="rec" value="true"/><arg name="dir" value="$(var out)/bags"/>'
                     f'</include><group><let name="g" value="sensors"/>'
                     f'<node pkg="hindrax_bringup" exec="$(var g)_node" respawn="true"/></group>'
                     f'<node pkg="hindrax_drivers" exec="static_tf_node" unless="true"/>'
                     f'<node pkg="foxglove_bridge" exec="foxglove_bridge" if="false"/></launch>')
    esc, rec, group = launch_processes(outer, {"out": "/data"})
    write, written = _values(tmp_path)
    assert (esc.label, esc.module) == ("esc", "hindrax_drivers.pca9685.node:main")
    # the remap reaches the process (the bench's former reader of its own dropped it)
    assert esc.process.ros_arguments(write) == ["--ros-args", "-r", "__node:=esc", "--params-file",
                                   str(package_share("hindrax_common") / "config/hindrax.yaml"),
                                   "-r", "wrench:=pilot/wrench"]
    args = rec.process.ros_arguments(write)
    assert args[:4] == ["--ros-args", "-r", "__node:=recorder", "--params-file"]
    assert written == [{"output_dir": "/data/bags"}]
    # a composed process has no name: its nodes keep theirs; its row is the executable without _node
    assert (group.process.name, group.label, group.module) == (
        None, "sensors", "hindrax_bringup.layout.composition:sensors_main")
    with pytest.raises(ValueError, match="outt"):
        launch_processes(outer, {"outt": "/data"})
    outer.write_text('<launch><node pkg="hindrax_drivers" exec="no_such_node"/></launch>')
    with pytest.raises(ValueError, match="no_such_node"):
        launch_processes(outer)


def test_the_bench_measures_the_pool_test_launch_file_with_recording_on(tmp_path):
    from hindrax_tools.benchmarks.launch_layout import launch_processes, package_share
    from hindrax_tools.benchmarks.stack import LAUNCH_FILE

    procs = launch_processes(package_share(LAUNCH_FILE[0]) / LAUNCH_FILE[1], {"output_dir": "/tmp/b"})
    entries = [p.module for p in procs]
    # the identification node, the controller and the recorder, in one process (hindrax_onboard.composition)
    assert "hindrax_onboard.composition:ident_record_main" in entries
    assert not [p for p in procs if p.module.startswith("hindrax_bringup.recording")]  # recorded once
    controller = next(p for p in procs if p.module == "hindrax_onboard.composition:ident_record_main")
    assert controller.process.node_names == ("identification", "controller", "recorder")
    write, written = _values(tmp_path)
    controller.process.ros_arguments(write)
    # the empty default stays the empty string (not None, not "''"); output_dir is the root of the recorder's
    # timestamped bags (recording/bag_dir.py)
    assert {"model_file": "", "recording.output_root": "/tmp/b", "autostart": True, "all_topics": True,
            "exclude_regex": "^/(esc|guard|supervisor)/heartbeat|^/thrusters/command_pulse_width|"
                             "^/dvl/(twist|altitude)|^/ping/confidence|^/(pressure|imu)/temperature|"
                             "^/imu/mag$"} in written


def test_ports_file_appears_whole_or_not_at_all(tmp_path, monkeypatch):
    """The pool writes its ports file through a temporary file in the same folder and os.replace: while it writes, the
    file the stack benchmark waits for does not exist (it once existed empty, and json.loads failed on it); a failed
    write leaves nothing behind. The reader answers None until the file is there and whole."""
    import json

    from hindrax_tools.benchmarks import launch_layout as ll

    path = tmp_path / "ports.json"
    ports = {"dvl75": "/dev/pts/7", "ping1d": "/dev/pts/8"}
    seen_while_writing = []

    def slow_dump(obj, f):
        f.write("{")
        f.flush()
        seen_while_writing.append((path.exists(), ll.read_ports_file(path)))
        f.write(json.dumps(obj)[1:])

    monkeypatch.setattr(ll.json, "dump", slow_dump)
    ll.write_ports_file(path, ports)
    assert seen_while_writing == [(False, None)]
    assert ll.read_ports_file(path) == ports and [p.name for p in tmp_path.iterdir()] == ["ports.json"]

    def failing_dump(obj, f):
        f.write("{")
        raise OSError("disk full")

    monkeypatch.setattr(ll.json, "dump", failing_dump)
    with pytest.raises(OSError, match="disk full"):
        ll.write_ports_file(tmp_path / "other.json", ports)
    assert [p.name for p in tmp_path.iterdir()] == ["ports.json"]

    for text in ("", '{"dvl75": "/dev/pt', "[]"):  # what a non-atomic writer could leave for a moment; not an object
        path.write_text(text)
        assert ll.read_ports_file(path) is None
    assert ll.read_ports_file(tmp_path / "missing.json") is None


#: modules no vehicle process may hold: the virtual pool (simulator, emulated hardware) and the bench's own code
_POOL_MODULES = ("hindrax_sim", "hindrax_tools.benchmarks.launch_layout",
                 "hindrax_tools.benchmarks.stack")
#: the processes that run drivers or safety nodes only: they hold no scipy either (frames and mountings are numpy)
_LEAN_PROCESSES = ("sensors", "actuation", "supervisor", "output_guard", "gateway")
#: the identification node and the controller: no scipy or filterpy at start either (the online filters step
#: estimation/kalman.py, the priors' tables estimation/priors.py's own spline; the offline fits import scipy in the
#: function that uses it): scipy held ~50 MB of proportional set size in that process
_MODEL_PROCESSES = ("ident_record",)
_IMPORTS = """
import importlib, json, sys
sys.argv = ["x"]
entry = {entry!r}
# the bench's wrapper: must add nothing heavy
import hindrax_tools.benchmarks.launch_node as launch_node
module_name, _, function = entry.partition(":")
module = importlib.import_module(module_name)
groups = getattr(module, "GROUPS", {{}})
for node in groups.get(function.removesuffix("_main") + "_node", ()):  # what a composed process builds at start
    importlib.import_module(module.NODE_CLASSES[node].partition(":")[0])
print(json.dumps(sorted(sys.modules)))
"""


def test_node_processes_import_neither_the_pool_nor_scipy():
    """Every process of the pool-test launch layout, as the stack benchmark starts it (launch_node + the console
    script's module + a composed group's node modules), imports no simulator and no benchmark module (they once
    came with the bench's node wrapper, 1,009 MB PSS for the layout), and no process imports scipy or filterpy at
    start (~21 MB private per driver process, ~50 MB PSS in the identification and controller process). Fails naming
    the process and the modules."""
    import json
    import subprocess
    import sys

    from hindrax_common.testing import child_env
    from hindrax_tools.benchmarks.launch_layout import launch_processes, package_share
    from hindrax_tools.benchmarks.stack import LAUNCH_FILE

    layout = launch_processes(package_share(LAUNCH_FILE[0]) / LAUNCH_FILE[1])
    assert {lp.label for lp in layout} >= set(_LEAN_PROCESSES) | set(_MODEL_PROCESSES)
    procs = {lp.label: subprocess.Popen([sys.executable, "-c", _IMPORTS.format(entry=lp.module)], env=child_env(),
                                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for lp in layout}
    bad = {}
    for label, proc in procs.items():
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, f"{label}: {err[-2000:]}"
        modules = json.loads(out)
        forbidden = _POOL_MODULES + (("scipy", "filterpy") if label in _LEAN_PROCESSES + _MODEL_PROCESSES else ())
        found = sorted({f for m in modules for f in forbidden if m == f or m.startswith(f + ".")})
        if found:
            bad[label] = found
    assert not bad, f"node processes import what they must not: {bad}"


_PROFILED_NODE = r"""
from rclpy.node import Node

from hindrax_common.node_support.node_common import run_node


class ProfiledProbe(Node):
    def __init__(self):
        super().__init__("profiled_probe")
        self.ticks = 0
        self.create_timer(0.02, self.probe_tick)

    def probe_tick(self):
        self.ticks += 1
        if self.ticks == 5:
            print("spinning", flush=True)

    def close(self):
        print("closed", flush=True)


def main():
    return run_node(ProfiledProbe, [])
"""


def test_a_profiled_node_process_writes_its_profile_although_it_ends_itself(tmp_path):
    """``HINDRAX_BENCH_PROFILE``: a node process run by launch_node under cProfile writes ``<module>.prof`` when
    SIGINT ends it, although a node process ends itself with ``os._exit`` (ros_process, "Exit without the DDS
    participant's teardown"), which skips launch_node's ``finally``; the profile holds the node's timer callback.
    Before BEFORE_PROCESS_END no file was written."""
    import pstats
    import subprocess
    import threading

    from hindrax_common.testing import child_env, child_process, interrupt, python_executable, wait_until
    from hindrax_tools.benchmarks.launch_node import PROFILE_ENV

    (tmp_path / "profiled_probe.py").write_text(_PROFILED_NODE)
    profile_dir = tmp_path / "prof"
    profile_dir.mkdir()
    env = child_env()
    env[PROFILE_ENV] = str(profile_dir)
    env["PYTHONPATH"] = str(tmp_path) + (":" + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    with child_process([python_executable(), "-m", "hindrax_tools.benchmarks.launch_node",
                        "profiled_probe:main"],
                       env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
        reader.start()
        wait_until(lambda: any("spinning" in ln for ln in lines) or proc.poll() is not None, 60,
                   message="the profiled probe spinning")
        assert proc.poll() is None, "".join(lines)
        assert interrupt(proc, 30) == 0, "".join(lines)
    reader.join(10)
    assert "closed" in "".join(lines), "".join(lines)
    stats = pstats.Stats(str(profile_dir / "profiled_probe.main.prof"))
    ticks = [calls for (_, _, name), (calls, *_rest) in stats.stats.items() if name == "probe_tick"]
    assert ticks and ticks[0] >= 5, ticks


def test_benchmarked_threads_carry_their_python_names():
    """A thread started after :func:`launch_node.name_os_threads` shows its ``threading`` name (cut to 15 bytes) as
    its OS name, where the benchmark reads wake-ups and CPU by thread; without it it would read ``python``."""
    import threading
    from pathlib import Path

    from hindrax_tools.benchmarks import launch_node

    start = threading.Thread._bootstrap_inner
    seen = {}
    try:
        launch_node.name_os_threads()
        t = threading.Thread(target=lambda: seen.update(
            comm=Path(f"/proc/self/task/{threading.get_native_id()}/comm").read_text().strip()),
            name="dvl-serial-reader-thread")
        t.start()
        t.join(30)
    finally:
        threading.Thread._bootstrap_inner = start
    assert seen["comm"] == "dvl-serial-read"
