"""Safety benchmark rows of the armed vehicle while other processes start and run beside it.

The vehicle's three safety processes (the ESC node, the supervisor and the output guard, each in its
own process on the shipped transport, :mod:`hindrax_common.process.dds_transport`, scheduled as
``vehicle.launch.xml`` starts them:
:func:`~hindrax_tools.benchmarks.safety.vehicle_scheduling`; the layout of
:func:`hindrax_tools.benchmarks.safety.running_layout`) are armed and commanded at 1700 us.
This process stands for the hardware (it serves the emulated PCA9685 and its /OE line) and watches
the heartbeats; hardware is never starved by a CPU load, so it takes ``SCHED_FIFO`` at
:data:`HARDWARE_STAND_IN_PRIORITY`, above the safety processes (:func:`hardware_priority`; without
the right to, the rows say so). Each run gives the rows of :meth:`_Watch.rows` (disarms, target 0;
heartbeat gaps as received, with a target, and between send stamps; tick gaps) under its prefix:

* ``participant_churn_*``: a new ROS 2 process starts every :data:`PERIOD_S` seconds for :data:`DURATION_S` seconds
  (alternately a 3 s subscriber to ``/diagnostics`` and the three heartbeats, as ``ros2 topic echo`` would, and
  ``hindrax health --quiet``), each exiting on its own. Fast DDS's shared-memory health check (Fast-DDS issue 6535) can
  stall a safety process on such a start; gap target :data:`GAP_TARGET_MS` (the heartbeat timeouts are 200 ms).
* ``busy_neighbours_*``: :data:`NEIGHBOURS` processes ``python3 -c 'while True: pass'``, in a session of their own (as
  another service or a terminal on the Pi), run for :data:`DURATION_S` seconds (:func:`cpu_bound_neighbours`; these rows
  are not measured without ``SCHED_FIFO``); ``busy_neighbours_nice_only_*``: the same with the real-time priority
  withheld (the launch file's nice -5 only), no target: what the priority buys here (docs/deployment.md §1).
* ``pool_day_churn_*``: the same processes with the gateway beside them
  (:func:`~hindrax_tools.benchmarks.sealed_authority.gateway_running`), commanded at 50 Hz beside :data:`NEIGHBOURS`
  CPU-bound processes; each of :data:`TRIALS` trials starts three processes together and waits for them to exit, as an
  operator and a curious user do on the pool day: a :data:`SUBSCRIBER_S` s subscriber to ``/diagnostics`` and the three
  heartbeats on the Pi's internal domain with Fast DDS's default transports
  (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, no profile: shared memory + UDP), one to the gateway's topside topics on
  the topside domain, and ``hindrax health --quiet`` on the internal domain (the Pi's shell); gap target
  :data:`POOL_DAY_GAP_TARGET_MS`."""
from __future__ import annotations

import os
import subprocess
import time
from contextlib import ExitStack, contextmanager
from typing import Iterator

from diagnostic_msgs.msg import DiagnosticArray
from domain_coordinator import domain_id
from hindrax_common.process.dds_transport import PROFILE_ENV, RANGE_ENV
from hindrax_common.node_support.liveness import HEARTBEAT_NAMES
from hindrax_common.process.scheduling import HARDWARE_STAND_IN_PRIORITY, set_every_thread
from hindrax_common.testing import child_process, python_executable, wait_until

from hindrax_msgs.msg import Heartbeat, ThrusterPwm

from . import run_alone
from .safety import _Layout, running_layout
from .sealed_authority import gateway_running

#: a new participant every PERIOD_S seconds, and how long the participants start or the neighbours
#: run (QUICK_DURATION_S with --quick), s; CPU-bound neighbours
PERIOD_S, DURATION_S, QUICK_DURATION_S, NEIGHBOURS = 2.0, 60.0, 20.0, 2
GAP_TARGET_MS = 100.0
#: pool-day trials (QUICK_TRIALS with --quick), each subscriber's life (s), its gap target (ms)
TRIALS, QUICK_TRIALS, SUBSCRIBER_S, POOL_DAY_GAP_TARGET_MS = 15, 3, 1.0, 150.0
#: how long one trial's three processes may take to exit under the load before the bench stops, s
TRIAL_TIMEOUT_S = 60.0

#: a subscriber process, as ``ros2 topic echo`` would be: ``-c _SUBSCRIBER NAME SECONDS MODULE:TYPE=TOPIC...``
_SUBSCRIBER = r"""
import importlib, sys, time
import rclpy
rclpy.init()
node = rclpy.create_node("churn_subscriber_" + sys.argv[1])
for spec in sys.argv[3:]:
    kind, topic = spec.split("=", 1)
    module, name = kind.split(":")
    node.create_subscription(getattr(importlib.import_module(module), name), topic, lambda m: None, 10)
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
node.destroy_node()
rclpy.shutdown()
"""
#: what a subscriber on the internal graph listens to: /diagnostics and the three safety heartbeats
INTERNAL_TOPICS = ("diagnostic_msgs.msg:DiagnosticArray=/diagnostics",
                   *(f"hindrax_msgs.msg:Heartbeat={topic}" for topic in HEARTBEAT_NAMES.values()))


def subscriber_argv(name: str, duration_s: float, topics: tuple[str, ...] = INTERNAL_TOPICS) -> list[str]:
    """The command of a subscriber process named ``churn_subscriber_<name>`` that listens to ``topics``
    (``module:Type=topic``) for ``duration_s`` s and exits."""
    return [python_executable(), "-c", _SUBSCRIBER, name, f"{duration_s:g}", *topics]


@contextmanager
def hardware_priority() -> Iterator[str]:
    """Every thread of this process (the emulated PCA9685 and /OE line, the probe) under ``SCHED_FIFO``
    :data:`HARDWARE_STAND_IN_PRIORITY` for the block, as the vehicle's hardware is never starved by a CPU load (the
    live pool takes the same, ``sim/live_pool.py``); with ``SCHED_RESET_ON_FORK``, so that the processes it starts do
    not inherit it. Yields '' or, when refused (not root, no ``RLIMIT_RTPRIO``), why."""
    try:
        set_every_thread(os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, HARDWARE_STAND_IN_PRIORITY)
    except OSError as exc:
        yield f"SCHED_FIFO not permitted here ({exc.strerror})"
        return
    try:
        yield ""
    finally:
        set_every_thread(os.SCHED_OTHER, 0)


class _VehicleLayout(_Layout):
    """The safety layout with the vehicle's scheduling: the three safety processes real-time, at nice -5 where that is
    refused, as ``vehicle.launch.xml`` starts them (:func:`~hindrax_tools.benchmarks.safety.vehicle_scheduling`),
    each in a session of its own as a launched process is."""

    new_session = True


class _NiceOnlyLayout(_VehicleLayout):
    """The vehicle layout with the real-time priority withheld: the launch file's nice -5 only."""

    realtime = False


class _Watch:
    """Arrival times and send stamps (the sender's steady clock, ``Heartbeat.steady_ns``) of the three heartbeats and
    the ESC's armed transitions, from subscriptions on ``node``."""

    def __init__(self, node) -> None:
        self.arrivals: dict[str, list[float]] = {name: [] for name in HEARTBEAT_NAMES}
        self.sent: dict[str, list[float]] = {name: [] for name in HEARTBEAT_NAMES}
        self.armed: bool | None = None
        self.disarms = 0
        self.active = False
        for name, topic in HEARTBEAT_NAMES.items():
            node.create_subscription(Heartbeat, topic, lambda m, n=name: self._beat(n, m), 50)
        node.create_subscription(ThrusterPwm, "thrusters/pulse_width", self._state, 50)
        #: status name -> the worst tick gap it reported on /diagnostics, (gap, thread CPU, process CPU) in ms
        self.tick_gaps: dict[str, tuple[float, float, float]] = {}
        #: status name -> heartbeats its process took at a stale judgement (liveness.HeartbeatWatch.fresh)
        self.taken_late: dict[str, int] = {}
        self._active_since: float | None = None
        node.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostics, 50)

    def _diagnostics(self, msg) -> None:
        now = time.monotonic()
        if not self.active:
            self._active_since = None
            return
        if self._active_since is None:
            self._active_since = now
        if now - self._active_since < 1.1:  # a 1 Hz report may cover time before the window (the arming)
            return
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "heartbeats_taken_late" in values:  # a counter: its last report
                self.taken_late[status.name] = int(values["heartbeats_taken_late"])
            if "tick_gap_max_ms" in values:
                gap = tuple(float(values[k]) for k in ("tick_gap_max_ms", "tick_gap_thread_cpu_ms",
                                                       "tick_gap_process_cpu_ms"))
                if gap[0] > self.tick_gaps.get(status.name, (-1.0,))[0]:
                    self.tick_gaps[status.name] = gap

    def tick_gap_row(self, name: str) -> dict:
        """Row ``name``: the longest tick gap a safety process reported (TickGaps), with its CPU split."""
        if not self.tick_gaps:
            return {"name": name, "value": None, "unit": "ms", "note": "no tick gap reported on /diagnostics"}
        worst = max(v[0] for v in self.tick_gaps.values())
        each = "; ".join(f"{k} {g:.0f} ms ({t:.1f} / {p:.1f})" for k, (g, t, p) in sorted(self.tick_gaps.items()))
        return {"name": name, "value": worst, "unit": "ms",
                "note": f"longest gap between two steady ticks of a safety process (reports covering the window only), "
                        f"each with the CPU time in it (its executor thread / the whole process, ms): {each}; "
                        f"heartbeats taken at a stale judgement: {self.taken_late or 'none reported'}"}

    def _beat(self, name: str, msg) -> None:
        if self.active:
            self.arrivals[name].append(time.monotonic())
            self.sent[name].append(msg.steady_ns * 1e-9)

    def _state(self, msg) -> None:
        if self.active and self.armed and not msg.armed:
            self.disarms += 1
        self.armed = bool(msg.armed)

    def gaps_s(self, sent: bool = False) -> dict[str, float]:
        """Heartbeat name -> the largest gap between two of its consecutive beats (inf with fewer than two), s;
        ``sent``: between their send stamps (the sender late) instead of their arrivals here."""
        return {name: max((b - a for a, b in zip(times, times[1:])), default=float("inf"))
                for name, times in (self.sent if sent else self.arrivals).items()}

    def start(self) -> None:
        """Count from here on: the vehicle is armed, no disarm seen yet."""
        self.armed, self.disarms, self.active = True, 0, True

    def rows(self, prefix: str, what: str, target_ms: float, n: int | None = None) -> list[dict]:
        """Rows ``<prefix>disarms`` (target 0, note ``what``; ``n``: the trials), ``<prefix>heartbeat_gap_max_ms``
        (target ``target_ms``), ``<prefix>heartbeat_sent_gap_max_ms`` and ``<prefix>tick_gap_max_ms``."""
        beats = sum(len(v) for v in self.arrivals.values())
        rows = [{"name": prefix + "disarms", "value": self.disarms, "unit": "disarms", "target": 0,
                 **({} if n is None else {"n": n}), "note": what}]
        for sent, name, note in (
                (False, "heartbeat_gap_max_ms",
                 f"largest gap between two received beats of one heartbeat, over {beats} beats"),
                (True, "heartbeat_sent_gap_max_ms",
                 "the same between the beats' send stamps (the sender late, not the delivery)")):
            gaps = self.gaps_s(sent)
            each = ", ".join(f"{k} {v * 1e3:.0f}" for k, v in gaps.items())
            rows.append({"name": prefix + name, "value": max(gaps.values()) * 1e3, "unit": "ms",
                         **({} if sent else {"target": target_ms}), "n": beats,
                         "note": f"{note}; each (ms): {each}"})
        return rows + [self.tick_gap_row(prefix + "tick_gap_max_ms")]


def churn_rows(quick: bool = False) -> list[dict]:
    """The ``participant_churn_*`` rows (module docstring)."""
    duration_s = QUICK_DURATION_S if quick else DURATION_S
    with running_layout("hindrax-bench-churn-", layout=_VehicleLayout) as lay:
        watch = _Watch(lay.probe)
        started: list[subprocess.Popen] = []
        with ExitStack() as stack:  # every process started is killed if still running at the end
            lay.armed_at_1700()
            with hardware_priority() as refused:
                watch.start()
                t0 = time.monotonic()
                k = 0
                while time.monotonic() - t0 < duration_s:
                    if k % 2 == 0:
                        argv = subscriber_argv(str(k), 3.0)
                    else:
                        argv = [python_executable(), "-m", "hindrax_tools.cli", "health", "--quiet", "--timeout", "3"]
                    started.append(stack.enter_context(child_process(
                        argv, env=lay.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)))
                    k += 1
                    next_start = t0 + k * PERIOD_S
                    wait_until(lambda: time.monotonic() >= next_start, PERIOD_S + 5.0, lambda: time.sleep(0.02),
                               "next participant's start")
                watch.active = False
            for p in started:
                p.wait(60)
    what = (f"{k} ROS 2 processes started every {PERIOD_S:g} s for {duration_s:g} s (a 3 s subscriber and "
            f"`hindrax health` alternately) while armed at 1700 us; safety processes on the UDP loopback transport; "
            f"emulated hardware {'not real-time: ' + refused if refused else 'real-time, above them'}")
    return watch.rows("participant_churn_", what, GAP_TARGET_MS, n=k)


@contextmanager
def cpu_bound_neighbours(n: int = NEIGHBOURS) -> Iterator[list[subprocess.Popen]]:
    """``n`` processes ``python3 -c 'while True: pass'`` at normal priority, each in a session of its own (another
    service or a terminal on the Pi), for the block; killed on the way out. Raises RuntimeError if one inherited this
    process's real-time priority (it would starve the vehicle's processes, not stand beside them)."""
    with ExitStack() as stack:
        neighbours = [stack.enter_context(child_process(
            [python_executable(), "-c", "while True: pass"], start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)) for _ in range(n)]
        if any(os.sched_getscheduler(p.pid) != os.SCHED_OTHER for p in neighbours):
            raise RuntimeError("a CPU-bound neighbour inherited this process's real-time priority")
        yield neighbours


def busy_rows(quick: bool = False, realtime: bool = True) -> list[dict]:
    """The ``busy_neighbours_*`` rows (module docstring); ``realtime`` False: the nice-only run."""
    duration_s = QUICK_DURATION_S if quick else DURATION_S
    prefix = "busy_neighbours_" if realtime else "busy_neighbours_nice_only_"
    layout = _VehicleLayout if realtime else _NiceOnlyLayout
    with running_layout("hindrax-bench-busy-", layout=layout) as lay:
        watch = _Watch(lay.probe)
        lay.armed_at_1700()
        # real-time from here on: every thread of this process, the emulation's serving threads included (one per node
        # process, started when it connected: a thread started under SCHED_RESET_ON_FORK would not be)
        with hardware_priority() as refused:
            if refused:  # the same rows, not measured
                return [{**r, "value": None, "note": f"not measured: {refused}"}
                        for r in watch.rows(prefix, "", GAP_TARGET_MS)]
            watch.start()
            with cpu_bound_neighbours(NEIGHBOURS):
                # the measurement window itself (the probe spins in the layout's thread)
                time.sleep(duration_s)
            watch.active = False
            load = os.getloadavg()[0]
    what = (f"armed at 1700 us for {duration_s:g} s beside {NEIGHBOURS} CPU-bound processes of "
            f"another session (1-minute load {load:.1f} at the end); safety processes "
            + ("real-time as vehicle.launch.xml starts them" if realtime else "at nice -5 only"))
    rows = watch.rows(prefix, what, GAP_TARGET_MS)
    return rows if realtime else [{k: v for k, v in r.items() if k != "target"} for r in rows]


def topside_topics(vehicle: str) -> tuple[str, ...]:
    """What the topside subscriber listens to (``module:Type=topic``): the gateway's status topics and odometry."""
    return (f"diagnostic_msgs.msg:DiagnosticStatus=/{vehicle}/supervisor/status",
            f"diagnostic_msgs.msg:DiagnosticStatus=/{vehicle}/gateway/status", f"nav_msgs.msg:Odometry=/{vehicle}/odom")


def pool_day_rows(quick: bool = False) -> list[dict]:
    """The ``pool_day_churn_*`` rows (module docstring); ``quick``: :data:`QUICK_TRIALS` trials."""
    trials = QUICK_TRIALS if quick else TRIALS
    exits: list[int] = []
    with running_layout("hindrax-bench-poolday-", layout=_VehicleLayout) as lay, domain_id() as topside:
        watch = _Watch(lay.probe)
        lay.ensure()
        internal_default = {k: v for k, v in lay.env.items() if k != PROFILE_ENV} | {RANGE_ENV: "LOCALHOST"}
        topside_env = internal_default | {"ROS_DOMAIN_ID": str(topside)}
        health = [lay.py, "-m", "hindrax_tools.cli", "health", "--quiet", "--timeout", "3"]
        topics = topside_topics(lay.vehicle)
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        with gateway_running(lay, topside):
            lay.armed_at_1700()
            with hardware_priority() as refused, cpu_bound_neighbours(NEIGHBOURS):
                watch.start()
                for k in range(trials):
                    specs = ((subscriber_argv(f"internal_{k}", SUBSCRIBER_S), internal_default),
                             (subscriber_argv(f"topside_{k}", SUBSCRIBER_S, topics), topside_env), (health, lay.env))
                    with ExitStack() as stack:
                        procs = [stack.enter_context(child_process(argv, env=env, **quiet)) for argv, env in specs]
                        exits += [p.wait(TRIAL_TIMEOUT_S) for p in procs]
                watch.active = False
                load = os.getloadavg()[0]
    hardware = "not real-time: " + refused if refused else "real-time, above them"
    what = (f"{trials} trials, each a {SUBSCRIBER_S:g} s subscriber on the internal domain with default transports, "
            f"one on the topside and `hindrax health` started together (exit codes {sorted(set(exits))}), armed and "
            f"commanded at 1700 us, 50 Hz, beside {NEIGHBOURS} CPU-bound processes (1-minute load {load:.1f} at the "
            f"end); emulated hardware {hardware}")
    return watch.rows("pool_day_churn_", what, POOL_DAY_GAP_TARGET_MS, n=trials)


def run(quick: bool = False) -> list[dict]:
    """This module's rows of the ``safety`` section (``make bench``,
    :mod:`hindrax_tools.bench`), in the order of the module docstring."""
    return churn_rows(quick) + busy_rows(quick) + busy_rows(quick, realtime=False) + pool_day_rows(quick)


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
