"""Progress a person can follow: one line that updates in place on a terminal, each new state once elsewhere.

A long command (a campaign's feedback at several hertz) must not scroll the same line: on a terminal
:meth:`ProgressLine.update` rewrites the current line (carriage return, erase to the end of the line); in a log or
a pipe, where a carriage return would pile up, it writes a line only when the text changed. :meth:`ProgressLine.line`
prints a line that stays (a prompt, a result), ending the updating line first. :class:`Ticker` keeps a long step
alive on a terminal (its text and the seconds elapsed, rewritten every second) and elsewhere names each new step,
and again every :data:`QUIET_S` while it lasts: ``hindrax ident bag``'s fit, ``make ros-install``'s colcon build
(:mod:`hindrax_tools.progress_run`; here in the virtual pool's package, below the campaign that ticks it)."""
from __future__ import annotations

import sys
import threading
import time
from typing import Callable, TextIO

__all__ = ["QUIET_S", "ProgressLine", "Ticker"]

#: off a terminal, the longest a :class:`Ticker` stays silent: it repeats its step with the seconds elapsed, s (issue
#: 74.6: a log showed 142 s without a line during a fit and was taken for a hang; no step silent over 10 s)
QUIET_S = 9.0


class ProgressLine:
    """One updating progress line (module docstring).

    write: where whole lines go when not on a terminal (default ``print``). stream / tty: the terminal stream and
    whether it is one (default ``sys.stdout`` and its ``isatty()``)."""

    def __init__(self, write: Callable[[str], None] = print, stream: TextIO | None = None,
                 tty: bool | None = None) -> None:
        self._write = write
        self._stream = stream or sys.stdout
        self._tty = self._stream.isatty() if tty is None else tty
        self._last: str | None = None
        self._open = False

    def update(self, text: str) -> None:
        """Show ``text`` as the current progress."""
        if text == self._last:
            return
        self._last = text
        if self._tty:
            self._stream.write("\r" + text + "\x1b[K")
            self._stream.flush()
            self._open = True
        else:
            self._write(text)

    def line(self, text: str) -> None:
        """Print ``text`` as a line of its own, after the progress line."""
        self.close()
        self._write(text)

    def close(self) -> None:
        """End the updating line (a newline on a terminal, if one is open)."""
        if self._open:
            self._stream.write("\n")
            self._stream.flush()
            self._open = False


class Ticker:
    """A step's text with the seconds elapsed since the ticker started, on a :class:`ProgressLine`: rewritten every
    ``period_s`` (s) on a terminal by a thread of its own; elsewhere the text alone at each change, and again with
    the seconds every ``quiet_s`` (s, :data:`QUIET_S`) while the step lasts. A context manager: the thread stops and
    the line ends on the way out. ``clock``: seconds (monotonic).

    ``with Ticker(ProgressLine(), "ident bag: fitting") as t: ...; t.set("ident bag: writing the report")``"""

    def __init__(self, progress: ProgressLine, text: str, period_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic, quiet_s: float = QUIET_S) -> None:
        self.progress, self.period_s, self.clock, self.quiet_s = progress, float(period_s), clock, float(quiet_s)
        self.t0 = clock()
        self._text = text
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def elapsed_s(self) -> float:
        """Seconds since the ticker started."""
        return self.clock() - self.t0

    def show(self) -> None:
        """Show the current text (with the elapsed seconds on a terminal)."""
        with self._lock:
            tty = self.progress._tty
            self.progress.update(f"{self._text}  {self.elapsed_s():.0f} s" if tty else self._text)

    def set(self, text: str) -> None:
        """A new step: show ``text`` now."""
        self._text = text
        self.show()

    def line(self, text: str) -> None:
        """A line that stays (a package built, a warning), above the ticking one."""
        with self._lock:
            self.progress.line(text)

    def _run(self) -> None:
        tty = self.progress._tty
        while not self._stop.wait(self.period_s if tty else self.quiet_s):
            if tty:
                self.show()
            else:  # a log: the step again with its seconds, so that no line is more than quiet_s apart
                with self._lock:
                    self.progress.update(f"{self._text} ({self.elapsed_s():.0f} s)")

    def __enter__(self) -> "Ticker":
        self.show()
        self._thread = threading.Thread(target=self._run, daemon=True, name="progress-ticker")
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.progress.close()
