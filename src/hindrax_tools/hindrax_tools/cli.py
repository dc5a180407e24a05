"""The ``hindrax`` command: one entry point for pool-test engineers.

Subcommands are registered in :data:`COMMANDS` as (words, module, help); each module provides
``add_arguments(parser)`` and ``run(args) -> int``. Only the module of the subcommand named on the
command line is imported, so ``hindrax --help`` imports nothing but argparse and ``hindrax config
check`` does not import ROS (src/hindrax_tools/test/test_cli_help.py; time: ``make bench``).

Exit status: 0 on success, 1 when the command found a problem (it raises
:class:`~hindrax_tools.commands.common.CommandError`, whose one-line message goes to
stderr), 2 on a usage error (argparse), 130 when interrupted, 141 when the reader of its output
closed the pipe (``| head``: no traceback).
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

#: the package of the command modules
PACKAGE = "hindrax_tools.commands"
#: (command words, module in PACKAGE implementing add_arguments/run, one-line help)
COMMANDS: list[tuple[tuple[str, ...], str, str]] = [
    (("config", "check"), "config_check",
     "validate a vehicle configuration file; print each error as one line, or a summary"),
    (("allocate",), "allocate",
     "allocate a base_link wrench X Y Z K M N (N, N m) to thruster forces and pulse widths (JSON)"),
    (("arm",), "arm", "arm a vehicle's thruster outputs (through its gateway from the topside)"),
    (("disarm",), "arm", "disarm a vehicle's thruster outputs"),
    (("reset",), "arm", "clear the supervisor's latched trip or e-stop (signed, like arm), printing what it cleared"),
    (("thruster-test",), "thruster_test",
     "step each thruster alone and print the wrench the model expects (reversed, swapped)"),
    (("bringup",), "bringup",
     "the virtual pool's single-process graph (--sim); the vehicle runs the launch file instead"),
    (("health",), "health",
     "ready to dive? every node of the launch file running, /diagnostics and supervisor OK"),
    (("decode",), "decode",
     "run a serial driver's parser (dvl75: text lines, ping1d: raw bytes) over a capture (JSON)"),
    (("bag", "record"), "bag.record", "record topics to a rosbag2-compatible MCAP bag"),
    (("bag", "play"), "bag.play", "publish a bag with its timing"),
    (("bag", "info"), "bag.info", "topics, types, counts, rates, duration and size of a bag"),
    (("bag", "recover"), "bag.recover", "rebuild a bag whose recorder was killed"),
    (("ident", "free-decay"), "ident",
     "added mass from a free-decay CSV (time s, acceleration m/s^2), [Hindrax-AM] eqs. 2-9 (JSON)"),
    (("ident", "thruster-fit"), "ident",
     "thrust-curve cubics from bollard-pull CSV, [Hindrax-Drag] eq. 1 (JSON; --write CONFIG)"),
    (("ident", "priors"), "ident_references",
     "empirical added mass and damping priors from geometry, [NTNU-Thesis] App. A.1/A.2 (JSON)"),
    (("ident", "inclining"), "ident_references",
     "roll/pitch restoring stiffness from an inclining test CSV with a known mass (JSON)"),
    (("ident", "tilt-decay"), "ident_references",
     "rigid + added roll/pitch inertia from a free-decay CSV and the inclining stiffness (JSON)"),
    (("ident", "campaign"), "ident", "the campaign in-process (`hindrax run --in-process`)"),
    (("ident", "scenarios"), "scenarios",
     "scenario suite: in-process campaigns on named truth files; error, z, coverage, verdicts"),
    (("ident", "start"), "ident_live",
     "send the identification campaign to a running stack, print its feedback; Ctrl-C cancels"),
    (("ident", "status"), "ident_live", "where a running campaign is (identification/status)"),
    (("ident", "continue"), "ident_live",
     "tell a running campaign's calibration step that the operator did what its prompt asked"),
    (("ident", "bag"), "ident_bag",
     "offline identification of a recorded campaign bag: identification.yaml + report"),
    (("ident", "fit"), "ident_fit",
     "identify from any bag, validated (K-fold, holdout): identification.yaml + report"),
    (("ident", "predict"), "ident_predict",
     "open-loop predictions of an identification.yaml on bags: one CSV per bag and DOF, nrmse"),
    (("run",), "run", "identification campaign on the virtual pool through the ROS graph"),
    (("control", "evaluate"), "control",
     "closed-loop holds in the virtual pool: identified model vs vehicle file vs the PD hold"),
    (("control", "scenarios"), "control",
     "per scenario truth: identify in-process, then compare the holds of the two models"),
    (("control", "hold"), "control_hold",
     "the running controller holds a depth or an altitude and the heading, or where it is"),
    (("control", "release"), "control_hold", "the running controller lets go (zero wrench)"),
    (("control", "model"), "control", "the controller's gains and the source of each model value"),
    (("sros2", "policy"), "sros2", "write the vehicle's SROS2 permissions policies"),
    (("sros2", "keystore"), "sros2",
     "create the vehicle's SROS2 keystore: enclaves, certificates, permissions (needs sros2)"),
    (("keys",), "keys", "create the vehicle's operator key that signs its operator requests"),
    (("pool", "rehearse"), "pool",
     "the README's pool day on a laptop: the live pool, the installed launch, the shells' env"),
    (("esc", "calibrate"), "esc", "PCA9685 oscillator (esc.oscillator_hz) from a scope reading"),
    (("topic", "echo"), "topic", "print a topic's messages as YAML (ros2 topic echo, without the ros2 CLI)"),
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
        p.set_defaults(_module=f"{PACKAGE}.{module}")
        if words == words_given:
            _add_module_arguments(p, f"{PACKAGE}.{module}")
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
    from hindrax_drivers.process.dds_transport import loopback_transport  # stdlib only; --help never gets here

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
