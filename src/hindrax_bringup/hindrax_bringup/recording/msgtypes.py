"""Python message classes from ``pkg/msg/Type`` names (for raw subscriptions and raw publishers).

rclpy needs the generated Python class (its type support) to create a subscription or publisher even when only CDR bytes
pass through. Types whose package is not installed cannot be subscribed to or published; they can still be decoded from
a bag's stored ``ros2msg`` schema (:meth:`hindrax_bringup.recording.reader.BagReader.decoded`)."""
from __future__ import annotations

import importlib
from typing import Any

from hindrax_common.cdr.msgdefs import split_type_name


class TypeNotInstalledError(LookupError):
    """The Python module of a message type cannot be imported."""


def message_class(type_name: str) -> Any:
    """The generated class of ``pkg/msg/Type`` (e.g. ``sensor_msgs.msg.Imu``).

    Raises :class:`TypeNotInstalledError` with a one-line explanation when it cannot be imported, and
    ValueError for a malformed name."""
    pkg, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f"{pkg}.msg")
    except ImportError as exc:
        raise TypeNotInstalledError(
            f"message type {pkg}/msg/{name} is not installed (no Python module {pkg}.msg: {exc})") from exc
    cls = getattr(module, name, None)
    if cls is None:
        raise TypeNotInstalledError(f"message type {pkg}/msg/{name} is not installed ({pkg}.msg has no {name})")
    return cls


def from_decoded(cls: Any, decoded: Any) -> Any:
    """An instance of the generated class ``cls`` holding the fields of ``decoded``, an object decoded from a
    bag's stored definition (``mcap_ros2``: one attribute per field, nested messages as objects).

    For a bag recorded before the installed type changed: a field the stored definition lacks keeps the installed
    default (``ThrusterPwm.output_state`` reads ``OUTPUT_UNKNOWN`` in a bag from before it existed), a field the
    installed type lacks is dropped. Nested messages and sequences of messages are converted the same way.
    Raises what the generated setters raise (TypeError, AssertionError) for a field whose type changed."""
    msg = cls()
    for name, ftype in cls.get_fields_and_field_types().items():
        if not hasattr(decoded, name):
            continue
        value = getattr(decoded, name)
        current = getattr(msg, name)
        if hasattr(current, "get_fields_and_field_types"):
            value = from_decoded(type(current), value)
        elif ftype.startswith("sequence<") and "/" in ftype:
            inner = message_class(ftype[len("sequence<"):].split(",")[0].rstrip(">"))
            value = [from_decoded(inner, v) for v in value]
        elif "/" in ftype and ftype.endswith("]"):  # fixed array of messages: pkg/Type[n]
            inner = message_class(ftype[:ftype.index("[")])
            value = [from_decoded(inner, v) for v in value]
        elif isinstance(value, (bytes, bytearray)) and not isinstance(current, (bytes, bytearray)):
            value = list(value)
        setattr(msg, name, value)
    return msg
