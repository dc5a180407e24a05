"""Run a long build command with a progress line: ``python -m hindrax_tools.progress_run LABEL [--results-doc PATH
--record NAME] -- COMMAND ...`` (``make ros-install`` runs colcon through it: 4 silent minutes before).

The command's output (stdout and stderr together) passes through line by line; colcon's ``Starting >>> <pkg>`` and
``Finished <<< <pkg>`` lines also set the state shown under them (:class:`~hindrax_sim.progress_line.Ticker`: on a
terminal ``LABEL: building <pkgs> (<n> finished)  <s> s``, rewritten every second; in a log the state once per
change). At the end one line says how long it took; with ``--results-doc`` and ``--record`` a successful run writes
that time into the measurements document's ``durations`` section
(:func:`hindrax_tools.results_doc.record_duration`). The exit status is the command's (127 when it cannot start)."""
from __future__ import annotations

import argparse
import subprocess
import sys
from typing import Sequence

from hindrax_sim.progress_line import ProgressLine, Ticker
from .results_doc import main as results_main

__all__ = ["ColconState", "main", "run"]


class ColconState:
    """What colcon is doing, from its console lines: the packages started and not finished, the number finished."""

    def __init__(self) -> None:
        self.building: list[str] = []
        self.finished = 0

    def feed(self, line: str) -> bool:
        """One output line; True when it changed the state."""
        words = line.split()
        if len(words) >= 3 and words[0] in ("Starting", "Finished", "Failed") and words[1] in (">>>", "<<<"):
            pkg = words[2]
            if words[0] == "Starting":
                self.building.append(pkg)
            elif pkg in self.building:
                self.building.remove(pkg)
                self.finished += words[0] == "Finished"
            return True
        return False

    def text(self, label: str) -> str:
        """``LABEL: building a, b (n finished)``, or ``LABEL: running`` before the first package."""
        if not self.building:
            return f"{label}: running ({self.finished} finished)" if self.finished else f"{label}: running"
        return f"{label}: building {', '.join(self.building)} ({self.finished} finished)"


def run(label: str, command: Sequence[str], progress: ProgressLine | None = None, cwd: str | None = None) -> tuple[
        int, float]:
    """Run ``command`` (module docstring) showing its progress on ``progress`` (default: stdout); returns (exit
    status, seconds taken)."""
    progress = progress or ProgressLine(lambda s: print(s, flush=True))
    state = ColconState()
    with Ticker(progress, f"{label}: starting") as ticker:
        try:
            proc = subprocess.Popen(list(command), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                    bufsize=1, cwd=cwd)
        except OSError as exc:
            ticker.line(f"{label}: cannot run {command[0]!r}: {exc}")
            return 127, ticker.elapsed_s()
        ticker.set(state.text(label))
        for raw in proc.stdout:
            line = raw.rstrip("\n")
            ticker.line(line)
            if state.feed(line):
                ticker.set(state.text(label))
        code = proc.wait()
        seconds = ticker.elapsed_s()
    progress.line(f"{label}: {'finished' if code == 0 else f'FAILED (exit {code})'} in {seconds:.0f} s")
    return code, seconds


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring); returns the command's exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" not in argv:
        print("usage: python -m hindrax_tools.progress_run LABEL [--results-doc PATH --record NAME] -- COMMAND ...",
              file=sys.stderr)
        return 2
    split = argv.index("--")
    parser = argparse.ArgumentParser(prog="python -m hindrax_tools.progress_run")
    parser.add_argument("label")
    parser.add_argument("--results-doc", default="", metavar="PATH")
    parser.add_argument("--record", default="", metavar="NAME", help="the command's row in section durations")
    args = parser.parse_args(argv[:split])
    command = argv[split + 1:]
    if not command:
        parser.error("no command after --")
    code, seconds = run(args.label, command)
    if code == 0 and args.results_doc and args.record:
        results_main(["duration", args.record, f"{seconds:.1f}", "--results-doc", args.results_doc])
    return code


if __name__ == "__main__":
    raise SystemExit(main())
