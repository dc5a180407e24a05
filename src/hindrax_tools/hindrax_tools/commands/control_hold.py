"""``hindrax control hold [--depth-m D | --altitude-m A] [--heading-deg H] [--vehicle NAME]`` and
``hindrax control release [--vehicle NAME]``: the running controller of a vehicle holds, or lets go.

``hold`` with a depth or an altitude sends that setpoint (hindrax_msgs/ControlSetpoint on ``controller/setpoint``,
depth of base_link below the surface or altitude above the floor, m; the heading given, else the one the controller
measures now; zero velocity over the bottom), waits until the controller's status carries it, then enables the
controller (``controller/enable``, std_srvs/SetBool). Without a target it calls ``controller/hold`` (hold depth and
heading where the vehicle is). ``release`` disables the controller (zero wrench). The controller refuses while the
ESC is not armed or an identification goal owns the wrench (docs/control.md §3); the refusal is printed and the
exit code is 1. After a hold it watches the controller's status ``--watch-s`` seconds (default 10) and prints what
was held and its error over them (:func:`hold_result`).

On the topside the names are the gateway's ``/<name>/controller/...`` (docs/architecture.md §8.2); on the vehicle
they are the controller's own. The vehicle is the one named, or the only one on the domain
(:mod:`hindrax_onboard.commands.vehicle`). Prints ``<name>: <the controller's message>``."""
from __future__ import annotations

import argparse
import math
import time
from typing import Any

from hindrax_onboard.commands.common import CommandError
from hindrax_onboard.commands.vehicle import (Target, add_vehicle_arguments, call_service, find_vehicle, wait_for,
                                              with_ros)

__all__ = ["add_arguments", "run", "hold_result"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``hold`` or ``release`` (the verb is the subcommand's own name) to ``parser``."""
    hold = parser.prog.split()[-1] == "hold"
    parser.set_defaults(_hold=hold)
    add_vehicle_arguments(parser)
    parser.add_argument("--timeout", type=float, default=10.0, metavar="S",
                        help="how long to wait for the controller's answer, s (default 10)")
    if hold:
        target = parser.add_mutually_exclusive_group()
        target.add_argument("--depth-m", type=float, default=None, metavar="D",
                            help="hold this depth of base_link below the surface, m (positive down)")
        target.add_argument("--altitude-m", type=float, default=None, metavar="A",
                            help="hold this altitude above the floor (Ping1D range), m")
        parser.add_argument("--heading-deg", type=float, default=None, metavar="H",
                            help="hold this compass heading, deg clockwise from north (default: the heading now)")
        parser.add_argument("--watch-s", type=float, default=10.0, metavar="S",
                            help="then watch the hold this long and print what it held and its error, s "
                                 "(default 10; 0: do not wait)")


def _check(args: argparse.Namespace) -> None:
    for key in ("depth_m", "altitude_m", "heading_deg"):
        value = getattr(args, key, None)
        if value is not None and not math.isfinite(value):
            raise CommandError(f"--{key.replace('_', '-')} {value}: allowed a finite number")
    if getattr(args, "depth_m", None) is not None and args.depth_m < 0.0:
        raise CommandError(f"--depth-m {args.depth_m:g}: allowed >= 0 (positive down)")
    if getattr(args, "altitude_m", None) is not None and args.altitude_m <= 0.0:
        raise CommandError(f"--altitude-m {args.altitude_m:g}: allowed > 0")


def _send_setpoint(node: Any, executor: Any, target: Target, args: argparse.Namespace, statuses: list) -> None:
    """Publish the setpoint until the controller's status (``statuses``, filled by a subscription) shows it (a
    topic: nothing else says it arrived)."""
    from hindrax_msgs.msg import ControlSetpoint

    pub = node.create_publisher(ControlSetpoint, target.resolve("controller/setpoint", "controller/setpoint"), 10)
    wait_for(executor, lambda: statuses and pub.get_subscription_count() > 0, args.timeout,
          f"{target.name}: no controller status")
    msg = ControlSetpoint()
    msg.header.frame_id = "base_link"
    if args.depth_m is not None:
        msg.vertical_mode, msg.depth_m, value = ControlSetpoint.VERTICAL_DEPTH, float(args.depth_m), "depth_setpoint_m"
    else:
        msg.vertical_mode, msg.altitude_m = ControlSetpoint.VERTICAL_ALTITUDE, float(args.altitude_m)
        value = "altitude_setpoint_m"
    heading = math.radians(args.heading_deg) if args.heading_deg is not None else statuses[-1].heading_rad
    msg.hold_heading, msg.heading_rad = math.isfinite(heading), float(heading) if math.isfinite(heading) else 0.0
    msg.hold_velocity, msg.surge_m_s, msg.sway_m_s = True, 0.0, 0.0
    wanted = msg.depth_m if msg.vertical_mode == ControlSetpoint.VERTICAL_DEPTH else msg.altitude_m
    sent = [0.0]

    def arrived() -> bool:
        s = statuses[-1]
        if s.vertical_mode == msg.vertical_mode and abs(getattr(s, value) - wanted) < 1e-9:
            return True
        if time.monotonic() - sent[0] > 0.5:  # again: a relayed topic's first message may meet no subscriber yet
            msg.header.stamp = node.get_clock().now().to_msg()
            pub.publish(target.sign("controller/setpoint", msg))
            sent[0] = time.monotonic()
        return False
    wait_for(executor, arrived, args.timeout, f"{target.name}: the controller did not take the setpoint")


def hold_or_release(node: Any, executor: Any, args: argparse.Namespace) -> tuple[str, bool, str]:
    """Do ``hold`` or ``release`` on the vehicle found; after a hold, watch it ``args.watch_s`` (wall) and add
    :func:`hold_result`'s line to the message. Returns (vehicle name, success, the controller's message).
    Raises :class:`CommandError` for no vehicle or no answer."""
    from hindrax_msgs.msg import ControllerStatus
    from std_srvs.srv import SetBool, Trigger

    target = find_vehicle(node, executor, args.vehicle, args.discovery_timeout)
    statuses: list = []
    node.create_subscription(ControllerStatus, target.resolve("controller/status", "controller/status"),
                             statuses.append, 10)
    enable = lambda on: target.service("controller/enable", "controller/enable", SetBool, data=on)  # noqa: E731
    if not args._hold:
        answer = call_service(node, executor, enable(False), args.timeout)
    elif args.depth_m is None and args.altitude_m is None:
        hold = target.service("controller/hold", "controller/hold", Trigger)
        answer = call_service(node, executor, hold, args.timeout)
    else:
        _send_setpoint(node, executor, target, args, statuses)
        answer = call_service(node, executor, enable(True), args.timeout)
    message = str(answer.message)
    if args._hold and answer.success and args.watch_s > 0:
        print(f"{target.name}: {message}; watching the hold for {args.watch_s:g} s ...", flush=True)
        n = len(statuses)
        deadline = time.monotonic() + args.watch_s
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        message = hold_result(statuses[n:], args.watch_s)
    return target.name, bool(answer.success), message


def hold_result(statuses: list, watch_s: float) -> str:
    """One line of what the controller held over the statuses (hindrax_msgs/ControllerStatus) received while
    watching for ``watch_s`` s: the depth or altitude setpoint (m), the mean measured value and the error (measured
    - setpoint: mean, RMS, largest magnitude, m), and the heading's RMS error (deg); or why there is none (the
    controller let go, no status arrived)."""
    from hindrax_msgs.msg import ControlSetpoint

    held = [s for s in statuses if s.enabled]
    if not held:
        last = statuses[-1].message if statuses else "no controller status arrived"
        return f"not holding after {watch_s:g} s: {last}"
    mode = held[-1].vertical_mode
    what, get, want = {ControlSetpoint.VERTICAL_DEPTH: ("depth", "depth_m", "depth_setpoint_m"),
                       ControlSetpoint.VERTICAL_ALTITUDE: ("altitude", "altitude_m", "altitude_setpoint_m")}.get(
        mode, ("", "", ""))
    parts = []
    if what:
        setpoint = getattr(held[-1], want)
        err = [getattr(s, get) - getattr(s, want) for s in held if s.vertical_mode == mode]
        err = [e for e in err if math.isfinite(e)]
        if err:
            mean, rms = sum(err) / len(err), math.sqrt(sum(e * e for e in err) / len(err))
            parts.append(f"{what} {setpoint:.3f} m held: measured {setpoint + mean:.3f} m mean, error {mean:+.3f} m "
                         f"mean, {rms:.3f} m RMS, {max(abs(e) for e in err):.3f} m largest")
        else:
            parts.append(f"{what} {setpoint:.3f} m: no measurement")
    heading = [math.remainder(s.heading_rad - s.heading_setpoint_rad, math.tau) for s in held]
    heading = [h for h in heading if math.isfinite(h)]
    if heading:
        parts.append(f"heading error {math.degrees(math.sqrt(sum(h * h for h in heading) / len(heading))):.1f} deg "
                     "RMS")
    return f"over the last {watch_s:g} s ({len(held)} statuses): " + "; ".join(parts or ["nothing held"])


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    _check(args)
    name, ok, message = with_ros(lambda node, ex: hold_or_release(node, ex, args), "hindrax_control")
    if not ok:
        raise CommandError(f"{name}: {'hold' if args._hold else 'release'} refused: {message}")
    print(f"{name}: {message}", flush=True)
    return 0
