"""Emulated I2C bus over a Unix socket: round-trip time of one transaction, with the serving process quiet or busy.

The launch-layout tests and the pool-day rehearsal serve the emulated PCA9685, MS5837 and ICM-20948 from the test
process (:class:`~hindrax_common.transport.socket_i2c.I2CSocketServer`, one thread per client connection); the driver
processes are its clients (:class:`~hindrax_common.transport.socket_i2c.SocketI2CBus`). A serving thread needs the GIL
of its process for every request, so CPU-bound Python threads beside it (the test's own spinning, other emulators) delay
every transaction by up to the interpreter's switch interval (``sys.getswitchinterval()``, 5 ms) per hand-over.

Rows (milliseconds, p50 and p99 of one 32-byte block write to the PCA9685, what the ESC writes per command, timed in
a client process): the server in a quiet process; with two busy Python threads beside it; the same with the switch
interval at 0.5 ms; and the server in a process of its own while the two busy threads run in the process that
started it."""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_common.testing import child_process
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.socket_i2c import I2CSocketServer, SocketI2CBus

_MODULE = "hindrax_tools.benchmarks.i2c_socket"
_WRITE = (0x40, 0x06, list(range(32)))  # PCA9685 at 0x40, LED0_ON_L, one 8-channel block


def _client(path: str, n: int) -> list[float]:
    """``n`` block writes through a :class:`SocketI2CBus` at ``path``; their round-trip times, s."""
    bus = SocketI2CBus(path)
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        bus.write_i2c_block_data(*_WRITE)
        times.append(time.perf_counter() - t0)
    bus.close()
    return times


def _server(path: str):
    return I2CSocketServer(EmulatedI2CBus({0x40: Pca9685Emulator()}), path)


def _busy(stop: threading.Event) -> None:
    x = 0
    while not stop.is_set():
        x += 1


@contextlib.contextmanager
def _busy_threads(n: int) -> Iterator[None]:
    """``n`` CPU-bound Python threads (:func:`_busy`) spinning in this process for the ``with`` block; stopped and
    joined when it ends, also on an error."""
    stop = threading.Event()
    threads = [threading.Thread(target=_busy, args=(stop,), daemon=True) for _ in range(n)]
    for th in threads:
        th.start()
    try:
        yield
    finally:
        stop.set()
        for th in threads:
            th.join()


def _measure(path: str, n: int) -> list[float]:
    out = subprocess.run([sys.executable, "-m", _MODULE, "--client", path, str(n)], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout)


def _row(name: str, times_s: list[float], note: str) -> list[dict]:
    ms = np.array(times_s) * 1e3
    return [{"name": f"{name}_p50", "value": float(np.percentile(ms, 50)), "unit": "ms", "note": note},
            {"name": f"{name}_p99", "value": float(np.percentile(ms, 99)), "unit": "ms", "note": note}]


def run(quick: bool = False) -> list[dict]:
    """Rows for ``make bench`` (module docstring); ``quick``: 200 transactions per case instead of 1000."""
    n = 200 if quick else 1000
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="hindrax-i2c-bench-") as tmp:
        for case, busy, switch_s in (("quiet", 0, None), ("busy2", 2, None), ("busy2_switch0.5ms", 2, 0.0005)):
            path = str(Path(tmp) / f"{case}.sock")
            server, old = _server(path), sys.getswitchinterval()
            try:
                if switch_s is not None:
                    sys.setswitchinterval(switch_s)
                with _busy_threads(busy):
                    times = _measure(path, n)
            finally:
                sys.setswitchinterval(old)
                server.close()
            rows += _row(f"i2c_socket_round_trip_{case}", times,
                         f"server in this process, {busy} busy Python threads beside it" +
                         (f", switch interval {switch_s * 1e3:g} ms" if switch_s else ""))
        path = str(Path(tmp) / "own.sock")
        with child_process([sys.executable, "-m", _MODULE, "--serve", path], stdout=subprocess.PIPE,
                           text=True) as proc, _busy_threads(2):
            proc.stdout.readline()  # "serving"
            times = _measure(path, n)
        rows += _row("i2c_socket_round_trip_own_process", times,
                     "server in a process of its own; 2 busy Python threads in the process that started it")
    return rows


if __name__ == "__main__":
    if sys.argv[1:2] == ["--client"]:
        print(json.dumps(_client(sys.argv[2], int(sys.argv[3]))))
    elif sys.argv[1:2] == ["--serve"]:
        _server(sys.argv[2])
        print("serving", flush=True)
        threading.Event().wait()  # serve until terminated
    else:
        for row in run(quick=True):
            print(row)
    os._exit(0)
