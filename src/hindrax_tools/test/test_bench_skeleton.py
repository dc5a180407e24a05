"""The benchmark's launch skeleton, built from the launch processes' declared topology, has the same
processes, nodes and endpoints (topic, type, QoS, raw, events); others are refused."""
from __future__ import annotations

import contextlib
import copy
import functools
import subprocess

import pytest
import rclpy

from hindrax_bringup.layout.launch_xml import write_parameter_file
from hindrax_common.testing import (child_env, child_process, python_executable, ros_context,
                                     wait_until)
from hindrax_tools.benchmarks import stack
from hindrax_tools.benchmarks.launch_layout import launch_processes, package_share
from hindrax_tools.benchmarks.launch_node import TOPOLOGY_ENV

#: processes of the pool-test launch that run without the virtual pool's devices
_NO_DEVICES = ("supervisor", "gateway")


@pytest.fixture(scope="module")
def launch_topology(tmp_path_factory):
    """label -> topology of the pool-test launch's supervisor and gateway, started as the benchmark
    starts them (launch_node, the launch file's arguments and environment), read by SIGUSR1."""
    tmp = tmp_path_factory.mktemp("launch")
    launch_file = package_share(stack.LAUNCH_FILE[0]) / stack.LAUNCH_FILE[1]
    layout = [lp for lp in launch_processes(launch_file, {"output_dir": str(tmp / "bags")})
              if lp.label in _NO_DEVICES]
    assert [lp.label for lp in layout] == list(_NO_DEVICES)
    (tmp / "params").mkdir()
    values = functools.partial(write_parameter_file, directory=tmp / "params")
    env = child_env(**{TOPOLOGY_ENV: str(tmp)})
    launch_node = [python_executable(), "-m", "hindrax_tools.benchmarks.launch_node"]
    with contextlib.ExitStack() as stack_:
        procs = {lp.label: stack_.enter_context(child_process(
            [*launch_node, lp.module, *lp.process.ros_arguments(values)],
            env=dict(env, **dict(lp.process.env)), stdout=subprocess.DEVNULL,
            stderr=subprocess.STDOUT))
            for lp in layout}
        # signalled only once both are on the graph (SIGUSR1 ends a process without the handler),
        # then read until every node is in an executor (its constructor made every endpoint: a
        # fresh clone's suite read the supervisor while it declared its parameters, before its
        # subscriptions, 2026-11-29) and two reads agree
        with ros_context() as ctx:
            probe = rclpy.create_node("skeleton_test_probe", context=ctx)
            wait_until(lambda: {"supervisor", "gateway"} <= set(probe.get_node_names()), 120, None,
                       "both nodes")
            probe.destroy_node()
        seen: list = []

        def stable() -> bool:
            assert all(p.poll() is None for p in procs.values()), "a launch process exited"
            seen.append(stack.read_topologies(procs, tmp))
            return (len(seen) > 1 and seen[-1] == seen[-2]
                    and all(t["nodes"] and t["spinning"] for t in seen[-1].values()))

        wait_until(stable, 120, None, "the launch processes' topology")
        envs = {lp.label: ([], dict(lp.process.env)) for lp in layout}
        return seen[-1], envs


def test_the_skeleton_has_the_launch_processes_endpoints(launch_topology):
    """The skeleton built from the launch processes' declared topology declares the same one (read
    back from its processes, the same way), and the launch's topology is the real one: the
    supervisor's sensor readers are best effort, the gateway's nodes are in their namespace."""
    topo, envs = launch_topology
    subs = [s for n in topo["supervisor"]["nodes"] for s in n["subscriptions"]]
    assert {n["namespace"] for n in topo["gateway"]["nodes"]} == {"/hindrax"}, topo["gateway"]
    assert any(s["qos"]["reliability"] == 2 for s in subs), subs  # BEST_EFFORT
    rates = {p["topic"]: 5.0 for t in topo.values() for n in t["nodes"] for p in n["publishers"]}
    skel = stack._skeleton(stack.skeleton_spec(topo, [rates]), [], 1.0, envs, check=topo)
    assert stack.topology_differences(topo, skel["topology"]) == []


def test_a_skeleton_missing_a_process_a_topic_or_a_qos_is_refused(launch_topology):
    """topology_differences names a process missing, a topic missing and a QoS changed; the
    benchmark's run-time check (``_skeleton(..., check=)``) raises on such a difference."""
    topo, envs = launch_topology
    no_process = {k: v for k, v in topo.items() if k != "gateway"}
    diff = stack.topology_differences(topo, no_process)
    assert diff[0] == "process gateway only in the launch", diff
    assert all("'gateway'" in d for d in diff[1:]), diff
    no_topic = copy.deepcopy(topo)
    node = next(n for n in no_topic["supervisor"]["nodes"] if n["subscriptions"])
    gone = node["subscriptions"].pop()
    diff = stack.topology_differences(topo, no_topic)
    assert len(diff) == 1 and gone["topic"] in diff[0], diff
    assert diff[0].startswith("only in the launch"), diff
    other_qos = copy.deepcopy(topo)
    pub = next(p for n in other_qos["supervisor"]["nodes"] for p in n["publishers"])
    pub["qos"]["depth"] += 1
    diff = stack.topology_differences(topo, other_qos)
    assert len(diff) == 2 and all(pub["topic"] in d for d in diff), diff
    with pytest.raises(RuntimeError, match="not the launch's"):
        stack._skeleton(stack.skeleton_spec(no_topic, [{}]), [], 1.0, envs, check=topo)
