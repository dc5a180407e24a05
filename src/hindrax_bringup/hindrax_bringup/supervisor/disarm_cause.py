"""Why the thrust stopped, and what the operator does next: one line for the topside (pure, no ROS, no clocks).

Three processes can stop the thrusters (docs/architecture.md §8): the supervisor (a limit, an e-stop, another node's
abort: its latched reason), the output guard (a silent ESC or supervisor, an I2C fault: the reason of its
``guard/heartbeat`` while it silences the outputs) and the ESC itself (its watchdog, a disarm request: the ``reason``
of ``esc/output_state``). Each one says why only in its own process's log and on the internal graph; the supervisor
gathers them here and its ``supervisor/status`` (relayed to the topside by the gateway) carries the result as the
KeyValue ``disarm_cause``: ``<process>: <cause>; next: <step>``.

Rules (:class:`DisarmCauses`): the first cause seen while the output is armed is kept until the next arming (a
supervisor trip, then the guard's "supervisor tripped" and the ESC's "disarmed" that follow it, name the trip); a
supervisor trip is a cause whether armed or not (it also refuses the next arming). The guard's beat counts while the
supervisor sees the ESC armed: a killed ESC stops reporting, its last (armed) state stays latched, and only the guard's
beat says that its outputs were silenced. An ESC that reports disarmed without a cause seen before is named with its own
reason. A starvation a node reports after the stop it caused joins that cause (:meth:`DisarmCauses.on_starved`)."""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DisarmCauses", "next_step"]

#: (words in a cause, the operator's next step), first match wins; checked in order
_NEXT_STEPS: tuple[tuple[tuple[str, ...], str], ...] = (
    ((" starved for ",), "a process was starved of CPU (docs/architecture.md §10.1): stop what else loads the "
                         "vehicle's computer, then hindrax reset, hindrax arm"),
    (("esc output state silent", "no esc heartbeat"),
     "check the ESC process (hindrax health; the launch respawns it), then hindrax arm"),
    (("not identified yet",), "discovery has not named a heartbeat's publisher yet (a loaded machine): wait a "
                              "few seconds, then hindrax arm"),
    (("no supervisor heartbeat", "supervisor heartbeat"),
     "check the supervisor process (hindrax health), then hindrax arm"),
    (("output state unknown", "i2c", "pca9685", "guard cannot act", "watchdog on /oe", "hardware watchdog"),
     "check the PCA9685, its I2C bus and /OE line (hindrax health), then hindrax arm"),
    (("heartbeat not trusted", "not trusted"),
     "stop the process that publishes a second heartbeat (hindrax health), then hindrax arm"),
    (("watchdog: no command",),
     "the ESC got no thrust command in time: check the allocation and the controller, then hindrax arm"),
    (("operator e-stop",), "when it is safe: hindrax reset, then hindrax arm"),
    (("disarmed",), "hindrax arm when ready"),
)
#: the step for a supervisor trip (a limit, a rate, an abort) not matched above
_TRIP_STEP = "bring the vehicle back inside the envelope (or fix what the cause names), then hindrax reset, hindrax arm"
_DEFAULT_STEP = "hindrax health, then hindrax arm"


def next_step(process: str, cause: str) -> str:
    """The operator's next step (one line) after ``process`` (``supervisor``, ``output guard``, ``ESC``) stopped the
    thrust for ``cause`` (its one-line reason)."""
    low = cause.lower()
    for words, step in _NEXT_STEPS:
        if any(w in low for w in words):
            return step
    return _TRIP_STEP if process == "supervisor" else _DEFAULT_STEP


@dataclass
class DisarmCauses:
    """The cause of the last stop of the thrust (module docstring). Feed it the supervisor's armed view, its trips,
    the guard's beats and the ESC's state; :attr:`line` is ``''`` or ``<process>: <cause>; next: <step>``."""

    armed: bool = False
    process: str = ""
    cause: str = ""

    @property
    def line(self) -> str:
        """``<process>: <cause>; next: <step>``, or '' when nothing stopped the thrust since the last arming."""
        return f"{self.process}: {self.cause}; next: {next_step(self.process, self.cause)}" if self.cause else ""

    def _set(self, process: str, cause: str) -> None:
        if not self.cause and cause:
            self.process, self.cause = process, cause

    def on_armed(self, armed: bool, esc_reason: str = "") -> None:
        """The ESC's armed flag as the supervisor reads it (:func:`~hindrax_common.node_support.esc_state.armed_after`)
        and the state's ``reason``. Arming clears the cause; a disarm without one seen before is the ESC's own."""
        if armed and not self.armed:
            self.process, self.cause = "", ""
        elif self.armed and not armed:
            self._set("ESC", esc_reason or "disarmed")
        self.armed = bool(armed)

    def on_trip(self, reason: str) -> None:
        """The supervisor latched a breach (a limit, an e-stop, an abort): ``reason``, its one line."""
        self._set("supervisor", reason)

    def on_starved(self, report: str) -> None:
        """Another node's abort ``report``: one that names a starvation (``... starved for 1.80 s ...``) and comes
        after the cause it explains (a stale command, a sensor check tripping while that node could not run) is
        added to that cause (``(after: <report>)``), once."""
        if " starved for " in report and self.cause and " starved for " not in self.cause:
            self.cause += f" (after: {report})"

    def on_guard(self, ok: bool, message: str) -> None:
        """One ``guard/heartbeat``: level OK (``ok``) or the reason the guard silences the outputs (``message``);
        a cause only while the output is armed."""
        if not ok and self.armed:
            self._set("output guard", message or "outputs silenced")
