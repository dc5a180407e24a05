"""Stack benchmark: the Pi budget. CPU of every node and of the whole vehicle graph, in one process and in the launch
layout, messages per second per topic, and the cost of a skeleton sending the same topics at the same rates.

CPU is process (or thread) CPU time over wall time. It still grows with the load of a shared machine (by 20-40 %
between a quiet and a loaded run here), so compare layouts in runs close in time, and repeat.

The graph: the sensor drivers, the ESC, the allocation, the identification node, the supervisor and the recorder
(every topic except ``sim/*`` and ``/clock``), devices emulated and excluded from the stack's CPU. Two phases of
``duration_s`` each: ``running`` (the identification node runs a surge goal) and ``idle`` (goal cancelled, a 50 Hz
``wrench`` stream from the benchmark).

``inproc``: the graph of ``hindrax run`` (:func:`hindrax_sim.graph.bringup.build_graph`, ``drive_clocks``) in one
executor; per node the CPU of its callbacks less the emulators' time in them, plus its own threads; the rest is
``executor+dds``. ``launch``: the processes of :data:`LAUNCH_FILE` (:func:`.launch_layout.launch_processes`), the
virtual pool in another process; CPU per process from ``/proc/<pid>/stat``; the running phase in :data:`RUNNING_WINDOWS`
windows, each row their median. Rates and the IMU's timing (:func:`imu_timing`) come from the launch layout's bag.

Machine speed: n-body CPU before and after (:mod:`.machine`); the launch totals are also given at the reference
machine's speed, per unit of the virtual pool's CPU and at :data:`REFERENCE_POOL_CPU`. Wake-ups per process and the
DDS threads' CPU; :data:`PARTICIPANT_PROBES` give what one more process costs. ``--baseline GIT_REF`` measures that
commit's launch layout first (:func:`baseline_launch`, rows ``..._vs_baseline``). ``--rig-cores F`` (``make rig``):
the launch layout alone in a Pi-sized CPU rig of F cores here (:func:`rig_rows`,
:mod:`hindrax_tools.benchmarks.rig`), rows ``rig_*``.

Skeletons (:func:`_skeleton`, run by :func:`.launch_node.skeleton_main`): the launch's processes with the same endpoints
(read back by SIGUSR1, :func:`read_topologies`, and checked equal), launch-prefix and environment, each topic at the
launch's rate with a recorded message, callbacks doing nothing: the floor of moving the vehicle's messages
(``launch_skeleton_*``, ``launch_*_vs_skeleton_ratio_*``). ``cpu_bare_rclpy_same_topics`` is one publisher process for
the one-process idle phase's topics."""
from __future__ import annotations

import argparse
import collections
import functools
import json
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import rclpy
from domain_coordinator import domain_id
from geometry_msgs.msg import Vector3, Wrench, WrenchStamped
from rclpy.action import ActionClient
from rclpy.executors import ShutdownException, TimeoutException
from std_msgs.msg import Header

from hindrax_common.node_support.action_goal import GoalSender
from hindrax_common.config import default_config_path
from hindrax_bringup.layout.launch_xml import write_parameter_file
from hindrax_common.cdr.lean_cdr import cdr_decoder, type_name_of
from hindrax_common.node_support.liveness import heartbeat_qos
from hindrax_bringup.recording.reader import BagReader
from hindrax_bringup.recording.selection import TopicSelection
from hindrax_tools import results_doc
from hindrax_tools.benchmarks.rig import PI4_CORE_HERE, PI4_FACTOR, Rig
from hindrax_common.testing import (ConditionTimeout, GraphSettled, child_env, python_executable, ros_context,
                                     wait_until)
from hindrax_common.transport.socket_i2c import SOCKET_ENV
from hindrax_sim.graph.bringup import build_graph
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import AllocationStatus, Heartbeat, ThrusterPwm
from hindrax_msgs.srv import SetArmed

from .launch_layout import launch_processes, package_share, read_ports_file
from .actuation import wrench_to_registers
from .launch_node import TOPOLOGY_ENV
from . import call, probe_spinning, spin_for, start_logged, stop_processes
from .machine import REFERENCE_NBODY_CPU_S, nbody_cpu_s, proc_cpu_s, thread_cpu_s
from .recorder import subscribe_recorder_counts

#: not recorded in either layout: the simulator's ground truth and /clock (they do not exist on the vehicle)
EXCLUDE_REGEX = r"^/(sim/|clock$)"
#: the processes / nodes of the stack, in launch order
NODES = ("dvl75", "ping1d", "ms5837", "icm20948", "esc", "thrust_allocation", "identification", "supervisor",
         "recorder")
WRENCH_RATE_HZ = 50.0
#: the ICM-20948's topic, whose rate and gaps the running phase reports (:func:`imu_timing`)
IMU_TOPIC = "/imu/data_raw"
#: the launch layout is armed once its ROS graph has not changed for this long (s): the publish stalls of a new
#: participant's first messages came 0-3.0 s after it appeared (hindrax_common.testing.GraphSettled)
GRAPH_QUIET_S = 5.0


def _proc_wakeups(pid: int) -> tuple[int, int, dict[str, int], dict[str, float]]:
    """(every thread's, the main thread's, by thread name) voluntary context switches of a process so far, and the
    CPU seconds by thread name: each switch is a sleep that ends in a wake-up (a timer, a message, a reply on a
    socket). Threads that ended before the call are not counted; threads of one name (Fast DDS's ``dds.udp.*``
    receivers ...) are summed."""
    total = main = 0
    named: dict[str, int] = collections.defaultdict(int)
    cpu: dict[str, float] = collections.defaultdict(float)
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            text = (task / "status").read_text()
            thread_cpu = proc_cpu_s(f"{pid}/task/{task.name}")
        except OSError:  # the thread ended meanwhile
            continue
        fields = dict(ln.split(":", 1) for ln in text.splitlines() if ":" in ln)
        n = int(fields["voluntary_ctxt_switches"])
        total += n
        main += n if task.name == str(pid) else 0
        name = "main" if task.name == str(pid) else fields["Name"].strip()
        named[name] += n
        cpu[name] += thread_cpu
    return total, main, named, cpu


def _wakeup_rates(before: tuple, after: tuple, wall_s: float) -> tuple[float, float, dict[str, float],
                                                                        dict[str, float]]:
    """Wake-ups per second between two :func:`_proc_wakeups` readings (total, main thread, by thread name), and the
    CPU by thread name over the same interval, fraction of a core."""
    return ((after[0] - before[0]) / wall_s, (after[1] - before[1]) / wall_s,
            {k: (v - before[2].get(k, 0)) / wall_s for k, v in after[2].items()},
            {k: (v - before[3].get(k, 0.0)) / wall_s for k, v in after[3].items()})


def _proc_mb(pid: int, key: str) -> float:
    """A memory figure of a process, MB (10^6 bytes), NaN when absent: ``VmRSS`` (resident set size, from
    /proc/PID/status) or ``Pss`` (proportional set size, /proc/PID/smaps_rollup: its private pages plus its share of the
    pages it shares, the venv's libraries mapped by every node process, so the sum over processes is the memory they
    hold together, unlike the sum of RSS, which counts shared pages once per process)."""
    path = Path(f"/proc/{pid}/{'status' if key == 'VmRSS' else 'smaps_rollup'}")
    for line in path.read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024 / 1e6
    return float("nan")


def _wrench_msg(stamp: Any) -> Any:
    return WrenchStamped(header=Header(frame_id="base_link", stamp=stamp),
                         wrench=Wrench(force=Vector3(x=6.0), torque=Vector3(z=0.5)))


def _wrench_stream(probe: Any) -> Callable[[bool], None]:
    """The pilot's 50 Hz wrench stream from ``probe``, off until switched on (the returned ``switch(on)``): its timer
    runs only while it is on, so the bench wakes no 50 Hz timer in the running phase."""
    wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
    timer = probe.create_timer(1.0 / WRENCH_RATE_HZ, lambda: wrench.publish(
        _wrench_msg(probe.get_clock().now().to_msg())), autostart=False)
    return lambda on: timer.reset() if on else timer.cancel()


def _running_then_idle(probe: Any, action: Any, switch: Callable[[bool], None], window: Any,
                       spin: Any, spin_idle: Any, what: str) -> None:
    """The measured sequence of both layouts: the surge goal (sent through
    :class:`~hindrax_common.node_support.action_goal.GoalSender`, which survives a lost goal or cancel response), 3
    s of warm-up, the "running" window, cancel, 2 s of warm-up with the pilot's wrench stream on, the "idle" window.

    switch(on) switches the wrench stream; window(label) measures one window; spin / spin_idle: one executor spin
    while running / while idle. Raises RuntimeError when the goal is rejected, or when it ended before the running
    window did (the window would not have measured a running campaign)."""
    goals = GoalSender(probe, action, "run_identification")
    switch(False)
    handle = goals.send(RunIdentification.Goal(dofs=["surge"], levels_per_dof=3), spin, 30)
    if not handle.accepted:
        raise RuntimeError(f"{what}: the surge goal was rejected")
    spin_for(3.0, spin)
    window("running")
    if goals.status(handle) in (4, 5, 6):  # SUCCEEDED, CANCELED, ABORTED: the campaign did not run throughout
        got: list = []
        try:  # the node's reason, for the error
            wait_until(lambda: got.append(goals.poll_result(handle)) or got[-1] is not None, 10, spin, "goal result")
            why = getattr(got[-1].result, "message", "")
        except Exception:  # noqa: BLE001 - the reason is a courtesy; the error below is what matters
            why = "(no result received)"
        raise RuntimeError(f"{what}: the surge goal ended (status {goals.status(handle)}) during the running "
                           f"window: {why}")
    wait_until(lambda: goals.cancel(handle), 30, spin, "goal cancel")
    switch(True)
    spin_for(2.0, spin_idle)
    window("idle")
    goals.destroy()


# ---------------------------------------------------------------------------------------------- one process
def _timed(fn: Callable, spent: dict[str, float], key: Callable[[], str]) -> Callable:
    """``fn``, each call's thread CPU time added to ``spent[key()]``."""
    def timed(*a: Any) -> Any:
        t0 = time.thread_time()
        try:
            return fn(*a)
        finally:
            spent[key()] += time.thread_time() - t0
    return timed


def _in_process(duration_s: float, tmp: Path) -> dict:
    cpu: dict[str, float] = collections.defaultdict(float)  # callbacks by node name
    # emulator time inside callbacks by node name, and the simulator's time under "(simulator)"
    emu: dict[str, float] = collections.defaultdict(float)
    current: list[str | None] = [None]
    out: dict = {"phases": {}}
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, record=True, record_dir=str(tmp / "unused-bag"),
                            context=ctx, overrides={"esc.arming_time_s": 1.0}, real_time_factor=1.0,
                            identification=True, drive_clocks=True)
        ex = graph.executor
        hw = graph.hardware
        names = {id(n): name for name, n in graph.nodes.items()}

        def spin_once(timeout_sec: float | None = None) -> bool:
            """Run one ready callback (waiting up to ``timeout_sec``), its thread CPU counted to
            its node; False when none came."""
            try:
                handler, _entity, node = ex.wait_for_ready_callbacks(timeout_sec=timeout_sec)
            except (TimeoutException, ShutdownException):
                return False
            name = names.get(id(node), node.get_name() if node is not None else "(executor)")
            current[0] = name
            t0 = time.thread_time()
            handler()
            cpu[name] += time.thread_time() - t0
            current[0] = None
            if handler.exception() is not None:
                raise handler.exception()
            return True

        def spin_until_idle() -> None:  # as Graph.spin_until_idle, through spin_once
            for _ in range(100_000):
                if not spin_once(0.0):
                    return

        graph.spin_until_idle = spin_until_idle
        ex.spin_once = spin_once
        sim_node = graph.nodes["simulator"]
        advance = sim_node.advance_clock_period
        sim_node.advance_clock_period = _timed(advance, emu, lambda: "(simulator)")
        for device in (hw.emulators[n] for n in ("ms5837", "icm20948", "pca9685")):
            for meth in ("i2c_read", "i2c_write"):
                setattr(device, meth, _timed(getattr(device, meth), emu, lambda: current[0] or "(outside callbacks)"))

        recorder = graph.nodes["recorder"]
        recorder.stop_recording()
        selection = TopicSelection(all_topics=True, exclude_regex=EXCLUDE_REGEX)
        recorder.start_recording(str(tmp / "inproc-bag"), selection)

        def startup_complete() -> bool:
            if not hw.serial_startup_done():
                return False
            recorder.discover_now()
            wanted = {pub.topic_name for name, n in graph.nodes.items() if name != "recorder"
                      for pub in n.publishers if selection.matches(pub.topic_name)}
            return recorder.subscribed_to(wanted)

        graph.startup_complete = startup_complete
        probe = rclpy.create_node("bench_probe", context=ctx)
        ex.add_node(probe)
        names[id(probe)] = "bench_probe"
        wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        action = ActionClient(probe, RunIdentification, "run_identification")
        spin = lambda: graph.spin_once(0.01)  # noqa: E731
        graph.start_and_arm(arm, 120, ready=action.server_is_ready)
        alloc_clock = graph.nodes["thrust_allocation"].get_clock()
        stream = {"on": False, "next": time.monotonic()}

        def spin_with_wrench() -> None:
            now = time.monotonic()
            if stream["on"] and now >= stream["next"]:
                stream["next"] = max(stream["next"] + 1.0 / WRENCH_RATE_HZ, now - 0.1)
                wrench.publish(_wrench_msg(alloc_clock.now().to_msg()))
            spin()

        def window(phase: str) -> None:
            writer = recorder._writer
            counts0 = writer.topic_counts()
            cpu.clear()
            emu.clear()
            threads0 = thread_cpu_s()
            sim_t0 = sim_node.simulator.t_s
            proc, wall = spin_for(duration_s, spin_with_wrench)
            threads1 = thread_cpu_s()
            counts1 = writer.topic_counts()
            thr = {k: threads1.get(k, 0.0) - threads0.get(k, 0.0) for k in threads1}
            per = {name: cpu.get(name, 0.0) - emu.get(name, 0.0) for name in NODES if name in graph.nodes}
            for name, port in hw.ports.items():
                per[name] += thr.get(f"SerialTransport({port})", 0.0)
            per["recorder"] += sum(v for k, v in thr.items() if k.startswith("bag-writer"))
            stack = proc - sum(emu.values()) - cpu.get("bench_probe", 0.0)
            per["executor+dds"] = stack - sum(per.values())
            rates = {t: (counts1.get(t, 0) - counts0.get(t, 0)) / wall for t in counts1}
            out["phases"][phase] = {"per_node": {k: v / wall for k, v in per.items()},
                                    "stack": stack / wall, "rates": rates,
                                    "sim_rtf": (sim_node.simulator.t_s - sim_t0) / wall}

        _running_then_idle(probe, action, lambda on: stream.update(on=on), window, spin, spin_with_wrench, "in-process")
        out["types"] = {pub.topic_name: type_name_of(pub.msg_type) for n in graph.nodes.values()
                        for pub in n.publishers}
        out["dropped"] = recorder._writer.dropped
        graph.shutdown()
        probe.destroy_node()
    return out


# ---------------------------------------------------------------------------------------------- launch layout
def _launch(duration_s: float, tmp: Path, windows: int = 1, rig: Rig | None = None, tally: dict | None = None) -> dict:
    """The launch layout: every process of :data:`LAUNCH_FILE` (recording on), the virtual pool in
    another. ``windows`` consecutive windows of ``duration_s`` in the running phase (one in the idle
    phase); per window the CPU of every process and its wall-clock span (the rates come from the
    bag). ``rig``: the launch's processes start inside it (:mod:`hindrax_tools.benchmarks.rig`), the pool outside.
    ``tally``: filled as it runs (:func:`rig_rows`): ``disarms`` after the first arming, ``stale`` allocation
    statuses rejecting a stale wrench, per window the rig's ``(phase, RigUsage)`` in ``rig``."""
    py = python_executable()
    sock = str(tmp / "i2c.sock")
    ports_file = tmp / "ports.json"
    bag_root = tmp / "launch-bags"  # the launch files' output_dir: the root the recorder makes its bag beneath
    launch_file = package_share(LAUNCH_FILE[0]) / LAUNCH_FILE[1]
    layout = launch_processes(launch_file, {"output_dir": str(bag_root)})
    procs: dict[str, subprocess.Popen] = {}
    extra: dict[str, subprocess.Popen] = {}  # the participant probes (PARTICIPANT_PROBES)
    out: dict = {"phases": {}, "launch_file": str(launch_file),
                 "processes": {lp.label: {"prefix": list(lp.process.launch_prefix),
                                          "env": dict(lp.process.env)} for lp in layout}}
    with domain_id() as did:
        env = child_env(ROS_DOMAIN_ID=str(did))
        try:
            pool = ["-m", "hindrax_tools.benchmarks.launch_layout", "pool", "--socket", sock,
                    "--ports-file", str(ports_file)]
            procs["pool"] = start_logged(tmp / "pool.log", [py, *pool], env=env)
            ports = wait_until(lambda: _check_alive({"pool": procs["pool"]}, tmp) and read_ports_file(ports_file), 60,
                               None, "pool process ready")
            # the bench's devices: the serial emulators' pseudo-terminals, a short arming time, and the emulated
            # PCA9685's oscillator, exactly nominal: calibrated (the ESC refuses to arm otherwise). Vehicle keys,
            # so every process may get them: a node ignores the keys it does not declare.
            bench = ["-p", f"sensors.dvl75.port:={ports['dvl75']}", "-p", f"sensors.ping1d.port:={ports['ping1d']}",
                     "-p", "esc.arming_time_s:=1.0", "-p", "esc.oscillator_calibrated:=true"]
            wrap = ["-m", "hindrax_tools.benchmarks.launch_node"]  # no simulator here
            (tmp / "params").mkdir(exist_ok=True)
            values_file = functools.partial(write_parameter_file, directory=tmp / "params")
            for lp in layout:
                if lp.label in procs:
                    raise RuntimeError(f"{launch_file.name}: two processes named {lp.label}")
                # the launch file's launch-prefix and environment too (the safety processes' real-time priority,
                # docs/deployment.md §1; the DDS transport, hindrax_common.process.dds_transport)
                argv = [*lp.process.launch_prefix, *(rig.prefix if rig else ()), py, *wrap, lp.module,
                        *lp.process.ros_arguments(values_file), *bench]
                own = {**dict(lp.process.env), SOCKET_ENV: sock, TOPOLOGY_ENV: str(tmp)}
                procs[lp.label] = start_logged(tmp / f"{lp.label}.log", argv, env={**env, **own})
            (tmp / "probes.json").write_text(json.dumps({"processes": {  # no publishers
                name: _one_node(name, [], [_endpoint(t, ty, raw=True) for t, ty in topics])
                for name, topics in PARTICIPANT_PROBES.items()}}))
            for name in PARTICIPANT_PROBES:  # what one more process costs (not in the totals)
                argv = _skeleton_argv(tmp / "probes.json", name)
                extra[name] = start_logged(tmp / f"{name}.log", argv, env=env)
            with probe_spinning(did) as (probe, _ex, spin):
                counts, lock = subscribe_recorder_counts(probe, 50)
                if tally is not None:
                    _tally(probe, tally)
                arm = probe.create_client(SetArmed, "esc/set_armed")
                action = ActionClient(probe, RunIdentification, "run_identification")
                switch = _wrench_stream(probe)

                alive = functools.partial(_check_alive, procs, tmp)
                sensors = ("/dvl/data", "/imu/data_raw", "/pressure/fluid_pressure", "/ping/altitude")
                wait_until(lambda: alive() and all(counts.get(t, 0) > 5 for t in sensors), 120, spin,
                           "every sensor topic recorded")
                wait_until(lambda: alive() and arm.service_is_ready() and action.server_is_ready(), 60, spin,
                           "esc/set_armed and run_identification")
                # arm only once discovery has settled: a process's first message to a new participant can stall its
                # publishes 0.33 s (Fast DDS's shared-memory port health check, GraphSettled), which silences a
                # safety heartbeat past its 0.2 s timeout and disarms the ESC before or during the running window
                settled = GraphSettled(probe, quiet_s=GRAPH_QUIET_S, min_nodes=len(layout))
                wait_until(lambda: alive() and settled(), 120, spin, "the ROS graph unchanged for "
                                                                       f"{GRAPH_QUIET_S:g} s")

                answer = [""]

                def try_arm() -> bool:
                    res = call(arm, SetArmed.Request(arm=True), spin)
                    answer[0] = res.message
                    return res.armed

                try:
                    wait_until(try_arm, 30, spin, "armed")
                except ConditionTimeout as exc:
                    raise ConditionTimeout(f"{exc}: the ESC's last answer was {answer[0]!r}") from None
                print(f"stack benchmark, launch layout ({len(layout)} processes of {launch_file.name}): "
                      f"{answer[0]}", flush=True)
                spin_for(3.0, spin)

                def window(phase: str) -> None:
                    alive()
                    results = []
                    for _ in range(windows if phase == "running" else 1):
                        cpu0 = {n: proc_cpu_s(p.pid) for n, p in {**procs, **extra}.items()}
                        wake0 = {n: _proc_wakeups(p.pid) for n, p in {**procs, **extra}.items()}
                        load0, t0_ns = os.getloadavg()[0], time.time_ns()
                        rig0 = rig.usage() if rig else None
                        bench, wall = spin_for(duration_s, spin)
                        if rig and tally is not None:
                            tally["rig"].append((phase, rig0, rig.usage()))
                        cpu1 = {n: proc_cpu_s(p.pid) for n, p in {**procs, **extra}.items()}
                        wake1 = {n: _proc_wakeups(p.pid) for n, p in {**procs, **extra}.items()}
                        t1_ns = time.time_ns()
                        alive()
                        nodes = [(n, p) for n, p in procs.items() if n != "pool"]
                        results.append({"wall_s": wall, "t0_ns": t0_ns, "t1_ns": t1_ns,
                                        "per_process": {n: (cpu1[n] - cpu0[n]) / wall for n in procs if n != "pool"},
                                        "pool": (cpu1["pool"] - cpu0["pool"]) / wall,
                                        "wakeups": {n: _wakeup_rates(wake0[n], wake1[n], wall)
                                                    for n in procs if n != "pool"},
                                        "participants": {n: ((cpu1[n] - cpu0[n]) / wall,
                                                             (wake1[n][0] - wake0[n][0]) / wall) for n in extra},
                                        "bench": bench / wall,
                                        "loadavg": 0.5 * (load0 + os.getloadavg()[0]),
                                        "rss_mb": {n: _proc_mb(p.pid, "VmRSS") for n, p in nodes},
                                        "pss_mb": {n: _proc_mb(p.pid, "Pss") for n, p in nodes}})
                    out["phases"][phase] = {"windows": results}

                try:
                    _running_then_idle(probe, action, switch, window, spin, spin, "launch layout")
                except RuntimeError as exc:  # what the safety chain said (a disarm, a trip, a stale heartbeat)
                    raise RuntimeError(f"{exc}\n{_safety_log_lines(tmp, list(procs))}") from exc
                # each node's declared endpoints, recorder subscriptions made: the skeleton's plan
                declared = {n: p for n, p in procs.items() if n != "pool"}
                out["topology"] = read_topologies(declared, tmp)
        finally:
            stop_processes([*reversed(procs.values()), *extra.values()])
    bags = sorted(p for p in bag_root.iterdir() if p.is_dir()) if bag_root.exists() else []
    if len(bags) != 1:  # one recorder start (nothing respawns here)
        raise RuntimeError(f"expected one bag under {bag_root}, found {[b.name for b in bags]}")
    out["bag"] = str(bags[0])
    _bag_rates(out)
    return out


def _tally(probe: Any, tally: dict) -> None:
    """Count on ``probe`` what breaks first when the launch is starved (:func:`rig_rows`): disarms
    (``thrusters/pulse_width`` armed -> not armed, once armed), allocation statuses rejecting a stale wrench, and
    the output guard's reasons for silencing the outputs (``guard/heartbeat`` above OK), in ``tally``."""
    def on_pwm(msg: ThrusterPwm) -> None:
        armed = bool(msg.armed)
        tally["disarms"] += int(tally["armed"] is True and not armed)
        tally["armed"] = armed if armed or tally["armed"] is not None else None

    def on_status(msg: AllocationStatus) -> None:
        tally["stale"] += int(msg.rejected and "stale" in msg.reason)

    def on_guard(msg: Heartbeat) -> None:
        if tally["armed"] is not None and msg.level != 0 and msg.message not in tally["why"] and len(tally["why"]) < 5:
            tally["why"].append(msg.message)

    probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", on_pwm, 50)
    probe.create_subscription(AllocationStatus, "allocation/status", on_status, 50)
    probe.create_subscription(Heartbeat, "guard/heartbeat", on_guard, heartbeat_qos())


def rig_rows(cores: float, busy_loops: int = 0, duration_s: float = 10.0, windows: int = 1) -> list[dict]:
    """The launch layout (:func:`_launch`) inside a rig of ``cores`` cores here with ``busy_loops`` beside it
    (:class:`~hindrax_tools.benchmarks.rig.Rig`, the virtual pool and this benchmark outside): the rig's CPU and
    throttling in the running and idle windows, and what broke: disarms, stale-wrench statuses, whether the
    surge goal ran through its running window (else the first line of why not). Raises
    :class:`~hindrax_tools.benchmarks.rig.RigError` where no cgroup cpu controller is writable."""
    tally: dict = {"armed": None, "disarms": 0, "stale": 0, "why": [], "rig": []}
    error = ""
    with tempfile.TemporaryDirectory(prefix="hindrax-bench-rig-") as tmpdir, Rig(cores, busy_loops=busy_loops) as rig:
        try:
            _launch(duration_s, Path(tmpdir), windows, rig=rig, tally=tally)
        except (RuntimeError, ConditionTimeout) as exc:
            error = str(exc).splitlines()[0]
        whole = rig.usage()
    beside = f"{busy_loops} busy loop(s) of one Pi core each beside it" if busy_loops else "nothing beside it"
    rows = [{"name": "rig_cores", "value": cores, "unit": "cores here",
             "note": f"{cores / PI4_CORE_HERE:g} Pi 4 cores at {PI4_CORE_HERE:g} core here each "
                     f"(hindrax_tools/benchmarks/rig.py); {beside}; launch of {LAUNCH_FILE[1]} inside, the virtual "
                     "pool outside"}]
    for phase in ("running", "idle"):
        spans = [(a, b) for p, a, b in tally["rig"] if p == phase]
        if spans:
            wall = sum(b.wall_s - a.wall_s for a, b in spans)
            rows += [{"name": f"rig_{phase}_cpu", "value": 100 * sum(b.cpu_s - a.cpu_s for a, b in spans) / wall,
                      "unit": "% of a core", "target": f"<= {100 * cores:g}",
                      "note": "the launch's processes in the rig (cpuacct / cpu.stat), busy loops excluded"},
                     {"name": f"rig_{phase}_throttled", "value": 100 * sum(
                         b.throttled_s - a.throttled_s for a, b in spans) / wall, "unit": "% of the time",
                      "note": "time the rig's quota held its processes off the CPUs, summed over the CPUs (cpu.stat "
                              f"throttled time; up to {100 * (os.cpu_count() or 1)} %)"}]
    rows += [
        {"name": "rig_whole_run_cpu", "value": 100 * whole.cores, "unit": "% of a core",
         "note": f"start to stop, {whole.wall_s:.0f} s (start-up included); busy loops {whole.busy_cpu_s:.0f} s CPU"},
        {"name": "rig_disarms", "value": tally["disarms"], "unit": "", "target": "0",
         "note": "; ".join(tally["why"]) or "the output guard never silenced the outputs"},
        {"name": "rig_stale_wrench_statuses", "value": tally["stale"], "unit": "", "target": "0",
         "note": "allocation/status rejecting a stale wrench (neutral thrust)"},
        {"name": "rig_goal_ran_through", "value": 0 if error else 1, "unit": "", "target": "1",
         "note": error or "the surge goal ran through the running window; cancelled, then the idle window"},
    ]
    return rows


def _bag_rates(out: dict) -> None:
    """Messages per second per topic of every window, from the launch layout's bag (log time = the recorder's
    reception time on the system clock, the windows' clock), and the IMU's timing (:func:`imu_timing`)."""
    reader = BagReader(out["bag"])
    spans = [(w["t0_ns"], w["t1_ns"], w) for ph in out["phases"].values() for w in ph["windows"]]
    imu: dict[int, list[tuple[int, int]]] = {id(w): [] for *_, w in spans}
    decode = cdr_decoder("sensor_msgs/msg/Imu")
    for *_, w in spans:
        w["rates"] = collections.Counter()
    out["payloads"] = payloads = {}  # a recorded message per topic (CDR hex): the skeleton sends it
    first = min(t0 for t0, _, _ in spans)
    last = max(t1 for _, t1, _ in spans)
    for m in reader.messages(start_ns=first, end_ns=last):
        for t0, t1, w in spans:
            if t0 <= m.log_time_ns < t1:
                w["rates"][m.topic] += 1
                payloads.setdefault(m.topic, bytes(m.data).hex())
                if m.topic == IMU_TOPIC:
                    stamp = decode(m.data).header.stamp
                    imu[id(w)].append((m.log_time_ns, stamp.sec * 1_000_000_000 + stamp.nanosec))
    for t0, t1, w in spans:
        w["rates"] = {t: n / ((t1 - t0) * 1e-9) for t, n in w["rates"].items()}
        w["imu"] = imu_timing(imu[id(w)])


def imu_timing(samples: list[tuple[int, int]]) -> dict[str, float]:
    """The IMU's timing as a subscriber in another process sees it (the recorder: what the supervisor's rate check
    sees too). samples: (reception time, header stamp) of each message in one window, ns on the system clock, in
    reception order (at least 2). Returns ``rate_hz`` (messages per second between the first and last reception),
    ``gap_max_s`` (largest interval between two receptions), ``stamp_gap_max_s`` (largest interval between two
    stamps: the driver's poll taken late), ``age_p50_ms``, ``age_p99_ms``, ``age_max_ms`` (reception time minus
    stamp: the I2C read, the publish and the delivery; the ICM-20948 stamps its sample at the poll, before the
    read). Raises ValueError for fewer than 2 samples."""
    if len(samples) < 2:
        raise ValueError(f"imu_timing: {len(samples)} sample(s), need at least 2")
    log = [t for t, _ in samples]
    stamps = sorted(s for _, s in samples)
    ages = sorted((t - s) * 1e-6 for t, s in samples)
    return {"rate_hz": (len(log) - 1) / ((log[-1] - log[0]) * 1e-9),
            "gap_max_s": max(b - a for a, b in zip(log, log[1:])) * 1e-9,
            "stamp_gap_max_s": max(b - a for a, b in zip(stamps, stamps[1:])) * 1e-9,
            "age_p50_ms": ages[len(ages) // 2], "age_p99_ms": ages[min(len(ages) - 1, int(0.99 * len(ages)))],
            "age_max_ms": ages[-1]}


def _safety_log_lines(tmp: Path, names: list[str], keep: int = 12) -> str:
    """The last ``keep`` lines of each process log that speak of arming, heartbeats, trips or the watchdog."""
    out = []
    for name in names:
        try:
            lines = (tmp / f"{name}.log").read_text(errors="replace").splitlines()
        except OSError:
            continue
        hits = [ln for ln in lines if re.search(r"arm|heartbeat|trip|watchdog|stale|guard", ln, re.I)]
        out += [f"{name}: {ln[:300]}" for ln in hits[-keep:]]
    return "\n".join(out) or "(no process logged a disarm, trip or heartbeat)"


def _check_alive(procs: dict, tmp: Path) -> bool:
    """True while every process runs; else RuntimeError with the end of the first dead one's log."""
    dead = [n for n, p in procs.items() if p.poll() is not None]
    if dead:
        try:
            tail = (tmp / f"{dead[0]}.log").read_text()[-2000:]
        except OSError:
            tail = ""
        raise RuntimeError(f"launch layout: process(es) {dead} exited; {dead[0]}'s log ends:\n{tail}")
    return True


#: the participant probes of the launch layout: name -> topics it subscribes (raw CDR, like the recorder without
#: writing): one more process with its participant and executor and nothing to do, and the same with the sensor
#: topics the identification and the controller take: what a node costs apart from the process of its publishers
PARTICIPANT_PROBES = {
    "participant_idle": [],
    "participant_sensor_subscriber": [["/imu/data_raw", "sensor_msgs/msg/Imu"], ["/dvl/data", "hindrax_msgs/msg/Dvl"],
                                      ["/pressure/fluid_pressure", "sensor_msgs/msg/FluidPressure"],
                                      ["/ping/altitude", "sensor_msgs/msg/Range"]],
}


# ---------------------------------------------------------------------------------------- skeletons
def skeleton_spec(topology: dict, rates: list[dict[str, float]], payloads: dict[str, str] | None = None) -> dict:
    """The processes of a skeleton (:func:`~.launch_node.skeleton_main`): ``topology`` (label ->
    :func:`~.launch_node.topology` of that process) with, on every publisher, ``rates`` (one per
    phase: that phase's messages/s of its topic, shared equally by the topic's publishers) and
    ``payload`` (``payloads``: topic -> CDR bytes, hex; else a default-constructed message)."""
    count = collections.Counter(p["topic"] for t in topology.values() for n in t["nodes"] for p in n["publishers"])
    out = json.loads(json.dumps(topology))
    for n in (n for t in out.values() for n in t["nodes"]):
        for p in n["publishers"]:
            p["rates"] = [r.get(p["topic"], 0.0) / count[p["topic"]] for r in rates]
            p["payload"] = (payloads or {}).get(p["topic"])
    return out


def topology_differences(launch: dict, skeleton: dict) -> list[str]:
    """Two topologies' differences (label -> :func:`~.launch_node.topology`), rates and payloads
    ignored: a line per process, node or endpoint (topic, type, QoS, raw, events) only one has."""
    def items(t: dict) -> set:
        kinds = ("publishers", "subscriptions", "services", "clients", "node")
        return {(label, n["namespace"], n["name"], kind, json.dumps({k: v for k, v in e.items()
                 if k not in ("rates", "payload")}, sort_keys=True)) for label, proc in t.items()
                for n in proc["nodes"] for kind in kinds for e in n.get(kind, [{}])}
    a, b = items(launch), items(skeleton)
    sides = (("launch", launch, skeleton), ("skeleton", skeleton, launch))
    return [f"process {p} only in the {side}" for side, x, y in sides for p in set(x) - set(y)] \
        + [f"only in the launch: {x}" for x in sorted(a - b)] \
        + [f"only in the skeleton: {x}" for x in sorted(b - a)]


def read_topologies(procs: dict[str, subprocess.Popen], directory: Path) -> dict:
    """Label -> :func:`~.launch_node.topology` of each process in ``procs`` (started by launch_node
    with ``HINDRAX_BENCH_TOPOLOGY=directory``): sends SIGUSR1, reads ``<pid>.json``."""
    for p in procs.values():
        (directory / f"{p.pid}.json").unlink(missing_ok=True)
        p.send_signal(signal.SIGUSR1)
    paths = {label: directory / f"{p.pid}.json" for label, p in procs.items()}
    wait_until(lambda: all(f.is_file() for f in paths.values()), 30, None, "every process's topology")
    return {label: json.loads(f.read_text()) for label, f in paths.items()}


def _skeleton(spec: dict, phases: list[tuple[str, int]], duration_s: float,
              envs: dict | None = None, stream_phase: str | None = None, check: dict | None = None) -> dict:
    """Run ``spec`` (:func:`skeleton_spec`; ``envs[label] = (launch-prefix, env)``) and measure
    ``phases`` (name, windows of ``duration_s``; SIGUSR2, 2 s warm-up first), the pilot's wrench
    stream on in ``stream_phase``; ``check``: topology to match (else RuntimeError). Returns
    ``{"phases": {name: {"windows": [{"wall_s", "per_process"}]}}, "topology"}``."""
    out: dict = {"phases": {}}
    with (tempfile.TemporaryDirectory(prefix="hindrax-bench-skeleton-") as tmpdir, domain_id() as did):
        tmp = Path(tmpdir)
        env = child_env(ROS_DOMAIN_ID=str(did), **{TOPOLOGY_ENV: tmpdir})
        (tmp / "spec.json").write_text(json.dumps({"processes": spec}))
        procs: dict[str, subprocess.Popen] = {}
        try:
            for label in spec:
                prefix, extra = (envs or {}).get(label, ([], {}))
                argv = [*prefix, *_skeleton_argv(tmp / "spec.json", label)]
                procs[label] = start_logged(tmp / f"{label}.log", argv, env=dict(env, **extra))
            with probe_spinning(did) as (probe, _ex, spin):
                switch = _wrench_stream(probe)
                settled = GraphSettled(probe, quiet_s=GRAPH_QUIET_S,
                                       min_nodes=sum(len(t["nodes"]) for t in spec.values()))
                wait_until(lambda: _check_alive(procs, tmp) and settled(), 120, spin, "the skeleton's graph settled")
                out["topology"] = read_topologies(procs, tmp)
                wrong = topology_differences(check, out["topology"]) if check is not None else []
                if wrong:
                    raise RuntimeError("the skeleton's topology is not the launch's:\n" + "\n".join(wrong[:20]))
                for k, (phase, n) in enumerate(phases):
                    if k:
                        for p in procs.values():
                            p.send_signal(signal.SIGUSR2)
                    switch(phase == stream_phase)
                    spin_for(2.0, spin)
                    wins = []
                    for _ in range(n):
                        cpu0 = {lb: proc_cpu_s(p.pid) for lb, p in procs.items()}
                        _, wall = spin_for(duration_s, spin)
                        cpu = {lb: (proc_cpu_s(p.pid) - cpu0[lb]) / wall for lb, p in procs.items()}
                        wins.append({"wall_s": wall, "per_process": cpu})
                    _check_alive(procs, tmp)
                    out["phases"][phase] = {"windows": wins}
        finally:
            stop_processes(list(procs.values()))
    return out


def _skeleton_argv(spec_file: Path, label: str) -> list[str]:
    return [python_executable(), "-m", "hindrax_tools.benchmarks.launch_node",
            "hindrax_tools.benchmarks.launch_node:skeleton_main", str(spec_file), label]


def _endpoint(topic: str, type_name: str, raw: bool | None = None) -> dict:
    """A skeleton's topic endpoint: depth 10, reliable, volatile, no QoS event handler."""
    qos = dict(history=1, depth=10, reliability=1, durability=2, liveliness=0, deadline=0,
               lifespan=0, liveliness_lease_duration=0)
    return {"topic": topic, "type": type_name, "qos": qos, "events": [], **({} if raw is None else {"raw": raw})}


def _one_node(name: str, pubs: list, subs: list) -> dict:
    return {"nodes": [{"name": name, "namespace": "/", "publishers": pubs, "subscriptions": subs,
                       "services": [], "clients": []}]}


def _bare(spec: list, duration_s: float) -> float:
    """CPU of one bare publisher process (the skeleton of ``spec``: (topic, type, rate),
    :func:`_endpoint`'s QoS, default messages) over ``duration_s``, fraction of a core."""
    topo = {"bare": _one_node("bare_publisher", [_endpoint(t, ty) for t, ty, _ in spec], [])}
    run = _skeleton(skeleton_spec(topo, [{t: r for t, _, r in spec}]), [("bare", 1)], duration_s)
    return run["phases"]["bare"]["windows"][0]["per_process"]["bare"]


def launch_skeleton(launch: dict, windows: int, duration_s: float) -> dict:
    """The launch layout's skeleton, measured like the launch: the topology its processes declared
    (``launch["topology"]``, checked on the skeleton), each topic at the launch's rate per phase
    with a recorded message, the running phase's ``windows`` and one idle window with the pilot's
    wrench stream (the idle ``/wrench`` rate less it: no identification then)."""
    rates = [_phase_rates(launch, "running"), _phase_rates(launch, "idle")]
    rates[1]["/wrench"] = max(0.0, rates[1].get("/wrench", 0.0) - WRENCH_RATE_HZ)
    envs = {label: (p["prefix"], p["env"]) for label, p in launch["processes"].items()}
    spec = skeleton_spec(launch["topology"], rates, launch["payloads"])
    return _skeleton(spec, [("running", windows), ("idle", 1)], duration_s, envs,
                     stream_phase="idle", check=launch["topology"])


def skeleton_rows(launch: dict, skel: dict) -> list[dict]:
    """Per phase, the skeleton's CPU per process and in total, in units of the launch's pool CPU in
    that phase (median CPU over median pool CPU), and the launch's CPU over the skeleton's
    (``..._vs_skeleton_ratio``), its note the part above: the logic, what leaner code can win."""
    rows: list[dict] = []
    for phase in ("running", "idle"):
        lw, sw = launch["phases"][phase]["windows"], skel["phases"][phase]["windows"]
        pool = _median([w["pool"] for w in lw])
        sk = {n: _median([w["per_process"][n] for w in sw]) for n in sw[0]["per_process"]}
        la = {n: _median([w["per_process"][n] for w in lw]) for n in sk}
        sk["total"] = _median([sum(w["per_process"].values()) for w in sw])
        la["total"] = _median([sum(w["per_process"].values()) for w in lw])
        for n in sk:
            target = ("<= 1.3" if phase == "running" else "<= 1.0") if n == "total" else ""
            rows += [{"name": f"launch_skeleton_{phase}_cpu_{n}_per_pool", "value": sk[n] / pool,
                      "unit": "x", "target": target,
                      "note": f"{100 * sk[n]:.1f} % of a core; the launch's endpoints, rates and messages without "
                              f"logic; unit: the pool's {100 * pool:.1f} % in the launch's {phase} windows"},
                     {"name": f"launch_{phase}_vs_skeleton_ratio_{n}", "value": la[n] / sk[n],
                      "unit": "x",
                      "note": f"launch {la[n] / pool:.3f} - skeleton {sk[n] / pool:.3f} = "
                      f"{(la[n] - sk[n]) / pool:.3f} pool units above the skeleton (logic)"}]
    return rows


# ---------------------------------------------------------------------------------------------- rows
#: The virtual pool's CPU (simulator and emulators, fraction of a core) in the running windows of the launch layout
#: on the reference machine: docs/results.md, make bench at c7544b1, machine_nbody_cpu_s 27.2 s (the reference
#: machine of :data:`~hindrax_tools.benchmarks.machine.REFERENCE_NBODY_CPU_S`)
REFERENCE_POOL_CPU = 0.203

#: the launch file the launch layout starts (package, path in its share directory), with recording on
LAUNCH_FILE = ("hindrax_onboard", "launch/pool_test.launch.xml")
#: running-phase windows of the launch layout in ``make bench`` (their medians are the rows)
RUNNING_WINDOWS = 3


def _median(values: list[float]) -> float:
    return float(statistics.median(values)) if values else float("nan")


def launch_rows(launch: dict, nbody_s: float | None = None) -> list[dict]:
    """Rows of the launch layout: per process, total, largest process and messages per second of each phase, each
    the median over the phase's windows (the notes list every window's value). ``nbody_s``: this machine's n-body
    time (:func:`~hindrax_tools.benchmarks.machine.nbody_cpu_s`), for the total and the
    largest process at the reference machine's speed (``..._at_reference_speed``); None: none."""
    rows: list[dict] = []
    for phase in ("idle", "running"):
        wins = launch["phases"][phase]["windows"]
        names = list(wins[0]["per_process"])
        per = {n: _median([w["per_process"][n] for w in wins]) for n in names}

        def span(vals):
            return "" if len(vals) < 2 else "windows: " + " / ".join(f"{100 * v:.1f}" for v in vals)

        for name in names:
            rows.append({"name": f"launch_{phase}_cpu_{name}", "value": 100 * per[name], "unit": "% of a core",
                         "target": "<= 15" if phase == "running" else "",
                         "note": span([w["per_process"][name] for w in wins])})
        totals = [sum(w["per_process"].values()) for w in wins]
        total = _median(totals)
        worst = max(per, key=per.get)
        rates = [sum(w["rates"].values()) for w in wins]
        rows += [
            {"name": f"launch_{phase}_cpu_total", "value": 100 * total, "unit": "% of a core",
             "target": "<= 40", "note": f"{len(names)} processes of {Path(launch['launch_file']).name}, recorder on; "
                                        f"{len(wins)} window(s) of {wins[0]['wall_s']:.0f} s"
                                        + (f" ({span(totals)})" if len(wins) > 1 else "")
                                        + f"; x{PI4_FACTOR:g} on a Pi 4 = {PI4_FACTOR * 100 * total:.0f} % of one "
                                          f"Pi core (of 4)"},
            {"name": f"launch_{phase}_cpu_max_process", "value": 100 * per[worst], "unit": "% of a core",
             "target": "<= 15", "note": worst},
            {"name": f"launch_{phase}_msgs_per_s", "value": _median(rates), "unit": "msg/s",
             "note": "recorded topics, from the bag"},
        ]
        if nbody_s:
            scale = REFERENCE_NBODY_CPU_S / nbody_s
            rows += [
                {"name": f"launch_{phase}_cpu_total_at_reference_speed", "value": 100 * total * scale,
                 "unit": "% of a core",
                 "note": f"launch_{phase}_cpu_total x {scale:.3g} (machine_nbody_cpu_s {nbody_s:.1f} s here, "
                         f"{REFERENCE_NBODY_CPU_S:g} s on the reference machine): the figure to compare between "
                         f"sessions' machines"},
                {"name": f"launch_{phase}_cpu_max_process_at_reference_speed", "value": 100 * per[worst] * scale,
                 "unit": "% of a core", "note": worst},
            ]
        pools = [w.get("pool") or 0.0 for w in wins]
        if all(p > 0.0 for p in pools):
            ratios = [t / p for t, p in zip(totals, pools)]
            ratio = _median(ratios)
            worst_ratio = _median([w["per_process"][worst] / p for w, p in zip(wins, pools)])
            rows += [
                {"name": f"launch_{phase}_cpu_total_per_pool", "value": ratio, "unit": "x",
                 "target": "<= 1.3" if phase == "running" else "<= 1.0",
                 "note": f"launch_{phase}_cpu_total / the virtual pool's CPU in the same windows "
                         f"({' / '.join(f'{r:.2f}' for r in ratios)}): the pool's code is the same in every run, "
                         f"so this ratio is the stack's cost in units of this machine's speed for wake-up-heavy "
                         f"Python (module docstring, \"Machine speed\")"},
                {"name": f"launch_{phase}_cpu_total_at_reference_pool", "value": 100 * ratio * REFERENCE_POOL_CPU,
                 "unit": "% of a core",
                 "note": f"launch_{phase}_cpu_total_per_pool x {100 * REFERENCE_POOL_CPU:g} % (the virtual pool on "
                         f"the reference machine): the figure to compare between sessions' machines"},
                {"name": f"launch_{phase}_cpu_max_process_at_reference_pool",
                 "value": 100 * worst_ratio * REFERENCE_POOL_CPU, "unit": "% of a core", "note": worst},
            ]
            for name in names:
                rows.append({"name": f"launch_{phase}_cpu_{name}_per_pool", "unit": "x",
                             "value": _median([w["per_process"][name] / p for w, p in zip(wins, pools)]),
                             "target": "<= 0.1" if phase == "idle" and name.startswith("ident_") else "<= 0.35"})
        if all("wakeups" in w for w in wins):
            for name in names:
                _, _, named, cpu = wins[0]["wakeups"][name]
                threads = collections.Counter(named)
                rows.append({"name": f"launch_{phase}_wakeups_{name}", "unit": "1/s",
                             "value": _median([w["wakeups"][name][0] for w in wins]),
                             "note": "voluntary context switches of every thread per second (each sleep ends in "
                                     "a wake-up); by thread (first window), wake-ups/s (its CPU, % of a core): "
                                     + ", ".join(f"{k} {v:.0f}" + (f" ({100 * cpu[k]:.1f})" if k in cpu else "")
                                                 for k, v in threads.most_common(6))})
            rows.append({"name": f"launch_{phase}_wakeups_total", "unit": "1/s",
                         "value": _median([sum(v[0] for v in w["wakeups"].values()) for w in wins])})
            dds = [sum(c for v in w["wakeups"].values() for k, c in v[3].items() if k.startswith("dds.")) for w in wins]
            rows.append({"name": f"launch_{phase}_cpu_dds_threads", "unit": "% of a core",
                         "value": 100 * _median(dds),
                         "note": f"Fast DDS's own threads (dds.ev event/timer, dds.udp receive, "
                                 f"...) of every process, {100 * _median(dds) / total:.0f} % of "
                                 "the total" if total > 0
                                 else "Fast DDS's own threads of every process"})
        for name in wins[0].get("participants", {}):
            cpu = [w["participants"][name][0] for w in wins]
            topics = ", ".join(t for t, _ in PARTICIPANT_PROBES.get(name, [])) or "no topic"
            rows.append({"name": f"launch_{phase}_cpu_{name}", "unit": "% of a core", "value": 100 * _median(cpu),
                         "note": f"one more process (a node process's entry point, run_nodes), not in the totals, "
                                 f"subscribing {topics}; "
                                 f"{_median([w['participants'][name][1] for w in wins]):.0f} wake-ups/s"
                                 + (f"; {_median([c / p for c, p in zip(cpu, pools)]):.3f} pool units"
                                    if all(p > 0.0 for p in pools) else "")})
        if phase == "running":
            rows += [
                {"name": "launch_running_cpu_excluded", "value": 100 * _median([w["pool"] + w["bench"] for w in wins]),
                 "unit": "% of a core",
                 "note": f"not in the total: the virtual pool (simulator, emulators) "
                         f"{100 * _median([w['pool'] for w in wins]):.1f} % and this benchmark's own process "
                         f"{100 * _median([w['bench'] for w in wins]):.1f} %"},
                {"name": "launch_running_loadavg", "value": _median([w["loadavg"] for w in wins]), "unit": "",
                 "note": f"1-minute load average of the machine ({os.cpu_count()} CPUs) during the windows: "
                         f"above the CPU count, every figure here is inflated (cache misses, waits)"},
            ]
            rss = wins[-1]["rss_mb"]
            rows.append({"name": "launch_rss_total_mb", "value": sum(rss.values()), "unit": "MB",
                         "note": "resident memory of the launch layout's processes at the end of the running phase: "
                                 + ", ".join(f"{n} {v:.0f}" for n, v in rss.items())})
            pss = wins[-1]["pss_mb"]
            rows.append({"name": "launch_pss_total_mb", "value": sum(pss.values()), "unit": "MB", "target": 400.0,
                         "note": "proportional set size of the launch layout's processes (shared pages divided among "
                                 "the processes sharing them; identification and recording on) at the end of the "
                                 "running phase: " + ", ".join(f"{n} {v:.0f}" for n, v in pss.items())})
            rows += [{"name": f"launch_pss_mb_{n}", "value": v, "unit": "MB"} for n, v in pss.items()]
            rows += _imu_rows(wins)
    return rows


def _imu_rows(wins: list[dict]) -> list[dict]:
    """The running phase's IMU timing rows (:func:`imu_timing` of each window; none when a window has none): the
    rate, the largest gap and the sample age a subscriber in another process sees. The supervisor stops a campaign
    below ``safety.min_rate.imu_hz``; the identification's tick is 25 Hz."""
    timing = [w.get("imu") for w in wins]
    if not timing or not all(timing):
        return []

    def each(key: str, scale: float = 1.0) -> str:
        return "windows: " + " / ".join(f"{scale * t[key]:.3g}" for t in timing)

    return [
        {"name": "launch_running_imu_rate_hz", "value": _median([t["rate_hz"] for t in timing]), "unit": "Hz",
         "target": ">= 48", "note": f"{IMU_TOPIC} received by the recorder; {each('rate_hz')}"},
        {"name": "launch_running_imu_gap_max_s", "value": max(t["gap_max_s"] for t in timing), "unit": "s",
         "target": "<= 0.1", "note": f"largest interval between two receptions, all windows ({each('gap_max_s')}); "
                                     f"between two stamps (the poll taken late): "
                                     f"{max(t['stamp_gap_max_s'] for t in timing):.3f} s"},
        {"name": "launch_running_imu_age_p99_ms", "value": _median([t["age_p99_ms"] for t in timing]), "unit": "ms",
         "note": f"reception minus stamp (I2C read, publish, delivery), 99th percentile ({each('age_p99_ms')}); "
                 f"median {_median([t['age_p50_ms'] for t in timing]):.2f} ms, largest "
                 f"{max(t['age_max_ms'] for t in timing):.1f} ms"},
    ]


def _phase_rates(launch: dict, phase: str) -> dict[str, float]:
    wins = launch["phases"][phase]["windows"]
    topics = sorted({t for w in wins for t in w["rates"]})
    return {t: _median([w["rates"].get(t, 0.0) for w in wins]) for t in topics}


def run(quick: bool = False, layouts: tuple[str, ...] = ("inproc", "launch"), windows: int | None = None,
        duration_s: float | None = None, baselines: bool = True, baseline: str | None = None) -> list[dict]:
    """The stack benchmark's rows (module docstring). layouts: ``inproc`` and/or ``launch``; windows: running windows of
    the launch layout (default :data:`RUNNING_WINDOWS`, 1 with ``quick``); duration_s: window length, s; baselines:
    bare rclpy and the launch's skeleton; baseline: a git ref whose launch layout is measured first in the same run
    (:func:`baseline_launch`), for the rows of today's cost over the baseline's (``..._vs_baseline``)."""
    # windows: 10 s per phase and layout (the launch layout's running phase: 3 of them, medians), 8 s per baseline
    duration_s = duration_s or (8.0 if quick else 10.0)
    windows = windows or (1 if quick else RUNNING_WINDOWS)
    base_s = 6.0 if quick else 8.0
    inproc = launch = None
    before = baseline_launch(baseline, windows, duration_s) if baseline else None
    nbody_before = nbody_cpu_s()  # the machine's speed before and after the layouts (it drifts within minutes)
    with tempfile.TemporaryDirectory(prefix="hindrax-bench-stack-") as tmpdir:
        tmp = Path(tmpdir)
        if "inproc" in layouts:
            inproc = _in_process(duration_s, tmp)
        if "launch" in layouts:
            launch = _launch(duration_s, tmp, windows=windows)
            launch["types"] = BagReader(launch["bag"]).topics
    nbody_after = nbody_cpu_s()
    nbody_s = (nbody_before + nbody_after) / 2
    rows: list[dict] = [
        {"name": "pi4_factor_assumed", "value": PI4_FACTOR, "unit": "x",
         "note": "hindrax_tools/benchmarks/rig.py PI4_FACTOR: issue 73's n-body 2.8x (C), 3.6x (the same CPython), "
                 "the stack's mix 4-6x; not measured on a Pi (docs/pi_budget.md, the first Pi day)"},
        {"name": "machine_nbody_cpu_s", "value": nbody_s, "unit": "s",
         "note": f"this machine's Python speed: CPU time of 5 million n-body steps (benchmarks/machine.py, least of "
                 f"5 runs of 100,000), mean of {nbody_before:.1f} s before the layouts and {nbody_after:.1f} s "
                 f"after; {REFERENCE_NBODY_CPU_S:g} s on the reference machine, about 47 s on the one of the "
                 f"previous session (by its virtual pool's CPU)"},
    ]
    if inproc:
        for phase in ("idle", "running"):
            ph = inproc["phases"][phase]
            for name, v in ph["per_node"].items():
                rows.append({"name": f"inproc_{phase}_cpu_{name}", "value": 100 * v, "unit": "% of a core"})
            rows.append({"name": f"inproc_{phase}_msgs_per_s", "value": sum(ph["rates"].values()),
                         "unit": "msg/s", "note": "recorded topics"})
            if phase == "idle":
                rows.append({"name": "cpu_stack_excluding_simulator", "value": 100 * ph["stack"],
                             "unit": "% of a core", "note": "one process, identification idle, 50 Hz wrench stream, "
                                                           "recorder on; emulators and simulator excluded"})
            else:
                rows.append({"name": "inproc_running_cpu_stack", "value": 100 * ph["stack"], "unit": "% of a core",
                             "note": "one process, identification running surge, recorder on"})
        if baselines:
            # the topics' types: the launch layout's bag, the graph's publishers, and two of rcl's
            types = {"/rosout": "rcl_interfaces/msg/Log", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
                     **(launch["types"] if launch else {}), **inproc["types"]}
            idle_rates = sorted(inproc["phases"]["idle"]["rates"].items())
            idle_spec = [(t, types[t], r) for t, r in idle_rates if r > 0.05 and t in types]
            bare_pub = _bare(idle_spec, base_s)
            idle_msgs = sum(r for *_, r in idle_spec)
            rows += [
                {"name": "cpu_bare_rclpy_same_topics", "value": 100 * bare_pub, "unit": "% of a core",
                 "note": f"publishers only, {len(idle_spec)} topics, {idle_msgs:.0f} msg/s (one-process idle phase)"},
                {"name": "stack_vs_bare_ratio",
                 "value": inproc["phases"]["idle"]["stack"] / bare_pub if bare_pub else -1,
                 "unit": "x", "note": "cpu_stack_excluding_simulator / cpu_bare_rclpy_same_topics (stack includes "
                                      "the recorder and every subscriber; the baseline has none)"},
            ]
    if launch:
        rows += launch_rows(launch, nbody_s)
        running = _phase_rates(launch, "running")
        idle = _phase_rates(launch, "idle")
        if baselines:
            rows += skeleton_rows(launch, launch_skeleton(launch, windows, duration_s))
        if before is not None:
            rows += baseline_rows(rows, before, baseline)
        for topic, rate in running.items():
            rows.append({"name": f"rate {topic}", "value": round(rate, 2), "unit": "msg/s",
                         "note": f"launch layout, running; idle {idle.get(topic, 0.0):.2f}"})
    if inproc:
        rows += [
            {"name": "simulator_real_time_factor", "value": inproc["phases"]["idle"]["sim_rtf"], "unit": "x",
             "note": "achieved in the one-process graph (configured 1.0)"},
            {"name": "recorder_drops", "value": inproc["dropped"], "unit": "messages", "target": "0"},
        ]
    # the command path the controller waits on: wrench -> PCA9685 registers through the actuation process's nodes
    rows += [dict(r, name=f"actuation_{r['name']}") for r in wrench_to_registers(300 if quick else 1000)
             if r["name"].startswith("wrench_to_registers")]
    return rows


def baseline_launch(ref: str, windows: int, duration_s: float) -> list[dict]:
    """The launch layout's rows of the code at git ref ``ref``: a detached worktree of this checkout's repository
    at ``ref`` (in a temporary folder, removed after), its own stack benchmark (``--layouts launch --no-baselines``)
    run by this venv's interpreter with PYTHONPATH at the worktree's two Python packages, so that every process of
    that layout (its launch file, its nodes, its virtual pool) runs the baseline's code. Raises RuntimeError when
    git refuses the ref or the baseline's benchmark fails (the end of its output)."""
    repo = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=Path(__file__).parent, capture_output=True,
                          text=True, check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="hindrax-bench-baseline-") as tmpdir:
        tree = Path(tmpdir) / "tree"
        made = subprocess.run(["git", "-C", repo, "worktree", "add", "--detach", str(tree), ref], capture_output=True,
                              text=True)
        if made.returncode != 0:
            raise RuntimeError(f"--baseline {ref!r}: git worktree add failed: {made.stderr.strip()}")
        try:
            out = Path(tmpdir) / "rows.json"
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(
                str(p) for p in sorted((tree / "src").iterdir()) if (p / "setup.py").is_file()))
            print(f"stack benchmark: the baseline {ref} first", flush=True)
            done = subprocess.run([python_executable(), "-m",
                                   "hindrax_tools.benchmarks.stack", "--layouts", "launch",
                                   "--no-baselines", "--windows", str(windows), "--window-s", str(duration_s),
                                   "--json", str(out)], env=env, cwd=tree, capture_output=True, text=True)
            if done.returncode != 0 or not out.is_file():
                tail = (done.stdout + done.stderr)[-3000:]
                raise RuntimeError(f"--baseline {ref}: its stack benchmark failed:\n{tail}")
            return json.loads(out.read_text())
        finally:
            subprocess.run(["git", "-C", repo, "worktree", "remove", "--force", str(tree)], capture_output=True)


def baseline_rows(rows: list[dict], before: list[dict], ref: str) -> list[dict]:
    """Today's launch-layout figures over the baseline's, measured in the same run (:func:`baseline_launch`): per
    phase the CPU total, total per pool unit, largest process and wake-ups (and PSS, the IMU's rate and largest gap in
    the running phase), as ratios, and the baseline's CPU per process."""
    now = {r["name"]: r["value"] for r in rows}
    then = {r["name"]: r["value"] for r in before}
    out = []
    for phase in ("running", "idle"):
        more = ("launch_pss_total_mb", "launch_running_imu_rate_hz", "launch_running_imu_gap_max_s") \
            if phase == "running" else ()
        for name in [f"launch_{phase}_{key}" for key in ("cpu_total", "cpu_total_per_pool", "cpu_max_process",
                                                        "wakeups_total")] + list(more):
            if name in now and then.get(name):
                out.append({"name": f"{name}_vs_baseline", "value": now[name] / then[name], "unit": "x",
                            "note": f"today {now[name]:.4g} / baseline {ref} {then[name]:.4g}, same run"})
        out.append({"name": f"launch_{phase}_cpu_baseline_processes", "value": then.get(f"launch_{phase}_cpu_total",
                                                                                       float("nan")),
                    "unit": "% of a core", "note": f"baseline {ref}: " + ", ".join(
                        f"{r['name'][len(f'launch_{phase}_cpu_'):]} {r['value']:.1f}" for r in before
                        if re.fullmatch(rf"launch_{phase}_cpu_[a-z_]+", r["name"]) and r["unit"] == "% of a core"
                        and not re.search(r"_(total|max_process|excluded)", r["name"]))})
    return out


def write_rig_section(args, rows: list[dict]) -> None:
    """The rig's rows (:func:`rig_rows`) into section ``bench-rig-F[-busyN]`` of
    ``args.results_doc`` (F with ``_`` for its point: one section per rig, beside the stack
    bench's), when that option was given."""
    table = results_doc.markdown_table(
        ["measure", "value", "unit", "target", "note"],
        [[r["name"], f"{r['value']:.4g}", r.get("unit", ""), r.get("target", ""), r.get("note", "")]
         for r in rows])
    cores, loops = args.rig_cores, args.rig_busy_loops
    tag = f"{cores:g}".replace(".", "_") + (f"-busy{loops}" if loops else "")
    results_doc.write_if_asked(
        args, f"bench-rig-{tag}", f"The Pi rig: {cores:g} cores here, {loops} busy loops",
        f"{platform.platform()}, {os.cpu_count()} cores; 1-minute load {os.getloadavg()[0]:.1f} at "
        f"the end; one running and one idle window of {args.window_s or 10.0:g} s (`make rig`, "
        f"issue 73).\n\n{table}")


def main(argv: list[str] | None = None) -> int:
    """``python -m hindrax_tools.benchmarks.stack``: the stack benchmark alone, with the
    options ``make bench`` does not take (``--help``); prints the rows as JSON (to a file too:
    ``--json``). :func:`baseline_launch` runs a baseline commit's this way."""
    parser = argparse.ArgumentParser(prog="python -m hindrax_tools.benchmarks.stack",
                                     description="The Pi budget: CPU of the vehicle graph in the launch layout "
                                                 "(one process per <node> of pool_test.launch.xml) and in one "
                                                 "process. CPU = process CPU time / wall time.")
    parser.add_argument("--layouts", nargs="+", choices=("inproc", "launch"), default=("inproc", "launch"))
    parser.add_argument("--windows", type=int, default=None,
                        help=f"running windows of the launch layout (default {RUNNING_WINDOWS}); rows are medians")
    parser.add_argument("--window-s", type=float, default=None, help="window length, s (default 10)")
    parser.add_argument("--no-baselines", action="store_true",
                        help="skip the bare rclpy baseline and the launch's skeleton")
    parser.add_argument("--quick", action="store_true", help="one 8 s window")
    parser.add_argument("--json", type=Path, default=None, help="also write the rows to this file")
    parser.add_argument("--rig-cores", type=float, default=None,
                        help="only the launch layout in a Pi-sized rig of this many cores here (rig_rows; root)")
    parser.add_argument("--rig-busy-loops", type=int, default=0, help="busy loops beside the rig's launch")
    results_doc.add_argument(parser)
    args = parser.parse_args(argv)
    if args.rig_cores:
        rows = rig_rows(args.rig_cores, args.rig_busy_loops, args.window_s or 10.0, args.windows or 1)
    else:
        rows = run(quick=args.quick, layouts=tuple(args.layouts), windows=args.windows,
                   duration_s=args.window_s, baselines=not args.no_baselines)
    print(json.dumps(rows, indent=2))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    if args.rig_cores:
        write_rig_section(args, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
