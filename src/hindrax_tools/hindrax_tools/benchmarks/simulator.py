"""Benchmark of the virtual pool (``make bench``, name "simulator").

Rows:
* ``steps_per_s``: :meth:`hindrax_sim.simulator.Simulator.step` calls per wall second at the default step
  (``simulation.step_s``) with every sensor model on, thrust changing every 0.5 s;
* ``real_time_factor``: simulated seconds per wall second of the same run (target >= 20);
* ``node_real_time_factor``: the ROS node at real_time_factor 0 in one SingleThreadedExecutor with a
  ``use_sim_time`` probe subscribing to /clock and sim/odometry (what a node under test sees; informative)."""
from __future__ import annotations

import time

import numpy as np
import rclpy
from hindrax_common.testing import ros_context
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from hindrax_common.config import default_config_path, load_config
from hindrax_sim.node import SimulatorNode
from hindrax_sim.simulator import Simulator

from . import spinning


def _simulator_rate(duration_s: float) -> tuple[float, float, int]:
    cfg = load_config(default_config_path())
    sim = Simulator(cfg)
    sim.reset(position_ned_m=[5.0, 3.0, 0.9])
    rng = np.random.default_rng(0)
    n = int(round(duration_s / sim.step_s))
    every = int(round(0.5 / sim.step_s))
    samples = 0
    start = time.perf_counter()
    for k in range(n):
        pw = rng.uniform(1350.0, 1650.0, 8) if k % every == 0 else None
        samples += len(sim.step(pw))
    wall = time.perf_counter() - start
    return n / wall, n * sim.step_s / wall, samples


def _node_rate(wall_s: float) -> float:
    cfg = load_config(default_config_path(), overrides={"simulation.real_time_factor": 0.0})
    with ros_context() as ctx:
        sim_node = SimulatorNode(config=cfg, context=ctx)
        probe = rclpy.create_node("bench_probe", context=ctx,
                                  parameter_overrides=[Parameter("use_sim_time", value=True)])
        probe.create_subscription(Clock, "/clock", lambda m: None, 10)
        probe.create_subscription(Odometry, "sim/odometry", lambda m: None, 10)
        with spinning(ctx, sim_node, probe, timeout_s=0.01) as (_ex, spin):
            for _ in range(20):
                spin()
            t0_sim, t0 = sim_node.simulator.t_s, time.perf_counter()
            while time.perf_counter() - t0 < wall_s:
                spin()
            return (sim_node.simulator.t_s - t0_sim) / (time.perf_counter() - t0)


def run(quick: bool = False) -> list[dict]:
    """Rows {name, value, unit, target?, note} (see module docstring)."""
    steps, rtf, samples = _simulator_rate(5.0 if quick else 15.0)
    return [
        {"name": "steps_per_s", "value": round(steps), "unit": "steps/s",
         "note": f"RK4, default step, all 7 sensor models on ({samples} samples)"},
        {"name": "real_time_factor", "value": round(rtf, 1), "unit": "x", "target": ">= 20",
         "note": "simulated s per wall s, Simulator.step without ROS"},
        {"name": "node_real_time_factor", "value": round(_node_rate(1.0 if quick else 5.0), 1),
         "unit": "x",
         "note": "ROS node, real_time_factor 0, /clock 100 Hz, with a use_sim_time probe"},
    ]
