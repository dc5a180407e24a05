"""The virtual pool: vehicle model + thrusters + pool + sensors, stepped at a fixed rate. No ROS.

:class:`Simulator` owns a :class:`~.model.VehicleModel`, :class:`~.thrusters.Thrusters`, a :class:`~.pool.Pool`
and a :class:`~.sensors.SensorSuite`, all built from one :class:`~hindrax_common.config.VehicleConfig`.
``step(pulse_widths_us)`` advances one integration step; identification tests drive it directly, the ROS
node (:mod:`.node`) wraps it.

Integration: classical 4th-order Runge-Kutta with the fixed step ``simulation.step_s`` (default 5 ms) on the state
``[position NED (3), quaternion xyzw (4), nu (6)]``; the quaternion is renormalised after every step. Within a step the
pulse widths and any external wrench are held; the thruster thrust follows its first-order lag exactly
(:mod:`.thrusters`), evaluated at the Runge-Kutta stage times. After the step the pool's contact constraints are applied
(:meth:`.pool.Pool.resolve`), the time advances to ``k * step_s`` (no accumulated rounding) and the sensors due at that
time are sampled. Everything is deterministic for a given configuration and seed.

Truth (:mod:`.truth`): the simulator runs on the truth configuration and applies its disturbances
(:mod:`.disturbances`): the thrust factor per thruster on the curve thrust, the ESC latency ``esc.output_latency_s`` as
a queue of written widths, the extra wrench held over each step, and the sensor disturbances
(:meth:`.sensors.SensorSuite.apply_disturbances`; the DVL latency reads a history of states kept for that long)."""
from __future__ import annotations

import math
from collections import deque
from typing import Any, Callable, Sequence

import numpy as np

from hindrax_common.base import frames
from hindrax_common.config import VehicleConfig

from .model import VehicleModel, euler_from_rotation_matrix, rotation_matrix_from_quaternion
from .pool import ContactState, Pool
from .sensors import SensorSuite, VehicleTruth
from .thrusters import PulseWidthError, Thrusters
from .truth import Truth, load_truth
from .disturbances import DisturbanceModel

__all__ = ["Simulator", "SensorListener", "PulseWidthError", "fill_odometry", "fill_wrench"]

#: Callback receiving each new sensor sample: (device name, sample dataclass).
SensorListener = Callable[[str, Any], None]


def _wrench6(wrench_frd) -> list[float]:
    """An external wrench as 6 floats; ``ValueError`` unless 6 finite numbers."""
    try:
        w = [float(x) for x in wrench_frd]
    except (TypeError, ValueError):
        w = []
    if len(w) != 6 or not all(math.isfinite(x) for x in w):
        raise ValueError(f"external_wrench_frd must be 6 finite numbers, got {wrench_frd!r}")
    return w


def fill_odometry(odom: Any, position_ned_m, quaternion_xyzw, twist_flu) -> Any:
    """Set a nav_msgs/msg/Odometry ``odom`` (frame ``odom``, ENU; child ``base_link``) from the body position (3,) NED
    m, the quaternion (4,) xyzw of FRD in NED and the twist (6,) in base_link FLU."""
    odom.header.frame_id, odom.child_frame_id = "odom", "base_link"
    p, o = odom.pose.pose.position, odom.pose.pose.orientation
    p.x, p.y, p.z = (float(v) for v in frames.ned_to_enu(position_ned_m))
    o.x, o.y, o.z, o.w = (float(v) for v in frames.quaternion_marine_to_ros(quaternion_xyzw))
    lin, ang = odom.twist.twist.linear, odom.twist.twist.angular
    lin.x, lin.y, lin.z, ang.x, ang.y, ang.z = (float(v) for v in twist_flu)
    return odom


def fill_wrench(wrench: Any, wrench_flu) -> None:
    """Set a geometry_msgs/msg/Wrench from [Fx Fy Fz Tx Ty Tz] (6,), N and N m."""
    f, tq = wrench.force, wrench.torque
    f.x, f.y, f.z, tq.x, tq.y, tq.z = (float(v) for v in wrench_flu)


class Simulator:
    """6-DOF Hindrax simulator (module docstring).

    Parameters
    ----------
    config: the vehicle configuration (every parameter comes from it).
    seed: sensor-noise seed (default ``simulation.seed``).
    step_s: integration step (default ``simulation.step_s``), s.
    sensors: True or None (all devices), False (none) or a sequence of device names (see :mod:`.sensors`).
    pool: False removes the pool (no walls, floor or free surface: a fully submerged vehicle in unbounded
        water), for model tests.
    truth: the pool's truth (:mod:`.truth`): a truth file path, a :class:`~.truth.Truth`, or None (the shipped
        ``truth/default.yaml`` fills the keys ``config`` lacks: the sensor noise, no disturbance). The simulator
        runs on ``truth.config``; ``config`` is kept as ``vehicle_config`` (what the nodes believe).

    Raises ``ValueError`` for a non-positive step or an unknown sensor device, :class:`~.truth.TruthError` for a
    bad truth file."""

    def __init__(self, config: VehicleConfig, *, seed: int | None = None, step_s: float | None = None,
                 sensors: bool | Sequence[str] | None = True, pool: bool = True, truth: Any = None) -> None:
        if not isinstance(truth, Truth):
            truth = load_truth(config, truth)
        self.truth_model: Truth = truth
        self.vehicle_config = config
        config = truth.config
        self.config = config
        self.step_s = float(config.simulation.step_s if step_s is None else step_s)
        if not (math.isfinite(self.step_s) and self.step_s > 0.0):
            raise ValueError(f"step_s must be a positive number of seconds, got {step_s!r}")
        self.seed = int(config.simulation.seed if seed is None else seed)
        self.pool: Pool | None = Pool.from_config(config) if pool else None
        self.model = VehicleModel(config, surface_fraction=self.pool.free_surface if self.pool else None)
        self.thrusters = Thrusters(config)
        if sensors is True or sensors is None:
            devices = None
        elif sensors is False:
            devices = []
        else:
            devices = list(sensors)
        self.sensors = SensorSuite(config, self.pool, self.seed, devices=devices)
        if self.pool is not None:
            self.pool.set_floor_gradient(truth.disturbances.floor.gradient)
        self.disturbances = DisturbanceModel(config, truth.disturbances, self.model, self.pool)
        self.sensors.apply_disturbances(truth.disturbances, self._delayed_state)
        self._keep_history_s = float(truth.disturbances.dvl.latency_s)
        self._listeners: list[SensorListener] = []
        self._neutral = np.full(self.thrusters.n, self.thrusters.neutral_us)
        self._lag_half = self.thrusters.lag.decay(0.5 * self.step_s)
        self._lag_full = self.thrusters.lag.decay(self.step_s)
        self.reset()

    # ------------------------------------------------------------------ set-up
    def reset(self, position_ned_m: Sequence[float] | None = None, rpy_rad: Sequence[float] | None = None,
              quaternion_xyzw: Sequence[float] | None = None, nu: Sequence[float] | None = None) -> None:
        """Start a new run at t = 0: thrusters stopped, contacts and sensor grids reset.

        position_ned_m (3,): body origin in the pool frame (default ``pool.start_position_ned_m``). Orientation:
        ``quaternion_xyzw`` (4,) or ``rpy_rad`` (3,) Fossen ZYX (default level, heading ``pool.start_heading_rad``). nu
        (6,): initial body velocity (default 0). Raises ``ValueError`` for wrong shapes or non-finite values."""
        pool = self.config.pool
        pos = np.asarray(pool.start_position_ned_m if position_ned_m is None else position_ned_m, dtype=float)
        if quaternion_xyzw is not None:
            quat = np.asarray(quaternion_xyzw, dtype=float)
        else:
            rpy = [0.0, 0.0, pool.start_heading_rad] if rpy_rad is None else rpy_rad
            quat = np.asarray(frames.quaternion_from_euler_ned(np.asarray(rpy, dtype=float)), dtype=float)
        vel = np.zeros(6) if nu is None else np.asarray(nu, dtype=float)
        if pos.shape != (3,) or quat.shape != (4,) or vel.shape != (6,):
            raise ValueError("reset needs position_ned_m (3,), quaternion_xyzw (4,) or rpy_rad (3,), nu (6,)")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat)) and np.all(np.isfinite(vel))):
            raise ValueError("reset values must be finite")
        norm = float(np.linalg.norm(quat))
        if norm < 1e-9:
            raise ValueError("quaternion_xyzw must not be zero")
        self._state: list[float] = [*pos.tolist(), *(quat / norm).tolist(), *vel.tolist()]
        self._k = 0
        self._t = 0.0
        self._external = [0.0] * 6
        self._last_pw: np.ndarray | None = None
        self._esc_queue: deque = deque()
        self._base_force = np.zeros(self.thrusters.n)
        self._dist_wrench = [0.0] * 6
        self._nu_dot_prev = [0.0] * 6
        self._history = deque([(0.0, list(self._state))]) if self._keep_history_s > 0.0 else deque()
        self.thrusters.reset()
        self._truth_cache: VehicleTruth | None = None
        if self.pool is not None:
            self.pool.reset_contacts()
            self.pool.resolve(self._state, 0.0)
        self.sensors.reset(0.0)

    def add_sensor_listener(self, callback: SensorListener) -> None:
        """Call ``callback(device_name, sample)`` for every new sensor sample (in step order)."""
        self._listeners.append(callback)

    def remove_sensor_listener(self, callback: SensorListener) -> None:
        """Stop calling ``callback`` (ValueError if it was not registered)."""
        self._listeners.remove(callback)

    # ------------------------------------------------------------------ stepping
    def step(self, pulse_widths_us: Sequence[float] | None = None, external_wrench_frd: Sequence[float] | None = None,
             armed: bool = True) -> list[tuple[str, Any]]:
        """Advance one integration step ``step_s``.

        pulse_widths_us (n,): wire pulse widths in thruster order (None: keep the last applied ones, which are neutral
        after a disarmed step). external_wrench_frd (6,): extra wrench [X Y Z K M N] about the body origin (FRD, N, N m)
        held over the step (None: keep the previous one, initially zero), e.g. a pure force at the CG for tests. armed:
        False means the ESC outputs are neutral whatever the widths. Returns the new ``(device, sample)`` pairs of this
        step. Raises :class:`PulseWidthError` (state unchanged) for bad widths and ``ValueError`` for a bad wrench."""
        new_external = None if external_wrench_frd is None else _wrench6(external_wrench_frd)
        thr = self.thrusters
        dist = self.disturbances
        pw = self._neutral if not armed else pulse_widths_us
        if pw is not None:
            try:
                arr = np.asarray(pw, dtype=float)
            except (TypeError, ValueError) as exc:
                raise PulseWidthError(f"pulse widths must be {thr.n} numbers (us), got {pw!r}") from exc
            if self._last_pw is None or arr.shape != self._last_pw.shape or not np.array_equal(arr, self._last_pw):
                if dist.esc_latency_s > 0.0:  # the truth's ESC delay: widths act latency_s after they were written
                    thr.thrust_from_pulse_width(arr)  # raises PulseWidthError before anything changes
                    self._esc_queue.append((self._t + dist.esc_latency_s, arr.copy()))
                else:
                    thr.command(arr)  # raises PulseWidthError before anything changes
                    self._base_force = thr.commanded_force_n.copy()
                self._last_pw = arr.copy()
        while self._esc_queue and self._esc_queue[0][0] <= self._t + 1e-9:
            thr.command(self._esc_queue.popleft()[1])
            self._base_force = thr.commanded_force_n.copy()
        if new_external is not None:
            self._external = new_external
        if dist.thrust_active:
            thr.commanded_force_n = self._base_force * dist.thrust_factor(self._t, self._state, self._base_force)

        dt = self.step_s
        if thr.time_constant_s <= 0.0:  # no lag: a new command acts from the start of the step
            thr.force_n = thr.commanded_force_n.copy()
        f0 = thr.force_n
        fc = thr.commanded_force_n
        b = thr.matrix_co
        tau_c = (b @ fc).tolist()
        dtau = (b @ (f0 - fc)).tolist()
        ext = self._external
        if dist.wrench_active:
            self._dist_wrench = dist.wrench(self._t, self._state, self._nu_dot_prev)
            ext = [a + b for a, b in zip(ext, self._dist_wrench)]
        eh, ef = self._lag_half, self._lag_full
        tau0 = [tc + d + e for tc, d, e in zip(tau_c, dtau, ext)]
        tauh = [tc + eh * d + e for tc, d, e in zip(tau_c, dtau, ext)]
        tau1 = [tc + ef * d + e for tc, d, e in zip(tau_c, dtau, ext)]

        deriv = self.model.derivative_list
        s = self._state
        h2 = 0.5 * dt
        k1 = deriv(s, tau0)
        k2 = deriv([x + h2 * k for x, k in zip(s, k1)], tauh)
        k3 = deriv([x + h2 * k for x, k in zip(s, k2)], tauh)
        k4 = deriv([x + dt * k for x, k in zip(s, k3)], tau1)
        d6 = dt / 6.0
        new = [x + d6 * (a + 2.0 * (bb + c) + d) for x, a, bb, c, d in zip(s, k1, k2, k3, k4)]
        qx, qy, qz, qw = new[3:7]
        inv = 1.0 / math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
        new[3], new[4], new[5], new[6] = qx * inv, qy * inv, qz * inv, qw * inv
        thr.advance(dt)
        self._k += 1
        self._t = self._k * dt
        if self.pool is not None:
            self.pool.resolve(new, self._t)
        if dist.wrench_active:
            self._nu_dot_prev = [(a - b) / dt for a, b in zip(new[7:13], s[7:13])]
        self._state = new
        if self._keep_history_s > 0.0:
            self._history.append((self._t, list(new)))
            while len(self._history) > 1 and self._history[1][0] <= self._t - self._keep_history_s - 1e-9:
                self._history.popleft()
        self._truth_cache = None
        samples = self.sensors.update(self._t, self.truth)
        if samples and self._listeners:
            for name, sample in samples:
                for cb in self._listeners:
                    cb(name, sample)
        return samples

    def advance(self, duration_s: float, pulse_widths_us: Sequence[float] | None = None,
                external_wrench_frd: Sequence[float] | None = None, armed: bool = True) -> int:
        """Run ``round(duration_s / step_s)`` steps with the given held inputs; returns the number of steps."""
        n = int(round(float(duration_s) / self.step_s))
        if n < 0:
            raise ValueError(f"duration_s must be >= 0, got {duration_s!r}")
        for i in range(n):
            self.step(pulse_widths_us if i == 0 else None, external_wrench_frd if i == 0 else None, armed)
        return n

    def set_external_wrench(self, wrench_frd: Sequence[float]) -> None:
        """Hold ``wrench_frd`` (6,) [X Y Z K M N] about the body origin (FRD, N, N m) from the next step on, as
        :meth:`step`'s ``external_wrench_frd`` does, for a plant stepped by someone else (the simulator node): e.g.
        the known force of a calibration step (:mod:`hindrax_sim.graph.graph_campaign`). Raises
        ``ValueError`` unless 6 finite numbers."""
        self._external = _wrench6(wrench_frd)

    # ------------------------------------------------------------------ truth
    @property
    def t_s(self) -> float:
        """Simulated time, s (k * step_s)."""
        return self._t

    @property
    def state(self) -> np.ndarray:
        """Copy of the state (13,): [position NED m, quaternion xyzw, nu (m/s, rad/s)]."""
        return np.array(self._state)

    @property
    def position_ned_m(self) -> np.ndarray:
        """Body origin in the pool frame (3,), NED, m."""
        return np.array(self._state[0:3])

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        """Orientation of body FRD in NED, (4,) x, y, z, w."""
        return np.array(self._state[3:7])

    @property
    def rotation(self) -> np.ndarray:
        """R (3, 3), body FRD -> NED."""
        return rotation_matrix_from_quaternion(self._state[3:7])

    @property
    def euler_rad(self) -> np.ndarray:
        """Fossen ZYX [roll, pitch, yaw] (3,), rad."""
        return euler_from_rotation_matrix(self.rotation)

    @property
    def nu(self) -> np.ndarray:
        """Body velocity [u v w p q r] (6,), FRD, m/s and rad/s."""
        return np.array(self._state[7:13])

    @property
    def nu_dot(self) -> np.ndarray:
        """d nu / dt (6,) at the current state with the current thrust and external wrench."""
        tau = (self.thrusters.wrench_co() + np.asarray(self._external) + np.asarray(self._dist_wrench)).tolist()
        return np.array(self.model.derivative_list(self._state, tau)[7:13])

    @property
    def wrench_frd(self) -> np.ndarray:
        """Current thruster wrench [X Y Z K M N] (6,) about the body origin, FRD, N and N m."""
        return self.thrusters.wrench_co()

    @property
    def thrust_n(self) -> np.ndarray:
        """Current (lagged) thrust of each thruster (n,), N."""
        return self.thrusters.force_n.copy()

    @property
    def contact(self) -> ContactState:
        """Latest contact report (empty without a pool)."""
        return self.pool.contact if self.pool is not None else ContactState(self._t)

    @property
    def buoyancy_fraction(self) -> float:
        """Submerged fraction of the hull in [0, 1]."""
        return self.model.buoyancy_fraction(self._state)

    def truth(self) -> VehicleTruth:
        """Snapshot of the vehicle now (cached until the next step)."""
        if self._truth_cache is None:
            r = self.rotation
            self._truth_cache = VehicleTruth(
                t_s=self._t, position_ned_m=self.position_ned_m, quaternion_xyzw=self.quaternion_xyzw, rotation=r,
                euler_rad=euler_from_rotation_matrix(r), nu=self.nu, nu_dot=self.nu_dot, wrench_frd=self.wrench_frd,
                buoyancy_fraction=self.buoyancy_fraction)
        return self._truth_cache

    def _delayed_state(self, delay_s: float) -> list[float]:
        """The state (13,) ``delay_s`` ago (the newest kept one at or before it; for the DVL latency)."""
        if not self._history:
            return list(self._state)
        target = self._t - delay_s + 1e-9
        best = self._history[0][1]
        for t, st in self._history:
            if t > target:
                break
            best = st
        return list(best)

    def measure(self, device: str, dropout: bool = False) -> Any | None:
        """A sample of ``device`` on the vehicle as it is now (:meth:`SensorSuite.measure`: noise and bias, off the
        device's rate grid; None when ``dropout`` and the device drops it). Raises ``KeyError`` for a disabled
        device."""
        return self.sensors.measure(device, self.truth(), dropout)

