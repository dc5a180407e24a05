"""Record the driver test bag from the virtual pool: ``sim_drivers_3s`` under ``src/hindrax_bringup/test/data/``.

Usage: ``python test/support/hindrax_test_support/record_bag.py [--out DIR]`` (default: the repository's
``src/hindrax_bringup/test/data``; the synthetic bags are :mod:`hindrax_bringup.recording.make_test_bags`).

Content: the whole driver graph on the virtual pool (:func:`hindrax_sim.graph.bringup.build_graph` with ``sim=True``:
simulator -> device emulators -> pty / emulated I2C bus -> the real DVL-75, Ping1D, MS5837, ICM-20948 and ESC driver
nodes), recorded by the stack's own recorder node (all topics), simulated time starting at 0 (``/clock``), as fast as
possible. The vehicle floats passively from ``pool.start_position_ned_m`` = :data:`START_POSITION_NED_M` (ESC disarmed,
neutral): every parsed topic (``dvl/*``, ``ping/*``, ``pressure/*``, ``imu/*``, ``thrusters/pulse_width``) beside the
raw device data (``raw/<device>``, hindrax_msgs/RawDeviceData: every serial chunk and I2C transaction), the simulator's
ground truth (``sim/*``) and ``/clock``.

A clean start and end, so that a replay of the raw data through fresh drivers reproduces the parsed topics
exactly (:mod:`.replay_devices`): simulated time is held at 0 until the recorder
has subscribed to and matched every topic; at the end simulated time is frozen and the recorder is stopped
only once it has written every message the drivers published. The only driver traffic before the recording
are the ESC node's constructor writes (PCA9685 configuration and first neutral), inside ``build_graph``.

Simulated content is deterministic for a seed, but the exact message count is not (how the executor interleaves the
driver timers with /clock steps varies with machine load), so tests check properties, not counts fixed in advance. It
lives with the tests: only they and this bag use it; not in hindrax_bringup, so that the drivers do not import the
simulator."""
from __future__ import annotations

import argparse
import collections
import functools
import shutil
import sys
from pathlib import Path
from typing import Any

from hindrax_common.process.conditions import ConditionTimeout, ros_context, wait_until
from hindrax_common.base.devices import DEVICES, I2C
from hindrax_bringup.recording.make_test_bags import default_output_dir, write_bags
from hindrax_bringup.recording.reader import BagReader
from hindrax_common.config import default_config_path

from hindrax_sim.graph.bringup import build_graph

__all__ = ["SIM_BAGS", "SIM_SEED", "START_POSITION_NED_M", "record_simulated_run", "write_sim_bag", "main"]

SIM_SEED = 7
"""Simulation seed of the committed bags."""
START_POSITION_NED_M = [3.0, 3.0, 0.9]
"""Start position of base_link in the pool (NED, m): 0.9 m deep in the 1.8 m deep pool."""

#: bag name -> (simulated duration s, configuration overrides of the recorder's writer)
SIM_BAGS: dict[str, tuple[float, dict[str, Any]]] = {
    # every driver on the virtual pool, raw and parsed topics; the gyro-bias estimate is off so that a replay
    # through fresh drivers reproduces every field exactly (test/test_bag_replay_drivers.py)
    "sim_drivers_3s": (3.0, {"recording.chunk_size_bytes": 64 * 1024, "sensors.icm20948.estimate_gyro_bias": False}),
}


def record_simulated_run(bag_dir: str | Path, duration_s: float, *, context: Any,
                         overrides: dict | None = None) -> dict:
    """Record ``duration_s`` (s) of simulated time of the whole driver graph (the shipped vehicle file, seed
    :data:`SIM_SEED`, extra dotted-key ``overrides``) into ``bag_dir`` (removed first if it exists), in the initialised
    rclpy ``context``. Returns topic -> number of messages the graph's nodes published while recording (every one is in
    the bag). Raises :class:`~hindrax_common.process.conditions.ConditionTimeout` naming the condition not reached (each
    wait: 60 s of wall time), ConfigError for bad overrides."""
    timeout_s = 60.0
    bag_dir = Path(bag_dir)
    if bag_dir.exists():
        shutil.rmtree(bag_dir)
    ov = {"simulation.real_time_factor": 0.0, "pool.start_position_ned_m": list(START_POSITION_NED_M),
          "recording.flush_interval_s": 60.0}
    ov.update(overrides or {})
    graph = build_graph(default_config_path(), sim=True, record=True, record_dir=str(bag_dir),
                        context=context, seed=SIM_SEED, overrides=ov)
    sim_node = graph.nodes["simulator"]
    recorder = graph.nodes["recorder"]
    published: collections.Counter[str] = collections.Counter()
    counting = [False]

    def count(pub: Any) -> None:
        topic, original = pub.topic_name, pub.publish

        def publish(msg: Any) -> None:
            original(msg)
            if counting[0]:
                published[topic] += 1
        pub.publish = publish

    spin = functools.partial(graph.spin_once, 0.005)
    drivers = [graph.nodes[d.node] for d in DEVICES]
    for node in drivers + [sim_node]:
        for pub in node.publishers:
            count(pub)
    wanted = {pub.topic_name for node in drivers + [sim_node] for pub in node.publishers}
    try:
        graph.freeze_time()  # at 0 until the drivers' start-up and the recorder's subscriptions
        wait_until(graph.startup_complete, timeout_s, spin, "the drivers' start-up and the recorder's subscriptions")
        links = list(graph.hardware.serial_lock_steps.values())
        counting[0] = True
        graph.resume_time()
        sim = sim_node.simulator
        wait_until(lambda: sim.t_s >= duration_s, timeout_s, spin, f"{duration_s} s of simulated time")
        graph.freeze_time()

        def flushed() -> bool:
            # the I2C drivers' raw records still pending (RawDataPublisher publishes them every 0.1 s), also those
            # of a poll that was due at the freeze and runs now
            for node in [graph.nodes[d.node] for d in DEVICES if d.transport == I2C]:
                node.raw.flush_pending()
            # the serial devices are in lock-step: every byte sent was handled by its driver before time moved on
            got = recorder._writer.topic_counts() if recorder._writer is not None else {}
            return all(link.settled() for link in links) and all(
                got.get(t, 0) >= n for t, n in published.items() if t in wanted)
        try:
            wait_until(flushed, timeout_s, spin, "the recorder wrote every published message")
        except ConditionTimeout:
            got = recorder._writer.topic_counts()
            lagging = {t: (n, got.get(t)) for t, n in published.items() if got.get(t, 0) < n}
            raise ConditionTimeout(f"lagging: {lagging}") from None
        counting[0] = False
        recorder.stop_recording()
    finally:
        graph.resume_time()
        graph.shutdown()
    return dict(published)


def write_sim_bag(bag_dir: Path, duration_s: float, overrides: dict[str, Any]) -> int:
    """Record one bag (see :func:`record_simulated_run`); returns its message count."""
    with ros_context() as ctx:
        record_simulated_run(bag_dir, duration_s, context=ctx, overrides=overrides)
    return sum(c.message_count for c in BagReader(bag_dir).channels.values())


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name); returns the exit code."""
    parser = argparse.ArgumentParser(prog="record_bag", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(default_output_dir()), help="directory to write the bags into")
    args = parser.parse_args(argv)
    write_bags(Path(args.out), SIM_BAGS, write_sim_bag)
    return 0


if __name__ == "__main__":
    sys.exit(main())
