"""The ``hindrax`` command: one entry point for pool-test engineers, on the vehicle and on the topside PC.

The vehicle's build installs this package (``hindrax = hindrax_onboard.cli:main``), so ``hindrax`` exists on the Pi
with the vehicle's commands (:data:`COMMANDS`: their modules import drivers and onboard only). A package installed
beside it adds its commands through the entry-point group :data:`GROUP` (hindrax_tools, the topside's: fit,
simulation, campaigns), so one console script serves both machines (two dists owning one script fight) and
``hindrax --help`` of the topside lists every command. Rows are (words, module implementing
``add_arguments(parser)`` and ``run(args) -> int``, one-line help). Only the module of the subcommand named on
the command line is imported, so ``hindrax --help`` imports nothing but argparse and ``hindrax config check``
does not import ROS (src/hindrax_tools/test/test_cli_help.py; time: ``make bench``). docs/architecture.md §2.

Exit status: 0 on success, 1 when the command found a problem (it raises
:class:`~hindrax_onboard.commands.common.CommandError`, whose one-line message goes to stderr) or names a
command of a package not installed here (a topside command on the vehicle), 2 on a usage error (argparse),
130 when interrupted, 141 when the reader of its output closed the pipe (``| head``: no traceback)."""
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
# One OpenBLAS thread unless told otherwise, set before any command imports numpy. With
# OpenBLAS's default (a thread per core) `hindrax run`'s identification.yaml followed the core
# count: two threads against one changed the last bits of six entries (README: one seed, one
# table on any machine). The fit's matrices are small: its term selection took 7-9 CPU-s with
# two threads, 2.6 with one, no faster in wall time.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

#: the entry-point group through which other packages add (words, module, help) rows (hindrax_tools/setup.py)
GROUP = "hindrax.commands"
_V = "hindrax_onboard.commands"
#: the vehicle's commands: (command words, module implementing add_arguments/run, one-line help)
COMMANDS: list[tuple[tuple[str, ...], str, str]] = [
    (("config", "check"), f"{_V}.config_check",
     "validate a vehicle configuration file; print each error as one line, or a summary"),
    (("arm",), f"{_V}.arm", "arm a vehicle's thruster outputs (through its gateway from the topside)"),
    (("disarm",), f"{_V}.arm", "disarm a vehicle's thruster outputs"),
    (("reset",), f"{_V}.arm",
     "clear the supervisor's latched trip or e-stop (signed, like arm), printing what it cleared"),
    (("thruster-test",), f"{_V}.thruster_test",
     "step each thruster alone and print the wrench the model expects (reversed, swapped)"),
    (("health",), f"{_V}.health",
     "ready to dive? every node of the launch file running, /diagnostics and supervisor OK"),
    (("decode",), f"{_V}.decode",
     "run a serial driver's parser (dvl75: text lines, ping1d: raw bytes) over a capture (JSON)"),
    (("bag", "record"), f"{_V}.bag.record", "record topics to a rosbag2-compatible MCAP bag"),
    (("bag", "play"), f"{_V}.bag.play", "publish a bag with its timing"),
    (("bag", "info"), f"{_V}.bag.info", "topics, types, counts, rates, duration and size of a bag"),
    (("bag", "recover"), f"{_V}.bag.recover", "rebuild a bag whose recorder was killed"),
    (("sros2", "policy"), f"{_V}.sros2", "write the vehicle's SROS2 permissions policies"),
    (("sros2", "keystore"), f"{_V}.sros2",
     "create the vehicle's SROS2 keystore: enclaves, certificates, permissions (needs sros2)"),
    (("keys",), f"{_V}.keys", "create the vehicle's operator key that signs its operator requests"),
    (("esc", "calibrate"), f"{_V}.esc", "PCA9685 oscillator (esc.oscillator_hz) from a scope reading"),
    (("topic", "echo"), f"{_V}.topic", "print a topic's messages as YAML (ros2 topic echo, without the ros2 CLI)"),
]


def all_commands() -> list[tuple[tuple[str, ...], str, str]]:
    """:data:`COMMANDS` and the rows of every installed package's :data:`GROUP` entry point (each a list of rows)."""
    from importlib.metadata import entry_points

    rows = list(COMMANDS)
    for ep in entry_points(group=GROUP):
        rows += ep.load()
    return rows


def build_parser(argv: Sequence[str] | None = None, commands=None) -> argparse.ArgumentParser:
    """The argparse tree of all registered subcommands, with the arguments of the one ``argv`` names.

    argv: the command line (without the program name; default ``sys.argv[1:]``); commands: the rows (default
    :func:`all_commands`). Only the module of the
    subcommand its leading words name is imported (:func:`_add_module_arguments`); the other subcommands get
    their help line only, which is all ``hindrax --help`` and ``hindrax <group> --help`` print."""
    commands = all_commands() if commands is None else commands
    words_given = _command_words(commands, sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="hindrax", description="Hindrax ROV onboard stack")
    groups: dict[tuple[str, ...], argparse._SubParsersAction] = {}
    root = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    groups[()] = root
    for words, module, help_text in commands:
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


def _command_words(commands, argv: Sequence[str]) -> tuple[str, ...]:
    """The command path of ``commands`` (rows) that the leading non-option words of ``argv`` spell, or ``()``."""
    prefixes = {words[:i] for words, _m, _h in commands for i in range(1, len(words) + 1)}
    full = {words for words, _m, _h in commands}
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
    """SIGINT and SIGTERM handler: record the signal and raise KeyboardInterrupt in the main thread, so a command cleans
    up (closes its bag, removes its emulated ports) on SIGTERM (``docker stop``, ``kill``) exactly as on Ctrl-C.

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
    # a vehicle command needs no entry-point lookup (importlib.metadata: about 50 ms, the HEALTHCHECK every 30 s)
    commands = COMMANDS if _command_words(COMMANDS, argv) else all_commands()
    words = [w for w in argv if not w.startswith("-")][:2]
    if len(commands) == len(COMMANDS) and words and words[0] not in {w[0] for w, _m, _h in commands}:
        print(f"`hindrax {' '.join(words)}` is not a vehicle command: topside commands run on the topside PC "
              "(hindrax_tools is not installed here)", file=sys.stderr)
        return 1
    args = build_parser(argv, commands).parse_args(argv)
    if getattr(args, "_import_error", None):
        print(f"hindrax: this command is unavailable ({args._import_error})", file=sys.stderr)
        return 1
    from hindrax_common.process.dds_transport import loopback_transport  # stdlib only; --help never gets here

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
