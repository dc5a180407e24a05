"""Thrust-allocation node: wrench in, pulse widths/forces/status out; bad wrenches command neutral."""
import math

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_bringup.allocation.node import ThrustAllocationNode
from hindrax_common.config import default_config_path, load_config
from hindrax_common.node_support.esc_state import esc_state_values
from hindrax_common.testing import ros_context, wait_until
from hindrax_msgs.msg import AllocationStatus, ThrusterForces, ThrusterPwm

pytestmark = pytest.mark.ros


@pytest.fixture
def graph():
    with ros_context() as ctx:
        node = ThrustAllocationNode(context=ctx)
        probe = rclpy.create_node("probe", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        got = {"pwm": [], "forces": [], "status": []}
        probe.create_subscription(ThrusterPwm, "thrusters/command_pulse_width", got["pwm"].append, 10)
        probe.create_subscription(ThrusterForces, "thrusters/forces", got["forces"].append, 10)
        probe.create_subscription(AllocationStatus, "allocation/status", got["status"].append, 10)
        pub = probe.create_publisher(WrenchStamped, "wrench", 10)
        spin = lambda: ex.spin_once(timeout_sec=0.02)  # noqa: E731
        wait_until(lambda: pub.get_subscription_count() > 0, 10, spin, "allocation node subscribed")

        def post(w, frame="base_link", stamp=None):
            m = WrenchStamped()
            m.header.frame_id = frame
            m.header.stamp = stamp if stamp is not None else probe.get_clock().now().to_msg()
            (m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
             m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z) = w
            pub.publish(m)
            return m.header.stamp

        def send(w, frame="base_link", stamp=None):
            # widths go out per wrench; forces and status at <= 10 Hz, the latest one always: wait for the ones
            # that describe this wrench (same header stamp)
            stamp = post(w, frame, stamp)
            this = lambda q: q and q[-1].header.stamp == stamp  # noqa: E731
            wait_until(lambda: this(got["pwm"]) and this(got["forces"]) and this(got["status"]), 10, spin,
                       "allocation of this wrench")
            return got["pwm"][-1], got["forces"][-1], got["status"][-1]

        send.post = post  # publish without waiting
        yield node, send, got, spin
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_wrench_is_allocated_by_the_shared_core(graph):
    node, send, _, _ = graph
    w = [12.0, -3.0, 6.0, 0.2, -0.1, 0.5]
    pwm, forces, status = send(w)
    expected = AllocationCore(load_config(default_config_path())).allocate(w)
    assert np.allclose(pwm.pulse_width_us, expected.pulse_width_us)
    assert np.allclose(forces.force_n, expected.force_n)
    assert not status.rejected and status.scale == pytest.approx(1.0)
    achieved = [status.achieved_wrench.force.x, status.achieved_wrench.force.y, status.achieved_wrench.force.z]
    assert np.allclose(achieved, w[:3], atol=0.1 * 15.5)  # within the curves' small-force granularity
    assert status.header.frame_id == "base_link" and pwm.armed


def test_saturation_is_reported(graph):
    _, send, _, _ = graph
    pwm, _, status = send([150.0, 0, 0, 0, 0, 0])
    assert status.saturated and 0 < status.scale < 1
    assert any(status.thruster_saturated)
    assert max(pwm.pulse_width_us) <= 1900.0 and min(pwm.pulse_width_us) >= 1100.0


@pytest.mark.parametrize("bad", [[math.nan, 0, 0, 0, 0, 0], [0, 0, math.inf, 0, 0, 0], [0, 0, 0, 0, 0, -math.inf]])
def test_nan_or_inf_wrench_commands_neutral(graph, bad):
    _, send, _, _ = graph
    send([5.0, 0, 0, 0, 0, 0])
    pwm, forces, status = send(bad)
    assert status.rejected and "finite" in status.reason
    assert list(pwm.pulse_width_us) == [1500.0] * 8 and not pwm.armed
    assert list(forces.force_n) == [0.0] * 8


def test_bytes_that_are_no_wrench_are_counted_and_command_neutral(graph):
    """``wrench`` is taken as CDR bytes and decoded by rosbags: bytes that do not decode (a raw publisher's bug) never
    crash the node; they are counted, and neutral goes out with the reason."""
    node, send, got, spin = graph
    send([5.0, 0, 0, 0, 0, 0])
    pub = node.create_publisher(WrenchStamped, "wrench", 10)  # a second, raw publisher on the node's own graph
    wait_until(lambda: pub.get_subscription_count() > 0, 10, spin, "raw publisher matched")
    n = len(got["status"])
    pub.publish(b"\x00\x01\x00\x00\x05\x00")
    wait_until(lambda: len(got["status"]) > n and got["status"][-1].rejected, 10, spin, "neutral for the bad bytes")
    assert "undecodable wrench" in got["status"][-1].reason and node.undecodable == 1
    assert set(got["pwm"][-1].pulse_width_us) == {1500.0} and not got["pwm"][-1].armed
    pwm, _, status = send([5.0, 0, 0, 0, 0, 0])  # and the next good wrench is allocated
    assert not status.rejected and pwm.armed


def test_stale_and_wrong_frame_wrenches_are_rejected(graph):
    node, send, _, _ = graph
    old = node.get_clock().now().nanoseconds - int(2e9)
    _, _, status = send([5.0, 0, 0, 0, 0, 0], stamp=Time(sec=old // 10**9, nanosec=old % 10**9))
    assert status.rejected and "stale wrench" in status.reason
    pwm, _, status = send([5.0, 0, 0, 0, 0, 0], frame="odom")
    assert status.rejected and "frame_id" in status.reason and set(pwm.pulse_width_us) == {1500.0}


def test_wrench_stream_stopping_commands_neutral(graph):
    node, send, got, spin = graph
    send([8.0, 0, 0, 0, 0, 0])
    n = len(got["status"])
    wait_until(lambda: len(got["status"]) > n and got["status"][-1].rejected, 10, spin, "stale timeout")
    assert "no wrench" in got["status"][-1].reason
    assert set(got["pwm"][-1].pulse_width_us) == {1500.0}


def test_the_stale_check_sleeps_while_no_wrench_comes(graph):
    """The stale check's timer runs only from a wrench to its stale report (and a held status): idle, nothing wakes
    the allocation to find nothing (it had woken 10 times a second for ever after the first stale report, and from
    start-up). A wrench restarts it: the stream stopping again commands neutral again, and nothing is sent idle."""
    node, send, got, spin = graph
    assert node.stale_timer.is_canceled()  # before the first wrench
    for _ in range(2):
        send([8.0, 0, 0, 0, 0, 0])
        assert not node.stale_timer.is_canceled()
        n = len(got["status"])
        wait_until(lambda: len(got["status"]) > n and got["status"][-1].rejected, 10, spin, "stale timeout")
        assert "no wrench" in got["status"][-1].reason and set(got["pwm"][-1].pulse_width_us) == {1500.0}
        wait_until(node.stale_timer.is_canceled, 10, spin, "the stale check asleep")
        sent = len(got["pwm"]), len(got["status"]), len(got["forces"])
        span_end = node.get_clock().now().nanoseconds + 3 * node.stale_timer.timer_period_ns
        wait_until(lambda: node.get_clock().now().nanoseconds > span_end, 10, spin, "three stale-check periods")
        assert (len(got["pwm"]), len(got["status"]), len(got["forces"])) == sent
        assert node.stale_timer.is_canceled()


def test_allocator_is_rebuilt_on_parameter_change_only(graph):
    node, send, _, _ = graph
    before = node.core.allocator
    send([1.0, 0, 0, 0, 0, 0])
    assert node.core.allocator is before  # not rebuilt per message
    res = node.set_parameters([Parameter("thrusters.t1.allocation_weight", value=100.0)])
    assert not res[0].successful and "no ESC output state" in res[0].reason  # fail closed until the ESC reports
    node.armed.take(esc_state(armed=False, output_state=1))
    res = node.set_parameters([Parameter("thrusters.t1.allocation_weight", value=100.0)])
    assert res[0].successful and node.core.allocator is not before
    _, forces, _ = send([0.0, 10.0, 0, 0, 0, 0])
    assert abs(forces.force_n[0]) < 0.5 < abs(forces.force_n[1])  # heavily weighted T1 is (almost) unused
    res = node.set_parameters([Parameter("thrusters.t1.allocation_weight", value=-1.0)])
    # refused by the descriptor's range (rclpy's reason names key, range and value)
    assert not res[0].successful and "thrusters.t1.allocation_weight" in res[0].reason and "-1.0" in res[0].reason


def esc_state(armed, output_state):
    """An ``esc/output_state`` as the ESC publishes it."""
    return DiagnosticStatus(values=[KeyValue(key=k, value=v) for k, v in esc_state_values(armed, output_state, "")])


@pytest.mark.parametrize("key,value", [("thrusters.t1.trim_us", 10.0), ("thrusters.wrench_timeout_s", 5.0),
                                       ("thrusters.pulse_width_max_us", 1850.0)])
def test_thruster_keys_are_read_only_while_armed(graph, key, value):
    """Trims, timeouts and limits change what reaches the wire: a change while the ESC reports armed (or unknown
    after armed) is refused with the reason and leaves the allocator as it was."""
    node = graph[0]
    before = (node.core.allocator, node.timeout_s, node.get_parameter(key).value)
    for armed, state in ((True, 2), (False, 0)):
        node.armed.take(esc_state(armed, state))
        res = node.set_parameters([Parameter(key, value=value)])[0]
        assert not res.successful and key in res.reason and "armed" in res.reason, res.reason
        assert (node.core.allocator, node.timeout_s, node.get_parameter(key).value) == before
    node.armed.take(esc_state(False, 1))
    assert node.set_parameters([Parameter(key, value=value)])[0].successful
    assert node.get_parameter(key).value == value


def test_forces_and_status_are_throttled_and_the_latest_is_sent(graph):
    """30 wrenches back to back: 30 width commands, far fewer forces/status (<= 10 Hz), the last of them
    describing the last wrench (held and sent by the timer)."""
    node, send, got, spin = graph
    send([1.0, 0, 0, 0, 0, 0])
    n_pwm, n_forces, n_status = len(got["pwm"]), len(got["forces"]), len(got["status"])
    stamps = []
    for i in range(30):  # one at a time (the node's wrench queue keeps 10), as fast as the node takes them
        stamps.append(send.post([2.0 + 0.1 * i, 0, 0, 0, 0, 0]))
        wait_until(lambda: len(got["pwm"]) > n_pwm + i, 10, spin, "widths of this wrench")
    wait_until(lambda: len(got["pwm"]) >= n_pwm + 30 and got["status"] and got["forces"]
               and got["status"][-1].header.stamp == got["forces"][-1].header.stamp == stamps[-1], 10, spin,
               "forces and status of the last wrench")
    assert len(got["pwm"]) - n_pwm == 30
    assert len(got["status"]) - n_status <= 15 and len(got["forces"]) - n_forces <= 15
    assert got["pwm"][-1].header.stamp == stamps[-1]
    assert got["status"][-1].requested_wrench.force.x == pytest.approx(2.0 + 0.1 * 29)


#: surge the thrusters can produce: T1-T4 at 55 deg from the x axis (the shipped layout), each at most 15.53 N (the
#: shipped curve at 1100 us and, mirrored, at 1900 us): 4 cos(55 deg) 15.53 N = 35.63 N; the shipped
#: thrusters.max_wrench_excess_ratio is 10, so 356 N is the most accepted
SURGE_CAPACITY_N = 4 * math.cos(math.radians(55.0)) * 15.53


@pytest.mark.parametrize("wrench, rejected", [
    ([300.0, 0, 0, 0, 0, 0], False),  # 8.4 times: saturated, scaled
    ([400.0, 0, 0, 0, 0, 0], True),  # 11.2 times
    ([1e30, 0, 0, 0, 0, 0], True),
    ([0, 0, 0, 0, 0, 1e308], True),
])
def test_a_wrench_far_beyond_the_thrusters_is_rejected_not_scaled_into_full_thrust(graph, wrench, rejected):
    """Issue 44 finding 3: 1e30 N and 1e308 N m were accepted and saturated to full thrust ("saturated: scaled"). A
    wrench beyond thrusters.max_wrench_excess_ratio times what the thrusters can produce is a fault: neutral, not
    armed, and the reason."""
    assert 8.0 < 300.0 / SURGE_CAPACITY_N < 10.0 < 400.0 / SURGE_CAPACITY_N
    _, send, _, _ = graph
    pwm, forces, status = send(wrench)
    if rejected:
        assert status.rejected and "beyond what the thrusters can produce" in status.reason
        assert "thrusters.max_wrench_excess_ratio 10" in status.reason
        assert list(pwm.pulse_width_us) == [1500.0] * 8 and not pwm.armed and list(forces.force_n) == [0.0] * 8
    else:
        assert not status.rejected and status.saturated and status.reason == "saturated: scaled" and pwm.armed


def test_thruster_test_forces_go_through_the_allocation(graph):
    """``hindrax thruster-test`` steps one thruster at a time through ``thrusters/test_forces``: the allocation, the
    one commander the ESC accepts, puts each force through its thruster's curve; a force beyond the thruster's
    limits (the shipped curve gives at most 15.53 N) is rejected: neutral, not armed."""
    from hindrax_msgs.msg import ThrusterForces

    node, _send, got, spin = graph
    pub = node.create_publisher(ThrusterForces, "thrusters/test_forces", 10)
    wait_until(lambda: pub.get_subscription_count() > 0, 10, spin, "allocation subscribed to test forces")
    n = len(got["pwm"])
    pub.publish(ThrusterForces(force_n=[0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    wait_until(lambda: len(got["pwm"]) > n, 10, spin, "the test command")
    pwm = got["pwm"][-1]
    widths = list(pwm.pulse_width_us)
    assert pwm.armed and widths[:2] == [1500.0, 1500.0] and widths[3:] == [1500.0] * 5
    assert 1525.0 <= widths[2] <= 1600.0  # 3 N forward: outside the deadband, well below full thrust
    curve = node.core.allocator.curves[2]
    assert float(curve.thrust_n(widths[2])) == pytest.approx(3.0, abs=0.05)
    n = len(got["pwm"])
    pub.publish(ThrusterForces(force_n=[0.0, 0.0, 40.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    wait_until(lambda: len(got["pwm"]) > n, 10, spin, "the rejection")
    assert not got["pwm"][-1].armed and set(got["pwm"][-1].pulse_width_us) == {1500.0}
