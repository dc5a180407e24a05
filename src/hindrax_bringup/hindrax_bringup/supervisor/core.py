"""Safety supervisor, pure logic (no ROS, no clocks): is the vehicle inside its safe envelope?

The supervisor is the last line of defence after the identification's own limits (``limits.*``, which abort a
manoeuvre): it watches the sensors and, on a breach, the node disarms the ESC output (docs/architecture.md §8).
Checks, all only while the ESC is armed (a vehicle on the bench or at the surface, disarmed, trips nothing):

* **sensor rates**: ALIVE messages per second of each watched sensor over the last ``supervisor.rate_window_s``
  at least ``supervisor.min_rate.<sensor>_hz`` (0 = not watched, with a reason in
  ``supervisor.rate_check_disabled.<sensor>``), checked once armed for one window. A sensor is alive only while it
  delivers valid, finite, fresh, changing data: a DVL report without a valid velocity, a NaN or infinite depth, a
  NaN or ``+inf`` altitude (REP-117 "no detection") do not count, nor does
  - a **stale** sample: its header stamp more than ``supervisor.max_sample_age_s`` from the time it is taken (older,
    or as far in the future; a zero stamp is never set: stale), e.g. a replay or a driver that re-sends a buffer,
  - a **frozen** stream: a sample bit-identical (header stamp aside) to the ones before it for longer than
    ``supervisor.max_identical_s``: the sensors' noise (docs/devices.md) changes the last bits of every reading
    within a few samples, so a longer run is a driver or device that repeats itself, not a still vehicle;
  such samples are counted per sensor (:attr:`SupervisorCore.not_alive`, in the status) and the rate trip names why;
* **data quality**: a NaN or infinite depth trips at once; an altitude of ``-inf`` (REP-117: closer than the
  sonar's minimum range) trips at once; no valid DVL velocity for ``supervisor.max_invalid_dvl_s`` while armed
  trips (where the DVL rate is watched) and the cage's dead reckoning stops meanwhile;
* **depth** (pressure port, m, positive down) at most ``supervisor.max_depth_m``;
* **altitude** (altimeter, m) at least ``supervisor.min_altitude_m``;
* **attitude**: |roll| <= ``supervisor.max_roll_rad``, |pitch| <= ``supervisor.max_pitch_rad`` (DVL attitude,
  Fossen ZYX Euler angles of body FRD in NED). A DVL report without attitude (no ``$DVEXT``: the driver's all-zero
  quaternion) is invalid attitude, never level: while the DVL's attitude is missing or older than
  ``max_sample_age_s``, roll and pitch come from the IMU's accelerometer (gravity's direction,
  :func:`tilt_from_specific_force`, a quasi-static estimate), and with neither for ``supervisor.reaction_time_s``
  while armed the supervisor trips (only where the DVL or the IMU is watched, ``min_rate`` > 0);
* **cage**: the dead-reckoned horizontal position inside the pool box (``pool.length_m`` north x
  ``pool.width_m`` east, origin at the pool corner) shrunk by ``supervisor.cage_margin_m`` on every side;
* **run time**: armed for at most ``supervisor.max_run_time_s``;
* **ROS time standing still** for ``clock_stall_timeout_s`` of steady time (the node's measure,
  :meth:`SupervisorCore.stall_check`): every check on ROS time would be blind;
* **operator e-stop** and **abort requests** from other nodes (:meth:`SupervisorCore.trip`).

Position (kept simple, and said so): DVL dead reckoning from ``pool.start_position_ned_m`` (where the operator
puts the vehicle in the water), north/east += R(yaw) [u, v] dt with the DVL's body velocity (FRD, m/s) and its
yaw; integrated only over valid velocities and gaps under 1 s. It drifts (a few % of the distance travelled with
the DVL's scale error, docs/devices.md §1): ``cage_margin_m`` and the wider identification box absorb that; the
identification's own, better position estimate aborts a manoeuvre first.

A breach latches: :attr:`SupervisorCore.tripped` keeps the first reason until :meth:`SupervisorCore.reset`, and
the node disarms again whenever the ESC reports armed while tripped."""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["DISARM_RETRY_S", "SENSORS", "SupervisorLimits", "SupervisorCore", "tilt_from_specific_force"]

#: Watched sensors, with the topic each one is measured on (the node's subscriptions).
SENSORS: dict[str, str] = {"dvl": "dvl/data", "altimeter": "ping/altitude", "pressure": "pressure/depth",
                           "imu": "imu/data_raw"}
#: A disarm request is repeated this often while the ESC still reports armed after a breach, s (steady clock).
DISARM_RETRY_S = 0.2
#: Longest gap between two DVL velocities that is integrated, s.
MAX_DEAD_RECKONING_GAP_S = 1.0
#: An accelerometer reading whose magnitude is outside this fraction of g is no tilt reference (the vehicle is
#: accelerating hard, or the sample is zero/garbage), -.
TILT_ACCEL_TOLERANCE = 0.3


def tilt_from_specific_force(f_frd_m_s2: np.ndarray, g_m_s2: float = 9.81) -> tuple[float, float] | None:
    """Roll and pitch (rad, Fossen ZYX of body FRD in NED) from an accelerometer's specific force at rest.

    f_frd_m_s2: (3,) specific force in body FRD, m/s^2 (a level vehicle at rest reads (0, 0, -g)). At rest
    f = R_nb^T (0, 0, -g) = -g (-sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)) ([Fossen2011] §2.1, R of
    eq. 2.18, gravity in NED), so phi = atan2(-f_y, -f_z) and theta = atan2(f_x, sqrt(f_y^2 + f_z^2)). Returns None
    when |f| is not within TILT_ACCEL_TOLERANCE of g (accelerating, or not a reading) or not finite."""
    f = np.asarray(f_frd_m_s2, dtype=float)
    if f.shape != (3,) or not np.all(np.isfinite(f)):
        return None
    norm = float(np.linalg.norm(f))
    if abs(norm - g_m_s2) > TILT_ACCEL_TOLERANCE * g_m_s2:
        return None
    return math.atan2(-f[1], -f[2]), math.atan2(f[0], math.hypot(f[1], f[2]))


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
    max_sample_age_s: float = math.inf
    max_identical_s: float = math.inf
    reaction_time_s: float = math.inf
    clock_stall_timeout_s: float = math.inf

    @classmethod
    def from_config(cls, cfg: Any, clock_stall_timeout_s: float | None = None) -> "SupervisorLimits":
        """From a :class:`~hindrax_common.config.VehicleConfig` (``supervisor.*`` and ``pool.*`` keys) and the node
        parameter ``clock_stall_timeout_s`` (s; None: its default ``supervisor.rate_window_s``)."""
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
                   start_heading_rad=float(g("pool.start_heading_rad")),
                   max_sample_age_s=float(g("supervisor.max_sample_age_s")),
                   max_identical_s=float(g("supervisor.max_identical_s")),
                   reaction_time_s=float(g("supervisor.reaction_time_s")),
                   clock_stall_timeout_s=float(clock_stall_timeout_s or g("supervisor.rate_window_s")))


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
    #: time (same base as ``t_s``) of the last DVL attitude / IMU tilt taken, None before any
    dvl_attitude_t: float | None = None
    imu_tilt_t: float | None = None
    #: per sensor: samples not alive (stale, frozen) and why the last one was not
    not_alive: dict = field(default_factory=dict)
    not_alive_reason: dict = field(default_factory=dict)
    _identical: dict = field(default_factory=dict)
    #: steady time (s) of the last disarm request (:meth:`disarm_due`)
    disarm_asked_s: float = -math.inf

    def __post_init__(self) -> None:
        self.position_ne = np.array(self.limits.start_position_ne, dtype=float)
        self.yaw_rad = self.limits.start_heading_rad
        self._stamps = {s: collections.deque() for s in SENSORS}
        self.not_alive = {s: 0 for s in SENSORS}
        self.not_alive_reason = {s: "" for s in SENSORS}

    # ------------------------------------------------------------------ state
    def set_armed(self, t_s: float, armed: bool) -> str:
        """The ESC's armed flag (``esc/output_state``). Arming starts the run-time and rate grace clocks."""
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

    def disarm_due(self, steady_s: float, breach: bool = False) -> bool:
        """Is a disarm request to the ESC due at steady time ``steady_s`` (s)? At a new breach (``breach``) at once,
        armed or not; then while tripped and the ESC reports armed every :data:`DISARM_RETRY_S`, for a lost request
        or a re-arm. Steady time: a ROS time that steps back or stands still must not hold the repeats off."""
        if not breach and not (self.tripped and self.armed and steady_s - self.disarm_asked_s >= DISARM_RETRY_S):
            return False
        self.disarm_asked_s = steady_s
        return True

    def _breach(self, reason: str) -> str:
        if not self.armed:
            return ""
        return self.trip(reason)

    # ------------------------------------------------------------------ samples
    def alive(self, sensor: str, t_s: float, stamp_s: float | None = None, fingerprint: Any = None) -> bool:
        """Is this sample of ``sensor`` alive (module docstring)? ``stamp_s``: its header stamp in the time base
        of ``t_s`` (None: not checked); ``fingerprint``: its content without the stamp, compared for bit-identical
        repeats (bytes or a tuple of floats; None: not checked). A sample that is not is counted in
        :attr:`not_alive` with the reason in :attr:`not_alive_reason`."""
        reason = ""
        if stamp_s is not None:
            age = t_s - stamp_s
            if stamp_s == 0.0 or abs(age) > self.limits.max_sample_age_s:
                reason = (f"stamped {age:.1f} s {'old' if age >= 0 else 'ahead'}, beyond supervisor.max_sample_age_s "
                          f"{self.limits.max_sample_age_s:g}" if stamp_s != 0.0 else "stamp 0 (never set)")
        if fingerprint is not None:
            # (content, start of its run, last sample): a run is broken by a change, or by a gap longer than
            # max_identical_s (two samples that far apart say nothing about the stream in between)
            last = self._identical.get(sensor)
            if last is not None and last[0] == fingerprint and t_s - last[2] <= self.limits.max_identical_s:
                self._identical[sensor] = (fingerprint, last[1], t_s)
                if t_s - last[1] > self.limits.max_identical_s and not reason:
                    reason = (f"bit-identical for {t_s - last[1]:.1f} s, beyond supervisor.max_identical_s "
                              f"{self.limits.max_identical_s:g} (frozen)")
            else:
                self._identical[sensor] = (fingerprint, t_s, t_s)
        if reason:
            self.not_alive[sensor] += 1
            self.not_alive_reason[sensor] = reason
            return False
        return True

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
        for name in ("armed_since_s", "_last_velocity_t", "last_valid_dvl_t", "dvl_attitude_t", "imu_tilt_t"):
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, value + step_s)
        self._identical = {k: (fp, t0 + step_s, t1 + step_s) for k, (fp, t0, t1) in self._identical.items()}

    def on_depth(self, t_s: float, depth_m: float, stamp_s: float | None = None) -> str:
        """One ``pressure/depth`` sample: depth (m, positive down) taken at ``t_s``, header stamp ``stamp_s``."""
        if not math.isfinite(depth_m):
            return self._breach(f"depth {depth_m} is not finite (pressure/depth): the depth limit is blind")
        if not self.alive("pressure", t_s, stamp_s, (float(depth_m),)):
            return ""
        self.on_message("pressure", t_s)
        self.depth_m = float(depth_m)
        if depth_m > self.limits.max_depth_m:
            return self._breach(f"depth {depth_m:.2f} m beyond supervisor.max_depth_m {self.limits.max_depth_m:g}")
        return ""

    def on_altitude(self, t_s: float, altitude_m: float, stamp_s: float | None = None) -> str:
        """One ``ping/altitude`` range (m; REP-117 infinities) taken at ``t_s``, header stamp ``stamp_s``."""
        if stamp_s is not None and not self.alive("altimeter", t_s, stamp_s):
            return ""  # a stale -inf is no reading either
        if altitude_m == -math.inf:
            return self._breach(f"altitude -inf (REP-117: closer than the altimeter's minimum range), below "
                                f"supervisor.min_altitude_m {self.limits.min_altitude_m:g}")
        if not math.isfinite(altitude_m):
            return ""  # NaN / +inf (no detection): not a valid reading, not counted toward the altimeter's rate
        if not self.alive("altimeter", t_s, None, (float(altitude_m),)):
            return ""
        self.on_message("altimeter", t_s)
        self.altitude_m = float(altitude_m)
        if altitude_m < self.limits.min_altitude_m:
            return self._breach(f"altitude {altitude_m:.2f} m below supervisor.min_altitude_m "
                                f"{self.limits.min_altitude_m:g}")
        return ""

    def on_attitude(self, roll_rad: float, pitch_rad: float, yaw_rad: float, t_s: float | None = None) -> str:
        """DVL attitude (rad, Fossen ZYX of body FRD in NED) of an alive report taken at ``t_s``; counted with the
        DVL's message by :meth:`on_dvl`. Non-finite roll or pitch is no attitude (not level)."""
        if math.isfinite(yaw_rad):
            self.yaw_rad = float(yaw_rad)
        if t_s is not None and math.isfinite(roll_rad) and math.isfinite(pitch_rad):
            self.dvl_attitude_t = t_s
        return self._check_attitude(roll_rad, pitch_rad, "DVL")

    def on_imu(self, t_s: float, stamp_s: float | None = None, fingerprint: Any = None,
               specific_force_frd_m_s2: np.ndarray | None = None) -> str:
        """One ``imu/data_raw`` sample taken at ``t_s`` (header stamp ``stamp_s``, content ``fingerprint``): counted
        when alive; its specific force (3,) body FRD m/s^2, when given, is the tilt reference used for the roll and
        pitch limits while the DVL gives no fresh attitude."""
        if not self.alive("imu", t_s, stamp_s, fingerprint):
            return ""
        self.on_message("imu", t_s)
        if specific_force_frd_m_s2 is None:
            return ""
        tilt = tilt_from_specific_force(specific_force_frd_m_s2)
        if tilt is None:
            return ""
        self.imu_tilt_t = t_s
        if self._dvl_attitude_fresh(t_s):
            return ""
        return self._check_attitude(tilt[0], tilt[1], "IMU accelerometer (no fresh DVL attitude)")

    def _dvl_attitude_fresh(self, t_s: float) -> bool:
        return self.dvl_attitude_t is not None and t_s - self.dvl_attitude_t <= self.limits.max_sample_age_s

    def _check_attitude(self, roll_rad: float, pitch_rad: float, source: str) -> str:
        suffix = "" if source == "DVL" else f" ({source})"
        if math.isfinite(roll_rad):
            self.roll_rad = float(roll_rad)
            if abs(roll_rad) > self.limits.max_roll_rad:
                return self._breach(f"roll {roll_rad:.2f} rad beyond supervisor.max_roll_rad "
                                    f"{self.limits.max_roll_rad:g}{suffix}")
        if math.isfinite(pitch_rad):
            self.pitch_rad = float(pitch_rad)
            if abs(pitch_rad) > self.limits.max_pitch_rad:
                return self._breach(f"pitch {pitch_rad:.2f} rad beyond supervisor.max_pitch_rad "
                                    f"{self.limits.max_pitch_rad:g}{suffix}")
        return ""

    def on_dvl(self, t_s: float, velocity_frd_m_s: np.ndarray | None, stamp_s: float | None = None,
               attitude_rpy_rad: tuple[float, float, float] | None = None, fingerprint: Any = None) -> str:
        """One DVL report taken at ``t_s`` (header stamp ``stamp_s``): its attitude (roll, pitch, yaw rad, Fossen
        ZYX; None: the report has none) to :meth:`on_attitude`; counts it, dead-reckons with a valid body velocity
        (3,) FRD m/s (None: invalid), and checks the cage. A stale or frozen report (its stamp; ``fingerprint``, the
        report's content: velocity alone is quantised to 1 cm/s at 10 Hz and repeats at rest, the beams do not) is
        one without velocity nor attitude."""
        if not self.alive("dvl", t_s, stamp_s, fingerprint):
            velocity_frd_m_s, attitude_rpy_rad = None, None
        if attitude_rpy_rad is not None:
            reason = self.on_attitude(*attitude_rpy_rad, t_s=t_s)
            if reason:
                return reason
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
    def stall_check(self, stalled_for_s: float) -> str:
        """ROS time has stood still for ``stalled_for_s`` of steady time (s; the node's
        :class:`~hindrax_common.node_support.liveness.ClockStepMonitor`): armed and beyond
        ``limits.clock_stall_timeout_s`` is a breach, for every check on ROS time is blind. Returns a new breach."""
        if stalled_for_s <= self.limits.clock_stall_timeout_s:
            return ""
        return self._breach(f"ROS time stalled for {stalled_for_s:.1f} s while armed: the supervisor's ROS-time "
                            "checks are blind")

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
        watched = self.limits.min_rate_hz
        if (watched.get("dvl", 0.0) > 0.0 or watched.get("imu", 0.0) > 0.0) and not self._dvl_attitude_fresh(t_s):
            tilt_t = self.imu_tilt_t if self.imu_tilt_t is not None else -math.inf
            latest = max(tilt_t, self.dvl_attitude_t if self.dvl_attitude_t is not None else -math.inf)
            since = max(latest, self.armed_since_s)
            if t_s - tilt_t > self.limits.max_sample_age_s and t_s - since > self.limits.reaction_time_s:
                return self._breach(f"no attitude for {t_s - since:.1f} s (no fresh DVL attitude: $DVEXT missing, "
                                    "nor an IMU tilt), beyond supervisor.reaction_time_s "
                                    f"{self.limits.reaction_time_s:g}: the roll and pitch limits are blind")
        if armed_for >= self.limits.rate_window_s:
            for sensor, minimum in self.limits.min_rate_hz.items():
                if minimum > 0.0:
                    rate = self.rate_hz(sensor, t_s)
                    if rate < minimum:
                        why = self.not_alive_reason[sensor]
                        return self._breach(f"{SENSORS[sensor]} at {rate:.1f} Hz, below "
                                            f"supervisor.min_rate.{sensor}_hz {minimum:g}"
                                            + (f" (samples not alive: {why})" if why else ""))
        return ""

    def values(self, t_s: float) -> list[tuple[str, str]]:
        """Key/value pairs for the status and /diagnostics."""
        out = [("armed", str(self.armed)), ("tripped", self.tripped or "no"),
               ("depth_m", f"{self.depth_m:.2f}"), ("altitude_m", f"{self.altitude_m:.2f}"),
               ("roll_rad", f"{self.roll_rad:.3f}"), ("pitch_rad", f"{self.pitch_rad:.3f}"),
               ("position_north_m", f"{self.position_ne[0]:.2f}"), ("position_east_m", f"{self.position_ne[1]:.2f}")]
        out += [(f"rate_hz.{s}", f"{self.rate_hz(s, t_s):.1f}") for s in SENSORS]
        out += [(f"not_alive.{s}", str(n)) for s, n in self.not_alive.items() if n]
        if self.armed_since_s is not None:
            out.append(("armed_for_s", f"{t_s - self.armed_since_s:.1f}"))
        return out
