"""Safety benchmark rows ``pool_day_churn_*``: the pool day's churn check beside two CPU-bound neighbours.

The vehicle's three safety processes, scheduled as ``vehicle.launch.xml`` starts them, with the gateway beside
them (the layout of :mod:`hindrax_ident.tools.benchmarks.participant_churn` and
:func:`hindrax_ident.tools.benchmarks.sealed_authority.gateway_running`), are armed and commanded at 1700 us,
50 Hz. :data:`NEIGHBOURS` processes ``python3 -c 'while True: pass'`` at normal priority run throughout
(:func:`hindrax_ident.tools.benchmarks.busy_neighbours.cpu_bound_neighbours`). Each of :data:`TRIALS` trials
starts three processes together and waits for them to exit, as an operator and a curious user do on the pool
day:

* a :data:`SUBSCRIBER_S` s subscriber to ``/diagnostics`` and the three heartbeats on the Pi's internal domain with
  Fast DDS's default transports (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, no profile: shared memory + UDP);
* a :data:`SUBSCRIBER_S` s subscriber to the gateway's topside topics on the topside domain;
* ``hindrax health --quiet`` on the internal domain (the Pi's shell).

Rows: those of :meth:`.participant_churn._Watch.rows` (disarms, heartbeat gaps, tick gaps) with
the prefix ``pool_day_churn_``, the heartbeat gap's target :data:`GAP_TARGET_MS`.

Run alone: ``python -m hindrax_ident.tools.benchmarks.pool_day_churn [--quick]`` (prints the rows as
JSON).
"""
from __future__ import annotations

import os
import subprocess
from contextlib import ExitStack

from domain_coordinator import domain_id
from hindrax_drivers.dds_transport import PROFILE_ENV, RANGE_ENV
from hindrax_drivers.testing import child_process

from . import run_alone
from .busy_neighbours import cpu_bound_neighbours
from .participant_churn import _VehicleLayout, _Watch, hardware_priority, subscriber_argv
from .safety import running_layout
from .sealed_authority import gateway_running

#: trials (QUICK_TRIALS with --quick), CPU-bound neighbours, each subscriber's life (s), the gap target (ms)
TRIALS, QUICK_TRIALS, NEIGHBOURS, SUBSCRIBER_S, GAP_TARGET_MS = 15, 3, 2, 1.0, 150.0
#: how long one trial's three processes may take to exit under the load before the bench stops, s
TRIAL_TIMEOUT_S = 60.0


def topside_topics(vehicle: str) -> tuple[str, ...]:
    """What the topside subscriber listens to (``module:Type=topic``): the gateway's status topics and odometry."""
    return (f"diagnostic_msgs.msg:DiagnosticStatus=/{vehicle}/supervisor/status",
            f"diagnostic_msgs.msg:DiagnosticStatus=/{vehicle}/gateway/status",
            f"nav_msgs.msg:Odometry=/{vehicle}/odom")


def run(quick: bool = False) -> list[dict]:
    """The ``pool_day_churn_*`` rows (module docstring); ``quick``: :data:`QUICK_TRIALS` trials."""
    trials = QUICK_TRIALS if quick else TRIALS
    exits: list[int] = []
    with running_layout("hindrax-bench-poolday-", layout=_VehicleLayout) as lay, domain_id() as topside:
        watch = _Watch(lay.probe)
        lay.ensure()
        internal_default = {k: v for k, v in lay.env.items() if k != PROFILE_ENV} | {RANGE_ENV: "LOCALHOST"}
        topside_env = internal_default | {"ROS_DOMAIN_ID": str(topside)}
        health = [lay.py, "-m", "hindrax_ident.tools.cli", "health", "--quiet", "--timeout", "3"]
        topics = topside_topics(lay.vehicle)
        quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
        with gateway_running(lay, topside):
            lay.armed_at_1700()
            with hardware_priority() as refused, cpu_bound_neighbours(NEIGHBOURS):
                watch.start()
                for k in range(trials):
                    specs = ((subscriber_argv(f"internal_{k}", SUBSCRIBER_S), internal_default),
                             (subscriber_argv(f"topside_{k}", SUBSCRIBER_S, topics), topside_env),
                             (health, lay.env))
                    with ExitStack() as stack:
                        procs = [stack.enter_context(child_process(argv, env=env, **quiet))
                                 for argv, env in specs]
                        exits += [p.wait(TRIAL_TIMEOUT_S) for p in procs]
                watch.active = False
                load = os.getloadavg()[0]
    what = (f"{trials} trials, each a {SUBSCRIBER_S:g} s subscriber on the internal domain with default transports, "
            f"one on the topside and `hindrax health` started together (exit codes {sorted(set(exits))}), armed and "
            f"commanded at 1700 us, 50 Hz, beside {NEIGHBOURS} CPU-bound processes (1-minute load {load:.1f} at the "
            f"end); emulated hardware {'not real-time: ' + refused if refused else 'real-time, above them'}")
    return watch.rows("pool_day_churn_", what, GAP_TARGET_MS, n=trials)


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
