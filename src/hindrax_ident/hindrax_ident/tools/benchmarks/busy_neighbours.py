"""Safety benchmark rows ``busy_neighbours_*``: the armed vehicle beside CPU-bound processes of another session.

The vehicle's three safety processes (the ESC node, the supervisor and the output guard, each in its own process,
scheduled as ``vehicle.launch.xml`` starts them: :func:`hindrax_ident.tools.benchmarks.safety.vehicle_scheduling`;
the layout of :func:`hindrax_ident.tools.benchmarks.safety.running_layout`) are armed and commanded at 1700 us.
Then :data:`NEIGHBOURS` processes ``python3 -c 'while True: pass'``, in a session of their own (as another service or
a terminal on the Pi), run for :data:`DURATION_S` seconds. This process stands for the hardware (it serves the
emulated PCA9685 and its /OE line) and watches the heartbeats; hardware is never starved by a CPU load, so for the
run it takes ``SCHED_FIFO`` at :data:`HARDWARE_STAND_IN_PRIORITY`, above the safety processes.

* ``busy_neighbours_*``: the rows of :meth:`.participant_churn._Watch.rows` (disarms, target 0;
  heartbeat gaps as received, target :data:`GAP_TARGET_MS`, and between send stamps; tick gaps);
* ``busy_neighbours_nice_only_*``: the same with the real-time priority withheld (the launch file's nice -5 only),
  no target: what the priority buys here. In this three-process layout little: the starvation that nice -5 let
  through was seen with the whole launch layout, the live pool and the suite's other worker on the two cores
  (docs/deployment.md §1).

Without the right to set ``SCHED_FIFO`` (not root, no ``RLIMIT_RTPRIO``) the rows are not measured and say so.

Run alone: ``python -m hindrax_ident.tools.benchmarks.busy_neighbours [--quick]`` (prints the rows as JSON).
"""
from __future__ import annotations

import os
import subprocess
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

from hindrax_drivers.testing import child_process, python_executable

from . import run_alone
from .participant_churn import _VehicleLayout, _Watch, hardware_priority
from .safety import running_layout

#: CPU-bound neighbours, and how long they run while the vehicle is armed (QUICK_DURATION_S with --quick), s
NEIGHBOURS, DURATION_S, QUICK_DURATION_S = 2, 60.0, 20.0
GAP_TARGET_MS = 100.0


class _NiceOnlyLayout(_VehicleLayout):
    """The vehicle layout with the real-time priority withheld: the launch file's nice -5 only."""

    realtime = False


@contextmanager
def cpu_bound_neighbours(n: int = NEIGHBOURS) -> Iterator[list[subprocess.Popen]]:
    """``n`` processes ``python3 -c 'while True: pass'`` at normal priority, each in a session of its own (another
    service or a terminal on the Pi), for the block; killed on the way out. Raises RuntimeError if one inherited
    this process's real-time priority (it would starve the vehicle's processes, not stand beside them)."""
    with ExitStack() as stack:
        neighbours = [stack.enter_context(child_process(
            [python_executable(), "-c", "while True: pass"], start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)) for _ in range(n)]
        if any(os.sched_getscheduler(p.pid) != os.SCHED_OTHER for p in neighbours):
            raise RuntimeError("a CPU-bound neighbour inherited this process's real-time priority")
        yield neighbours


def busy_rows(quick: bool = False, realtime: bool = True) -> list[dict]:
    """The rows of one run (module docstring); ``realtime`` False: the nice-only comparison run."""
    duration_s = QUICK_DURATION_S if quick else DURATION_S
    prefix = "busy_neighbours_" if realtime else "busy_neighbours_nice_only_"
    with running_layout("hindrax-bench-busy-", layout=_VehicleLayout if realtime else _NiceOnlyLayout) as lay:
        watch = _Watch(lay.probe)
        lay.armed_at_1700()
        # real-time from here on: every thread of this process, the emulation's serving threads included (one
        # per node process, started when it connected: a thread started under SCHED_RESET_ON_FORK would not be)
        with hardware_priority() as refused:
            if refused:  # the same rows, not measured
                return [{**r, "value": None, "note": f"not measured: {refused}"}
                        for r in watch.rows(prefix, "", GAP_TARGET_MS)]
            watch.start()
            with cpu_bound_neighbours(NEIGHBOURS):
                time.sleep(duration_s)  # the measurement window itself (the probe spins in the layout's thread)
            watch.active = False
            load = os.getloadavg()[0]
    what = (f"armed at 1700 us for {duration_s:g} s beside {NEIGHBOURS} CPU-bound processes of another session "
            f"(1-minute load {load:.1f} at the end); safety processes "
            + ("real-time as vehicle.launch.xml starts them" if realtime else "at nice -5 only"))
    rows = watch.rows(prefix, what, GAP_TARGET_MS)
    return rows if realtime else [{k: v for k, v in r.items() if k != "target"} for r in rows]


def run(quick: bool = False) -> list[dict]:
    """The ``safety`` section's rows (``make bench``; :mod:`hindrax_ident.tools.bench`): the vehicle's scheduling,
    then the nice-only comparison."""
    return busy_rows(quick) + busy_rows(quick, realtime=False)


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
