"""``hindrax topic echo TOPIC [--count N] [--timeout S]``: print a topic's messages, for a shell without the ros2 CLI.

The pip wheels of the venv carry rclpy but not ``ros2 topic``; the README's pool day reads the supervisor's status
(``/<name>/supervisor/status``: ``disarm_cause``) with this. The topic's type is the one the graph shows (waited for up
to ``--timeout`` s); each message prints as YAML (field order of the message definition), ``---`` after each, as
``ros2 topic echo`` does. Subscribed best effort, volatile: it hears reliable and best-effort publishers alike.
Exit 0 after ``--count`` messages (0: until Ctrl-C), 1 when the topic or a message does not come
within the timeout (the line then says whether the topic has a publisher at all, and which)."""
from __future__ import annotations

import argparse
import importlib
from typing import Any

from .common import CommandError
from .vehicle import wait_for, with_ros

__all__ = ["add_arguments", "run", "plain", "silence"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments to ``parser``."""
    parser.add_argument("topic", help="the topic's full name, e.g. /<vehicle>/supervisor/status on the topside")
    parser.add_argument("--count", type=int, default=0, metavar="N",
                        help="stop after N messages (default 0: until Ctrl-C)")
    parser.add_argument("--timeout", type=float, default=10.0, metavar="S",
                        help="how long to wait for the topic and for its first message, s (default 10)")


def plain(value: Any) -> Any:
    """``value`` (a ROS message, a sequence, a number, a string) as plain Python: a message as a dict of its fields in
    definition order (a byte field as its number), a sequence or array as a list."""
    if hasattr(value, "get_fields_and_field_types"):  # a byte field (DiagnosticStatus.level) as its number
        return {k: getattr(value, k)[0] if t in ("octet", "byte") else plain(getattr(value, k))
                for k, t in value.get_fields_and_field_types().items()}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)) or hasattr(value, "tolist"):  # array.array and numpy arrays: tolist
        return [plain(v) for v in (value.tolist() if hasattr(value, "tolist") else value)]
    return value


def silence(topic: str, timeout_s: float, publishers: list) -> str:
    """The one line for a topic that sent nothing within ``timeout_s``: whether the graph shows
    any publisher of it (``publishers``: rclpy's ``TopicEndpointInfo`` list), and which nodes."""
    silent = f"no message on {topic} within {timeout_s:g} s"
    if not publishers:
        return f"{silent}: it has no publisher (only readers on the graph)"
    names = sorted({f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in publishers})
    return (f"{silent} from its {len(publishers)} publisher(s) ({', '.join(names)}): is the node "
            f"sending (a status goes out on a change or at its period)?")


def run(args: argparse.Namespace) -> int:
    """Echo the topic (module docstring). Raises :class:`CommandError` for a topic absent or silent."""
    import yaml
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    if args.count < 0 or not args.timeout > 0:
        raise CommandError(f"--count {args.count} / --timeout {args.timeout:g}: allowed --count >= 0, --timeout > 0")

    def body(node: Any, executor: Any) -> int:
        types: list = []

        def found() -> bool:
            types[:] = [t for n, ts in node.get_topic_names_and_types() if n == args.topic for t in ts]
            return bool(types)
        wait_for(executor, found, args.timeout, f"no topic {args.topic}", "is it spelled as the graph has it?")
        package, kind, name = types[0].split("/")
        cls = getattr(importlib.import_module(f"{package}.{kind}"), name)
        got: list = []
        node.create_subscription(cls, args.topic, got.append,
                                 QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        try:
            wait_for(executor, lambda: got, args.timeout, f"no message on {args.topic}", "")
        except CommandError:  # the line says what the graph shows of its publishers instead
            publishers = node.get_publishers_info_by_topic(args.topic)
            raise CommandError(silence(args.topic, args.timeout, publishers)) from None
        shown = 0
        while not args.count or shown < args.count:
            while got and (not args.count or shown < args.count):
                print(yaml.safe_dump(plain(got.pop(0)), sort_keys=False, width=1 << 16) + "---", flush=True)
                shown += 1
            executor.spin_once(timeout_sec=0.1)
        return 0

    try:
        return with_ros(body, "hindrax_topic_echo")
    except KeyboardInterrupt:
        return 0


