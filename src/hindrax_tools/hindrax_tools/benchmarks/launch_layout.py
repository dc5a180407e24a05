"""The vehicle's launch layout for the stack benchmark: the processes of the launch file, devices emulated.

:func:`launch_processes` lists the processes of a launch XML file (``pool_test.launch.xml``, which includes
``vehicle.launch.xml``) through :func:`hindrax_bringup.layout.launch_xml.read_launch`, the project's one reader of
launch files, each with its console script's function; the benchmark starts them with the arguments ``ros2 launch``
would give (the ``launch`` package is not installable here, docs/architecture.md §11.3).

``python -m hindrax_tools.benchmarks.launch_layout pool --socket PATH --ports-file FILE``:
the virtual pool in its own process (excluded from the stack's CPU): the simulator
at real-time factor 1 (no ``/clock``, no ground truth: every node on system time), the serial
emulators on pseudo-terminals, the I2C emulators on an
:class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` served over a Unix socket
(:class:`I2CSocketServer`), all on ``time.monotonic``. The pty paths go to ``--ports-file`` (JSON,
:func:`write_ports_file`: whole or not at all) once everything is up."""
from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import tempfile
import threading
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Mapping

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from hindrax_common.config import default_config_path, load_config
from hindrax_common.process.dds_transport import loopback_transport
from hindrax_bringup.layout.launch_xml import NodeProcess, read_launch
from hindrax_common.transport.socket_i2c import I2CSocketServer
from hindrax_sim.hardware import VirtualHardware
from hindrax_sim.node import SimulatorNode
from hindrax_sim.simulator import Simulator


os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
loopback_transport()  # the vehicle's transport (hindrax_common.process.dds_transport)

#: the workspace's own packages: their share directory is the source package directory in a checkout
OWN_PACKAGES = ("hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard")


@dataclass(frozen=True)
class LaunchProcess:
    """One ``<node>`` of a launch file, as :func:`hindrax_bringup.layout.launch_xml.read_launch` reads it (the reader of
    the pool-day test and ``hindrax health``), with the function its console script runs.

    process: the node process (package, executable, name, parameters, remaps, ...); module: the console script's
    target, ``module:function``."""

    process: NodeProcess
    module: str

    @property
    def label(self) -> str:
        """The process's name in the benchmark's rows: the node name (``-r __node:=``), else, for a
        composed process, the executable without ``_node``."""
        return self.process.name or re.sub(r"_node$", "", self.process.executable)


def package_share(package: str) -> Path:
    """``$(find-pkg-share package)`` for this workspace's packages: the source package directory (it holds
    ``launch/`` and ``config/`` as colcon installs them under ``share/``). Raises ValueError for another package."""
    if package not in OWN_PACKAGES:
        raise ValueError(f"$(find-pkg-share {package}): not a package of this workspace")
    return Path(importlib.import_module(package).__file__).resolve().parents[1]


def console_scripts(package: str) -> dict[str, str]:
    """Console script name -> ``module:function`` of ``package`` (installed entry points). Raises ValueError when
    the package has none (not installed: ``make setup``)."""
    out = {ep.name: ep.value.replace(" ", "") for ep in entry_points(group="console_scripts")
           if ep.dist is not None and ep.dist.name.replace("-", "_") == package}
    if not out:
        raise ValueError(f"{package}: no console scripts installed (run make setup)")
    return out


def launch_processes(path: str | Path, arguments: Mapping[str, str] | None = None) -> list[LaunchProcess]:
    """The processes ``ros2 launch`` would start for the launch XML file ``path`` with ``arguments`` (name ->
    value; the others take their defaults), in launch order, includes and groups expanded: those of
    :func:`hindrax_bringup.layout.launch_xml.read_launch` (``$(find-pkg-share)`` resolved to this checkout's packages),
    each with the function its console script runs.

    Raises :class:`~hindrax_bringup.layout.launch_xml.LaunchFileError` (a ValueError) for what the reader refuses (an
    undeclared argument, an unsupported element or substitution, a non-boolean condition), and ValueError for an
    enabled node of another package or an executable the package does not install."""
    out = []
    for proc in read_launch(path, arguments, find_share=package_share):
        scripts = console_scripts(proc.package) if proc.package in OWN_PACKAGES else {}
        if proc.executable not in scripts:
            raise ValueError(f"{Path(path).name}: {proc.package}/{proc.executable} is not an executable of this "
                             f"workspace")
        out.append(LaunchProcess(proc, scripts[proc.executable]))
    return out


def write_ports_file(path: str | Path, ports: Mapping[str, str]) -> None:
    """Write the pool's pseudo-terminal paths to ``path`` as JSON, atomically: a temporary file in the same folder,
    then ``os.replace``: a reader waiting for ``path`` never reads it empty or half written."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(dict(ports), f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_ports_file(path: str | Path) -> dict | None:
    """The ports :func:`write_ports_file` wrote to ``path``, or None while there is no such file or it is not a whole
    JSON object yet (a writer that is not atomic), for a ``wait_until``."""
    try:
        ports = json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return ports if isinstance(ports, dict) else None


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name; module docstring): runs the
    virtual pool until interrupted; returns the exit code."""
    parser = argparse.ArgumentParser(prog="python -m hindrax_tools.benchmarks.launch_layout")
    parser.add_argument("command", choices=["pool"])
    parser.add_argument("--socket", required=True)
    parser.add_argument("--ports-file", required=True)
    args = parser.parse_args(argv)
    cfg = load_config(default_config_path(), {"simulation.real_time_factor": 1.0})
    rclpy.init()
    lock = threading.Lock()
    simulator = Simulator(cfg)
    truth = simulator.config  # the simulator's truth (vehicle file + simulation keys), as bringup
    hardware = VirtualHardware(simulator, truth, seed=cfg.simulation.seed, serial_threads=True)
    hardware.use_clock(time.monotonic)
    node = SimulatorNode(config=cfg, simulator=simulator, pulse_width_source=hardware.pulse_widths_us)
    node.publish_clock_topic = False
    node._publish_truth = lambda *_a: None  # no ground truth on the wire: the recorder records every topic
    node._publish_contact = lambda *_a: None
    original_step = node._step_once

    def locked_step() -> None:  # the I2C server threads call the emulators (and so the simulator) too
        with lock:
            original_step()

    node._step_once = locked_step
    server = I2CSocketServer(hardware.i2c_bus, args.socket, lock)
    write_ports_file(args.ports_file, hardware.ports)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        server.close()
        hardware.close()
        ex.shutdown()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
