"""What the topside commands share beyond the vehicle's helpers (:mod:`hindrax_onboard.commands.common`): result
folders and a wall-clock progress printer."""
from __future__ import annotations

import contextlib
import time
from pathlib import Path

from hindrax_onboard.commands.common import CommandError


def result_dir(out: str | None, root: Path, name: str, unwritable: str) -> Path:
    """The folder of one result (:mod:`hindrax_tools.output_dirs`): ``out`` when given (new or empty), else a new
    ``<root>/<name>_<time>[_N]`` (one line printed when the plain name was taken). Raises CommandError: ``out``
    unusable, or ``unwritable`` (its ``{why}`` filled in) when ``root`` is not writable."""
    from ..output_dirs import OutputDirError, explicit_result_dir, new_result_dir

    try:
        if out:
            return explicit_result_dir(out)
        path, notice = new_result_dir(root, name)
    except OutputDirError as exc:
        raise CommandError(str(exc)) from exc
    except OSError as exc:
        raise CommandError(unwritable.format(why=exc.strerror or exc)) from exc
    if notice:
        print(notice, flush=True)
    return path


def remove_if_empty(path: Path) -> None:
    """Remove the folder ``path`` if it is empty: a failed command leaves no half-named result."""
    with contextlib.suppress(OSError):
        path.rmdir()


class WallProgress:
    """A progress printer: ``progress(msg)`` prints ``[  t s] msg``, t the wall seconds
    (:meth:`elapsed`) since it was made."""

    def __init__(self) -> None:
        self.start = time.monotonic()

    def elapsed(self) -> float:
        return time.monotonic() - self.start

    def __call__(self, msg: str) -> None:
        print(f"[{self.elapsed():6.1f} s] {msg}", flush=True)
