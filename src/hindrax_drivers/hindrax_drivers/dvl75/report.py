"""DVL-75 records -> one report in ROS conventions (base_link FLU, SI): the pure core of the DVL node.

:class:`DvlReportBuilder` turns a ``$DVPDL`` record (velocity source) plus the latest ``$DVEXT`` record
(lock, attitude, altitude, beams) into a :class:`DvlReport` holding exactly the fields of
``hindrax_msgs/Dvl`` and ``geometry_msgs/TwistWithCovarianceStamped``; the node only copies them into
messages. No ROS, no clocks: receive times are passed in (ns).

Conventions and sources
- ``$DVPDL`` deltas are in the DVL's vehicle frame, FRD (X bow, Y starboard, Z down; docs/devices.md §1.3.1,
  §1.5), after SET-SENSOR-ORIENTATION. Velocity = position delta / ``dtu`` (the mean over the interval,
  docs/devices.md §1.3.1 "common use"), so its time of validity is the middle of the interval.
- Lever arm: the DVL measures the velocity of its transducer, at ``position_frd_m`` from the centre of
  gravity (the base_link origin, README "Configuration and frames"). Rigid-body kinematics
  v_CG = v_DVL - omega x r gives the base_link velocity; omega is taken from the ``$DVPDL`` angle
  deltas over ``dtu`` (small-angle: Euler-angle increments ~ body rotation increments). The position
  delta is corrected the same way (delta_p_CG = delta_p_DVL - delta_theta x r), so velocity equals
  delta_position / delta_time. Conversion FRD -> FLU through :mod:`hindrax_common.base.frames` only.
- Validity (docs/architecture.md §8 "lost DVL lock"): a velocity is published only when ``$DVPDL`` confidence > 0,
  ``dtu`` > 0, and the latest ``$DVEXT`` (if one arrived within ``max_extended_age_s``) reports bottom
  lock. Otherwise velocity and delta position are NaN, ``velocity_valid`` is False and the covariance
  is marked unknown (``[0] = -1``, hindrax_msgs/Dvl). Confidence 0 means every field after ``dtu`` is
  garbage (Tracker-650 doc, docs/devices.md §1.3.1 [D4b]).
- Plausibility gates (``sensors.dvl75.max_speed_m_s``, ``min_interval_s``, ``max_interval_s``): a
  checksum-valid ``$DVPDL`` whose ``dtu`` lies outside [min_interval_s, max_interval_s] or whose speed
  |delta_p| / dtu exceeds max_speed_m_s (or is not finite) is published not valid, like an unlocked one,
  with the reason in :attr:`DvlReport.rejection`. The XOR checksum passes about 1 in 256 random
  corruptions of a line, so a corrupted number can reach the parser: 999.999 m over 0.1 s would otherwise
  be 9999.99 m/s, a 1 us interval 1e306 m/s. The DVL-75 envelope is <= 8 kn (4.1 m/s) and its pings come
  at 5-20 Hz (docs/devices.md §1.1).
- ``$DVEXT`` (docs/devices.md §1.3.2, §1.5):
  - quaternion (w, x, y, z) = FLU body in ENU, neutral bow east: already REP-103; reordered to
    (x, y, z, w) and normalised (6 printed decimals). Taken as the vehicle's orientation, as the
    emulator does [UNVERIFIED: the vendor text says "relative to sensor head"; identical for the
    default mounting (0, 0, 0)]. No accuracy is documented: orientation covariance unknown (-1).
  - ``altitude`` is the distance along the sensor axis; ``Dvl.altitude_m`` is its vertical component
    over a flat bottom, ``altitude * cos(roll) * cos(pitch)`` (DVEXT vehicle-frame Euler angles), NaN
    when unlocked or not positive.
  - beam velocities: the DVL's sign is + approaching (the only documented sign, Tracker-650 [D16],
    docs/devices.md §1.3.4; [UNVERIFIED for the DVL-75]); ``hindrax_msgs/Dvl`` wants + away from the
    transducer, so the sign is flipped. Beams without lock report NaN range and velocity."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional, Sequence, Tuple

import numpy as np

from hindrax_common.base.frames import frd_to_flu
from .protocol import DvlExtended, DvlPositionDelta

__all__ = ["DvlReport", "DvlReportBuilder", "UNKNOWN_COVARIANCE_3X3", "altitude_range_m"]

#: Row-major 3x3 "unknown" covariance of hindrax_msgs/Dvl and sensor_msgs (element 0 = -1).
UNKNOWN_COVARIANCE_3X3: Tuple[float, ...] = (-1.0,) + (0.0,) * 8
_NAN3 = (math.nan, math.nan, math.nan)
#: 6x6 twist covariance, every element unknown (-1 on the diagonal)
_UNKNOWN_TWIST = tuple(float(x) for x in (-np.eye(6)).ravel())


@dataclass(frozen=True)
class DvlReport:
    """Content of one ``hindrax_msgs/Dvl`` message (base_link FLU, SI units).

    Attributes:
        device_time_ns: DVL clock (``tu``) at the time of validity of the velocity (middle of the
            ``$DVPDL`` interval), ns since DVL boot; None for a report built from ``$DVEXT`` alone.
        velocity_valid: see the module docstring.
        velocity_flu_m_s: (3,) base_link velocity over the bottom, m/s (NaN when not valid).
        velocity_covariance: 9 floats, row-major (m/s)^2; ``[-1, 0...]`` when not valid.
        twist_covariance: 36 floats, row-major, for TwistWithCovariance: linear block velocity_std^2 * I,
            angular block -1 on the diagonal (not measured by this message), 0 elsewhere.
        delta_position_flu_m: (3,) base_link displacement over ``delta_time_s``, m (NaN when not valid).
        delta_time_s: ``dtu`` in s (NaN without ``$DVPDL``).
        confidence_pct: ``$DVPDL`` confidence, 0..100 % (0 without ``$DVPDL``).
        bottom_lock: ``$DVEXT`` lock flag (fresh), else confidence > 0.
        altitude_m: vertical altitude over the bottom, m, NaN when unknown.
        beam_range_m, beam_velocity_m_s: (4,) per beam A port, B stern, C starboard, D bow; NaN without lock;
            velocity + away from the transducer.
        beam_lock: (4,) per-beam lock.
        orientation_xyzw: (4,) base_link in ENU, (0, 0, 0, 0) when no attitude.
        orientation_covariance: 9 floats, ``[-1, 0...]`` (unknown).
        rejection: why a report with confidence > 0 failed a plausibility gate ("" when it passed or
            was never a candidate)."""

    device_time_ns: Optional[int]
    velocity_valid: bool
    velocity_flu_m_s: Tuple[float, float, float]
    velocity_covariance: Tuple[float, ...]
    twist_covariance: Tuple[float, ...]
    delta_position_flu_m: Tuple[float, float, float]
    delta_time_s: float
    confidence_pct: float
    bottom_lock: bool
    altitude_m: float
    beam_range_m: Tuple[float, float, float, float]
    beam_velocity_m_s: Tuple[float, float, float, float]
    beam_lock: Tuple[bool, bool, bool, bool]
    orientation_xyzw: Tuple[float, float, float, float]
    orientation_covariance: Tuple[float, ...] = field(default=UNKNOWN_COVARIANCE_3X3)
    rejection: str = ""


def altitude_range_m(ext: DvlExtended) -> float:
    """Value for the ``dvl/altitude`` sensor_msgs/Range: the ``$DVEXT`` altitude along the sensor axis, m,
    when locked and positive; ``+inf`` otherwise (REP-117: no detection)."""
    if ext.locked and ext.altitude_m > 0.0:
        return float(ext.altitude_m)
    return math.inf


class DvlReportBuilder:
    """Builds :class:`DvlReport` from DVL records (see the module docstring).

    Args:
        position_frd_m: (3,) DVL position relative to the CG in FRD, m (``sensors.dvl75.position_frd_m``).
        velocity_std_m_s: 1-sigma velocity error per axis, m/s (``sensors.dvl75.velocity_std_m_s``).
        max_extended_age_s: a ``$DVEXT`` older than this (receive time) is not used, s.
        max_speed_m_s: speed gate, m/s (``sensors.dvl75.max_speed_m_s``); None: only finiteness.
        min_interval_s, max_interval_s: ``dtu`` gate, s (``sensors.dvl75.min/max_interval_s``); None: off.
        max_angular_rate_rad_s: gate on |delta_theta| / dtu, rad/s (``sensors.dvl75.max_angular_rate_rad_s``);
            None: only finiteness. The speed gate applies to the lever-arm-corrected velocity (the one published):
            a wild attitude delta over a small displacement would otherwise pass as a huge CG velocity.
    Raises ``ValueError``: position not 3 finite numbers, negative std or age, non-positive gate."""

    def __init__(self, position_frd_m: Sequence[float] = (0.0, 0.0, 0.0), velocity_std_m_s: float = 0.02,
                 max_extended_age_s: float = 1.0, max_speed_m_s: Optional[float] = None,
                 min_interval_s: Optional[float] = None, max_interval_s: Optional[float] = None,
                 max_angular_rate_rad_s: Optional[float] = None) -> None:
        r = np.asarray(position_frd_m, dtype=float)
        if r.shape != (3,) or not np.all(np.isfinite(r)):
            raise ValueError(f"position_frd_m must be 3 finite numbers, got {position_frd_m!r}")
        if not velocity_std_m_s >= 0 or not max_extended_age_s >= 0:
            raise ValueError("velocity_std_m_s and max_extended_age_s must be >= 0")
        for name, gate in (("max_speed_m_s", max_speed_m_s), ("min_interval_s", min_interval_s),
                           ("max_interval_s", max_interval_s), ("max_angular_rate_rad_s", max_angular_rate_rad_s)):
            if gate is not None and not gate > 0:
                raise ValueError(f"{name} must be > 0, got {gate!r}")
        self.max_speed_m_s = None if max_speed_m_s is None else float(max_speed_m_s)
        self.min_interval_s = None if min_interval_s is None else float(min_interval_s)
        self.max_interval_s = None if max_interval_s is None else float(max_interval_s)
        self.max_angular_rate_rad_s = None if max_angular_rate_rad_s is None else float(max_angular_rate_rad_s)
        self.position_frd_m = r
        self._r = tuple(float(x) for x in r)
        self.velocity_std_m_s = float(velocity_std_m_s)
        self.max_extended_age_ns = int(max_extended_age_s * 1e9)
        self._ext: Optional[DvlExtended] = None
        self._ext_receive_ns = 0
        var = self.velocity_std_m_s ** 2
        self._vel_cov = tuple(float(x) for x in (np.eye(3) * var).ravel())
        twist = np.zeros((6, 6))
        twist[:3, :3] = np.eye(3) * var
        twist[3:, 3:] = -np.eye(3)
        self._twist_cov = tuple(float(x) for x in twist.ravel())

    # -- inputs
    def update_extended(self, ext: DvlExtended, receive_ns: int) -> None:
        """Remember the latest ``$DVEXT`` and its receive time (ns)."""
        self._ext = ext
        self._ext_receive_ns = int(receive_ns)

    def fresh_extended(self, now_ns: int) -> Optional[DvlExtended]:
        """The latest ``$DVEXT`` if received within ``max_extended_age_s`` of ``now_ns``, else None."""
        if self._ext is None or int(now_ns) - self._ext_receive_ns > self.max_extended_age_ns:
            return None
        return self._ext

    # -- outputs
    def plausibility(self, pdl: DvlPositionDelta) -> str:
        """Why ``pdl`` (confidence > 0, dtu > 0) is implausible, or "" (see the module docstring)."""
        dt = pdl.delta_time_s
        if self.min_interval_s is not None and dt < self.min_interval_s:
            return f"dtu {dt * 1e3:.3f} ms below {self.min_interval_s * 1e3:g} ms"
        if self.max_interval_s is not None and dt > self.max_interval_s:
            return f"dtu {dt:.3f} s above {self.max_interval_s:g} s"
        rate = math.hypot(pdl.delta_roll_rad, pdl.delta_pitch_rad, pdl.delta_yaw_rad) / dt
        if not math.isfinite(rate):
            return "angular rate not finite"
        if self.max_angular_rate_rad_s is not None and rate > self.max_angular_rate_rad_s:
            return f"angular rate {rate:.3g} rad/s above {self.max_angular_rate_rad_s:g} rad/s"
        for label, dp in (("", (pdl.delta_x_m, pdl.delta_y_m, pdl.delta_z_m)),
                          (" (lever-arm corrected)", self.lever_arm_corrected(pdl))):
            speed = math.hypot(*dp) / dt  # hypot: no OverflowError at 1e300
            if not math.isfinite(speed):
                return f"velocity{label} not finite"
            if self.max_speed_m_s is not None and speed > self.max_speed_m_s:
                return f"speed{label} {speed:.3g} m/s above {self.max_speed_m_s:g} m/s"
        return ""

    def lever_arm_corrected(self, pdl: DvlPositionDelta) -> Tuple[float, float, float]:
        """delta_p_CG = delta_p_DVL - delta_theta x r, FRD, m (``r`` = ``position_frd_m``)."""
        a, b, c = pdl.delta_roll_rad, pdl.delta_pitch_rad, pdl.delta_yaw_rad
        rx, ry, rz = self._r
        # np.cross costs ~50 us on 3-vectors; written out
        return (pdl.delta_x_m - (b * rz - c * ry), pdl.delta_y_m - (c * rx - a * rz), pdl.delta_z_m - (a * ry - b * rx))

    def from_position_delta(self, pdl: DvlPositionDelta, receive_ns: int) -> DvlReport:
        """Report for one ``$DVPDL`` (received at ``receive_ns``), with the fresh ``$DVEXT`` fields."""
        ext = self.fresh_extended(receive_ns)
        dt = pdl.delta_time_s
        valid = pdl.confidence_pct > 0 and dt > 0.0 and (ext is None or ext.locked)
        rejection = self.plausibility(pdl) if pdl.confidence_pct > 0 and dt > 0.0 else ""
        valid = valid and not rejection
        if valid:
            dp_cg = self.lever_arm_corrected(pdl)
            dp_flu = frd_to_flu(dp_cg)
            delta = tuple(float(x) for x in dp_flu)
            velocity = tuple(float(x) / dt for x in dp_flu)
        else:
            delta, velocity = _NAN3, _NAN3
        device_mid_ns = round(pdl.time_since_boot_s * 1e9 - 0.5 * dt * 1e9)
        return self._report(ext, device_time_ns=device_mid_ns, valid=valid, velocity=velocity, delta=delta,
                            delta_time_s=dt, confidence=float(pdl.confidence_pct),
                            lock_fallback=pdl.confidence_pct > 0, rejection=rejection)

    def from_extended(self, ext: DvlExtended) -> DvlReport:
        """Report built from a ``$DVEXT`` alone (no ``$DVPDL`` stream): velocity never valid."""
        return self._report(ext, device_time_ns=None, valid=False, velocity=_NAN3, delta=_NAN3,
                            delta_time_s=math.nan, confidence=0.0, lock_fallback=False)

    @staticmethod
    def invalidated(report: DvlReport, reason: str) -> DvlReport:
        """``report`` with its velocity withdrawn (NaN, not valid, covariances unknown) for ``reason``
        (e.g. a stuck device): everything else (attitude, altitude, beams) is kept."""
        return replace(report, velocity_valid=False, velocity_flu_m_s=_NAN3, delta_position_flu_m=_NAN3,
                       velocity_covariance=UNKNOWN_COVARIANCE_3X3, twist_covariance=_UNKNOWN_TWIST,
                       rejection=report.rejection or reason)

    def _report(self, ext: Optional[DvlExtended], *, device_time_ns, valid, velocity, delta, delta_time_s,
                confidence, lock_fallback, rejection: str = "") -> DvlReport:
        if ext is not None:
            lock = ext.locked
            altitude = (ext.altitude_m * math.cos(ext.roll_rad) * math.cos(ext.pitch_rad)
                        if ext.locked and ext.altitude_m > 0.0 else math.nan)
            beam_lock = tuple(bool(b) for b in ext.beam_locked)
            ranges = tuple(float(r) if ok else math.nan for r, ok in zip(ext.beam_range_m, beam_lock))
            beam_vel = tuple(-float(v) if ok else math.nan for v, ok in zip(ext.beam_velocity_m_s, beam_lock))
            orientation = _normalised_xyzw(ext.orientation_wxyz)
        else:
            lock = bool(lock_fallback)
            altitude = math.nan
            beam_lock = (False,) * 4
            ranges = beam_vel = (math.nan,) * 4
            orientation = (0.0, 0.0, 0.0, 0.0)
        return DvlReport(
            device_time_ns=device_time_ns, velocity_valid=bool(valid), velocity_flu_m_s=velocity,
            velocity_covariance=self._vel_cov if valid else UNKNOWN_COVARIANCE_3X3,
            twist_covariance=self._twist_cov if valid else _UNKNOWN_TWIST,
            delta_position_flu_m=delta,
            delta_time_s=float(delta_time_s), confidence_pct=confidence, bottom_lock=bool(lock),
            altitude_m=float(altitude), beam_range_m=ranges, beam_velocity_m_s=beam_vel,  # type: ignore[arg-type]
            beam_lock=beam_lock, orientation_xyzw=orientation, rejection=rejection)  # type: ignore[arg-type]


def _normalised_xyzw(wxyz: Sequence[float]) -> Tuple[float, float, float, float]:
    w, x, y, z = (float(v) for v in wxyz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(n) or abs(n - 1.0) > 0.1:
        return (0.0, 0.0, 0.0, 0.0)  # not a rotation: report "no attitude"
    return (x / n, y / n, z / n, w / n)
