"""Light decoding of CDR bytes for the polled inputs: ``rosbags``' generated deserialisers instead of rclpy's classes.

Why (docs/architecture.md §10.1): taking a message as an rclpy object is mostly its conversion into Python objects,
not DDS. Measured here (one process, 50 queued messages per take, thread CPU per message, November 2026): an
``Imu`` taken as an object 77 us, as CDR bytes 11 us; ``hindrax_msgs/Dvl`` 85 and 12 us; ``ThrusterPwm`` 43 and
11 us. ``rosbags`` (a maintained bag library the project already uses) decodes the same bytes in 20, 29 and 10 us
with deserialisers it generates per type, so a node that reads a few fields of every sample takes ``Imu`` for about
31 us instead of 77. Its objects have the ROS field names (nested messages as objects, numeric arrays as numpy
arrays), so a handler written for the rclpy message reads them unchanged; they are read-only data, not rclpy
messages (no ``publish``, no rclpy type checks).

:func:`cdr_decoder` returns ``bytes -> object`` for a ``pkg/msg/Type`` name or an rclpy message class. The project's
own interfaces (``hindrax_msgs``) are registered from their installed ``.msg`` files
(:func:`hindrax_drivers.recording.msgdefs.message_definition`), the standard ones come with rosbags' Jazzy store.
"""
from __future__ import annotations

import functools
import threading
from typing import Any, Callable

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .recording.msgdefs import DELIMITER, message_definition

__all__ = ["cdr_decoder", "type_name_of"]

_lock = threading.Lock()


def type_name_of(msg_type: Any) -> str:
    """``pkg/msg/Type`` of an rclpy message class (``sensor_msgs.msg.Imu`` -> ``sensor_msgs/msg/Imu``), or the name
    itself when given a string. Raises ValueError for anything else."""
    if isinstance(msg_type, str):
        return msg_type
    module = getattr(msg_type, "__module__", "")
    parts = module.split(".")
    if len(parts) < 2 or parts[1] != "msg":
        raise ValueError(f"not a ROS message class: {msg_type!r}")
    return f"{parts[0]}/msg/{msg_type.__name__}"


@functools.lru_cache(maxsize=1)
def _typestore() -> Any:
    return get_typestore(Stores.ROS2_JAZZY)


def _register(store: Any, type_name: str) -> None:
    """Register ``type_name`` and the dependencies the store lacks, from the installed ``.msg`` files."""
    parts = message_definition(type_name).split("\n" + DELIMITER + "\n")
    types: dict = {}
    for i, text in enumerate(parts):
        name = type_name
        if i:
            header, _, text = text.partition("\n")
            pkg, _, leaf = header[len("MSG: "):].strip().partition("/")
            name = f"{pkg}/msg/{leaf.rsplit('/', 1)[-1]}"
        if name not in store.fielddefs:
            types.update(get_types_from_msg(text, name))
    store.register(types)


@functools.lru_cache(maxsize=None)
def _decoder(type_name: str) -> Callable[[bytes], Any]:
    store = _typestore()
    with _lock:
        if type_name not in store.fielddefs:
            _register(store, type_name)
    deserialize = store.deserialize_cdr
    return lambda data: deserialize(data, type_name)


def cdr_decoder(msg_type: Any) -> Callable[[bytes], Any]:
    """``bytes -> object`` decoding the CDR of ``msg_type`` (an rclpy message class or ``pkg/msg/Type``) with rosbags
    (module docstring). Raises ValueError for a name that is not a message type and
    :class:`~hindrax_drivers.recording.msgdefs.DefinitionNotFoundError` when its definition is not installed."""
    return _decoder(type_name_of(msg_type))
