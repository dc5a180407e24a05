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
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor

from hindrax_drivers.allocation.node import ThrustAllocationNode
from hindrax_drivers.config import OPTIONAL_PREFIXES, SCHEMA
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_drivers.node_parameters import select_schema_keys
from hindrax_drivers.testing import config_parameters, ros_context, wait_until
from hindrax_drivers.tf.node import StaticTfNode
from hindrax_drivers.tf.static_tf import TF_KEYS
from hindrax_drivers.transport.emulated_i2c import EmulatedI2CBus


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
        from hindrax_drivers.allocation.node import ALLOCATION_KEYS

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
        # writable, valid: applied by the node
        r = set_param(call, "ms5837", "environment.surface_pressure_pa",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=101000.0))
        assert r.successful and baro.surface_pressure_pa == pytest.approx(101000.0)
        before = alloc.core.allocator
        r = set_param(call, "thrust_allocation", "thrusters.t1.trim_us",
                      ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5.0))
        assert r.successful and alloc.core.allocator is not before
        # a cross-key check of the file loader also guards a running change
        r = set_param(call, "thrust_allocation", "thrusters.t2.esc_channel",
                      ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=0))
        assert not r.successful and "esc_channel" in r.reason and "already used" in r.reason


def test_without_overrides_the_node_takes_the_shipped_vehicle_file_and_still_only_its_keys():
    with running(lambda c: StaticTfNode(context=c)) as (nodes, call):
        names = listed(call, "static_tf")
        assert vehicle_keys(names) == expected(TF_KEYS)
        assert len(nodes[0].message.transforms) == 12


def test_node_specific_parameters_are_described_too():
    from hindrax_drivers.recording.recorder_node import RecorderNode
    from hindrax_ident.sim.node import SimulatorNode

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
