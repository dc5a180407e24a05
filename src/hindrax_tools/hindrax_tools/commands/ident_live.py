"""``hindrax ident start | status | continue``: the identification campaign on a running stack
(vehicle or virtual pool).

* ``hindrax ident start [--dofs ...] [--levels N] [--fractions F1,F2,...] [--calibrate STEPS
  [--calibration-only]] [--server-timeout S]`` sends one ``run_identification`` goal
  (hindrax_msgs/action/RunIdentification) and prints its feedback as one updating line on a terminal
  (:mod:`hindrax_sim.progress_line`), a calibration step's operator prompt once, prefixed ``>>>``.
  Ctrl-C cancels the goal: the node brings the vehicle to a zero wrench and holds it until the ESC
  reports neutral widths, and the command waits for that end (a second Ctrl-C stops waiting). Exit 0
  when the campaign completed, 1 when it was rejected, aborted or cancelled, or no server answered.
* ``hindrax ident status`` prints the next ``identification/status`` message (ManeuverStatus);
  exit 1 when none arrives within the timeout.
* ``hindrax ident continue`` calls ``identification/continue`` (std_srvs/Trigger) once the operator
  did what the prompt asked; exit 1 when nothing was awaited or no service answered.

Each subcommand talks to the vehicle named by ``--vehicle NAME``, or to the only one on the domain
(:mod:`hindrax_onboard.commands.vehicle`): on the topside through the vehicle's gateway
(``/<name>/run_identification``, ``/<name>/identification/...``), on the vehicle itself directly.
The ESC output must be armed first (``hindrax arm``); the node refuses a goal otherwise."""
from __future__ import annotations

import argparse
import math
import signal
import time
from typing import Any, Callable

from hindrax_onboard.commands.common import CommandError, choices
from hindrax_onboard.commands.vehicle import (Target, add_vehicle_arguments, call_service,
                                              find_vehicle, refuse_shared_answer, wait_for,
                                              with_ros)

__all__ = ["add_arguments", "run", "format_estimate", "format_feedback", "format_status", "start_campaign",
           "call_continue"]

_PHASE_NAMES = {0: "idle", 1: "positioning", 2: "running", 3: "returning", 4: "done", 5: "aborted"}
_ROTATIONS = ("roll", "pitch", "yaw")
_NO_STACK = "is the stack running (hindrax bringup)?"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``start`` or ``status`` (the subcommand is the last word of ``parser.prog``)."""
    which = parser.prog.split()[-1]
    parser.set_defaults(_live=which)
    if which == "start":
        parser.add_argument("--dofs", default="", help="comma-separated DOFs, in order (default: all six)")
        parser.add_argument("--levels", type=int, default=0,
                            help="levels per DOF (default 0: identification.levels_per_dof of the running node)")
        parser.add_argument("--fractions", default="",
                            help="explicit level fractions of each DOF's authority, comma-separated, each in (0, 1]")
        parser.add_argument("--calibrate", default="",
                            help="reference steps before the ladders, as hindrax run --calibrate "
                                 "(the node prompts; answer with `hindrax ident continue`)")
        parser.add_argument("--calibration-only", action="store_true",
                            help="run only the --calibrate steps (no ladders)")
        parser.add_argument("--server-timeout", type=float, default=10.0,
                            help="wall time to wait for the run_identification server, s (default 10)")
    elif which == "continue":
        parser.add_argument("--timeout", type=float, default=10.0,
                            help="wall time to wait for the identification/continue service and its answer, s "
                                 "(default 10)")
    else:
        parser.add_argument("--timeout", type=float, default=5.0,
                            help="wall time to wait for a status message, s (default 5)")
    add_vehicle_arguments(parser)


def _unit(dof: str) -> str:
    return "N m" if dof in _ROTATIONS else "N"


def format_feedback(fb: Any) -> str:
    """One line of a RunIdentification feedback: DOF, level i/n, command with its unit, or else the phase and the
    step the node is in (e.g. ``calibration (ballast): hold depth without the ballast``); progress."""
    where = (f"{fb.dof} level {fb.level_index + 1}/{fb.level_count} {fb.level_command:+.2f} {_unit(fb.dof)}"
             if fb.dof else (fb.phase or "positioning") + (f": {fb.step}" if fb.step else ""))
    return f"{where}  progress {100.0 * fb.progress:5.1f} %"


def format_status(msg: Any) -> str:
    """One line of a ManeuverStatus: phase, DOF, level, command, progress, message."""
    phase = _PHASE_NAMES.get(int(msg.phase), str(msg.phase))
    parts = [f"phase {phase}"]
    if msg.dof:
        parts.append(f"dof {msg.dof} level {msg.level_index + 1}/{msg.level_count} "
                     f"command {msg.level_command:+.2f} {_unit(msg.dof)}")
    parts.append(f"progress {100.0 * msg.progress:.1f} %")
    if msg.message:
        parts.append(msg.message)
    return "  ".join(parts)


def _parse(args: argparse.Namespace) -> tuple[list[str], int, list[float], list[str]]:
    """(DOFs, levels, fractions, calibration steps) of ``hindrax ident start``. Raises
    :class:`CommandError` for a bad one, or ``--calibration-only`` without a step."""
    from hindrax_common.config import DOFS

    from hindrax_onboard.identification.online.executive import CALIBRATION_STEPS

    dofs = choices("--dofs", args.dofs, DOFS, "DOF")
    steps = choices("--calibrate", args.calibrate, CALIBRATION_STEPS, "step")
    if args.calibration_only and not steps:
        raise CommandError("--calibration-only needs --calibrate STEP[,STEP]")
    if args.levels < 0:
        raise CommandError(f"--levels: {args.levels} is not >= 0")
    try:
        fractions = [float(x) for x in str(args.fractions).split(",") if x.strip()]
    except ValueError:
        raise CommandError(f"--fractions: not numbers: {args.fractions!r}") from None
    if any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in fractions):
        raise CommandError(f"--fractions: each must be in (0, 1], got {fractions}")
    return dofs, int(args.levels), fractions, steps


def start_campaign(node: Any, executor: Any, dofs: list[str], levels: int, fractions: list[float],
                   server_timeout_s: float, print_line: Callable[[str], None] = print,
                   cancel_requested: Callable[[], bool] = lambda: False,
                   give_up: Callable[[], bool] = lambda: False, calibrate: list[str] | None = None,
                   calibration_only: bool = False, action_name: str = "run_identification",
                   sign: Callable[[Any], Any] = lambda goal: goal,
                   status_topic: str = "identification/status") -> tuple[bool, str]:
    """Send one goal from ``node`` (spun by ``executor``), print its feedback (an operator prompt once, when it
    appears, prefixed ``>>>``), cancel it once ``cancel_requested()`` turns True, and wait for its end
    (``give_up()`` True stops waiting after a cancel). ``calibrate`` / ``calibration_only``: the goal's fields.
    ``action_name``: the action (``/<vehicle>/run_identification`` through the gateway, on the topside); ``sign``:
    signs the goal for the gateway (:meth:`~hindrax_onboard.commands.vehicle.Target.sign`); ``status_topic``:
    the node's ManeuverStatus (``/<vehicle>/identification/status`` on the topside). Returns (success, message).
    Raises :class:`CommandError` when no server answers, the goal is rejected, a campaign is
    already running (read on ``status_topic`` before the goal is sent: the goal is then not sent),
    or more than one server answers the action's goals (the acceptance may be another server's,
    docs/threat_model.md §3)."""
    from rclpy.action import ActionClient

    from hindrax_common.node_support.action_goal import GoalNotAnswered, GoalSender
    from hindrax_msgs.action import RunIdentification

    from hindrax_sim.progress_line import ProgressLine

    client = ActionClient(node, RunIdentification, action_name)
    goals = GoalSender(node, client, action_name)
    spin = lambda: executor.spin_once(timeout_sec=0.1)  # noqa: E731
    running = _running_campaign(node, executor, status_topic)
    wait_for(executor, client.server_is_ready, server_timeout_s, "no run_identification server", _NO_STACK)
    running()  # a campaign under way: its line, and no goal sent (it would wait behind the running one)
    goal = RunIdentification.Goal(dofs=dofs, levels_per_dof=levels, level_fractions=fractions,
                                  calibrate=list(calibrate or []), calibration_only=bool(calibration_only))
    goal = sign(goal)
    last_prompt = [""]
    # the feedback comes several times a second: one updating line on a terminal, each new state once elsewhere
    progress = ProgressLine(print_line, tty=None if print_line is print else False)
    print_line = progress.line

    def on_feedback(m) -> None:
        fb = m.feedback
        if fb.prompt:
            if fb.prompt != last_prompt[0]:
                print_line(f">>> {fb.prompt} (hindrax ident continue)")
        else:
            progress.update(format_feedback(fb))
        last_prompt[0] = fb.prompt

    try:
        handle = goals.send(goal, spin, max(server_timeout_s, 5.0), feedback_callback=on_feedback)
    except GoalNotAnswered as exc:
        running()
        raise CommandError(f"run_identification: {exc}; the node's status: hindrax ident status") from None
    if not handle.accepted:
        running()
        raise CommandError("goal rejected: a campaign is already running or still ending, or the goal is invalid "
                           "(hindrax ident status; the identification node's log)")
    goal_servers = node.count_services(f"{action_name}/_action/send_goal")
    refuse_shared_answer(action_name, goal_servers, "its goals", "acceptance", "goal",
                         "hindrax ident status; hindrax health on the vehicle")
    what = "calibration only" if calibration_only else (', '.join(dofs) or 'all DOFs')
    cal = f" after calibration {', '.join(calibrate)}" if (calibrate and not calibration_only) else ""
    print_line(f"campaign started: {what}{cal}; Ctrl-C cancels")
    cancelled = False
    while (result := goals.poll_result(handle)) is None:
        if not cancelled and cancel_requested():
            cancelled = True
            print_line("cancelling: the vehicle is brought to a zero wrench and held ...")
        if cancelled:
            goals.cancel(handle)
        if cancelled and give_up():
            return False, "stopped waiting for the end of the cancelled goal"
        spin()
    res = result.result
    if res.estimates:
        print_line("online estimates (RLS), not the verdict (hindrax ident fit on the bag gives it):")
    for e in res.estimates:
        print_line(f"  {format_estimate(e)}")
    return bool(res.success), str(res.message)


def format_estimate(e: Any) -> str:
    """One line of a HydroEstimate: the DOF, then each parameter's name, value and unit with its 95 % interval
    (value +- 1.96 std; "no interval" where the node publishes std -1: not converged or not trusted), e.g.
    ``heave: inertia 56.6 kg [55.1, 58.1], ...``."""
    def one(name: str, value: float, unit: str, std: float | None) -> str:
        band = (f"[{value - 1.96 * std:.4g}, {value + 1.96 * std:.4g}]" if std is not None and std >= 0.0
                else "(no interval)")
        return f"{name} {value:.4g} {unit} {band}"
    units, stds = list(e.parameter_units), list(e.std)
    return f"{e.dof}: " + ", ".join(
        one(n, v, units[i] if i < len(units) else "", stds[i] if i < len(stds) else None)
        for i, (n, v) in enumerate(zip(e.parameter_names, e.values)))


def _running_campaign(node: Any, executor: Any, topic: str, wait_s: float = 3.0) -> Callable[[], None]:
    """Listen to ``topic`` (identification/status, ManeuverStatus); the returned check spins up to ``wait_s`` (wall)
    for a message and raises :class:`CommandError` ``"a campaign is already running (<status>) ..."`` when the last
    one shows a goal under way (positioning, running, returning). No message: no objection (the goal's own answer
    says more)."""
    from hindrax_msgs.msg import ManeuverStatus

    got: list = []
    node.create_subscription(ManeuverStatus, topic, got.append, 10)
    under_way = (ManeuverStatus.PHASE_POSITIONING, ManeuverStatus.PHASE_RUNNING, ManeuverStatus.PHASE_RETURNING)

    def check() -> None:
        deadline = time.monotonic() + wait_s
        while not got and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if got and int(got[-1].phase) in under_way:
            raise CommandError(f"a campaign is already running ({format_status(got[-1])}); not started: it goes "
                               "on undisturbed (hindrax ident status; Ctrl-C in its own terminal cancels it)")
    return check


def _on_vehicle(args: argparse.Namespace, body: Callable[[Any, Any, Target], Any]) -> Any:
    """``body(node, executor, target)`` with the vehicle the arguments name (:func:`find_vehicle`)."""
    def on_ros(node, ex):
        return body(node, ex, find_vehicle(node, ex, args.vehicle, args.discovery_timeout))
    return with_ros(on_ros, "hindrax_cli_ident")  # Ctrl-C is ours (cancel)


def _start(args: argparse.Namespace) -> int:
    dofs, levels, fractions, calibrate = _parse(args)
    interrupts = []
    previous = signal.signal(signal.SIGINT, lambda *_: interrupts.append(time.monotonic()))
    try:
        ok, message = _on_vehicle(args, lambda node, ex, target: start_campaign(
            node, ex, dofs, levels, fractions, args.server_timeout, lambda s: print(s, flush=True),
            cancel_requested=lambda: len(interrupts) >= 1, give_up=lambda: len(interrupts) >= 2,
            calibrate=calibrate, calibration_only=bool(args.calibration_only),
            action_name=target.resolve("run_identification", "run_identification"),
            sign=lambda goal: target.sign("run_identification", goal),
            status_topic=target.resolve("identification/status", "identification/status")))
    finally:
        signal.signal(signal.SIGINT, previous)
    print(f"result: {'complete' if ok else 'not complete'}: {message}", flush=True)
    return 0 if ok else 1


def _status(args: argparse.Namespace) -> int:
    from hindrax_msgs.msg import ManeuverStatus

    def body(node, executor, target) -> int:
        got: list = []
        node.create_subscription(ManeuverStatus, target.resolve("identification/status", "identification/status"),
                                 got.append, 10)
        wait_for(executor, lambda: got, args.timeout, "no identification/status", _NO_STACK)
        print(format_status(got[-1]), flush=True)
        return 0

    return _on_vehicle(args, body)


def call_continue(node: Any, executor: Any, timeout_s: float, target: Target | None = None) -> tuple[bool, str]:
    """Call ``identification/continue`` (std_srvs/Trigger; through the gateway on the topside, signed, when
    ``target`` is a topside one) from ``node`` (spun by ``executor``) once; returns the node's (success, message).
    Raises :class:`CommandError` when the service is not there or does not answer within ``timeout_s`` (wall). Not
    repeated on a lost answer: a second continue could skip the next prompt."""
    from std_srvs.srv import Trigger

    name = "identification/continue"
    srv, service, request = (target or Target("", False)).service(name, name, Trigger)
    res = call_service(node, executor, (srv, service, request), timeout_s, _NO_STACK,
                       "check with hindrax ident status before calling it again")
    return bool(res.success), str(res.message)


def _continue(args: argparse.Namespace) -> int:
    ok, message = _on_vehicle(args, lambda node, ex, target: call_continue(node, ex, args.timeout, target))
    print(f"{'continued' if ok else 'not continued'}: {message}", flush=True)
    return 0 if ok else 1


def run(args: argparse.Namespace) -> int:
    """Dispatch on the subcommand."""
    return {"start": _start, "continue": _continue}.get(args._live, _status)(args)
