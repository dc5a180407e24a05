"""Is the vehicle ready to dive? The verdict of ``hindrax health`` from what the graph shows (docs/deployment.md §7).

Pure core (no ROS): :func:`expectation` says what a launch layout must show, :func:`assess` compares it with what
was seen within a listening window and returns a :class:`HealthReport`. The command (``hindrax health``, the
container's HEALTHCHECK) collects the inputs: the node names in the graph, the latest ``/diagnostics`` status of
each name, and the supervisor's ``supervisor/status``.

Ready means: every node of the launch file is in the graph; every status those nodes publish on ``/diagnostics``
(:data:`STATUS_OF_NODE`) was received and is OK (a WARN is listed and fails only with ``strict``: a DVL out of the
water says "connected, no data"); and the supervisor's own status was received and is OK (no latched breach).
Anything else is listed, one line each, with the status message the node gave."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping

from hindrax_common.base.devices import DEVICES

__all__ = ["STATUS_OF_NODE", "SUPERVISOR_STATUS_TOPIC", "Expectation", "HealthReport", "Seen", "assess",
           "expectation", "level_name"]

#: node name in the launch files -> the name of the status it publishes on /diagnostics (nodes absent here publish
#: none; their presence in the graph is what is checked)
STATUS_OF_NODE = {
    **{d.node: d.status or f"hindrax/{d.node}" for d in DEVICES},
    "supervisor": "hindrax/supervisor",
    "output_guard": "hindrax/output_guard",
    "recorder": "recorder: recording",
}
#: the supervisor's own state (diagnostic_msgs/DiagnosticStatus: OK, or ERROR with the latched breach)
SUPERVISOR_STATUS_TOPIC = "supervisor/status"
_LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


def level_name(level: int) -> str:
    """``OK``, ``WARN``, ``ERROR``, ``STALE`` (diagnostic_msgs/DiagnosticStatus levels 0-3)."""
    return _LEVELS.get(int(level), f"level {int(level)}")


@dataclass(frozen=True)
class Expectation:
    """What a ready vehicle shows: ``nodes`` (names that must be in the graph), ``statuses`` (diagnostic status
    names that must be received), ``supervisor`` (whether ``supervisor/status`` must be received and OK)."""

    nodes: tuple[str, ...]
    statuses: tuple[str, ...]
    supervisor: bool


def expectation(node_names: Iterable[str]) -> Expectation:
    """The expectation for a launch layout whose nodes are ``node_names`` (e.g. the labels of
    :func:`~hindrax_bringup.layout.launch_xml.read_launch`)."""
    names = tuple(node_names)
    return Expectation(names, tuple(STATUS_OF_NODE[n] for n in names if n in STATUS_OF_NODE), "supervisor" in names)


@dataclass(frozen=True)
class Seen:
    """One status as received: ``level`` (0-3) and ``message``."""

    level: int
    message: str


@dataclass
class HealthReport:
    """The verdict: ``ready``, and the ``problems`` (each one line) that make it not ready, the ``warnings`` that do
    not, and ``ok`` (the expected items that are fine)."""

    ready: bool
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    ok: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """Human-readable report: one line per item, then the verdict."""
        out = [f"  OK    {x}" for x in self.ok] + [f"  WARN  {x}" for x in self.warnings] + \
              [f"  FAIL  {x}" for x in self.problems]
        return out + [self.summary()]

    def summary(self) -> str:
        """The verdict in one line."""
        if self.ready:
            return f"READY to dive ({len(self.ok)} checks OK, {len(self.warnings)} warning(s))"
        return f"NOT READY: {len(self.problems)} problem(s): " + "; ".join(self.problems)


def assess(expect: Expectation, nodes: Iterable[str], statuses: Mapping[str, Seen], supervisor: Seen | None,
           strict: bool = False) -> HealthReport:
    """Compare what was seen with ``expect`` (module docstring). ``nodes``: node names in the graph (with or
    without a leading namespace ``/``); ``statuses``: status name -> latest :class:`Seen`; ``supervisor``: the
    latest ``supervisor/status`` or None; ``strict``: a WARN is a problem too."""
    present = {n.rsplit("/", 1)[-1] for n in nodes}
    report = HealthReport(ready=True)
    for name in expect.nodes:
        if name in present:
            report.ok.append(f"node {name} running")
        else:
            report.problems.append(f"node {name} missing")
    for status in expect.statuses:
        _judge(report, status, statuses.get(status), strict)
    if expect.supervisor:
        _judge(report, SUPERVISOR_STATUS_TOPIC, supervisor, strict)
    report.ready = not report.problems
    return report


def _judge(report: HealthReport, name: str, seen: Seen | None, strict: bool) -> None:
    if seen is None:
        report.problems.append(f"{name}: no status received")
        return
    text = f"{name}: {level_name(seen.level)} {seen.message}".rstrip()
    if seen.level == 0:
        report.ok.append(text)
    elif seen.level == 1 and not strict:
        report.warnings.append(text)
    else:
        report.problems.append(text)
