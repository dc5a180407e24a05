"""Safety benchmark: how fast every disarm path puts all thrusters at neutral, read back on the emulated chip.

One process, one SingleThreadedExecutor, wall-clock ROS time: the ESC node on a register-exact PCA9685 emulator,
the safety supervisor, and a probe (controller, operator, sensors). For each path the vehicle is armed and
commanded to 1700 us on every thruster, then the event happens; the time is taken from the event to the first
I2C transaction after which the emulator decodes every thruster channel at neutral (1500 us within one count):

* ``watchdog``: commands stop; measured from the last command the node took, so it includes ``esc.watchdog_timeout_s``
  (0.5 s in the shipped file); the row ``..._beyond_timeout`` subtracts it (the design bound: one output period);
* ``disarm_service``: ``esc/set_armed`` with ``arm=False`` called;
* ``supervisor_breach``: a ``pressure/depth`` message beyond ``supervisor.max_depth_m`` published;
* ``estop``: ``supervisor/estop`` called;
* ``exception``: a command with a NaN pulse width (a fault in the output path);
* ``shutdown``: :meth:`EscNode.close` (what SIGINT/SIGTERM run through ``run_node``);
* ``chip_reset``: the PCA9685 reset (brown-out) while armed: detect = until the node's read-back finds it
  (``esc.readback_interval_s``, 0.25 s), recover = until neutral is back on the re-initialised chip;
* ``clock_loss``: ``use_sim_time`` and ``/clock`` stops while commanding (the commands stop with it): the
  steady-clock watchdog; measured from the last command the node took (so it includes the 0.5 s timeout).

Process, bus and clock failures (:func:`run_processes`; target 500 ms each), in the vehicle's layout: the
ESC node, the supervisor and the output guard each in its own process (``python -m ...``, EventsExecutor), sharing
an emulated PCA9685 and its /OE line that this process serves over a Unix socket
(:mod:`hindrax_common.transport.shared_emulation`); the bench's own vehicle file wires /OE and watches no sensor:

* ``supervisor_killed|hung_outputs_stopped``: SIGKILL / SIGSTOP of the supervisor while armed at 1700 us, until
  no thruster carries a non-neutral pulse (the ESC's heartbeat disarm or the guard's /OE, whichever is first);
* ``esc_killed|hung_oe_asserted``: SIGKILL / SIGSTOP of the ESC process while armed, until /OE is high;
* ``i2c_outage_state_unknown``: the PCA9685 stops acknowledging, until ``thrusters/pulse_width`` says
  ``OUTPUT_UNKNOWN`` (received by this process);
* ``clock_step_back_detected``: a supervisor on ``use_sim_time``, ``/clock`` (100 Hz from here) steps back 100 s,
  until its ``/diagnostics`` carries ``errors.clock_step``.

A bag of the vehicle replayed on its own domain (:func:`replay_rows`): the same three processes, armed
at 1700 us, recorded for :data:`REPLAY_RECORD_S` by the project's recorder (every topic, as the vehicle launch
records); then that bag is replayed in a loop with every topic, heartbeats and commands included (the worst case:
the player with ``safety_topics`` and its graph check off, as a tool without that check would publish), and the
supervisor is SIGKILLed :data:`REPLAY_LEAD_S` after the replay's first message:

* ``supervisor_killed_during_replay_thrust_after_kill``: from the kill until no thruster carries a non-neutral pulse
  (0 when the outputs had already stopped; :data:`REPLAY_CENSOR_S` when thrust was still on then, counted in the note);
* ``replay_alone_stopped_outputs``: the repeats in which the replay itself stopped the outputs before the kill (a
  second heartbeat publisher is a fault), with the time from the replay process's start in the note.

The same layout serves the section's other modules (their rows in their own docstrings):
:mod:`.participant_churn` and :mod:`.sealed_authority`.

The hardware watchdog on /OE (:func:`frozen_rows`, docs/watchdog.md): the bench's layout has it fitted
(the emulated monostable ORed into /OE, ``esc.output_enable_feed_timeout_s`` 0.33 s, fed by the guard at 10 Hz):

* ``launch_frozen_outputs_stopped``: SIGSTOP of the guard, the ESC and the supervisor while armed at 1700 us, until
  no thruster carries a pulse (the watchdog runs out: the guard's own /OE line stays low);
* ``guard_without_line_arming_refused``: the guard started while its /OE line is busy (the request fails); the arm
  requests refused of those made, then the line is granted and the time until an arm is accepted is in the note.

A partial freeze without the hardware watchdog (:func:`partial_freeze_rows`; the shipped vehicle file has no feed line):
the same layout with /OE but no feed, its processes under :class:`SystemdWatchdogStandIn` (what systemd does for the
bare-metal unit: ``WatchdogSec`` :data:`UNIT_WATCHDOG_S`, SIGKILL; without systemd's timer slack of up to 0.25 s):

* ``partial_freeze_no_feed_outputs_stopped_ms``: SIGSTOP of the ESC and the guard while the supervisor runs, armed
  at 1700 us, until no thruster carries a pulse (the guard's pings stop, the unit is killed, the freed /OE line
  goes high). The Docker unit has no watchdog (no ``$NOTIFY_SOCKET`` in the container): there only the feed stops it.

Each path is repeated (:data:`QUICK_REPEATS` times with ``--quick``, otherwise :data:`REPEATS` in-process and
:data:`PROCESS_REPEATS` for the process failures); rows give the median and the maximum in ms."""
from __future__ import annotations

import functools
import json
import os
import signal as _signal
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numpy as np
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from domain_coordinator import domain_id
from geometry_msgs.msg import PoseWithCovarianceStamped
from hindrax_common.node_support.liveness import HEARTBEAT_NAMES, heartbeat_qos
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_drivers.pca9685.node import EscNode
from hindrax_bringup.recording.reader import BagReader
from hindrax_common.process.scheduling import PRIORITY_ENV
from hindrax_bringup.supervisor.node import SupervisorNode
from hindrax_common.testing import (AllocationStandIn, ConditionTimeout, GraphSettled,
                                     SafetyHeartbeats, child_env, child_process, config_parameters,
                                     interrupt, python_executable, ros_context, wait_until)
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.gpio import EmulatedGpioLine, WatchdogFeedLine, WatchedOutputEnable
from hindrax_common.transport.shared_emulation import SOCKET_ENV, EmulationServer
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from hindrax_common.config import default_config_path, load_config
from hindrax_msgs.msg import Heartbeat, ThrusterPwm
from hindrax_msgs.srv import SetArmed

from . import call, spin_for, start_logged, stop_processes
from .launch_layout import launch_processes, package_share
from .machine import proc_cpu_s

NEUTRAL_US = 1500.0
#: Repeats per path: in-process paths, process failures (kill/stop/outage/brown-out), and both with ``--quick``
#: (docs/architecture.md §8.1 quotes them; test/test_docs_truth.py compares).
REPEATS = 6
PROCESS_REPEATS = 5
#: arm requests per :meth:`_Layout.armed_at_1700` when the ESC disarms itself before thrust reaches the wire
ARM_ATTEMPTS = 3
QUICK_REPEATS = 3
#: no sensors run in this bench: every supervisor rate check off, with the reason the configuration requires
NO_SENSORS = {**{f"supervisor.min_rate.{s}_hz": 0.0 for s in ("dvl", "altimeter", "pressure", "imu")},
              **{f"supervisor.rate_check_disabled.{s}": "safety bench: no sensors simulated"
                 for s in ("dvl", "altimeter", "pressure", "imu")}}
TICK_US = 1.3  # one PCA9685 count at 200 Hz is 1.24 us (docs/devices.md §5.1)


def _rig(ctx, sim_time: bool = False):
    class TimedEmulator(Pca9685Emulator):
        """Records the monotonic time of the first transaction that leaves every thruster channel at neutral."""

        watch = False
        neutral_at: float | None = None

        def i2c_write(self, data: bytes) -> None:
            super().i2c_write(data)
            if self.watch and self.neutral_at is None and self.all_neutral():
                self.neutral_at = time.monotonic()

        def all_neutral(self) -> bool:
            return all(abs(self.pulse_width_us(c) - NEUTRAL_US) < TICK_US for c in range(8))

    emu = TimedEmulator()
    # the emulated chip runs at exactly esc.oscillator_hz (calibrated by construction); sensors not simulated here,
    # so the supervisor's rate checks are off
    over = {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True, **NO_SENSORS}
    params = config_parameters(over) + ([Parameter("use_sim_time", value=True)] if sim_time else [])
    esc = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx, parameter_overrides=params)
    sup = SupervisorNode(context=ctx, parameter_overrides=params)
    probe = rclpy.create_node("bench_safety", context=ctx)
    SafetyHeartbeats(probe, supervisor=None)  # the output guard's heartbeat (the supervisor is real)
    ex = SingleThreadedExecutor(context=ctx)
    for n in (esc, sup, probe):
        ex.add_node(n)
    allocation = AllocationStandIn(ctx)  # the one commander the ESC accepts
    r = dict(emu=emu, esc=esc, sup=sup, probe=probe, ex=ex, allocation=allocation, cmd=allocation.pub,
             depth=probe.create_publisher(PoseWithCovarianceStamped, "pressure/depth", 10),
             clock=probe.create_publisher(Clock, "/clock", 10), arm=probe.create_client(SetArmed, "esc/set_armed"),
             estop=probe.create_client(Trigger, "supervisor/estop"),
             reset=probe.create_client(Trigger, "supervisor/reset"), ns=1_000_000_000)

    def spin(timeout_s: float = 0.002) -> None:
        if sim_time:
            r["ns"] += 2_000_000
            r["clock"].publish(Clock(clock=Time(nanoseconds=r["ns"]).to_msg()))
        ex.spin_once(timeout_sec=timeout_s)

    def command(width: float = 1700.0) -> None:
        r["cmd"].publish(ThrusterPwm(pulse_width_us=[width] * 8, armed=True))

    def commanding() -> None:  # one 1700 us command, then one spin
        command()
        spin()

    def armed_at_1700() -> None:
        # the previous path's disarm (and any supervisor disarm request) has landed before the reset and re-arm
        emu.watch = False
        if esc.armed:  # the watchdog neutralises but stays armed
            call(r["arm"], SetArmed.Request(arm=False), spin)
        settled = lambda: not esc.armed and not sup.core.armed and (  # noqa: E731
            sup.disarm_future is None or sup.disarm_future.done())
        wait_until(settled, 10, spin, "previous disarm settled")
        t_quiet = time.monotonic() + 0.3  # > DISARM_RETRY_S (supervisor.core): no retry on its way
        wait_until(lambda: time.monotonic() > t_quiet and settled(), 10, spin, "previous disarm settled")
        call(r["reset"], Trigger.Request(), spin)
        emu.watch, emu.neutral_at = False, None
        wait_until(lambda: esc.neutral_confirmed_time is not None and esc.arming_remaining_s() == 0.0
                   and not esc.heartbeat_refusal(), 20, spin, "ESC ready")
        res = call(r["arm"], SetArmed.Request(arm=True), spin)
        if not res.success:
            raise RuntimeError(f"arming refused: {res.message}")
        wait_until(lambda: emu.pulse_width_us(0) > 1690.0 and sup.core.armed, 20, commanding, "1700 us on the wire")
        emu.watch = True

    def until_neutral(timeout_s: float = 10.0, poll=None) -> float:
        wait_until(lambda: emu.neutral_at is not None, timeout_s, poll or spin, "neutral on the chip")
        return emu.neutral_at

    wait_until(lambda: r["cmd"].get_subscription_count() > 0 and r["arm"].service_is_ready()
               and r["estop"].service_is_ready() and sup.esc_client.service_is_ready(), 20, spin, "graph ready")
    r.update(spin=spin, command=command, commanding=commanding, armed_at_1700=armed_at_1700,
             until_neutral=until_neutral)
    return r


def _close(r) -> None:
    r["ex"].shutdown()
    for n in (r["probe"], r["sup"], r["esc"], r["allocation"].node):
        n.destroy_node()


def _ms_row(name: str, seconds, **extra) -> dict:
    """A row of times ``seconds`` (s): their median in ms, with ``max`` (ms) and ``n``, plus ``extra`` keys."""
    ms = np.asarray(seconds, dtype=float) * 1e3
    return {"name": name, "value": float(np.median(ms)), "unit": "ms", "max": float(np.max(ms)),
            "n": int(ms.size), **extra}


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: the reduced CI variant); returns its result rows."""
    repeats = QUICK_REPEATS if quick else REPEATS
    times: dict[str, list[float]] = {k: [] for k in (
        "watchdog", "watchdog_beyond_timeout", "disarm_service", "supervisor_breach", "estop", "exception",
        "shutdown", "chip_reset_detect", "chip_reset_recover", "clock_loss")}
    # a reserved ROS domain: this bench trips supervisors and calls e-stops, which must never reach another graph
    with domain_id() as did, ros_context(domain_id=did) as ctx:
        r = _rig(ctx)
        esc, emu = r["esc"], r["emu"]
        watchdog_s = esc.watchdog_s

        def deep():  # a fresh sample beyond the depth limit (a stamp-0 one is not alive)
            m = PoseWithCovarianceStamped()
            m.header.stamp = r["sup"].get_clock().now().to_msg()
            m.pose.pose.position.z = -(r["sup"].core.limits.max_depth_m + 0.1)
            return m

        #: each path's event (a service call returns its future, answered before the next path)
        events = {"disarm_service": lambda: r["arm"].call_async(SetArmed.Request(arm=False)),
                  "supervisor_breach": lambda: r["depth"].publish(deep()),
                  "estop": lambda: r["estop"].call_async(Trigger.Request()),
                  "exception": lambda: r["command"](float("nan")),  # a fault in the output path
                  "shutdown": esc.close}
        for _ in range(repeats):
            # watchdog: the controller stops
            r["armed_at_1700"]()
            # from the last command the node took (steady clock)
            dt = r["until_neutral"]() - esc._steady_command
            times["watchdog"].append(dt)
            times["watchdog_beyond_timeout"].append(dt - watchdog_s)
            for name, event in events.items():  # from the event to neutral on the chip
                r["armed_at_1700"]()
                t0 = time.monotonic()
                fut = event()
                times[name].append(r["until_neutral"]() - t0)
                if fut is not None:
                    wait_until(fut.done, 5, r["spin"], f"{name} answer")
            # chip reset (brown-out) while armed and commanding
            r["armed_at_1700"]()
            emu.watch = False
            reinits = esc.link.chip_reinits
            t0 = time.monotonic()
            emu.reset()
            emu.watch, emu.neutral_at = True, None
            wait_until(lambda: esc.link.chip_reinits > reinits, 10, r["commanding"], "chip reset detected")
            times["chip_reset_detect"].append(esc.link.last_chip_reinit_monotonic - t0)
            times["chip_reset_recover"].append(r["until_neutral"](poll=r["commanding"]) - t0)
        _close(r)
        # /clock loss: the steady-clock watchdog
        rs = _rig(ctx, sim_time=True)
        for _ in range(repeats):
            rs["armed_at_1700"]()  # returns right after the last /clock message
            t_neutral = rs["until_neutral"](poll=lambda: rs["ex"].spin_once(timeout_sec=0.002))
            times["clock_loss"].append(t_neutral - rs["esc"]._steady_command)
        _close(rs)

    notes = {"watchdog": f"from the last command; includes esc.watchdog_timeout_s = {watchdog_s:g} s",
             "watchdog_beyond_timeout": "design bound: one output period (20 ms at 50 Hz)",
             "chip_reset_detect": "read-back every esc.readback_interval_s (0.25 s)",
             "chip_reset_recover": "re-initialised at neutral, disarmed",
             "clock_loss": "use_sim_time, /clock stops: steady-clock watchdog (includes the 0.5 s timeout)"}
    plain = ("chip", "clock")  # the others are named for the time until neutral
    rows = [_ms_row(f"{'' if name.startswith(plain) else 'neutral_after_'}{name}_ms", values,
                    **({"note": notes[name]} if name in notes else {}))
            for name, values in times.items()]
    return (rows + run_processes(quick) + replay_rows(quick) + frozen_rows(quick) + partial_freeze_rows(quick)
            + gc_rows(quick))


# ------------------------------------------------------------------------------------ garbage collection pauses
# A full collection holds the GIL of a node process for as long as it traverses the heap (ros_process.py, "Garbage
# collection"). Measured in a fresh interpreter per process of the vehicle layout that has a safety tick: the
# modules it runs imported and rclpy initialised, then gc.collect() timed (CPU of the process) before and after
# freeze_startup_heap(), which RosProcess.spin() calls once the nodes are built.

GC_PROCESSES = {"actuation": ["hindrax_bringup.layout.composition", "hindrax_bringup.allocation.node",
                              "hindrax_drivers.pca9685.node"],
                "supervisor": ["hindrax_bringup.supervisor.node"], "output_guard": ["hindrax_bringup.guard.node"]}

_GC_PROBE = r"""
import gc, importlib, json, sys, time
import rclpy
for name in sys.argv[2:]:
    importlib.import_module(name)
rclpy.init(args=[])
from hindrax_common.process.ros_process import freeze_startup_heap

def full_collection_ms():
    out = []
    for _ in range(int(sys.argv[1])):
        t = time.process_time()
        gc.collect()
        out.append((time.process_time() - t) * 1e3)
    return sorted(out)[len(out) // 2]

before, objects = full_collection_ms(), len(gc.get_objects())
frozen = freeze_startup_heap()
print(json.dumps({"unfrozen": before, "frozen": full_collection_ms(), "objects": objects, "frozen_objects": frozen}))
rclpy.shutdown()
"""


def gc_rows(quick: bool = False) -> list[dict]:
    """Rows ``gc_full_collection_cpu_ms_<process>`` (frozen: what a full collection costs once the process spins)
    and ``..._unfrozen`` (the same heap without :func:`~hindrax_common.process.ros_process.freeze_startup_heap`),
    median CPU ms of 3 (quick) or 7 collections, for each process of :data:`GC_PROCESSES`."""
    rows = []
    for label, modules in GC_PROCESSES.items():
        out = subprocess.run([python_executable(), "-c", _GC_PROBE, "3" if quick else "7", *modules],
                             env=child_env(), capture_output=True, text=True, timeout=300, check=True)
        got = json.loads(out.stdout.strip().splitlines()[-1])
        rows.append({"name": f"gc_full_collection_cpu_ms_{label}_unfrozen", "value": got["unfrozen"], "unit": "ms",
                     "note": f"{got['objects']} objects tracked after start-up ({', '.join(modules)} imported)"})
        rows.append({"name": f"gc_full_collection_cpu_ms_{label}", "value": got["frozen"], "unit": "ms",
                     "target": 20.0, "note": f"after RosProcess.spin froze {got['frozen_objects']} objects; the "
                     "heartbeat timeouts are 200 ms, and the Pi 4 is about 6x slower (README)"})
    return rows


# ---------------------------------------------------------------------------------------------- process failures
# The vehicle layout (vehicle.launch.xml): the ESC node, the supervisor and the output guard each in their own
# process, sharing the PCA9685 and its /OE line. Here this process holds the emulated chip and line and serves them
# (hindrax_common.transport.shared_emulation: a killed client's line returns to its pull-up, as the kernel frees a
# dead process's request); the three nodes run as `python -m <module>` with HINDRAX_EMULATION_SOCKET set.

PROCESSES = {"esc": "hindrax_drivers.pca9685.node", "supervisor": "hindrax_bringup.supervisor.node",
             "guard": "hindrax_bringup.guard.node"}
#: the vehicle launch file's process of each (vehicle.launch.xml): its scheduling is theirs here
VEHICLE_EXECUTABLES = {"esc": "actuation_node", "supervisor": "supervisor_node", "guard": "output_guard_node"}


@functools.cache
def vehicle_scheduling() -> dict[str, tuple[tuple[str, ...], dict[str, str]]]:
    """Name of :data:`PROCESSES` -> (launch prefix, environment additions) that ``vehicle.launch.xml`` starts its
    process with: ``nice -n -5`` and ``HINDRAX_REALTIME_PRIORITY`` (docs/deployment.md §1,
    :mod:`hindrax_common.process.scheduling`), read from the launch file, so a benchmark schedules the safety processes
    as the vehicle does. Read once per process (the launch file and the installed console scripts)."""
    read = {lp.process.executable: lp.process for lp in
            launch_processes(package_share("hindrax_bringup") / "launch" / "vehicle.launch.xml")}
    return {name: (tuple(read[exe].launch_prefix),
                   {k: v for k, v in read[exe].env if k == PRIORITY_ENV}) for name, exe in VEHICLE_EXECUTABLES.items()}


#: the emulated hardware watchdog's timeout (the circuit of docs/watchdog.md §3: 330 kOhm x 1.0 uF), s
WATCHDOG_TIMEOUT_S = 0.33


class _Hardware:
    """The emulated PCA9685 with /OE and the hardware watchdog on it (docs/watchdog.md), served to the node processes;
    records when the outputs stop. :attr:`line_busy`: the /OE line refuses requests (another consumer holds it)."""

    def __init__(self, sock: str, feed: bool = True) -> None:
        hw = self
        self.line_busy = False

        class Line(EmulatedGpioLine):
            def set_high(self, high: bool) -> None:
                if hw.line_busy:
                    raise OSError(16, "Device or resource busy")
                super().set_high(high)
                hw._event()

            def release(self) -> None:
                super().release()
                hw._event()

        class Chip(Pca9685Emulator):
            def i2c_write(self, data: bytes) -> None:
                super().i2c_write(data)
                hw._event()

        class Feed(WatchdogFeedLine):
            def set_high(self, high: bool) -> None:
                super().set_high(high)
                hw._event()

        self.line = Line(pull_high=True)
        self.feed = Feed(WATCHDOG_TIMEOUT_S) if feed else None  # None: no hardware watchdog fitted
        self.emu = Chip(output_enable_line=WatchedOutputEnable(self.line, self.feed) if feed else self.line)
        self.bus = EmulatedI2CBus({0x40: self.emu})
        self.server = EmulationServer(sock, bus=self.bus, lines={"oe": self.line, **({"oe_feed": self.feed} if feed
                                                                                      else {})})
        self.watch = False
        self.stopped_at: float | None = None  # every thruster at neutral or without pulses
        self.oe_at: float | None = None  # /OE high

    def thrust(self) -> bool:
        return any(abs(self.emu.pulse_width_us(c) - NEUTRAL_US) > TICK_US and self.emu.pulse_width_us(c) > 0.0
                   for c in range(8))

    def _event(self) -> None:
        if not self.watch:
            return
        t = time.monotonic()
        if self.oe_at is None and self.line.is_high():
            self.oe_at = t
        if self.stopped_at is None and not self.thrust():
            self.stopped_at = t

    def stop_time(self) -> float | None:
        """Monotonic time at which the outputs stopped: the first event that left no thrust, or the watchdog's
        run-out (no event marks it), whichever came first; None while thrust is on."""
        if self.thrust():
            return None
        ran_out = self.feed is not None and self.feed.expired()
        times = [t for t in (self.stopped_at, self.feed.expires_at() if ran_out else None) if t is not None]
        return min(times) if times else time.monotonic()


def _config_file(tmp, feed: bool = True) -> str:
    """The shipped vehicle file with /OE wired, no sensors watched, no arming hold (the bench's own file); ``feed``:
    the hardware watchdog's feed line wired too (the shipped file has none)."""
    doc = yaml.safe_load(default_config_path().read_text())
    params = doc["/**"]["ros__parameters"]
    for key, value in {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True,
                       "esc.watchdog_timeout_s": 2.0, **NO_SENSORS}.items():
        *path, leaf = key.split(".")
        node = params
        for p in path:
            node = node.setdefault(p, {})
        node[leaf] = value
    params["esc"]["output_enable_gpio"] = {"chip": "/dev/gpiochip0", "line": 17}  # served by _Hardware
    if feed:
        params["esc"]["output_enable_feed_gpio"] = {"chip": "/dev/gpiochip0", "line": 27}  # the watchdog's feed
        params["esc"]["output_enable_feed_rate_hz"] = 10.0
        params["esc"]["output_enable_feed_timeout_s"] = WATCHDOG_TIMEOUT_S
    path = tmp / "vehicle.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


class _Layout:
    """The three node processes, restartable, with a probe (commands at 50 Hz, arm/disarm, state) in this one."""

    def __init__(self, ctx, did: int, tmp, hw: _Hardware) -> None:
        self.ctx, self.tmp, self.hw = ctx, tmp, hw
        self.config = _config_file(tmp, feed=self.feed)
        self.vehicle = load_config(self.config).vehicle.name  # validated like any vehicle file
        # unbuffered logs: a failure prints the processes' last lines while they still run
        self.env = child_env(ROS_DOMAIN_ID=str(did), RCUTILS_LOGGING_BUFFERED_STREAM="0", PYTHONUNBUFFERED="1",
                             **{SOCKET_ENV: hw.server.path}, **self.unit_env())
        self.py = python_executable()
        self.procs: dict = {}
        self.probe = rclpy.create_node("bench_safety_layout", context=ctx)
        self.arm_client = self.probe.create_client(SetArmed, "esc/set_armed")
        self.reset_client = self.probe.create_client(Trigger, "supervisor/reset")
        self.allocation = AllocationStandIn(ctx)  # the one commander the ESC accepts
        self.commanding = False
        self.last_state: tuple[float, int] | None = None  # (monotonic receive time, output_state)
        self.last_msg = None  # the last thrusters/pulse_width (for the failure message)
        self.arming = False  # from just before an arm request until the next step stops commanding
        self.seen_armed = False  # thrusters/pulse_width said armed since the last arm request
        self.disarmed_after_arm = False  # ... and then disarmed, before 1700 us reached the wire
        self.rearms: list[str] = []  # why the ESC disarmed itself right after an arm (its log line)
        self.last_esc_diag: str = ""
        self.unknown_at: float | None = None
        self.diag: list[tuple[float, object]] = []
        self.probe.create_timer(0.02, lambda: self.commanding and self.allocation.pub.publish(
            ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True)))
        self.probe.create_subscription(ThrusterPwm, "thrusters/pulse_width", self._on_state, 50)
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 50)
        self.ex = SingleThreadedExecutor(context=ctx)
        self.ex.add_node(self.probe)
        self._spin = True
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while self._spin:
            self.ex.spin_once(timeout_sec=0.01)

    def _on_state(self, msg) -> None:
        t = time.monotonic()
        self.last_state = (t, msg.output_state)
        self.last_msg = msg
        # from before the request: the armed state may come before its answer is read
        if self.arming:
            if msg.armed:
                self.seen_armed = True
            elif self.seen_armed:
                self.disarmed_after_arm = True
        if msg.output_state == ThrusterPwm.OUTPUT_UNKNOWN and self.unknown_at is None:
            self.unknown_at = t

    def _on_diag(self, msg) -> None:
        t = time.monotonic()
        for st in msg.status:
            if st.hardware_id == "esc" or "esc" in st.name or "pca9685" in st.name:
                self.last_esc_diag = f"{st.name}: {st.message} " + ", ".join(f"{kv.key}={kv.value}" for kv in st.values)
            if st.name == "hindrax/supervisor" and any(kv.key == "errors.clock_step" for kv in st.values):
                self.diag.append((t, st))

    #: the hardware watchdog on /OE fitted (its feed line in the vehicle file)
    feed = True

    def unit_env(self) -> dict[str, str]:
        """Environment a service manager gives the node processes (none here; :class:`_UnitLayout`)."""
        return {}

    # -- processes
    #: False: the real-time priority withheld (the launch file's nice -5 only), for a comparison
    realtime = True
    #: True: each node process in a session of its own, as a launched process is (the project's runner, a systemd
    #: service), so that the kernel's session autogroups rank it as on the vehicle
    #: (hindrax_common/process/scheduling.py)
    new_session = False

    def start(self, name: str, extra: tuple = ()) -> None:
        # scheduled as vehicle.launch.xml starts the safety processes (real-time, nice -5 where refused;
        # docs/deployment.md §1): on a machine shared with other jobs a 0.33 s gap in the guard's feed would be the
        # machine's load, not the failure measured
        prefix, env = vehicle_scheduling()[name]
        argv = [*prefix, self.py, "-m", PROCESSES[name], "--ros-args", "--params-file", self.config, *extra]
        self.procs[name] = start_logged(self.tmp / f"{name}.log", argv, "a",
                                        env=dict(self.env, **(env if self.realtime else {})),
                                        start_new_session=self.new_session)

    def ensure(self) -> None:
        for name in PROCESSES:
            p = self.procs.get(name)
            if p is None or p.poll() is not None:
                self.start(name)

    def signal(self, name: str, sig: int) -> None:
        self.procs[name].send_signal(sig)

    def kill(self, name: str) -> None:
        p = self.procs.pop(name)
        p.send_signal(_signal.SIGKILL)
        p.wait(10)

    def close(self) -> None:
        """Stop every process (:func:`~hindrax_tools.benchmarks.stop_processes`, SIGKILL after 5 s)."""
        self.commanding = False
        stop_processes([self.procs.pop(name) for name in list(self.procs)], wait_s=5.0)
        self._spin = False
        self.thread.join(5)
        self.ex.shutdown()
        self.probe.destroy_node()
        self.allocation.destroy()

    def _last_log_line(self, name: str, containing: str) -> str:
        """The last line of process ``name``'s log that contains ``containing`` ('' when none)."""
        path = self.tmp / f"{name}.log"
        lines = [ln for ln in path.read_text().splitlines() if containing in ln] if path.exists() else []
        return lines[-1] if lines else ""

    def process_states(self) -> str:
        """Each node process's state (running, exited N, not started), its heartbeat's
        publishers in the probe's graph and its last log line, for a failure message."""
        states = []
        for name in PROCESSES:
            p = self.procs.get(name)
            state = ("not started" if p is None else "running" if p.poll() is None
                     else f"exited {p.returncode}")
            beats = self.probe.count_publishers(HEARTBEAT_NAMES[name])
            states.append(f"{name} {state}, {beats} heartbeat publisher(s), last log line "
                          f"{self._last_log_line(name, '')!r}")
        return "; ".join(states)

    # -- vehicle
    def call(self, client, request, timeout: float = 3.0, attempts: int = 10):
        """A service call, asked again when no answer comes (a killed server's endpoint is still discovered for a
        while after its restart: the request goes nowhere)."""
        for _ in range(attempts):
            fut = client.call_async(request)
            try:
                wait_until(fut.done, timeout, None, "service answer")
                return fut.result()
            except ConditionTimeout:
                client.remove_pending_request(fut)
        raise ConditionTimeout(f"no answer from {client.srv_name} after {attempts} attempts of "
                               f"{timeout:g} s; {self.process_states()}")

    def armed_at_1700(self) -> None:
        """(Re)start what is not running, arm (retrying while the ESC still refuses), command 1700 us until it is
        on the wire."""
        self.hw.watch = False
        self.commanding = self.arming = False
        self.ensure()
        # up: the two services, and each safety heartbeat in the graph (the ESC refuses to arm
        # while the guard's is not: a guard still starting on a loaded machine is no refusal)
        def up() -> bool:
            return (self.arm_client.service_is_ready() and self.reset_client.service_is_ready()
                    and all(self.probe.count_publishers(t) for t in HEARTBEAT_NAMES.values()))
        wait_until(up, 60, None, "processes up")
        if self.last_msg is not None and self.last_msg.armed:
            # still armed from the caller's previous step, its commands stopped above: disarm first, or the 1700 us
            # found on the wire below may be the old arm's, with the ESC watchdog's neutral still to come
            self.call(self.arm_client, SetArmed.Request(arm=False))
            wait_until(lambda: not self.last_msg.armed and not self.hw.thrust(), 10, None, "disarmed")
        self.call(self.reset_client, Trigger.Request())
        answer = [""]

        def arm() -> bool:
            res = self.call(self.arm_client, SetArmed.Request(arm=True))
            answer[0] = res.message
            if not res.success:
                time.sleep(0.05)  # the ESC refuses until the guard has released /OE: ask again
            return res.success
        for _ in range(ARM_ATTEMPTS):
            self.seen_armed = self.disarmed_after_arm = False
            self.arming = True
            try:
                wait_until(arm, 30, None, "armed")
            except Exception as exc:
                raise RuntimeError(f"{exc}: last answer {answer[0]!r}; "
                                   f"{self.process_states()}") from exc
            self.commanding = True
            try:
                wait_until(lambda: self.disarmed_after_arm or (
                    self.hw.thrust() and self.hw.emu.pulse_width_us(0) > 1690.0), 10, None, "1700 us on the wire")
            except ConditionTimeout as exc:
                m = self.last_msg
                state = "none" if m is None else (
                    f"armed={m.armed} output_state={m.output_state} widths={list(m.pulse_width_us)[:2]} "
                    f"{time.monotonic() - self.last_state[0]:.2f} s ago")
                raise RuntimeError(f"{exc}: arm answered {answer[0]!r}; last thrusters/pulse_width {state}; chip "
                                   f"channel 0 {self.hw.emu.pulse_width_us(0):.1f} us, /OE high "
                                   f"{self.hw.line.is_high()}; last ESC diagnostics: {self.last_esc_diag}") from exc
            if not self.disarmed_after_arm:
                break
            # the ESC disarmed itself between the arm and the first thrust: say why, and arm again
            self.commanding = False
            self.rearms.append(self._last_log_line("esc", "disarming"))
        else:
            raise RuntimeError(f"the ESC disarmed itself after each of {ARM_ATTEMPTS} arms: {self.rearms[-3:]}")
        self.unknown_at = None
        self.hw.stopped_at = self.hw.oe_at = None
        self.hw.watch = True


@contextmanager
def running_layout(prefix: str, did: int | None = None, layout: type[_Layout] = _Layout) -> Iterator[_Layout]:
    """A ``layout`` (:class:`_Layout` or a subclass) on a new :class:`_Hardware`, in a new temporary folder named
    ``prefix...``, on ROS domain ``did`` (a free one reserved when None) with its own rclpy context. The node
    processes are started by the layout's own calls (``armed_at_1700``, ``ensure``). Yields the layout (``.hw``,
    ``.ctx``, ``.tmp``, ``.probe``); when the body raises, the last 15 lines of each process's log are printed
    before the error propagates; the layout and the hardware are closed on the way out."""
    with tempfile.TemporaryDirectory(prefix=prefix) as d, \
            (nullcontext(did) if did is not None else domain_id()) as did, ros_context(domain_id=did) as ctx:
        tmp = Path(d)
        hw = _Hardware(str(tmp / "emulation.sock"), feed=layout.feed)
        lay = layout(ctx, did, tmp, hw)
        try:
            yield lay
        except Exception:
            for f in sorted(tmp.glob("*.log")):  # what the node processes said
                print(f"--- {f.name}\n" + "\n".join(f.read_text().splitlines()[-15:]), flush=True)
            raise
        finally:
            lay.close()
            hw.server.close()


#: the bare-metal unit's WatchdogSec (docker/hindrax-bare-metal.service), s
UNIT_WATCHDOG_S = 0.2


class SystemdWatchdogStandIn:
    """What systemd does for the bare-metal unit (``Type=notify``, ``NotifyAccess=all``, ``WatchdogSec``,
    ``WatchdogSignal=SIGKILL``; systemd.service(5)): a datagram socket at ``path`` for ``$NOTIFY_SOCKET``; once
    READY=1 came, when no WATCHDOG=1 arrives for ``watchdog_s`` every process ``pids()`` lists gets SIGKILL (the unit
    is stopped; ``Restart=`` would start it again). :attr:`fired_at`: monotonic time of the last kill. systemd's own
    timer may fire up to its event loop's default accuracy (250 ms, sd_event_add_time(3)) later; this one polls
    every 5 ms."""

    def __init__(self, path: str, watchdog_s: float, pids) -> None:
        self.path, self.watchdog_s, self.pids = path, float(watchdog_s), pids
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(path)
        self.sock.settimeout(0.005)
        self.ready = False
        self.last_ping = time.monotonic()
        self.pings = 0
        self.fired_at: float | None = None
        self._run = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def env(self) -> dict[str, str]:
        """``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` as systemd sets them for the unit's processes."""
        return {"NOTIFY_SOCKET": self.path, "WATCHDOG_USEC": str(int(round(self.watchdog_s * 1e6)))}

    def _loop(self) -> None:
        while self._run:
            try:
                for state in self.sock.recv(256).decode(errors="replace").split("\n"):
                    if state == "READY=1" and not self.ready:
                        self.ready, self.last_ping = True, time.monotonic()
                    elif state == "WATCHDOG=1":
                        self.pings += 1
                        self.last_ping = time.monotonic()
            except OSError:
                pass
            if self.ready and time.monotonic() - self.last_ping > self.watchdog_s:
                self.fired_at = time.monotonic()
                self.ready = False  # the unit is stopped; its next start sends READY=1 again
                for pid in self.pids():
                    try:
                        os.kill(pid, _signal.SIGKILL)
                    except ProcessLookupError:
                        pass

    def close(self) -> None:
        self._run = False
        self.thread.join(5)
        self.sock.close()


class _UnitLayout(_Layout):
    """The layout as the bare-metal unit runs it, with the shipped vehicle file's wiring (/OE, no watchdog feed):
    the node processes under :class:`SystemdWatchdogStandIn` (:attr:`unit`)."""

    feed = False

    def unit_env(self) -> dict[str, str]:
        self.unit = SystemdWatchdogStandIn(str(self.tmp / "notify"), UNIT_WATCHDOG_S,
                                           lambda: [p.pid for p in self.procs.values() if p.poll() is None])
        return self.unit.env()

    def close(self) -> None:
        super().close()
        self.unit.close()


def partial_freeze_rows(quick: bool = False) -> list[dict]:
    """Row of a partial freeze without the /OE watchdog feed (module docstring): SIGSTOP of the ESC and the guard
    while the supervisor runs, armed at 1700 us, until no thruster carries a pulse (the unit stopped, the guard's
    line freed, /OE at its pull-up)."""
    repeats = QUICK_REPEATS if quick else PROCESS_REPEATS
    stopped: list[float] = []
    with running_layout("hindrax-bench-partial-", layout=_UnitLayout) as lay:
        lay.ensure()
        wait_until(GraphSettled(lay.probe, quiet_s=3.0, min_nodes=3), 90, None, "graph settled")
        for _ in range(repeats):
            stopped.append(partial_freeze_stop_s(lay))
    return [_ms_row("partial_freeze_no_feed_outputs_stopped_ms", stopped, target=500.0,
                    note="SIGSTOP of ESC and guard while the supervisor runs, armed at 1700 us, "
                         "no watchdog feed; the guard's pings stop, the unit's watchdog "
                         f"({UNIT_WATCHDOG_S:g} s, systemd's behaviour emulated without its timer "
                         "slack of up to 250 ms) kills the unit, the freed /OE line goes high")]


def partial_freeze_stop_s(lay: _UnitLayout, timeout_s: float = 10.0) -> float:
    """Arm ``lay`` at 1700 us, SIGSTOP its ESC and guard; seconds until the outputs stopped (ConditionTimeout
    after ``timeout_s``). The unit's processes are killed on the way; the next arm starts them again."""
    hw = lay.hw
    lay.armed_at_1700()
    wait_until(lambda: lay.unit.ready, 30, None, "READY=1 from the guard")
    t0 = time.monotonic()
    for name in ("guard", "esc"):
        lay.signal(name, _signal.SIGSTOP)
    wait_until(lambda: hw.stop_time() is not None, timeout_s, None, "outputs stopped")
    return max(0.0, hw.stop_time() - t0)


#: how long the armed layout is recorded for the replay rows, s
REPLAY_RECORD_S = 12.0
#: replay time before the supervisor is killed: every vehicle process has discovered the replay (about 2 s) and taken
#: its heartbeats, s
REPLAY_LEAD_S = 3.0
#: how long thrust is watched after the kill before the repeat counts as "still on", s
REPLAY_CENSOR_S = 3.0

#: the bag player in its own process, with every topic and the graph check off (what a tool without it publishes);
#: prints the monotonic time (system-wide CLOCK_MONOTONIC) of its first message
_REPLAY = r"""
import sys, time
from rclpy.parameter import Parameter
from hindrax_bringup.recording.player_node import BagPlayerNode
from hindrax_common.process.ros_process import RosProcess
class Unchecked(BagPlayerNode):
    def _check_graph(self, force=False):
        pass
    def _graph_settled(self):
        return True
with RosProcess([]) as proc:
    node = proc.own(Unchecked(parameter_overrides=[
        Parameter("bag", value=sys.argv[1]), Parameter("start_offset_s", value=float(sys.argv[2])),
        Parameter("loop", value=True), Parameter("safety_topics", value=True),
        Parameter("wait_for_subscribers_timeout_s", value=1.0)]))
    node.wait_for_subscribers()
    print(time.monotonic(), flush=True)
    node.play()
"""


def _record_vehicle_bag(lay: _Layout, tmp: Path) -> tuple[Path, float]:
    """Record the armed, commanded layout for :data:`REPLAY_RECORD_S` with the project's recorder (every topic).
    Returns the bag and the start offset (s) from which it holds all three heartbeats (the recorder subscribes to
    each topic as it discovers it): replayed from there, every pass carries them without a gap until its end."""
    bag = tmp / "vehicle_bag"
    lay.armed_at_1700()
    argv = [lay.py, "-m", "hindrax_bringup.recording.recorder_node", "--ros-args", "--params-file", lay.config,
            "-p", "all_topics:=true", "-p", "autostart:=true", "-p", f"output_dir:={bag}"]
    rec = start_logged(tmp / "recorder.log", argv, env=lay.env)
    try:
        wait_until(lambda: (bag / "metadata.yaml").exists() or any(bag.glob("*.mcap")), 30, None, "recorder started")
        spin_for(REPLAY_RECORD_S)
    finally:
        interrupt(rec, 30)
    lay.commanding = False
    reader = BagReader(bag)
    wanted = ("/supervisor/heartbeat", "/guard/heartbeat", "/esc/heartbeat", "/thrusters/command_pulse_width")
    missing = [t for t in wanted if t not in reader.channels]
    if missing:
        raise RuntimeError(f"the recorded bag lacks {missing}; it has {sorted(reader.channels)}")
    first = max(next(iter(reader.messages([t]))).log_time_ns for t in wanted)
    return bag, (first - reader.start_ns) / 1e9


def replay_rows(quick: bool = False) -> list[dict]:
    """Rows of the supervisor killed while a bag of the vehicle replays (module docstring; target
    <= 500 ms median and max)."""
    repeats = QUICK_REPEATS if quick else PROCESS_REPEATS
    after_kill: list[float] = []
    censored = 0
    by_replay: list[float] = []
    spurious = 0  # outputs stopped before the replay's first message: not the replay's doing, the repeat is redone
    with running_layout("hindrax-bench-replay-") as lay:
        tmp, hw = lay.tmp, lay.hw
        bag, offset_s = _record_vehicle_bag(lay, tmp)
        k = 0
        while len(after_kill) < repeats:
            if spurious > repeats:
                raise RuntimeError(f"the outputs stopped before the replay began in {spurious} attempts")
            k += 1
            lay.armed_at_1700()
            t_start = time.monotonic()  # the replay's participant and publishers may stop the outputs already
            with open(tmp / f"replay{k}.log", "w") as log, child_process(
                    [lay.py, "-c", _REPLAY, str(bag), f"{offset_s:.3f}"], env=lay.env,
                    stdout=subprocess.PIPE, stderr=log, text=True) as replay:
                if hw.stopped_at is not None and hw.stopped_at < t_start:
                    spurious += 1
                    continue
                line = replay.stdout.readline()
                if not line:
                    raise RuntimeError(f"the replay exited ({replay.wait(10)}) before its first message")
                t_replay = float(line)
                wait_until(lambda: hw.stopped_at is not None or time.monotonic() > t_replay + REPLAY_LEAD_S,
                           REPLAY_LEAD_S + 10, None, "replay running")
                t0 = time.monotonic()
                lay.kill("supervisor")
                if hw.stopped_at is not None and hw.stopped_at <= t0:
                    by_replay.append(hw.stopped_at - t_start)
                    after_kill.append(0.0)
                    continue
                try:
                    wait_until(lambda: hw.stopped_at is not None, REPLAY_CENSOR_S, None, "outputs stopped")
                    after_kill.append(hw.stopped_at - t0)
                except ConditionTimeout:
                    censored += 1
                    after_kill.append(REPLAY_CENSOR_S)
    note = ("bag of the armed layout replayed in a loop with every topic (heartbeats, commands), supervisor SIGKILLed "
            f"{REPLAY_LEAD_S:g} s into the replay; {censored} of {repeats} still had thrust "
            f"{REPLAY_CENSOR_S:g} s after the kill (counted as {REPLAY_CENSOR_S * 1e3:.0f} ms), {len(by_replay)} had "
            f"stopped before it (counted as 0); {spurious} attempt(s) redone (outputs stopped before the replay began)")
    stopped_note = ("the replay's heartbeat publishers (a second publisher, another node's name) stopped the outputs "
                    "before the kill" + (f", {1e3 * float(np.median(by_replay)):.0f} ms median, "
                                         f"{1e3 * float(np.max(by_replay)):.0f} ms max after the replay process "
                                         "started" if by_replay else ""))
    return [_ms_row("supervisor_killed_during_replay_thrust_after_kill_ms", after_kill, target=500.0, note=note),
            {"name": "replay_alone_stopped_outputs", "value": len(by_replay), "unit": f"of {repeats} repeats",
             "note": stopped_note}]


def frozen_rows(quick: bool = False) -> list[dict]:
    """Rows of the hardware watchdog (module docstring; targets <= 500 ms median and max for the
    frozen launch, and arming refused by a guard without its line)."""
    repeats = QUICK_REPEATS if quick else PROCESS_REPEATS
    stopped: list[float] = []
    oe_low = 0  # repeats in which the guard's own /OE line was still low when the outputs stopped
    with running_layout("hindrax-bench-frozen-") as lay:
        hw = lay.hw
        lay.ensure()  # a start-up's stalls (discovery) are not what is measured: the graph settles first
        wait_until(GraphSettled(lay.probe, quiet_s=3.0, min_nodes=3), 90, None, "graph settled")
        for _ in range(repeats):
            lay.armed_at_1700()
            t0 = time.monotonic()
            for name in ("guard", "esc", "supervisor"):
                lay.signal(name, _signal.SIGSTOP)
            try:
                wait_until(lambda: hw.stop_time() is not None, 10, None, "outputs stopped")
                stopped.append(max(0.0, hw.stop_time() - t0))
                oe_low += not hw.line.is_high()
            finally:
                for name in ("supervisor", "esc", "guard"):
                    lay.signal(name, _signal.SIGCONT)
        refused, attempts, answer, granted_s = _guard_without_line(lay, hw)
    return [_ms_row("launch_frozen_outputs_stopped_ms", stopped, target=500.0,
                    note="SIGSTOP of guard, ESC and supervisor while armed at 1700 us; the "
                         f"emulated watchdog (t_W {WATCHDOG_TIMEOUT_S:g} s, fed at 10 Hz) ran out; "
                         f"the guard's own /OE line was still low in {oe_low} of {len(stopped)}"),
            {"name": "guard_without_line_arming_refused", "value": refused, "unit": f"of {attempts} arm requests",
             "note": f"/OE line busy when the guard started; the ESC answered {answer[:140]!r}; line granted -> "
                     f"armed after {granted_s:.1f} s"}]


def _guard_without_line(lay: _Layout, hw: _Hardware) -> tuple[int, int, str, float]:
    """Restart the guard while its /OE line is busy, ask the ESC to arm 5 times (0.3 s apart,
    after the guard heartbeats), then grant the line. Returns (refused, attempts, last refusal,
    seconds until an arm worked after the grant)."""
    lay.commanding = False
    if lay.procs.get("guard") is not None:
        lay.kill("guard")
    hw.line_busy = True
    try:
        lay.ensure()
        heard = []
        sub = lay.probe.create_subscription(Heartbeat, "guard/heartbeat", heard.append, heartbeat_qos())
        wait_until(lambda: len(heard) >= 5, 60, None, "guard heartbeats")
        refused, answer, attempts = 0, "", 5
        for _ in range(attempts):
            res = lay.call(lay.arm_client, SetArmed.Request(arm=True))
            if res.success:
                lay.call(lay.arm_client, SetArmed.Request(arm=False))
            else:
                refused += 1
                answer = res.message
            spin_for(0.3)
        lay.probe.destroy_subscription(sub)
    finally:
        hw.line_busy = False
    t0 = time.monotonic()
    wait_until(lambda: lay.call(lay.arm_client, SetArmed.Request(arm=True)).success, 60, None,
               "armed once the line is granted")
    granted_s = time.monotonic() - t0
    lay.call(lay.arm_client, SetArmed.Request(arm=False))
    return refused, attempts, answer, granted_s


def _clock_rows(lay: _Layout, repeats: int) -> list[float]:
    """A supervisor on use_sim_time; this process publishes /clock at 100 Hz and steps it back 100 s."""
    lay.kill("supervisor")
    lay.start("supervisor", ("-p", "use_sim_time:=true"))
    pub = lay.probe.create_publisher(Clock, "/clock", 10)
    state = {"ns": 1_000_000_000_000}

    def clock() -> None:
        state["ns"] += 10_000_000
        pub.publish(Clock(clock=Time(nanoseconds=state["ns"]).to_msg()))
    timer = lay.probe.create_timer(0.01, clock)  # the layout's thread spins the probe
    out = []
    try:
        wait_until(lambda: pub.get_subscription_count() > 0 and lay.reset_client.service_is_ready(), 60, None,
                   "supervisor on /clock")
        spin_for(2.0)  # the supervisor's checks running on the received clock
        for k in range(repeats):
            n0 = len(lay.diag)
            t0 = time.monotonic()
            state["ns"] -= 100_000_000_000
            wait_until(lambda: len(lay.diag) > n0, 10, None, "clock step reported on /diagnostics")
            out.append(lay.diag[n0][0] - t0)
            spin_for(1.5)  # the 1 Hz diagnostics of this step are not the next step's report
            del lay.diag[n0:]
    finally:
        lay.probe.destroy_timer(timer)
        lay.signal("supervisor", _signal.SIGINT)
    return out


def run_processes(quick: bool = False) -> list[dict]:
    """Rows of the process, bus and clock failures (target: each <= 0.5 s), median and max in ms;
    the guard's CPU and the ESC's disarms right after an arm."""
    repeats = QUICK_REPEATS if quick else PROCESS_REPEATS
    notes = {"supervisor_killed_outputs_stopped": "SIGKILL: ESC heartbeat timeout 0.2 s and guard /OE",
             "supervisor_hung_outputs_stopped": "SIGSTOP: the same paths",
             "esc_killed_oe_asserted": "SIGKILL: guard sees esc/heartbeat silent for 0.2 s",
             "esc_hung_oe_asserted": "SIGSTOP: the same path",
             "i2c_outage_state_unknown": "PCA9685 NACKs: thrusters/pulse_width output_state UNKNOWN",
             "clock_step_back_detected": "/clock -100 s: supervisor /diagnostics errors.clock_step"}
    times: dict[str, list] = {k: [] for k in notes}
    with running_layout("hindrax-bench-safety-") as lay:
        hw = lay.hw
        # the guard's cost while armed and commanded (50 Hz ESC state, 20 Hz heartbeats)
        lay.armed_at_1700()
        cpu0 = proc_cpu_s(lay.procs["guard"].pid)
        _, wall = spin_for(5.0 if quick else 10.0)
        guard_cpu = 100.0 * (proc_cpu_s(lay.procs["guard"].pid) - cpu0) / wall
        for _ in range(repeats):
            # the supervisor killed / hung until the outputs stop, then the ESC until /OE is high
            for who, what, at in (("supervisor", "outputs_stopped", lambda: hw.stopped_at),
                                  ("esc", "oe_asserted", lambda: hw.oe_at)):
                for kind in ("killed", "hung"):
                    lay.armed_at_1700()
                    t0 = time.monotonic()
                    if kind == "killed":
                        lay.kill(who)
                    else:
                        lay.signal(who, _signal.SIGSTOP)
                    wait_until(lambda: at() is not None, 10, None, what)
                    times[f"{who}_{kind}_{what}"].append(at() - t0)
                    if kind == "hung":
                        lay.signal(who, _signal.SIGCONT)
            lay.armed_at_1700()
            t0 = time.monotonic()
            hw.bus.disconnected = True
            wait_until(lambda: lay.unknown_at is not None, 10, None, "output state unknown")
            times["i2c_outage_state_unknown"].append(lay.unknown_at - t0)
            hw.bus.disconnected = False
        lay.commanding = False
        times["clock_step_back_detected"] = _clock_rows(lay, repeats)
        rearms = lay.rearms
    rows = [{"name": "guard_cpu_percent", "value": guard_cpu, "unit": "% of a core",
             "note": "output guard process while armed and commanded (EventsExecutor, 20 Hz timer)"},
            {"name": "esc_disarmed_right_after_arm", "value": len(rearms), "unit": "arms",
             "note": f"of {5 * repeats + 1} arm requests, the ESC disarmed itself before 1700 us "
                     "reached the wire (the bench armed again)"
                     + (f"; last ESC log line: {rearms[-1][-160:]}" if rearms else "")}]
    return rows + [_ms_row(f"{name}_ms", values, target=500.0, note=notes[name]) for name, values in times.items()]
