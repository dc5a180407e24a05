"""How fast this machine runs Python, measured in every stack benchmark run: the scale between a CPU figure here
("% of a core here") and the same figure on another machine or at another moment; and the CPU time of a process
(:func:`proc_cpu_s`).

:func:`nbody_cpu_s`: the CPU time (``time.process_time``) of the classic n-body workload (the Sun and the
four giant planets, pairwise gravity, a semi-implicit Euler step of 0.01 years), the least over a few runs,
extrapolated to the 5 million steps of the Computer Language Benchmarks Game's n-body timings. It is the project's
own code for that algorithm, checked against the Benchmarks Game's published energies (tests); its times are not
those of the Benchmarks Game's Python program, so they do not rescale a published time into the Pi 4 factor
(``benchmarks/rig.py``: on the Pi this row joins the factor's measure), only figures of this project between
machines: a figure times ``nbody_cpu_s() / REFERENCE_NBODY_CPU_S`` is the figure at the reference machine's speed.

The workload is pure Python, which is most of the stack's cost (docs/architecture.md §10.1); the C/C++ half (rcl,
Fast DDS) may scale differently between machines."""
from __future__ import annotations

import collections
import math
import os
import threading
import time

#: Steps of the published timings (Benchmarks Game n-body, argument 5000000).
NBODY_STEPS = 5_000_000
#: :func:`nbody_cpu_s` on the reference machine, s (the least of 12 quiet runs: 26.8 s).
REFERENCE_NBODY_CPU_S = 27.0

_DAYS_PER_YEAR = 365.24
_SOLAR_MASS = 4.0 * math.pi * math.pi  # G M_sun in AU^3 / year^2


def _bodies() -> list[tuple[list[float], list[float], float]]:
    """(position [x, y, z] in AU, velocity [vx, vy, vz] in AU/year, mass in solar masses x 4 pi^2) of the Sun,
    Jupiter, Saturn, Uranus and Neptune (the Benchmarks Game's initial state, from the JPL ephemerides of its
    time), the Sun's velocity set so that the total momentum is zero."""
    planets = [
        (4.84143144246472090e+00, -1.16032004402742839e+00, -1.03622044471123109e-01,
         1.66007664274403694e-03, 7.69901118419740425e-03, -6.90460016972063023e-05, 9.54791938424326609e-04),
        (8.34336671824457987e+00, 4.12479856412430479e+00, -4.03523417114321381e-01,
         -2.76742510726862411e-03, 4.99852801234917238e-03, 2.30417297573763929e-05, 2.85885980666130812e-04),
        (1.28943695621391310e+01, -1.51111514016986312e+01, -2.23307578892655734e-01,
         2.96460137564761618e-03, 2.37847173959480950e-03, -2.96589568540237556e-05, 4.36624404335156298e-05),
        (1.53796971148509165e+01, -2.59193146099879641e+01, 1.79258772950371181e-01,
         2.68067772490389322e-03, 1.62824170038242295e-03, -9.51592254519715870e-05, 5.15138902046611451e-05),
    ]
    bodies = [([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], _SOLAR_MASS)]
    for x, y, z, vx, vy, vz, m in planets:
        bodies.append(([x, y, z], [vx * _DAYS_PER_YEAR, vy * _DAYS_PER_YEAR, vz * _DAYS_PER_YEAR], m * _SOLAR_MASS))
    for i in range(3):
        bodies[0][1][i] = -sum(v[i] * m for _, v, m in bodies[1:]) / _SOLAR_MASS
    return bodies


def _advance(bodies: list[tuple[list[float], list[float], float]], steps: int, dt: float = 0.01) -> None:
    """``steps`` semi-implicit Euler steps of ``dt`` years: every pair's velocity change, then every position."""
    pairs = [(bodies[i], bodies[j]) for i in range(len(bodies)) for j in range(i + 1, len(bodies))]
    for _ in range(steps):
        for ((x1, y1, z1), v1, m1), ((x2, y2, z2), v2, m2) in pairs:
            dx, dy, dz = x1 - x2, y1 - y2, z1 - z2
            mag = dt * (dx * dx + dy * dy + dz * dz) ** -1.5
            m2mag, m1mag = m2 * mag, m1 * mag
            v1[0] -= dx * m2mag
            v1[1] -= dy * m2mag
            v1[2] -= dz * m2mag
            v2[0] += dx * m1mag
            v2[1] += dy * m1mag
            v2[2] += dz * m1mag
        for r, (vx, vy, vz), _ in bodies:
            r[0] += dt * vx
            r[1] += dt * vy
            r[2] += dt * vz


def nbody_cpu_s(steps: int = 100_000, repeats: int = 5) -> float:
    """CPU seconds this process takes for :data:`NBODY_STEPS` n-body steps, extrapolated from ``steps`` steps, the
    least of ``repeats`` runs (the least is the one least disturbed by other processes and the machine's own
    swings, module docstring). About 3 s of CPU with the defaults on the reference machine. Raises ``ValueError``
    for ``steps`` or ``repeats`` < 1."""
    if steps < 1 or repeats < 1:
        raise ValueError(f"steps={steps}, repeats={repeats}: both must be >= 1")
    best = math.inf
    for _ in range(repeats):
        bodies = _bodies()
        t0 = time.process_time()
        _advance(bodies, steps)
        best = min(best, time.process_time() - t0)
    return best * NBODY_STEPS / steps


def proc_cpu_s(pid: int | str = "self") -> float:
    """User + system CPU seconds of process ``pid`` so far (all its threads; ``/proc/<pid>/stat``, proc(5));
    ``"self/task/<tid>"`` gives one thread's. Raises OSError when the process is gone."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def thread_cpu_s() -> dict[str, float]:
    """CPU seconds so far per Python thread name of this process (threads of one name summed),
    the calling thread excepted (``pthread_getcpuclockid``); threads that ended are left out."""
    out: dict[str, float] = collections.defaultdict(float)
    for t in threading.enumerate():
        if t is not threading.current_thread() and t.ident is not None:
            try:
                out[t.name] += time.clock_gettime(time.pthread_getcpuclockid(t.ident))
            except OSError:  # the thread ended meanwhile
                pass
    return out
