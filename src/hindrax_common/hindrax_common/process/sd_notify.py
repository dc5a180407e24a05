"""systemd's service notification protocol (sd_notify(3)) for the safety processes: READY=1 and the WATCHDOG=1 pings.

The bare-metal unit (``docker/hindrax-bare-metal.service``) runs the launch as ``Type=notify`` with
``NotifyAccess=all`` and ``WatchdogSec``: systemd puts ``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` in the environment
that the launch hands to its nodes. One process speaks for the three safety processes: the output guard, which
already watches the ESC's and the supervisor's heartbeats (identity-checked). At each of its ticks
(:class:`SafetyNotifier`) it sends WATCHDOG=1 only while both beats are fresh (:func:`stale_heartbeats`: younger than
its heartbeat timeout), READY=1 the first time they are. A frozen or dead ESC, supervisor or guard therefore stops the
pings whichever process still runs: after ``WatchdogSec`` systemd aborts the unit (``WatchdogSignal``, SIGABRT, then
SIGCONT to stopped processes) and ``Restart=on-failure`` starts it again; the guard's GPIO requests are freed, /OE
returns to its pull-up, and the new processes start with the outputs off (docs/watchdog.md). The ESC and the
supervisor send nothing: a live process's ping would keep a unit whose safety process is frozen.

Why our own 30 lines: the protocol is one datagram on a Unix socket (``socket`` from the standard library);
``systemd-python`` needs libsystemd's headers and a compiler on the vehicle's image, and the ``sdnotify`` package
is the same datagram, unmaintained since 2017."""
from __future__ import annotations

import os
import socket
from typing import Mapping

__all__ = ["SafetyNotifier", "notify", "stale_heartbeats", "watchdog_period_s"]


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


def stale_heartbeats(ages_s: Mapping[str, float], timeout_s: float) -> list[str]:
    """The safety heartbeats that are not fresh: ``ages_s`` maps a sender (``"esc"``, ``"supervisor"``) to its
    beat's age in s (inf or NaN: never heard); fresh = age <= ``timeout_s``. Empty: the unit may be pinged."""
    return [name for name, age in ages_s.items() if not (age <= timeout_s)]


class SafetyNotifier:
    """READY=1 and WATCHDOG=1 from the process that watches the safety heartbeats (module docstring): call
    :meth:`update` at every tick of that process. Does nothing without ``$NOTIFY_SOCKET``. :attr:`sent` counts the
    datagrams sent, :attr:`withheld` the ticks without a ping (a stale heartbeat), :attr:`reason` the last one's."""

    def __init__(self, environ: Mapping[str, str] = os.environ) -> None:
        self.environ = environ
        self.enabled = bool(environ.get("NOTIFY_SOCKET"))
        self.watchdog = watchdog_period_s(environ) is not None
        self.sent = 0
        self.withheld = 0
        self.ready = False
        self.reason = ""

    def update(self, ages_s: Mapping[str, float], timeout_s: float) -> bool:
        """Ping systemd when every heartbeat in ``ages_s`` is fresh (:func:`stale_heartbeats`); READY=1 the first
        time. Returns True when a ping went out."""
        stale = stale_heartbeats(ages_s, timeout_s)
        self.reason = f"stale heartbeat(s): {', '.join(stale)}" if stale else ""
        if not self.enabled:
            return False
        if stale:
            self.withheld += 1
            return False
        if not self.ready:
            self.ready = notify("READY=1", self.environ)
            self.sent += self.ready
        pinged = self.watchdog and notify("WATCHDOG=1", self.environ)
        self.sent += pinged
        return bool(pinged)
