"""Progress a person can follow: one line that updates in place on a terminal, each new state once elsewhere.

A long command (a campaign's feedback at several hertz) must not scroll the same line: on a terminal
:meth:`ProgressLine.update` rewrites the current line (carriage return, erase to the end of the line); in a log or
a pipe, where a carriage return would pile up, it writes a line only when the text changed. :meth:`ProgressLine.line`
prints a line that stays (a prompt, a result), ending the updating line first.
"""
from __future__ import annotations

import sys
from typing import Callable, TextIO

__all__ = ["ProgressLine"]


class ProgressLine:
    """One updating progress line (module docstring).

    write: where whole lines go when not on a terminal (default ``print``). stream / tty: the terminal stream and
    whether it is one (default ``sys.stdout`` and its ``isatty()``).
    """

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
