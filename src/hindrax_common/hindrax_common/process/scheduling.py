"""A node process's CPU scheduling: real-time priority (``SCHED_FIFO``) for the safety processes, when allowed.

The vehicle launch file gives the processes whose deadlines stop the thrusters (the actuation process with the ESC,
the supervisor, the output guard) and the sensor drivers whose rates the supervisor checks the environment variable
:data:`PRIORITY_ENV` (``<env name="HINDRAX_REALTIME_PRIORITY" value="..."/>`` in ``vehicle.launch.xml``).
:func:`apply_realtime_priority`, called by every node process before ``rclpy.init``
(:func:`hindrax_common.node_support.node_common.run_nodes`), puts every thread of the process under ``SCHED_FIFO`` at
that priority; threads started later (Fast DDS's, the ESC's bus worker) inherit it (glibc's ``pthread_create`` default,
``PTHREAD_INHERIT_SCHED``). The process logs the outcome once it has a node (:func:`describe`).

Why not ``nice``: on a kernel with ``CONFIG_SCHED_AUTOGROUP`` (Debian's, Raspberry Pi OS's; enabled on this
project's development machines, ``/proc/sys/kernel/sched_autogroup_enabled`` 1), a nice value only ranks a process
against the other processes of its own session; each session's group shares the CPU equally with every other's.
A process started in a session of its own (a systemd service, a ``setsid`` child, the test suite's process runner)
therefore gains nothing from ``nice -n -5`` against a CPU-bound process of another session;
``SCHED_FIFO`` threads are scheduled before every ``SCHED_OTHER`` thread of every session (sched(7),
"SCHED_FIFO"). Real-time throttling (``/proc/sys/kernel/sched_rt_runtime_us``, 0.95 s of every 1 s
by default) leaves the rest of the machine a share even if a real-time process spins.

Refused: setting ``SCHED_FIFO`` needs ``CAP_SYS_NICE`` or an ``RLIMIT_RTPRIO`` at least the priority (sched(7),
"Privileges and resource limits"): root, ``LimitRTPRIO=`` in the bare-metal systemd unit, ``ulimits: rtprio:`` in
the compose file (docs/deployment.md §1). Without it the process runs on under its ``nice`` value (the launch file's
``launch-prefix``) and says so in one warning naming the priority and the limit; it never stops a node.

Own code, not a library's: the standard library's ``os.sched_setscheduler`` is the whole interface; what is here is
the choice of threads and the report."""
from __future__ import annotations

import contextlib
import errno
import os
import resource
from dataclasses import dataclass
from typing import Mapping

__all__ = ["HARDWARE_STAND_IN_PRIORITY", "PRIORITY_ENV", "PRIORITY_RANGE", "Scheduling", "apply_realtime_priority",
           "describe", "requested_priority", "set_every_thread", "set_this_thread"]

#: the environment variable naming a process's ``SCHED_FIFO`` priority (unset, empty or 0: not asked)
PRIORITY_ENV = "HINDRAX_REALTIME_PRIORITY"
#: the priorities allowed: above 0 (``SCHED_OTHER``), below the kernel's threaded interrupt handlers (50)
PRIORITY_RANGE = (1, 49)
#: ``SCHED_FIFO`` priority of what stands in for the vehicle's hardware on a machine without it (the emulated
#: devices' serving threads, the live pool): above every vehicle process (5-12, ``vehicle.launch.xml``), as the real
#: devices answer whatever the CPU load
HARDWARE_STAND_IN_PRIORITY = 20


@dataclass(frozen=True)
class Scheduling:
    """The outcome of :func:`apply_realtime_priority`. requested: the priority asked (0: none). granted: every thread
    of the process runs ``SCHED_FIFO`` at ``requested``. reason: why not, when asked and not granted ("" otherwise).
    threads: the threads set."""

    requested: int
    granted: bool
    reason: str = ""
    threads: int = 0


def requested_priority(environ: Mapping[str, str] | None = None) -> int:
    """The priority :data:`PRIORITY_ENV` asks for (0 when unset or empty).

    Raises ``ValueError``: a value that is not an integer in :data:`PRIORITY_RANGE` or 0, in one line naming the
    variable, the value and the allowed range."""
    raw = (os.environ if environ is None else environ).get(PRIORITY_ENV, "").strip()
    if not raw:
        return 0
    lo, hi = PRIORITY_RANGE
    try:
        value = int(raw)
    except ValueError:
        value = -1
    if value != 0 and not lo <= value <= hi:
        raise ValueError(f"{PRIORITY_ENV}={raw!r}: allowed 0 (not real-time) or an integer {lo}..{hi}")
    return value


def apply_realtime_priority(environ: Mapping[str, str] | None = None) -> Scheduling:
    """Put every thread of this process under ``SCHED_FIFO`` at the priority :data:`PRIORITY_ENV` asks for (module
    docstring). Call it before the process starts threads (before ``rclpy.init``): later threads inherit the policy.
    A refusal (``EPERM``: neither ``CAP_SYS_NICE`` nor a large enough ``RLIMIT_RTPRIO``) leaves the process as it was
    and is returned, not raised. Raises ``ValueError`` for a bad value (:func:`requested_priority`)."""
    priority = requested_priority(environ)
    if priority == 0:
        return Scheduling(0, False)
    try:
        done = set_every_thread(os.SCHED_FIFO, priority)
    except OSError as exc:
        return Scheduling(priority, False, _refusal(exc, priority))
    return Scheduling(priority, True, threads=done)


def _refusal(exc: OSError, priority: int) -> str:
    """Why ``SCHED_FIFO`` at ``priority`` was refused (``exc``: the ``sched_setscheduler`` error)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_RTPRIO)
    why = "not permitted" if exc.errno == errno.EPERM else os.strerror(exc.errno or 0)
    return f"{why}: needs CAP_SYS_NICE or RLIMIT_RTPRIO >= {priority} (RLIMIT_RTPRIO is {soft})"


def set_every_thread(policy: int, priority: int) -> int:
    """Set ``policy`` (``os.SCHED_FIFO``, ``os.SCHED_OTHER``) at ``priority`` (0 for ``SCHED_OTHER``) on every thread
    of this process; returns how many were set. All or none: on a refusal the threads already set go back to
    ``SCHED_OTHER`` and the ``OSError`` is raised."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        tids = [0]
    done: list[int] = []
    for tid in tids:
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(priority))
            done.append(tid)
        except ProcessLookupError:  # a thread that ended meanwhile
            continue
        except OSError:
            for t in done:
                with contextlib.suppress(OSError):
                    os.sched_setscheduler(t, os.SCHED_OTHER, os.sched_param(0))
            raise
    return len(done)


def set_this_thread(priority: int) -> str:
    """Put the calling thread alone under ``SCHED_FIFO`` ``priority`` (Linux schedules threads, not processes: sched(7);
    threads it starts afterwards inherit it). For a thread that stands in for hardware inside a process that must not
    become real-time as a whole (a test process serving emulated devices). Returns '' when granted, else why not
    (``CAP_SYS_NICE`` or ``RLIMIT_RTPRIO``); the thread then keeps its scheduling. ``priority`` 0: nothing asked."""
    if priority <= 0:
        return ""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        return f"SCHED_FIFO priority {priority} refused ({_refusal(exc, priority)})"
    return ""


def describe(result: Scheduling) -> tuple[str, str]:
    """(level, text) of the start-up log line for ``result``: ``("info", "real-time scheduling: SCHED_FIFO priority
    10 (1 thread at start)")``, ``("warn", "real-time scheduling SCHED_FIFO priority 10 refused (...): running at nice
    -5 ...")``, or ``("", "")`` when none was asked."""
    if result.requested == 0:
        return "", ""
    if result.granted:
        threads = f"{result.threads} thread{'' if result.threads == 1 else 's'}"
        return "info", f"real-time scheduling: SCHED_FIFO priority {result.requested} ({threads} at start)"
    return "warn", (f"real-time scheduling SCHED_FIFO priority {result.requested} refused ({result.reason}): "
                    f"running at nice {os.getpriority(os.PRIO_PROCESS, 0)}, late under CPU load "
                    "(docs/deployment.md §1)")
