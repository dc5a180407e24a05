"""Node parameters as a ROS 2 user sees them, through the standard parameter services of running nodes.

Each node is given every vehicle key (as bringup and `--params-file hindrax.yaml` do) and must declare only its
own, each with a description and the allowed range from the configuration schema; a read-only key is refused
with a reason, an invalid value of a writable key is refused with a reason, a valid one is applied.
Clients: rcl_interfaces ListParameters / DescribeParameters / SetParameters (what `ros2 param` calls).
"""
from __future__ import annotations

import contextlib

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor

from hindrax_bringup.allocation.node import ThrustAllocationNode
from hindrax_common.config import OPTIONAL_PREFIXES, SCHEMA
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_common.config.node_parameters import select_schema_keys
from hindrax_common.node_support.esc_state import esc_state_values
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_drivers.tf.node import StaticTfNode
from hindrax_drivers.tf.static_tf import TF_KEYS
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus


@contextlib.contextmanager
def running(*factories):
    """Nodes built in one context and spun by one executor, plus a client node; yields (nodes, call)."""
    with ros_context() as ctx:
        nodes = [f(ctx) for f in factories]
        client = rclpy.create_node("param_client", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        for n in nodes + [client]:
            ex.add_node(n)

        def call(node_name: str, srv_type, srv: str, request):
            cli = client.create_client(srv_type, f"/{node_name}/{srv}")
            wait_until(lambda: cli.service_is_ready(), 10, lambda: ex.spin_once(timeout_sec=0.02), f"{srv} ready")
            fut = cli.call_async(request)
            wait_until(fut.done, 10, lambda: ex.spin_once(timeout_sec=0.02), f"{srv} answered")
            client.destroy_client(cli)
            return fut.result()
        try:
            yield nodes, call
        finally:
            ex.shutdown()
            for n in nodes + [client]:
                n.destroy_node()


def listed(call, name):
    return set(call(name, ListParameters, "list_parameters", ListParameters.Request()).result.names)


def describe(call, name, names):
    return {d.name: d for d in call(name, DescribeParameters, "describe_parameters",
                                    DescribeParameters.Request(names=sorted(names))).descriptors}


def set_param(call, name, key, value: ParameterValue):
    req = SetParameters.Request(parameters=[ParameterMsg(name=key, value=value)])
    return call(name, SetParameters, "set_parameters", req).results[0]


def vehicle_keys(names):
    return {n for n in names if n.split(".")[0] in {k.split(".")[0] for k in SCHEMA}}


def expected(prefixes):
    names = [f"t{i}" for i in range(1, 9)]
    keys = set()
    for k in select_schema_keys(prefixes):
        keys |= {k.replace("<thruster>", n) for n in names} if "<thruster>" in k else {k}
    return {k for k in keys if not k.startswith(("simulation.sensors.", "recording.topics"))}


ALL = config_parameters()


def test_each_node_declares_only_its_own_keys_with_descriptions_and_ranges():
    with running(lambda c: ThrustAllocationNode(context=c, parameter_overrides=ALL),
                 lambda c: StaticTfNode(context=c, parameter_overrides=ALL),
                 lambda c: Ms5837Node(bus=EmulatedI2CBus({}), context=c, parameter_overrides=ALL)) as (nodes, call):
        from hindrax_bringup.allocation.node import ALLOCATION_KEYS

        for node_name, prefixes in (("thrust_allocation", ALLOCATION_KEYS), ("static_tf", TF_KEYS),
                                    ("ms5837", ("sensors.ms5837", "environment"))):
            names = listed(call, node_name)
            assert vehicle_keys(names) == expected(prefixes), node_name
            descriptors = describe(call, node_name, names - {"use_sim_time"})
            for key, d in descriptors.items():
                assert d.description, f"{node_name}: {key} has no description"
                if key in vehicle_keys(names):
                    assert d.additional_constraints.startswith("allowed "), (key, d.additional_constraints)
                    # typed once it has a value; an optional key absent from the file has none
                    assert d.type != ParameterType.PARAMETER_NOT_SET or key.startswith(OPTIONAL_PREFIXES), key
        d = describe(call, "ms5837", ["sensors.ms5837.rate_hz", "environment.surface_pressure_pa",
                                      "sensors.ms5837.oversampling"])
        spec = SCHEMA["sensors.ms5837.rate_hz"]
        rate = d["sensors.ms5837.rate_hz"]
        assert rate.read_only and rate.type == ParameterType.PARAMETER_DOUBLE
        assert (d["sensors.ms5837.rate_hz"].floating_point_range[0].from_value,
                d["sensors.ms5837.rate_hz"].floating_point_range[0].to_value) == (spec.lo, spec.hi)
        assert "4096" in d["sensors.ms5837.oversampling"].additional_constraints  # choices spelled out
        assert not d["environment.surface_pressure_pa"].read_only  # zero_depth writes it while running


def test_read_only_and_invalid_changes_are_refused_with_a_reason_and_valid_ones_applied():
    with running(lambda c: ThrustAllocationNode(context=c, parameter_overrides=ALL),
                 lambda c: Ms5837Node(bus=EmulatedI2CBus({}), context=c, parameter_overrides=ALL)) as (nodes, call):
        alloc, baro = nodes
        r = set_param(call, "ms5837", "sensors.ms5837.rate_hz",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=20.0))
        assert not r.successful and "read-only" in r.reason and "sensors.ms5837.rate_hz" in r.reason
        assert baro.get_parameter("sensors.ms5837.rate_hz").value == pytest.approx(10.0)
        r = set_param(call, "thrust_allocation", "esc.pwm_frequency_hz",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=100.0))
        assert not r.successful and "read-only" in r.reason
        # writable, out of range / wrong type: refused with the reason
        r = set_param(call, "ms5837", "environment.surface_pressure_pa",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=10.0))
        assert not r.successful and "environment.surface_pressure_pa" in r.reason
        r = set_param(call, "ms5837", "environment.surface_pressure_pa",
                      ParameterValue(type=ParameterType.PARAMETER_STRING, string_value="high"))
        assert not r.successful and r.reason
        # writable, valid: refused until the ESC reports disarmed (read-only while armed), then applied by the node
        r = set_param(call, "ms5837", "environment.surface_pressure_pa",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=101000.0))
        assert not r.successful and "esc/output_state" in r.reason and baro.surface_pressure_pa == 101325.0
        disarmed = DiagnosticStatus(values=[KeyValue(key=k, value=v) for k, v in esc_state_values(False, 1, "")])
        alloc.armed.take(disarmed)
        baro.armed.take(disarmed)
        r = set_param(call, "ms5837", "environment.surface_pressure_pa",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=101000.0))
        # and then checked as pressure/zero_depth is (issue 71.7): this sensor has no reading to check it against
        assert not r.successful and "no pressure reading yet" in r.reason and baro.surface_pressure_pa == 101325.0
        before = alloc.core.allocator
        r = set_param(call, "thrust_allocation", "thrusters.t1.trim_us",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5.0))
        assert r.successful and alloc.core.allocator is not before
        # a cross-key check of the file loader also guards a running change
        r = set_param(call, "thrust_allocation", "thrusters.t2.esc_channel",
                      ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=0))
        assert not r.successful and "esc_channel" in r.reason and "already used" in r.reason


def test_a_writable_vehicle_key_cannot_be_declared_without_the_arm_lock():
    """Every key a node applies while running is read-only while armed: declaring one without a ``locked`` check (the
    ESC's :class:`~hindrax_common.node_support.esc_state.ArmedWatch`) is a programming error, caught before any
    parameter exists."""
    from hindrax_common.config.node_parameters import declare_vehicle_parameters

    with ros_context() as ctx:
        node = rclpy.create_node("lockless", context=ctx)
        try:
            with pytest.raises(ValueError, match="locked"):
                declare_vehicle_parameters(node, ("environment",), dynamic=("environment.surface_pressure_pa",),
                                           on_change=lambda cfg: None)
            assert not node.has_parameter("environment.surface_pressure_pa")
        finally:
            node.destroy_node()


def test_without_overrides_the_node_takes_the_shipped_vehicle_file_and_still_only_its_keys():
    with running(lambda c: StaticTfNode(context=c)) as (nodes, call):
        names = listed(call, "static_tf")
        assert vehicle_keys(names) == expected(TF_KEYS)
        assert len(nodes[0].message.transforms) == 12


def test_node_specific_parameters_are_described_too():
    from hindrax_bringup.recording.recorder_node import RecorderNode
    from hindrax_sim.node import SimulatorNode

    rclpy_own = {"use_sim_time", "start_type_description_service"}  # declared by rclpy itself
    with running(lambda c: SimulatorNode(context=c, parameter_overrides=ALL),
                 lambda c: RecorderNode(context=c, parameter_overrides=ALL)) as (nodes, call):
        for name in ("hindrax_simulator", "recorder"):
            names = listed(call, name) - rclpy_own
            assert len(names) > (100 if name == "hindrax_simulator" else 8)
            undocumented = sorted(k for k, d in describe(call, name, names).items() if not d.description)
            assert not undocumented, (name, undocumented)
        # its own section only (recording.topics is optional: declared, without a value unless given)
        assert vehicle_keys(listed(call, "recorder")) - {"recording.topics"} == expected(("recording",))


def test_bringup_passes_its_safety_timeouts_as_read_only_parameters_ros2_param_get_sees():
    """``hindrax bringup`` (one process) widens the safety heartbeats' timeout to 2 s and, with the virtual pool
    holding simulated time on purpose, the clock-stall checks to 30 s: as parameter overrides of the nodes, so the
    value each node uses is the one its parameter services report (GetParameters, as ``ros2 param get``), read-only
    and described with its allowed range; the vehicle file keeps its own 0.2 s."""
    from rcl_interfaces.srv import GetParameters

    from hindrax_common.config import default_config_path, load_config
    from hindrax_sim.graph.bringup import build_graph

    shipped = load_config(default_config_path()).esc
    assert shipped.heartbeat_timeout_s == shipped.guard_heartbeat_timeout_s == 0.2
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, drive_clocks=True, identification=False, context=ctx)
        client = rclpy.create_node("param_client", context=ctx)
        graph.executor.add_node(client)
        graph.freeze_time()

        def call(node_name, srv_type, srv, request):
            cli = client.create_client(srv_type, f"/{node_name}/{srv}")
            wait_until(cli.service_is_ready, 10, graph.spin_once, f"{node_name}/{srv} ready")
            fut = cli.call_async(request)
            wait_until(fut.done, 10, graph.spin_once, f"{node_name}/{srv} answered")
            client.destroy_client(cli)
            return fut.result()

        try:
            seen = {}
            for node_name, names in (("esc", ["heartbeat_timeout_s", "steady_watchdog_timeout_s"]),
                                     ("output_guard", ["heartbeat_timeout_s"]),
                                     ("supervisor", ["clock_stall_timeout_s"])):
                values = call(node_name, GetParameters, "get_parameters", GetParameters.Request(names=names)).values
                seen.update({f"{node_name}.{n}": v.double_value for n, v in zip(names, values)})
                for n, d in describe(call, node_name, names).items():
                    assert d.read_only and d.type == ParameterType.PARAMETER_DOUBLE, (node_name, n)
                    assert d.description and d.additional_constraints.startswith("allowed number in ["), (node_name, n)
            assert seen == {"esc.heartbeat_timeout_s": 2.0, "esc.steady_watchdog_timeout_s": 30.0,
                            "output_guard.heartbeat_timeout_s": 2.0, "supervisor.clock_stall_timeout_s": 30.0}
            # ... and the nodes use those values
            esc, guard, supervisor = (graph.nodes[n] for n in ("esc", "output_guard", "supervisor"))
            assert (esc.peers.timeout_s, esc.steady_watchdog_s) == (2.0, 30.0)
            assert guard.timeout_s == guard.core.timeout_s == guard.esc_age.max_step_s == 2.0
            assert supervisor.core.limits.clock_stall_timeout_s == 30.0
            r = set_param(call, "esc", "heartbeat_timeout_s",
                          ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=0.2))
            assert not r.successful and "read-only" in r.reason
        finally:
            graph.executor.remove_node(client)
            client.destroy_node()
            graph.shutdown()


@pytest.mark.parametrize("factory, name, value, line", [
    ("esc", "heartbeat_timeout_s", 0.0, "heartbeat_timeout_s = 0.0: allowed number in [0.05, 10]"),
    ("esc", "steady_watchdog_timeout_s", 600.0, "steady_watchdog_timeout_s = 600.0: allowed number in [0.02, 60]"),
    ("output_guard", "heartbeat_timeout_s", "long", "heartbeat_timeout_s = 'long': allowed number in [0.05, 10]"),
    ("supervisor", "clock_stall_timeout_s", -1.0, "clock_stall_timeout_s = -1.0: allowed number in [0.2, 120]"),
])
def test_a_bad_node_parameter_stops_the_node_with_one_line(factory, name, value, line):
    from rclpy.parameter import Parameter

    from hindrax_common.config import ConfigError
    from hindrax_bringup.guard.node import OutputGuardNode
    from hindrax_drivers.pca9685.emulator import Pca9685Emulator
    from hindrax_drivers.pca9685.node import EscNode
    from hindrax_bringup.supervisor.node import SupervisorNode

    make = {"esc": lambda **kw: EscNode(bus=EmulatedI2CBus({0x40: Pca9685Emulator()}), **kw),
            "output_guard": lambda **kw: OutputGuardNode(bus=EmulatedI2CBus({}), **kw),
            "supervisor": SupervisorNode}[factory]
    with ros_context() as ctx:
        with pytest.raises(ConfigError) as err:
            make(context=ctx, parameter_overrides=ALL + [Parameter(name, value=value)])
    assert str(err.value) == f"parameters of {factory}: {line}"


def test_the_parameters_a_running_vehicle_node_accepts_are_the_documented_ones():
    """docs/threat_model.md §5: at run time only the allocation's thrusters.* and the MS5837's surface pressure are
    writable (each behind the arm lock and its checks); every rclpy built-in and every other parameter is read-only."""
    from hindrax_bringup.guard.node import OutputGuardNode
    from hindrax_drivers.pca9685.emulator import Pca9685Emulator
    from hindrax_drivers.pca9685.node import EscNode
    from hindrax_bringup.supervisor.node import SupervisorNode
    from hindrax_common.transport.gpio import EmulatedGpioLine

    factories = {
        "thrust_allocation": lambda c: ThrustAllocationNode(context=c, parameter_overrides=ALL),
        "ms5837": lambda c: Ms5837Node(bus=EmulatedI2CBus({}), context=c, parameter_overrides=ALL),
        "static_tf": lambda c: StaticTfNode(context=c, parameter_overrides=ALL),
        "supervisor": lambda c: SupervisorNode(context=c, parameter_overrides=ALL),
        "output_guard": lambda c: OutputGuardNode(line=EmulatedGpioLine(), context=c, parameter_overrides=ALL),
        "esc": lambda c: EscNode(bus=EmulatedI2CBus({0x40: Pca9685Emulator()}), context=c, parameter_overrides=ALL),
    }
    with ros_context() as ctx:
        for label, make in factories.items():
            node = make(ctx)
            try:
                writable = sorted(n for n in node._parameters if not node.describe_parameter(n).read_only)
            finally:
                node.destroy_node()
            if label == "thrust_allocation":
                assert writable and all(n.startswith("thrusters.") for n in writable), writable
            elif label == "ms5837":
                assert writable == ["environment.surface_pressure_pa"], writable
            else:
                assert writable == [], (label, writable)
