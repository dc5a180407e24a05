"""What the ESC node hears from its peers: the supervisor's and the output guard's heartbeats, turned into the two
verdicts :meth:`.core.EscCore.set_peers` takes ('' = trusted, else why not), and who publishes its commands
(:func:`.core.command_source_fault`).

:class:`EscPeers` subscribes to ``supervisor/heartbeat`` and ``guard/heartbeat`` through
:class:`~.liveness.HeartbeatWatch` (a forged or replayed beat, a second publisher or another node name
is a fault; only accepted beats reach the handlers) and ages each on the steady clock in executor-alive time
(:class:`~.liveness.AliveAge`; on simulated time also on the graph's clock). The verdict rules are
:func:`.core.heartbeat_verdict`'s. Node parameter (read-only, config.sections.esc): ``heartbeat_timeout_s``
(default ``esc.heartbeat_timeout_s``)."""
from __future__ import annotations

import time
from typing import Any, Callable

from hindrax_common.config.sections.esc import ESC_HEARTBEAT_TIMEOUT
from hindrax_common.cdr.lean_cdr import Beat
from hindrax_common.node_support.liveness import (HEARTBEAT_NAMES, AliveAge, HeartbeatWatch, PublisherNames,
    heartbeat_ok, simulated_now_s)
from hindrax_common.config.node_parameters import declare_node_parameter
from .core import UNNAMED_NODE, command_source_fault, command_source_unnamed, heartbeat_verdict

__all__ = ["EscPeers", "COMMAND_TOPIC"]

COMMAND_TOPIC = "thrusters/command_pulse_width"


class EscPeers:
    """The ESC's view of the supervisor and the output guard (module docstring).

    ``node``: the ESC node (subscriptions, its parameter, the graph); ``period_s``: its tick period, s (an age counts
    at most two periods per gap between ticks); ``default_timeout_s``: ``esc.heartbeat_timeout_s``; ``armed()``: whether
    the ESC is armed (identity rules while armed); ``on_bad_news()``: called when a beat says the peer forbids thrust
    (a supervisor trip while armed, any guard beat that is not OK)."""

    def __init__(self, node: Any, period_s: float, default_timeout_s: float, armed: Callable[[], bool],
                 on_bad_news: Callable[[], Any]) -> None:
        self._node = node
        #: heartbeat timeout, s: parameter ``heartbeat_timeout_s`` (:data:`~hindrax_common.config.sections.esc.
        #: ESC_HEARTBEAT_TIMEOUT`)
        self.timeout_s = float(declare_node_parameter(node, "heartbeat_timeout_s", ESC_HEARTBEAT_TIMEOUT,
                                                      default_timeout_s))
        #: live publishers of the commands (the command subscription's liveliness event, :meth:`on_liveliness`)
        self.command_publishers_alive = 0
        #: who publishes the commands, asked of the graph when the command subscription's events say it changed
        #: (its ``event_callbacks``: the node passes them to that subscription)
        self.command_publishers = PublisherNames(node, COMMAND_TOPIC)
        #: steady time since when a command publisher has been unnamed (discovery not finished), s; None: none is
        self.unnamed_since: float | None = None
        #: on simulated time, also on the graph's clock (liveness.AliveAge: late only when late in the simulation)
        self.supervisor_age = AliveAge(2.0 * period_s, graph_now_s=lambda: simulated_now_s(node))
        self.guard_age = AliveAge(2.0 * period_s, graph_now_s=lambda: simulated_now_s(node))
        self.supervisor_ok, self.supervisor_message = False, ""
        self.guard_ok, self.guard_message = False, ""
        #: the newest accepted guard beat, handled: (its boot_id, its seq); (0, 0) before the first
        self.guard_ack: tuple[int, int] = (0, 0)
        self._armed, self._on_bad_news = armed, on_bad_news
        self.watches = {"supervisor": HeartbeatWatch(node, "supervisor", self.on_supervisor_heartbeat, armed),
                        "guard": HeartbeatWatch(node, "guard", self.on_guard_heartbeat, armed)}

    def tick(self) -> None:
        """Advance both ages to now (the safety tick and an arm request; the beats arrive by callbacks, a stale one's
        waiting beats are taken first: :meth:`~hindrax_common.node_support.liveness.HeartbeatWatch.fresh`)."""
        for kind, age in (("supervisor", self.supervisor_age), ("guard", self.guard_age)):
            age.tick()
            self.watches[kind].fresh(age, self.timeout_s)

    def check_graph(self) -> tuple[str, str]:
        """The heartbeats' identity checks against the graph, then the command topic's: (fault, unnamed), each ''
        or why the commands cannot be trusted (only the allocation may publish them, :func:`.core.
        command_source_fault`) or are held while a publisher is not named yet (:func:`.core.
        command_source_unnamed`; a fault once unnamed for longer than :data:`.core.NAME_RESOLVE_BOUND_S`)."""
        for watch in self.watches.values():
            watch.check()
        names = self.command_publishers.names()
        now = time.monotonic()
        if UNNAMED_NODE not in names:
            self.unnamed_since = None
        elif self.unnamed_since is None:
            self.unnamed_since = now
        unnamed_for_s = 0.0 if self.unnamed_since is None else now - self.unnamed_since
        fault = command_source_fault(names, COMMAND_TOPIC, self.command_publishers_alive, unnamed_for_s)
        return fault, command_source_unnamed(names, COMMAND_TOPIC)

    def on_liveliness(self, info: Any) -> None:
        """The command subscription's liveliness event (1 s lease)."""
        self.command_publishers_alive = int(info.alive_count)

    def on_supervisor_heartbeat(self, msg: Beat) -> None:
        """``supervisor/heartbeat``: level OK = within the envelope; otherwise the breach is latched. A trip
        disarms when it is handled (at once as a callback; at the next safety tick on the system clock, where
        the supervisor's own ``esc/set_armed`` request has disarmed already)."""
        self.supervisor_age.heard()
        self.supervisor_ok, self.supervisor_message = heartbeat_ok(msg), msg.message
        if not self.supervisor_ok and self._armed():
            self._on_bad_news()

    def on_guard_heartbeat(self, msg: Beat) -> None:
        """``guard/heartbeat``: level OK = the guard lets the outputs through (/OE low). Once handled (a beat that is
        not OK has disarmed), the beat is what :attr:`guard_ack` acknowledges: the guard releases its outputs only
        on an ESC beat at neutral that acknowledges one of its ERROR beats (:mod:`hindrax_bringup.guard.core`)."""
        self.guard_age.heard()
        self.guard_ok, self.guard_message = heartbeat_ok(msg), msg.message
        if not self.guard_ok:
            self._on_bad_news()  # restarts the time at neutral even if a later beat of the same take says OK
        self.guard_ack = (msg.boot_id, msg.seq)

    def verdicts(self) -> tuple[str, str]:
        """The supervisor's and the guard's verdicts ('' = trusted, else why not)."""
        t = self.timeout_s
        sup = heartbeat_verdict("supervisor", HEARTBEAT_NAMES["supervisor"], self.supervisor_age.age_s, t,
                                self.supervisor_ok, self.supervisor_message)
        if sup and self.supervisor_age.fresh(t):
            sup = f"supervisor tripped: {self.supervisor_message} (clear it with hindrax reset)"
        guard = heartbeat_verdict("output guard", HEARTBEAT_NAMES["guard"], self.guard_age.age_s, t,
                                  self.guard_ok, self.guard_message)
        if guard and self.guard_age.fresh(t):
            guard = f"output guard holds the outputs off: {self.guard_message}"
        # a silent peer first (its identity fault is then "no live publisher"); then the identity checks, before
        # the level: a forged or replayed OK must not count as the peer's
        sup_id, guard_id = (self.watches[k].identity.fault for k in ("supervisor", "guard"))
        return (sup if not self.supervisor_age.fresh(t) else
                f"supervisor heartbeat not trusted: {sup_id}" if sup_id else sup,
                guard if not self.guard_age.fresh(t) else
                f"output-guard heartbeat not trusted: {guard_id}" if guard_id else guard)

    def diagnostics(self) -> list[tuple[str, Any]]:
        """Key-values for /diagnostics."""
        return [("supervisor_heartbeat_age_s", f"{self.supervisor_age.age_s:.2f}"),
                ("guard_heartbeat_age_s", f"{self.guard_age.age_s:.2f}"),
                ("heartbeats_rejected", sum(w.identity.rejected for w in self.watches.values())),
                ("heartbeats_taken_late", sum(w.taken_late for w in self.watches.values()))]
