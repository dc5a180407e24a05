"""What the ESC node hears from its safety peers: the supervisor's and the output guard's heartbeats, turned into
the two verdicts :meth:`.core.EscCore.set_peers` takes ('' = trusted, else why not).

:class:`EscPeers` subscribes to ``supervisor/heartbeat`` and ``guard/heartbeat`` through
:class:`~hindrax_drivers.liveness.HeartbeatWatch` (a forged or replayed beat, a second publisher or another node name
is a fault; only accepted beats reach the handlers) and ages each on the steady clock in executor-alive time
(:class:`~hindrax_drivers.liveness.AliveAge`). The verdict rules are :func:`.core.heartbeat_verdict`'s.
"""
from __future__ import annotations

from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus

from ..liveness import HEARTBEAT_NAMES, AliveAge, HeartbeatWatch, heartbeat_ok
from .core import heartbeat_verdict

__all__ = ["EscPeers"]


class EscPeers:
    """The ESC's view of the supervisor and the output guard (module docstring).

    ``node``: the ESC node (subscriptions); ``period_s``: its tick period, s (an age counts at most two periods per
    gap between ticks); ``timeout_s``: the heartbeat timeout, s (``esc.heartbeat_timeout_s``); ``armed()``: whether
    the ESC is armed (identity rules while armed); ``on_bad_news()``: called when a beat says the peer forbids thrust
    (a supervisor trip while armed, any guard beat that is not OK)."""

    def __init__(self, node: Any, period_s: float, timeout_s: float, armed: Callable[[], bool],
                 on_bad_news: Callable[[], Any]) -> None:
        self.timeout_s = float(timeout_s)
        self.supervisor_age = AliveAge(2.0 * period_s)
        self.guard_age = AliveAge(2.0 * period_s)
        self.supervisor_ok, self.supervisor_message = False, ""
        self.guard_ok, self.guard_message = False, ""
        self._armed, self._on_bad_news = armed, on_bad_news
        self.watches = {"supervisor": HeartbeatWatch(node, "supervisor", self.on_supervisor_heartbeat, armed),
                        "guard": HeartbeatWatch(node, "guard", self.on_guard_heartbeat, armed)}

    def tick(self) -> None:
        """Advance both ages to now (the safety tick and an arm request; the beats arrive by callbacks)."""
        self.supervisor_age.tick()
        self.guard_age.tick()

    def check_identities(self) -> None:
        """The heartbeats' identity checks against the graph (who publishes them)."""
        for watch in self.watches.values():
            watch.check()

    def on_supervisor_heartbeat(self, msg: DiagnosticStatus) -> None:
        """``supervisor/heartbeat``: level OK = within the envelope; otherwise the breach is latched. A trip
        disarms when it is handled (at once as a callback; at the next safety tick on the system clock, where
        the supervisor's own ``esc/set_armed`` request has disarmed already)."""
        self.supervisor_age.heard()
        self.supervisor_ok, self.supervisor_message = heartbeat_ok(msg), msg.message
        if not self.supervisor_ok and self._armed():
            self._on_bad_news()

    def on_guard_heartbeat(self, msg: DiagnosticStatus) -> None:
        """``guard/heartbeat``: level OK = the guard lets the outputs through (/OE low)."""
        self.guard_age.heard()
        self.guard_ok, self.guard_message = heartbeat_ok(msg), msg.message
        if not self.guard_ok:
            self._on_bad_news()  # restarts the time at neutral even if a later beat of the same take says OK

    def verdicts(self) -> tuple[str, str]:
        """The supervisor's and the guard's verdicts ('' = trusted, else why not)."""
        t = self.timeout_s
        sup = heartbeat_verdict("supervisor", HEARTBEAT_NAMES["supervisor"], self.supervisor_age.age_s, t,
                                self.supervisor_ok, self.supervisor_message)
        if sup and self.supervisor_age.fresh(t):
            sup = f"supervisor tripped: {self.supervisor_message} (clear it with supervisor/reset)"
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
                ("heartbeats_rejected", sum(w.identity.rejected for w in self.watches.values()))]
