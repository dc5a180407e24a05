"""One node process of the stack benchmark's launch layout: a console script's function, as installed.

``python -m hindrax_ident.tools.benchmarks.launch_node MODULE[:FUNCTION] --ros-args ...`` runs
``MODULE.FUNCTION()``
(default ``main``; a console script's target, e.g. ``hindrax_drivers.composition:i2c_sensors_main``) as the
installed console script does. The I2C drivers reach the virtual pool's emulated bus through their own
``open_smbus`` (:data:`SOCKET_ENV` set in the process's environment, :mod:`hindrax_drivers.transport.socket_i2c`),
so nothing of the node is replaced. This module imports nothing else: no simulator, emulator or benchmark code
(:mod:`hindrax_ident.tools.benchmarks.launch_layout` runs the pool in its own process), so a
benchmarked process holds
the modules, and the memory, the vehicle's process holds (``test_bench_launch_layout.py`` checks it). With
``HINDRAX_BENCH_PROFILE=DIR`` (:data:`PROFILE_ENV`) the node runs under cProfile and writes
``DIR/<module>.prof`` on exit (``python -m pstats``), also when the node process ends itself with ``os._exit``
(:data:`hindrax_drivers.ros_process.BEFORE_PROCESS_END`). Every Python thread the node starts takes its
``threading`` name as its OS thread name (:func:`name_os_threads`), so the benchmark's wake-ups and CPU by thread
(``/proc/PID/task/*/comm``) name it.
"""
from __future__ import annotations

import cProfile
import ctypes
import importlib
import os
import sys
import threading
from pathlib import Path

from hindrax_drivers.ros_process import BEFORE_PROCESS_END
from hindrax_drivers.transport.socket_i2c import SOCKET_ENV

__all__ = ["PROFILE_ENV", "SOCKET_ENV", "main", "name_os_threads"]

#: a directory: each node process runs under cProfile and writes ``<module>.prof`` there when it exits
PROFILE_ENV = "HINDRAX_BENCH_PROFILE"


#: prctl's option that names the calling thread (linux/prctl.h); the kernel keeps 15 bytes of it
_PR_SET_NAME = 15


def name_os_threads() -> None:
    """From now on, every Python thread started in this process names its OS thread after its ``threading`` name
    (the first 15 bytes; Linux ``prctl(PR_SET_NAME)``); without it every Python thread is ``python`` in
    ``/proc/PID/task/*/comm``. Only the benchmark's node processes do this: nothing of the node changes."""
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    start = threading.Thread._bootstrap_inner

    def named_start(thread: threading.Thread) -> None:
        prctl(_PR_SET_NAME, thread.name.encode(errors="replace")[:15], 0, 0, 0)
        start(thread)

    threading.Thread._bootstrap_inner = named_start


def main(argv: list[str] | None = None) -> int:
    """Run the console script target ``argv[0]`` (``module[:function]``) with the arguments ``argv[1:]``
    (``sys.argv`` without the program name by default); returns its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        print("usage: python -m hindrax_ident.tools.benchmarks.launch_node MODULE[:FUNCTION] "
              "[--ros-args ...]", file=sys.stderr)
        return 2
    entry, rest = argv[0], argv[1:]
    name_os_threads()
    module_name, _, function = entry.partition(":")
    module = importlib.import_module(module_name)
    run = getattr(module, function or "main")
    sys.argv = [module_name] + rest
    profile_dir = os.environ.get(PROFILE_ENV)
    if not profile_dir:
        return int(run() or 0)

    profiler = cProfile.Profile()
    path = str(Path(profile_dir) / f"{entry.replace(':', '.')}.prof")

    def dump() -> None:
        profiler.disable()
        profiler.dump_stats(path)

    BEFORE_PROCESS_END.append(dump)
    try:
        return int(profiler.runcall(run) or 0)
    finally:
        BEFORE_PROCESS_END.remove(dump)
        profiler.dump_stats(path)


if __name__ == "__main__":
    raise SystemExit(main())
