"""Light decoding and encoding of CDR bytes: ``rosbags``' generated (de)serialisers instead of rclpy's classes.

Taking or publishing an rclpy message is mostly its conversion between Python and C structures; rosbags' objects skip
that. They have the ROS field names (nested messages as objects, numeric arrays as numpy arrays), so a handler written
for the rclpy message reads them unchanged, but they are read-only data (no rclpy type checks). The bytes differ from
rclpy's only in padding, and every reader decodes them to the same message (test_lean_cdr.py).

On the 50 Hz chain and the safety path (docs/architecture.md §10): the wrench, the allocation's command, the ESC's pulse
widths and latched state and the IMU are published as bytes (:func:`cdr_encoder`, ``Publisher.publish(bytes)``); the
supervisor's ``imu/data_raw``, the allocation's ``wrench`` and the campaign bag reader's topics are decoded with
:func:`cdr_decoder` (``bytes -> object`` for a ``pkg/msg/Type`` name or an rclpy message class). ``hindrax_msgs`` types
are registered from their installed ``.msg`` files (:func:`hindrax_common.cdr.msgdefs.message_definition`), the standard
ones come with rosbags' Jazzy store.

The safety heartbeats (``hindrax_msgs/Heartbeat``) are a fixed layout, fixed-size fields first and
one string last: :func:`heartbeat_cdr` and :func:`read_heartbeat` pack and read it with
:mod:`struct` at fixed offsets, tested against rclpy's own serialiser."""
from __future__ import annotations

import functools
import struct
import threading
from typing import Any, Callable, NamedTuple, Sequence

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .msgdefs import DELIMITER, message_definition

__all__ = ["Beat", "cdr_decoder", "cdr_encoder", "diagnostic_status_cdr", "heartbeat_cdr", "imu_cdr", "lean_class",
           "prepare", "read_heartbeat", "thruster_pwm_cdr", "thruster_pwm_encode", "thruster_pwm_lean", "type_name_of",
           "wrench_stamped_cdr"]

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


def _registered_store(type_name: str) -> Any:
    store = _typestore()
    with _lock:
        if type_name not in store.fielddefs:
            _register(store, type_name)
    return store


def _compiled_store(type_name: str) -> Any:
    """The store with ``type_name`` registered and its code generated (rosbags does that at the first message)."""
    store = _registered_store(type_name)
    store.get_msgdef(type_name)
    return store


@functools.lru_cache(maxsize=None)
def _decoder(type_name: str) -> Callable[[bytes], Any]:
    deserialize = _compiled_store(type_name).deserialize_cdr
    return lambda data: deserialize(data, type_name)


@functools.lru_cache(maxsize=None)
def _encoder(type_name: str) -> Callable[[Any], bytes]:
    serialize = _compiled_store(type_name).serialize_cdr
    return lambda obj: bytes(serialize(obj, type_name))


def prepare(*msg_types: Any) -> None:
    """Register ``msg_types`` (rclpy message classes or ``pkg/msg/Type`` names) and generate their
    rosbags code now, at a node's start: the first use costs tens of ms of CPU, which a tick of the
    ESC's executor would otherwise pay while its heartbeat waits. Raises as :func:`cdr_decoder`."""
    for msg_type in msg_types:
        _compiled_store(type_name_of(msg_type))


def cdr_encoder(msg_type: Any) -> Callable[[Any], bytes]:
    """``object -> bytes``: the CDR (little-endian, with its 4-byte encapsulation header, as rclpy publishes) of a
    rosbags object of ``msg_type`` (an rclpy message class or ``pkg/msg/Type``; build it with :func:`lean_class`),
    for ``Publisher.publish(bytes)`` (module docstring). Raises as :func:`cdr_decoder`."""
    return _encoder(type_name_of(msg_type))


def lean_class(msg_type: Any) -> Any:
    """rosbags' dataclass of ``msg_type`` (an rclpy message class or ``pkg/msg/Type``): keyword arguments are the ROS
    field names, nested messages are objects of their own classes, numeric arrays numpy arrays. Raises as
    :func:`cdr_decoder`."""
    type_name = type_name_of(msg_type)
    return _registered_store(type_name).types[type_name]


def cdr_decoder(msg_type: Any) -> Callable[[bytes], Any]:
    """``bytes -> object`` decoding the CDR of ``msg_type`` (an rclpy message class or ``pkg/msg/Type``) with rosbags
    (module docstring). Raises ValueError for a name that is not a message type and
    :class:`~hindrax_common.cdr.msgdefs.DefinitionNotFoundError` when its definition is not installed."""
    return _decoder(type_name_of(msg_type))


# -- the messages published as bytes (module docstring): the 50 Hz wrench -> registers chain and the IMU ----------
@functools.lru_cache(maxsize=1)
def _stamp_classes() -> tuple[Any, Any]:
    return lean_class("std_msgs/msg/Header"), lean_class("builtin_interfaces/msg/Time")


def _header(stamp_ns: int, frame_id: str) -> Any:
    """rosbags' ``std_msgs/Header`` of ROS time ``stamp_ns`` (ns, >= 0) and ``frame_id``."""
    header, time_ = _stamp_classes()
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return header(stamp=time_(sec=sec, nanosec=nanosec), frame_id=frame_id)


@functools.lru_cache(maxsize=1)
def _wrench_parts() -> tuple[Any, ...]:
    return (lean_class("geometry_msgs/msg/WrenchStamped"), lean_class("geometry_msgs/msg/Wrench"),
            lean_class("geometry_msgs/msg/Vector3"), cdr_encoder("geometry_msgs/msg/WrenchStamped"))


def wrench_stamped_cdr(stamp_ns: int, frame_id: str, wrench: Any) -> bytes:
    """CDR of a ``geometry_msgs/WrenchStamped`` (:func:`cdr_encoder`): header stamp ``stamp_ns`` (ns of ROS time,
    >= 0), ``frame_id``, ``wrench`` 6 numbers [Fx Fy Fz Mx My Mz] (N, N m, in ``frame_id``)."""
    cls, wrench_cls, vector, encode = _wrench_parts()
    f = [float(x) for x in wrench]
    return encode(cls(header=_header(stamp_ns, frame_id),
                      wrench=wrench_cls(force=vector(x=f[0], y=f[1], z=f[2]), torque=vector(x=f[3], y=f[4], z=f[5]))))


@functools.lru_cache(maxsize=1)
def _pwm_parts() -> tuple[Any, Any]:
    return lean_class("hindrax_msgs/msg/ThrusterPwm"), cdr_encoder("hindrax_msgs/msg/ThrusterPwm")


def thruster_pwm_lean(stamp_ns: int, frame_id: str, pulse_width_us: Any, armed: bool, output_state: int = 0) -> Any:
    """A rosbags ``hindrax_msgs/ThrusterPwm`` (:func:`lean_class`): header stamp ``stamp_ns`` (ns of ROS time, >= 0),
    ``frame_id``, ``pulse_width_us`` (n,) us (a float64 array), ``armed``, ``output_state`` (0-2, the message's
    constants; 0 for a command). Its fields read as an rclpy message's; :func:`thruster_pwm_encode` gives its CDR."""
    return _pwm_parts()[0](header=_header(stamp_ns, frame_id),
                           pulse_width_us=np.asarray(pulse_width_us, dtype=np.float64), armed=bool(armed),
                           output_state=int(output_state))


def thruster_pwm_encode(msg: Any) -> bytes:
    """CDR of a rosbags ``ThrusterPwm`` (:func:`thruster_pwm_lean`), for ``Publisher.publish(bytes)``."""
    return _pwm_parts()[1](msg)


def thruster_pwm_cdr(stamp_ns: int, frame_id: str, pulse_width_us: Any, armed: bool, output_state: int) -> bytes:
    """CDR of a ``hindrax_msgs/ThrusterPwm`` (:func:`cdr_encoder`): the fields of :func:`thruster_pwm_lean`."""
    return thruster_pwm_encode(thruster_pwm_lean(stamp_ns, frame_id, pulse_width_us, armed, output_state))


@functools.lru_cache(maxsize=1)
def _imu_parts() -> tuple[Any, ...]:
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0  # REP-145: no orientation estimate
    return (lean_class("sensor_msgs/msg/Imu"), lean_class("geometry_msgs/msg/Vector3"),
            lean_class("geometry_msgs/msg/Quaternion"), no_orientation, cdr_encoder("sensor_msgs/msg/Imu"))


def imu_cdr(stamp_ns: int, frame_id: str, accel_m_s2: Any, gyro_rad_s: Any, accel_cov: Any, gyro_cov: Any) -> bytes:
    """CDR of a ``sensor_msgs/Imu`` without orientation (:func:`cdr_encoder`; REP-145: ``orientation_covariance[0]
    = -1``, the orientation left at rclpy's default, the identity): header stamp ``stamp_ns`` (ns of ROS time, >= 0),
    ``frame_id``, linear acceleration (3,) m/s^2 and angular velocity (3,) rad/s in ``frame_id``, their covariances
    (9,) or (3, 3)."""
    cls, vector, quaternion, no_orientation, encode = _imu_parts()
    a = [float(x) for x in accel_m_s2]
    g = [float(x) for x in gyro_rad_s]
    return encode(cls(header=_header(stamp_ns, frame_id), orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                      orientation_covariance=no_orientation, angular_velocity=vector(x=g[0], y=g[1], z=g[2]),
                      angular_velocity_covariance=np.asarray(gyro_cov, dtype=np.float64).ravel(),
                      linear_acceleration=vector(x=a[0], y=a[1], z=a[2]),
                      linear_acceleration_covariance=np.asarray(accel_cov, dtype=np.float64).ravel()))


# -- the ESC's latched state (esc_state.py)
@functools.lru_cache(maxsize=1)
def _status_parts() -> tuple[Any, ...]:
    return (lean_class("diagnostic_msgs/msg/DiagnosticStatus"), lean_class("diagnostic_msgs/msg/KeyValue"),
            cdr_encoder("diagnostic_msgs/msg/DiagnosticStatus"))


def diagnostic_status_cdr(level: int, name: str, message: str, hardware_id: str,
                          values: Sequence[tuple[str, str]] = ()) -> bytes:
    """CDR of a ``diagnostic_msgs/DiagnosticStatus`` (:func:`cdr_encoder`): ``esc/output_state``
    (:mod:`hindrax_common.node_support.esc_state`). ``level``: the message's constants (OK 0 ... STALE 3, an int or
    rclpy's one-byte bytes); ``values``: (key, value) pairs."""
    cls, key_value, encode = _status_parts()
    if isinstance(level, (bytes, bytearray)):  # rclpy's constants are one-byte bytes (``byte`` fields)
        level = level[0]
    return encode(cls(level=int(level), name=name, message=message, hardware_id=hardware_id,
                      values=[key_value(key=k, value=v) for k, v in values]))


# -- the safety heartbeats (module docstring)
#: CDR little-endian encapsulation (plain CDR, options 0), as rclpy publishes on every ROS 2 host here
_CDR_LE = b"\x00\x01\x00\x00"
#: hindrax_msgs/Heartbeat up to the string's length: header, boot_id, seq, steady_ns, guard_boot_id, guard_seq (uint64,
#: offsets 0-39 of the payload), level, output_state, armed (40-42), one byte of alignment, the string length (44)
_BEAT = struct.Struct("<4sQQQQQBB?xI")


class Beat(NamedTuple):
    """One ``hindrax_msgs/Heartbeat`` as :func:`read_heartbeat` reads it: the message's fields, same names and
    meaning (``hindrax_msgs/msg/Heartbeat.msg``), so a handler reads it or an rclpy ``Heartbeat`` alike."""

    boot_id: int
    seq: int
    steady_ns: int
    guard_boot_id: int
    guard_seq: int
    level: int
    output_state: int
    armed: bool
    message: str


def heartbeat_cdr(boot_id: int, seq: int, steady_ns: int, level: int, message: str = "", output_state: int = 0,
                  armed: bool = False, guard_boot_id: int = 0, guard_seq: int = 0) -> bytes:
    """CDR of a ``hindrax_msgs/Heartbeat`` for ``Publisher.publish(bytes)``: the fields of :class:`Beat` (integers in
    their field's range: ``struct.error`` otherwise; ``message`` UTF-8)."""
    text = message.encode("utf-8") + b"\0"
    return _BEAT.pack(_CDR_LE, boot_id, seq, steady_ns, guard_boot_id, guard_seq, level, output_state, armed,
                      len(text)) + text


def read_heartbeat(data: bytes) -> Beat | None:
    """The :class:`Beat` in the CDR bytes of a ``hindrax_msgs/Heartbeat`` (a raw subscription's message), or None when
    they are not one: another encapsulation, too short, a string that does not fit or is not UTF-8."""
    if len(data) < _BEAT.size or data[:4] != _CDR_LE:
        return None
    _, boot_id, seq, steady_ns, guard_boot_id, guard_seq, level, output_state, armed, n = _BEAT.unpack_from(data)
    end = _BEAT.size + n
    if n < 1 or len(data) < end or data[end - 1] != 0:
        return None
    try:
        message = data[_BEAT.size:end - 1].decode("utf-8")
    except UnicodeDecodeError:
        return None
    return Beat(boot_id, seq, steady_ns, guard_boot_id, guard_seq, level, output_state, armed, message)
