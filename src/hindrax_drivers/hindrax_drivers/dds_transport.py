"""The vehicle's DDS transport: Fast DDS over UDPv4 bound to 127.0.0.1, no shared memory.

Fast DDS 2.14's shared-memory transport runs a port health check when a process first sends to a new
participant; it can sleep 333 ms holding the participant's send lock (Fast-DDS issue 6535), so starting any
ROS 2 process (``hindrax health``, a topic echo, a respawned node) could silence a safety heartbeat past its
0.2 s timeout and disarm the vehicle. The profile ``share/hindrax_drivers/config/fastdds_loopback.xml`` gives
every participant one UDPv4 transport whose interface white list is 127.0.0.1: discovery (multicast joined on
loopback) and data stay on the machine, as ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps them, without the
shared-memory transport (docs/architecture.md §11.4; the ``safety`` rows of ``make bench`` measure it).

Why not simply LOCALHOST: under ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps 8.4 replaces a
participant's transports by its own shared-memory + UDPv4 pair, ignoring the profile's. So a process that asks
for loopback discovery gets ``SYSTEM_DEFAULT`` (rmw leaves the transports alone) plus the profile
(``FASTRTPS_DEFAULT_PROFILES_FILE``); ``test_dds_transport.py`` checks that every UDP socket of such a process is
bound to 127.0.0.1 (or is a multicast group joined on loopback) and that it maps no Fast DDS shared memory.
A process that asks for ``SUBNET`` (the topside, the gateway's topside side) keeps Fast DDS's default transports.

Applied by: ``vehicle.launch.xml`` (``<set_env>`` for every vehicle process), the ``hindrax`` command
(:mod:`hindrax_ident.cli`), the virtual pool's bring-up, the tests (conftest, :func:`hindrax_drivers.testing.
child_env`) and ``make bench``. This module imports nothing but the standard library, so ``hindrax --help``
stays fast.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import MutableMapping

__all__ = ["PROFILE_ENV", "PROFILE_FILE", "RANGE_ENV", "loopback_transport", "profile_path"]

#: the discovery-range variable of ROS 2 Jazzy
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
#: Fast DDS's default-profile file variable (read once per process, at its first participant)
PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
#: the profile's file name, in ``share/hindrax_drivers/config`` (repository: ``ros_ws/config``)
PROFILE_FILE = "fastdds_loopback.xml"
_PACKAGE = "hindrax_drivers"


def profile_path() -> Path:
    """The loopback UDP profile of this workspace: ``share/hindrax_drivers/config/fastdds_loopback.xml`` of the
    install space this module was imported from (colcon), else the checkout's ``src/hindrax_drivers/config``
    (the dev venv), else the first ament prefix (``AMENT_PREFIX_PATH``) holding it.

    Raises FileNotFoundError naming the places searched."""
    here = Path(__file__).resolve()
    candidates = [here.parents[1] / "config" / PROFILE_FILE]  # checkout: src/hindrax_drivers/config
    for parent in here.parents:  # install space: <prefix>/lib/pythonX.Y/site-packages/hindrax_drivers
        if parent.name == "lib":
            candidates.append(parent.parent / "share" / _PACKAGE / "config" / PROFILE_FILE)
            break
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / _PACKAGE / "config" / PROFILE_FILE)
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"{PROFILE_FILE} not found (searched {', '.join(map(str, candidates))})")


def loopback_transport(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """Give ``env`` (default ``os.environ``, changed in place and returned) the loopback UDP transport when it asks
    for loopback discovery: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` unset, empty or ``LOCALHOST`` becomes
    ``SYSTEM_DEFAULT`` with ``FASTRTPS_DEFAULT_PROFILES_FILE`` = :func:`profile_path`. Any other range
    (``SUBNET``, ``OFF``, ``SYSTEM_DEFAULT`` chosen by the user) is left as it is.

    Call it before the process's first rclpy ``init`` (Fast DDS reads the profile file once per process).
    Raises FileNotFoundError when the profile is not installed."""
    env = os.environ if env is None else env
    if env.get(RANGE_ENV, "").strip().upper() in ("", "LOCALHOST"):
        env[PROFILE_ENV] = str(profile_path())
        env[RANGE_ENV] = "SYSTEM_DEFAULT"
    return env
