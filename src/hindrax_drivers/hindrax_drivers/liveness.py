"""Heartbeat ages and ROS-time step detection on the steady clock (docs/architecture.md §8, "Time").

Two small pieces every safety node (ESC, output guard, supervisor) shares:

* :class:`AliveAge`: how long ago a peer was last heard, counted on ``time.monotonic`` but only over time this
  process's executor was running (each gap between two :meth:`AliveAge.tick` calls counts at most ``max_step_s``).
  A peer that dies or hangs in another process ages at wall-clock speed; this process's own stall (a busy
  single-process graph, a SIGSTOP of this process) does not make every peer look dead when it resumes.
* :class:`ClockStepMonitor`: compares ROS time with the steady clock at each tick and reports a backward step of
  ROS time (``/clock`` restarted or a bag looped) and a stall (ROS time frozen while the steady clock runs), so a
  node can re-base its ROS-time checks and say so on ``/diagnostics``.
"""
from __future__ import annotations

import math
import time
from typing import Callable

__all__ = ["AliveAge", "ClockStepMonitor", "HEARTBEAT_NAMES", "heartbeat_ok"]

#: heartbeat topics (diagnostic_msgs/DiagnosticStatus: level OK = healthy, ERROR = tripped/asserted + reason)
HEARTBEAT_NAMES = {"supervisor": "supervisor/heartbeat", "guard": "guard/heartbeat", "esc": "esc/heartbeat"}


def heartbeat_ok(msg) -> bool:
    """Whether a heartbeat (diagnostic_msgs/DiagnosticStatus) says OK (level 0). ``level`` is a ``byte`` field:
    rclpy gives one-byte ``bytes`` (``DiagnosticStatus.OK`` is the byte 0), rosbags' lean decoding
    (:mod:`hindrax_drivers.lean_cdr`) an int; both are read here, so a beat taken either way means the same. Any
    other type is not OK."""
    level = msg.level
    if isinstance(level, (bytes, bytearray)):
        return len(level) == 1 and level[0] == 0
    return isinstance(level, int) and not isinstance(level, bool) and level == 0


class AliveAge:
    """Age of the last message from a peer, s, in executor-alive steady time (module docstring).

    ``max_step_s``: the most one tick-to-tick gap may add (two tick periods is the usual choice).
    ``age_s`` is ``math.inf`` until the peer is first heard.
    """

    def __init__(self, max_step_s: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.max_step_s = float(max_step_s)
        self._clock = clock
        self._last_tick = clock()
        self.age_s = math.inf

    def heard(self, ago_s: float = 0.0) -> None:
        """The peer spoke ``ago_s`` seconds ago (0: now; a message taken from a polled subscription passes the wall
        time since its DDS reception, so that its age is what a callback at its arrival would have counted)."""
        self.age_s = max(0.0, float(ago_s))

    def tick(self) -> float:
        """Advance by the (capped) time since the previous tick; returns the age, s."""
        t = self._clock()
        gap, self._last_tick = t - self._last_tick, t
        if math.isfinite(self.age_s):
            self.age_s += min(max(gap, 0.0), self.max_step_s)
        return self.age_s

    def fresh(self, timeout_s: float) -> bool:
        """Heard within ``timeout_s``."""
        return self.age_s <= timeout_s


class ClockStepMonitor:
    """Detects a backward step of ROS time against the steady clock (and a stalled ROS clock).

    ``ros_now_s``: the node's ROS time in seconds; ``tolerance_s``: a backward move smaller than this is jitter.
    :meth:`check` returns the step in seconds (negative) when ROS time went back, else 0.0; :attr:`steps_back`
    counts them, :attr:`last_step_s` keeps the last. :meth:`stalled_for_s` is how long ROS time has not moved
    while the steady clock ran.
    """

    def __init__(self, ros_now_s: Callable[[], float], tolerance_s: float = 0.05,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._ros = ros_now_s
        self._clock = clock
        self.tolerance_s = float(tolerance_s)
        self._last_ros = ros_now_s()
        self._moved_at = clock()
        self.steps_back = 0
        self.last_step_s = 0.0

    def check(self) -> float:
        """Call at every steady tick. Returns the backward step (s, < 0) or 0.0."""
        ros = self._ros()
        delta = ros - self._last_ros
        self._last_ros = ros
        if delta != 0.0:
            self._moved_at = self._clock()
        if delta < -self.tolerance_s:
            self.steps_back += 1
            self.last_step_s = delta
            return delta
        return 0.0

    def stalled_for_s(self) -> float:
        """Steady time since ROS time last moved, s."""
        return self._clock() - self._moved_at
