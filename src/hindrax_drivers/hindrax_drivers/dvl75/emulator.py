"""Cerulean DVL-75 device emulator (device side of the serial protocol), I/O-free.

Layer 2 of the DVL-75 driver (docs/architecture.md §2): it speaks the DVL's ASCII protocol byte-exactly from the
device side, driven by a *truth source* (simulator, bag replay or test script), with fault injection
in its API.  It does no I/O and reads no clock: the host's bytes come in through
:meth:`Dvl75Emulator.feed_host_bytes` and the device's bytes come out of
:meth:`Dvl75Emulator.poll` ``(t_s)``; :class:`hindrax_common.transport.pty_device.PtyDevice` serves
it on a pseudo-terminal so the real pyserial path runs against it.

Behaviour (docs/devices.md §1.1-§1.6, especially the §1.6 checklist):
- Factory defaults [D11]: ``$DVPDL`` **OFF**, ``$DVEXT`` ON, free-form text ON, ``$GPRMC`` OFF,
  DVKFA/B OFF, re-tweets OFF, declination 0, speed of sound 1484 m/s, orientation (0,0,0).  Settings
  live in :class:`DvlFlash` ("emulated flash", sticky across REBOOT and across emulator instances
  sharing the object).
- Each ping cycle (rate 5..20 Hz, default 10 Hz; the real rate is automatic and has no command) emits
  the enabled sentences with correct checksums and CR LF: ``$DVPDL`` (``dtu`` = the real interval,
  ``c=0`` and zero deltas when unlocked), ``$DVEXT`` (ranges -1.000 when unlocked, trailing empty
  field), ``$GPRMC``.  Free-form ``$DVTXT`` lines (no checksum, as documented [D10]) at boot and as
  the CONFIGURATION response; command errors are reported as ``$DVTXT`` (real behaviour unverified,
  §1.6 item 5).
- Commands (§1.4) are split on LF with CR stripped; keywords are case-insensitive here.

Truth -> measurement model (the emulator's own modelling choices are marked [EMULATOR]):
- ``DvlTruth`` is given in the marine convention: body velocity over ground in FRD, attitude as
  roll/pitch/yaw with yaw = heading clockwise from north (NED), altitude = vertical distance to a flat bottom.
- ``$DVPDL`` deltas: trapezoidal integral of the FRD velocity over ``dtu``; angle deltas are wrapped
  differences of (roll, pitch, yaw) [EMULATOR: the firmware's exact definition is undocumented].
- ``$DVEXT``: roll as is, pitch negated (DVL Euler angles are right-handed about X bow / Y port,
  docs/devices.md §1.5, so + = bow down [DERIVED]), heading = yaw in 0..360 deg; quaternion = FLU body in
  ENU; north/east/up velocities = R_nb v; altitude along the sensor (body z) axis =
  altitude / (cos roll cos pitch); per-beam ranges and velocities from a four-beam Janus geometry
  (A port, B stern, C starboard, D bow) tilted ``beam_tilt_rad`` from the sensor axis [EMULATOR: the
  DVL-75 beam angle is not in docs/devices.md], beam velocity + = approaching along the beam (the only
  documented sign, Tracker-650 [D16]).  Per-beam data in the truth override the geometry.
- Lock: truth flag, altitude within 0.3..40 m and tilt within 20 deg (operating envelope, §1.1).
- Speed of sound: velocities and ranges scale by (configured c / true c) when
  ``true_speed_of_sound_m_s`` is given; SET-VELOCITY-ADJUSTMENT multiplies velocities.
- Not emulated: re-tweeted IMU/GPS lines, ``$DVKFA``/``$DVKFB`` (layout unverified, docs/devices.md §6),
  Ethernet/UDP, mounting-orientation mismatch (the truth is taken to be in the configured vehicle
  frame), declination effects on heading."""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional, Tuple, Union

import numpy as np
from scipy.spatial.transform import Rotation

from hindrax_common.base import frames
from hindrax_common.base.frames import wrap_angle
from hindrax_common.transport.pty_device import PeriodicSchedule, StreamFaults
from .protocol import (BEAM_TILT_RAD, DvlExtended, DvlGprmc, DvlLineFramer, DvlParseError,
                       DvlPositionDelta, beam_directions_frd, format_dvext, format_dvpdl,
                       format_dvtxt, format_gprmc, parse_command, parse_line)

__all__ = ["from_config", "DvlTruth", "DvlFlash", "Dvl75Emulator", "EARTH_RADIUS_M"]

#: Mean Earth radius used for dead-reckoned latitude/longitude [EMULATOR].
EARTH_RADIUS_M = 6371000.0
_GPS_FRESH_S = 1.5  # SET-POSITION counts as a fix, fresh for 1.5 s (docs/devices.md §1.3.2, §1.4)
_IMU_CALIBRATION = "3333"  # $DVEXT field 3: every IMU part fully calibrated
_DEFAULT_GAIN_DB = 25.0  # per-beam gain when the truth gives none (the capture shows 25)
_MAX_TILT_RAD = math.radians(20.0)  # lock envelope (docs/devices.md §1.1)
_MAX_BACKLOG_S = 1.0  # when polled late, cycles older than this are skipped rather than emitted


@dataclass(frozen=True)
class DvlTruth:
    """True state the DVL measures at one instant (inputs of :class:`Dvl75Emulator`).

    Attributes:
        velocity_frd_m_s: vehicle velocity over the bottom in body FRD axes (surge, sway, heave), m/s.
        altitude_m: vertical distance from the DVL to a flat bottom, m; None = no bottom in range.
        roll_rad, pitch_rad, yaw_rad: attitude, Fossen/SNAME ZYX Euler angles of FRD body in NED
            (yaw = heading clockwise from true north), rad.
        bottom_lock: False forces "searching" whatever the geometry.
        confidence_pct: ``$DVPDL`` confidence when locked, 0..100 %.
        beam_locked, beam_velocity_m_s, beam_range_m, beam_gain_db: optional per-beam values in the order A port, B
            stern, C starboard, D bow (4-tuples) reported verbatim instead of the emulator's geometric model."""

    velocity_frd_m_s: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    altitude_m: Optional[float] = 5.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0
    bottom_lock: bool = True
    confidence_pct: float = 100.0
    beam_locked: Optional[Tuple[bool, bool, bool, bool]] = None
    beam_velocity_m_s: Optional[Tuple[float, float, float, float]] = None
    beam_range_m: Optional[Tuple[float, float, float, float]] = None
    beam_gain_db: Optional[Tuple[float, float, float, float]] = None


@dataclass
class DvlFlash:
    """Sticky DVL settings ("emulated flash", docs/devices.md §1.4 "Sticky" column), at factory defaults
    [D11] when constructed without arguments.  Survives REBOOT; share one instance between emulators
    to model power cycles."""

    send_dvpdl: bool = False
    send_dvext: bool = True
    send_gprmc: bool = False
    send_freeform: bool = True
    send_dvkfa: bool = False
    send_dvkfb: bool = False
    retweet_gps: bool = False
    retweet_imu: bool = False
    declination_rad: float = 0.0
    speed_of_sound_m_s: float = 1484.0
    velocity_adjustment: float = 1.0
    sensor_orientation_rad: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    baud_rate: int = 115200
    static_ip: str = "0.0.0.0"
    host_address: str = "255.255.255.255:27000"
    fallback_address: str = "192.168.2.3"
    other: Dict[str, str] = field(default_factory=dict)


TruthSource = Union[Callable[[float], DvlTruth], DvlTruth]

_SEND_FLAGS = {
    "DVPDL": "send_dvpdl", "DVEXT": "send_dvext", "GPRMC": "send_gprmc", "FREEFORM": "send_freeform",
    "DVKFA": "send_dvkfa", "DVKFB": "send_dvkfb", "DVFKA": "send_dvkfa", "DVFKB": "send_dvkfb",
}
_STORED_ONLY = ("HEADING-OFFSET", "SET-SIDE-TRACKING", "SEND-SIDE-TRACKING-FRAME", "MANUAL-MODE",
                "GRAB-IMU-CAL", "VOID-IMU-CAL", "SUPPRESS-GPS")
_COORD_RE = re.compile(
    r"\s*(?:(?P<dd>[+-]?[0-9]+(?:\.[0-9]+)?)"
    r"|(?P<d>[0-9]+)\s+(?P<m>[0-9]+(?:\.[0-9]+)?)\s*(?P<h1>[NSEW])"
    r"|(?P<ddmm>[0-9]+(?:\.[0-9]+)?)\s*(?P<h2>[NSEW]))\s*"
)


def _parse_coordinate(text: str) -> float:
    """One SET-POSITION coordinate: DD, ``D M.m H`` or ``DDMM.m H`` (docs/devices.md §1.4)."""
    m = _COORD_RE.fullmatch(text)
    if m is None:
        raise ValueError(f"bad coordinate {text!r}")
    if m.group("dd") is not None:
        return float(m.group("dd"))
    if m.group("d") is not None:
        value, hemi = int(m.group("d")) + float(m.group("m")) / 60.0, m.group("h1")
    else:
        raw = float(m.group("ddmm"))
        value, hemi = int(raw // 100) + (raw % 100) / 60.0, m.group("h2")
    return -value if hemi in "SW" else value


class Dvl75Emulator:
    """I/O-free Cerulean DVL-75 (serial side).  See the module docstring for the model.

    Args:
        truth_source: callable ``t_s -> DvlTruth`` (or a constant :class:`DvlTruth`).
        rate_hz: ping/output rate, 5..20 Hz (docs/devices.md §1.1).
        flash: sticky settings; default factory settings.
        beam_tilt_rad: beam angle from the sensor axis for the geometric beam model [EMULATOR].
        true_speed_of_sound_m_s: water's true c; None = equal to the configured c (no scale error).
        min_altitude_m, max_altitude_m: lock envelope (docs/devices.md §1.1).
        seed: seed of the fault generator.
    Attributes:
        faults: :class:`StreamFaults` (garbage, bad checksums, truncated/dropped lines, stuck values, disconnect).
        flash: the :class:`DvlFlash` in use.
        sent_counts: sentences generated per sentence id (before faults).
        commands_received: every command line received, decoded."""

    def __init__(self, truth_source: TruthSource, *, rate_hz: float = 10.0, flash: Optional[DvlFlash] = None,
                 beam_tilt_rad: float = BEAM_TILT_RAD, true_speed_of_sound_m_s: Optional[float] = None,
                 min_altitude_m: float = 0.3, max_altitude_m: float = 40.0, seed: int = 0) -> None:
        if isinstance(truth_source, DvlTruth):
            constant = truth_source
            truth_source = lambda _t: constant  # noqa: E731
        self._truth_source: Callable[[float], DvlTruth] = truth_source
        self._schedule = PeriodicSchedule(0.1)
        self.set_rate_hz(rate_hz)
        self.flash = flash if flash is not None else DvlFlash()
        self._beam_dirs = np.array(beam_directions_frd(beam_tilt_rad))
        self.true_speed_of_sound_m_s = true_speed_of_sound_m_s
        self.min_altitude_m = float(min_altitude_m)
        self.max_altitude_m = float(max_altitude_m)
        self.faults = StreamFaults(garbage_alphabet=bytes(range(0x80, 0x100)), seed=seed)
        self.sent_counts: Dict[str, int] = {}
        self.commands_received: List[str] = []
        self._lock = threading.RLock()
        self._framer = DvlLineFramer()
        self._pending: List[bytes] = []
        self._force_unlocked = False
        self._force_zero_confidence = False
        self._boot_t: Optional[float] = None
        self._now = 0.0
        self._reset_runtime()

    # --- configuration / faults -----------------------------------------------------------------
    def set_rate_hz(self, rate_hz: float) -> None:
        """Change the output rate (5..20 Hz, docs/devices.md §1.1); takes effect from the next cycle.

        Raises ``ValueError``: outside 5..20 Hz."""
        if not 5.0 <= rate_hz <= 20.0:
            raise ValueError(f"DVL-75 rate {rate_hz} Hz outside 5..20 Hz")
        self._schedule.set_period(1.0 / float(rate_hz))

    def set_unlocked(self, unlocked: bool) -> None:
        """Fault: report "searching" (no bottom lock) regardless of the truth."""
        self._force_unlocked = bool(unlocked)

    def set_zero_confidence(self, zero: bool) -> None:
        """Fault: report ``$DVPDL`` confidence 0 (with zero deltas) regardless of the truth."""
        self._force_zero_confidence = bool(zero)

    # --- host interface ---------------------------------------------------------------------------
    def feed_host_bytes(self, data: bytes) -> None:
        """Receive bytes written by the host; complete command lines are executed immediately and
        any replies are queued for the next :meth:`poll`.  Ignored while ``faults.disconnected``."""
        with self._lock:
            if self.faults.disconnected:
                return
            for line in self._framer.feed(data):
                self._handle_command(line)

    def poll(self, t_s: float) -> bytes:
        """Return the bytes the DVL sends up to time ``t_s`` (s, emulator clock).  The first call
        boots the device (banner) at ``t_s``; then one ping cycle every 1/rate s."""
        with self._lock:
            if self._boot_t is None:
                self.reboot(t_s)
            self._now = t_s
            if not self._paused:
                for t_cycle in self._schedule.due(t_s, _MAX_BACKLOG_S):
                    self._cycle(t_cycle)
            messages, self._pending = self._pending, []
            return self.faults.transmit(messages, _corrupt_nmea_checksum)

    def next_output_s(self) -> Optional[float]:
        """When the next unprompted output is due (s): the next cycle; -inf before the boot or with replies queued; None
        while paused (:class:`~hindrax_common.transport.pty_device.ByteStreamEmulator`)."""
        with self._lock:
            if self._boot_t is None or self._pending:
                return -math.inf
            return None if self._paused else self._schedule.next_s()

    def reboot(self, t_s: float) -> None:
        """Restart as at power-up at time ``t_s``: boot time (``tu`` = 0), non-sticky state
        (pause, position, GPS fix) reset, flash kept, boot banner queued (if free-form is on)."""
        with self._lock:
            self._boot_t = float(t_s)
            self._now = float(t_s)
            self._reset_runtime()
            self._schedule.restart(self._boot_t, 1)
            self._text("Cerulean Sonar DVL-75 (hindrax emulator) booting")
            self._text(f"Baud rate {self.flash.baud_rate}, speed of sound {self.flash.speed_of_sound_m_s:.1f} m/s")
            self._text("Boot complete")

    # --- internals --------------------------------------------------------------------------------
    def _reset_runtime(self) -> None:
        self._paused = False
        self._prev_tu: Optional[int] = None
        self._prev_truth: Optional[DvlTruth] = None
        self._prev_velocity: Optional[np.ndarray] = None
        self._latitude_deg = 0.0
        self._longitude_deg = 0.0
        self._position_set = False
        self._fix_t: Optional[float] = None
        self._data_skips = 0

    def _emit(self, sentence_id: str, message: bytes) -> None:
        self.sent_counts[sentence_id] = self.sent_counts.get(sentence_id, 0) + 1
        self._pending.append(message)

    def _text(self, text: str) -> None:
        if self.flash.send_freeform:
            safe = "".join(ch if 0x20 <= ord(ch) <= 0x7E and ch not in "*$" else "?" for ch in text)
            self._emit("DVTXT", format_dvtxt(safe))

    def _velocity_scale(self) -> Tuple[float, float]:
        """(velocity scale, range scale) from configured vs true c and the velocity adjustment."""
        c_true = self.true_speed_of_sound_m_s
        range_scale = 1.0 if c_true is None else self.flash.speed_of_sound_m_s / c_true
        return range_scale * self.flash.velocity_adjustment, range_scale

    def _is_locked(self, truth: DvlTruth) -> bool:
        alt = truth.altitude_m
        if self._force_unlocked or not truth.bottom_lock or alt is None or not math.isfinite(alt):
            return False
        if not self.min_altitude_m <= alt <= self.max_altitude_m:
            return False
        tilt = math.acos(max(-1.0, min(1.0, math.cos(truth.roll_rad) * math.cos(truth.pitch_rad))))
        return tilt <= _MAX_TILT_RAD

    def _cycle(self, t: float) -> None:
        """One ping cycle at time ``t``: queues the enabled sentences, ``$DVEXT`` before ``$DVPDL`` (the order on the
        real DVL is not documented, docs/devices.md §1.3; with this order the driver's latest ``$DVEXT`` is the one of
        the same ping when the ``$DVPDL`` arrives, so the attitude published with a velocity is not a ping old)."""
        truth = self.faults.hold(self._truth_source(t))
        assert self._boot_t is not None
        tu = round((t - self._boot_t) * 1000.0) * 1000  # captures show whole milliseconds
        dtu = tu - self._prev_tu if self._prev_tu is not None else round(self._schedule.period_s * 1000.0) * 1000
        dt = dtu / 1e6
        locked = self._is_locked(truth)
        vel_scale, range_scale = self._velocity_scale()
        velocity = np.asarray(truth.velocity_frd_m_s, dtype=float) * vel_scale
        r_nb = Rotation.from_euler("ZYX", [truth.yaw_rad, truth.pitch_rad, truth.roll_rad]).as_matrix()
        self._data_skips = 0 if locked else self._data_skips + 1

        v_ned = r_nb @ velocity if locked else np.zeros(3)
        if locked:
            self._latitude_deg += math.degrees(v_ned[0] * dt / EARTH_RADIUS_M)
            cos_lat = max(1e-6, math.cos(math.radians(self._latitude_deg)))
            self._longitude_deg += math.degrees(v_ned[1] * dt / (EARTH_RADIUS_M * cos_lat))
            self._longitude_deg = (self._longitude_deg + 180.0) % 360.0 - 180.0
        gps_fresh = self._fix_t is not None and t - self._fix_t < _GPS_FRESH_S

        if self.flash.send_dvext:
            self._emit("DVEXT", format_dvext(self._extended(truth, locked, dt, velocity, v_ned, r_nb,
                                                            range_scale, gps_fresh)))
        if self.flash.send_dvpdl:
            confidence = int(round(min(100.0, max(0.0, truth.confidence_pct))))
            if not locked or self._force_zero_confidence:
                confidence = 0
            if confidence > 0:
                prev_v = self._prev_velocity if self._prev_velocity is not None else velocity
                delta = 0.5 * (prev_v + velocity) * dt
                prev = self._prev_truth if self._prev_truth is not None else truth
                d_att = (wrap_angle(truth.roll_rad - prev.roll_rad), wrap_angle(truth.pitch_rad - prev.pitch_rad),
                         wrap_angle(truth.yaw_rad - prev.yaw_rad))
            else:
                delta, d_att = np.zeros(3), (0.0, 0.0, 0.0)
            record = DvlPositionDelta(tu / 1e6, dt, *d_att, *(float(x) for x in delta), confidence)
            self._emit("DVPDL", format_dvpdl(record))

        if self.flash.send_gprmc:
            valid = gps_fresh or (self._position_set and locked)
            self._emit("GPRMC", format_gprmc(
                time_of_day_s=t - self._boot_t, valid=valid,
                latitude_deg=self._latitude_deg if valid else None,
                longitude_deg=self._longitude_deg if valid else None,
                speed_m_s=float(math.hypot(v_ned[0], v_ned[1])), track_rad=truth.yaw_rad))

        self._prev_tu, self._prev_truth = tu, truth
        self._prev_velocity = velocity if locked else None

    def _extended(self, truth: DvlTruth, locked: bool, dt: float, velocity: np.ndarray, v_ned: np.ndarray,
                  r_nb: np.ndarray, range_scale: float, gps_fresh: bool) -> DvlExtended:
        alt = truth.altitude_m if truth.altitude_m is not None else 0.0
        if locked:
            along_axis = alt / (math.cos(truth.roll_rad) * math.cos(truth.pitch_rad)) * range_scale
        else:
            along_axis = 0.0
        beam_locked: List[bool] = []
        beam_velocity: List[float] = []
        beam_range: List[float] = []
        for k in range(4):
            down = float((r_nb @ self._beam_dirs[k])[2])
            hit = locked and down > 1e-6
            is_locked = hit if truth.beam_locked is None else (locked and bool(truth.beam_locked[k]))
            if not is_locked:
                beam_locked.append(False)
                beam_velocity.append(0.0)
                beam_range.append(-1.0)
                continue
            beam_locked.append(True)
            beam_velocity.append(float(truth.beam_velocity_m_s[k]) if truth.beam_velocity_m_s is not None
                                 else float(velocity @ self._beam_dirs[k]))
            beam_range.append(float(truth.beam_range_m[k]) if truth.beam_range_m is not None
                              else alt / down * range_scale)
        gains = (tuple(float(g) for g in truth.beam_gain_db) if truth.beam_gain_db is not None
                 else (_DEFAULT_GAIN_DB,) * 4)
        # the DVL reports base_link (FLU) in ENU (docs/devices.md §1.5, REP-103)
        qx, qy, qz, qw = frames.quaternion_marine_to_ros(Rotation.from_matrix(r_nb).as_quat())
        return DvlExtended(
            locked=locked,
            gps_status="A" if gps_fresh else "X",
            imu_calibration=tuple(int(ch) for ch in _IMU_CALIBRATION),  # type: ignore[arg-type]
            imu_calibration_raw=_IMU_CALIBRATION,
            roll_rad=truth.roll_rad,
            pitch_rad=-truth.pitch_rad,
            heading_rad=truth.yaw_rad % (2.0 * math.pi),
            data_skips=self._data_skips,
            velocity_up_m_s=float(-v_ned[2]),
            altitude_m=along_axis,
            velocity_north_m_s=float(v_ned[0]),
            velocity_east_m_s=float(v_ned[1]),
            latitude_deg=self._latitude_deg,
            longitude_deg=self._longitude_deg,
            ekf_elapsed_time_s=dt,
            orientation_wxyz=(float(qw), float(qx), float(qy), float(qz)),
            beam_gain_db=gains,  # type: ignore[arg-type]
            beam_locked=tuple(beam_locked),  # type: ignore[arg-type]
            beam_velocity_m_s=tuple(beam_velocity),  # type: ignore[arg-type]
            beam_range_m=tuple(beam_range),  # type: ignore[arg-type]
        )

    # --- commands -----------------------------------------------------------------------------------
    def _handle_command(self, line: bytes) -> None:
        try:
            cmd = parse_command(line)
        except DvlParseError as exc:
            self._text(f"Error: {exc}")
            return
        self.commands_received.append(line.decode("ascii", errors="replace"))
        k, arg = cmd.keyword, cmd.argument
        flash = self.flash
        try:
            if k in _STORED_ONLY:
                flash.other[k] = arg
            elif k.startswith("SEND-") and k[5:] in _SEND_FLAGS:
                setattr(flash, _SEND_FLAGS[k[5:]], _on_off(arg))
            elif k in ("RETWEET-GPS", "RETWEET-IMU"):
                setattr(flash, "retweet_" + k[8:].lower(), _on_off(arg))
            elif k == "SET-SPEED-OF-SOUND":
                flash.speed_of_sound_m_s = _ranged(arg, 1100.0, 1950.0)
            elif k == "SET-VELOCITY-ADJUSTMENT":
                flash.velocity_adjustment = _ranged(arg, 0.8, 1.25)
            elif k == "DECLINATION":
                flash.declination_rad = math.radians(_ranged(arg, -180.0, 180.0))
            elif k == "SET-SENSOR-ORIENTATION":
                parts = arg.split(",")
                if len(parts) != 3:
                    raise ValueError("expected roll,pitch,heading")
                flash.sensor_orientation_rad = tuple(  # type: ignore[assignment]
                    math.radians(_ranged(p, -180.0, 180.0)) for p in parts)
            elif k == "BAUD-RATE":
                flash.baud_rate = int(_ranged(arg, 9600, 921600))  # applied at next boot
            elif k == "IP-ADDRESS":
                flash.static_ip = _ipv4(arg)
            elif k == "FALLBACK-ADDRESS":
                ip = _ipv4(arg)
                if ip in ("0.0.0.0", "255.255.255.255"):
                    raise ValueError("fallback address cannot be 0.0.0.0 or broadcast")
                flash.fallback_address = ip
            elif k == "HOST-ADDRESS":
                ip, sep, port = arg.partition(":")
                if not sep or not port.isdigit() or not 0 < int(port) < 65536:
                    raise ValueError("expected ip:port")
                flash.host_address = f"{_ipv4(ip)}:{int(port)}"
            elif k == "UNICAST-TO-ME":
                pass  # Ethernet only; undefined on serial (docs/devices.md §1.4)
            elif k == "SET-POSITION":
                lat_s, sep, lon_s = arg.partition(",")
                if not sep:
                    raise ValueError("expected lat,lon")
                self._set_fix(_parse_coordinate(lat_s), _parse_coordinate(lon_s))
            elif k == "$GPRMC":
                rec = parse_line(arg)
                if (isinstance(rec, DvlGprmc) and rec.valid and rec.latitude_deg is not None
                        and rec.longitude_deg is not None):
                    self._set_fix(rec.latitude_deg, rec.longitude_deg)  # ignored unless status A
            elif k == "PAUSE":
                self._paused = True
            elif k == "RESUME":
                if self._paused:
                    self._paused = False
                    self._prev_tu, self._prev_truth, self._prev_velocity = None, None, None
                    self._schedule.restart(self._now, 1)
            elif k == "REBOOT":
                self.reboot(self._now)
            elif k == "CONFIGURATION":
                self._configuration()
            else:
                self._text(f"Unknown command: {k}")
        except (ValueError, DvlParseError) as exc:
            self._text(f"Error in {k}: {exc}")

    def _set_fix(self, latitude_deg: float, longitude_deg: float) -> None:
        if not (-90.0 <= latitude_deg <= 90.0 and -180.0 <= longitude_deg <= 180.0):
            raise ValueError("position out of range")
        self._latitude_deg, self._longitude_deg = latitude_deg, longitude_deg
        self._position_set = True
        self._fix_t = self._now

    def _configuration(self) -> None:
        f = self.flash
        onoff = {True: "ON", False: "OFF"}
        roll, pitch, heading = (math.degrees(a) for a in f.sensor_orientation_rad)
        lines = [
            "CONFIGURATION",
            f"SEND-DVPDL {onoff[f.send_dvpdl]}", f"SEND-DVEXT {onoff[f.send_dvext]}",
            f"SEND-GPRMC {onoff[f.send_gprmc]}", f"SEND-FREEFORM {onoff[f.send_freeform]}",
            f"SEND-DVKFA {onoff[f.send_dvkfa]}", f"SEND-DVKFB {onoff[f.send_dvkfb]}",
            f"RETWEET-GPS {onoff[f.retweet_gps]}", f"RETWEET-IMU {onoff[f.retweet_imu]}",
            f"DECLINATION {math.degrees(f.declination_rad):.2f}",
            f"SET-SPEED-OF-SOUND {f.speed_of_sound_m_s:.1f}",
            f"SET-VELOCITY-ADJUSTMENT {f.velocity_adjustment:.4f}",
            f"SET-SENSOR-ORIENTATION {roll:.2f},{pitch:.2f},{heading:.2f}",
            f"BAUD-RATE {f.baud_rate}", f"IP-ADDRESS {f.static_ip}",
            f"HOST-ADDRESS {f.host_address}", f"FALLBACK-ADDRESS {f.fallback_address}",
            f"local IP address {f.fallback_address}:50000",
        ]
        for line in lines:
            self._text(line)


def _on_off(arg: str) -> bool:
    """SEND-/RETWEET- argument: ``OFF`` -> False, anything starting with ``ON`` -> True ("parser is
    more lenient with on than off", docs/devices.md §1.4)."""
    a = arg.strip().upper()
    if a == "OFF":
        return False
    if a.startswith("ON"):
        return True
    raise ValueError(f"expected ON or OFF, got {arg!r}")


def _ranged(text: str, lo: float, hi: float) -> float:
    value = float(text.strip())
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ValueError(f"{text.strip()!r} outside {lo}..{hi}")
    return value


def _ipv4(text: str) -> str:
    parts = text.strip().split(".")
    if len(parts) != 4 or not all(p.isdigit() and 0 <= int(p) <= 255 for p in parts):
        raise ValueError(f"bad IPv4 address {text!r}")
    return ".".join(str(int(p)) for p in parts)


def _corrupt_nmea_checksum(message: bytes) -> bytes:
    """Replace the two hex digits after ``*`` with a different value; lines without checksum
    (``$DVTXT``) get a character changed instead so they still differ."""
    star = message.rfind(b"*")
    if star >= 0 and len(message) >= star + 3:
        wrong = int(message[star + 1:star + 3], 16) ^ 0x5A
        return message[:star + 1] + b"%02X" % wrong + message[star + 3:]
    body = message.rstrip(b"\r\n")
    return body[:-1] + b"#" + message[len(body):] if body else message


def from_config(config, truth: TruthSource, clock: Callable[[], float], seed: int = 0, *, rate_hz: float = 10.0,
                min_altitude_m: float = 0.3, max_altitude_m: float = 40.0) -> Dvl75Emulator:
    """A DVL-75 on ``truth`` (devices.py factory; clock: the pty's). Ping rate, Hz, and bottom-lock range, m, are
    the simulated part's (the simulator passes its truth's); the defaults are the emulator's."""
    return Dvl75Emulator(truth, rate_hz=rate_hz, flash=DvlFlash(), min_altitude_m=min_altitude_m,
                         max_altitude_m=max_altitude_m, seed=seed)
