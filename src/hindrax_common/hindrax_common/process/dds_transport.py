"""The vehicle's DDS transport: Fast DDS over UDPv4 bound to 127.0.0.1, no shared memory.

Fast DDS 2.14's shared-memory transport can sleep 333 ms holding a participant's send lock when it first sends to a new
participant (Fast-DDS issue 6535): starting any ROS 2 process could silence a safety heartbeat past its 0.2 s timeout.
The profile ``share/hindrax_common/config/fastdds_loopback.xml`` gives every participant one UDPv4 transport
white-listed to 127.0.0.1 (docs/architecture.md §11.4; the ``safety`` rows of ``make bench``).

Not ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` alone: under it rmw_fastrtps 8.4 replaces the profile's transports by
its own shared-memory + UDPv4 pair. So a process that asks for loopback gets ``SYSTEM_DEFAULT`` plus the profile
(``FASTRTPS_DEFAULT_PROFILES_FILE``; ``test_dds_transport.py`` checks its sockets and that it maps no shared memory).
``SUBNET`` (the topside) keeps Fast DDS's default transports, with ``fastdds_topside.xml``'s 0.5 s announcement period.

Applied by ``vehicle.launch.xml`` (``<set_env>``), the ``hindrax`` command, the virtual pool's bring-up, the tests
(:func:`hindrax_common.testing.child_env`) and ``make bench``. Standard library only, so ``hindrax --help`` stays fast.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Callable, MutableMapping

__all__ = ["ANNOUNCE_PERIOD_S", "DISCOVERY_BOUND_S", "DISCOVERY_CAP_S", "PROFILE_ENV", "PROFILE_FILE", "RANGE_ENV",
           "TOPSIDE_PROFILE_FILE", "loopback_transport", "profile_path", "wait_discovered"]

#: the discovery-range variable of ROS 2 Jazzy
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
#: Fast DDS's default-profile file variable (read once per process, at its first participant)
PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
#: the profile's file name, in ``share/hindrax_common/config`` (repository: ``ros_ws/config``)
PROFILE_FILE = "fastdds_loopback.xml"
#: the topside's profile beside it: default transports, the same announcement period (:func:`loopback_transport`)
TOPSIDE_PROFILE_FILE = "fastdds_topside.xml"
_PACKAGE = "hindrax_common"
#: how often every participant announces itself (``leaseAnnouncement`` of the profiles, Fast DDS's default 3 s), s
ANNOUNCE_PERIOD_S = 0.5
#: a participant that is running is seen by a new one within this, s: three announcement periods (a missed first
#: exchange and a missed periodic announcement, and the delivery)
DISCOVERY_BOUND_S = 3 * ANNOUNCE_PERIOD_S
#: :func:`wait_discovered` gives up on a graph that keeps changing after this, s
DISCOVERY_CAP_S = 8.0
#: the name the graph gives an endpoint seen before its participant's node names arrived (discovery not finished)
UNNAMED_NODE = "_NODE_NAME_UNKNOWN_"


def wait_discovered(view: Callable[[], object], ready: Callable[[], bool], pause: Callable[[], object], *,
                    bound_s: float = DISCOVERY_BOUND_S, quiet_s: float = ANNOUNCE_PERIOD_S,
                    cap_s: float = DISCOVERY_CAP_S, clock: Callable[[], float] = time.monotonic) -> bool:
    """Wait on discovery, the one way every tool does (the refusal look-out, the CLI's choice of vehicle): True once
    ``ready()`` holds, ``bound_s`` has passed since the call (:data:`DISCOVERY_BOUND_S`: whatever runs has been seen)
    and ``view()`` (what the graph shows: any value compared with ``==``) has not changed for ``quiet_s`` (one
    announcement period: names and endpoints follow their participant); False when ``cap_s`` passed first. ``pause()``
    runs between looks (spin an executor, or wait). What ``ready`` or ``view`` raise (a refusal) propagates."""
    start = clock()
    shown, changed_at = view(), start
    while True:
        now = clock()
        latest = view()
        if latest != shown:
            shown, changed_at = latest, now
        if ready() and now - start >= bound_s and now - changed_at >= quiet_s:
            return True
        if now - start >= cap_s:
            return False
        pause()


def profile_path(name: str = PROFILE_FILE) -> Path:
    """A profile of this workspace (default the loopback UDP one; :data:`TOPSIDE_PROFILE_FILE` the topside's):
    ``share/hindrax_common/config/<name>`` of the install space this module was imported from (colcon), else the
    checkout's ``src/hindrax_common/config`` (the dev venv), else the first ament prefix (``AMENT_PREFIX_PATH``)
    holding it.

    Raises FileNotFoundError naming the places searched."""
    here = Path(__file__).resolve()
    candidates = [here.parents[2] / "config" / name]  # checkout: src/hindrax_common/config
    for parent in here.parents:  # install space: <prefix>/lib/pythonX.Y/site-packages/hindrax_common
        if parent.name == "lib":
            candidates.append(parent.parent / "share" / _PACKAGE / "config" / name)
            break
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidates.append(Path(prefix) / "share" / _PACKAGE / "config" / name)
    for path in candidates:
        if path.is_file():
            return path
    raise FileNotFoundError(f"{name} not found (searched {', '.join(map(str, candidates))})")


def loopback_transport(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """Give ``env`` (default ``os.environ``, changed in place and returned) the loopback UDP transport when it asks for
    loopback discovery: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` unset, empty or ``LOCALHOST`` becomes ``SYSTEM_DEFAULT`` with
    ``FASTRTPS_DEFAULT_PROFILES_FILE`` = :func:`profile_path`. ``SUBNET`` (the topside) keeps its transports and gets
    the topside profile (:data:`TOPSIDE_PROFILE_FILE`: the announcement period only) unless a profile is already named.
    Any other range (``OFF``, ``SYSTEM_DEFAULT`` chosen by the user) is left as it is.

    Call it before the process's first rclpy ``init`` (Fast DDS reads the profile file once per process).
    Raises FileNotFoundError when the profile is not installed."""
    env = os.environ if env is None else env
    scope = env.get(RANGE_ENV, "").strip().upper()
    if scope in ("", "LOCALHOST"):
        env[PROFILE_ENV] = str(profile_path())
        env[RANGE_ENV] = "SYSTEM_DEFAULT"
    elif scope == "SUBNET" and not env.get(PROFILE_ENV):
        env[PROFILE_ENV] = str(profile_path(TOPSIDE_PROFILE_FILE))
    return env
