"""The ESC's latched output state, ``esc/output_state``: whether the ESC is armed and what is on the
wire, for the nodes that need only that (the supervisor, the MS5837 driver's
``pressure/zero_depth``, the controller) and not the 50 Hz widths of ``thrusters/pulse_width``.

Message: diagnostic_msgs/DiagnosticStatus with the state of the ESC's ``esc/heartbeat`` (docs/architecture.md §8): level
OK, or ERROR while the output state is unknown; ``message`` the state's name (``neutral``, ``commanding``, ``unknown``);
KeyValues ``output_state`` (the hindrax_msgs/ThrusterPwm ``OUTPUT_*`` constant, decimal text), ``armed``
(``true`` / ``false``, false while unknown) and ``reason``. QoS (:func:`esc_state_qos`): reliable, transient local, keep
last 1, so a late subscriber gets the current state at once.

Publishing (:class:`EscStateLatch`, pure): on every change of (armed, output_state), and every
:data:`REPUBLISH_PERIOD_S` of steady time.

Reading (:func:`read_esc_state`, :func:`armed_after`): a message without a valid ``output_state`` (0-2) or ``armed`` is
malformed (None: counted, treated as OUTPUT_UNKNOWN, disarmed). An output state that became unknown while armed counts
as still armed. When the ESC is gone the last state stays: each reader says in its docstring what that means for it.

Arm lock (:class:`ArmedWatch`): refuses a change while the thrusters may run (``pressure/zero_depth`` and every vehicle
key a node applies while running, :func:`hindrax_common.config.node_parameters.declare_vehicle_parameters`): while the
last state says armed (or unknown after armed) and before any state has arrived (fail closed)."""
from __future__ import annotations

import math
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["ESC_STATE_TOPIC", "REPUBLISH_PERIOD_S", "ArmedWatch", "EscStateLatch", "armed_after", "esc_state_qos",
           "esc_state_values", "read_esc_state"]

#: the topic (relative: the vehicle's namespace)
ESC_STATE_TOPIC = "esc/output_state"
#: the state is published again after this long without a change, s (steady clock)
REPUBLISH_PERIOD_S = 1.0
#: hindrax_msgs/ThrusterPwm output states (the same values as :mod:`.pca9685.core`; checked equal in the tests)
OUTPUT_UNKNOWN, OUTPUT_NEUTRAL, OUTPUT_COMMANDING = 0, 1, 2


def esc_state_qos() -> QoSProfile:
    """Reliable, transient local, keep last 1, for the writer and the readers (module docstring)."""
    return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


class EscStateLatch:
    """When the ESC publishes ``esc/output_state``: :meth:`due` is asked at every output (several per period) and
    answers True on the first call, on a change of (armed, output_state) and when ``period_s`` (s) passed since the
    last publication. Times in s of a steady clock (``time.monotonic`` on the vehicle)."""

    def __init__(self, period_s: float = REPUBLISH_PERIOD_S) -> None:
        self.period_s = float(period_s)
        self.last: tuple[bool, int] | None = None
        self.last_s = -math.inf
        self.published = 0

    def due(self, t_s: float, armed: bool, output_state: int) -> bool:
        """True when the state (``armed``, ``output_state``) is to be published now (counted as published)."""
        state = (bool(armed), int(output_state))
        if state == self.last and t_s - self.last_s < self.period_s:
            return False
        self.last, self.last_s = state, float(t_s)
        self.published += 1
        return True


def esc_state_values(armed: bool, output_state: int, reason: str) -> list[tuple[str, str]]:
    """The KeyValues of one ``esc/output_state``."""
    return [("output_state", str(int(output_state))), ("armed", "true" if armed else "false"), ("reason", reason)]


def read_esc_state(msg: Any) -> tuple[int, bool] | None:
    """(output_state, armed) of an ``esc/output_state`` DiagnosticStatus (rclpy's or rosbags' lean one), or None
    when it is malformed (module docstring)."""
    values = {kv.key: kv.value for kv in msg.values}
    armed = values.get("armed")
    try:
        state = int(values.get("output_state", ""))
    except ValueError:
        return None
    if state not in (OUTPUT_UNKNOWN, OUTPUT_NEUTRAL, OUTPUT_COMMANDING) or armed not in ("true", "false"):
        return None
    return state, armed == "true"


def armed_after(previous: bool, output_state: int, armed: bool) -> bool:
    """Whether thrust may be on the wire after a report of (``output_state``, ``armed``) when it may have been before
    (``previous``): armed, or unknown after armed (an output state that became unknown may still be thrusting)."""
    return bool(armed) or (int(output_state) == OUTPUT_UNKNOWN and bool(previous))


class ArmedWatch:
    """Whether the ESC may be thrusting, from its ``esc/output_state`` (module docstring, "Arm lock").

    :meth:`take` is the subscription's callback (:meth:`subscribe` makes it); :meth:`refusal` is '' when a change is
    allowed (a state arrived and says disarmed), else the reason. A malformed state is read as unknown (a disarmed
    ESC stays disarmed, an armed one stays armed) and reported to ``on_malformed()`` (the node counts it)."""

    def __init__(self, on_malformed: Callable[[], None] | None = None) -> None:
        self.armed = False  # the last state taken says armed, or unknown after armed
        self.seen = False  # a state arrived
        self.on_malformed = on_malformed

    def take(self, msg: Any) -> None:
        """One ``esc/output_state`` (DiagnosticStatus)."""
        state = read_esc_state(msg)
        if state is None:
            if self.on_malformed is not None:
                self.on_malformed()
            state = (OUTPUT_UNKNOWN, False)
        self.armed = armed_after(self.armed, *state)
        self.seen = True

    def refusal(self) -> str:
        """'' when the ESC reported disarmed; else why a change is refused (one line, no trailing period)."""
        if not self.seen:
            return "refused: no ESC output state yet (esc/output_state), the thrusters may be running"
        return "refused while the ESC is armed (esc/output_state)" if self.armed else ""

    def subscribe(self, node: Any, **kwargs: Any) -> Any:
        """Subscribe ``node`` to ``esc/output_state`` with :meth:`take` (latched QoS); kwargs go to
        ``create_subscription``. Returns the subscription."""
        return node.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, self.take, esc_state_qos(), **kwargs)
