"""One node process of the stack benchmark's launch layout: a console script's function, as installed.

``python -m hindrax_tools.benchmarks.launch_node MODULE[:FUNCTION] --ros-args ...`` runs ``MODULE.FUNCTION()``
(default ``main``, e.g. ``hindrax_bringup.layout.composition:i2c_sensors_main``) as the installed console script
does. The I2C drivers reach the virtual pool's emulated bus through their own ``open_smbus``
(:data:`hindrax_common.transport.socket_i2c.SOCKET_ENV`), so nothing of the node is replaced. This module imports no
simulator, emulator or benchmark code, so a benchmarked process holds the modules and memory the vehicle's holds
(``test_bench_launch_layout.py`` checks it).

``HINDRAX_BENCH_PROFILE=DIR`` (:data:`PROFILE_ENV`): cProfile, ``DIR/<module>.prof`` written on exit, ``os._exit``
included (:data:`hindrax_common.process.ros_process.BEFORE_PROCESS_END`). Every Python thread takes its ``threading``
name as its OS thread name (:func:`name_os_threads`), for the benchmark's figures by thread.

``HINDRAX_BENCH_TOPOLOGY=DIR`` (:data:`TOPOLOGY_ENV`): a SIGUSR1 writes the process's nodes' endpoints to
``DIR/<pid>.json`` (:func:`topology`). :func:`skeleton_main` rebuilds one process of such a topology without logic: the
same nodes and endpoints, one pre-serialised message per publisher from a timer at its rate (publishers of one rate
share a timer), callbacks that do nothing; SIGUSR2 switches it to its next phase's rates."""
from __future__ import annotations

import cProfile
import ctypes
import importlib
import json
import os
import signal
import sys
import threading
import weakref
from functools import partial
from pathlib import Path
from typing import Any

from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message

from hindrax_bringup.gateway.internal import interface_type
from hindrax_common.node_support.node_common import run_nodes
from hindrax_common.process.ros_process import BEFORE_PROCESS_END

#: a directory: each node process runs under cProfile and writes ``<module>.prof`` there when it exits
PROFILE_ENV = "HINDRAX_BENCH_PROFILE"


#: a directory: on SIGUSR1 a process writes its endpoints (:func:`topology`) to ``<pid>.json`` there
TOPOLOGY_ENV = "HINDRAX_BENCH_TOPOLOGY"
_QOS_KEYS = ("history", "depth", "reliability", "durability", "liveliness", "deadline", "lifespan",
             "liveliness_lease_duration")
#: an event type (``RCL_SUBSCRIPTION_LIVELINESS_CHANGED``...) less its prefix -> the callbacks' key
_EVENT_KEYS = {"REQUESTED_DEADLINE_MISSED": "deadline", "OFFERED_DEADLINE_MISSED": "deadline",
               "LIVELINESS_CHANGED": "liveliness", "LIVELINESS_LOST": "liveliness",
               "REQUESTED_INCOMPATIBLE_QOS": "incompatible_qos", "OFFERED_INCOMPATIBLE_QOS": "incompatible_qos",
               "MESSAGE_LOST": "message_lost", "INCOMPATIBLE_TYPE": "incompatible_type", "MATCHED": "matched"}


def _type(cls: Any) -> str:
    parts = cls.__module__.split(".")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def _endpoint(e: Any, kind: str) -> dict:
    out: dict = {"topic": getattr(e, "topic_name", None) or e.srv_name,
                 "type": _type(getattr(e, "msg_type", None) or e.srv_type)}
    if kind in ("publishers", "subscriptions"):
        out["qos"] = {k: int(getattr(v, "nanoseconds", v)) for k in _QOS_KEYS for v in [getattr(e.qos_profile, k)]}
        out["events"] = sorted(_EVENT_KEYS[h.event_type.name.split("_", 2)[2]] for h in e.event_handlers)
    if kind == "subscriptions":
        out["raw"] = bool(e.raw)
    return out


def topology(nodes: Any) -> dict:
    """The endpoints of ``nodes`` (rclpy, one process) as JSON: ``{"nodes": [{"name", "namespace",
    "publishers", "subscriptions", "services", "clients"}]}``, each ``{"topic", "type"}``
    (``pkg/msg/Name``), topics with ``qos`` (durations in ns) and ``events`` (event handlers),
    subscriptions with ``raw``; sorted; without each node's own ``/parameter_events`` publisher."""
    out = []
    for node in nodes:
        entry: dict = {"name": node.get_name(), "namespace": node.get_namespace()}
        for kind in ("publishers", "subscriptions", "services", "clients"):
            entry[kind] = sorted((_endpoint(e, kind) for e in getattr(node, kind)
                                  if getattr(e, "topic_name", "") != "/parameter_events"),
                                 key=json.dumps)
        out.append(entry)
    return {"nodes": sorted(out, key=lambda n: (n["namespace"], n["name"]))}


def _dump_topology_on_sigusr1(directory: str) -> None:
    """On SIGUSR1, :func:`topology` of this process's nodes (not ``_exit_``) to ``<pid>.json``, with
    ``"spinning"``: every node is in an executor (its constructor, which makes its endpoints, has
    returned; a node is on the graph from its first line)."""
    nodes: weakref.WeakSet = weakref.WeakSet()
    init = Node.__init__

    def tracked_init(self: Any, *a: Any, **kw: Any) -> None:
        init(self, *a, **kw)
        nodes.add(self)

    def dump(*_: Any) -> None:
        alive = [n for n in list(nodes) if not n.get_name().startswith("_exit_")]
        path = Path(directory) / f"{os.getpid()}.json"
        spinning = bool(alive) and all(n.executor is not None for n in alive)
        path.with_suffix(".tmp").write_text(json.dumps({**topology(alive), "spinning": spinning}))
        os.replace(path.with_suffix(".tmp"), path)

    Node.__init__ = tracked_init
    signal.signal(signal.SIGUSR1, dump)


def _profile(qos: dict) -> Any:
    dur = ("deadline", "lifespan", "liveliness_lease_duration")
    return QoSProfile(**{k: Duration(nanoseconds=v) if k in dur else v for k, v in qos.items()})


def _events(kind: str, names: list) -> Any:
    cls = PublisherEventCallbacks if kind == "publishers" else SubscriptionEventCallbacks
    return cls(use_default_callbacks=False, **{k: (lambda _e: None) for k in names})


def _call_all(fns: list) -> None:
    for fn in fns:  # noqa: SIM110 - calls, not a search
        fn()


def skeleton_main() -> int:
    """One skeleton process: argv ``SPEC LABEL``, SPEC a JSON file ``{"processes": {label:
    topology}}`` whose publishers carry ``rates`` (messages/s per phase) and ``payload`` (CDR hex;
    null: a default message). Returns :func:`~hindrax_common.node_support.node_common.run_nodes`'s status."""
    spec = json.loads(Path(sys.argv[1]).read_text())["processes"][sys.argv[2]]
    phase, timers = [0], []

    def build(nd: dict) -> Any:
        names = {s["topic"] for s in nd["services"]}
        node = Node(nd["name"], namespace=nd["namespace"],
                    start_parameter_services=any(n.endswith("/get_parameters") for n in names))
        have = {e["topic"] for e in topology([node])["nodes"][0]["services"]}  # parameter services
        groups: dict = {}
        for p in nd["publishers"]:
            cls = interface_type(p["type"])
            pub = node.create_publisher(cls, p["topic"], _profile(p["qos"]),
                                        event_callbacks=_events("publishers", p["events"]))
            data = bytes.fromhex(p["payload"]) if p.get("payload") else serialize_message(cls())
            for k, rate in enumerate(p["rates"]):
                if rate > 0:
                    key = (k, round(rate) if rate >= 1 else rate)
                    groups.setdefault(key, []).append(partial(pub.publish, data))
        for (k, rate), sends in groups.items():
            timer = node.create_timer(1.0 / rate, partial(_call_all, sends), autostart=k == 0)
            timers.append((k, timer))
        for s in nd["subscriptions"]:
            node.create_subscription(interface_type(s["type"]), s["topic"], lambda _m: None, _profile(s["qos"]),
                                     raw=s["raw"], event_callbacks=_events("subscriptions", s["events"]))
        for s in nd["services"]:
            if s["topic"] not in have:
                node.create_service(interface_type(s["type"]), s["topic"], lambda _q, r: r)
        for c in nd["clients"]:
            node.create_client(interface_type(c["type"]), c["topic"])
        return node

    def next_phase(*_: Any) -> None:
        phase[0] += 1
        for k, timer in timers:
            timer.reset() if k == phase[0] else timer.cancel()

    signal.signal(signal.SIGUSR2, next_phase)
    return run_nodes([partial(build, nd) for nd in spec["nodes"]], [sys.argv[0]])


#: prctl's option that names the calling thread (linux/prctl.h); the kernel keeps 15 bytes of it
_PR_SET_NAME = 15


def name_os_threads() -> None:
    """From now on, every Python thread started in this process names its OS thread after its ``threading`` name
    (the first 15 bytes; Linux ``prctl(PR_SET_NAME)``); without it every Python thread is ``python`` in
    ``/proc/PID/task/*/comm``. Only the benchmark's node processes do this: nothing of the node changes."""
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    start = threading.Thread._bootstrap_inner

    def named_start(thread: threading.Thread) -> None:
        prctl(_PR_SET_NAME, thread.name.encode(errors="replace")[:15], 0, 0, 0)
        start(thread)

    threading.Thread._bootstrap_inner = named_start


def main(argv: list[str] | None = None) -> int:
    """Run the console script target ``argv[0]`` (``module[:function]``) with the arguments ``argv[1:]``
    (``sys.argv`` without the program name by default); returns its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        print("usage: python -m hindrax_tools.benchmarks.launch_node MODULE[:FUNCTION] "
              "[--ros-args ...]", file=sys.stderr)
        return 2
    entry, rest = argv[0], argv[1:]
    name_os_threads()
    if os.environ.get(TOPOLOGY_ENV):
        _dump_topology_on_sigusr1(os.environ[TOPOLOGY_ENV])
    module_name, _, function = entry.partition(":")
    module = importlib.import_module(module_name)
    run = getattr(module, function or "main")
    sys.argv = [module_name] + rest
    profile_dir = os.environ.get(PROFILE_ENV)
    if not profile_dir:
        return int(run() or 0)

    profiler = cProfile.Profile()
    path = str(Path(profile_dir) / f"{entry.replace(':', '.')}.prof")

    def dump() -> None:
        profiler.disable()
        profiler.dump_stats(path)

    BEFORE_PROCESS_END.append(dump)
    try:
        return int(profiler.runcall(run) or 0)
    finally:
        BEFORE_PROCESS_END.remove(dump)
        profiler.dump_stats(path)


if __name__ == "__main__":
    raise SystemExit(main())
