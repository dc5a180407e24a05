"""The vehicle's launch layout for the stack benchmark: one process per node, devices emulated.

Two entry points (``python -m hindrax_ident.benchmarks.launch_layout pool|node ...``):

``pool --socket PATH --ports-file FILE [--set KEY=VALUE ...]``
    The virtual pool in its own process (excluded from the stack's CPU): the simulator at real-time factor 1
    (no ``/clock`` and no ground-truth topics: every node runs on system time, as on the vehicle), the DVL-75 and Ping1D
    emulators on pseudo-terminals served by their own threads, and the MS5837, ICM-20948 and PCA9685 emulators on an
    :class:`~hindrax_drivers.transport.emulated_i2c.EmulatedI2CBus` served over a Unix socket
    (:class:`I2CSocketServer`). The emulators run on ``time.monotonic`` (the drivers' clock here). The pty paths
    are written to ``--ports-file`` (JSON) once everything is up.

``node MODULE --ros-args ...``
    Runs ``MODULE.main()`` (e.g. ``hindrax_drivers.ms5837.node``) exactly as ``python -m MODULE --ros-args ...``
    would, except that ``open_smbus`` returns a :class:`SocketI2CBus` connected to the pool when the
    environment variable ``HINDRAX_BENCH_I2C_SOCKET`` is set. With ``HINDRAX_BENCH_PROFILE=DIR`` the node runs under
    cProfile and writes ``DIR/<module>.prof`` on exit (``python -m pstats``). A transaction is then one request/answer
    on a Unix socket in the driver process (two system calls and a pickle each way), which stands in for the ``ioctl``
    of a real ``smbus2.SMBus`` on the Pi; the emulator's own work happens in the pool process.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import threading
import time
from pathlib import Path

from hindrax_drivers.transport.socket_i2c import I2CSocketServer, SocketI2CBus

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

SOCKET_ENV = "HINDRAX_BENCH_I2C_SOCKET"
#: a directory: each node process runs under cProfile and writes ``<module>.prof`` there when it exits
PROFILE_ENV = "HINDRAX_BENCH_PROFILE"


def _pool(argv: list[str]) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    from hindrax_drivers.config import default_config_path, load_config
    from hindrax_ident.sim.hardware import VirtualHardware
    from hindrax_ident.sim.node import SimulatorNode
    from hindrax_ident.sim.simulator import Simulator

    parser = argparse.ArgumentParser(prog="launch_layout pool")
    parser.add_argument("--socket", required=True)
    parser.add_argument("--ports-file", required=True)
    parser.add_argument("--config", default=str(default_config_path()))
    parser.add_argument("--set", action="append", default=[], help="KEY=JSON configuration override")
    args = parser.parse_args(argv)
    overrides = {"simulation.real_time_factor": 1.0}
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = json.loads(value)
    cfg = load_config(args.config, overrides)
    rclpy.init()
    lock = threading.Lock()
    simulator = Simulator(cfg)
    truth = getattr(simulator, "config", cfg)  # the simulator's truth (vehicle file + simulation keys), as bringup
    hardware = VirtualHardware(simulator, truth, seed=cfg.get("simulation.seed"), serial_threads=True)
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
    Path(args.ports_file).write_text(json.dumps({"dvl75": hardware.dvl_port, "ping1d": hardware.ping_port}))
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


def _node(argv: list[str]) -> int:
    module_name, rest = argv[0], argv[1:]
    path = os.environ.get(SOCKET_ENV)
    module = importlib.import_module(module_name)
    if path:
        import hindrax_drivers.transport.i2c as i2c

        opener = lambda _bus_number: SocketI2CBus(path)  # noqa: E731
        i2c.open_smbus = opener
        if hasattr(module, "open_smbus"):
            module.open_smbus = opener
    sys.argv = [module_name] + rest
    profile_dir = os.environ.get(PROFILE_ENV)
    if not profile_dir:
        return int(module.main() or 0)
    import cProfile

    profiler = cProfile.Profile()
    try:
        return int(profiler.runcall(module.main) or 0)
    finally:
        profiler.dump_stats(str(Path(profile_dir) / f"{module_name}.prof"))


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name); returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("pool", "node"):
        print("usage: python -m hindrax_ident.benchmarks.launch_layout pool|node ...", file=sys.stderr)
        return 2
    return _pool(argv[1:]) if argv[0] == "pool" else _node(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
