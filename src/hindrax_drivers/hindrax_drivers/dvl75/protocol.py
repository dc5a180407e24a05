"""Cerulean DVL-75 serial protocol: pure framing, checksum, sentence parsing/formatting, commands.

This is the protocol layer of the DVL-75 driver (docs/architecture.md §2): bytes in, typed records out, and the
reverse for the commands a driver sends.  No I/O, no clocks, no ROS.

Source: docs/devices.md §0, §1.2-§1.5 (tags [D3]-[D21] there).

Framing (docs/devices.md §1.2, verified on real captures): ``$`` + sentence id + ``,`` + fields + ``*`` + two hex
digits + CR LF, the checksum the XOR of every byte strictly between ``$`` and ``*``. ``$DVPDL``, ``$DVEXT`` and
``$GPRMC`` (§1.3) parse into dataclasses with SI field names; ``$DVTXT`` and bare lines into :class:`DvlText`; any other
line (``$DVNVM``, ``IMU:``, ``GPS:$...``) into :class:`DvlUnknown`, not an error. Host -> DVL commands (§1.4) are plain
ASCII lines without checksum, as the BlueOS driver sends them [D17].

Vendor-document errors handled here (docs/devices.md §0 item 2, §1.2): the ``$DVPDL`` example printed
in Cerulean's documentation ends in ``*22`` although its checksum is ``6E``; this module rejects it,
as it rejects every sentence whose checksum does not verify.  The ``$DVEXT`` format line in the
vendor doc shows ``u.uu`` (two decimals) for velocity-up, but real captures print three; the
formatter follows the captures.

Why our own code: there is no maintained Python parser for these sentences (the Cerulean pynmea2 fork
[D18] only adds two sentence types and raises generic errors), and the checksum, signed fields and
trailing empty field need exact control.

Frames (docs/devices.md §1.3.1, §1.5): each record's docstring gives the frame of each field."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import reduce
from typing import Any, Callable, Optional, Sequence, Tuple, Union

__all__ = ["DvlParseError", "DvlPositionDelta", "DvlExtended", "DvlGprmc", "DvlText", "DvlUnknown", "DvlRecord",
           "DvlCommand", "DvlLineFramer", "BEAM_NAMES", "BEAM_TILT_RAD", "beam_directions_frd", "LINE_TERMINATOR",
           "KNOT_M_S", "nmea_checksum", "format_sentence", "split_sentence", "parse_line", "parse_dvpdl", "parse_dvext",
           "parse_gprmc", "format_dvpdl", "format_dvext", "format_gprmc", "format_dvtxt", "parse_command",
           "build_command", "cmd_send", "cmd_set_sensor_orientation", "cmd_set_speed_of_sound", "startup_commands"]

#: Line terminator the DVL uses and the driver sends (CR LF; docs/devices.md §1.2, §1.4).
LINE_TERMINATOR = b"\r\n"
#: Beam order of the per-beam ``$DVEXT`` fields: A = port, B = stern, C = starboard, D = bow (§1.3.2).
BEAM_NAMES = ("port", "stern", "starboard", "bow")
#: Tilt of each beam from the transducer axis, rad. ASSUMPTION: docs/devices.md gives no beam angle; a four-beam
#: Janus head at 22.5 deg, as the emulator models (:class:`~hindrax_drivers.dvl75.emulator.Dvl75Emulator`).
BEAM_TILT_RAD = math.radians(22.5)


def beam_directions_frd(tilt_rad: float = BEAM_TILT_RAD) -> tuple[tuple[float, float, float], ...]:
    """Unit direction of each beam (A port, B stern, C starboard, D bow, :data:`BEAM_NAMES`) in the sensor's FRD
    axes (a downward DVL: z along the transducer axis), tilted ``tilt_rad`` from the axis towards its side."""
    s, c = math.sin(tilt_rad), math.cos(tilt_rad)
    return ((0.0, -s, c), (-s, 0.0, c), (0.0, s, c), (s, 0.0, c))


#: One knot in m/s (1852 m per hour), for the ``$GPRMC`` speed field (§1.3.3).
KNOT_M_S = 1852.0 / 3600.0

_DVPDL_FIELDS = 10  # "DVPDL" + 9 data fields (§1.3.1)
_DVEXT_FIELDS = 35  # "DVEXT" + 34 data fields, plus the trailing empty field 35 (§1.3.2)

_INT_RE = re.compile(r"[+-]?[0-9]+")
_FLOAT_RE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_ID_RE = re.compile(r"[A-Za-z0-9]+")
_CAL_RE = re.compile(r"[0-3]{4}")
_HEX = b"0123456789abcdefABCDEF"


class DvlParseError(ValueError):
    """Raised for any DVL line, sentence or command that cannot be parsed (bad checksum, wrong field
    count, malformed number, out-of-range value, non-printable bytes).  Source: docs/devices.md §1.2."""


# Records
@dataclass(frozen=True)
class DvlPositionDelta:
    """One ``$DVPDL`` sentence: motion since the previous ``$DVPDL`` (docs/devices.md §1.3.1).

    All deltas are in the DVL's ArduSub vehicle frame, which is FRD (X bow, Y starboard, Z down;
    rotations right-handed about those axes), after the SET-SENSOR-ORIENTATION rotation [D4][D20].

    Attributes:
        time_since_boot_s: field ``tu`` (µs since DVL boot) in s.
        delta_time_s: field ``dtu`` (µs since the previous ``$DVPDL``) in s.
        delta_roll_rad, delta_pitch_rad, delta_yaw_rad: fields ``adr, adp, ady``, rad, about X (bow),
            Y (starboard), Z (down).
        delta_x_m, delta_y_m, delta_z_m: fields ``pdx, pdy, pdz``, m, forward / starboard / down.
        confidence_pct: field ``c``, 0..100 % (0 = none; then every field after ``dtu`` is garbage [D4b])."""

    time_since_boot_s: float
    delta_time_s: float
    delta_roll_rad: float
    delta_pitch_rad: float
    delta_yaw_rad: float
    delta_x_m: float
    delta_y_m: float
    delta_z_m: float
    confidence_pct: int

    def velocity_frd_m_s(self) -> Optional[Tuple[float, float, float]]:
        """Mean velocity over the interval, (surge, sway, heave) m/s in FRD: position delta / dtu
        (the usage in [D22], docs/devices.md §1.3.1).  ``None`` when ``confidence_pct`` is 0 or
        ``delta_time_s`` is not positive (no usable data)."""
        if self.confidence_pct <= 0 or self.delta_time_s <= 0.0:
            return None
        dt = self.delta_time_s
        return (self.delta_x_m / dt, self.delta_y_m / dt, self.delta_z_m / dt)


@dataclass(frozen=True)
class DvlExtended:
    """One ``$DVEXT`` sentence (docs/devices.md §1.3.2); every field, in SI units.

    Per-beam tuples are ordered A, B, C, D = port, stern, starboard, bow (:data:`BEAM_NAMES`).
    Check ``locked`` (and ``beam_locked``) before using altitude, velocities or ranges [D5].

    Attributes:
        locked: field 1, True = locked on bottom (``T``), False = searching (``F``).
        gps_status: field 2, ``A`` fresh fix, ``V`` invalid, ``X`` stale (any single letter is kept).
        imu_calibration: field 3 as (system, gyro, accel, mag), each 0..3 (3 = fully calibrated);
            None when the field is not four digits 0-3 (undefined with the upgraded IMU [D19]).
        imu_calibration_raw: field 3 exactly as received.
        roll_rad, pitch_rad: fields 4, 5 (degrees on the wire), DVL Vehicle-frame Euler angles about
            X bow / Y port (right-handed, hence positive pitch = bow down [DERIVED from §1.5]).
        heading_rad: field 6 (degrees 0..360 on the wire), compass convention (clockwise from north).
        data_skips: field 7, signed count of attempts since the last successful ping return.
        velocity_up_m_s: field 8, m/s, + up ("do not rely on this number").
        altitude_m: field 9, m to the target along the sensor pointing axis.
        velocity_north_m_s, velocity_east_m_s: fields 10, 11, m/s, world components (noisy).
        latitude_deg, longitude_deg: fields 12, 13, decimal degrees (kept in degrees as NavSatFix does).
        ekf_elapsed_time_s: field 14, s since the previous EKF step.
        orientation_wxyz: fields 15-18, quaternion (w, x, y, z) of the FLU body in ENU (neutral = bow
            east, level; §1.5).
        beam_gain_db: fields 19-22, dB (6..66).
        beam_locked: fields 23-26, valid bottom return per beam.
        beam_velocity_m_s: fields 27-30, m/s along each beam axis, unfiltered.
        beam_range_m: fields 31-34, m along each beam axis, unfiltered; -1.0 when unlocked."""

    locked: bool
    gps_status: str
    imu_calibration: Optional[Tuple[int, int, int, int]]
    imu_calibration_raw: str
    roll_rad: float
    pitch_rad: float
    heading_rad: float
    data_skips: int
    velocity_up_m_s: float
    altitude_m: float
    velocity_north_m_s: float
    velocity_east_m_s: float
    latitude_deg: float
    longitude_deg: float
    ekf_elapsed_time_s: float
    orientation_wxyz: Tuple[float, float, float, float]
    beam_gain_db: Tuple[float, float, float, float]
    beam_locked: Tuple[bool, bool, bool, bool]
    beam_velocity_m_s: Tuple[float, float, float, float]
    beam_range_m: Tuple[float, float, float, float]


@dataclass(frozen=True)
class DvlGprmc:
    """A ``$GPRMC`` sentence as emitted by the DVL's GPS emulation (docs/devices.md §1.3.3) or sent to it
    as a position command (§1.4).

    Attributes:
        time_of_day_s: UTC time of day in s (for the DVL: time since power-on, power-on = midnight); None when empty.
        valid: status ``A`` (True) or ``V`` (False).
        latitude_deg, longitude_deg: decimal degrees (+N, +E); None when empty.
        speed_m_s: speed over ground (knots on the wire), m/s; None when empty.
        track_rad: track / heading, rad clockwise from north; None when empty.
        date_ddmmyy: the date field as received (the DVL always sends ``010120``)."""

    time_of_day_s: Optional[float]
    valid: bool
    latitude_deg: Optional[float]
    longitude_deg: Optional[float]
    speed_m_s: Optional[float]
    track_rad: Optional[float]
    date_ddmmyy: str


@dataclass(frozen=True)
class DvlText:
    """Free-form text from the DVL: a ``$DVTXT,<text>`` sentence (``sentence_id == 'DVTXT'``) or a bare
    printable line from older firmware (``sentence_id == ''``), e.g. CONFIGURATION output
    (docs/devices.md §1.2, [D10][D3]).  ``checksum_ok`` is None when the line carried no checksum."""

    text: str
    sentence_id: str
    checksum_ok: Optional[bool]


@dataclass(frozen=True)
class DvlUnknown:
    """Any other line sharing the stream, kept rather than rejected (docs/devices.md §1.2): unknown
    ``$`` sentences (``$DVNVM``, ``$DVKFA``...), ``IMU:`` lines (``sentence_id == 'IMU'``) and re-tweeted
    ``GPS:$...`` lines (``sentence_id == 'GPS'``).

    Attributes:
        sentence_id: sentence id without ``$`` (or ``IMU`` / ``GPS``).
        fields: comma-separated fields after the id (checksum removed).
        line: the whole line, decoded (non-UTF-8 bytes replaced).
        checksum_ok: True when a ``*hh`` checksum was present and verified, None when absent."""

    sentence_id: str
    fields: Tuple[str, ...]
    line: str
    checksum_ok: Optional[bool]


DvlRecord = Union[DvlPositionDelta, DvlExtended, DvlGprmc, DvlText, DvlUnknown]


@dataclass(frozen=True)
class DvlCommand:
    """A host -> DVL command line split into an upper-cased keyword and its argument text
    (docs/devices.md §1.4).  ``?``-lines map to keyword ``CONFIGURATION``; a ``$GPRMC`` sentence maps to
    keyword ``$GPRMC`` with the whole sentence as argument."""

    keyword: str
    argument: str


# Checksum and sentence framing
def _to_bytes(line: Union[bytes, bytearray, str]) -> bytes:
    if isinstance(line, str):
        return line.encode("utf-8", errors="replace")
    return bytes(line)


def nmea_checksum(body: Union[bytes, str]) -> int:
    """NMEA checksum: XOR of every byte of ``body`` (the bytes strictly between ``$`` and ``*``).

    Args:
        body: sentence body without ``$`` and ``*hh``; str is encoded as UTF-8.
    Returns int 0..255.
    Source: docs/devices.md §1.2 ("NMEA standard", verified on real captures [D21])."""
    return reduce(lambda acc, b: acc ^ b, _to_bytes(body), 0)


def format_sentence(body: str, *, with_checksum: bool = True) -> bytes:
    r"""Build one complete sentence ``$<body>*HH\r\n`` (uppercase hex, docs/devices.md §1.2).

    Args:
        body: printable ASCII without ``$``, ``*``, CR or LF, e.g. ``"DVPDL,1,2,..."``.
        with_checksum: False gives ``$<body>\r\n`` (how ``$DVTXT`` is documented [D10]).
    Raises ``ValueError``: if ``body`` is not printable ASCII or contains ``$`` or ``*``."""
    raw = body.encode("ascii")  # UnicodeEncodeError is a ValueError
    if any(b < 0x20 or b > 0x7E for b in raw) or b"$" in raw or b"*" in raw:
        raise ValueError(f"sentence body must be printable ASCII without '$' or '*': {body!r}")
    if not with_checksum:
        return b"$" + raw + LINE_TERMINATOR
    return b"$" + raw + b"*%02X" % nmea_checksum(raw) + LINE_TERMINATOR


def split_sentence(line: Union[bytes, bytearray, str]) -> Tuple[str, Tuple[str, ...], Optional[bool]]:
    """Split a ``$`` sentence into (sentence id, fields, checksum_ok), verifying the checksum.

    Trailing CR/LF are ignored.  A checksum is recognised when the line ends in ``*`` + two hex
    digits; ``checksum_ok`` is None when there is none.

    Raises ``DvlParseError``: line does not start with ``$``, has a malformed sentence id, or its checksum does not
    verify (docs/devices.md §1.2)."""
    raw = _to_bytes(line).rstrip(b"\r\n")
    if not raw.startswith(b"$"):
        raise DvlParseError(f"not an NMEA sentence (no leading '$'): {raw[:40]!r}")
    checksum_ok: Optional[bool] = None
    body = raw[1:]
    if len(raw) >= 4 and raw[-3:-2] == b"*" and raw[-2] in _HEX and raw[-1] in _HEX:
        body = raw[1:-3]
        expected = int(raw[-2:].decode("ascii"), 16)
        computed = nmea_checksum(body)
        if computed != expected:
            raise DvlParseError(f"checksum mismatch: line says {expected:02X}, computed {computed:02X}: {raw[:60]!r}")
        checksum_ok = True
    text = body.decode("utf-8", errors="replace")
    parts = text.split(",")
    if not _ID_RE.fullmatch(parts[0]):
        raise DvlParseError(f"malformed sentence id {parts[0][:20]!r}")
    return parts[0], tuple(parts[1:]), checksum_ok


# Field helpers
def _int(field: str, name: str) -> int:
    if not _INT_RE.fullmatch(field):
        raise DvlParseError(f"field {name}: expected an integer, got {field[:20]!r}")
    return int(field)


def _float(field: str, name: str) -> float:
    if not _FLOAT_RE.fullmatch(field):
        raise DvlParseError(f"field {name}: expected a decimal number, got {field[:20]!r}")
    value = float(field)
    if not math.isfinite(value):
        raise DvlParseError(f"field {name}: value out of range: {field[:20]!r}")
    return value


def _flag(field: str, name: str) -> bool:
    if field == "T":
        return True
    if field == "F":
        return False
    raise DvlParseError(f"field {name}: expected 'T' or 'F', got {field[:20]!r}")


def _tf(flag: bool) -> str:
    return "T" if flag else "F"


# $DVPDL
def parse_dvpdl(fields: Sequence[str]) -> DvlPositionDelta:
    """Parse the 9 data fields of ``$DVPDL`` (``tu,dtu,adr,adp,ady,pdx,pdy,pdz,c``; docs/devices.md §1.3.1).

    Args:
        fields: the fields after the sentence id (checksum already verified and removed).
    Raises ``DvlParseError``: wrong field count, malformed number, negative time, confidence outside 0..100."""
    if len(fields) != _DVPDL_FIELDS - 1:
        raise DvlParseError(f"$DVPDL: expected {_DVPDL_FIELDS - 1} fields, got {len(fields)}")
    tu = _int(fields[0], "tu")
    dtu = _int(fields[1], "dtu")
    if tu < 0 or dtu < 0:
        raise DvlParseError(f"$DVPDL: negative time (tu={tu}, dtu={dtu})")
    confidence = _int(fields[8], "c")
    if not 0 <= confidence <= 100:
        raise DvlParseError(f"$DVPDL: confidence {confidence} outside 0..100")
    return DvlPositionDelta(
        time_since_boot_s=tu / 1e6,
        delta_time_s=dtu / 1e6,
        delta_roll_rad=_float(fields[2], "adr"),
        delta_pitch_rad=_float(fields[3], "adp"),
        delta_yaw_rad=_float(fields[4], "ady"),
        delta_x_m=_float(fields[5], "pdx"),
        delta_y_m=_float(fields[6], "pdy"),
        delta_z_m=_float(fields[7], "pdz"),
        confidence_pct=confidence,
    )


def format_dvpdl(record: DvlPositionDelta) -> bytes:
    """Format a ``$DVPDL`` sentence exactly as the DVL prints it (docs/devices.md §1.3.1 "Observed
    format"): integer µs times, ``%.6f`` angle deltas, ``%.3f`` position deltas, integer confidence,
    ``*HH`` checksum, CR LF.  Quantisation: 1 µs, 1e-6 rad, 1 mm.

    Raises ``ValueError``: negative times, non-finite values or confidence outside 0..100."""
    tu = round(record.time_since_boot_s * 1e6)
    dtu = round(record.delta_time_s * 1e6)
    if tu < 0 or dtu < 0:
        raise ValueError("times must be non-negative")
    if not 0 <= int(record.confidence_pct) <= 100:
        raise ValueError(f"confidence {record.confidence_pct} outside 0..100")
    values = (record.delta_roll_rad, record.delta_pitch_rad, record.delta_yaw_rad,
              record.delta_x_m, record.delta_y_m, record.delta_z_m)
    if not all(math.isfinite(v) for v in values):
        raise ValueError("non-finite delta")
    body = "DVPDL,%d,%d,%.6f,%.6f,%.6f,%.3f,%.3f,%.3f,%d" % (tu, dtu, *values, int(record.confidence_pct))
    return format_sentence(body)


# $DVEXT
def _fmt_gain(gain_db: float) -> str:
    return "%d" % round(gain_db)


#: $DVEXT fields 4-14 (after lock, GPS status and IMU calibration): (record attribute, field name,
#: printf format); the angles are degrees on the wire (radians in the record), data_skips an integer
_DVEXT_SCALARS = (("roll_rad", "roll", "%.1f"), ("pitch_rad", "pitch", "%.1f"),
                  ("heading_rad", "heading", "%.1f"), ("data_skips", "data_skips", "%d"),
                  ("velocity_up_m_s", "velocity_up", "%.3f"), ("altitude_m", "altitude", "%.2f"),
                  ("velocity_north_m_s", "velocity_north", "%.3f"),
                  ("velocity_east_m_s", "velocity_east", "%.3f"),
                  ("latitude_deg", "latitude", "%.9f"), ("longitude_deg", "longitude", "%.9f"),
                  ("ekf_elapsed_time_s", "elapsed_time", "%.3f"))
#: $DVEXT fields 15-34, four each (quaternion w x y z, beams A-D): (attribute, field name, parse, format)
_DVEXT_FOURS = (("orientation_wxyz", "q", _float, "%.6f".__mod__),
                ("beam_gain_db", "gain", _float, _fmt_gain), ("beam_locked", "lock", _flag, _tf),
                ("beam_velocity_m_s", "velocity", _float, "%.4f".__mod__),
                ("beam_range_m", "range", _float, "%.3f".__mod__))

def parse_dvext(fields: Sequence[str]) -> DvlExtended:
    """Parse the data fields of ``$DVEXT`` (docs/devices.md §1.3.2): 34 fields plus the trailing empty field 35 that
    real sentences carry (``...,rd,*hh``); a sentence without the trailing comma is accepted too.

    Raises ``DvlParseError``: wrong field count, non-empty field 35, malformed number or flag."""
    n = _DVEXT_FIELDS - 1
    if len(fields) == n + 1:
        if fields[n] != "":
            raise DvlParseError(f"$DVEXT: field 35 must be empty, got {fields[n][:20]!r}")
    elif len(fields) != n:
        raise DvlParseError(f"$DVEXT: expected {n} fields plus a trailing empty one, got {len(fields)}")
    f = fields
    gps = f[1]
    if len(gps) != 1 or not gps.isascii() or not gps.isalpha():
        raise DvlParseError(f"$DVEXT: GPS status must be one letter, got {gps[:20]!r}")
    cal_raw = f[2]
    cal = tuple(int(c) for c in cal_raw) if _CAL_RE.fullmatch(cal_raw) else None
    locked = _flag(f[0], "lock")
    scalars: dict[str, Any] = {}
    for k, (attr, name, fmt) in enumerate(_DVEXT_SCALARS, start=3):
        value = _int(f[k], name) if fmt == "%d" else _float(f[k], name)
        scalars[attr] = math.radians(value) if attr.endswith("_rad") else value
    fours: dict[str, Any] = {
        attr: tuple(parse(f[14 + 4 * j + k], f"{name}{'ABCD'[k]}") for k in range(4))
        for j, (attr, name, parse, _) in enumerate(_DVEXT_FOURS)}
    return DvlExtended(locked=locked, gps_status=gps, imu_calibration=cal,  # type: ignore[arg-type]
                       imu_calibration_raw=cal_raw, **scalars, **fours)


def format_dvext(record: DvlExtended) -> bytes:
    """Format a ``$DVEXT`` sentence as the DVL prints it, including the trailing empty field.

    Number formats follow the real capture in docs/devices.md §1.2 (the vendor format line differs for
    velocity-up): attitude ``%.1f`` deg, data skips integer, velocity-up ``%.3f``, altitude ``%.2f``,
    north/east ``%.3f``, lat/lon ``%.9f``, elapsed time ``%.3f``, quaternion ``%.6f``, gains integer
    dB, beam velocities ``%.4f``, beam ranges ``%.3f``.

    Raises ``ValueError``: non-finite values, or a GPS status / calibration field that is not printable."""
    r = record
    floats = [getattr(r, attr) for attr, _, fmt in _DVEXT_SCALARS if fmt != "%d"] + [
        v for attr, _, parse, _ in _DVEXT_FOURS if parse is _float for v in getattr(r, attr)]
    if not all(math.isfinite(v) for v in floats):
        raise ValueError("non-finite value in $DVEXT record")
    parts = ["DVEXT", _tf(r.locked), r.gps_status, r.imu_calibration_raw,
             *(fmt % (math.degrees(getattr(r, attr)) if attr.endswith("_rad") else getattr(r, attr))
               for attr, _, fmt in _DVEXT_SCALARS),
             *(out(v) for attr, _, _, out in _DVEXT_FOURS for v in getattr(r, attr)),
             ""]  # trailing empty field (§0 item 3)
    return format_sentence(",".join(parts))


# $GPRMC
def _parse_ddmm(value: str, hemi: str, deg_digits: int, name: str, positive: str, negative: str) -> Optional[float]:
    if value == "" and hemi == "":
        return None
    v = _float(value, name)
    if v < 0:
        raise DvlParseError(f"$GPRMC {name}: negative ddmm value {value!r}")
    degrees = int(v // 100)
    minutes = v - 100 * degrees
    if minutes >= 60.0 or degrees > (90 if deg_digits == 2 else 180):
        raise DvlParseError(f"$GPRMC {name}: invalid ddmm.mmmm value {value!r}")
    result = degrees + minutes / 60.0
    if hemi == negative:
        return -result
    if hemi == positive:
        return result
    raise DvlParseError(f"$GPRMC {name}: hemisphere must be {positive}/{negative}, got {hemi[:5]!r}")


def parse_gprmc(fields: Sequence[str]) -> DvlGprmc:
    """Parse the data fields of ``$GPRMC`` (docs/devices.md §1.3.3): time, status, lat, N/S, lon, E/W,
    speed (knots), track (deg), date, magnetic variation, E/W, and an optional mode field.

    Raises ``DvlParseError``: wrong field count, malformed time/position/number, status not A/V."""
    if len(fields) not in (11, 12):
        raise DvlParseError(f"$GPRMC: expected 11 or 12 fields, got {len(fields)}")
    t = fields[0]
    time_of_day_s: Optional[float] = None
    if t != "":
        if not re.fullmatch(r"[0-9]{6}(?:\.[0-9]+)?", t):
            raise DvlParseError(f"$GPRMC: malformed time {t[:20]!r}")
        hh, mm, ss = int(t[0:2]), int(t[2:4]), float(t[4:])
        if hh > 23 or mm > 59 or ss >= 61.0:
            raise DvlParseError(f"$GPRMC: time out of range {t!r}")
        time_of_day_s = hh * 3600.0 + mm * 60.0 + ss
    if fields[1] not in ("A", "V"):
        raise DvlParseError(f"$GPRMC: status must be A or V, got {fields[1][:5]!r}")
    lat = _parse_ddmm(fields[2], fields[3], 2, "latitude", "N", "S")
    lon = _parse_ddmm(fields[4], fields[5], 3, "longitude", "E", "W")
    speed = None if fields[6] == "" else _float(fields[6], "speed") * KNOT_M_S
    track = None if fields[7] == "" else math.radians(_float(fields[7], "track"))
    return DvlGprmc(time_of_day_s=time_of_day_s, valid=fields[1] == "A", latitude_deg=lat,
                    longitude_deg=lon, speed_m_s=speed, track_rad=track, date_ddmmyy=fields[8])


def format_gprmc(time_of_day_s: float, valid: bool, latitude_deg: Optional[float],
                 longitude_deg: Optional[float], speed_m_s: float, track_rad: float) -> bytes:
    """Format ``$GPRMC`` as the DVL's GPS emulation does (docs/devices.md §1.3.3): ``hhmmss.ss`` time,
    lat ``ddmm.mmmm`` + N/S, lon ``dddmm.mmmm`` + E/W (empty when None), speed in knots and track in
    degrees (``%.2f``), date (the DVL always sends ``010120``), empty magnetic-variation fields.

    Args:
        time_of_day_s: s since midnight (wrapped to one day).
        track_rad: rad clockwise from north (printed as 0..360 deg).
    Raises ``ValueError``: non-finite inputs."""
    if not all(math.isfinite(v) for v in (time_of_day_s, speed_m_s, track_rad)):
        raise ValueError("non-finite $GPRMC input")
    centis = round((time_of_day_s % 86400.0) * 100) % 8640000
    hh, rem = divmod(centis, 360000)
    mm, rem = divmod(rem, 6000)
    time_str = "%02d%02d%05.2f" % (hh, mm, rem / 100.0)

    def ddmm(value: Optional[float], width: int, pos: str, neg: str) -> Tuple[str, str]:
        if value is None:
            return "", ""
        a = abs(value)
        deg = int(a)
        minutes = round((a - deg) * 60.0, 4)
        if minutes >= 60.0:
            deg, minutes = deg + 1, 0.0
        return "%0*d%07.4f" % (width, deg, minutes), (pos if value >= 0 else neg)

    lat_s, ns = ddmm(latitude_deg, 2, "N", "S")
    lon_s, ew = ddmm(longitude_deg, 3, "E", "W")
    track_deg = math.degrees(track_rad) % 360.0
    body = "GPRMC,%s,%s,%s,%s,%s,%s,%.2f,%.2f,010120,," % (
        time_str, "A" if valid else "V", lat_s, ns, lon_s, ew, speed_m_s / KNOT_M_S, track_deg)
    return format_sentence(body)


def format_dvtxt(text: str) -> bytes:
    """Format a free-form ``$DVTXT,<text>`` line, without checksum as documented [D10] (§1.2).

    Raises ``ValueError``: text not printable ASCII (or containing ``*``/``$``)."""
    return format_sentence("DVTXT," + text, with_checksum=False)


# Line dispatcher
def _printable(raw: bytes) -> bool:
    return all(0x20 <= b <= 0x7E or b == 0x09 for b in raw)


#: the data sentences, which must carry a checksum
_DATA_PARSERS: dict[str, Callable[[Sequence[str]], DvlRecord]] = {
    "DVPDL": parse_dvpdl, "DVEXT": parse_dvext, "GPRMC": parse_gprmc}


def parse_line(line: Union[bytes, bytearray, str]) -> DvlRecord:
    """Parse one line from the DVL (terminator optional) into a typed record.

    Dispatch (docs/devices.md §1.2-§1.3): ``$DVPDL`` -> :class:`DvlPositionDelta`, ``$DVEXT`` ->
    :class:`DvlExtended`, ``$GPRMC`` -> :class:`DvlGprmc` (these three require a valid checksum),
    ``$DVTXT`` and bare printable lines -> :class:`DvlText`, anything else (``$DVNVM``, ``IMU:``,
    ``GPS:$``, unknown ``$`` sentences) -> :class:`DvlUnknown`.  Bytes that are not UTF-8 are
    tolerated (replaced) and make numeric fields fail cleanly.

    Raises ``DvlParseError``: empty line, bad checksum on any ``$`` sentence, missing checksum on a data sentence,
    malformed fields, or a non-``$`` line with non-printable bytes."""
    raw = _to_bytes(line).rstrip(b"\r\n")
    if not raw:
        raise DvlParseError("empty line")
    if raw.startswith(b"$"):
        sentence_id, fields, checksum_ok = split_sentence(raw)
        parse = _DATA_PARSERS.get(sentence_id)
        if parse is not None:
            if checksum_ok is None:
                raise DvlParseError(f"${sentence_id} sentence without checksum")
            return parse(fields)
        if sentence_id == "DVTXT":
            return DvlText(text=",".join(fields), sentence_id="DVTXT", checksum_ok=checksum_ok)
        return DvlUnknown(sentence_id=sentence_id, fields=fields,
                          line=raw.decode("utf-8", errors="replace"), checksum_ok=checksum_ok)
    if not _printable(raw):
        raise DvlParseError(f"non-printable bytes in line: {raw[:40]!r}")
    text = raw.decode("ascii")
    for prefix in ("IMU:", "GPS:"):
        if text.startswith(prefix):
            rest = text[len(prefix):]
            return DvlUnknown(sentence_id=prefix[:-1], fields=tuple(rest.split(",")), line=text, checksum_ok=None)
    return DvlText(text=text, sentence_id="", checksum_ok=None)


# Line framer
class DvlLineFramer:
    """Incremental line splitter for the DVL byte stream (docs/devices.md §1.2: split on LF, strip CR).

    Feed arbitrary chunks; complete lines come out without CR/LF.  Garbage handling:
    - bytes before the last ``$`` of a line are discarded (resynchronisation after line noise or a
      truncated sentence), except for ``$DVTXT`` text and ``GPS:$...`` re-tweets;
    - a line without ``$`` that contains non-printable bytes is discarded whole;
    - a line longer than ``max_line_bytes`` is discarded whole (up to its LF);
    - empty lines are skipped silently (not garbage).
    Discarded bytes (LF terminators excluded) are counted in :attr:`discarded_bytes`.  The result
    does not depend on how the stream is chunked.

    Args:
        max_line_bytes: longest accepted line in bytes (a ``$DVEXT`` is about 250)."""

    def __init__(self, max_line_bytes: int = 1024) -> None:
        if max_line_bytes < 16:
            raise ValueError("max_line_bytes must be >= 16")
        self.max_line_bytes = int(max_line_bytes)
        self._buf = bytearray()
        self._skipping = False
        #: Total bytes discarded as garbage since construction.
        self.discarded_bytes = 0

    def reset(self) -> None:
        """Drop any partial line (e.g. after a reconnect); counters are kept.  The partial line's
        bytes are counted as discarded."""
        self.discarded_bytes += len(self._buf)
        self._buf.clear()
        self._skipping = False

    def feed(self, data: Union[bytes, bytearray]) -> list:
        """Add a chunk; return the complete lines it finishes (list of bytes, no CR/LF)."""
        out: list = []
        *segments, rest = bytes(data).split(b"\n")
        for segment in segments:
            if self._skipping:  # the end of an over-long line
                self.discarded_bytes += len(segment)
                self._skipping = False
                continue
            self._buf += segment
            if len(self._buf) > self.max_line_bytes:
                self.discarded_bytes += len(self._buf)
            elif line := self._clean(bytes(self._buf)):
                out.append(line)
            self._buf.clear()
        if self._skipping:
            self.discarded_bytes += len(rest)
        else:
            self._buf += rest
            if len(self._buf) > self.max_line_bytes:
                self.discarded_bytes += len(self._buf)
                self._buf.clear()
                self._skipping = True
        return out

    def _clean(self, line: bytes) -> bytes:
        stripped = line.rstrip(b"\r")
        if not stripped:
            return b""
        if not stripped.startswith(b"$DVTXT"):
            k = stripped.rfind(b"$")
            if k > 0 and not (k == 4 and stripped.startswith(b"GPS:")):
                self.discarded_bytes += k
                stripped = stripped[k:]
        if not stripped.startswith(b"$") and not _printable(stripped):
            self.discarded_bytes += len(stripped)
            return b""
        return stripped


# Commands (host -> DVL)
def parse_command(line: Union[bytes, bytearray, str]) -> DvlCommand:
    """Split one host command line into keyword and argument (docs/devices.md §1.4: one ASCII line per
    command, LF-terminated, CR ignored).  Keywords are upper-cased (case sensitivity of the real
    firmware is undocumented).

    Raises ``DvlParseError``: empty line or non-printable bytes."""
    raw = _to_bytes(line).rstrip(b"\r\n").strip(b" \t")
    if not raw:
        raise DvlParseError("empty command")
    if not _printable(raw):
        raise DvlParseError(f"non-printable bytes in command: {raw[:40]!r}")
    text = raw.decode("ascii")
    if text.startswith("?"):
        return DvlCommand("CONFIGURATION", text[1:].strip())
    if text.upper().startswith("$GPRMC"):
        return DvlCommand("$GPRMC", text)
    keyword, _, argument = text.partition(" ")
    return DvlCommand(keyword.upper(), argument.strip())


def build_command(keyword: str, argument: Optional[str] = None) -> bytes:
    r"""Build one command line ``KEYWORD[ argument]\r\n`` (docs/devices.md §1.4; CR LF as the BlueOS
    driver sends [D17]).  Commands carry no checksum.

    Raises ``ValueError``: keyword/argument not printable ASCII, or keyword empty / containing spaces."""
    if not keyword or " " in keyword:
        raise ValueError(f"invalid command keyword {keyword!r}")
    text = keyword if argument is None else f"{keyword} {argument}"
    raw = text.encode("ascii")
    if not _printable(raw):
        raise ValueError(f"command must be printable ASCII: {text!r}")
    return raw + LINE_TERMINATOR


def _num(value: float, decimals: int = 3) -> str:
    if not math.isfinite(value):
        raise ValueError(f"non-finite command argument {value}")
    text = f"{round(value, decimals) + 0.0:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


_SEND_TARGETS = ("DVPDL", "DVEXT", "GPRMC", "FREEFORM", "DVKFA", "DVKFB", "DVFKA", "DVFKB")


def cmd_send(message: str, enabled: bool) -> bytes:
    """``SEND-<message> ON|OFF`` (docs/devices.md §1.4, sticky).  ``message`` is one of DVPDL, DVEXT,
    GPRMC, FREEFORM, DVKFA/DVKFB (the command table spells DVFKA/DVFKB, possibly a typo [UNVERIFIED];
    both spellings pass through verbatim).

    Raises ``ValueError``: unknown message name."""
    name = message.upper()
    if name not in _SEND_TARGETS:
        raise ValueError(f"unknown SEND- target {message!r}; expected one of {_SEND_TARGETS}")
    return build_command(f"SEND-{name}", "ON" if enabled else "OFF")


def cmd_set_sensor_orientation(roll_rad: float, pitch_rad: float, heading_rad: float) -> bytes:
    """``SET-SENSOR-ORIENTATION <roll>,<pitch>,<heading>`` in degrees (docs/devices.md §1.4): the
    sensor -> vehicle rotation, each angle within ±180 deg; factory (0,0,0) = downward-looking.

    Raises ``ValueError``: an angle outside ±pi rad (±180 deg) or non-finite."""
    degs = [math.degrees(a) for a in (roll_rad, pitch_rad, heading_rad)]
    for d in degs:
        if not math.isfinite(d) or abs(d) > 180.0 + 1e-9:
            raise ValueError(f"sensor orientation angle {d} deg outside ±180")
    return build_command("SET-SENSOR-ORIENTATION", ",".join(_num(d) for d in degs))


def cmd_set_speed_of_sound(speed_of_sound_m_s: float) -> bytes:
    """``SET-SPEED-OF-SOUND <m/s>`` (docs/devices.md §1.4: 1100..1950 m/s, sticky; factory 1484).

    Raises ``ValueError``: outside 1100..1950 m/s."""
    if not 1100.0 <= speed_of_sound_m_s <= 1950.0:
        raise ValueError(f"speed of sound {speed_of_sound_m_s} m/s outside 1100..1950")
    return build_command("SET-SPEED-OF-SOUND", _num(speed_of_sound_m_s, 1))


def startup_commands(sensor_orientation_rad: Tuple[float, float, float] = (0.0, 0.0, 0.0),
                     speed_of_sound_m_s: Optional[float] = None, request_configuration: bool = True) -> list:
    """The command lines a driver sends at start-up, modelled on the BlueOS sequence [D17]
    (docs/devices.md §0 item 1, §1.4): ``SEND-DVPDL ON`` (factory OFF!), ``SEND-DVEXT ON``,
    ``SEND-GPRMC OFF``, ``RETWEET-IMU OFF``, ``RETWEET-GPS OFF``, ``SET-SENSOR-ORIENTATION``,
    optionally ``SET-SPEED-OF-SOUND``, ``RESUME`` and optionally ``CONFIGURATION``.

    Args:
        sensor_orientation_rad: (roll, pitch, heading) sensor -> vehicle rotation, rad.
        speed_of_sound_m_s: None leaves the DVL's sticky value alone.
    Returns list of bytes, one command line each (CR LF terminated).
    Raises ``ValueError``: out-of-range arguments (see the individual builders)."""
    cmds = [cmd_send("DVPDL", True), cmd_send("DVEXT", True), cmd_send("GPRMC", False),
            build_command("RETWEET-IMU", "OFF"), build_command("RETWEET-GPS", "OFF"),
            cmd_set_sensor_orientation(*sensor_orientation_rad)]
    if speed_of_sound_m_s is not None:
        cmds.append(cmd_set_speed_of_sound(speed_of_sound_m_s))
    cmds.append(build_command("RESUME"))  # restart pinging
    if request_configuration:
        cmds.append(build_command("CONFIGURATION"))  # dumped as free-form lines
    return cmds

