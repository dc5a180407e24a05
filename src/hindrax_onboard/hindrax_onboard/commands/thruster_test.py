"""``hindrax thruster-test [--force-n F] [--dry-run] [--config FILE]``: catch a reversed thruster or a swapped
channel before a pool test.

Each thruster is stepped alone at a small thrust (default 3 N along its configured direction). For each
step the command prints the pulse width, the ESC channel and the wrench the model expects (base_link FLU,
N and N m: column i of the thrust allocation matrix times the force, [Hindrax-Drag] eq. 9), so the
engineer can watch the vehicle (or a hand on the frame) and compare. Without ``--dry-run`` it drives the ESCs through
the running stack: it arms through ``esc/set_armed`` (hindrax_msgs/SetArmed), publishes the step's per-thruster
forces on ``thrusters/test_forces`` (hindrax_msgs/ThrusterForces; the allocation node turns them into the command,
the only one the ESC accepts) for ``--step-s`` seconds per thruster with 0 N in between, then disarms (also on
Ctrl-C or any error). It runs on the vehicle itself (``thrusters/*`` never cross its gateway,
docs/architecture.md §8.2), on the vehicle named by ``--vehicle NAME`` or the only one its graph shows; it refuses
with one line on the topside, or when it sees no vehicle or several."""
from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from .common import CommandError, add_config_argument, load_vehicle
from .vehicle import add_vehicle_arguments, find_vehicle

if TYPE_CHECKING:
    from hindrax_bringup.allocation.core import AllocationCore


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("--force-n", type=float, default=3.0, help="thrust per step, N (sign = direction)")
    parser.add_argument("--step-s", type=float, default=2.0, help="duration of each step on hardware, s")
    parser.add_argument("--dry-run", action="store_true", help="only print; do not drive the ESCs")
    add_config_argument(parser)
    add_vehicle_arguments(parser)


def plan(core: AllocationCore, force_n: float) -> list[dict]:
    """One row per thruster: name, channel, pulse width, actual force and expected wrench (base_link)."""
    import numpy as np

    curve = core.allocator.curves[0]
    rows = []
    for i, th in enumerate(core.cfg.thrusters.thrusters):
        pw = float(np.asarray(curve.pulse_width_us(force_n)))
        actual = float(np.asarray(curve.thrust_n(pw)))
        rows.append({"thruster": th.name, "esc_channel": th.esc_channel, "pulse_width_us": round(pw, 2),
                     "force_n": round(actual, 4),
                     "expected_wrench_base_link": [round(float(x), 4) for x in core.thruster_wrench_flu(i, actual)]})
    return rows


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.allocation.core import AllocationCore

    core = AllocationCore(load_vehicle(args.config))
    rows = plan(core, args.force_n)
    for row in rows:
        print(json.dumps(row))
    if args.dry_run:
        return 0
    return _drive(core, rows, args.step_s, args.vehicle, args.discovery_timeout)


def _drive(core: AllocationCore, rows: list[dict], step_s: float, vehicle: str | None = None,
           discovery_timeout_s: float = 10.0) -> int:
    """Arm, step each thruster for ``step_s`` s with 1 s of neutral after it, disarm (also on Ctrl-C or any
    error: registered before the node's clean-up, :class:`~hindrax_common.process.ros_process.RosProcess`)."""
    import rclpy

    from hindrax_common.process.ros_process import RosProcess
    from hindrax_msgs.msg import ThrusterForces
    from hindrax_msgs.srv import SetArmed

    with RosProcess([]) as proc:
        node = proc.own(rclpy.create_node("thruster_test"))
        ex = proc.executor
        ex.add_node(node)
        target = find_vehicle(node, ex, vehicle, discovery_timeout_s)
        if target.topside:
            raise CommandError(f"{target.name}: thruster-test drives thrusters/*, which exist only on the vehicle: "
                               "run it there (docker exec hindrax hindrax thruster-test)")
        pub = node.create_publisher(ThrusterForces, "thrusters/test_forces", 10)
        arm = node.create_client(SetArmed, "esc/set_armed")

        def call_arm(value: bool) -> bool:
            fut = arm.call_async(SetArmed.Request(arm=value))
            ex.spin_until_future_complete(fut, timeout_sec=5.0)
            res = fut.result()
            if res is None or not res.success:
                print(f"{'arm' if value else 'disarm'} refused: {res.message if res else 'no answer'}", file=sys.stderr)
                return False
            return True

        def hold(forces, seconds: float) -> None:
            end = node.get_clock().now().nanoseconds + int(seconds * 1e9)
            while node.get_clock().now().nanoseconds < end:
                msg = ThrusterForces(force_n=[float(x) for x in forces])
                msg.header.stamp = node.get_clock().now().to_msg()
                pub.publish(msg)
                ex.spin_once(timeout_sec=0.05)

        if not arm.wait_for_service(timeout_sec=10.0):
            raise CommandError("esc/set_armed not available: is the stack running (hindrax bringup)?")
        proc.at_exit(lambda: call_arm(False))
        if not call_arm(True):
            return 1
        zero = [0.0] * len(rows)
        try:
            for i, row in enumerate(rows):
                forces = list(zero)
                forces[i] = row["force_n"]
                print(f"stepping {row['thruster']} (channel {row['esc_channel']}) at {row['pulse_width_us']} us",
                      flush=True)
                hold(forces, step_s)
                hold(zero, 1.0)
        except KeyboardInterrupt:
            proc.status = 130
    return proc.status
