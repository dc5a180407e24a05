"""The vehicle's DDS transport (hindrax_common.process.dds_transport): UDPv4 on 127.0.0.1 only, no shared memory.

Why the vehicle processes run with ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT, not LOCALHOST: under LOCALHOST
rmw_fastrtps puts its own shared-memory + UDP transports on every participant (Fast-DDS issue 6535's stall). The
live test shows that the replacement keeps everything on loopback: every UDP socket of every process of the
vehicle launch file is bound to 127.0.0.1 (or is a multicast group, joined on loopback by the white list), and no
process maps Fast DDS shared memory, while a LOCALHOST process (the control) does.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.config import default_config_path, load_config
from hindrax_common.process.dds_transport import (ANNOUNCE_PERIOD_S, DISCOVERY_BOUND_S, PROFILE_ENV, PROFILE_FILE,
                                                   RANGE_ENV, TOPSIDE_PROFILE_FILE, loopback_transport, profile_path,
                                                   wait_discovered)
from hindrax_bringup.layout.emulated_devices import EmulatedDevices
from hindrax_bringup.layout.launch_xml import read_launch
from hindrax_bringup.layout.process_runner import ProcessRunner
from hindrax_common.process.proc_sockets import child_pids, reachable_from_network, udp_sockets
from hindrax_common.testing import child_env, ros_context, wait_until

REPO = Path(__file__).resolve().parents[3]
PKG = REPO / "src" / "hindrax_bringup"
NS = "{http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles}"
WAIT_S = 90.0


def share(package: str) -> Path:
    return REPO / "src" / package


@pytest.mark.parametrize("given", [None, "", "LOCALHOST", "localhost"])
def test_loopback_discovery_becomes_the_udp_loopback_profile(given):
    env = {} if given is None else {RANGE_ENV: given}
    loopback_transport(env)
    assert env[RANGE_ENV] == "SYSTEM_DEFAULT"
    assert Path(env[PROFILE_ENV]).resolve() == (REPO / "ros_ws/config/fastdds_loopback.xml").resolve()


@pytest.mark.parametrize("given", ["OFF", "SYSTEM_DEFAULT"])
def test_other_discovery_ranges_keep_their_transports(given):
    env = {RANGE_ENV: given}
    loopback_transport(env)
    assert env == {RANGE_ENV: given}


def test_the_topside_keeps_its_range_and_gets_the_announcement_period_unless_a_profile_is_named():
    env = {RANGE_ENV: "SUBNET"}
    loopback_transport(env)
    assert env[RANGE_ENV] == "SUBNET"  # the topside's SUBNET reaches the network with Fast DDS's transports
    assert Path(env[PROFILE_ENV]).resolve() == (REPO / "ros_ws/config/fastdds_topside.xml").resolve()
    own = {RANGE_ENV: "SUBNET", PROFILE_ENV: "/etc/my_profile.xml"}
    assert loopback_transport(dict(own)) == own


@pytest.mark.parametrize("name", [PROFILE_FILE, TOPSIDE_PROFILE_FILE])
def test_both_profiles_announce_every_participant_at_the_period_the_discovery_waits_assume(name):
    participant = ET.parse(profile_path(name)).getroot().find(f"{NS}participant")
    assert participant.get("is_default_profile") == "true"
    lease = participant.find(f"{NS}rtps/{NS}builtin/{NS}discovery_config/{NS}leaseAnnouncement")
    assert int(lease.findtext(f"{NS}sec")) + int(lease.findtext(f"{NS}nanosec")) * 1e-9 == ANNOUNCE_PERIOD_S
    if name == TOPSIDE_PROFILE_FILE:  # no transport named: the range's own (the tether) stay
        assert participant.find(f"{NS}rtps/{NS}userTransports") is None
        assert participant.find(f"{NS}rtps/{NS}useBuiltinTransports") is None


class _Graph:
    """A graph whose view changes at the times given, and a clock that each pause advances by 0.05 s."""

    def __init__(self, changes=(), ready_at=0.0):
        self.t, self.changes, self.ready_at = 0.0, list(changes), ready_at

    def view(self):
        return sum(1 for c in self.changes if c <= self.t)

    def ready(self):
        return self.t >= self.ready_at

    def pause(self):
        self.t = round(self.t + 0.05, 6)


def _wait(graph, **kw):
    return wait_discovered(graph.view, graph.ready, graph.pause, clock=lambda: graph.t, **kw)


def test_discovery_wait_lasts_the_bound_then_until_the_graph_is_quiet_for_one_announcement_period():
    g = _Graph()
    assert _wait(g) and g.t == DISCOVERY_BOUND_S == 3 * ANNOUNCE_PERIOD_S  # nothing changes: the bound
    g = _Graph(changes=[0.3, 1.4])
    assert _wait(g) and g.t == pytest.approx(1.4 + ANNOUNCE_PERIOD_S)  # a late arrival: quiet after it
    g = _Graph(ready_at=2.2)
    assert _wait(g) and g.t == pytest.approx(2.2)  # not ready: waits for the condition


def test_discovery_wait_gives_up_at_its_cap_and_lets_a_refusal_through():
    g = _Graph(changes=[0.1 * k for k in range(200)])  # a graph that keeps changing
    assert not _wait(g, cap_s=4.0) and g.t == pytest.approx(4.0)
    g = _Graph(ready_at=99.0)
    assert not _wait(g, cap_s=2.0)

    def refuse():
        raise RuntimeError("a second vehicle")
    with pytest.raises(RuntimeError, match="a second vehicle"):
        wait_discovered(lambda: 0, refuse, lambda: None)


def test_the_profile_is_udpv4_on_loopback_only_without_builtin_transports():
    root = ET.parse(profile_path()).getroot()
    descriptors = root.findall(f"{NS}transport_descriptors/{NS}transport_descriptor")
    assert [d.findtext(f"{NS}type") for d in descriptors] == ["UDPv4"]
    assert [a.text for a in descriptors[0].iter(f"{NS}address")] == ["127.0.0.1"]
    participant = root.find(f"{NS}participant")
    assert participant.get("is_default_profile") == "true"  # rmw_fastrtps applies the default profile only
    assert participant.findtext(f"{NS}rtps/{NS}useBuiltinTransports") == "false"  # no shared memory
    assert [t.text for t in participant.iter(f"{NS}transport_id")] == [descriptors[0].findtext(f"{NS}transport_id")]


@pytest.mark.parametrize("launch", ["hindrax_bringup/vehicle.launch.xml", "hindrax_onboard/pool_test.launch.xml"])
def test_every_launched_process_gets_the_profile(launch):
    package, name = launch.split("/")
    procs = read_launch(share(package) / "launch" / name, {}, find_share=share)
    assert procs
    for p in procs:
        env = dict(p.env)
        assert env[RANGE_ENV] == "SYSTEM_DEFAULT", p.label
        assert Path(env[PROFILE_ENV]).resolve() == profile_path().resolve(), p.label


def _maps_shared_memory(pid: int) -> bool:
    """True when process ``pid`` maps a Fast DDS shared-memory segment (/dev/shm/fastrtps_*)."""
    return "/dev/shm/fastrtps" in Path(f"/proc/{pid}/maps").read_text()


@pytest.mark.ros
@pytest.mark.vehicle_launch
@pytest.mark.timeout(600)
def test_every_vehicle_udp_socket_binds_loopback_and_no_process_uses_shared_memory(tmp_path):
    cfg = load_config(default_config_path())
    procs = read_launch(PKG / "launch" / "vehicle.launch.xml", {"record": "true", "output_dir": str(tmp_path / "runs")},
                        find_share=share)
    expected = {n for p in procs for n in p.node_names}
    control = None
    # a shell that asks for loopback discovery only, as the Makefile's: the launch file's <set_env> does the rest
    plain = dict(child_env(), **{RANGE_ENV: "LOCALHOST"})
    plain.pop(PROFILE_ENV)
    with EmulatedDevices(cfg, tmp_path / "dev") as devices, ros_context() as ctx:
        runner = ProcessRunner(
            procs, env=plain,
            extra_env={p.label: {k: v for n in p.node_names for k, v in devices.env(n).items()} for p in procs},
            extra_ros_args={p.label: [a for n in p.node_names for a in devices.ros_arguments(n)] for p in procs},
            log_dir=tmp_path / "logs")
        probe = rclpy.create_node("transport_probe", context=ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(probe)
        try:
            runner.start()
            # the control: a plain LOCALHOST participant, as rmw_fastrtps sets it up (shared memory + UDP)
            control = subprocess.Popen([sys.executable, "-c", "import rclpy, time; rclpy.init(); "
                                        "n = rclpy.create_node('localhost_control'); time.sleep(600)"],
                                       env=plain)
            names = lambda: {n for n, _ in probe.get_node_names_and_namespaces()}  # noqa: E731
            try:
                wait_until(lambda: expected | {"localhost_control"} <= names(), WAIT_S,
                           lambda: executor.spin_once(timeout_sec=0.1), "every vehicle node discovered")
            except Exception as exc:
                tails = "\n".join(f"--- {p.label}:\n{runner.log(p.label)[-800:]}" for p in procs)
                raise AssertionError(f"{exc}; seen {sorted(names())}\n{tails}") from exc
            wait_until(lambda: _maps_shared_memory(control.pid), WAIT_S, lambda: time.sleep(0.05),
                       "the LOCALHOST control maps shared memory")
            states = runner.states()
            assert all(s.running for s in states.values()), states
            for label, state in states.items():
                pids = [state.pid]
                if label == "gateway":
                    # its topside process must reach the tether; its internal side is its child, on loopback like
                    # every other vehicle process (docs/architecture.md §8.2)
                    pids = child_pids(state.pid)
                    assert len(pids) == 1, (label, pids)
                for pid in pids:
                    sockets = udp_sockets(pid)
                    assert sockets, label  # a DDS participant holds UDP sockets: this looked at the right process
                    assert not any(reachable_from_network(a) for a, _ in sockets), (label, sockets)
                    assert not _maps_shared_memory(pid), label
            assert not any(a == "0.0.0.0" for a, _ in udp_sockets(os.getpid()))  # the tests' own process too
        finally:
            if control is not None:
                control.kill()
                control.wait()
            runner.stop()
            executor.shutdown()
            probe.destroy_node()
