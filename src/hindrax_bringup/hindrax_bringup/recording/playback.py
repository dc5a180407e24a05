"""Playback timing: when each recorded message is due, and the /clock values (pure core of the player).

A bag message logged at ``t`` (ns, log time) is published at wall time

    wall(t) = wall_0 + (t - origin) / rate            (s; origin = bag start + start offset)

so the original spacing is kept, scaled by ``rate`` (2.0 = twice as fast). When ``/clock`` is published
it carries the bag time that corresponds to the wall time ``w``:

    bag_time(w) = origin + (w - wall_0) * rate        (ns)

at a fixed wall-clock period (rosbag2's ``--clock`` behaviour), plus the message's own log time just
before each message so that a ``use_sim_time`` consumer never sees a message stamped ahead of its clock.
With ``loop`` the bag restarts at its origin (the clock jumps back, as with rosbag2).

:func:`play` runs the schedule with injected ``monotonic``/``wait``/``publish`` callables, so tests drive
it with a simulated clock; the player node passes ``time.monotonic`` and ``threading.Event.wait``."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable


@dataclass
class PlayStats:
    """What a run of :func:`play` did: messages published per pass, passes, stopped early."""

    published: int = 0
    passes: int = 0
    stopped: bool = False


def due_wall_time_s(log_time_ns: int, origin_ns: int, wall_origin_s: float, rate: float) -> float:
    """Wall time (s, same clock as ``wall_origin_s``) at which a message logged at ``log_time_ns`` is due."""
    return wall_origin_s + (log_time_ns - origin_ns) / 1e9 / rate


def bag_time_ns(wall_s: float, origin_ns: int, wall_origin_s: float, rate: float) -> int:
    """Bag time (ns) corresponding to wall time ``wall_s`` during a pass started at ``wall_origin_s``."""
    return origin_ns + int(round((wall_s - wall_origin_s) * rate * 1e9))


def play(messages: Callable[[], Iterable[Any]], publish: Callable[[Any], None], origin_ns: int, *,
         rate: float = 1.0, loop: bool = False, publish_clock: Callable[[int], None] | None = None,
         clock_period_s: float = 0.01, monotonic: Callable[[], float] = time.monotonic,
         wait: Callable[[float], Any] | None = None, stop: threading.Event | None = None,
         max_passes: int | None = None) -> PlayStats:
    """Publish messages at their recorded times (see module docstring).

    messages: called once per pass, returns the messages (objects with ``log_time_ns``) in log-time
        order, already filtered (topics, start offset). publish: called with each message when due.
    origin_ns: bag time that maps to the start of each pass (bag start + start offset).
    rate: playback rate factor (> 0). loop: repeat until ``stop`` is set (or ``max_passes``).
    publish_clock: called with bag time (ns) every ``clock_period_s`` of wall time and before each
        message; None = no clock. monotonic/wait: wall clock (s) and a wait(seconds) function.
    Returns :class:`PlayStats`. Raises ValueError for rate <= 0 or clock_period_s <= 0."""
    if not rate > 0:
        raise ValueError(f"rate {rate}: must be > 0")
    if publish_clock is not None and not clock_period_s > 0:
        raise ValueError(f"clock_period_s {clock_period_s}: must be > 0")
    stop = stop or threading.Event()
    wait = wait or stop.wait
    stats = PlayStats()
    while not stop.is_set():
        wall0 = monotonic()
        next_tick = wall0
        last_clock = None
        stats.passes += 1
        for m in messages():
            due = due_wall_time_s(m.log_time_ns, origin_ns, wall0, rate)
            while True:
                if stop.is_set():
                    stats.stopped = True
                    return stats
                now = monotonic()
                if publish_clock is not None and next_tick <= now and next_tick <= due:
                    t = bag_time_ns(next_tick, origin_ns, wall0, rate)
                    if last_clock is None or t > last_clock:
                        publish_clock(t)
                        last_clock = t
                    # next grid point after now (ticks missed while busy are skipped, not bunched)
                    next_tick += clock_period_s * max(1, int((now - next_tick) // clock_period_s) + 1)
                    continue
                if now >= due:
                    break
                target = min(due, next_tick) if publish_clock is not None else due
                wait(max(0.0, target - now))
            if publish_clock is not None and (last_clock is None or m.log_time_ns > last_clock):
                publish_clock(m.log_time_ns)
                last_clock = m.log_time_ns
            publish(m)
            stats.published += 1
        if not loop or (max_passes is not None and stats.passes >= max_passes):
            break
    stats.stopped = stop.is_set()
    return stats
