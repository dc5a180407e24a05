"""The ``hindrax`` command: one entry point for pool-test engineers.

Subcommands are registered in :data:`COMMANDS` as (path, module, help); each module provides
``add_arguments(parser)`` and ``run(args) -> int``. The command tree is built from :data:`COMMANDS` alone;
only the module of the subcommand named on the command line is imported (to add its arguments, then to run
it), so ``hindrax --help`` and ``hindrax bag --help`` import nothing but argparse, and ``hindrax config check``
does not import ROS (checked by ``src/hindrax_ident/test/test_cli_help.py``; time in ``make bench``, ``cli``).

Exit status: 0 on success, 1 when the command ran and found a problem (e.g. an invalid configuration: the
command raises :class:`~hindrax_ident.tools.commands.common.CommandError`, whose one-line message
goes to stderr),
2 on a usage error (argparse), 141 when the reader of its output closed the pipe (``| head``: no traceback).
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from typing import Sequence

# Every process the project starts keeps DDS discovery on loopback unless told otherwise (SUBNET on the topside),
# over the vehicle's loopback UDP transport (docs/architecture.md §11.4).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

#: (command words, module implementing add_arguments/run, one-line help)
COMMANDS: list[tuple[tuple[str, ...], str, str]] = [
    (("config", "check"), "hindrax_ident.tools.commands.config_check",
     "validate a vehicle configuration file; print each error as one line, or a summary"),
    (("allocate",), "hindrax_ident.tools.commands.allocate",
     "allocate a base_link wrench X Y Z K M N (N, N m) to thruster forces and pulse widths (JSON)"),
    (("arm",), "hindrax_ident.tools.commands.arm",
     "arm a vehicle's thruster outputs (--vehicle NAME, or the only vehicle on the domain; through its gateway "
     "from the topside)"),
    (("disarm",), "hindrax_ident.tools.commands.arm",
     "disarm a vehicle's thruster outputs (--vehicle NAME, or the only vehicle on the domain)"),
    (("thruster-test",), "hindrax_ident.tools.commands.thruster_test",
     "step each thruster alone and print the wrench the model expects (catch reversed/swapped thrusters)"),
    (("bringup",), "hindrax_ident.tools.commands.bringup",
     "the virtual pool's single-process graph (--sim); the vehicle runs the launch file instead "
     "(ros2 launch hindrax_drivers vehicle.launch.xml)"),
    (("health",), "hindrax_ident.tools.commands.health",
     "ready to dive? every node of the vehicle's launch file running, its /diagnostics OK and the supervisor OK; "
     "exit 0, or 1 listing what is missing"),
    (("decode",), "hindrax_ident.tools.commands.decode",
     "run a serial driver's parser (dvl75: text lines, ping1d: raw bytes) over a capture; one JSON record per line"),
    (("bag", "record"), "hindrax_ident.tools.commands.bag.record",
     "record topics to a rosbag2-compatible MCAP bag (--topics/--regex/--all, --out, --duration)"),
    (("bag", "play"), "hindrax_ident.tools.commands.bag.play",
     "publish a bag with its timing (--rate, --start-offset, --topics, --loop, --clock)"),
    (("bag", "info"), "hindrax_ident.tools.commands.bag.info",
     "topics, types, counts, rates, duration and size of a bag"),
    (("bag", "recover"), "hindrax_ident.tools.commands.bag.recover",
     "rebuild the summary and metadata.yaml of a bag whose recorder was killed"),
    (("ident", "free-decay"), "hindrax_ident.tools.commands.ident",
     "added mass from a free-decay CSV (time s, acceleration m/s^2), [Hindrax-AM] eqs. 2-9 (JSON)"),
    (("ident", "thruster-fit"), "hindrax_ident.tools.commands.ident",
     "thrust-curve cubics from bollard-pull CSV (pulse width us, thrust N), [Hindrax-Drag] eq. 1 "
     "(JSON; --write CONFIG)"),
    (("ident", "priors"), "hindrax_ident.tools.commands.ident_references",
     "empirical added mass and damping priors from geometry, [NTNU-Thesis] App. A.1/A.2 (JSON; --config "
     "FILE or --length-m ... --top-area-m2)"),
    (("ident", "inclining"), "hindrax_ident.tools.commands.ident_references",
     "roll/pitch restoring stiffness from an inclining test CSV (arm m, IMU tilt rad) with a known mass (JSON)"),
    (("ident", "tilt-decay"), "hindrax_ident.tools.commands.ident_references",
     "rigid + added roll/pitch inertia from a free-decay CSV (time s, gyro rate or angle) and the inclining "
     "stiffness, nonlinear ODE fit (JSON)"),
    (("ident", "campaign"), "hindrax_ident.tools.commands.ident",
     "identification campaign in-process on the simulator (same as `hindrax run`)"),
    (("ident", "scenarios"), "hindrax_ident.tools.commands.scenarios",
     "scenario suite: in-process campaigns on named truth files (disturbed pools); error, z, coverage, verdicts"),
    (("ident", "start"), "hindrax_ident.tools.commands.ident_live",
     "send the identification campaign to a running stack (action run_identification), print its feedback; "
     "Ctrl-C cancels to a zero wrench"),
    (("ident", "status"), "hindrax_ident.tools.commands.ident_live",
     "print where a running identification campaign is (identification/status)"),
    (("ident", "continue"), "hindrax_ident.tools.commands.ident_live",
     "tell a running campaign's calibration step that the operator did what its prompt asked "
     "(service identification/continue)"),
    (("ident", "bag"), "hindrax_ident.tools.commands.ident_bag",
     "offline identification (batch LS + output error, [Hindrax-Drag] eqs. 6-8) of a recorded campaign bag: "
     "identification.yaml + report"),
    (("ident", "fit"), "hindrax_ident.tools.commands.ident_fit",
     "identify from any bag (WrenchStamped or ThrusterPwm force; Odometry, Twist or Dvl velocity): prediction-error "
     "fit with delay, K-fold and holdout validation (nrmse): identification.yaml + report"),
    (("ident", "predict"), "hindrax_ident.tools.commands.ident_predict",
     "open-loop predictions of an identification.yaml on bags, re-initialised per segment (--segment-s): one CSV "
     "t_s,segment,measured,predicted per bag and DOF, and their nrmse"),
    (("run",), "hindrax_ident.tools.commands.run",
     "identification campaign on the virtual pool through the ROS graph (action, recorder): bag/, "
     "identification.yaml, report"),
    (("control", "evaluate"), "hindrax_ident.tools.commands.control",
     "closed-loop depth step, altitude hold over a sloped floor and heading step in the virtual pool against a truth: "
     "identified model vs vehicle file vs the former PD hold (table, control.json, report)"),
    (("control", "scenarios"), "hindrax_ident.tools.commands.control",
     "for each scenario truth: identify in-process, then compare the depth and altitude holds of the identified model "
     "and the vehicle file (control_scenarios.md/.json)"),
    (("control", "hold"), "hindrax_ident.tools.commands.control_hold",
     "the running controller holds a depth or an altitude (--depth-m / --altitude-m) and the heading, or where it is"),
    (("control", "release"), "hindrax_ident.tools.commands.control_hold",
     "the running controller lets go (zero wrench)"),
    (("control", "model"), "hindrax_ident.tools.commands.control",
     "the controller's gains and the source of each model value (--model identification.yaml or the vehicle file)"),
    (("sros2", "policy"), "hindrax_ident.tools.commands.sros2",
     "write the vehicle's SROS2 permissions policies (internal and topside domain) for its name and launch files"),
    (("sros2", "keystore"), "hindrax_ident.tools.commands.sros2",
     "create the vehicle's SROS2 keystore: enclaves, certificates, signed permissions (needs sros2, on the Pi)"),
    (("keys",), "hindrax_ident.tools.commands.keys",
     "create the vehicle's operator key (mode 0600) that signs arm, campaign and setpoints; says where the topside "
     "copy goes"),
    (("pool", "rehearse"), "hindrax_ident.tools.commands.pool",
     "the README's pool day on a laptop: the live pool, the installed launch, the two shells' environments"),
    (("esc", "calibrate"), "hindrax_ident.tools.commands.esc",
     "PCA9685 oscillator (esc.oscillator_hz) from one scope reading of a pulse: --measured-us X [--write]"),
]


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argparse tree of all registered subcommands, with the arguments of the one ``argv`` names.

    argv: the command line (without the program name; default ``sys.argv[1:]``). Only the module of the
    subcommand its leading words name is imported (:func:`_add_module_arguments`); the other subcommands get
    their help line only, which is all ``hindrax --help`` and ``hindrax <group> --help`` print.
    """
    words_given = _command_words(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="hindrax", description="Hindrax ROV onboard stack")
    groups: dict[tuple[str, ...], argparse._SubParsersAction] = {}
    root = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    groups[()] = root
    for words, module, help_text in COMMANDS:
        for depth in range(1, len(words)):
            prefix = words[:depth]
            if prefix not in groups:
                sub = groups[prefix[:-1]].add_parser(prefix[-1], help=f"{prefix[-1]} commands")
                groups[prefix] = sub.add_subparsers(dest="_".join(prefix) + "_command", metavar="COMMAND",
                                                    required=True)
        p = groups[words[:-1]].add_parser(words[-1], help=help_text, description=help_text)
        p.set_defaults(_module=module)
        if words == words_given:
            _add_module_arguments(p, module)
    return parser


def _command_words(argv: Sequence[str]) -> tuple[str, ...]:
    """The registered command path that the leading non-option words of ``argv`` spell, or ``()``."""
    prefixes = {words[:i] for words, _m, _h in COMMANDS for i in range(1, len(words) + 1)}
    full = {words for words, _m, _h in COMMANDS}
    path: tuple[str, ...] = ()
    for token in argv:
        if token.startswith("-"):
            continue
        if path + (token,) not in prefixes:
            break
        path += (token,)
        if path in full:
            return path
    return ()


def _add_module_arguments(parser: argparse.ArgumentParser, module: str) -> None:
    """Let the subcommand's module declare its arguments. A module that fails to import does not take the
    other subcommands down: its subcommand then reports the import error and exits 1."""
    try:
        mod = importlib.import_module(module)
    except Exception as exc:  # noqa: BLE001 - reported when that subcommand is used
        parser.set_defaults(_import_error=f"{type(exc).__name__}: {exc}")
        parser.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        return
    mod.add_arguments(parser)


#: the stop signals (SIGINT, SIGTERM) this process received, in order (:func:`_terminate`)
_stop_signals: list[int] = []


def _terminate(signum: int, _frame) -> None:
    """SIGINT and SIGTERM handler: record the signal and raise KeyboardInterrupt in the main thread, so a command
    cleans up (closes its bag, removes its emulated ports) on SIGTERM (``docker stop``, ``kill``) exactly as on
    Ctrl-C.

    Python runs this handler at the next bytecode of the main thread, which may be inside a C extension's call back
    into Python: pybind11 (rclpy's ``take_goal_response`` converting the response message) then replaces the
    ``KeyboardInterrupt`` by ``RuntimeError: Unable to convert call argument ...``. :func:`main` therefore reads any
    exception that ends a command after a stop signal as the interruption (:data:`_stop_signals`)."""
    _stop_signals.append(signum)
    raise KeyboardInterrupt(f"signal {signum}")


def _interrupted() -> int:
    print("interrupted", file=sys.stderr)
    return 130


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``hindrax`` console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    if getattr(args, "_import_error", None):
        print(f"hindrax: this command is unavailable ({args._import_error})", file=sys.stderr)
        return 1
    from hindrax_drivers.dds_transport import loopback_transport  # stdlib only; --help never gets here

    try:
        loopback_transport()  # before any command creates a participant
    except FileNotFoundError as exc:
        print(f"hindrax: {exc}", file=sys.stderr)
        return 1
    mod = importlib.import_module(args._module)
    _stop_signals.clear()
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in previous:  # SIGTERM (docker stop, kill) ends a command as Ctrl-C does
        signal.signal(sig, _terminate)
    try:
        return _run_command(mod, args, argv)
    except Exception:
        if _stop_signals:  # the interruption, renamed on its way through a C extension (_terminate)
            return _interrupted()
        raise
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


def _run_command(mod, args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the command module ``mod`` on ``args``; returns the exit status, with the errors a user can meet said in
    one line (1), an interruption 130 and a closed output pipe 141."""
    from .commands.common import CommandError

    try:
        status = int(mod.run(args) or 0)
        sys.stdout.flush()  # inside the try: a closed pipe (| head) is said here, not at interpreter exit
        return status
    except CommandError as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return _interrupted()
    except (UnicodeDecodeError, RecursionError) as exc:  # an input no reader of the command caught: one line
        what = "a binary file where text was expected" if isinstance(exc, UnicodeDecodeError) else \
            "input nested too deeply (recursion limit)"
        print(f"hindrax {' '.join(w for w in argv[:2] if not w.startswith('-'))}: {what}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # the reader of our output went away (| head): stop quietly, as the standard tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, the shell's status for a tool stopped by a closed pipe


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
