"""Actuation benchmark: wrench-in to PCA9685-registers-written latency and CPU per command at 50 Hz.

One process, one EventsExecutor (as the vehicle's ``actuation_node``, composing the two nodes:
``hindrax_bringup.layout.composition``), every thread scheduled as ``vehicle.launch.xml`` starts that
process (``SCHED_FIFO`` at its ``HINDRAX_REALTIME_PRIORITY``; if refused, nice 0 and a note: the p99
is then mostly a shared machine's load): a publisher of geometry_msgs/WrenchStamped at 50 Hz, the
thrust allocation node and the ESC node writing to a register-exact PCA9685 emulator on an emulated
I2C bus. Wrenches alternate two surge levels so T1's pulse width changes with every command; latency
is from ``publish()`` to the I2C write after which the emulator decodes T1's new pulse width. The
ESC node writes a command when its subscription callback takes it (event-driven; the output tick is
the watchdog), so this is two deliveries inside the process (the wrench, the command), the
allocation and one I2C block write. CPU per command is the process CPU time (three nodes and DDS)
over the commands sent.

The allocator alone (:func:`allocator_cost`): thread CPU time of one ``AllocationCore.allocate`` call over random
wrenches from 0.1 N to 30 N, with and without the deadband search (docs/architecture.md §9,
``allocation/deadband.py``), so the search's own cost is the difference of two figures measured in the same process."""
from __future__ import annotations

import os
import time

import numpy as np
import rclpy
from domain_coordinator import domain_id
from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import Header

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_bringup.allocation.node import ThrustAllocationNode
from hindrax_common.config import default_config_path, load_config
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode
from hindrax_common.process.scheduling import apply_realtime_priority, set_every_thread
from hindrax_common.testing import SafetyHeartbeats, config_parameters, ros_context, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_msgs.srv import SetArmed

from . import call, spinning
from .safety import vehicle_scheduling


def allocator_cost(quick: bool = False) -> list[dict]:
    """CPU time per ``AllocationCore.allocate`` call (the allocation node's whole core, FLU in, widths out), in us.

    Wrenches: normal in each axis (N: 1, N m: 0.15) times a size drawn from 0.1, 0.3, 1, 3, 10 and 30, seed 26, so
    most fall where some thruster is asked for less than its smallest thrust (the deadband search runs). Each call is
    timed with ``time.thread_time_ns`` (CPU of this thread: waiting for a core on a shared machine is not counted),
    the least of 3 passes over the list per wrench (a cache miss or interrupt is not the allocator's cost). The passes
    go through the whole list, so no call repeats the one before it: a repeat is answered from the allocator's last
    result (``ThrustAllocator.allocate``), whose cost is ``allocate_cpu_repeat_p50``."""
    n = 300 if quick else 3000
    rng = np.random.default_rng(26)
    sizes = rng.choice([0.1, 0.3, 1.0, 3.0, 10.0, 30.0], size=(n, 1))
    wrenches = rng.normal(size=(n, 6)) * np.array([1.0, 1.0, 1.0, 0.15, 0.15, 0.15]) * sizes
    cfg = load_config(default_config_path())
    cores = {True: AllocationCore(cfg), False: AllocationCore(cfg)}
    cores[False].allocator.reconfigure(deadband_search=False)
    rows = []
    for search, label in ((True, ""), (False, "_without_search")):
        core = cores[search]
        per_call = np.full(n, np.inf)
        for _ in range(3):
            for i, w in enumerate(wrenches):
                t0 = time.thread_time_ns()
                core.allocate(w)
                per_call[i] = min(per_call[i], (time.thread_time_ns() - t0) / 1e3)
        rows += [
            {"name": f"allocate_cpu_p50{label}", "value": float(np.percentile(per_call, 50)), "unit": "us"},
            {"name": f"allocate_cpu_p99{label}", "value": float(np.percentile(per_call, 99)), "unit": "us",
             **({"target": "the search adds well under 1 ms"} if search else {})},
        ]
    repeat = np.empty(n)
    for i, w in enumerate(wrenches):  # each wrench twice in a row: the second call is the repeat
        cores[True].allocate(w)
        t0 = time.thread_time_ns()
        cores[True].allocate(w)
        repeat[i] = (time.thread_time_ns() - t0) / 1e3
    rows.append({"name": "allocate_cpu_repeat_p50", "value": float(np.percentile(repeat, 50)), "unit": "us",
                 "note": "the same wrench as the call before: answered from the allocator's last result"})
    # calls where the search chose other forces than the saturation step (a force fell in a deadband gap)
    changed = sum(not np.array_equal(cores[True].allocate(w).force_n, cores[False].allocate(w).force_n)
                  for w in wrenches)
    rows.append({"name": "allocate_calls_changed_by_search", "value": 100.0 * changed / n, "unit": "%",
                 "note": f"of {n} wrenches"})
    return rows


def run(quick: bool = False) -> list[dict]:
    """The benchmark's rows: wrench-to-registers latency and CPU at 50 Hz, then :func:`allocator_cost`."""
    return wrench_to_registers(150 if quick else 1500) + allocator_cost(quick)


def wrench_to_registers(n_commands: int) -> list[dict]:
    """Rows of the wrench -> PCA9685 registers latency (p50, p99, CPU p99) and CPU per command, ``n_commands`` wrenches
    at 50 Hz through the actuation process's two nodes (module docstring)."""
    cfg = load_config(default_config_path())
    core = AllocationCore(cfg)
    levels = [np.array([8.0, 0, 0, 0, 0, 0]), np.array([14.0, 0, 0, 0, 0, 0])]
    expected = [core.allocate(w).pulse_width_us[0] for w in levels]
    pending: dict = {}
    latencies: list[float] = []
    cpu_latencies: list[float] = []  # process CPU time over the same interval (all threads: executor and DDS)

    class TimedEmulator(Pca9685Emulator):
        def i2c_write(self, data: bytes) -> None:
            super().i2c_write(data)
            if pending and abs(self.pulse_width_us(0) - pending["target"]) < 1.0:
                latencies.append(time.monotonic() - pending.pop("t0"))
                cpu_latencies.append(time.process_time() - pending.pop("cpu0"))
                pending.clear()

    emu = TimedEmulator()
    bus = EmulatedI2CBus({cfg.esc.i2c_address: emu})

    sched = apply_realtime_priority(vehicle_scheduling()["esc"][1])  # DDS threads inherit it
    # a reserved ROS domain: the bench publishes wrenches and arms, which must never reach another graph
    with domain_id() as did, ros_context(domain_id=did) as ctx:
        # the emulated PCA9685 runs at exactly esc.oscillator_hz: calibrated by construction
        params = config_parameters({"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True})
        alloc = ThrustAllocationNode(context=ctx, parameter_overrides=params)
        esc = EscNode(bus=bus, context=ctx, parameter_overrides=params)
        driver = rclpy.create_node("bench_driver", context=ctx)
        SafetyHeartbeats(driver)  # stand-in supervisor and output guard: the ESC arms only with their heartbeats
        with spinning(ctx, alloc, esc, driver, events=True, timeout_s=0.005) as (_ex, spin):
            pub = driver.create_publisher(WrenchStamped, "wrench", 10)
            arm = driver.create_client(SetArmed, "esc/set_armed")
            wait_until(lambda: pub.get_subscription_count() > 0 and arm.service_is_ready()
                       and not esc.heartbeat_refusal() and esc.arming_remaining_s() == 0.0, 10,
                       spin, "graph and the ESC's time at neutral")
            res = call(arm, SetArmed.Request(arm=True), spin, 5)
            if not res.success:
                raise RuntimeError(f"the ESC refused to arm: {res.message}")
            state = {"sent": 0}

            def send() -> None:
                stamp = driver.get_clock().now().to_msg()
                m = WrenchStamped(header=Header(frame_id="base_link", stamp=stamp))
                m.wrench.force.x = float(levels[state["sent"] % 2][0])
                pending.clear()
                pending.update(t0=time.monotonic(), cpu0=time.process_time(), target=expected[state["sent"] % 2])
                pub.publish(m)
                state["sent"] += 1

            driver.create_timer(1.0 / 50.0, send)
            cpu0, wall0 = time.process_time(), time.monotonic()
            wait_until(lambda: state["sent"] >= n_commands, n_commands / 50.0 + 30.0, spin, "commands sent")
            cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    if sched.granted:
        set_every_thread(os.SCHED_OTHER, 0)
    lat_ms = np.array(latencies) * 1e3
    return [
        {"name": "wrench_to_registers_p50", "value": float(np.percentile(lat_ms, 50)), "unit": "ms"},
        {"name": "wrench_to_registers_p99", "value": float(np.percentile(lat_ms, 99)), "unit": "ms",
         "target": "<= 3 ms (event-driven ESC output)", "note": f"SCHED_FIFO {sched.requested}"
         if sched.granted else f"nice 0: {sched.reason or 'no priority in the launch file'}"},
        {"name": "wrench_to_registers_cpu_p99", "value": float(np.percentile(np.array(cpu_latencies) * 1e3, 99)),
         "unit": "ms", "note": "process CPU time over the same interval: the work, not the wait for a core"},
        {"name": "commands_measured", "value": int(lat_ms.size), "unit": "count", "note": f"of {state['sent']} sent"},
        {"name": "cpu_per_command", "value": cpu / state["sent"] * 1e3, "unit": "ms",
         "note": "whole process: publisher + allocation + ESC node"},
        {"name": "cpu_load_at_50hz", "value": cpu / wall * 100.0, "unit": "% of a core"},
    ]
