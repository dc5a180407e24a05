"""Stack benchmark: CPU of each node and of the whole stack (simulator excluded) at the nominal rates in the
virtual pool, as a ratio against a bare rclpy process publishing the same topics at the same rates.

Method
- The graph of ``hindrax bringup --sim`` (simulator, five emulators, four drivers, ESC node, allocation,
  recorder) runs in this process at real-time factor 1 while a 50 Hz wrench stream keeps the thrusters busy.
- Per node: CPU time (``time.thread_time``) of every executor callback, attributed to the node that owns it
  (a SingleThreadedExecutor subclass that times ``handler()``), plus the serial drivers' reader threads
  (``SerialTransport`` threads) measured from ``/proc/self/task/<native id>/stat``.
- Whole stack, simulator excluded: process CPU time minus the simulator node's callbacks and the emulator
  threads (``PtyDevice``), i.e. drivers + ESC + allocation + recorder + DDS/rclpy threads.
- Baseline: a child process (plain rclpy, SingleThreadedExecutor) publishing, for every topic the drivers,
  ESC and allocation published during the window, a message of the same type at the same measured rate.
- Ratio = stack CPU / baseline CPU over the same wall time.
"""
from __future__ import annotations

import collections
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

_CLK = os.sysconf("SC_CLK_TCK")


def _thread_cpu_s() -> dict[str, float]:
    """CPU seconds per Python thread name (native thread ids -> /proc/self/task/<tid>/stat utime + stime)."""
    import threading

    out: dict[str, float] = collections.defaultdict(float)
    for t in threading.enumerate():
        try:
            fields = Path(f"/proc/self/task/{t.native_id}/stat").read_text().rsplit(")", 1)[1].split()
            out[t.name] += (int(fields[11]) + int(fields[12])) / _CLK
        except (OSError, IndexError, ValueError, TypeError):
            continue
    return out


_BASELINE = textwrap.dedent('''
    import importlib, json, sys, time
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    spec = json.loads(sys.argv[1]); duration = float(sys.argv[2])
    rclpy.init(); node = rclpy.create_node("bare_baseline")
    for i, (topic, type_name, rate) in enumerate(spec):
        pkg, _, name = type_name.split("/")
        cls = getattr(importlib.import_module(pkg + ".msg"), name)
        pub = node.create_publisher(cls, "/baseline" + topic, 10)
        msg = cls()
        node.create_timer(1.0 / rate, (lambda p, m: (lambda: p.publish(m)))(pub, msg))
    ex = SingleThreadedExecutor(); ex.add_node(node)
    t_end = time.monotonic() + duration
    c0 = time.process_time()
    while time.monotonic() < t_end:
        ex.spin_once(timeout_sec=0.05)
    print(json.dumps({"cpu_s": time.process_time() - c0}))
''')


def run(quick: bool = False) -> list[dict]:
    import rclpy
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import SingleThreadedExecutor, TimeoutException, ShutdownException

    from hindrax_drivers.config import default_config_path
    from hindrax_drivers.testing import ros_context, wait_until
    from hindrax_ident.bringup import build_graph
    from hindrax_msgs.srv import SetArmed

    duration_s = 10.0 if quick else 30.0
    cpu_by_node: dict[str, float] = collections.defaultdict(float)

    class TimingExecutor(SingleThreadedExecutor):
        def spin_once(self, timeout_sec=None):
            try:
                handler, _entity, node = self.wait_for_ready_callbacks(timeout_sec=timeout_sec)
            except (TimeoutException, ShutdownException):
                return
            t0 = time.thread_time()
            handler()
            cpu_by_node[node.get_name() if node is not None else "(executor)"] += time.thread_time() - t0
            if handler.exception() is not None:
                raise handler.exception()

    counts: dict[str, int] = collections.Counter()
    types: dict[str, str] = {}
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, record=True,
                            record_dir=str(Path(os.environ.get("TMPDIR", "/tmp")) / f"bench-stack-{os.getpid()}"),
                            context=ctx, overrides={"esc.arming_time_s": 1.0, "simulation.real_time_factor": 1.0,
                                                    "pool.start_position_ned_m": [3.0, 3.0, 0.9]})
        ex = TimingExecutor(context=ctx)
        graph.executor.shutdown()
        graph.executor = ex
        for node in graph.nodes.values():
            ex.add_node(node)
        probe = rclpy.create_node("bench_probe", context=ctx)
        ex.add_node(probe)
        wrench = probe.create_publisher(WrenchStamped, "wrench", 10)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        spin = lambda: ex.spin_once(timeout_sec=0.01)  # noqa: E731
        wait_until(lambda: graph.nodes["esc"].arming_remaining_s() == 0.0 and arm.service_is_ready(), 60, spin)
        fut = arm.call_async(SetArmed.Request(arm=True))
        wait_until(fut.done, 10, spin)

        def push():
            m = WrenchStamped()
            m.header.frame_id = "base_link"
            m.header.stamp = probe.get_clock().now().to_msg()
            m.wrench.force.x = 6.0
            m.wrench.torque.z = 0.5
            wrench.publish(m)
        probe.create_timer(0.02, push)
        stack_names = {"dvl75", "ping1d", "ms5837", "icm20948", "esc", "thrust_allocation"}
        for name, node in graph.nodes.items():
            if name not in stack_names:
                continue
            for pub in node.publishers:
                topic = pub.topic_name
                if topic.startswith("/rosout") or topic.startswith("/parameter_events"):
                    continue
                mt = pub.msg_type
                types[topic] = f"{mt.__module__.split('.')[0]}/msg/{mt.__name__}"
                probe.create_subscription(mt, topic, (lambda t: (lambda _m: counts.__setitem__(t, counts[t] + 1)))(topic),
                                          10)
        # warm-up, then the measured window
        end = time.monotonic() + 3.0
        wait_until(lambda: time.monotonic() > end, 10, spin)
        counts.clear()
        cpu_by_node.clear()
        threads0 = _thread_cpu_s()
        proc0, wall0 = time.process_time(), time.monotonic()
        sim0 = graph.nodes["simulator"].simulator.t_s
        end = wall0 + duration_s
        wait_until(lambda: time.monotonic() > end, duration_s + 30, spin)
        proc_cpu = time.process_time() - proc0
        wall = time.monotonic() - wall0
        threads1 = _thread_cpu_s()
        sim_rtf = (graph.nodes["simulator"].simulator.t_s - sim0) / wall
        recorder = graph.nodes.get("recorder")
        writer = getattr(recorder, "_writer", None) or getattr(recorder, "writer", None)
        dropped = getattr(writer, "dropped", None)
        graph.shutdown()
        probe.destroy_node()
    thread_cpu = {k: threads1.get(k, 0.0) - threads0.get(k, 0.0) for k in threads1}
    emulator_threads = sum(v for k, v in thread_cpu.items() if k.startswith("PtyDevice"))
    serial_threads = sum(v for k, v in thread_cpu.items() if k.startswith("SerialTransport"))
    stack_cpu = proc_cpu - cpu_by_node.get("hindrax_simulator", 0.0) - emulator_threads \
        - cpu_by_node.get("bench_probe", 0.0)

    spec = [(t, types[t], counts[t] / wall) for t in sorted(counts) if counts[t] > 0]
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    base = subprocess.run([sys.executable, "-c", _BASELINE, json.dumps(spec), str(wall)], capture_output=True,
                          text=True, env=env, timeout=wall + 60)
    baseline_cpu = json.loads(base.stdout.strip().splitlines()[-1])["cpu_s"]
    rows = []
    for name in sorted(stack_names):
        node_name = {"esc": "esc", "thrust_allocation": "thrust_allocation"}.get(name, name)
        rows.append({"name": f"cpu_{name}", "value": cpu_by_node.get(node_name, 0.0) / wall * 100.0,
                     "unit": "% of a core", "note": "executor callbacks"})
    rows += [
        {"name": "cpu_serial_reader_threads", "value": serial_threads / wall * 100.0, "unit": "% of a core",
         "note": "DVL + Ping transports (parse and publish in their threads)"},
        {"name": "cpu_recorder", "value": cpu_by_node.get("recorder", 0.0) / wall * 100.0, "unit": "% of a core"},
        {"name": "cpu_stack_excluding_simulator", "value": stack_cpu / wall * 100.0, "unit": "% of a core"},
        {"name": "cpu_bare_rclpy_same_topics", "value": baseline_cpu / wall * 100.0, "unit": "% of a core",
         "note": f"{len(spec)} topics, {sum(r for *_, r in spec):.0f} msg/s"},
        {"name": "stack_vs_bare_ratio", "value": stack_cpu / baseline_cpu if baseline_cpu > 0 else float("nan"),
         "unit": "x"},
        {"name": "simulator_real_time_factor", "value": sim_rtf, "unit": "x",
         "note": "achieved, with the whole graph in one process (configured 1.0)"},
        {"name": "recorder_drops", "value": dropped if dropped is not None else -1, "unit": "messages"},
    ]
    return rows
