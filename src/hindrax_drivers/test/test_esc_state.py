"""The ESC's latched output state (esc_state.py): when the ESC publishes it, how a reader takes it, its QoS.

Expected values come from the module's rules (publish on a change of (armed, output_state) and 1 s after the last
publication; unknown after armed counts as armed), not from the code under test."""
from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

from hindrax_common.node_support.esc_state import (OUTPUT_COMMANDING, OUTPUT_NEUTRAL, OUTPUT_UNKNOWN, EscStateLatch,
                                                    armed_after, esc_state_qos, esc_state_values, read_esc_state)
from hindrax_drivers.pca9685 import core
from hindrax_msgs.msg import ThrusterPwm


def test_the_output_states_are_thrusterpwm_s_and_the_core_s():
    assert (OUTPUT_UNKNOWN, OUTPUT_NEUTRAL, OUTPUT_COMMANDING) == (
        ThrusterPwm.OUTPUT_UNKNOWN, ThrusterPwm.OUTPUT_NEUTRAL, ThrusterPwm.OUTPUT_COMMANDING) == (
        core.OUTPUT_UNKNOWN, core.OUTPUT_NEUTRAL, core.OUTPUT_COMMANDING)


def test_published_first_on_every_change_and_once_a_second_without_one():
    latch = EscStateLatch()
    assert latch.due(10.0, False, OUTPUT_NEUTRAL)  # the first call: a late joiner's state exists at once
    # 50 Hz outputs without a change: nothing until 1 s after the last publication
    assert [latch.due(10.0 + k * 0.02, False, OUTPUT_NEUTRAL) for k in range(1, 50)] == [False] * 49
    assert latch.due(11.0, False, OUTPUT_NEUTRAL)
    assert not latch.due(11.02, False, OUTPUT_NEUTRAL)
    assert latch.due(11.04, True, OUTPUT_NEUTRAL)  # armed: at once
    assert latch.due(11.06, True, OUTPUT_COMMANDING)  # the output state alone changed: at once
    assert not latch.due(11.08, True, OUTPUT_COMMANDING)
    assert latch.due(11.10, False, OUTPUT_UNKNOWN)
    assert latch.due(11.12, False, OUTPUT_NEUTRAL)
    # a change restarts the period: the repeat comes 1 s after it
    assert not latch.due(12.10, False, OUTPUT_NEUTRAL)
    assert latch.due(12.12, False, OUTPUT_NEUTRAL)
    assert latch.published == 7


def test_the_period_is_the_latch_s():
    latch = EscStateLatch(period_s=0.5)
    assert latch.due(0.0, True, OUTPUT_COMMANDING)
    assert not latch.due(0.49, True, OUTPUT_COMMANDING)
    assert latch.due(0.5, True, OUTPUT_COMMANDING)


def _status(values):
    return DiagnosticStatus(values=[KeyValue(key=k, value=v) for k, v in values])


def test_a_reader_takes_what_the_esc_writes_and_refuses_what_it_never_writes():
    assert read_esc_state(_status(esc_state_values(True, OUTPUT_COMMANDING, "armed"))) == (OUTPUT_COMMANDING, True)
    assert read_esc_state(_status(esc_state_values(False, OUTPUT_UNKNOWN, "no I2C bus"))) == (OUTPUT_UNKNOWN, False)
    for bad in ([], [("output_state", "1")], [("armed", "true")], [("output_state", "3"), ("armed", "false")],
                [("output_state", "neutral"), ("armed", "false")], [("output_state", "1"), ("armed", "yes")]):
        assert read_esc_state(_status(bad)) is None, bad


def test_unknown_after_armed_counts_as_armed_until_a_known_state_says_otherwise():
    assert armed_after(False, OUTPUT_NEUTRAL, True)
    assert armed_after(True, OUTPUT_UNKNOWN, False)  # may still be thrusting
    assert not armed_after(False, OUTPUT_UNKNOWN, False)  # unknown, never armed: not armed
    assert not armed_after(True, OUTPUT_NEUTRAL, False)  # neutral confirmed, disarmed
    assert armed_after(True, OUTPUT_COMMANDING, True)


def test_latched_qos():
    q = esc_state_qos()
    assert (q.depth, q.durability, q.reliability) == (1, DurabilityPolicy.TRANSIENT_LOCAL, ReliabilityPolicy.RELIABLE)
