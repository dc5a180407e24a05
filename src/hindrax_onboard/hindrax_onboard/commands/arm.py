"""``hindrax arm|disarm|reset [--vehicle NAME]``: arm or disarm a vehicle's thruster outputs, or clear its
supervisor's latched trip (``reset``: after an e-stop or a limit; then ``hindrax arm``).

On the topside (the operator's PC on the vehicle's topside domain) the command calls the gateway's
``/<name>/arm`` or ``/<name>/disarm`` (hindrax_msgs/SignedTrigger, signed with the vehicle's key,
docs/architecture.md §8.2); run on the vehicle itself it calls the ESC's ``esc/set_armed``
(hindrax_msgs/SetArmed). The vehicle is the one named, or the only one on the domain
(:mod:`hindrax_onboard.commands.vehicle`). Prints one line, ``<name>: armed`` / ``<name>:
disarmed``, and exits 0; a refusal (the ESC's reason: not yet at neutral long enough, the
supervisor tripped, the guard silent...) or no answer prints the reason on stderr and exits 1.

``reset`` calls the gateway's ``/<name>/reset`` (signed, like ``arm``) or, on the vehicle, ``supervisor/reset``
(std_srvs/Trigger), and prints what it cleared: ``<name>: cleared: <the trip's reason>`` or ``<name>: was not
tripped``."""
from __future__ import annotations

import argparse
from typing import Any

from .common import CommandError
from .vehicle import add_vehicle_arguments, call_service, find_vehicle, with_ros

__all__ = ["add_arguments", "run", "set_armed", "reset"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options to ``parser`` (the verb is the subcommand's own name)."""
    parser.set_defaults(_arm=parser.prog.split()[-1] == "arm", _verb=parser.prog.split()[-1])
    add_vehicle_arguments(parser)
    parser.add_argument("--timeout", type=float, default=5.0, metavar="S",
                        help="how long to wait for the answer, s (default 5)")


def set_armed(node: Any, executor: Any, arm: bool, wanted: str | None, discovery_timeout_s: float,
              timeout_s: float) -> tuple[str, bool, str]:
    """Arm (``arm`` True) or disarm the vehicle found by :func:`~hindrax_onboard.commands.vehicle.find_vehicle`. Returns
    (vehicle name, success, message). Raises :class:`CommandError` when no vehicle or no answer."""
    from hindrax_msgs.srv import SetArmed

    target = find_vehicle(node, executor, wanted, discovery_timeout_s)
    verb = "arm" if arm else "disarm"
    srv, service, request = target.service(verb, "esc/set_armed", SetArmed, **({} if target.topside else {"arm": arm}))
    answer = call_service(node, executor, (srv, service, request), timeout_s,
                          f"vehicle {target.name}; check with hindrax health on it")
    message = answer.message or (("armed" if answer.armed else "disarmed") if not target.topside else verb + "ed")
    return target.name, bool(answer.success), message


def reset(node: Any, executor: Any, wanted: str | None, discovery_timeout_s: float,
          timeout_s: float) -> tuple[str, bool, str]:
    """Clear the supervisor's latched trip on the vehicle found (module docstring). Returns (vehicle name, success,
    the supervisor's message: what it cleared). Raises :class:`CommandError` when no vehicle or no answer."""
    from std_srvs.srv import Trigger

    target = find_vehicle(node, executor, wanted, discovery_timeout_s)
    answer = call_service(node, executor, target.service("reset", "supervisor/reset", Trigger), timeout_s,
                          f"vehicle {target.name}; check with hindrax health on it")
    return target.name, bool(answer.success), answer.message


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    if args._verb == "reset":
        name, ok, message = with_ros(lambda node, ex: reset(node, ex, args.vehicle, args.discovery_timeout,
                                                            args.timeout), "hindrax_reset")
        if not ok:
            raise CommandError(f"{name}: reset refused: {message}")
        print(f"{name}: {message or 'reset'}", flush=True)
        return 0
    name, ok, message = with_ros(lambda node, ex: set_armed(node, ex, args._arm, args.vehicle,
                                                             args.discovery_timeout, args.timeout), "hindrax_arm")
    verb = "arm" if args._arm else "disarm"
    if not ok:
        raise CommandError(f"{name}: {verb} refused: {message}")
    print(f"{name}: {message}", flush=True)
    return 0
