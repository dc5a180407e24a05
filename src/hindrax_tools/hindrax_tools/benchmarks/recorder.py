"""Recorder benchmark: drops and CPU per message at the stack's nominal load, and the highest sustained rate
recorded with zero drops.

Set-up: the recorder runs as in the stack, in its own process (``python -m
hindrax_bringup.recording.recorder_node``, default configuration: zstd chunks of 1 MiB, fsync at least
every ``recording.flush_interval_s``), recording every ``/bench/...`` topic. This process publishes
pre-serialized messages of realistic size (the synthetic test-bag messages) on a wall-clock schedule:

- nominal load (docs/architecture.md §7; the issue's figures): Imu 100 Hz and MagneticField 100 Hz (best effort, like
  sensor drivers), Dvl 10 Hz, Range 10 Hz x2, FluidPressure 10 Hz, ThrusterPwm 50 Hz, and raw device data
  (hindrax_msgs/RawDeviceData) 300 msg/s over five devices: 590 msg/s in all;
- ramp: one reliable Imu stream at increasing rates; each stage's drops = published - recorded.

"Recorded" is the recorder's own per-topic count (``/diagnostics``), checked against the finished bag.
CPU is the recorder process's user + system time from ``/proc/<pid>/stat`` over the publishing window;
CPU per message = that time / messages recorded. The process and its DDS traffic stay on loopback in a
reserved ROS domain."""
from __future__ import annotations

import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from domain_coordinator import domain_id
from hindrax_bringup.recording.make_test_bags import STREAMS
from hindrax_bringup.recording.metadata import read_metadata
from hindrax_bringup.recording.msgtypes import message_class
from hindrax_common.testing import child_env, child_process, interrupt, python_executable, wait_until
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.serialization import serialize_message

from . import probe_spinning, run_alone
from .machine import proc_cpu_s

NOMINAL = (  # topic suffix, stream in make_test_bags.STREAMS (for the message), rate Hz, best effort
    ("imu/data", "/imu/data", 100.0, True),
    ("imu/mag", "/imu/mag", 100.0, True),
    ("dvl/data", "/dvl/data", 10.0, False),
    ("dvl/range", "/dvl/range", 10.0, False),
    ("ping1d/range", "/ping1d/range", 10.0, False),
    ("depth/pressure", "/depth/pressure", 10.0, False),
    ("thrusters/pwm", "/thrusters/pwm", 50.0, False),
    ("raw/icm20948", "/raw/icm20948", 100.0, False),
    ("raw/ms5837", "/raw/ms5837", 50.0, False),
    ("raw/dvl75", "/raw/dvl75", 50.0, False),
    ("raw/ping1d", "/raw/dvl75", 50.0, False),
    ("raw/pca9685", "/raw/ms5837", 50.0, False),
)
RAMP_RATES_HZ = (1000.0, 2000.0, 3000.0, 4000.0, 6000.0)


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: the reduced CI variant); returns its result rows."""
    nominal_s = 5.0 if quick else 15.0
    stage_s = 2.0 if quick else 3.0
    streams = {s.topic: s for s in STREAMS}
    rng = np.random.default_rng(1)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp, domain_id() as did:
        bag = Path(tmp) / "bench"
        with child_process(
                [python_executable(), "-m", "hindrax_bringup.recording.recorder_node", "--ros-args",
                 "-p", "autostart:=true", "-p", f"output_dir:={bag}", "-p", "topic_regex:=^/bench/",
                 "-p", "discovery_period_s:=0.2", "-p", "status_period_s:=0.2"],
                env=child_env(ROS_DOMAIN_ID=str(did)), stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE) as proc:
            with probe_spinning(did, "recorder_bench", 0.01) as (node, ex, spin):
                counts, lock = subscribe_recorder_counts(node, 10)

                def publishers(spec):
                    out = []
                    for suffix, src, rate, best_effort in spec:
                        s = streams[src]
                        qos = qos_profile_sensor_data if best_effort else QoSProfile(
                            depth=100, reliability=ReliabilityPolicy.RELIABLE)
                        pub = node.create_publisher(message_class(s.type), f"/bench/{suffix}", qos)
                        out.append([pub, serialize_message(s.make(0.5, rng)), rate, f"/bench/{suffix}"])
                    return out

                def run_stage(pubs, duration_s):
                    """Publish on schedule for duration_s; returns (published per topic, recorder CPU s, wall s)."""
                    wait_until(lambda: all(p.get_subscription_count() > 0 for p, *_ in pubs), 20, spin,
                               "recorder subscribed to every benchmark topic")
                    published = {t: 0 for *_, t in pubs}
                    cpu0, t0 = proc_cpu_s(proc.pid), time.monotonic()
                    next_due = [t0 for _ in pubs]
                    ev = threading.Event()
                    while True:
                        now = time.monotonic()
                        if now - t0 >= duration_s:
                            break
                        for i, (pub, data, rate, topic) in enumerate(pubs):
                            while next_due[i] <= now:
                                pub.publish(data)
                                published[topic] += 1
                                next_due[i] += 1.0 / rate
                        ex.spin_once(timeout_sec=0.0)
                        ev.wait(max(0.0, min(next_due) - time.monotonic()))
                    wall = time.monotonic() - t0
                    # let the recorder drain: its count reaches what was published, or stops growing
                    last, stable_since = -1, time.monotonic()
                    deadline = time.monotonic() + 15.0
                    while time.monotonic() < deadline:
                        spin()
                        with lock:
                            got = sum(counts.get(t, 0) for t in published)
                        if got >= sum(published.values()):
                            break
                        if got != last:
                            last, stable_since = got, time.monotonic()
                        elif time.monotonic() - stable_since > 2.0:
                            break
                    cpu = proc_cpu_s(proc.pid) - cpu0
                    with lock:
                        recorded = {t: counts.get(t, 0) for t in published}
                    return published, recorded, cpu, wall

                # --- nominal load
                pubs = publishers(NOMINAL)
                published, recorded, cpu, wall = run_stage(pubs, nominal_s)
                n_pub, n_rec = sum(published.values()), sum(recorded.values())
                rows += [
                    {"name": "nominal offered rate", "value": round(n_pub / wall, 1), "unit": "msg/s",
                     "note": "Imu, Mag 100 Hz; Dvl, 2x Range, Pressure 10 Hz; PWM 50 Hz; raw 300 msg/s"},
                    {"name": "nominal drops", "value": n_pub - n_rec, "unit": "messages", "target": "0",
                     "note": f"{n_pub} published in {wall:.1f} s"},
                    {"name": "nominal recorder CPU", "value": round(100 * cpu / wall, 1), "unit": "% of a core"},
                    {"name": "recorder CPU per message", "value": round(1000 * cpu / max(1, n_rec), 3), "unit": "ms",
                     "note": "executor + raw callback + writer thread + zstd + fsync"},
                ]
                # --- ramp: one reliable Imu stream
                best = 0.0
                ramp_note = []
                for k, rate in enumerate(RAMP_RATES_HZ):
                    pubs = publishers([(f"ramp{k}", "/imu/data", rate, False)])
                    published, recorded, cpu, wall = run_stage(pubs, stage_s)
                    n_pub, n_rec = sum(published.values()), sum(recorded.values())
                    ramp_note.append(f"{n_pub / wall:.0f}/s: {n_pub - n_rec} dropped, {100 * cpu / wall:.0f}% CPU")
                    if n_pub - n_rec == 0:
                        best = max(best, n_pub / wall)
                    else:
                        break
                rows.append({"name": "max sustained rate, zero drops", "value": round(best, 0), "unit": "msg/s",
                             "target": ">= 1180 (2x nominal)", "note": "; ".join(ramp_note)})
            interrupt(proc, 30)
            meta = read_metadata(bag)
            size = sum(p.stat().st_size for p in bag.glob("*.mcap"))
            rows.append({"name": "bag bytes per message", "value": round(size / max(1, meta.message_count), 1),
                         "unit": "B", "note": f"{meta.message_count} messages, zstd chunks (repeated payloads compress "
                                                    "far better than real data)"})
    return rows


def subscribe_recorder_counts(node, depth: int) -> tuple[dict[str, int], "threading.Lock"]:
    """Subscribe ``node`` to ``/diagnostics`` and keep the recorder's per-topic message counts (its
    ``topic:<name>`` values) in the returned dict, guarded by the returned lock."""
    counts: dict[str, int] = {}
    lock = threading.Lock()

    def on_diag(msg: DiagnosticArray) -> None:
        with lock:
            for st in msg.status:
                for kv in st.values:
                    if kv.key.startswith("topic:"):
                        counts[kv.key[6:]] = int(kv.value)

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, depth)
    return counts, lock


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
