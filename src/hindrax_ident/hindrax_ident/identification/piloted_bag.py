"""A piloted virtual-pool run written as a bag of standard messages only (for ``hindrax ident fit`` and its tests).

A "pilot" (a saturated PD controller on body-frame position and heading errors) tracks random setpoints in the
in-process simulator (:class:`hindrax_ident.sim.simulator.Simulator` on the truth of :mod:`hindrax_ident.sim.truth`),
one move at a time, as an engineer flies in a pool: "forward 1.5 m", "right 1 m", "down 0.4 m", "turn 90 deg"
(targets drawn until they lie inside ``pool.*`` less ``pool.margin_m``), plus a random jitter on every commanded
axis. The commanded wrench acts on the vehicle directly (``external_wrench_frd``: no thrusters, so the truth is
the configured hydrodynamics) ``delay_s`` after it is commanded, like an actuation delay.

The bag (:class:`hindrax_drivers.recording.writer.BagWriter`) holds, REP-103 FLU (:mod:`hindrax_drivers.frames`):

* ``/wrench`` geometry_msgs/msg/WrenchStamped, ``base_link``, at ``control_hz`` (the commanded wrench, stamped at
  the command time);
* ``/odometry`` nav_msgs/msg/Odometry, frame ``odom`` (ENU), child ``base_link`` (twist in base_link), published
  at ``control_hz`` but its velocity updated only at ``velocity_hz`` (the repeated values of a slow estimator), with
  white noise, header stamps = time of validity and receive (log) times late by 0-``late_s`` with bursts, and
  ``gap`` (start s, length s) lost.

Messy on purpose: :mod:`.fit_any` must handle every one of those.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hindrax_drivers import frames
from hindrax_drivers.config import VehicleConfig

__all__ = ["PilotSettings", "write_piloted_bag"]

EPOCH_NS = 1_700_000_000 * 1_000_000_000  # ROS time of the run's start (any fixed epoch)


@dataclass(frozen=True)
class PilotSettings:
    """duration_s: run length; control_hz: controller and /wrench rate; velocity_hz: odometry velocity update
    rate; delay_s: command -> action delay; noise_linear_m_s / noise_angular_rad_s: odometry twist noise (1 sigma);
    late_s: max receive latency; gap: (start, length) s of lost messages or None; max_force_n, max_moment_n_m:
    saturation (surge/sway, heave; yaw); jitter: relative random force added to the PD output; axes: the moves the
    pilot makes (0 forward/back, 1 right/left, 2 down/up, 3 turn), drawn uniformly from this tuple (repeat one to make it
    more frequent); header_stamps: False leaves every header stamp unset (readers must use receive times);
    imu: also ``/imu`` sensor_msgs/msg/Imu (angular rate, at ``control_hz``, noise ``noise_angular_rad_s``) in the
    frame ``imu_link`` mounted upside down (180 deg about x) with that rotation in ``/tf_static``
    (tf2_msgs/msg/TFMessage), and the odometry's angular twist left at zero."""

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


def _serialize(msg) -> bytes:
    from rclpy.serialization import serialize_message

    return serialize_message(msg)


def _stamp(header, t_ns: int) -> None:
    header.stamp.sec = int(t_ns // 1_000_000_000)
    header.stamp.nanosec = int(t_ns % 1_000_000_000)


def write_piloted_bag(bag_dir: str | Path, cfg: VehicleConfig, seed: int = 0,
                      settings: PilotSettings = PilotSettings(), truth=None) -> Path:
    """Fly one piloted run (module docstring) and write it to the bag directory ``bag_dir``; returns the path.

    cfg: the vehicle file; truth: the simulator's truth (path, :class:`~hindrax_ident.sim.truth.Truth` or None for
    the shipped default). Raises ``FileExistsError`` when ``bag_dir`` already holds a bag.
    """
    from geometry_msgs.msg import WrenchStamped
    from nav_msgs.msg import Odometry

    from hindrax_drivers.recording.writer import BagWriter, WriterOptions

    from ..sim.simulator import Simulator

    s = settings
    rng = np.random.default_rng(seed)
    sim = Simulator(cfg, seed=seed, sensors=False, truth=truth)
    f = sim.config.flat
    # depth: the hull well under the surface even pitched and overshooting (no free-surface buoyancy loss)
    half = 0.5 * float(f["vehicle.height_m"]) + 0.25
    lo = np.array([f["pool.margin_m"], f["pool.margin_m"], half + 0.15])
    hi = np.array([f["pool.length_m"] - f["pool.margin_m"], f["pool.width_m"] - f["pool.margin_m"],
                   min(f["pool.depth_m"] - half, float(f["limits.max_depth_m"]) - 0.05)])
    start = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])])
    sim.reset(position_ned_m=start, rpy_rad=[0.0, 0.0, float(rng.uniform(-math.pi, math.pi))])
    target_pos, target_yaw = start.copy(), float(sim.euler_rad[2])
    steps_per_tick = max(1, int(round(1.0 / (s.control_hz * sim.step_s))))
    tick_s = steps_per_tick * sim.step_s
    n_ticks = int(s.duration_s / tick_s)
    vel_every = max(1, int(round(s.control_hz / s.velocity_hz)))
    kp = np.array([25.0, 25.0, 80.0, 6.0])
    kd = np.array([30.0, 35.0, 50.0, 2.5])
    sat = np.array([s.max_force_n[0], s.max_force_n[0], s.max_force_n[1], s.max_moment_n_m])
    pending: list[tuple[float, np.ndarray]] = []
    next_move = 0.0
    jitter = np.zeros(4)
    twist_held = np.zeros(6)
    bag = Path(bag_dir)
    with BagWriter(bag, WriterOptions(fsync=False)) as w:
        w.add_topic("/wrench", "geometry_msgs/msg/WrenchStamped")
        w.add_topic("/odometry", "nav_msgs/msg/Odometry")
        out: list[tuple[int, str, bytes]] = []
        r_imu = np.diag([1.0, -1.0, -1.0])  # imu_link axes in base_link: 180 deg about x
        if s.imu:
            from geometry_msgs.msg import TransformStamped
            from sensor_msgs.msg import Imu
            from tf2_msgs.msg import TFMessage

            w.add_topic("/imu", "sensor_msgs/msg/Imu")
            w.add_topic("/tf_static", "tf2_msgs/msg/TFMessage")
            tr = TransformStamped()
            _stamp(tr.header, EPOCH_NS)
            tr.header.frame_id, tr.child_frame_id = "base_link", "imu_link"
            tr.transform.rotation.x, tr.transform.rotation.w = 1.0, 0.0
            w.write("/tf_static", EPOCH_NS, _serialize(TFMessage(transforms=[tr])))
        for k in range(n_ticks):
            t = k * tick_s
            if t >= next_move:  # the pilot's next move: one DOF at a time, in body axes, inside the pool
                for _ in range(50):
                    axis = int(rng.choice(s.axes))
                    yaw = float(sim.euler_rad[2])
                    if axis == 3:
                        new_yaw = target_yaw + float(rng.choice([-1, 1]) * rng.uniform(1.0, 3.0))
                        new_pos = target_pos
                        break
                    step = np.zeros(3)
                    step[axis] = float(rng.choice([-1, 1]) * (rng.uniform(1.5, 4.0) if axis < 2 else
                                                              rng.uniform(0.4, 1.0)))
                    c, sn = math.cos(yaw), math.sin(yaw)
                    delta = np.array([c * step[0] - sn * step[1], sn * step[0] + c * step[1], step[2]])
                    cand = target_pos + delta
                    if axis == 2:  # down/up: to near the farther end of the depth range (fast, both ways)
                        cand = target_pos.copy()
                        far_top = target_pos[2] - lo[2] > hi[2] - target_pos[2]
                        cand[2] = float(lo[2] + rng.uniform(0.0, 0.15) if far_top else hi[2] - rng.uniform(0.0, 0.15))
                    if np.all(cand >= lo) and np.all(cand <= hi):
                        new_pos, new_yaw = cand, target_yaw
                        break
                else:
                    new_pos, new_yaw = start.copy(), target_yaw
                target_pos, target_yaw = new_pos, new_yaw
                next_move = t + float(rng.uniform(4.0, 8.0))
            pos, eul, nu = sim.position_ned_m, sim.euler_rad, sim.nu
            c, sn = math.cos(eul[2]), math.sin(eul[2])
            err_ned = target_pos - pos
            err = np.array([c * err_ned[0] + sn * err_ned[1], -sn * err_ned[0] + c * err_ned[1], err_ned[2],
                            math.remainder(target_yaw - eul[2], 2 * math.pi)])
            vel = np.array([nu[0], nu[1], nu[2], nu[5]])
            jitter = 0.9 * jitter + 0.1 * rng.normal(0.0, 1.0, 4) * sat * s.jitter * 3.0
            cmd4 = np.clip(kp * err - kd * vel + jitter, -sat, sat)
            wrench_frd = np.array([cmd4[0], cmd4[1], cmd4[2], 0.0, 0.0, cmd4[3]])
            pending.append((t + s.delay_s, wrench_frd))
            t_ns = EPOCH_NS + int(round(t * 1e9))
            in_gap = s.gap is not None and s.gap[0] <= t < s.gap[0] + s.gap[1]
            # commanded wrench, FLU
            wm = WrenchStamped()
            _stamp(wm.header, t_ns)
            wm.header.frame_id = "base_link"
            wf = frames.wrench_frd_to_flu(wrench_frd)
            wm.wrench.force.x, wm.wrench.force.y, wm.wrench.force.z = (float(x) for x in wf[:3])
            wm.wrench.torque.x, wm.wrench.torque.y, wm.wrench.torque.z = (float(x) for x in wf[3:])
            # odometry of the state now (velocity held between updates)
            if k % vel_every == 0:
                noise = np.concatenate([rng.normal(0, s.noise_linear_m_s, 3), rng.normal(0, s.noise_angular_rad_s, 3)])
                twist_held = frames.twist_frd_to_flu(np.asarray(nu, dtype=float)) + noise
            om = Odometry()
            _stamp(om.header, t_ns)
            om.header.frame_id = "odom"
            om.child_frame_id = "base_link"
            p_enu = frames.ned_to_enu(pos)
            om.pose.pose.position.x, om.pose.pose.position.y, om.pose.pose.position.z = (float(x) for x in p_enu)
            q = frames.quaternion_marine_to_ros(sim.quaternion_xyzw)
            (om.pose.pose.orientation.x, om.pose.pose.orientation.y, om.pose.pose.orientation.z,
             om.pose.pose.orientation.w) = (float(x) for x in q)
            om.twist.twist.linear.x, om.twist.twist.linear.y, om.twist.twist.linear.z = (float(x) for x in twist_held[:3])
            om.twist.twist.angular.x, om.twist.twist.angular.y, om.twist.twist.angular.z = (
                float(x) for x in twist_held[3:])
            if s.imu:
                om.twist.twist.angular.x = om.twist.twist.angular.y = om.twist.twist.angular.z = 0.0
                im = Imu()
                _stamp(im.header, t_ns)
                im.header.frame_id = "imu_link"
                w_imu = r_imu.T @ frames.frd_to_flu(np.asarray(nu[3:], dtype=float)) + rng.normal(
                    0, s.noise_angular_rad_s, 3)
                im.angular_velocity.x, im.angular_velocity.y, im.angular_velocity.z = (float(x) for x in w_imu)
            if not s.header_stamps:
                for m in (wm, om) + ((im,) if s.imu else ()):
                    m.header.stamp.sec = m.header.stamp.nanosec = 0
            if not in_gap:
                if s.imu:
                    out.append((t_ns + int(rng.uniform(0.0, 0.004) * 1e9), "/imu", _serialize(im)))
                burst = rng.random() < 0.05
                late = int(rng.uniform(0.0, s.late_s) * 1e9) + (int(0.2e9) if burst else 0)
                out.append((t_ns + int(rng.uniform(0.0, 0.005) * 1e9), "/wrench", _serialize(wm)))
                out.append((t_ns + late, "/odometry", _serialize(om)))
            # advance the simulator to the next tick, applying the delayed commands
            for i in range(steps_per_tick):
                ts = t + i * sim.step_s
                apply = None
                while pending and pending[0][0] <= ts + 1e-9:
                    apply = pending.pop(0)[1]
                sim.step(None, apply)
            if len(out) > 200 or k == n_ticks - 1:  # write in receive order (bounded lateness)
                out.sort(key=lambda x: x[0])
                horizon = EPOCH_NS + int(round((t - 0.5) * 1e9)) if k < n_ticks - 1 else None
                keep = []
                for item in out:
                    if horizon is None or item[0] < horizon:
                        w.write(item[1], item[0], item[2])
                    else:
                        keep.append(item)
                out = keep
    return bag
