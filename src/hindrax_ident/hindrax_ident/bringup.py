"""Bring up the Hindrax node graph in one process (SingleThreadedExecutor; ros2-pip.md: the
MultiThreadedExecutor is broken here, and launch is not available).

Nodes: the four sensor drivers (DVL-75, Ping1D, MS5837, ICM-20948), the ESC output (PCA9685), the thrust
allocation, the identification executive (:mod:`hindrax_ident.identification.node`, on by default with
``sim``) and, optionally, the recorder. On the vehicle they open the configured serial ports and
``/dev/i2c-N``. With ``sim=True`` the virtual pool replaces the hardware: a :class:`SimulatorNode` publishing
``/clock`` and :class:`~hindrax_ident.sim.hardware.VirtualHardware` (the five device emulators fed by the
simulator: serial devices on pseudo-terminals, I2C devices on an emulated bus); every other node then runs
with ``use_sim_time`` and the simulator takes the thrusters' pulse widths from the PCA9685 registers.

Each node class also runs alone (``python -m hindrax_drivers.<device>.node --ros-args --params-file ...``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from hindrax_drivers.config import VehicleConfig, load_config


@dataclass
class Graph:
    """A running node graph: ``nodes`` (name -> node), the executor, the virtual hardware (sim only)."""

    config: VehicleConfig
    nodes: dict[str, Any]
    executor: Any
    hardware: Any = None
    context: Any = None
    closers: list[Callable[[], None]] = field(default_factory=list)

    def spin_once(self, timeout_sec: float = 0.01) -> None:
        self.executor.spin_once(timeout_sec=timeout_sec)

    def shutdown(self) -> None:
        """Close every node (the ESC node writes neutral), stop the emulators, destroy the nodes."""
        for name in reversed(list(self.nodes)):
            close = getattr(self.nodes[name], "close", None)
            if callable(close):
                try:
                    close()
                except Exception as exc:  # noqa: BLE001 - keep closing the others
                    print(f"bringup: closing {name}: {exc}")
        for closer in self.closers:
            closer()
        self.executor.shutdown()
        for node in self.nodes.values():
            node.destroy_node()
        if self.hardware is not None:
            self.hardware.close()


def build_graph(config_path: str | Path, *, sim: bool = False, record: bool = False, record_dir: str = "",
                overrides: dict | None = None, context: Any = None, seed: int | None = None,
                real_time_factor: float | None = None, identification: bool | None = None,
                drive_clocks: bool = False) -> Graph:
    """Create every node of the stack (rclpy must be initialised for ``context``).

    config_path: vehicle configuration. sim: virtual pool instead of hardware. record: start the recorder
    (all topics) writing to ``record_dir`` (empty: timestamped directory under ``recording.output_root``).
    overrides: dotted configuration keys. seed / real_time_factor: simulation settings.
    identification: add the identification node (action ``run_identification``); default: ``sim``.
    drive_clocks (sim only): the simulator sets the nodes' clocks directly and publishes no /clock (about 20 %
    faster; for a graph nothing outside this process needs simulated time from, e.g. ``hindrax run``).
    Raises :class:`~hindrax_drivers.config.ConfigError` for an invalid configuration.
    """
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from hindrax_drivers.allocation.node import ThrustAllocationNode
    from hindrax_drivers.dvl75.node import Dvl75Node
    from hindrax_drivers.icm20948.node import Icm20948Node
    from hindrax_drivers.ms5837.node import Ms5837Node
    from hindrax_drivers.pca9685.node import EscNode
    from hindrax_drivers.ping1d.node import Ping1dNode

    overrides = dict(overrides or {})
    if seed is not None:
        overrides["simulation.seed"] = int(seed)
    if real_time_factor is not None:
        overrides["simulation.real_time_factor"] = float(real_time_factor)
    cfg = load_config(config_path, overrides)
    hardware = None
    nodes: dict[str, Any] = {}
    kw: dict[str, Any] = {"context": context} if context is not None else {}
    if sim:
        from .sim.hardware import VirtualHardware
        from .sim.node import SimulatorNode
        from .sim.simulator import Simulator

        simulator = Simulator(cfg)
        hardware = VirtualHardware(simulator, cfg, seed=cfg.get("simulation.seed"))
        nodes["simulator"] = SimulatorNode(config=cfg, simulator=simulator,
                                           pulse_width_source=hardware.pulse_widths_us, **kw)
        cfg = cfg.with_overrides({"sensors.dvl75.port": hardware.dvl_port, "sensors.ping1d.port": hardware.ping_port})
        bus = hardware.i2c_bus
    else:
        bus = None  # each I2C node opens smbus2.SMBus(<its configured bus>)
    params = [Parameter(k, value=v) for k, v in cfg.to_ros_parameters().items()]
    if sim:
        params.append(Parameter("use_sim_time", value=True))
    common = dict(parameter_overrides=params, **kw)
    nodes["dvl75"] = Dvl75Node(**common)
    nodes["ping1d"] = Ping1dNode(**common)
    nodes["ms5837"] = Ms5837Node(bus=bus, **common)
    nodes["icm20948"] = Icm20948Node(bus=bus, **common)
    nodes["esc"] = EscNode(bus=bus, **common)
    nodes["thrust_allocation"] = ThrustAllocationNode(**common)
    if (sim if identification is None else identification):
        from .identification.node import IdentificationNode

        nodes["identification"] = IdentificationNode(config=cfg, **common)
        if sim:  # lock-step: simulated time waits for every control tick of a running manoeuvre
            nodes["simulator"].add_step_gate(nodes["identification"].clock_may_advance)
    if hardware is not None:
        # emulators on the drivers' ROS clock (the MS5837 driver's): conversion waits line up exactly
        ms5837_clock = nodes["ms5837"].get_clock()
        hardware.use_clock(lambda: ms5837_clock.now().nanoseconds * 1e-9)
    if record:
        from hindrax_drivers.recording.recorder_node import RecorderNode

        rec_params = params + [Parameter("all_topics", value=True), Parameter("autostart", value=True),
                               Parameter("output_dir", value=str(record_dir))]
        nodes["recorder"] = RecorderNode(parameter_overrides=rec_params, **kw)
    if sim and drive_clocks:
        # The simulator sets every node's ROS clock directly at each tick instead of publishing /clock to ten
        # subscriptions (the nodes keep use_sim_time, so they start on simulated time; their own /clock
        # subscriptions stay idle). /clock is then not on the wire: a ROS tool in another process that needs
        # simulated time sees none (the bag keeps every header stamp; `hindrax bag play --clock` rebuilds it).
        sim_node = nodes["simulator"]
        for name, node in nodes.items():
            if name != "simulator":
                sim_node.drive_clock(node.get_clock())
        sim_node.publish_clock_topic = False
    executor = SingleThreadedExecutor(**kw)
    for node in nodes.values():
        executor.add_node(node)
    return Graph(cfg, nodes, executor, hardware, context)


def run(config_path: str | Path, *, sim: bool = False, record: bool = False, record_dir: str = "",
        seed: int | None = None, real_time_factor: float | None = None) -> int:
    """Process entry point of ``hindrax bringup``: build the graph, spin until SIGINT/SIGTERM, shut down."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from hindrax_drivers.config import ConfigError

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST" if sim else "SUBNET")
    rclpy.init()
    graph = None
    status = 0
    try:
        graph = build_graph(config_path, sim=sim, record=record, record_dir=record_dir, seed=seed,
                            real_time_factor=real_time_factor)
        print(f"bringup: {len(graph.nodes)} nodes ({', '.join(graph.nodes)}), "
              f"{'virtual pool' if sim else 'hardware'}; Ctrl-C to stop", flush=True)
        graph.executor.spin()
    except ConfigError as exc:
        print(f"invalid configuration: {exc}")
        status = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        from hindrax_drivers.node_common import shutdown_in_progress

        if not shutdown_in_progress():
            raise
    finally:
        if graph is not None:
            graph.shutdown()
        if rclpy.ok():
            rclpy.shutdown()
    return status
