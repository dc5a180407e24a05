"""systemd's service notification protocol (sd_notify(3)) for the safety processes: READY=1 and the WATCHDOG=1 pings.

The bare-metal unit (``docker/hindrax-bare-metal.service``) runs the launch as ``Type=notify`` with
``NotifyAccess=all`` and ``WatchdogSec``: systemd puts ``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` in the environment
that the launch hands to its nodes, and the ESC, the supervisor and the output guard (``run_node(...,
systemd_notify=True)``) each send READY=1 once their executor runs and WATCHDOG=1 every half ``WATCHDOG_USEC``
from a steady-clock timer of that executor. A launch frozen as a whole (Ctrl-Z, ``docker pause``, a cgroup freeze:
every safety process stopped) sends nothing; after ``WatchdogSec`` systemd kills the unit (``WatchdogSignal``) and
``Restart=on-failure`` starts it again: the killed processes' GPIO requests are freed, /OE returns to its pull-up,
and the new processes start with the outputs off (docs/watchdog.md). A single frozen process is the heartbeats'
case (docs/architecture.md §8), not this one: any live process's ping keeps the unit.

Why our own 30 lines: the protocol is one datagram on a Unix socket (``socket`` from the standard library);
``systemd-python`` needs libsystemd's headers and a compiler on the vehicle's image, and the ``sdnotify`` package
is the same datagram, unmaintained since 2017.
"""
from __future__ import annotations

import os
import socket
from typing import Any, Mapping

from rclpy.clock import Clock, ClockType

__all__ = ["SystemdNotifier", "notify", "watchdog_period_s"]


def notify(state: str, environ: Mapping[str, str] = os.environ) -> bool:
    """Send ``state`` (e.g. ``"READY=1"``, ``"WATCHDOG=1"``) to ``$NOTIFY_SOCKET`` (a path, or ``@name`` in the
    abstract namespace). Returns False when the variable is unset (not started by systemd) or the send fails."""
    address = environ.get("NOTIFY_SOCKET", "")
    if not address:
        return False
    if address[0] == "@":
        address = "\0" + address[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
            sock.connect(address)
            sock.sendall(state.encode("utf-8"))
    except OSError:
        return False
    return True


def watchdog_period_s(environ: Mapping[str, str] = os.environ) -> float | None:
    """The unit's ``WatchdogSec`` from ``$WATCHDOG_USEC`` (s), or None when absent or not a positive integer."""
    try:
        usec = int(environ.get("WATCHDOG_USEC", ""))
    except ValueError:
        return None
    return usec * 1e-6 if usec > 0 else None


class SystemdNotifier:
    """READY=1 at the first tick of ``node``'s executor, then WATCHDOG=1 every half the unit's watchdog period
    (module docstring), from a steady-clock timer on ``node``. Does nothing without ``$NOTIFY_SOCKET``.
    :attr:`sent` counts the datagrams sent."""

    def __init__(self, node: Any, environ: Mapping[str, str] = os.environ) -> None:
        self.environ = environ
        self.sent = 0
        self.ready = False
        self.timer = None
        if not environ.get("NOTIFY_SOCKET"):
            return
        period = watchdog_period_s(environ)
        self.timer = node.create_timer(period / 2.0 if period else 1.0, self.tick,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def tick(self) -> None:
        """Send READY=1 (first time) and WATCHDOG=1 (when the unit has a watchdog)."""
        if not self.ready:
            self.ready = notify("READY=1", self.environ)
            self.sent += self.ready
        if watchdog_period_s(self.environ) is not None and notify("WATCHDOG=1", self.environ):
            self.sent += 1
