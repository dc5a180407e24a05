"""``hindrax pool rehearse [--topside-domain N] [--dir DIR] [--truth FILE] [NAME:=VALUE ...]``: the README's pool
day on a laptop.

One command stands in for the vehicle: it starts the live pool (:mod:`hindrax_sim.live_pool`: the simulator
behind the five emulated devices, in a process of its own, on the wall clock) and the *installed*
``hindrax_onboard/pool_test.launch.xml`` (``make ros-install``, then ``source ros_ws/install/setup.bash``), process by
process as ``ros2 launch`` starts it (:class:`~hindrax_bringup.layout.process_runner.ProcessRunner`), the drivers
pointed at the pool's serial ports and I2C socket; ``NAME:=VALUE`` are more launch arguments (``model_file:=`` of the
block's second launch; an undeclared one is refused in one line). The vehicle file is the installed one with its
oscillator marked measured (``hindrax esc calibrate --write`` on a real vehicle), written to ``DIR/hindrax.yaml``.

Domains, as the README names them: the **internal domain** is this shell's ``ROS_DOMAIN_ID`` (the vehicle's
processes; default 0), the **topside domain** is ``--topside-domain`` (default: the internal one + 1), where the
gateway serves ``/<vehicle.name>/...``. Both on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``). It writes
``DIR/vehicle.env`` and ``DIR/topside.env`` (``source`` one in each shell that plays that machine), prints both, and
then reads the pool operator's hands from its standard input: a prompt's code (``attach_ballast``,
``remove_ballast``, ``apply_line_pull_surge``, ...) does that in the pool; ``quit``, end of input or Ctrl-C stops the
launch (SIGINT: the recorder closes its bag) and the pool. Logs: ``DIR/logs/``; bags: ``DIR/runs/``. It does
the block's ``hindrax keys`` itself (the gateway reads the key at its start): a new operator key in ``DIR/keys/``,
named in both environments (``HINDRAX_KEYS_DIR``). ``--rig-cores F``: the launch's processes run in a Pi-sized
CPU rig (:mod:`hindrax_tools.benchmarks.rig`), the pool outside it."""
from __future__ import annotations

import argparse
import contextlib
import os
import shlex
import sys
import tempfile
from pathlib import Path

from hindrax_onboard.commands.common import CommandError

__all__ = ["add_arguments", "run", "rehearsal_env"]

LAUNCH = ("hindrax_onboard", "pool_test.launch.xml")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options to ``parser``."""
    parser.add_argument("--topside-domain", type=int, default=None,
                        help="the topside domain, 0-101 (default: this shell's ROS_DOMAIN_ID + 1)")
    parser.add_argument("--dir", default=None, help="folder for the vehicle file, env files, logs and bags "
                                                    "(default: a new temporary one)")
    parser.add_argument("--truth", default=None, help="the pool's truth file (default: the shipped one)")
    parser.add_argument("launch_arguments", nargs="*", metavar="NAME:=VALUE",
                        help="more arguments of the launch, as ros2 launch takes them (e.g. model_file:=FILE for "
                             "the block's second launch, the identified model)")
    parser.add_argument("--rig-cores", type=float, default=None,
                        help="the launch inside a Pi-sized CPU rig of this many cores here, the pool outside "
                             "(hindrax_tools/benchmarks/rig.py; root): 0.4 half a Pi 4, 0.8 the whole Pi")
    parser.add_argument("--rig-busy-loops", type=int, default=0, help="busy loops in the rig, one Pi core each")


def rehearsal_env(domain: int, **extra: str) -> str:
    """The ``export`` lines of one machine's shell: ``ROS_DOMAIN_ID`` ``domain``, loopback discovery, ``extra``."""
    values = {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", **extra}
    return "".join(f"export {k}={shlex.quote(v)}\n" for k, v in values.items())


#: why a domain id is 0-101 (ROS 2 docs, "The ROS_DOMAIN_ID"): DDS maps it to UDP ports 7400 + 250 x id and up; above
#: 101 they run into Linux's ephemeral ports (32768-60999)
_WHY_0_101 = "ROS 2 maps a domain id to UDP ports 7400 + 250 x id; above 101 they meet Linux's ephemeral ports"


def _domains(args: argparse.Namespace) -> tuple[int, int]:
    raw = os.environ.get("ROS_DOMAIN_ID", "0") or "0"
    try:
        internal = int(raw)
    except ValueError:
        raise CommandError(f"ROS_DOMAIN_ID={raw!r}: allowed an integer 0-101 (the internal domain; {_WHY_0_101})") \
            from None
    topside = internal + 1 if args.topside_domain is None else int(args.topside_domain)
    for name, value in (("ROS_DOMAIN_ID (internal domain)", internal), ("--topside-domain", topside)):
        if not 0 <= value <= 101:
            raise CommandError(f"{name} {value}: allowed 0-101 ({_WHY_0_101})")
    if topside == internal:
        raise CommandError(f"--topside-domain {topside}: must differ from the internal domain (ROS_DOMAIN_ID)")
    return internal, topside


def _refuse_a_domain_in_use(domain: int) -> None:
    """Raise :class:`CommandError` ``"hindrax pool rehearse: refused: ROS domain N already has ESC /esc; ..."`` when
    an ESC or supervisor is on ``domain`` (:func:`hindrax_common.node_support.vehicle_graph.refuse_before_start`, as
    ``hindrax bringup`` and ``hindrax run``): a second vehicle there would cut the first one's thrusters and mix
    into its bags."""
    import rclpy

    from hindrax_common.node_support.vehicle_graph import ForeignVehicleError, refuse_before_start

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    try:
        refuse_before_start(context, "refusing to start a second vehicle on it (set ROS_DOMAIN_ID to a free "
                                     "domain)", "hindrax pool rehearse: refused")
    except ForeignVehicleError as exc:
        raise CommandError(str(exc)) from None
    finally:
        context.try_shutdown()


def run(args: argparse.Namespace) -> int:
    """Start the pool and the launch, print the shells' environments, act as the pool's operator (module
    docstring). Raises :class:`CommandError` without an installed workspace, with bad domains, or when the internal
    domain already has a vehicle (:func:`_refuse_a_domain_in_use`)."""
    import yaml

    from hindrax_common.config import ConfigError, load_config
    from hindrax_bringup.layout.launch_xml import LaunchFileError, ament_share, read_launch
    from hindrax_bringup.gateway.operator_signing import KEYS_DIR_ENV, create_key
    from hindrax_bringup.layout.process_runner import ProcessRunner, installed_command
    from hindrax_tools.benchmarks.rig import Rig, RigError

    from hindrax_sim.live_pool import LivePool

    internal, topside = _domains(args)
    given = dict(item.partition(":=")[::2] for item in args.launch_arguments)
    for item in args.launch_arguments:
        name, sep, _value = item.partition(":=")
        if not sep or not name or name in ("config", "output_dir", "topside_domain_id", "topside_discovery_range"):
            raise CommandError(f"pool rehearse: launch argument {item!r}: expected NAME:=VALUE, NAME not one the "
                               "rehearsal sets (config, output_dir, topside_domain_id, topside_discovery_range)")
    _refuse_a_domain_in_use(internal)
    try:
        launch_file = ament_share(LAUNCH[0]) / "launch" / LAUNCH[1]
        installed = ament_share("hindrax_common") / "config" / "hindrax.yaml"
    except LaunchFileError as exc:
        raise CommandError(f"pool rehearse: {exc}; run make ros-install, then source ros_ws/install/setup.bash") \
            from None
    folder = Path(args.dir or tempfile.mkdtemp(prefix="hindrax-rehearsal-")).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    from hindrax_common.config.sections.esc import board_id

    doc = yaml.safe_load(installed.read_text())
    doc["/**"]["ros__parameters"]["esc"]["oscillator_calibrated"] = True  # the emulated part's, measured here
    doc["/**"]["ros__parameters"]["esc"]["oscillator_measured_on"] = f"{board_id()} emulated"
    vehicle_file = folder / "hindrax.yaml"
    vehicle_file.write_text(yaml.safe_dump(doc))
    try:
        name = load_config(vehicle_file).vehicle.name
    except ConfigError as exc:
        raise CommandError(f"pool rehearse: {exc}") from None
    # the block's `hindrax keys`: the rehearsal's own operator key, read by its gateway and both shells
    keys = {KEYS_DIR_ENV: str(folder / "keys")}
    create_key(folder / "keys" / f"{name}.key", force=True)
    env = {**os.environ, "ROS_DOMAIN_ID": str(internal), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", **keys}
    arguments = {"config": str(vehicle_file), "output_dir": str(folder / "runs"), "topside_domain_id": str(topside),
                 "topside_discovery_range": "LOCALHOST", **given}
    try:
        processes = read_launch(launch_file, arguments)
    except LaunchFileError as exc:
        raise CommandError(f"pool rehearse: {exc}") from None
    files = {"vehicle": (internal, {"HINDRAX_CONFIG": str(vehicle_file), **keys}),
             "topside": (topside, {"HINDRAX_VEHICLE": name, **keys})}
    with contextlib.ExitStack() as rigged, LivePool(vehicle_file, folder / "pool", env=env, truth=args.truth) as pool:
        try:
            rig = rigged.enter_context(Rig(args.rig_cores, args.rig_busy_loops)) if args.rig_cores else None
        except (RigError, ValueError) as exc:
            raise CommandError(f"pool rehearse: {exc}") from None
        runner = ProcessRunner(
            processes, env=env, log_dir=folder / "logs",
            command=lambda p: [*(rig.prefix if rig else ()), *installed_command(p)],
            extra_env={p.label: {k: v for n in p.node_names for k, v in pool.env(n).items()} for p in processes},
            extra_ros_args={p.label: [a for n in p.node_names for a in pool.ros_arguments(n)] for p in processes})
        try:
            runner.start()
        except LookupError as exc:
            raise CommandError(f"pool rehearse: {exc}; run make ros-install, then source ros_ws/install/setup.bash") \
                from None
        try:
            for machine, (domain, extra) in files.items():
                path = folder / f"{machine}.env"
                path.write_text(rehearsal_env(domain, **extra))
                print(f"# {machine} shell ({'internal' if machine == 'vehicle' else 'topside'} domain {domain}): "
                      f"source {path}\n{path.read_text()}", end="", flush=True)
            print(f"rehearsal: {len(processes)} processes of {LAUNCH[0]}/{LAUNCH[1]} on the live pool (logs "
                  f"{folder / 'logs'}, bags {folder / 'runs'}); type a prompt's code to do it in the pool "
                  "(e.g. attach_ballast), quit to stop", flush=True)
            for line in sys.stdin:
                code = line.strip()
                if code == "quit":
                    break
                if code:
                    print(f"pool: {code} {'done' if pool.act(code) else 'unknown: not an operator code'}", flush=True)
        finally:
            runner.stop()
            if rig:
                u = rig.usage()
                print(f"rig {args.rig_cores:g} cores: the launch took {u.cores:.3f} cores, throttled "
                      f"{u.throttled_s:.1f} s of {u.wall_s:.0f} s", flush=True)
    print("rehearsal: stopped", flush=True)
    return 0
