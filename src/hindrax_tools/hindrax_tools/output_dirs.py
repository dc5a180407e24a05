"""Result folders of the ``hindrax`` commands: one new folder per result, named by its input and the time.

A result (``hindrax run``'s campaign, ``hindrax ident bag``'s identification) is never written into a folder that
holds another one: the default folder is new, ``<root>/<input>_YYYY_MM_DD-HH_MM_SS`` (the recorder's bag naming,
:mod:`hindrax_bringup.recording.bag_dir`, created atomically with ``os.mkdir``), and when that name is taken (two
runs in the same second) the next free ``_1``, ``_2``, ... is used and one line says so. A folder named with
``--out`` must be new or empty, or the command refuses in one line. ``<root>/latest`` is moved (atomically: a new
symbolic link renamed over the old) only when a result is complete, so it never points at an interrupted run."""
from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path

from hindrax_bringup.recording.bag_dir import bag_dir_name, new_bag_dir

__all__ = ["OutputDirError", "explicit_result_dir", "new_result_dir", "point_latest"]


class OutputDirError(ValueError):
    """A result folder that cannot be used (one line naming it and why)."""


def new_result_dir(root: str | os.PathLike, input_name: str,
                   now: _dt.datetime | None = None) -> tuple[Path, str | None]:
    """Create a new empty folder ``<root>/<input_name>_<time>[_N]`` (module docstring). Returns (its path, None),
    or (its path, a one-line notice) when the plain name was taken. Raises OSError when ``root`` cannot be
    created or written."""
    now = now or _dt.datetime.now()
    path = new_bag_dir(root, now, prefix=input_name)
    plain = bag_dir_name(now, input_name)
    return path, (None if path.name == plain else f"{Path(root) / plain} exists: writing to {path}")


def explicit_result_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """The folder an operator named (``--out``): created when missing, refused when it holds anything.
    Raises :class:`OutputDirError` (one line) when it is not empty or is not a folder."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputDirError(f"{option} {p}: not a folder")
    if p.is_dir() and any(p.iterdir()):
        raise OutputDirError(f"{option} {p}: not empty (results are never overwritten); name a new folder")
    p.mkdir(parents=True, exist_ok=True)
    return p


def point_latest(result: str | os.PathLike, link_name: str = "latest") -> Path:
    """Make ``<parent of result>/latest`` a relative symbolic link to ``result``, atomically (a new link renamed
    over the old one). Call once the result is complete. Returns the link's path; OSError when the folder is not
    writable or does not support symbolic links."""
    result = Path(result)
    link = result.parent / link_name
    tmp = result.parent / f".{link_name}.{os.getpid()}"
    tmp.unlink(missing_ok=True)
    os.symlink(result.name, tmp)
    os.replace(tmp, link)
    return link
