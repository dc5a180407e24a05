"""Python message classes from ``pkg/msg/Type`` names (for raw subscriptions and raw publishers).

rclpy needs the generated Python class (its type support) to create a subscription or publisher even
when only CDR bytes pass through. Types whose package is not installed cannot be subscribed to or
published; they can still be decoded from a bag's stored ``ros2msg`` schema
(:meth:`hindrax_drivers.recording.reader.BagReader.decoded`).
"""
from __future__ import annotations

import importlib
from typing import Any

from .msgdefs import split_type_name


class TypeNotInstalledError(LookupError):
    """The Python module of a message type cannot be imported."""


def message_class(type_name: str) -> Any:
    """The generated class of ``pkg/msg/Type`` (e.g. ``sensor_msgs.msg.Imu``).

    Raises :class:`TypeNotInstalledError` with a one-line explanation when it cannot be imported, and
    ValueError for a malformed name.
    """
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
