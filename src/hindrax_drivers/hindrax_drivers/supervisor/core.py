"""Safety supervisor, pure logic (no ROS, no clocks): is the vehicle inside its safe envelope?

The supervisor is the last line of defence after the identification's own limits (``limits.*``, which abort a
manoeuvre): it watches the sensors and, on a breach, the node disarms the ESC output (docs/architecture.md §8).
Checks, all only while the ESC is armed (a vehicle on the bench or at the surface, disarmed, trips nothing):

* **sensor rates**: VALID messages per second of each watched sensor over the last ``supervisor.rate_window_s``
  at least ``supervisor.min_rate.<sensor>_hz`` (0 = not watched, with a reason in
  ``supervisor.rate_check_disabled.<sensor>``), checked once armed for one window. A sensor is alive only while it
  delivers valid, finite data: a DVL report without a valid velocity, a NaN or infinite depth, a NaN or ``+inf``
  altitude (REP-117 "no detection") do not count;
* **data quality**: a NaN or infinite depth trips at once; an altitude of ``-inf`` (REP-117: closer than the
  sonar's minimum range) trips at once; no valid DVL velocity for ``supervisor.max_invalid_dvl_s`` while armed
  trips (where the DVL rate is watched) and the cage's dead reckoning stops meanwhile;
* **depth** (pressure port, m, positive down) at most ``supervisor.max_depth_m``;
* **altitude** (altimeter, m) at least ``supervisor.min_altitude_m``;
* **attitude**: |roll| <= ``supervisor.max_roll_rad``, |pitch| <= ``supervisor.max_pitch_rad`` (DVL attitude,
  Fossen ZYX Euler angles of body FRD in NED);
* **cage**: the dead-reckoned horizontal position inside the pool box (``pool.length_m`` north x
  ``pool.width_m`` east, origin at the pool corner) shrunk by ``supervisor.cage_margin_m`` on every side;
* **run time**: armed for at most ``supervisor.max_run_time_s``;
* **operator e-stop** and **abort requests** from other nodes (:meth:`SupervisorCore.trip`).

Position (kept simple, and said so): DVL dead reckoning from ``pool.start_position_ned_m`` (where the operator
puts the vehicle in the water), north/east += R(yaw) [u, v] dt with the DVL's body velocity (FRD, m/s) and its
yaw; integrated only over valid velocities and gaps under 1 s. It drifts (a few % of the distance travelled with
the DVL's scale error, docs/devices.md §1): ``cage_margin_m`` and the wider identification box absorb that; the
identification's own, better position estimate aborts a manoeuvre first.

A breach latches: :attr:`SupervisorCore.tripped` keeps the first reason until :meth:`SupervisorCore.reset`, and
the node disarms again whenever the ESC reports armed while tripped.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["SENSORS", "SupervisorLimits", "SupervisorCore"]

#: Watched sensors, with the topic each one is measured on (the node's subscriptions).
SENSORS: dict[str, str] = {"dvl": "dvl/data", "altimeter": "ping/altitude", "pressure": "pressure/depth",
                           "imu": "imu/data_raw"}
#: Longest gap between two DVL velocities that is integrated, s.
MAX_DEAD_RECKONING_GAP_S = 1.0


@dataclass(frozen=True)
class SupervisorLimits:
    """The envelope (SI units; see the module docstring). ``cage_min_ne``/``cage_max_ne``: (2,) north/east, m."""

    min_rate_hz: Mapping[str, float]
    rate_window_s: float
    max_depth_m: float
    min_altitude_m: float
    max_roll_rad: float
    max_pitch_rad: float
    cage_min_ne: tuple[float, float]
    cage_max_ne: tuple[float, float]
    max_run_time_s: float
    max_invalid_dvl_s: float = 2.0
    start_position_ne: tuple[float, float] = (0.0, 0.0)
    start_heading_rad: float = 0.0

    @classmethod
    def from_config(cls, cfg: Any) -> "SupervisorLimits":
        """From a :class:`~hindrax_drivers.config.VehicleConfig` (``supervisor.*`` and ``pool.*`` keys)."""
        g = cfg.get
        margin = float(g("supervisor.cage_margin_m"))
        start = g("pool.start_position_ned_m")
        return cls(min_rate_hz={s: float(g(f"supervisor.min_rate.{s}_hz")) for s in SENSORS},
                   rate_window_s=float(g("supervisor.rate_window_s")), max_depth_m=float(g("supervisor.max_depth_m")),
                   min_altitude_m=float(g("supervisor.min_altitude_m")),
                   max_roll_rad=float(g("supervisor.max_roll_rad")), max_pitch_rad=float(g("supervisor.max_pitch_rad")),
                   cage_min_ne=(margin, margin),
                   cage_max_ne=(float(g("pool.length_m")) - margin, float(g("pool.width_m")) - margin),
                   max_run_time_s=float(g("supervisor.max_run_time_s")),
                   max_invalid_dvl_s=float(g("supervisor.max_invalid_dvl_s")),
                   start_position_ne=(float(start[0]), float(start[1])),
                   start_heading_rad=float(g("pool.start_heading_rad")))


@dataclass
class SupervisorCore:
    """Envelope checks (module docstring). Feed it samples with their time ``t_s`` (any monotonic time base,
    seconds; the node uses ROS time) and call :meth:`check` periodically. Every ``on_*`` method and
    :meth:`check` return the reason of a NEW breach ('' otherwise); :attr:`tripped` holds the latched reason."""

    limits: SupervisorLimits
    armed: bool = False
    tripped: str = ""
    armed_since_s: float | None = None
    depth_m: float = math.nan
    altitude_m: float = math.nan
    roll_rad: float = math.nan
    pitch_rad: float = math.nan
    yaw_rad: float = math.nan
    position_ne: np.ndarray = field(default_factory=lambda: np.zeros(2))
    _stamps: dict = field(default_factory=dict)
    _last_velocity_t: float | None = None
    last_valid_dvl_t: float | None = None

    def __post_init__(self) -> None:
        self.position_ne = np.array(self.limits.start_position_ne, dtype=float)
        self.yaw_rad = self.limits.start_heading_rad
        self._stamps = {s: collections.deque() for s in SENSORS}

    # ------------------------------------------------------------------ state
    def set_armed(self, t_s: float, armed: bool) -> str:
        """The ESC's armed flag (``thrusters/pulse_width``). Arming starts the run-time and rate grace clocks."""
        if armed and not self.armed:
            self.armed_since_s = t_s
        if not armed:
            self.armed_since_s = None
        self.armed = bool(armed)
        return ""

    def trip(self, reason: str) -> str:
        """Latch a breach with ``reason`` (operator e-stop, another node's abort). Returns it if it is new."""
        if self.tripped:
            return ""
        self.tripped = reason or "tripped"
        return self.tripped

    def reset(self) -> None:
        """Clear the latched breach (operator, after the cause is understood)."""
        self.tripped = ""

    def _breach(self, reason: str) -> str:
        if not self.armed:
            return ""
        return self.trip(reason)

    # ------------------------------------------------------------------ samples
    def on_message(self, sensor: str, t_s: float) -> None:
        """Count one message of ``sensor`` (a key of :data:`SENSORS`) for its rate."""
        dq = self._stamps[sensor]
        dq.append(t_s)
        while dq and dq[0] < t_s - self.limits.rate_window_s:
            dq.popleft()

    def shift_time(self, step_s: float) -> None:
        """The node's time base stepped by ``step_s`` (e.g. -100 s: /clock restarted): move every stored time by
        it, so that rate windows, run time and the invalid-DVL time continue without a blind interval."""
        for dq in self._stamps.values():
            for i in range(len(dq)):
                dq[i] += step_s
        for name in ("armed_since_s", "_last_velocity_t", "last_valid_dvl_t"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, value + step_s)

    def on_depth(self, t_s: float, depth_m: float) -> str:
        if not math.isfinite(depth_m):
            return self._breach(f"depth {depth_m} is not finite (pressure/depth): the depth limit is blind")
        self.on_message("pressure", t_s)
        if math.isfinite(depth_m):
            self.depth_m = float(depth_m)
            if depth_m > self.limits.max_depth_m:
                return self._breach(f"depth {depth_m:.2f} m beyond supervisor.max_depth_m {self.limits.max_depth_m:g}")
        return ""

    def on_altitude(self, t_s: float, altitude_m: float) -> str:
        if altitude_m == -math.inf:
            return self._breach(f"altitude -inf (REP-117: closer than the altimeter's minimum range), below "
                                f"supervisor.min_altitude_m {self.limits.min_altitude_m:g}")
        if not math.isfinite(altitude_m):
            return ""  # NaN / +inf (no detection): not a valid reading, not counted toward the altimeter's rate
        self.on_message("altimeter", t_s)
        if math.isfinite(altitude_m):
            self.altitude_m = float(altitude_m)
            if altitude_m < self.limits.min_altitude_m:
                return self._breach(f"altitude {altitude_m:.2f} m below supervisor.min_altitude_m "
                                    f"{self.limits.min_altitude_m:g}")
        return ""

    def on_attitude(self, roll_rad: float, pitch_rad: float, yaw_rad: float) -> str:
        """DVL attitude (rad, Fossen ZYX of body FRD in NED); counted with the DVL's message by :meth:`on_dvl`."""
        if math.isfinite(yaw_rad):
            self.yaw_rad = float(yaw_rad)
        if math.isfinite(roll_rad):
            self.roll_rad = float(roll_rad)
            if abs(roll_rad) > self.limits.max_roll_rad:
                return self._breach(f"roll {roll_rad:.2f} rad beyond supervisor.max_roll_rad "
                                    f"{self.limits.max_roll_rad:g}")
        if math.isfinite(pitch_rad):
            self.pitch_rad = float(pitch_rad)
            if abs(pitch_rad) > self.limits.max_pitch_rad:
                return self._breach(f"pitch {pitch_rad:.2f} rad beyond supervisor.max_pitch_rad "
                                    f"{self.limits.max_pitch_rad:g}")
        return ""

    def on_dvl(self, t_s: float, velocity_frd_m_s: np.ndarray | None) -> str:
        """One DVL report: counts it, dead-reckons with a valid body velocity (3,) FRD m/s (None: invalid), and
        checks the cage."""
        if velocity_frd_m_s is None or not np.all(np.isfinite(velocity_frd_m_s)):
            self._last_velocity_t = None  # dead reckoning stops: the position is frozen, not trusted
            return ""
        self.on_message("dvl", t_s)
        self.last_valid_dvl_t = t_s
        if self._last_velocity_t is not None:
            dt = t_s - self._last_velocity_t
            if 0.0 < dt <= MAX_DEAD_RECKONING_GAP_S:
                c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
                u, v = float(velocity_frd_m_s[0]), float(velocity_frd_m_s[1])
                self.position_ne = self.position_ne + dt * np.array([c * u - s * v, s * u + c * v])
        self._last_velocity_t = t_s
        lo, hi = self.limits.cage_min_ne, self.limits.cage_max_ne
        n, e = self.position_ne
        if not (lo[0] <= n <= hi[0] and lo[1] <= e <= hi[1]):
            return self._breach(f"dead-reckoned position ({n:.2f}, {e:.2f}) m outside the cage "
                                f"north {lo[0]:g}..{hi[0]:g}, east {lo[1]:g}..{hi[1]:g} m (pool box less "
                                f"supervisor.cage_margin_m)")
        return ""

    # ------------------------------------------------------------------ periodic
    def rate_hz(self, sensor: str, t_s: float) -> float:
        """Messages per second of ``sensor`` over the window ending at ``t_s``."""
        dq = self._stamps[sensor]
        while dq and dq[0] < t_s - self.limits.rate_window_s:
            dq.popleft()
        return len(dq) / self.limits.rate_window_s

    def check(self, t_s: float) -> str:
        """Sensor rates (once armed for a whole window) and run time."""
        if not self.armed or self.armed_since_s is None:
            return ""
        armed_for = t_s - self.armed_since_s
        if armed_for > self.limits.max_run_time_s:
            return self._breach(f"armed for {armed_for:.0f} s, beyond supervisor.max_run_time_s "
                                f"{self.limits.max_run_time_s:g}")
        if self.limits.min_rate_hz.get("dvl", 0.0) > 0.0:
            # counted from the last valid velocity, or from arming if that is later
            since = max(self.last_valid_dvl_t if self.last_valid_dvl_t is not None else -math.inf, self.armed_since_s)
            if t_s - since > self.limits.max_invalid_dvl_s:
                return self._breach(f"no valid DVL velocity for {t_s - since:.1f} s, beyond "
                                    f"supervisor.max_invalid_dvl_s {self.limits.max_invalid_dvl_s:g} (dead-reckoned "
                                    "cage position frozen)")
        if armed_for >= self.limits.rate_window_s:
            for sensor, minimum in self.limits.min_rate_hz.items():
                if minimum > 0.0:
                    rate = self.rate_hz(sensor, t_s)
                    if rate < minimum:
                        return self._breach(f"{SENSORS[sensor]} at {rate:.1f} Hz, below "
                                            f"supervisor.min_rate.{sensor}_hz {minimum:g}")
        return ""

    def values(self, t_s: float) -> list[tuple[str, str]]:
        """Key/value pairs for the status and /diagnostics."""
        out = [("armed", str(self.armed)), ("tripped", self.tripped or "no"),
               ("depth_m", f"{self.depth_m:.2f}"), ("altitude_m", f"{self.altitude_m:.2f}"),
               ("roll_rad", f"{self.roll_rad:.3f}"), ("pitch_rad", f"{self.pitch_rad:.3f}"),
               ("position_north_m", f"{self.position_ne[0]:.2f}"), ("position_east_m", f"{self.position_ne[1]:.2f}")]
        out += [(f"rate_hz.{s}", f"{self.rate_hz(s, t_s):.1f}") for s in SENSORS]
        if self.armed_since_s is not None:
            out.append(("armed_for_s", f"{t_s - self.armed_since_s:.1f}"))
        return out
