"""Bring up the Hindrax node graph in one process (SingleThreadedExecutor; docs/architecture.md §11.5: the
MultiThreadedExecutor is broken here, and launch is not available).

Nodes: the device drivers (:data:`hindrax_common.base.devices.DEVICES`: DVL-75, Ping1D, MS5837, ICM-20948, and the ESC
output on the PCA9685), the thrust allocation, the safety supervisor (:mod:`hindrax_bringup.supervisor.node`), the
static TF (/tf_static), the identification executive (:mod:`hindrax_onboard.identification.online.node`, always: on
the vehicle as in the virtual pool, it cannot tell them apart; ``hindrax ident start`` sends it a campaign) and,
optionally, the recorder. On the vehicle they open the configured serial ports and ``/dev/i2c-N``. With ``sim=True``
the virtual pool replaces the hardware: a :class:`SimulatorNode` publishing ``/clock`` and
:class:`~hindrax_sim.hardware.VirtualHardware` (every device's emulator fed by the simulator: serial devices
on pseudo-terminals served in lock-step with the simulated clock, I2C devices on an emulated bus); every other node
then runs with ``use_sim_time`` and the simulator takes the thrusters' pulse widths from the PCA9685 registers.

Each node class also runs alone (``python -m hindrax_drivers.<device>.node --ros-args --params-file ...``)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from rclpy.executors import ShutdownException, TimeoutException
from rclpy.parameter import Parameter

from hindrax_common.base import devices as device_table
from hindrax_bringup.allocation.node import ThrustAllocationNode
from hindrax_common.process.conditions import wait_until
from hindrax_common.config import ConfigError, VehicleConfig, load_config
from hindrax_common.config.sections.esc import board_id
from hindrax_bringup.gateway.interface import GATEWAY_NODE
from hindrax_bringup.guard.node import OutputGuardNode
from hindrax_bringup.recording.recorder_node import RecorderNode
from hindrax_common.process.ros_process import RosProcess
from hindrax_bringup.supervisor.node import SupervisorNode
from hindrax_common.process.dds_transport import loopback_transport
from hindrax_drivers.tf.node import StaticTfNode
from hindrax_common.node_support.vehicle_graph import (ForeignVehicleError, ForeignVehicleWatch, own_view,
                                                        refuse_before_start)
from hindrax_common.node_support.vehicle_node import VehicleNode
from hindrax_msgs.srv import SetArmed

from hindrax_onboard.control.node import ControllerNode
from hindrax_onboard.identification.online.node import IdentificationNode
from .ordered_executor import LeanWaitExecutor
from ..hardware import VirtualHardware
from ..node import SimulatorNode
from ..simulator import Simulator


@dataclass
class Graph:
    """A running node graph: ``nodes`` (name -> node), the executor, the virtual hardware (sim only).

    ``stepped`` (sim with driven clocks, :func:`build_graph`): the simulator node is not in the executor; each
    :meth:`spin_once` advances it by one /clock period and then runs the callbacks ready at that instant
    (:meth:`spin_until_idle`). What runs at a tick then never depends on wall-clock timing (on a timer, the simulator
    could advance again before a driver's timer due at this tick had run, or not, depending on the load)."""

    config: VehicleConfig
    nodes: dict[str, Any]
    executor: Any
    hardware: Any = None
    context: Any = None
    closers: list[Callable[[], None]] = field(default_factory=list)
    stepped: bool = False
    _frozen: bool = False

    def spin_once(self, timeout_sec: float = 0.01) -> None:
        """Run the graph a little: one executor callback (waiting up to ``timeout_sec``), or, when ``stepped`` and
        time is not frozen, one /clock period of the simulator followed by every callback due (see the class
        docstring; at a real-time factor > 0 it first waits, handling callbacks, until the tick is due)."""
        if not self.stepped or self._frozen:
            self.executor.spin_once(timeout_sec=timeout_sec)
            return
        sim = self.nodes["simulator"]
        wait_s = sim.wall_time_until_next_tick_s()
        if wait_s > 0.0:
            self.executor.spin_once(timeout_sec=min(timeout_sec, wait_s))
            return
        sim.advance_clock_period()  # False while a step gate holds the time: the nodes run, then it asks again
        self.spin_until_idle()

    def spin_until_idle(self, max_callbacks: int = 100_000) -> int:
        """Run the callbacks one wait with zero timeout finds ready (rclpy ends a zero-timeout
        pass with a timeout: those these make ready run at the next call); returns how many ran."""
        for n in range(max_callbacks):
            try:
                handler, _entity, _node = self.executor.wait_for_ready_callbacks(0.0)
            except (TimeoutException, ShutdownException):
                return n
            handler()
            if handler.exception() is not None:
                raise handler.exception()
        return max_callbacks

    # -- simulated time (sim only): hold it while something happens at one simulated instant
    @property
    def time_frozen(self) -> bool:
        """True while :meth:`freeze_time` holds the simulated time."""
        if self.stepped:
            return self._frozen
        sim = self.nodes.get("simulator")
        return sim is not None and sim not in self.executor.get_nodes()

    def freeze_time(self) -> None:
        """Stop simulated time (every other node keeps running at the frozen instant), e.g. while an operator's
        service call or goal is answered, so that it takes effect at the same simulated instant whatever the wall
        time it needs. No-op without a simulator."""
        if self.stepped:
            self._frozen = True
        elif "simulator" in self.nodes and not self.time_frozen:
            self.executor.remove_node(self.nodes["simulator"])

    def resume_time(self) -> None:
        """Let simulated time run again after :meth:`freeze_time`. Stepped, the nodes first finish what is due at
        the frozen instant, so the state from which time resumes does not depend on how long the freeze took."""
        if self.stepped:
            if self._frozen:
                self.spin_until_idle()
            self._frozen = False
        elif self.time_frozen:
            self.executor.add_node(self.nodes["simulator"])

    def startup_complete(self) -> bool:
        """Poll (with time frozen, between executor spins) until True: the serial drivers are connected with their
        start-up commands taken and answered (:meth:`~.sim.hardware.VirtualHardware.serial_startup_done`), and
        the recorder, if any, is subscribed to every topic a node of the graph publishes. Starting the
        simulated clock only then makes a run independent of how long discovery and port opening took."""
        if self.hardware is not None and not self.hardware.serial_startup_done():
            return False
        recorder = self.nodes.get("recorder")
        if recorder is None:
            return True
        recorder.discover_now()
        wanted = {pub.topic_name for name, node in self.nodes.items() if name != "recorder" for pub in node.publishers}
        return recorder.subscribed_to(wanted)

    def start_and_arm(self, arm_client: Any, timeout_s: float, ready: Callable[[], bool] = lambda: True,
                      spin_timeout_s: float = 0.01) -> Any:
        """The operator's start of a simulated run, each step at a simulated instant independent of wall time:
        with time frozen, wait for :meth:`startup_complete`, ``arm_client`` (an ``esc/set_armed`` client) ready and
        ``ready()``; let time run through the ESC's arming time (``esc.arming_time_s`` at neutral); with time frozen
        again, wait for the ESC's steady-clock arming time and the safety heartbeats, and answer the arm request.
        Returns the SetArmed response. Raises :class:`~hindrax_common.process.conditions.ConditionTimeout` when a step
        takes longer than ``timeout_s`` of wall time."""
        spin = lambda: self.spin_once(spin_timeout_s)  # noqa: E731
        self.freeze_time()
        wait_until(lambda: self.startup_complete() and arm_client.service_is_ready() and ready(), timeout_s, spin,
                   "drivers' start-up, recorder subscriptions and services")
        # the vehicle holds neutral for esc.arming_time_s of simulated time (the drivers finish their start-up
        # meanwhile); the ESC counts its arming time and the safety heartbeats on the steady clock
        # (docs/architecture.md §8), so the rest of that wait happens with simulated time held: the arm request
        # lands at the same simulated instant whatever the machine's speed
        esc = self.nodes["esc"]
        self.resume_time()
        t0_ns = esc.get_clock().now().nanoseconds
        wait_until(lambda: esc.get_clock().now().nanoseconds - t0_ns >= esc.arming_time_s * 1e9, timeout_s, spin,
                   "ESC arming time (simulated)")
        self.freeze_time()
        wait_until(lambda: esc.arming_remaining_s() == 0.0 and not esc.heartbeat_refusal(), timeout_s, spin,
                   "ESC arming time (steady clock) and the supervisor's and guard's heartbeats")
        fut = arm_client.call_async(SetArmed.Request(arm=True))
        wait_until(fut.done, timeout_s, spin, "arm answer")
        self.resume_time()
        return fut.result()

    def shutdown(self) -> None:
        """Close every node (the ESC node writes neutral), stop the emulators, destroy the nodes. The emulators'
        pseudo-terminals are closed (and their /tmp folders removed) even when a step before fails, e.g. on a
        context a signal already shut down."""
        try:
            for name in reversed(list(self.nodes)):
                close = getattr(self.nodes[name], "close", None)
                if callable(close):
                    try:
                        close()
                    except Exception as exc:  # noqa: BLE001 - keep closing the others
                        print(f"bringup: closing {name}: {exc}")
            for closer in self.closers:
                closer()
            # a task the executor never ran (an action goal's execute coroutine when Ctrl-C or SIGTERM came) is
            # closed, not left to the garbage collector's "coroutine ... was never awaited" at exit
            for task, _entity, _node in list(getattr(self.executor, "_tasks", ())):
                if not task.done():
                    task.cancel()
            self.executor.shutdown()
            for node in self.nodes.values():
                node.destroy_node()
        finally:
            if self.hardware is not None:
                self.hardware.close()


#: heartbeat timeout of the ESC and the output guard inside one process (their parameter ``heartbeat_timeout_s``;
#: see build_graph), s
SINGLE_PROCESS_HEARTBEAT_TIMEOUT_S = 2.0
#: with the virtual pool, simulated time may stand still on purpose (step gates, Graph.freeze_time): the supervisor's
#: clock-stall check (``clock_stall_timeout_s``) and, with driven clocks, the ESC's steady-clock watchdog
#: (``steady_watchdog_timeout_s``) wait this long before they take it for a stalled clock, s
SIMULATED_TIME_HOLD_S = 30.0


def build_graph(config_path: str | Path, *, sim: bool = False, record: bool = False, record_dir: str = "",
                overrides: dict | None = None, context: Any = None, seed: int | None = None,
                real_time_factor: float | None = None, identification: bool = True,
                drive_clocks: bool = False, i2c_bus: Any = None, truth: Any = None, controller: bool = False,
                model_file: str = "", truth_rate_hz: float | None = None, parameter_services: bool = True) -> Graph:
    """Create every node of the stack (rclpy must be initialised for ``context``).

    config_path: vehicle configuration. sim: virtual pool instead of hardware. record: start the recorder
    (all topics) writing to ``record_dir`` (empty: timestamped directory under ``recording.output_root``).
    overrides: dotted configuration keys. seed / real_time_factor: simulation settings.
    identification: add the identification node (action ``run_identification``; default True, with or without
    ``sim``). controller: add the controller node (depth/altitude, heading and velocity holds, disabled until
    ``controller/hold``; docs/control.md) with the model of ``model_file`` ("" = the vehicle file's).
    i2c_bus (not with ``sim``): an object with the ``smbus2.SMBus`` interface every I2C node uses instead
    of opening its configured ``/dev/i2c-N`` (e.g. the emulated bus of
    :class:`~hindrax_sim.hardware.VirtualHardware`, to run the vehicle graph against emulated devices).
    drive_clocks (sim only): the simulator sets the nodes' clocks directly and publishes no /clock (about 20 %
    faster; for a graph nothing outside this process needs simulated time from, e.g. ``hindrax run``), and the
    graph is ``stepped``: drive it with :meth:`Graph.spin_once`, not ``executor.spin()``.
    truth_rate_hz (sim only): rate of the simulator's ground truth (sim/odometry, sim/wrench), Hz (default the clock
    rate; no node under test reads it).
    parameter_services: False leaves out the nodes' parameter and type-description services
    (:class:`~hindrax_common.node_support.vehicle_node.VehicleNode`; a graph nothing outside this process
    inspects, e.g. ``hindrax run``'s: a third fewer entities in each executor wait).
    Raises :class:`~hindrax_common.config.ConfigError` for an invalid configuration."""
    overrides = dict(overrides or {})
    if seed is not None:
        overrides["simulation.seed"] = int(seed)
    if real_time_factor is not None:
        overrides["simulation.real_time_factor"] = float(real_time_factor)
    cfg = load_config(config_path, overrides)
    hardware = None
    nodes: dict[str, Any] = {}
    kw: dict[str, Any] = {"context": context} if context is not None else {}
    nkw = kw if parameter_services else {**kw, "start_parameter_services": False}
    if sim:
        simulator = Simulator(cfg, truth=truth)  # the pool's truth (sim/truth.py); the nodes keep cfg
        hardware = VirtualHardware(simulator, simulator.config, seed=cfg.simulation.seed, serial_threads=False)
        rate = [] if truth_rate_hz is None else [Parameter("truth_rate_hz", value=float(truth_rate_hz))]
        nodes["simulator"] = SimulatorNode(config=cfg, simulator=simulator, pulse_width_source=hardware.pulse_widths_us,
                                           parameter_overrides=rate, **nkw)
        # The emulated PCA9685 reports its oscillator (VirtualHardware builds it at esc.oscillator_hz): measured, as
        # `hindrax esc calibrate` measures a real part, when it is the configured one (then the ESC puts pulses out)
        measured = hardware.emulators["pca9685"].oscillator_hz == cfg.esc.oscillator_hz
        ports = {f"{d.section}.port": hardware.ports[d.name] for d in device_table.DEVICES if d.name in hardware.ports}
        cfg = cfg.with_overrides({**ports, "esc.oscillator_calibrated": measured,
                                  "esc.oscillator_measured_on": f"{board_id()} emulated"})
        bus = hardware.i2c_bus
    else:
        bus = i2c_bus  # None: each I2C node opens smbus2.SMBus(<its configured bus>)
    params = [Parameter(k, value=v) for k, v in cfg.to_ros_parameters().items()]
    if sim:
        params.append(Parameter("use_sim_time", value=True))
    common = dict(parameter_overrides=params, **nkw)
    # one process, one executor thread: a slow callback delays the ESC, the supervisor and the guard alike, and none
    # of them can die or hang alone, so their heartbeats get a wide timeout (the vehicle runs them as processes)
    wide_beats = [Parameter("heartbeat_timeout_s", value=SINGLE_PROCESS_HEARTBEAT_TIMEOUT_S)]
    # simulated time may stand still on purpose (step gates, freeze_time): not a stalled /clock; stepped (driven
    # clocks), the ESC's wall-clock watchdog for a dead /clock must not trip during such a hold either, or the run
    # would depend on the machine's speed
    hold = [Parameter("clock_stall_timeout_s", value=SIMULATED_TIME_HOLD_S)] if sim else []
    steady = [Parameter("steady_watchdog_timeout_s", value=SIMULATED_TIME_HOLD_S)] if sim and drive_clocks else []
    # simulated: the chip jobs run in the executor thread, so that a write lands at the simulated instant of its
    # command (lock-step; the emulated bus answers at once); on hardware the ESC's bus has a thread of its own
    extra = {"esc": {"chip_thread": not sim, "parameter_overrides": params + wide_beats + steady}}
    for d in device_table.DEVICES:
        nodes[d.node] = device_table.build_node(d, bus, **{**common, **extra.get(d.node, {})})
    nodes["thrust_allocation"] = ThrustAllocationNode(**common)

    # disarms the ESC on a breach (supervisor.*)
    nodes["supervisor"] = SupervisorNode(**{**common, "parameter_overrides": params + hold})

    # the second stop path (docs/architecture.md §8): the ESC arms only with its heartbeat; without /OE wired it
    # silences the chip over the same bus
    nodes["output_guard"] = OutputGuardNode(bus=bus, **{**common, "parameter_overrides": params + wide_beats})

    nodes["static_tf"] = StaticTfNode(**common)  # base_link -> every sensor and thruster frame, on /tf_static
    # the vehicle's name on its graph, where commands that move a vehicle look for it (the launch layout's gateway
    # node; this single-process graph has no topside: docs/architecture.md §8.2)
    nodes["gateway"] = VehicleNode(GATEWAY_NODE, namespace="/" + cfg.vehicle.name,
                                   **{"start_parameter_services": False, **nkw})
    if identification:
        nodes["identification"] = IdentificationNode(config=cfg, **common)
        if sim:  # lock-step: simulated time waits for every control tick of a running manoeuvre
            nodes["simulator"].add_step_gate(nodes["identification"].clock_may_advance)
    if controller:
        nodes["controller"] = ControllerNode(config=cfg, model_file=model_file, **common)
        if sim:  # lock-step while it holds, as for the identification node
            nodes["simulator"].add_step_gate(nodes["controller"].clock_may_advance)
    if hardware is not None:
        # emulators on the drivers' ROS clock (the MS5837 driver's): conversion waits line up exactly
        ms5837_clock = nodes["ms5837"].get_clock()
        if drive_clocks:  # the clock moves only at the simulator's ticks: read once per tick, before the emulators
            now_s = [ms5837_clock.now().nanoseconds * 1e-9]
            nodes["simulator"].add_clock_listener(lambda _t: now_s.__setitem__(0, ms5837_clock.now().nanoseconds
                                                                               * 1e-9))
            hardware.use_clock(lambda: now_s[0])
        else:
            hardware.use_clock(lambda: ms5837_clock.now().nanoseconds * 1e-9)
        # serial devices in lock-step: sent at the clock tick, handled by the driver before time moves on
        serial = {d.name: nodes[d.node] for d in device_table.DEVICES if d.transport == device_table.SERIAL}
        hardware.lock_step_serial(nodes["simulator"], {n: node.transport for n, node in serial.items()},
                                  ready={n: (lambda c=node.commands: c.sequences_completed >= 1)
                                         for n, node in serial.items()})
    if record:
        rec_params = params + [Parameter("all_topics", value=True), Parameter("autostart", value=True),
                               Parameter("output_dir", value=str(record_dir))]
        nodes["recorder"] = RecorderNode(parameter_overrides=rec_params, **nkw)
    if sim and drive_clocks:
        # the nodes keep use_sim_time (they start on simulated time; their /clock subscriptions stay
        # idle); the bag keeps every header stamp (`hindrax bag play --clock` rebuilds /clock)
        sim_node = nodes["simulator"]
        for name, node in nodes.items():
            if name != "simulator":
                sim_node.drive_clock(node.get_clock())
        sim_node.publish_clock_topic = False
    executor = LeanWaitExecutor(**kw)
    stepped = bool(sim and drive_clocks)
    for name, node in nodes.items():
        if not (stepped and name == "simulator"):  # stepped: Graph.spin_once advances the simulator
            executor.add_node(node)
    return Graph(cfg, nodes, executor, hardware, context, stepped=stepped)


def run(config_path: str | Path, *, sim: bool = False, record: bool = False, record_dir: str = "",
        seed: int | None = None, real_time_factor: float | None = None, controller: bool = False,
        model_file: str = "") -> int:
    """Process entry point of ``hindrax bringup``: build the graph, spin until SIGINT/SIGTERM, shut down
    (:class:`~hindrax_common.process.ros_process.RosProcess`; :meth:`Graph.shutdown` on the way out). Returns the exit
    status: 1 with one line on stderr for an invalid configuration."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST" if sim else "SUBNET")
    loopback_transport()  # loopback discovery: over the vehicle's loopback UDP transport
    with RosProcess(errors={ConfigError: "invalid configuration", ForeignVehicleError: "hindrax bringup"}) as proc:
        consequence = "refusing to start a second vehicle graph on it (set ROS_DOMAIN_ID to a free domain)"
        load_config(config_path)  # an invalid file is refused before the domain is watched
        refuse_before_start(None, consequence)  # before any node: a refused start leaves no heartbeat publisher
        graph = build_graph(config_path, sim=sim, record=record, record_dir=record_dir, seed=seed,
                            real_time_factor=real_time_factor, controller=controller, model_file=model_file)
        proc.at_exit(graph.shutdown)
        watch = ForeignVehicleWatch(next(iter(graph.nodes.values())), "refused", consequence,
                                    own=lambda: own_view(graph.nodes.values()), window_s=0.0)
        watch.check()
        watch.check_every()  # a vehicle discovered after the window (a loaded machine) ends it the same way
        print(f"bringup: {len(graph.nodes)} nodes ({', '.join(graph.nodes)}), "
              f"{'virtual pool' if sim else 'hardware'}; Ctrl-C to stop", flush=True)
        proc.spin(graph.executor)
    return proc.status
