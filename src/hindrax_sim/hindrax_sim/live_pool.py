"""The virtual pool on the wall clock, for the vehicle's own launch: the simulator behind the five emulated devices,
in a process of its own, so that the launch layout's driver processes run exactly as on the vehicle.

``hindrax bringup --sim`` and ``hindrax run`` put the simulator and every node in one process on simulated time
(:mod:`hindrax_sim.graph.bringup`). Here nothing of the stack changes: the installed launch (``pool_test.launch.xml``,
one process per driver, the real clock, the vehicle's transport) opens its serial ports and its I2C bus, and finds
the emulators of :class:`~hindrax_sim.hardware.VirtualHardware` there, fed by a
:class:`~hindrax_sim.simulator.Simulator` that this process steps to keep up with the wall clock. The
simulator takes the thrusters' pulse widths from the PCA9685 emulator's registers, so wrench -> allocation -> ESC
process -> I2C -> thrust -> motion -> sensors -> drivers is the vehicle's path, with a simulated vehicle at its end.
The devices are reached as :class:`~hindrax_bringup.layout.emulated_devices.EmulatedDevices` are
(serial ports behind stable symlinks, the I2C bus over a Unix socket:
:class:`~hindrax_bringup.layout.emulated_devices.DriverEndpoints`), which hold a vehicle at rest instead.

Why a process of its own: the I2C emulators answer inside the drivers' bus calls, from a Python thread; in a busy
process (a test's probe nodes, a campaign client) those answers wait for the interpreter lock for tens of
milliseconds, the ESC's heartbeat follows them, and the output guard stops the thrusters. Alone, this process
spends under 1 % of a core stepping the simulator (0.04 ms per 5 ms step on the development machine); waking
200 times a second costs it more than the steps.

The operator's hands (the calibration steps' ballast, float, line pulls and inclining mass:
:class:`~hindrax_sim.campaign.PoolOperator`, the same as the in-process campaign's) are commands
on the process's standard input; :class:`LivePool` is the client.

Protocol (one line each way, JSON answers): the process prints ``{"ports": {...}, "i2c_socket": path}`` once its
devices are served; then, per command line on stdin: ``act <code>`` -> ``{"ok": bool}`` (an operator prompt's code,
e.g. ``attach_ballast``); ``truth`` -> ``{"t_s", "floor_depth_m", "altimeter_range_m", "position_ned_m", "euler_rad",
"nu", "pulse_widths_us"}`` (the pool floor's depth under the vehicle; the Ping1D's noise-free range along the body
z axis from where it is mounted; NED pool frame, FRD body, SI units, pulse widths in us); ``quit`` or the end of
the input stops it."""
from __future__ import annotations

import argparse
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Mapping

import numpy as np

from hindrax_common.config import load_config
from hindrax_bringup.layout.emulated_devices import DriverEndpoints
from hindrax_common.process.scheduling import HARDWARE_STAND_IN_PRIORITY, PRIORITY_ENV, apply_realtime_priority
from hindrax_common.transport.socket_i2c import I2CSocketServer

from .campaign import PoolOperator
from hindrax_onboard.identification.online.executive import calibration_forces, float_buoyancy, inclining_load
from .hardware import VirtualHardware
from .simulator import Simulator

__all__ = ["LivePool", "LivePoolServer", "main"]

#: Largest lag of simulated time behind the wall clock before the pool re-anchors (and says so on stderr), s.
MAX_LAG_S = 0.5


class LivePoolServer:
    """The simulator, its emulated devices served to other processes, and the thread that steps it on the wall
    clock (module docstring).

    config_path: the vehicle file (the nodes' view; the emulated PCA9685 runs at its ``esc.oscillator_hz``).
    directory: where the I2C socket goes. truth: the pool's truth file (None: the shipped default), seed: the sensor
    noise seed (None: ``simulation.seed``). Every emulator, the stepping and the operator's forces share one lock.
    Raises :class:`~hindrax_common.config.ConfigError` for a bad vehicle file."""

    def __init__(self, config_path: str | os.PathLike, directory: str | os.PathLike, truth: str | None = None,
                 seed: int | None = None) -> None:
        cfg = load_config(config_path)
        self.sim = Simulator(cfg, truth=truth, seed=seed)
        self.lock = threading.RLock()
        # where the Ping1D is mounted on the simulated vehicle (the truth's, not the vehicle file's), FRD, m
        self._ping_position_frd_m = np.asarray(self.sim.config.sensors.ping1d.position_frd_m, dtype=float)
        self.hardware = VirtualHardware(self.sim, self.sim.config, seed=self.sim.seed, serial_threads=False)
        self.sim.sensors.stop_grid()  # its emulators measure when the devices would: the grid's work is unread
        ballast_n, line_n = calibration_forces(cfg)
        self.operator = PoolOperator(ballast_n, line_n, inclining_load(cfg), float_buoyancy(cfg))
        self._wall0, self._sim0 = time.monotonic(), self.sim.t_s
        # the emulators' time is the wall clock since the start (as a driver's waits measure it), continuous
        self.hardware.use_clock(lambda: self._sim0 + (time.monotonic() - self._wall0))
        self.ports = dict(self.hardware.ports)
        # a wall clock: the serial threads wake for the host's bytes and the devices' outputs (PtyDevice), else 20 Hz
        self.hardware.serve_serial(lock=self.lock, poll_period_s=0.05)
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        self.socket_path = str(directory / "i2c.sock")
        if os.path.exists(self.socket_path):
            os.unlink(self.socket_path)
        self._server = I2CSocketServer(self.hardware.i2c_bus, self.socket_path, lock=self.lock)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-pool-step", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        step_s, applied = self.sim.step_s, False
        while not self._stop.is_set():
            due = self._sim0 + (time.monotonic() - self._wall0)
            if due - self.sim.t_s > MAX_LAG_S:
                print(f"live pool: {due - self.sim.t_s:.2f} s behind the wall clock; re-anchoring",
                      file=sys.stderr, flush=True)
                self._wall0, self._sim0 = time.monotonic(), self.sim.t_s
                due = self.sim.t_s
            while self.sim.t_s + 0.5 * step_s <= due:
                with self.lock:
                    if applied or self.operator.active:  # at rest the held external wrench stays zero
                        self.sim.set_external_wrench(self.operator.external_wrench_frd(self.sim.rotation))
                        applied = self.operator.active
                    self.sim.step(self.hardware.pulse_widths_us())
            # one sleep to the next step's deadline (an Event's wait costs a third more per wake)
            time.sleep(max(0.0, self._wall0 + self.sim.t_s + 0.5 * step_s - self._sim0 - time.monotonic()))

    def act(self, code: str) -> bool:
        """Do what an operator prompt's ``code`` asks (:meth:`PoolOperator.act`); False for an unknown code."""
        with self.lock:
            return bool(self.operator.act(code, self.sim.rotation))

    def truth(self) -> dict:
        """The vehicle's true state now (module docstring: the ``truth`` answer)."""
        with self.lock:
            x, y, _ = (float(v) for v in self.sim.position_ned_m)
            pool = self.sim.pool
            floor = float(pool.floor_depth_m(x, y)) if pool is not None else float("nan")
            rot = self.sim.rotation
            ping = rot @ self._ping_position_frd_m + self.sim.position_ned_m
            altimeter = float(pool.ray_distance_m(ping, rot[:, 2])) if pool is not None else float("nan")
            return {"t_s": float(self.sim.t_s), "floor_depth_m": floor, "altimeter_range_m": altimeter,
                    "position_ned_m": [float(x) for x in self.sim.position_ned_m],
                    "euler_rad": [float(x) for x in self.sim.euler_rad], "nu": [float(x) for x in self.sim.nu],
                    "pulse_widths_us": [float(x) for x in self.hardware.pulse_widths_us()]}

    def close(self) -> None:
        """Stop stepping and serving (idempotent)."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._server.close()
        self.hardware.close()


def take_hardware_priority() -> str:
    """Put every thread of this process under ``SCHED_FIFO`` :data:`HARDWARE_STAND_IN_PRIORITY`, so the emulated devices
    answer in microseconds whatever the load, as the vehicle's hardware does. A nice value cannot do that: it ranks
    a process only within its own session (:mod:`hindrax_common.process.scheduling`). Call it before the devices'
    threads start: they inherit it. Not with ``SCHED_RESET_ON_FORK``: the kernel applies that to every new thread too,
    and the serving threads would run ``SCHED_OTHER``; the process starts no other process. Refused (no
    ``CAP_SYS_NICE``): nice -10 if permitted. Returns the one line that says which."""
    result = apply_realtime_priority({PRIORITY_ENV: str(HARDWARE_STAND_IN_PRIORITY)})
    if result.granted:
        return f"SCHED_FIFO priority {HARDWARE_STAND_IN_PRIORITY} ({result.threads} thread(s) at start)"
    refused = f"SCHED_FIFO priority {HARDWARE_STAND_IN_PRIORITY} refused ({result.reason})"
    try:
        os.nice(-10)
        return f"{refused}; nice -10 (its devices may answer late under load)"
    except OSError:
        return f"{refused}; nice -10 not permitted either (its devices may answer late under load)"


def main(argv: list[str] | None = None) -> int:
    """``python -m hindrax_sim.live_pool --config FILE --directory DIR [--truth FILE] [--seed N]``: serve the
    live pool until ``quit`` or the end of standard input (module docstring: protocol)."""
    ap = argparse.ArgumentParser(prog="python -m hindrax_sim.live_pool", description=__doc__.splitlines()[0])
    ap.add_argument("--config", required=True, help="vehicle file")
    ap.add_argument("--directory", required=True, help="folder for the I2C socket")
    ap.add_argument("--truth", default=None, help="the pool's truth file (default: the shipped one)")
    ap.add_argument("--seed", type=int, default=None, help="sensor-noise seed (default simulation.seed)")
    args = ap.parse_args(argv)
    sys.setswitchinterval(0.001)  # the emulators answer other processes' bus calls: short waits for the GIL
    print(f"live pool: {take_hardware_priority()}", file=sys.stderr, flush=True)
    pool = LivePoolServer(args.config, args.directory, truth=args.truth, seed=args.seed)
    try:
        print(json.dumps({"ports": pool.ports, "i2c_socket": pool.socket_path}), flush=True)
        for line in sys.stdin:
            words = line.split()
            if not words:
                continue
            if words[0] == "quit":
                break
            if words[0] == "act" and len(words) == 2:
                print(json.dumps({"ok": pool.act(words[1])}), flush=True)
            elif words[0] == "truth":
                print(json.dumps(pool.truth()), flush=True)
            else:
                print(json.dumps({"error": f"unknown command {line.strip()!r}"}), flush=True)
    finally:
        pool.close()
    return 0


class LivePool(DriverEndpoints):
    """Client of a live pool process (module docstring): start it, reach its devices, act as the operator.

    config_path: the vehicle file; directory: a folder for the socket (default: a new temporary one); env: the child's
    environment (default: this one); truth: as :class:`LivePoolServer`. Use as a context manager. The driver-facing
    methods are those of :class:`~hindrax_bringup.layout.emulated_devices.DriverEndpoints` (``ports``,
    :meth:`ros_arguments`, :meth:`env`). Raises RuntimeError when the process does not come up within 60 s or does not
    answer within 10 s."""

    def __init__(self, config_path: str | os.PathLike, directory: str | os.PathLike | None = None,
                 env: Mapping[str, str] | None = None, truth: str | None = None) -> None:
        self.directory = Path(directory or tempfile.mkdtemp(prefix="hindrax-live-pool-"))
        self.directory.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "hindrax_sim.live_pool", "--config", str(config_path),
               "--directory", str(self.directory)]
        cmd += ["--truth", str(truth)] if truth else []
        self._stderr = open(self.directory / "live_pool.log", "w")
        self._proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr,
                                      text=True, env=dict(env) if env is not None else None)
        self.pid: int = self._proc.pid
        """The pool process's id."""
        hello = self._read(60.0)  # the devices come up within a minute
        self.ports: dict[str, str] = hello["ports"]
        self.socket_path: str = hello["i2c_socket"]

    def _read(self, timeout_s: float) -> dict:
        out = self._proc.stdout
        ready, _, _ = select.select([out], [], [], timeout_s)
        line = out.readline() if ready else ""
        if not line:
            self.close()
            raise RuntimeError(f"live pool gave no answer within {timeout_s:g} s (exit {self._proc.poll()}): "
                               f"{self.log()[-2000:]}")
        return json.loads(line)

    def _ask(self, command: str, timeout_s: float = 10.0) -> dict:
        self._proc.stdin.write(command + "\n")
        self._proc.stdin.flush()
        return self._read(timeout_s)

    def act(self, code: str) -> bool:
        """The operator does what a prompt's ``code`` asks (e.g. ``attach_ballast``); False for an unknown code."""
        return bool(self._ask(f"act {code}")["ok"])

    def truth(self) -> dict:
        """The simulated vehicle's true state (module docstring)."""
        return self._ask("truth")

    def log(self) -> str:
        """What the pool process wrote on stderr (its own file: readable after :meth:`close` too)."""
        return (self.directory / "live_pool.log").read_text()

    def close(self) -> None:
        """Stop the process (idempotent)."""
        if self._proc.poll() is None:
            try:
                self._proc.stdin.write("quit\n")
                self._proc.stdin.close()
                self._proc.wait(timeout=10.0)
            except (OSError, ValueError, subprocess.TimeoutExpired):
                self._proc.kill()
                self._proc.wait()
        self._stderr.close()


if __name__ == "__main__":
    raise SystemExit(main())
