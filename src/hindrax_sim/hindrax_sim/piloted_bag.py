"""A piloted or closed-loop virtual-pool run written as a bag of standard messages only (``hindrax ident fit``,
its tests and the realistic-data benchmark :mod:`hindrax_tools.benchmarks.ident_fit`).

Who flies (``PilotSettings.pilot``):

* ``"setpoints"``: a "pilot" (a saturated PD controller on body-frame position and heading errors) tracks random
  setpoints one move at a time, as an engineer flies in a pool: "forward 1.5 m", "right 1 m", "down 0.4 m",
  "turn 90 deg" (targets drawn until they lie inside ``pool.*`` less ``pool.margin_m``), plus a random jitter on
  every commanded axis;
* ``"openloop"``: open-loop runs as a team without a controller flies them: each axis a force level held 1-4 s,
  uniform up to ``level_top`` of the saturation, its sign toward the pool's centre when the vehicle is past half the
  way to a wall (no feedback within a level); with ``idle_fraction`` that fraction of the levels is instead an idle
  stretch of 4-12 s (a team discussing the next run);
* ``"autopilot"``: a closed-loop survey autopilot nobody designed for identification: lawnmower legs along the
  pool at ``cruise_m_s`` with a PI surge-speed loop, cross-track and heading PD, a depth PI loop with a depth step
  at every leg end, the turn between legs, and a small jitter. Its commands are smooth and mostly steady: little
  excitation, integral action against the current and the tether.

How the command acts (``actuation``):

* ``"wrench"``: the commanded wrench acts on the vehicle directly (``external_wrench_frd``: no thrusters, so the
  truth is the configured hydrodynamics) ``delay_s`` after it is commanded, like an actuation delay;
* ``"thrusters"``: the commanded wrench goes through the vehicle's thrust allocation
  (:class:`hindrax_bringup.allocation.core.AllocationCore`: saturation, curve inversion) to the simulated
  thrusters, so the truth's thrust lag, ESC latency, thrust scales and reverse asymmetry, battery sag, inflow loss
  and deadband (``ros_ws/config/truth``) make the real force differ from the recorded command, as on a real
  vehicle; ``delay_s`` adds a transport delay before the allocation.

With ``"thrusters"`` the bag also holds ``/allocation/status`` hindrax_msgs/msg/AllocationStatus (``base_link``), one
per allocated command, as the allocation node publishes it: the requested and the achieved wrench (its thrusters'
limits: saturation), header stamp = the command's stamp, received when it is allocated.

The bag (:class:`hindrax_bringup.recording.writer.BagWriter`) holds, REP-103 FLU (:mod:`hindrax_common.base.frames`):

* ``/wrench`` geometry_msgs/msg/WrenchStamped, ``base_link``, at ``control_hz`` (the commanded wrench, stamped at
  the command time);
* with ``sensors="odometry"``: ``/odometry`` nav_msgs/msg/Odometry, frame ``odom`` (ENU), child ``base_link`` (twist
  in base_link), published at ``control_hz`` but its velocity updated only at ``velocity_hz`` (the repeated values
  of a slow estimator), with white noise, header stamps = time of validity and receive (log) times late by
  0-``late_s`` with bursts, and ``gap`` (start s, length s) lost;
* with ``sensors="dvl"``: the simulated sensors of the truth (noise, dropouts, DVL scale error, misalignment,
  latency and multipath losses, IMU bias walk): ``/dvl/twist`` geometry_msgs/msg/TwistWithCovarianceStamped
  (``base_link``, the DVL-75 velocity moved to the body origin with the gyro rate, as a DVL driver does; none
  while the DVL has no bottom lock), ``/imu`` sensor_msgs/msg/Imu (``base_link``, angular rate and specific force
  at 100 Hz), ``/pressure`` sensor_msgs/msg/FluidPressure, receive times late by 0-``late_s`` and ``gap`` lost.

Messy on purpose: the any-topics reader (:mod:`..identification.bag_input.any_topics`) must handle every one of those.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from geometry_msgs.msg import TransformStamped, TwistWithCovarianceStamped, WrenchStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message as _serialize
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import FluidPressure, Imu
from tf2_msgs.msg import TFMessage

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import VehicleConfig
from hindrax_bringup.recording.writer import BagWriter, WriterOptions
from hindrax_msgs.msg import AllocationStatus

from .simulator import Simulator, fill_odometry, fill_wrench

__all__ = ["PilotSettings", "write_piloted_bag"]

EPOCH_NS = 1_700_000_000 * 1_000_000_000  # ROS time of the run's start (any fixed epoch)
PILOTS = ("setpoints", "autopilot", "openloop")
ACTUATIONS = ("wrench", "thrusters")
SENSORS = ("odometry", "dvl")


@dataclass(frozen=True)
class PilotSettings:
    """duration_s: run length; control_hz: controller and /wrench rate; velocity_hz: odometry velocity update
    rate; delay_s: command -> action delay; noise_linear_m_s / noise_angular_rad_s: odometry twist noise (1 sigma);
    late_s: max receive latency; gap: (start, length) s of lost messages or None; max_force_n, max_moment_n_m:
    saturation (surge/sway, heave; yaw); jitter: relative random force added to the controller's output; axes: the
    moves the pilot makes (0 forward/back, 1 right/left, 2 down/up, 3 turn), drawn uniformly from this tuple (repeat
    one to make it more frequent); header_stamps: False leaves every header stamp unset (readers must use receive
    times); imu: also ``/imu`` sensor_msgs/msg/Imu (angular rate, at ``control_hz``, noise ``noise_angular_rad_s``)
    in the frame ``imu_link`` mounted upside down (180 deg about x) with that rotation in ``/tf_static``
    (tf2_msgs/msg/TFMessage), and the odometry's angular twist left at zero (``sensors="odometry"`` only).
    pilot, actuation, sensors: one of :data:`PILOTS`, :data:`ACTUATIONS`, :data:`SENSORS` (module docstring);
    cruise_m_s: the autopilot's leg speed; gain_scale: the controllers' gains times this (a heavier vehicle needs
    larger gains); level_top, idle_fraction: the open-loop pilot's largest level (fraction of the saturation) and
    its share of idle stretches (module docstring)."""

    duration_s: float = 120.0
    control_hz: float = 20.0
    velocity_hz: float = 10.0
    delay_s: float = 0.05
    noise_linear_m_s: float = 0.005
    noise_angular_rad_s: float = 0.005
    late_s: float = 0.03
    gap: tuple[float, float] | None = (60.0, 1.5)
    max_force_n: tuple[float, float] = (40.0, 50.0)
    max_moment_n_m: float = 6.0
    jitter: float = 0.25
    axes: tuple[int, ...] = (0, 1, 2, 2, 2, 3)
    header_stamps: bool = True
    imu: bool = False
    pilot: str = "setpoints"
    actuation: str = "wrench"
    sensors: str = "odometry"
    cruise_m_s: float = 0.35
    gain_scale: float = 1.0
    level_top: float = 0.6
    idle_fraction: float = 0.0

    def __post_init__(self) -> None:
        for name, allowed in (("pilot", PILOTS), ("actuation", ACTUATIONS), ("sensors", SENSORS)):
            if getattr(self, name) not in allowed:
                raise ValueError(f"PilotSettings.{name}: {getattr(self, name)!r} is not one of {', '.join(allowed)}")


def _stamp(header, t_ns: int, frame_id: str) -> None:
    header.stamp.sec = int(t_ns // 1_000_000_000)
    header.stamp.nanosec = int(t_ns % 1_000_000_000)
    header.frame_id = frame_id


class _SetpointPilot:
    """Random moves one DOF at a time (module docstring), a saturated PD on body-frame errors."""

    def __init__(self, s: PilotSettings, rng, lo, hi, start, yaw0: float) -> None:
        self.s, self.rng, self.lo, self.hi, self.start = s, rng, lo, hi, start
        self.target_pos, self.target_yaw = start.copy(), yaw0
        self.next_move = 0.0
        self.kp = np.array([25.0, 25.0, 80.0, 6.0]) * s.gain_scale
        self.kd = np.array([30.0, 35.0, 50.0, 2.5]) * s.gain_scale

    def targets(self, t: float, yaw: float) -> None:
        s, rng, lo, hi = self.s, self.rng, self.lo, self.hi
        if t < self.next_move:
            return
        for _ in range(50):
            axis = int(rng.choice(s.axes))
            if axis == 3:
                new_yaw = self.target_yaw + float(rng.choice([-1, 1]) * rng.uniform(1.0, 3.0))
                new_pos = self.target_pos
                break
            step = np.zeros(3)
            step[axis] = float(rng.choice([-1, 1]) * (rng.uniform(1.5, 4.0) if axis < 2 else rng.uniform(0.4, 1.0)))
            c, sn = math.cos(yaw), math.sin(yaw)
            cand = self.target_pos + np.array([c * step[0] - sn * step[1], sn * step[0] + c * step[1], step[2]])
            if axis == 2:  # down/up: to near the farther end of the depth range (fast, both ways)
                cand = self.target_pos.copy()
                far_top = self.target_pos[2] - lo[2] > hi[2] - self.target_pos[2]
                cand[2] = float(lo[2] + rng.uniform(0.0, 0.15) if far_top else hi[2] - rng.uniform(0.0, 0.15))
            if np.all(cand >= lo) and np.all(cand <= hi):
                new_pos, new_yaw = cand, self.target_yaw
                break
        else:
            new_pos, new_yaw = self.start.copy(), self.target_yaw
        self.target_pos, self.target_yaw = new_pos, new_yaw
        self.next_move = t + float(rng.uniform(4.0, 8.0))

    def command(self, t: float, pos, eul, nu, tick_s: float) -> np.ndarray:
        """PD output [X, Y, Z, N] before jitter and saturation."""
        self.targets(t, float(eul[2]))
        c, sn = math.cos(eul[2]), math.sin(eul[2])
        e = self.target_pos - pos
        err = np.array([c * e[0] + sn * e[1], -sn * e[0] + c * e[1], e[2], frames.wrap_angle(self.target_yaw - eul[2])])
        return self.kp * err - self.kd * np.array([nu[0], nu[1], nu[2], nu[5]])


class _Autopilot:
    """Lawnmower survey (module docstring): legs along the pool's x axis at the cruise speed, a sideways shift and
    a depth step at each end, heading along the leg."""

    def __init__(self, s: PilotSettings, rng, lo, hi, start) -> None:
        self.s, self.rng, self.lo, self.hi = s, rng, lo, hi
        self.leg_dir = 1.0 if rng.random() < 0.5 else -1.0
        self.lane_y = float(start[1])
        self.depth = float(start[2])
        self.lane_dy = float(rng.choice([-1.0, 1.0]) * 0.8)
        self.i_u = 0.0
        self.i_z = 0.0

    def command(self, t: float, pos, eul, nu, tick_s: float) -> np.ndarray:
        s, lo, hi = self.s, self.lo, self.hi
        x_end = hi[0] if self.leg_dir > 0 else lo[0]
        if (x_end - pos[0]) * self.leg_dir < 0.4:  # leg end: turn round, next lane, new depth
            self.leg_dir = -self.leg_dir
            nxt = self.lane_y + self.lane_dy
            if not lo[1] <= nxt <= hi[1]:
                self.lane_dy = -self.lane_dy
                nxt = self.lane_y + self.lane_dy
            self.lane_y = float(np.clip(nxt, lo[1], hi[1]))
            self.depth = float(self.rng.uniform(lo[2], hi[2]))
        psi_ref = 0.0 if self.leg_dir > 0 else math.pi
        e_psi = frames.wrap_angle(psi_ref - eul[2])
        # slow down while the heading is off (the turn at the end of a leg)
        u_ref = s.cruise_m_s * max(0.0, math.cos(e_psi)) ** 4
        c, sn = math.cos(eul[2]), math.sin(eul[2])
        e_y = self.lane_y - pos[1]
        e_sway = -sn * 0.0 + c * e_y  # the cross-track error in body axes (legs along x)
        g = s.gain_scale
        self.i_u = float(np.clip(self.i_u + (u_ref - nu[0]) * tick_s, -20.0, 20.0))
        self.i_z = float(np.clip(self.i_z + (self.depth - pos[2]) * tick_s, -20.0, 20.0))
        x = g * (40.0 * (u_ref - nu[0]) + 15.0 * self.i_u)
        y = g * (20.0 * e_sway - 30.0 * nu[1])
        z = g * (60.0 * (self.depth - pos[2]) - 45.0 * nu[2] + 10.0 * self.i_z)
        n = g * (3.0 * e_psi - 2.0 * nu[5])
        return np.array([x, y, z, n])


class _OpenLoopPilot:
    """Held force levels per axis (module docstring), [X, Y, Z, N] in body axes."""

    def __init__(self, s: PilotSettings, rng, lo, hi, start) -> None:
        self.rng, self.lo, self.hi, self.mid, self.idle = rng, lo, hi, start, s.idle_fraction
        self.top = s.level_top * np.array([s.max_force_n[0], s.max_force_n[0], s.max_force_n[1], s.max_moment_n_m])
        self.level, self.until = np.zeros(4), np.zeros(4)

    def command(self, t: float, pos, eul, nu, tick_s: float) -> np.ndarray:
        c, sn = math.cos(eul[2]), math.sin(eul[2])
        off = (pos - self.mid) / np.maximum(0.5 * (self.hi - self.lo), 1e-3)  # -1..1 across the pool
        off_body = np.array([c * off[0] + sn * off[1], -sn * off[0] + c * off[1], off[2], 0.0])
        for i in np.flatnonzero(t >= self.until):
            if self.idle > 0.0 and self.rng.random() < self.idle:  # no draw without idle stretches
                self.level[i], self.until[i] = 0.0, t + float(self.rng.uniform(4.0, 12.0))
                continue
            a = float(self.rng.uniform(0.2, 1.0)) * self.top[i] * float(self.rng.choice([-1.0, 1.0]))
            self.level[i] = -math.copysign(a, off_body[i]) if abs(off_body[i]) > 0.5 else a
            self.until[i] = t + float(self.rng.uniform(1.0, 4.0))
        return self.level.copy()


def _allocation_status(res, stamp_ns: int) -> AllocationStatus:
    """The allocation node's ``allocation/status`` of one allocation ``res`` (FluAllocation) of the command
    stamped ``stamp_ns``."""
    st = AllocationStatus(scale=float(res.scale), thruster_saturated=[bool(x) for x in res.saturated],
                          saturated=bool(np.any(res.saturated)))
    _stamp(st.header, stamp_ns, "base_link")
    fill_wrench(st.requested_wrench, res.requested_wrench_flu)
    fill_wrench(st.achieved_wrench, res.achieved_wrench_flu)
    return st


def write_piloted_bag(bag_dir: str | Path, cfg: VehicleConfig, seed: int = 0,
                      settings: PilotSettings = PilotSettings(), truth=None) -> Path:
    """Fly one run (module docstring) and write it to the bag directory ``bag_dir``; returns the path.

    cfg: the vehicle file; truth: the simulator's truth (path, :class:`~hindrax_sim.truth.Truth` or None for
    the shipped default). Raises ``FileExistsError`` when ``bag_dir`` already holds a bag."""
    s = settings
    rng = np.random.default_rng(seed)
    dvl = s.sensors == "dvl"
    sim = Simulator(cfg, seed=seed, sensors=["dvl75", "icm20948_accel", "icm20948_gyro", "ms5837"] if dvl else False,
                    truth=truth)
    vc = sim.config
    pool = vc.pool
    # depth: the hull well under the surface even pitched and overshooting (no free-surface buoyancy loss)
    half = 0.5 * float(vc.vehicle.height_m) + 0.25
    lo = np.array([pool.margin_m, pool.margin_m, half + 0.15])
    hi = np.array([pool.length_m - pool.margin_m, pool.width_m - pool.margin_m,
                   min(pool.depth_m - half, float(vc.limits.max_depth_m) - 0.05)])
    start = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])])
    sim.reset(position_ned_m=start, rpy_rad=[0.0, 0.0, float(rng.uniform(-math.pi, math.pi))])
    if s.pilot == "setpoints":
        pilot = _SetpointPilot(s, rng, lo, hi, start, float(sim.euler_rad[2]))
    elif s.pilot == "openloop":
        pilot = _OpenLoopPilot(s, rng, lo, hi, start)
    else:
        pilot = _Autopilot(s, rng, lo, hi, start)
    core = None
    if s.actuation == "thrusters":
        core = AllocationCore(cfg)
        th = cfg.thrusters.thrusters
        neutral = float(cfg.thrusters.pulse_width_neutral_us)
        rev = np.array([t.reversed for t in th], dtype=bool)
        trim = np.array([t.trim_us for t in th], dtype=float)
    steps_per_tick = max(1, int(round(1.0 / (s.control_hz * sim.step_s))))
    tick_s = steps_per_tick * sim.step_s
    n_ticks = int(s.duration_s / tick_s)
    vel_every = max(1, int(round(s.control_hz / s.velocity_hz)))
    sat = np.array([s.max_force_n[0], s.max_force_n[0], s.max_force_n[1], s.max_moment_n_m])
    pending: list[tuple[float, np.ndarray, int]] = []  # (time it acts, wrench FRD, command stamp ns)
    jitter = np.zeros(4)
    twist_held = np.zeros(6)
    r_dvl = np.asarray(vc.sensors.dvl75.position_frd_m, dtype=float)
    roll_m, pitch_m, yaw_m = vc.sensors.icm20948.mounting_rpy_rad

    flu_from_sensor = Rotation.from_euler("ZYX", [yaw_m, pitch_m, roll_m]).as_matrix()
    gyro_frd = np.zeros(3)
    accel_flu = np.zeros(3)
    bag = Path(bag_dir)
    with BagWriter(bag, WriterOptions(fsync=False)) as w:
        w.add_topic("/wrench", "geometry_msgs/msg/WrenchStamped")
        if core is not None:
            w.add_topic("/allocation/status", "hindrax_msgs/msg/AllocationStatus")
        if dvl:
            w.add_topic("/dvl/twist", "geometry_msgs/msg/TwistWithCovarianceStamped")
            w.add_topic("/imu", "sensor_msgs/msg/Imu")
            w.add_topic("/pressure", "sensor_msgs/msg/FluidPressure")
        else:
            w.add_topic("/odometry", "nav_msgs/msg/Odometry")
        out: list[tuple[int, str, bytes]] = []
        r_imu = frames.R_FLU_FRD  # imu_link axes in base_link: pi about x, the FLU <-> FRD rotation
        if s.imu and not dvl:
            w.add_topic("/imu", "sensor_msgs/msg/Imu")
            w.add_topic("/tf_static", "tf2_msgs/msg/TFMessage")
            tr = TransformStamped()
            _stamp(tr.header, EPOCH_NS, "base_link")
            tr.child_frame_id = "imu_link"
            tr.transform.rotation.x, tr.transform.rotation.w = 1.0, 0.0
            w.write("/tf_static", EPOCH_NS, _serialize(TFMessage(transforms=[tr])))

        def in_gap(t: float) -> bool:
            return s.gap is not None and s.gap[0] <= t < s.gap[0] + s.gap[1]

        def late_ns() -> int:
            burst = rng.random() < 0.05
            return int(rng.uniform(0.0, s.late_s) * 1e9) + (int(0.2e9) if burst else 0)

        def on_samples(samples) -> None:  # the simulated sensors, as their drivers would publish them
            nonlocal gyro_frd, accel_flu
            for dev, smp in samples:
                t_ns = EPOCH_NS + int(round(smp.stamp_s * 1e9))
                if in_gap(smp.stamp_s):
                    continue
                if dev == "icm20948_gyro":
                    w_flu = flu_from_sensor @ np.asarray(smp.angular_rate_rad_s, dtype=float)
                    gyro_frd = frames.flu_to_frd(w_flu)
                elif dev == "icm20948_accel":
                    accel_flu = flu_from_sensor @ np.asarray(smp.specific_force_m_s2, dtype=float)
                    im = Imu()
                    _stamp(im.header, t_ns, "base_link")
                    wf = frames.frd_to_flu(gyro_frd)
                    im.angular_velocity.x, im.angular_velocity.y, im.angular_velocity.z = (float(x) for x in wf)
                    (im.linear_acceleration.x, im.linear_acceleration.y,
                     im.linear_acceleration.z) = (float(x) for x in accel_flu)
                    im.orientation_covariance[0] = -1.0  # no orientation
                    out.append((t_ns + int(rng.uniform(0.0, 0.004) * 1e9), "/imu", _serialize(im)))
                elif dev == "dvl75":
                    v = np.asarray(smp.velocity_frd_m_s, dtype=float)
                    if not (smp.locked and np.all(np.isfinite(v))):
                        continue
                    v = v - np.cross(gyro_frd, r_dvl)  # to the body origin, with the gyro, as a DVL driver does
                    tm = TwistWithCovarianceStamped()
                    _stamp(tm.header, t_ns, "base_link")
                    vf = frames.frd_to_flu(v)
                    tm.twist.twist.linear.x, tm.twist.twist.linear.y, tm.twist.twist.linear.z = (float(x) for x in vf)
                    cov = np.zeros(36)
                    cov[0] = cov[7] = cov[14] = 0.01 ** 2
                    cov[21] = cov[28] = cov[35] = -1.0
                    tm.twist.covariance = cov.tolist()
                    out.append((t_ns + late_ns(), "/dvl/twist", _serialize(tm)))
                elif dev == "ms5837":
                    pm = FluidPressure()
                    _stamp(pm.header, t_ns, "pressure_link")
                    pm.fluid_pressure = float(smp.pressure_pa)
                    out.append((t_ns + int(rng.uniform(0.0, 0.02) * 1e9), "/pressure", _serialize(pm)))

        for k in range(n_ticks):
            t = k * tick_s
            pos, eul, nu = sim.position_ned_m, sim.euler_rad, sim.nu
            u4 = pilot.command(t, pos, eul, nu, tick_s)
            jitter = 0.9 * jitter + 0.1 * rng.normal(0.0, 1.0, 4) * sat * s.jitter * 3.0
            cmd4 = np.clip(u4 + jitter, -sat, sat)
            wrench_frd = np.array([cmd4[0], cmd4[1], cmd4[2], 0.0, 0.0, cmd4[3]])
            t_ns = EPOCH_NS + int(round(t * 1e9))
            pending.append((t + s.delay_s, wrench_frd, t_ns))
            # commanded wrench, FLU
            wm = WrenchStamped()
            _stamp(wm.header, t_ns, "base_link")
            fill_wrench(wm.wrench, frames.wrench_frd_to_flu(wrench_frd))
            if not dvl:
                # odometry of the state now (velocity held between updates)
                if k % vel_every == 0:
                    noise = np.concatenate([rng.normal(0, s.noise_linear_m_s, 3),
                                            rng.normal(0, s.noise_angular_rad_s, 3)])
                    twist_held = frames.twist_frd_to_flu(np.asarray(nu, dtype=float)) + noise
                om = fill_odometry(Odometry(), pos, sim.quaternion_xyzw, twist_held)
                _stamp(om.header, t_ns, "odom")
                if s.imu:
                    om.twist.twist.angular.x = om.twist.twist.angular.y = om.twist.twist.angular.z = 0.0
                    im = Imu()
                    _stamp(im.header, t_ns, "imu_link")
                    w_imu = r_imu.T @ frames.frd_to_flu(np.asarray(nu[3:], dtype=float)) + rng.normal(
                        0, s.noise_angular_rad_s, 3)
                    im.angular_velocity.x, im.angular_velocity.y, im.angular_velocity.z = (float(x) for x in w_imu)
                if not s.header_stamps:
                    for m in (wm, om) + ((im,) if s.imu else ()):
                        m.header.stamp.sec = m.header.stamp.nanosec = 0
            elif not s.header_stamps:
                wm.header.stamp.sec = wm.header.stamp.nanosec = 0
            if not in_gap(t):
                if s.imu and not dvl:
                    out.append((t_ns + int(rng.uniform(0.0, 0.004) * 1e9), "/imu", _serialize(im)))
                late = late_ns() if not dvl else 0
                out.append((t_ns + int(rng.uniform(0.0, 0.005) * 1e9), "/wrench", _serialize(wm)))
                if not dvl:
                    out.append((t_ns + late, "/odometry", _serialize(om)))
            # advance the simulator to the next tick, applying the delayed commands
            for i in range(steps_per_tick):
                ts = t + i * sim.step_s
                apply = None
                while pending and pending[0][0] <= ts + 1e-9:
                    _t_act, apply, cmd_ns = pending.pop(0)
                if core is None:
                    samples = sim.step(None, apply)
                else:
                    widths = None
                    if apply is not None:  # allocated to the thrusters; the ESC writes the wire widths
                        res = core.allocate(frames.wrench_frd_to_flu(apply))
                        logical = res.pulse_width_us
                        widths = np.where(rev, 2.0 * neutral - logical, logical) + trim
                        # received 1 ms after the allocation (no draw from rng: the bag's other data stay as
                        # they were without this topic)
                        out.append((EPOCH_NS + int(round(ts * 1e9)) + 1_000_000, "/allocation/status",
                                    _serialize(_allocation_status(res, cmd_ns))))
                    samples = sim.step(widths)
                if dvl and samples:
                    on_samples(samples)
            if len(out) > 200 or k == n_ticks - 1:  # write in receive order (bounded lateness)
                out.sort(key=lambda x: x[0])
                horizon = EPOCH_NS + int(round((t - 0.5) * 1e9)) if k < n_ticks - 1 else math.inf
                for log_ns, topic, data in out:
                    if log_ns < horizon:
                        w.write(topic, log_ns, data)
                out = [item for item in out if item[0] >= horizon]
    return bag
