"""A heartbeat carries its sender's per-start value and a sequence, and a receiver accepts one
publisher with the expected node name (hindrax_common.node_support.liveness.HeartbeatIdentity, HeartbeatPublisher). On
simulated time the wall-clock liveliness lease does not silence a peer; its age on the graph's clock does
(AliveAge with a graph clock; the processes: test/test_sim_clock_liveness.py)."""
from __future__ import annotations

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from hindrax_common.cdr.lean_cdr import Beat
from hindrax_common.node_support.liveness import (AliveAge, HeartbeatIdentity, HeartbeatPublisher, heartbeat_ok,
                                                   simulated_now_s)
from hindrax_common.testing import ros_context, wait_until
from hindrax_msgs.msg import Heartbeat

A, B = 0xA1A1A1A1A1A1A1A1, 0xB2B2B2B2B2B2B2B2


def beat(boot_id, seq):
    return Beat(boot_id, seq, 0, 0, 0, 0, 0, False, "")


# (beats as (boot_id, seq, armed), accepted flags expected, fault substring expected at the end or "")
BEAT_TABLE = {
    "increasing": ([(A, 1, False), (A, 2, False), (A, 7, True)], [True, True, True], ""),
    "repeated": ([(A, 1, True), (A, 2, True), (A, 2, True)], [True, True, False], "repeated"),
    "went back": ([(A, 5, True), (A, 6, True), (A, 3, True)], [True, True, False], "went back"),
    "replay of the same boot after the live beats": (
        [(A, 100, True), (A, 101, True), (A, 1, True), (A, 2, True)], [True, True, False, False], "went back"),
    "boot change while armed": ([(A, 9, True), (B, 1, True)], [True, False], "boot_id changed"),
    "boot change while armed, then the old boot goes on": (
        [(A, 9, True), (B, 10, True), (A, 10, True)], [True, False, True], "boot_id changed"),
    "restart while disarmed": ([(A, 9, False), (B, 1, False), (B, 2, True)], [True, True, True], ""),
    "no boot_id": ([(0, 1, False)], [False], "without boot_id"),
    "no seq": ([(A, 0, False)], [False], "without boot_id"),
    "fault cleared by a beat accepted while disarmed": (
        [(A, 5, True), (A, 5, True), (A, 6, True), (A, 7, False)], [True, False, True, True], ""),
}


@pytest.mark.parametrize("case", list(BEAT_TABLE), ids=list(BEAT_TABLE))
def test_beat_table(case):
    beats, accepted, fault = BEAT_TABLE[case]
    ident = HeartbeatIdentity("supervisor/heartbeat", "supervisor")
    ident.on_publishers(["supervisor"])
    got = [ident.on_beat(beat(b, s), armed) for b, s, armed in beats]
    assert got == accepted
    if fault:
        assert fault in ident.fault and "supervisor/heartbeat" in ident.fault
    else:
        assert ident.fault == ""
    assert ident.rejected == accepted.count(False)


def test_bytes_that_are_not_a_beat_are_rejected_and_do_not_count():
    """A raw subscription hands the watch bytes that read_heartbeat cannot read (None): rejected, counted, and the
    fault holds until a beat is accepted while not armed."""
    ident = HeartbeatIdentity("supervisor/heartbeat", "supervisor")
    assert ident.on_beat(beat(A, 1), True)
    assert not ident.on_beat(None, True) and "without boot_id" in ident.fault and ident.rejected == 1
    assert ident.on_beat(beat(A, 2), True) and ident.fault  # still armed: the fault stays
    assert ident.on_beat(beat(A, 3), False) and ident.fault == ""


# (publisher node names in the graph, live publishers (None: count the names), fault substring or "")
PUBLISHER_TABLE = {
    "the supervisor alone": (["supervisor"], 1, ""),
    "the supervisor alone, graph count": (["supervisor"], None, ""),
    "a restarted supervisor beside its dead self": (["supervisor", "supervisor"], 1, ""),
    "a second live publisher with the same name": (["supervisor", "supervisor"], 2, "2 live publishers"),
    "two names, graph count": (["supervisor", "supervisor"], None, "2 live publishers"),
    "a forger beside the supervisor": (["supervisor", "forger"], 1, "node 'forger'"),
    "a bag player alone": (["rosbag2_player"], 1, "node 'rosbag2_player'"),
    "a dead forger still in the graph": (["forger", "supervisor"], 1, "node 'forger'"),
    "none live": (["supervisor"], 0, "no live publisher"),
    "none visible": ([], None, "no live publisher"),
    "a publisher discovery has not named yet": (["_NODE_NAME_UNKNOWN_"], 1, "not identified yet"),
    "a forger beside one not named yet": (["_NODE_NAME_UNKNOWN_", "forger"], 1, "node 'forger'"),
}


def test_a_publisher_not_named_yet_is_not_trusted_nor_called_forged_and_clears_when_named():
    """An endpoint seen before its participant's node names (the DDS placeholder ``_NODE_NAME_UNKNOWN_``, a loaded
    machine's discovery: an arm refused as "forged" in a CI run) is not the supervisor yet: a fault, so nothing arms
    on it, but not a forgery, and gone at the first check after discovery names it."""
    ident = HeartbeatIdentity("supervisor/heartbeat", "supervisor")
    assert ident.on_beat(beat(A, 1), False)
    out = ident.on_publishers(["_NODE_NAME_UNKNOWN_"], 1)
    assert out and "not identified yet" in out and "forged" not in out and "_NODE_NAME_UNKNOWN_" not in out
    assert ident.on_publishers(["supervisor"], 1) == ""


@pytest.mark.parametrize("case", list(PUBLISHER_TABLE), ids=list(PUBLISHER_TABLE))
def test_publisher_table(case):
    names, alive, fault = PUBLISHER_TABLE[case]
    ident = HeartbeatIdentity("supervisor/heartbeat", "supervisor")
    assert ident.on_beat(beat(A, 1), False)
    out = ident.on_publishers(names, alive)
    assert out == ident.fault
    assert (fault in out and "supervisor/heartbeat" in out) if fault else out == ""
    ident.on_publishers(["supervisor"], 1)  # the graph shows the supervisor alone again: the fault is gone
    assert ident.fault == ""


# (publisher node names in the graph, live publishers by the lease, fault substring or "" on simulated time, the same
# on the system clock)
SIMULATED_TABLE = {
    "the lease ran out on a starved machine, the supervisor still in the graph": (
        ["supervisor"], 0, "", "no live publisher"),
    "none in the graph": ([], 0, "no live publisher", "no live publisher"),
    "a second live publisher": (["supervisor", "supervisor"], 2, "2 live publishers", "2 live publishers"),
    "a restarted supervisor beside its dead self": (["supervisor", "supervisor"], 1, "", ""),
    "a forger whose lease ran out": (["supervisor", "forger"], 0, "node 'forger'", "node 'forger'"),
}


@pytest.mark.parametrize("case", list(SIMULATED_TABLE), ids=list(SIMULATED_TABLE))
def test_publisher_table_on_simulated_time(case):
    names, alive, fault, wall_fault = SIMULATED_TABLE[case]
    for simulated, expected in ((True, fault), (False, wall_fault)):
        out = HeartbeatIdentity("supervisor/heartbeat", "supervisor").on_publishers(names, alive, simulated)
        assert (expected in out and "supervisor/heartbeat" in out) if expected else out == "", (simulated, out)


class Clocks:
    """A steady clock and a simulated one, s, moved by the test."""

    def __init__(self):
        self.steady, self.sim = 100.0, 5000.0


def test_alive_age_on_simulated_time_is_late_only_when_late_on_the_graphs_clock():
    c = Clocks()
    age = AliveAge(0.2, clock=lambda: c.steady, graph_now_s=lambda: c.sim)  # the guard: max step = its timeout
    age.heard()
    for _ in range(30):  # 1.5 s of wall time, 0.06 s of a simulation at 0.04 x real time
        c.steady += 0.05
        c.sim += 0.002
        age.tick()
    assert age.steady_age_s == pytest.approx(1.5) and age.age_s == pytest.approx(0.06) and age.fresh(0.2)
    for _ in range(4):  # the simulation at real time: 0.2 s more on both clocks
        c.steady += 0.05
        c.sim += 0.05
        age.tick()
    assert age.age_s == pytest.approx(0.26) and not age.fresh(0.2)
    # a simulation faster than real time does not make steady-paced beats late
    age.heard()
    for _ in range(3):
        c.steady += 0.05
        c.sim += 0.5
        age.tick()
    assert age.age_s == pytest.approx(0.15) and age.fresh(0.2)
    # simulated time stepped back (a restarted /clock): counted from the step, not negative, not forgiven for ever
    age.heard()
    c.sim -= 100.0
    c.steady += 0.05
    assert age.tick() == 0.0
    for _ in range(5):
        c.steady += 0.05
        c.sim += 0.05
        age.tick()
    assert age.age_s == pytest.approx(0.25) and not age.fresh(0.2)


def test_alive_age_on_the_system_clock_is_the_steady_age():
    c = Clocks()
    age = AliveAge(0.2, clock=lambda: c.steady)
    age.heard()
    for _ in range(5):
        c.steady += 0.05
        age.tick()
    assert age.age_s == pytest.approx(0.25) and not age.fresh(0.2)


def test_alive_age_counts_from_the_beat_not_from_the_tick_before_it():
    """The busy-neighbours bench at nice -5 disarmed on an ESC beat gap of 182 ms, under the guard's
    0.2 s: the age counted each tick-to-tick gap in full, from the tick before the beat was heard,
    so at the guard's 20 Hz ticks a live peer read up to 50 ms older than its beat. A 180 ms gap
    between live beats, one tick 10 ms late: 165 ms."""
    c = Clocks()
    # the guard: ticks every 50 ms, max step = its timeout
    age = AliveAge(0.2, clock=lambda: c.steady)
    c.steady += 0.045
    age.heard()  # 45 ms after a tick
    for dt in (0.005, 0.05, 0.05, 0.06):  # the ticks at 50, 100, 150 and 210 ms
        c.steady += dt
        age.tick()
        assert age.fresh(0.2), age.age_s
    assert age.age_s == pytest.approx(0.165)
    for _ in range(2):  # no beat since: dead, stale once its beat is older than the timeout
        c.steady += 0.05
        age.tick()
    assert age.age_s == pytest.approx(0.265) and not age.fresh(0.2)


def test_the_clock_mode_is_the_receivers():
    """A node on the system clock judges by the lease and the steady age (None); one on use_sim_time by its ROS
    time, which follows /clock (or a simulator driving it)."""
    with ros_context() as ctx:
        wall = rclpy.create_node("wall", context=ctx)
        sim = rclpy.create_node("sim", context=ctx, parameter_overrides=[Parameter("use_sim_time", value=True)])
        assert simulated_now_s(wall) is None
        sim.get_clock().set_ros_time_override(rclpy.time.Time(seconds=1234.5))
        assert simulated_now_s(sim) == pytest.approx(1234.5)
        sim.destroy_node()
        wall.destroy_node()


def test_publisher_fault_comes_before_a_beat_fault():
    ident = HeartbeatIdentity("esc/heartbeat", "esc")
    ident.on_beat(beat(A, 3), True)
    ident.on_beat(beat(A, 2), True)
    ident.on_publishers(["esc", "x"], 1)
    assert ident.fault.startswith("esc/heartbeat published by node 'x'")
    ident.on_publishers(["esc"], 1)
    assert "went back" in ident.fault


def test_heartbeat_publisher_stamps_boot_id_and_seq_on_the_wire():
    with ros_context() as ctx:
        node = rclpy.create_node("supervisor", context=ctx)
        probe = rclpy.create_node("probe", context=ctx)
        got = []
        probe.create_subscription(Heartbeat, "supervisor/heartbeat", got.append, 10)
        first = HeartbeatPublisher(node, "supervisor")
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(probe)
        wait_until(lambda: first.publisher.get_subscription_count() > 0, 10, lambda: ex.spin_once(0.01), "matched")
        for _ in range(3):
            first.publish(True, "within the envelope", output_state=1, armed=True, guard_ack=(5, 4))
        wait_until(lambda: len(got) >= 3, 10, lambda: ex.spin_once(0.01), "three beats")
        assert [m.seq for m in got] == [1, 2, 3]
        assert {m.boot_id for m in got} == {first.boot_id} and first.boot_id != 0
        assert heartbeat_ok(got[0]) and got[0].message == "within the envelope"
        assert (got[0].output_state, got[0].armed, got[0].guard_boot_id, got[0].guard_seq) == (1, True, 5, 4)
        assert 0 < got[0].steady_ns <= got[1].steady_ns <= got[2].steady_ns
        # a receiver accepts them, and a restarted node is a new boot
        ident = HeartbeatIdentity("supervisor/heartbeat", "supervisor")
        ident.on_publishers([i.node_name for i in probe.get_publishers_info_by_topic("supervisor/heartbeat")], 1)
        assert all(ident.on_beat(m, True) for m in got) and ident.fault == ""
        second = HeartbeatPublisher(node, "supervisor")
        assert second.boot_id != first.boot_id
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_guard_core_silences_on_an_untrusted_heartbeat():
    from hindrax_bringup.guard.core import OUTPUT_NEUTRAL, GuardCore

    core = GuardCore(timeout_s=0.2)
    core.on_supervisor(True, "")
    core.on_esc(OUTPUT_NEUTRAL, False, 1)  # the ESC handled the guard's first (start-up, ERROR) beat
    assert core.decide(0.0, 0.0, 2) == (False, True)
    core.on_identity("2 live publishers on supervisor/heartbeat")
    assert core.decide(0.0, 0.0, 3) == (True, True) and core.reason.startswith("heartbeat not trusted: 2 live")
    core.on_identity("")
    assert core.decide(0.0, 0.0, 4) == (True, False)  # the ESC has not acknowledged beat 3 (ERROR) yet
    core.on_esc(OUTPUT_NEUTRAL, False, 3)
    assert core.decide(0.0, 0.0, 5) == (False, True)


def test_publisher_node_names_is_what_rclpy_s_endpoint_query_names():
    """The safety ticks' lean graph query (no TopicEndpointInfo per endpoint) names the same publishers as rclpy's
    ``get_publishers_info_by_topic``, for a relative, an absolute and a remapped topic, a namespaced receiver
    included, and follows a publisher leaving."""
    from hindrax_common.node_support.liveness import publisher_node_names

    with ros_context() as ctx:
        a = rclpy.create_node("supervisor", context=ctx)
        b = rclpy.create_node("forger", context=ctx)
        ns = rclpy.create_node("receiver", namespace="/robot", context=ctx,
                               cli_args=["--ros-args", "-r", "renamed/heartbeat:=/supervisor/heartbeat"])
        plain = rclpy.create_node("receiver", context=ctx)
        pubs = [a.create_publisher(Heartbeat, "supervisor/heartbeat", 10),
                b.create_publisher(Heartbeat, "/supervisor/heartbeat", 10)]

        def rclpy_names(node, topic):
            return sorted(i.node_name for i in node.get_publishers_info_by_topic(topic))
        wait_until(lambda: rclpy_names(plain, "supervisor/heartbeat") == ["forger", "supervisor"], 10, None,
                   "both publishers in the graph")
        for node, topic in ((plain, "supervisor/heartbeat"), (plain, "/supervisor/heartbeat"),
                            (ns, "/supervisor/heartbeat"), (ns, "renamed/heartbeat")):
            assert sorted(publisher_node_names(node, topic)) == rclpy_names(node, topic) == ["forger", "supervisor"]
        assert publisher_node_names(ns, "supervisor/heartbeat") == []  # /robot/supervisor/heartbeat: nobody
        b.destroy_publisher(pubs[1])
        wait_until(lambda: publisher_node_names(plain, "supervisor/heartbeat") == ["supervisor"], 10, None,
                   "the forger gone")
        with pytest.raises(Exception, match="topic"):
            publisher_node_names(plain, "bad topic name")


def test_the_graph_is_asked_on_dds_events_not_at_every_check():
    """PublisherNames asks the graph after a DDS event on the subscription (a publisher matched, or one of an
    incompatible QoS: rclpy's default QoS offers an infinite lease), for SETTLE_S after it, and at least every
    BACKSTOP_S; between, a check reuses the last answer. Every new publisher is named within the settle window."""
    from hindrax_common.node_support.liveness import BACKSTOP_S, SETTLE_S, PublisherNames, heartbeat_qos

    t = {"now": 100.0}
    with ros_context() as ctx, ros_context() as other:
        rx = rclpy.create_node("receiver", context=ctx)
        names = PublisherNames(rx, "supervisor/heartbeat", clock=lambda: t["now"])
        rx.create_subscription(Heartbeat, "supervisor/heartbeat", lambda _m: None, heartbeat_qos(), raw=True,
                               event_callbacks=names.event_callbacks())
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(rx)
        assert names.names() == [] and names.queries == 1  # the first check asks
        for _ in range(10):  # quiet: 10 checks in half the backstop ask nothing
            t["now"] += BACKSTOP_S / 20
            ex.spin_once(timeout_sec=0.01)
            names.names()
        assert names.queries == 1
        t["now"] += BACKSTOP_S / 2 + 0.01
        names.names()
        assert names.queries == 2  # the backstop
        peers = []
        for who, qos in (("supervisor", heartbeat_qos()), ("forger", 10)):
            peers.append(rclpy.create_node(who, context=other))
            peers[-1].create_publisher(Heartbeat, "supervisor/heartbeat", qos)
            asked = names.queries
            wait_until(lambda: who in names.names(), 20, lambda: ex.spin_once(timeout_sec=0.05), f"{who} named")
            assert names.queries > asked  # by the event: the fake clock stood still, the backstop never came
            t["now"] += SETTLE_S + 0.01  # settled: checks reuse the answer again
            asked = names.queries
            for _ in range(3):
                t["now"] += 0.01
                names.names()
            assert names.queries == asked
        assert sorted(names.names()) == ["forger", "supervisor"]
        ex.shutdown()
        rx.destroy_node()


def test_tick_gaps_report_the_longest_gap_and_where_the_cpu_went():
    """TickGaps keeps the longest gap between two ticks with the ticking thread's and the process's CPU time in it,
    reports it in ms and starts again."""
    from hindrax_common.node_support.liveness import TickGaps

    c = {"wall": 10.0, "thread": 1.0, "process": 2.0}
    gaps = TickGaps(lambda: c["wall"], lambda: c["thread"], lambda: c["process"])
    for wall, thread, process in ((0.02, 0.001, 0.002), (0.27, 0.001, 0.2), (0.05, 0.04, 0.045)):
        c["wall"] += wall
        c["thread"] += thread
        c["process"] += process
        gaps.tick()
    assert dict(gaps.report()) == {"tick_gap_max_ms": "270.0", "tick_gap_thread_cpu_ms": "1.0",
                                   "tick_gap_process_cpu_ms": "200.0"}
    c["wall"] += 0.02
    gaps.tick()
    assert dict(gaps.report())["tick_gap_max_ms"] == "20.0"
