"""A Pi-sized CPU rig on a development machine: the vehicle's processes inside a cgroup of F cores here.

The factor, :data:`PI4_FACTOR` (the project's one figure; the stack bench uses it too): a Pi 4 core does the work of
:data:`PI4_CORE_HERE` (0.2) of a core here for this stack. Source (issue 73; not measured on a Pi): n-body 2.8x slower
on the Pi 4 in C, 3.6x in the same CPython version; the stack's mix (rclpy, Fast DDS, wake-ups) 4-6x; 5 its middle.
(A published Python n-body time, 10.8x, is of an older, unstated CPython.) The first Pi day measures it
(:func:`measured_factor`, docs/pi_budget.md). Half a Pi 4 is 0.4 of a core here, the whole Pi 0.8.

The budget: the group's CFS quota (``cpu.cfs_quota_us``, cgroup v1; ``cpu.max``, cgroup v2) bounds its
``SCHED_OTHER`` processes, never its ``SCHED_FIFO`` ones (the kernel throttles those by the separate real-time
runtime). The vehicle's safety processes and sensor drivers run ``SCHED_FIFO`` (docs/deployment.md §1) and take
about three quarters of the stack's CPU, so a quota of F alone would bound almost nothing. Decision: the real-time
processes keep ``SCHED_FIFO`` (as on the Pi: they run before every other process) and the rest gets what they leave:
every :data:`BALANCE_PERIOD_S` the rig sets the quota to F less the real-time processes' CPU over the last
:data:`RT_WINDOW_S` (at least the kernel's 1 ms per period, :data:`MIN_QUOTA_US`). On cgroup v1 with real-time group
scheduling (``cpu.rt_runtime_us``), the group also gets a real-time runtime of F (capped at 0.9) shared by the CPUs
(F / CPUs each: the kernel lets a CPU's real-time processes borrow the others' runtime; measured here, a real-time busy
loop in a group of 0.2 per CPU took 0.39 of a core): without one, a process of the group is refused ``SCHED_FIFO``
(it warns and runs at nice -5). On cgroup v2 there is no
real-time runtime: a kernel without ``CONFIG_RT_GROUP_SCHED`` grants ``SCHED_FIFO`` there anyway; one with it refuses,
and the safety processes then run at nice -5 inside the quota. The quota's period is :data:`CFS_PERIOD_US` (20 ms):
a throttled group waits at most that long, not the kernel's default 100 ms, closer to a slower core's continuous
service. The group's CPU weight is ten times the default, so that it gets its F beside the machine's other work
(another user's processes share the CPU as equal groups otherwise). :meth:`Rig.usage` reports what the group took.

Busy loops (``busy_loops``): CPU-bound processes inside the rig, in a child group capped at one Pi core each (as
each takes one core of the Pi), each ending after ``busy_s`` (``timeout``).

A process joins the rig at its start, before it runs anything: :attr:`Rig.prefix` is a command to put before its
argv (a shell that writes its pid into the group, then ``exec``s it), so respawned processes join too. Needs root
(or a delegated writable cgroup); :class:`RigError` otherwise, in one line."""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["PI4_CORE_HERE", "PI4_FACTOR", "Rig", "RigError", "RigUsage", "find_cpu_controller", "main",
           "measured_factor"]

#: how many times slower a Raspberry Pi 4 core runs this stack than a core here (module docstring: its source)
PI4_FACTOR = 5.0
#: one Raspberry Pi 4 core, in cores of the development machine
PI4_CORE_HERE = 1 / PI4_FACTOR
#: the rows whose ratio, Pi over here, measures the factor (:func:`measured_factor`)
FACTOR_ROWS = ("launch_running_cpu_total", "launch_idle_cpu_total", "machine_nbody_cpu_s",
               "heartbeat_cycle_cpu_us_heartbeat")
#: the quota's period, us (module docstring)
CFS_PERIOD_US = 20_000
#: the kernel's least quota per period, us
MIN_QUOTA_US = 1_000
#: how often the quota follows the real-time processes' CPU, s
BALANCE_PERIOD_S = 0.1
#: the window of the real-time processes' CPU the quota subtracts, s
RT_WINDOW_S = 0.5
#: where the cpu controller is looked for: cgroup v1's hierarchy, then cgroup v2's (unified) mounts
V1_ROOT, V2_ROOTS = Path("/sys/fs/cgroup/cpu"), (Path("/sys/fs/cgroup/unified"), Path("/sys/fs/cgroup"))
#: the rig's child groups: the vehicle's processes, the busy loops (cgroup v2 allows processes only in leaves)
_CHILDREN = ("vehicle", "busy")
_CLOCK_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


class RigError(RuntimeError):
    """The rig cannot be set up here: one line naming what was tried."""


def find_cpu_controller(v1: Path = V1_ROOT, v2: tuple[Path, ...] = V2_ROOTS) -> tuple[int, Path]:
    """(1 or 2, the hierarchy's root) of the first writable cpu controller: cgroup v1's ``cpu`` hierarchy (a
    ``cpu.cfs_quota_us`` there), else a cgroup v2 mount whose ``cgroup.controllers`` lists ``cpu``. Raises
    :class:`RigError` when neither is writable."""
    if (v1 / "cpu.cfs_quota_us").is_file() and os.access(v1, os.W_OK):
        return 1, v1
    for root in v2:
        with contextlib.suppress(OSError):
            if "cpu" in (root / "cgroup.controllers").read_text().split() and os.access(root, os.W_OK):
                return 2, root
    raise RigError(f"rig: no writable cgroup cpu controller (v1 {v1}/cpu.cfs_quota_us, v2 "
                   f"{' or '.join(str(r / 'cgroup.controllers') for r in v2)} with cpu): run as root")


@dataclass(frozen=True)
class RigUsage:
    """What the rig's processes took since it started: cpu_s (CPU time, s; the busy loops excluded), busy_cpu_s
    (the busy loops'), wall_s, throttled_s (time the group's quota held it off a CPU, s) and throttled_periods."""

    cpu_s: float
    busy_cpu_s: float
    wall_s: float
    throttled_s: float
    throttled_periods: int

    @property
    def cores(self) -> float:
        """The rig's processes' CPU over wall time, in cores here."""
        return self.cpu_s / self.wall_s if self.wall_s > 0 else 0.0


class Rig:
    """A cgroup of ``cores`` cores here (module docstring). Use as a context manager; :attr:`prefix` starts a
    process inside it. ``busy_loops``: CPU-bound processes beside the vehicle's, each capped at one Pi core and
    ending after ``busy_s``. Raises ``ValueError`` for ``cores`` outside (0, cpu count] or a negative
    ``busy_loops``, :class:`RigError` without a writable cpu controller."""

    def __init__(self, cores: float, busy_loops: int = 0, busy_s: float = 3600.0, name: str | None = None) -> None:
        if not 0.0 < cores <= (os.cpu_count() or 1):
            raise ValueError(f"rig cores {cores!r}: allowed above 0, at most {os.cpu_count()} (this machine's CPUs)")
        if busy_loops < 0:
            raise ValueError(f"rig busy_loops {busy_loops!r}: allowed 0 or more")
        self.cores, self.busy_loops, self.busy_s = float(cores), int(busy_loops), float(busy_s)
        self.version, root = find_cpu_controller()
        self.path = root / (name or f"hindrax-rig-{os.getpid()}")
        acct = Path("/sys/fs/cgroup/cpuacct")  # v1: cpuacct beside cpu (or co-mounted with it)
        self.acct = self.path if self.version == 2 or (root / "cpuacct.usage").is_file() else acct / self.path.name
        self._busy: list[subprocess.Popen] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._balance, name="rig-balance", daemon=True)
        self._t0 = time.monotonic()
        self.quota_us = self._quota_us(0.0)
        self.busy_quota_us = int(self.busy_loops * PI4_CORE_HERE * CFS_PERIOD_US)  # one Pi core each
        #: the real-time runtime per CPU and period, us: F over the CPUs (the kernel lends a CPU's runtime to another)
        self.rt_runtime_us = int(min(self.cores, 0.9) / (os.cpu_count() or 1) * CFS_PERIOD_US)

    # -- life cycle ------------------------------------------------------------------------------
    def __enter__(self) -> Rig:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Create the group (and the busy loops' one), set its quota and real-time runtime, start the balancer and
        the busy loops. On :class:`RigError` (e.g. the parent's real-time runtime taken by another rig) nothing is
        left behind."""
        try:
            self._start()
        except RigError:
            self.close()
            raise

    def _start(self) -> None:
        for d in dict.fromkeys([self.path, self.acct] + [g / c for g in (self.path, self.acct) for c in _CHILDREN]):
            if self.version == 2:
                _write(d.parent / "cgroup.subtree_control", "+cpu")
            d.mkdir(exist_ok=True)
        # the rig gets its F whatever else the machine runs (a Pi of its own): weight x10 against the other groups
        _write(self.path / ("cpu.shares" if self.version == 1 else "cpu.weight"), 10240 if self.version == 1 else 1000)
        if self.version == 1:
            for d in (self.path, self.path / "busy"):
                _write(d / "cpu.cfs_period_us", CFS_PERIOD_US)
            if (self.path / "cpu.rt_runtime_us").is_file():  # the group, then the vehicle's within it
                for d in (self.path, self.path / "vehicle"):
                    _write(d / "cpu.rt_period_us", CFS_PERIOD_US)
                    _write(d / "cpu.rt_runtime_us", self.rt_runtime_us)
        self._set_quota(self.path, self.quota_us)
        if self.busy_loops:
            self._set_quota(self.path / "busy", min(self.quota_us, self.busy_quota_us))
        self._t0 = time.monotonic()
        self._start_usage = self._read_usage()
        self._thread.start()
        join = [*self._join_prefix(self.path / "busy"), "timeout", f"{self.busy_s:g}"]
        self._busy = [subprocess.Popen([*join, sys.executable, "-c", "while True: pass"])
                      for _ in range(self.busy_loops)]

    def close(self) -> None:
        """Stop the busy loops and the balancer; move what still runs in the group to the root; remove the group
        (idempotent)."""
        self._stop.set()
        for p in self._busy:
            p.terminate()  # timeout passes it on to its busy loop
            p.wait()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for d in [g / c for g in (self.path, self.acct) for c in _CHILDREN] + [self.path, self.acct]:
            root = self.path.parent if d.is_relative_to(self.path) else self.acct.parent
            with contextlib.suppress(OSError):
                for pid in (d / "cgroup.procs").read_text().split():
                    with contextlib.suppress(OSError, RigError):
                        _write(root / "cgroup.procs", pid)
                d.rmdir()

    # -- use ------------------------------------------------------------------------------------
    @property
    def prefix(self) -> list[str]:
        """The command to put before a process's argv: it joins the rig, then runs the rest (``exec``)."""
        return self._join_prefix(self.path / "vehicle")

    def _join_prefix(self, group: Path) -> list[str]:
        acct = self.acct / group.relative_to(self.path)
        dirs = [group] + ([acct] if acct != group else [])
        script = " && ".join(f"echo $$ > {shlex.quote(str(d / 'cgroup.procs'))}" for d in dirs)
        return ["/bin/sh", "-c", f'{script} && exec "$@"', "hindrax-rig"]

    def pids(self) -> list[int]:
        """The processes in the rig (the busy loops excluded)."""
        with contextlib.suppress(OSError):
            return [int(p) for p in (self.path / "vehicle" / "cgroup.procs").read_text().split()]
        return []

    def usage(self) -> RigUsage:
        """CPU taken and throttling since :meth:`start` (:class:`RigUsage`)."""
        now = self._read_usage()
        d = [b - a for a, b in zip(self._start_usage, now)]
        return RigUsage(cpu_s=d[0], busy_cpu_s=d[1], wall_s=time.monotonic() - self._t0, throttled_s=d[2],
                        throttled_periods=int(d[3]))

    # -- internals ------------------------------------------------------------------------------
    def _read_usage(self) -> tuple[float, float, float, float]:
        """(group CPU s, busy loops' CPU s, throttled s, throttled periods), cumulative."""
        def cpu_s(d: Path) -> float:
            if self.version == 1:
                return int((d / "cpuacct.usage").read_text()) * 1e-9
            return _stat(d)["usage_usec"] * 1e-6

        st = _stat(self.path)
        throttled = st.get("throttled_time", 0) * 1e-9 if self.version == 1 else st.get("throttled_usec", 0) * 1e-6
        return cpu_s(self.acct / "vehicle"), cpu_s(self.acct / "busy"), throttled, float(st.get("nr_throttled", 0))

    def _quota_us(self, rt_cores: float) -> int:
        return max(MIN_QUOTA_US, int((self.cores - rt_cores) * CFS_PERIOD_US))

    def _set_quota(self, group: Path, quota_us: int) -> None:
        if self.version == 1:
            _write(group / "cpu.cfs_quota_us", quota_us)
        else:
            _write(group / "cpu.max", f"{quota_us} {CFS_PERIOD_US}")

    def _balance(self) -> None:
        """Every :data:`BALANCE_PERIOD_S`: the quota is F less the real-time processes' CPU (module docstring)."""
        history: list[tuple[float, float]] = []
        while not self._stop.wait(BALANCE_PERIOD_S):
            now = time.monotonic()
            history = [h for h in history if now - h[0] <= RT_WINDOW_S] + [(now, _realtime_cpu_s(self.pids()))]
            (t0, c0), (t1, c1) = history[0], history[-1]
            rt = max(0.0, (c1 - c0) / (t1 - t0)) if t1 > t0 else 0.0  # a process that ended: its CPU is gone
            quota = self._quota_us(rt)
            if quota != self.quota_us:  # a child's quota may not exceed its parent's (v1): the lower one first
                steps = [(self.path, quota)] + ([(self.path / "busy", min(quota, self.busy_quota_us))]
                                                if self.busy_loops else [])
                with contextlib.suppress(RigError):
                    for group, q in (steps if quota > self.quota_us else steps[::-1]):
                        self._set_quota(group, q)
                    self.quota_us = quota


def _realtime_cpu_s(pids: list[int]) -> float:
    """CPU time (s) of the ``SCHED_FIFO``/``SCHED_RR`` processes among ``pids`` (proc(5): /proc/PID/stat fields 14,
    15 utime, stime in clock ticks; 41 policy)."""
    total = 0
    for pid in pids:
        with contextlib.suppress(OSError, ValueError, IndexError):
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[38]) in (os.SCHED_FIFO, os.SCHED_RR):
                total += int(fields[11]) + int(fields[12])
    return total * _CLOCK_TICK_S


def _stat(group: Path) -> dict[str, int]:
    with contextlib.suppress(OSError):
        return {k: int(v) for k, v in (ln.split() for ln in (group / "cpu.stat").read_text().splitlines())}
    return {}


def _write(path: Path, value: object) -> None:
    try:
        path.write_text(f"{value}\n")
    except OSError as exc:
        raise RigError(f"rig: cannot write {value!r} to {path}: {exc.strerror}") from None


def measured_factor(pi: dict, here: dict) -> dict[str, float]:
    """The Pi 4 factor measured (docs/pi_budget.md, the first Pi day): per row of :data:`FACTOR_ROWS` found in both,
    the Pi's value over this machine's (x). ``pi``, ``here``: ``results.json`` of ``python -m hindrax_tools.bench
    --only stack,heartbeats`` on each (``{"rows": [{"name", "value", ...}]}``). Raises ValueError when no row is in
    both."""
    values = [{r["name"]: r["value"] for r in doc["rows"]} for doc in (pi, here)]
    out = {n: values[0][n] / values[1][n] for n in FACTOR_ROWS if values[0].get(n) and values[1].get(n)}
    if not out:
        raise ValueError(f"no row of {', '.join(FACTOR_ROWS)} in both results")
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m hindrax_tools.benchmarks.rig --cores F [--busy-loops N] -- COMMAND...``: run a command (and the
    processes it starts) in a rig of F cores here; print the rig's CPU at its end. Exit status: the command's.
    ``--factor PI.json HERE.json``: print :func:`measured_factor` instead."""
    ap = argparse.ArgumentParser(prog="python -m hindrax_tools.benchmarks.rig", description=__doc__.splitlines()[0])
    ap.add_argument("--cores", type=float,
                    help=f"cores here (a Pi 4 core = {PI4_CORE_HERE:g}: half a Pi 0.4, the whole Pi 0.8)")
    ap.add_argument("--busy-loops", type=int, default=0, help="busy loops beside it, one Pi core each")
    ap.add_argument("--factor", nargs=2, type=Path, metavar=("PI_JSON", "HERE_JSON"),
                    help="the factor measured: results.json of the bench on the Pi and here")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args(argv)
    if args.factor:
        ratios = measured_factor(*(json.loads(p.read_text()) for p in args.factor))
        print("\n".join(f"{n}: {v:.2f}x (PI4_FACTOR today {PI4_FACTOR:g})" for n, v in ratios.items()))
        return 0
    if args.cores is None:
        ap.error("--cores is required")
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        ap.error("no command")
    try:
        with Rig(args.cores, busy_loops=args.busy_loops) as rig:
            code = subprocess.call([*rig.prefix, *command])
            u = rig.usage()
    except (RigError, ValueError) as exc:
        print(exc, file=sys.stderr)
        return 2
    print(f"rig {args.cores:g} cores: {u.cores:.3f} cores taken ({u.cpu_s:.1f} s CPU in {u.wall_s:.1f} s), throttled "
          f"{u.throttled_s:.1f} s in {u.throttled_periods} periods; busy loops {u.busy_cpu_s:.1f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
