"""Blue Robotics Ping1D (Ping / Ping2 echosounder) binary protocol: pure frame codec and payloads.

Layer 1 of the Ping1D altimeter driver (docs/architecture.md §2): bytes in, typed values out, and the reverse.
No I/O, no clocks, no ROS.  Source: docs/devices.md §2.2-§2.5 (tags [P1]-[P10]).

Frame (little-endian, docs/devices.md §2.2): ``'B' 'R'``, u16 payload_length, u16 message_id,
u8 src_device_id, u8 dst_device_id, payload, u16 checksum = (sum of every preceding byte) & 0xFFFF.

Our own codec, not the PyPI package ``bluerobotics-ping``: its 0.2.x ``Ping1D`` class is broken
(docs/devices.md §0 item 4, §2.7). This one is verified against the byte-exact vectors of §2.5,
with a declared parse error and a streaming framer that resynchronises on ``BR``.

Units: payload fields are converted to SI on decode (mm -> m, mm/s -> m/s, ms/µs -> s, mV -> V,
centi-degC -> degC; confidence stays in %), and back on encode with rounding to the wire resolution."""

from __future__ import annotations

import math
import struct
from dataclasses import MISSING, dataclass, field, fields as dc_fields, make_dataclass
from enum import IntEnum
from typing import Any, ClassVar, Dict, Optional, Tuple, Type, Union

__all__ = ["Ping1dParseError", "Ping1dId", "Ping1dMessage", "Ping1dFramer", "Ping1dPayload", "Ack", "Nack", "AsciiText",
           "DeviceInformation", "ProtocolVersion", "GeneralRequest", "SetDeviceId", "SetRange", "SetSpeedOfSound",
           "SetModeAuto", "SetPingInterval", "SetGainSetting", "SetPingEnable", "GotoBootloader", "FirmwareVersion",
           "DeviceId", "Voltage5", "SpeedOfSound", "Range", "ModeAuto", "PingInterval", "GainSetting",
           "TransmitDuration", "GeneralInfo", "DistanceSimple", "Distance", "ProcessorTemperature", "PcbTemperature",
           "PingEnable", "Profile", "ContinuousStart", "ContinuousStop", "PAYLOAD_TYPES", "GAIN_INDEX_TO_GAIN",
           "HEADER_BYTES", "CHECKSUM_BYTES", "SYNC_BYTE", "checksum", "encode_frame", "decode_frame", "request_frame",
           "encode_message", "decode_message"]

HEADER_BYTES = 8
CHECKSUM_BYTES = 2
#: Auto-baud sync byte ``U`` the host sends before its first message (firmware >= 3.28, §2.1).
SYNC_BYTE = b"U"
#: Gain index -> receiver gain (docs/devices.md §2.4 [P2]).
GAIN_INDEX_TO_GAIN = (0.6, 1.8, 5.5, 12.9, 30.2, 66.1, 144.0)

_HEADER = struct.Struct("<2sHHBB")
_CHECKSUM = struct.Struct("<H")


class Ping1dParseError(ValueError):
    """Raised for any Ping1D frame or payload that cannot be decoded (wrong start bytes, length mismatch, bad checksum,
    wrong payload size, unknown message id, out-of-range enum value). Source: docs/devices.md §2.2-§2.4."""


class Ping1dId(IntEnum):
    """Message ids used by an altimeter driver (docs/devices.md §2.4 [P2])."""

    ACK = 1
    NACK = 2
    ASCII_TEXT = 3
    DEVICE_INFORMATION = 4
    PROTOCOL_VERSION = 5
    GENERAL_REQUEST = 6
    SET_DEVICE_ID = 1000
    SET_RANGE = 1001
    SET_SPEED_OF_SOUND = 1002
    SET_MODE_AUTO = 1003
    SET_PING_INTERVAL = 1004
    SET_GAIN_SETTING = 1005
    SET_PING_ENABLE = 1006
    GOTO_BOOTLOADER = 1100
    FIRMWARE_VERSION = 1200
    DEVICE_ID = 1201
    VOLTAGE_5 = 1202
    SPEED_OF_SOUND = 1203
    RANGE = 1204
    MODE_AUTO = 1205
    PING_INTERVAL = 1206
    GAIN_SETTING = 1207
    TRANSMIT_DURATION = 1208
    GENERAL_INFO = 1210
    DISTANCE_SIMPLE = 1211
    DISTANCE = 1212
    PROCESSOR_TEMPERATURE = 1213
    PCB_TEMPERATURE = 1214
    PING_ENABLE = 1215
    PROFILE = 1300
    CONTINUOUS_START = 1400
    CONTINUOUS_STOP = 1401


# Frame codec
def checksum(data: bytes | bytearray) -> int:
    """Ping protocol checksum: sum of all bytes, modulo 2**16 (docs/devices.md §2.2)."""
    return sum(data) & 0xFFFF


@dataclass(frozen=True)
class Ping1dMessage:
    """One decoded frame: raw message id and payload bytes (docs/devices.md §2.2).

    Attributes:
        message_id: u16 message id.
        payload: payload bytes (may be empty: a legacy request, §2.3).
        src_device_id, dst_device_id: u8 device ids (0 = not implemented / host; 255 = broadcast)."""

    message_id: int
    payload: bytes = b""
    src_device_id: int = 0
    dst_device_id: int = 0

    def encode(self) -> bytes:
        """This message as a complete frame (see :func:`encode_frame`)."""
        return encode_frame(self.message_id, self.payload, self.src_device_id, self.dst_device_id)


def encode_frame(message_id: int, payload: bytes = b"", src_device_id: int = 0, dst_device_id: int = 0) -> bytes:
    """Build a complete frame: header, payload, checksum (docs/devices.md §2.2).

    Raises ``ValueError``: message id outside 0..65535, device ids outside 0..255, payload > 65535 bytes."""
    if not 0 <= int(message_id) <= 0xFFFF:
        raise ValueError(f"message id {message_id} outside 0..65535")
    if not (0 <= int(src_device_id) <= 0xFF and 0 <= int(dst_device_id) <= 0xFF):
        raise ValueError(f"device ids ({src_device_id}, {dst_device_id}) outside 0..255")
    payload = bytes(payload)
    if len(payload) > 0xFFFF:
        raise ValueError(f"payload of {len(payload)} bytes exceeds 65535")
    body = _HEADER.pack(b"BR", len(payload), int(message_id), int(src_device_id), int(dst_device_id)) + payload
    return body + _CHECKSUM.pack(checksum(body))


def decode_frame(frame: Union[bytes, bytearray]) -> Ping1dMessage:
    """Decode exactly one complete frame.

    Raises ``Ping1dParseError``: too short, not starting with ``BR``, payload_length inconsistent with the frame length,
    or checksum mismatch."""
    frame = bytes(frame)
    if len(frame) < HEADER_BYTES + CHECKSUM_BYTES:
        raise Ping1dParseError(f"frame too short ({len(frame)} bytes)")
    start, length, message_id, src, dst = _HEADER.unpack_from(frame)
    if start != b"BR":
        raise Ping1dParseError(f"frame does not start with 'BR': {frame[:2]!r}")
    if len(frame) != HEADER_BYTES + length + CHECKSUM_BYTES:
        raise Ping1dParseError(f"payload_length {length} inconsistent with frame of {len(frame)} bytes")
    (expected,) = _CHECKSUM.unpack_from(frame, HEADER_BYTES + length)
    computed = checksum(frame[: HEADER_BYTES + length])
    if computed != expected:
        raise Ping1dParseError(f"checksum mismatch: frame says 0x{expected:04x}, computed 0x{computed:04x}")
    return Ping1dMessage(message_id, frame[HEADER_BYTES: HEADER_BYTES + length], src, dst)


def request_frame(requested_id: int, src_device_id: int = 0, dst_device_id: int = 0) -> bytes:
    """Frame asking the device for message ``requested_id`` (docs/devices.md §2.3): a
    ``general_request`` (id 6, u16 payload; brping's legacy form, that id with an empty payload, is
    ``encode_frame(requested_id)``). Raises ValueError for ids out of range."""
    return encode_message(GeneralRequest(requested_id), src_device_id, dst_device_id)


class Ping1dFramer:
    """Streaming frame extractor: feed arbitrary byte chunks, get complete valid frames.

    Resynchronisation (docs/devices.md §2.2 parser state machine, §2.6): bytes before ``BR`` are
    discarded; a header whose payload_length exceeds ``max_payload_bytes`` is treated as a false start;
    a frame with a bad checksum is counted and scanning resumes one byte after its ``B``, so a valid
    frame hidden inside a corrupted or truncated one is still found.  Auto-baud ``U`` bytes and
    garbage are counted as discarded.  Results do not depend on chunking.

    Attributes:
        discarded_bytes: bytes dropped while resynchronising.
        bad_checksums: frames whose checksum did not verify.
        oversize_headers: false starts rejected by the payload-length limit.
        frames_ok: valid frames returned."""

    def __init__(self, max_payload_bytes: int = 1024) -> None:
        if max_payload_bytes < 0 or max_payload_bytes > 0xFFFF:
            raise ValueError("max_payload_bytes must be within 0..65535")
        self.max_payload_bytes = int(max_payload_bytes)
        self._buf = bytearray()
        self.discarded_bytes = 0
        self.bad_checksums = 0
        self.oversize_headers = 0
        self.frames_ok = 0

    def reset(self) -> None:
        """Drop any partial frame (counted as discarded); counters are kept."""
        self.discarded_bytes += len(self._buf)
        self._buf.clear()

    def feed(self, data: Union[bytes, bytearray]) -> list:
        """Add a chunk; return the list of :class:`Ping1dMessage` it completes."""
        buf = self._buf
        buf += data
        out: list = []
        while True:
            idx = buf.find(b"BR")
            if idx < 0:
                keep = 1 if buf.endswith(b"B") else 0
                self.discarded_bytes += len(buf) - keep
                del buf[: len(buf) - keep]
                break
            if idx:
                self.discarded_bytes += idx
                del buf[:idx]
            if len(buf) < HEADER_BYTES:
                break
            length = buf[2] | (buf[3] << 8)
            if length > self.max_payload_bytes:
                self.oversize_headers += 1
                self.discarded_bytes += 1
                del buf[:1]
                continue
            total = HEADER_BYTES + length + CHECKSUM_BYTES
            if len(buf) < total:
                break
            if checksum(buf[: total - CHECKSUM_BYTES]) != (buf[total - 2] | (buf[total - 1] << 8)):
                self.bad_checksums += 1
                self.discarded_bytes += 1
                del buf[:1]
                continue
            out.append(Ping1dMessage(buf[4] | (buf[5] << 8), bytes(buf[HEADER_BYTES: total - 2]), buf[6], buf[7]))
            del buf[:total]
        self.frames_ok += len(out)
        return out


# Typed payloads

# Field conversions: "int" (raw integer), "bool" (u8 0/1), or an int divisor d with SI = raw / d.
_Conv = Union[str, int]


class Ping1dPayload:
    """Base of the typed payload dataclasses (declared by :func:`_payload`): ``MESSAGE_ID``,
    ``LAYOUT`` (one ``(struct code, conversion)`` per fixed field, in wire order) and ``TAIL``
    (``"text"``: trailing char[]; ``"profile"``: u16 length + u8[] samples; None)."""

    MESSAGE_ID: ClassVar[int]
    LAYOUT: ClassVar[Tuple[Tuple[str, _Conv], ...]] = ()
    TAIL: ClassVar[Optional[str]] = None

    def pack(self) -> bytes:
        """Payload bytes (little-endian).

        Raises ``ValueError``: a value that does not fit its wire type (negative, too large, non-finite, non-integral
        where an integer is required, non-ASCII text)."""
        names = [f.name for f in dc_fields(self)]  # type: ignore[arg-type]
        raw = [_to_raw(getattr(self, n), conv, n) for n, (_, conv) in zip(names, self.LAYOUT)]
        try:
            data = struct.pack("<" + "".join(code for code, _ in self.LAYOUT), *raw)
        except struct.error as exc:
            raise ValueError(f"{type(self).__name__}: value out of range for its wire type: {exc}") from exc
        if self.TAIL == "text":
            data += getattr(self, names[-1]).encode("ascii")
        elif self.TAIL == "profile":
            samples = bytes(getattr(self, names[-1]))
            if len(samples) > 0xFFFF:
                raise ValueError("profile_data longer than 65535 samples")
            data += struct.pack("<H", len(samples)) + samples
        return data

    @classmethod
    def unpack(cls, payload: bytes):
        """Decode payload bytes into this type.

        Raises ``Ping1dParseError``: wrong length or invalid boolean value."""
        fmt = "<" + "".join(code for code, _ in cls.LAYOUT)
        size = struct.calcsize(fmt)
        payload = bytes(payload)
        if cls.TAIL is None and len(payload) != size:
            raise Ping1dParseError(f"{cls.__name__}: payload of {len(payload)} bytes, expected {size}")
        if cls.TAIL is not None and len(payload) < size:
            raise Ping1dParseError(f"{cls.__name__}: payload of {len(payload)} bytes, expected >= {size}")
        names = [f.name for f in dc_fields(cls)]  # type: ignore[arg-type]
        values = [_from_raw(r, conv, name) for r, (_, conv), name in
                  zip(struct.unpack_from(fmt, payload), cls.LAYOUT, names)]
        rest = payload[size:]
        if cls.TAIL == "text":
            values.append(rest.rstrip(b"\x00").decode("ascii", errors="replace"))
        elif cls.TAIL == "profile":
            if len(rest) < 2:
                raise Ping1dParseError(f"{cls.__name__}: missing profile_data_length")
            (n,) = struct.unpack_from("<H", rest)
            if len(rest) - 2 != n:
                raise Ping1dParseError(f"{cls.__name__}: profile_data_length {n} but {len(rest) - 2} samples present")
            values.append(bytes(rest[2:]))
        return cls(*values)

    def encode(self, src_device_id: int = 0, dst_device_id: int = 0) -> bytes:
        """Complete frame carrying this payload (see :func:`encode_message`)."""
        return encode_message(self, src_device_id, dst_device_id)


def _to_raw(value, conv: _Conv, name: str) -> int:
    if conv == "bool":
        return 1 if value else 0
    if conv == "int":
        if isinstance(value, float):
            if not value.is_integer():
                raise ValueError(f"{name}: {value} is not an integer")
            value = int(value)
        return int(value)
    try:
        scaled = float(value) * int(conv)
        if not math.isfinite(scaled):
            raise ValueError
        return int(round(scaled))
    except (ValueError, OverflowError, TypeError):
        raise ValueError(f"{name}: invalid value {value!r}") from None


def _from_raw(raw: int, conv: _Conv, name: str):
    if conv == "bool":
        if raw not in (0, 1):
            raise Ping1dParseError(f"{name}: expected 0 or 1, got {raw}")
        return bool(raw)
    if conv == "int":
        return raw
    return raw / int(conv)


_MM = 1000  # mm -> m, mm/s -> m/s, ms -> s, mV -> V
_US = 1000000  # µs -> s
_CC = 100  # centi-degC -> degC
_PY_TYPE = {"int": int, "bool": bool}  # a divisor conversion gives a float
_TAIL_TYPE = {"text": (str, ""), "profile": (bytes, b"")}
_WIRE = {"B": "u8", "H": "u16", "I": "u32", "text": "char[]", "profile": "u16 length + u8[]"}

#: message id -> payload class, for every message in docs/devices.md §2.4 (see :func:`_payload`).
PAYLOAD_TYPES: Dict[int, Type[Ping1dPayload]] = {}


def _payload(message_id: Ping1dId, note: str, *layout: tuple, tail: Optional[Tuple[str, str]] = None) -> Any:
    """Declare the frozen payload dataclass of ``message_id``, named after it (``SET_RANGE`` ->
    ``SetRange``), and register it in :data:`PAYLOAD_TYPES`.

    ``layout``: one ``(field, struct code, conversion[, default])`` per fixed field, in wire order; ``tail``:
    ``(field, "text" | "profile")`` (see :class:`Ping1dPayload`). The class docstring gives the wire layout, then
    ``note``; its sections are of docs/devices.md, §2.4 (the message table) unless it says otherwise."""
    fields: list = [(name, _PY_TYPE.get(conv, float), field(default=default[0] if default else MISSING))
                    for name, _, conv, *default in layout]
    if tail is not None:
        tail_type, tail_default = _TAIL_TYPE[tail[1]]
        fields.append((tail[0], tail_type, field(default=tail_default)))
    name = "".join(word.capitalize() for word in message_id.name.split("_"))
    wire = [f"{row[0]} {_WIRE[row[1]]}" for row in (*layout, *([tail] if tail else []))]
    cls = make_dataclass(name, fields, bases=(Ping1dPayload,), frozen=True, namespace={
        "MESSAGE_ID": message_id, "LAYOUT": tuple((code, conv) for _, code, conv, *_ in layout),
        "TAIL": None if tail is None else tail[1], "__module__": __name__,
        "__doc__": f"id {message_id.value} {message_id.name.lower()} ({', '.join(wire) or 'no payload'}): {note}"})
    PAYLOAD_TYPES[message_id] = cls
    return cls


_DISTANCE_LAYOUT = (("distance_m", "I", _MM), ("confidence_pct", "H", "int"),
                    ("transmit_duration_s", "H", _US), ("ping_number", "I", "int"),
                    ("scan_start_m", "I", _MM), ("scan_length_m", "I", _MM),
                    ("gain_setting", "I", "int"))

Ack = _payload(Ping1dId.ACK, "id of the acknowledged message (§2.3).", ("acked_id", "H", "int"))
Nack = _payload(Ping1dId.NACK, "id, then ASCII text, not necessarily NUL-terminated (§2.3).",
                ("nacked_id", "H", "int"), tail=("message", "text"))
AsciiText = _payload(Ping1dId.ASCII_TEXT, "§2.4.", tail=("text", "text"))
DeviceInformation = _payload(
    Ping1dId.DEVICE_INFORMATION, "device_type 0 unknown, 1 Ping Echosounder, 2 Ping360.",
    ("device_type", "B", "int"), ("device_revision", "B", "int"),
    ("firmware_version_major", "B", "int"), ("firmware_version_minor", "B", "int"),
    ("firmware_version_patch", "B", "int"), ("reserved", "B", "int", 0))
ProtocolVersion = _payload(
    Ping1dId.PROTOCOL_VERSION, "vector §2.5.", ("version_major", "B", "int"),
    ("version_minor", "B", "int"), ("version_patch", "B", "int"), ("reserved", "B", "int", 0))
GeneralRequest = _payload(Ping1dId.GENERAL_REQUEST, "the device answers with that message (§2.3).",
                          ("requested_id", "H", "int"))
SetDeviceId = _payload(Ping1dId.SET_DEVICE_ID, "0..254.", ("device_id", "B", "int"))
SetRange = _payload(Ping1dId.SET_RANGE, "mm, length >= 1000 mm; selects manual mode.",
                    ("scan_start_m", "I", _MM), ("scan_length_m", "I", _MM))
SetSpeedOfSound = _payload(Ping1dId.SET_SPEED_OF_SOUND, "mm/s, about 1 500 000 in water "
                           "(vector §2.5).", ("speed_of_sound_m_s", "I", _MM))
SetModeAuto = _payload(Ping1dId.SET_MODE_AUTO, "0 manual / 1 auto.", ("auto", "B", "bool"))
SetPingInterval = _payload(Ping1dId.SET_PING_INTERVAL, "ms between pings (vector §2.5).", ("ping_interval_s", "H", _MM))
SetGainSetting = _payload(Ping1dId.SET_GAIN_SETTING, "index 0..6 of :data:`GAIN_INDEX_TO_GAIN`.",
                          ("gain_setting", "B", "int"))
SetPingEnable = _payload(Ping1dId.SET_PING_ENABLE, "0 off / 1 on.", ("enabled", "B", "bool"))
GotoBootloader = _payload(Ping1dId.GOTO_BOOTLOADER, "§2.4.")
FirmwareVersion = _payload(
    Ping1dId.FIRMWARE_VERSION, "device_model 1 = Ping1D.", ("device_type", "B", "int"),
    ("device_model", "B", "int"), ("firmware_version_major", "H", "int"),
    ("firmware_version_minor", "H", "int"))
DeviceId = _payload(Ping1dId.DEVICE_ID, "§2.4.", ("device_id", "B", "int"))
Voltage5 = _payload(Ping1dId.VOLTAGE_5, "mV -> V.", ("voltage_5_v", "H", _MM))
SpeedOfSound = _payload(Ping1dId.SPEED_OF_SOUND, "mm/s -> m/s.", ("speed_of_sound_m_s", "I", _MM))
Range = _payload(Ping1dId.RANGE, "mm -> m.", ("scan_start_m", "I", _MM), ("scan_length_m", "I", _MM))
ModeAuto = _payload(Ping1dId.MODE_AUTO, "0 manual / 1 auto.", ("auto", "B", "bool"))
PingInterval = _payload(Ping1dId.PING_INTERVAL, "ms -> s, a minimum (the actual interval may be "
                        "longer).", ("ping_interval_s", "H", _MM))
GainSetting = _payload(Ping1dId.GAIN_SETTING, "**u32** gain index (the set message is u8).",
                       ("gain_setting", "I", "int"))
TransmitDuration = _payload(Ping1dId.TRANSMIT_DURATION, "µs -> s.", ("transmit_duration_s", "H", _US))
GeneralInfo = _payload(
    Ping1dId.GENERAL_INFO, "10 bytes; voltage_5 in mV, ping_interval in ms.",
    ("firmware_version_major", "H", "int"), ("firmware_version_minor", "H", "int"),
    ("voltage_5_v", "H", _MM), ("ping_interval_s", "H", _MM), ("gain_setting", "B", "int"),
    ("mode_auto", "B", "bool"))
DistanceSimple = _payload(Ping1dId.DISTANCE_SIMPLE, "5 bytes (vector §2.5).",
                          ("distance_m", "I", _MM), ("confidence_pct", "B", "int"))
Distance = _payload(
    Ping1dId.DISTANCE, "24 bytes, fields at @0, 4, 6, 8, 12, 16, 20; distance and scan in mm, "
    "confidence in %, transmit_duration in µs.", *_DISTANCE_LAYOUT)
ProcessorTemperature = _payload(Ping1dId.PROCESSOR_TEMPERATURE, "centi-degC -> degC.", ("temperature_degc", "H", _CC))
PcbTemperature = _payload(Ping1dId.PCB_TEMPERATURE, "centi-degC -> degC.", ("temperature_degc", "H", _CC))
PingEnable = _payload(Ping1dId.PING_ENABLE, "0 off / 1 on.", ("enabled", "B", "bool"))
Profile = _payload(
    Ping1dId.PROFILE, "the 1212 fields (24 B), the length @24, the samples @26 (first nearest the "
    "transducer, spanning scan_start .. scan_start + scan_length).", *_DISTANCE_LAYOUT,
    tail=("profile_data", "profile"))
ContinuousStart = _payload(Ping1dId.CONTINUOUS_START, "id to stream, 1300 = profile (vector §2.5).",
                           ("requested_id", "H", "int"))
ContinuousStop = _payload(Ping1dId.CONTINUOUS_STOP, "id to stop.", ("requested_id", "H", "int"))


def encode_message(payload: Ping1dPayload, src_device_id: int = 0, dst_device_id: int = 0) -> bytes:
    """Complete frame for a typed payload.

    Raises ``ValueError``: a field does not fit its wire type, or ids out of range."""
    return encode_frame(payload.MESSAGE_ID, payload.pack(), src_device_id, dst_device_id)


def decode_message(message: Union[Ping1dMessage, bytes, bytearray]) -> Ping1dPayload:
    """Typed payload of a frame (a :class:`Ping1dMessage` or the raw frame bytes).

    Raises ``Ping1dParseError``: bad frame, unknown message id, or payload of the wrong size / content."""
    if not isinstance(message, Ping1dMessage):
        message = decode_frame(message)
    cls = PAYLOAD_TYPES.get(message.message_id)
    if cls is None:
        raise Ping1dParseError(f"unknown message id {message.message_id}")
    return cls.unpack(message.payload)
