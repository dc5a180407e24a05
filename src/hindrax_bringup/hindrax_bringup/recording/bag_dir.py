"""A new bag directory under an output root, for every start of a recorder (docs/deployment.md §5).

The vehicle's launch files pass their ``output_dir`` argument as the recorder's root (``recording.output_root``):
each start of the recorder, a respawn after a crash included, makes a new directory beneath it and never stops on
a name that exists. The name is rosbag2's (``<prefix>_YYYY_MM_DD-HH_MM_SS``, local time); when it is taken (two
starts within one second, or a clock that stepped back: a Raspberry Pi has no real-time clock and boots with the
time it last saved until chrony corrects it), ``_1``, ``_2``, ... is appended. The directory is created here with
``os.mkdir`` (atomic: of two recorders starting at once, each gets its own) and is empty, which
:class:`~hindrax_bringup.recording.writer.BagWriter` accepts.

An explicitly named bag directory (``output_dir`` parameter, ``recorder/start`` request, ``hindrax bag record
--out``) is not this module's business: a directory that already holds a bag is refused there, since the
operator asked for that very name.
"""
from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path

__all__ = ["bag_dir_name", "new_bag_dir"]

#: names tried after the plain one: <name>_1 ... <name>_<MAX_SUFFIX>
MAX_SUFFIX = 999


def bag_dir_name(now: _dt.datetime | None = None, prefix: str = "hindrax") -> str:
    """``<prefix>_YYYY_MM_DD-HH_MM_SS`` of ``now`` (default: the local time now), rosbag2's naming."""
    return (now or _dt.datetime.now()).strftime(f"{prefix}_%Y_%m_%d-%H_%M_%S")


def new_bag_dir(output_root: str | os.PathLike, now: _dt.datetime | None = None, prefix: str = "hindrax") -> Path:
    """Create and return a new empty directory ``<output_root>/<bag_dir_name(now)>[_N]`` (module docstring).

    The root is created with its parents when missing. Raises ``OSError`` when the root cannot be created or
    written (permissions, read-only or missing medium), ``FileExistsError`` only when every suffix up to
    :data:`MAX_SUFFIX` is taken."""
    root = Path(output_root)
    root.mkdir(parents=True, exist_ok=True)
    base = bag_dir_name(now, prefix)
    for n in range(MAX_SUFFIX + 1):
        candidate = root / (base if n == 0 else f"{base}_{n}")
        try:
            os.mkdir(candidate)
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(f"{root}: {base} and its suffixes _1.._{MAX_SUFFIX} all exist")
