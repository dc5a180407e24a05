"""The any-topics adapter of the bag reader (:mod:`.reader`): force and velocity found by message type, read into
the fit core's per-DOF records. No ROS runtime (bags are decoded by
:class:`hindrax_bringup.recording.reader.BagReader` from their stored definitions).

Inputs (:data:`ACCEPTED`), every vector converted to body FRD with :mod:`hindrax_common.base.frames` (messages are
REP-103 FLU in ``base_link``):

* force: ``geometry_msgs/msg/WrenchStamped`` (commanded or measured wrench about base_link), or our
  ``hindrax_msgs/msg/ThrusterPwm`` through the configured thrust curves and allocation matrix
  (:func:`....vehicle.signals.thrust_of_written_widths`; needs ``--config``; the widths act ``esc.output_latency_s``
  late);
* velocity: ``nav_msgs/msg/Odometry`` (twist in ``child_frame_id``), ``TwistWithCovarianceStamped``,
  ``TwistStamped`` or our ``hindrax_msgs/msg/Dvl`` (:func:`....vehicle.signals.samples_from_dvl`);
* angular rate: the velocity message's angular part, else ``sensor_msgs/msg/Imu`` (``--imu-topic``, which then
  takes precedence; found by type with a Dvl velocity; an IMU frame other than the body frame is rotated with the
  bag's ``/tf_static``, else refused), else the attitude differentiated (odometry pose or DVL attitude);
* depth (optional, ``--depth-topic``): ``sensor_msgs/msg/FluidPressure`` or the pose of an Odometry/PoseStamped;
  when given, the heave velocity is its derivative (Savitzky-Golay) instead of the velocity topic's;
* allocation (optional, found by type with a WrenchStamped force): ``hindrax_msgs/msg/AllocationStatus``, the
  wrench the thrust allocation achieved less the one requested (held from each status to the next, 0 before the
  first): where it falls short (a thruster at its limit: the heave command clipped at the vertical thrusters'
  limits) the fit core's saturation term is a candidate (:class:`..fit.fit_core.Terms`).

Preprocessing (:class:`Preprocessed`, reported in the ``preprocessing`` section): per topic, header stamps when
every stamp is set, else receive (log) times; messages sorted by that time; repeated velocity values (a velocity
that updates slower than it is published) dropped, keeping the first of each run; gaps longer than
``max(gap_min_s, 5 x median spacing)`` in force or velocity cut the record (nothing is interpolated across them);
force held (zero-order: its mean over each step, :func:`_grid_stretches`) on a uniform grid of ``grid_s``; the
velocity samples kept at their own times, interpolated onto the grid only for the smoothed initial states
(Savitzky-Golay, 0.5 s), the Coriolis products and the cross-coupling candidates (:func:`dof_records`).

A DOF whose force or velocity standard deviation is below :data:`EXCITATION_MIN` is "not excited" (reported with
both numbers). Errors: :class:`FitInputError` (one line: the topic, the type found, the types accepted;
disagreeing frame ids; how much data is needed)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from rclpy.serialization import deserialize_message
from scipy import signal
from scipy.spatial.transform import Rotation

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig
from hindrax_bringup.recording.reader import BagReader

from ..fit import fit_core
from hindrax_onboard.identification.model.dof_model import restoring_regressor
from ..fit.fit_core import EXCITATION_MIN
from hindrax_onboard.vehicle.signals import samples_from_dvl, thrust_of_written_widths
from hindrax_onboard.vehicle.thrust_lag import ThrustLag

__all__ = ["ACCEPTED", "EXCITATION_MIN", "FitInputError", "FitOptions", "TopicChoice", "Preprocessed", "GridStretch",
           "preprocess_bag", "excitation", "dof_records"]


WRENCH, PWM = "geometry_msgs/msg/WrenchStamped", "hindrax_msgs/msg/ThrusterPwm"
ODOM, TWIST_COV, TWIST, DVL = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistWithCovarianceStamped",
                               "geometry_msgs/msg/TwistStamped", "hindrax_msgs/msg/Dvl")
IMU, PRESSURE, POSE = "sensor_msgs/msg/Imu", "sensor_msgs/msg/FluidPressure", "geometry_msgs/msg/PoseStamped"
ALLOCATION = "hindrax_msgs/msg/AllocationStatus"

#: role -> accepted message types
ACCEPTED: dict[str, tuple[str, ...]] = {
    "wrench": (WRENCH, PWM),
    "velocity": (ODOM, TWIST_COV, TWIST, DVL),
    "imu": (IMU,),
    "depth": (PRESSURE, ODOM, POSE),
}


class FitInputError(ValueError):
    """The bags cannot be used as given (one line saying what is wrong and what is accepted or needed)."""


@dataclass(frozen=True)
class TopicChoice:
    """Topic per role; None: found by type (exactly one topic of an accepted type, or an error)."""

    wrench: str | None = None
    velocity: str | None = None
    imu: str | None = None
    depth: str | None = None


@dataclass(frozen=True)
class FitOptions:
    """grid_s: resampling step, s; gap_min_s: shortest spacing treated as a gap, s; the others as
    :class:`..fit.fit_core.CoreOptions`."""

    grid_s: float = 0.05
    segment_s: float = fit_core.SEGMENT_S
    validation_s: float = fit_core.VALIDATION_S
    max_delay_s: float = 1.0
    gap_min_s: float = 0.5
    folds: int = 4
    persistence_margin: float = fit_core.PERSISTENCE_MARGIN


def _norm(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _select(path: Path, topics: dict[str, str], role: str, given: str | None, required: bool) -> tuple[str, str] | None:
    accepted = ACCEPTED[role]
    cands = [t for t, ty in topics.items() if ty in accepted]
    if given is not None:
        name = given if given in topics else _norm(given) if _norm(given) in topics else None
        if name is None:
            raise FitInputError(f"{path}: {role} topic {given} not in the bag (accepted types: {', '.join(accepted)}; "
                                f"topics of those types: {', '.join(cands) or 'none'})")
        if topics[name] not in accepted:
            raise FitInputError(f"{path}: {role} topic {name} has type {topics[name]}; accepted: {', '.join(accepted)}")
        return name, topics[name]
    if role == "depth":  # an odometry is the velocity source, not a depth source, unless asked for
        return None
    if len(cands) == 1:
        return cands[0], topics[cands[0]]
    if not cands:
        if not required:
            return None
        raise FitInputError(f"{path}: no {role} topic: none has an accepted type ({', '.join(accepted)}); topics: "
                            + ", ".join(f"{t} [{ty}]" for t, ty in sorted(topics.items())) + f"; give --{role}-topic")
    raise FitInputError(f"{path}: several {role} topics ({', '.join(sorted(cands))}): choose one with --{role}-topic")


def _static_rotation(reader, parent: str, child: str) -> np.ndarray | None:
    """Rotation (3, 3) taking vectors of ``child`` to ``parent`` from a direct transform in the bag's /tf_static
    (tf2_msgs/msg/TFMessage), or None."""
    topics = [t for t, ty in reader.topics.items() if ty == "tf2_msgs/msg/TFMessage" and t.endswith("tf_static")]
    if not topics:
        return None
    try:
        for _raw, msg in _decoded(reader, topics):
            for tr in msg.transforms:
                if tr.header.frame_id == parent and tr.child_frame_id == child:
                    q = tr.transform.rotation
                    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    except Exception:  # noqa: BLE001 - an unreadable /tf_static is the same as none
        return None
    return None


def _decoded(reader, topics: Sequence[str]):
    """(raw, message) pairs of ``topics`` in log-time order: rclpy's C deserializer for types whose Python package
    is installed with the layout the bag recorded (standard messages: several times faster), else the reader's
    mcap_ros2 decoding from the stored definitions (:meth:`hindrax_bringup.recording.reader.BagReader.decoded`;
    ``BagReader.installed_class`` decides): a bag recorded before a message gained a field
    (``ThrusterPwm.output_state``) stays readable."""
    classes = {t: reader.installed_class(t) for t in topics}
    if any(c is None for c in classes.values()):
        yield from reader.decoded(list(topics))
        return

    for raw in reader.messages(list(topics)):
        yield raw, deserialize_message(raw.data, classes[raw.topic])


def _hdr_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


@dataclass
class _Stream:
    """One topic's samples: header and receive times (ns), values (n, k), frame ids seen."""

    topic: str
    type: str
    hdr: list = field(default_factory=list)
    log: list = field(default_factory=list)
    val: list = field(default_factory=list)
    frames: set = field(default_factory=set)

    def series(self) -> tuple[np.ndarray, np.ndarray, str]:
        """(times (n,) s, values (n, k)) in time order, a sample at a time already seen dropped,
        and the time base used; seconds as float64 (relative values kept exact enough)."""
        hdr = np.asarray(self.hdr, dtype=np.int64)
        if hdr.size and np.all(hdr > 0):
            t, base = hdr.astype(np.float64) * 1e-9, "header stamps"
        else:
            t = np.asarray(self.log, dtype=np.int64).astype(np.float64) * 1e-9
            base = "receive times (header stamps unset)"
        o = np.argsort(t, kind="stable")
        t, v = t[o], np.asarray(self.val, dtype=float)[o]
        keep = np.ones(len(t), dtype=bool)
        keep[1:] = np.diff(t) > 0
        return t[keep], v[keep], base


def _read_streams(path: Path, choice: TopicChoice, cfg: VehicleConfig | None) -> tuple[dict[str, _Stream], dict]:
    reader = BagReader(path)
    topics = reader.topics
    sel = {"wrench": _select(path, topics, "wrench", choice.wrench, True),
           "velocity": _select(path, topics, "velocity", choice.velocity, True),
           "imu": _select(path, topics, "imu", choice.imu, False) if choice.imu is not None else None,
           "depth": _select(path, topics, "depth", choice.depth, False) if choice.depth is not None else None}
    alloc = [t for t, ty in topics.items() if ty == ALLOCATION]
    # the allocation's shortfall belongs to a commanded wrench only (widths already carry the saturation)
    sel["allocation"] = (alloc[0], ALLOCATION) if sel["wrench"][1] == WRENCH and len(alloc) == 1 else None
    if sel["wrench"][1] == PWM and cfg is None:
        raise FitInputError(f"{path}: force from {sel['wrench'][0]} [{PWM}] needs the thrust curves: give --config")
    if sel["velocity"][1] in (DVL, TWIST_COV, TWIST) and sel["imu"] is None:
        # a DVL's velocity carries no angular rate: an IMU found by type gives it (an odometry has its own)
        sel["imu"] = _select(path, topics, "imu", None, False)
    by_topic: dict[str, list[str]] = {}
    for role, s in sel.items():
        if s is not None:
            by_topic.setdefault(s[0], []).append(role)
    streams: dict[str, _Stream] = {role: _Stream(s[0], s[1]) for role, s in sel.items() if s is not None}
    streams["attitude"] = _Stream(sel["velocity"][0], sel["velocity"][1])
    pwm = None
    if sel["wrench"][1] == PWM:
        core = AllocationCore(cfg)
        pwm = (core.allocator.curves[0], np.asarray(core.matrix_frd, dtype=float),
               np.full(len(cfg.thrusters.thrusters), float(cfg.thrusters.pulse_width_neutral_us)),
               int(round(float(cfg.esc.output_latency_s) * 1e9)))
    for raw, msg in _decoded(reader, list(by_topic)):
        for role in by_topic[raw.topic]:
            st = streams[role]
            ty = st.type
            if role == "wrench":
                if ty == WRENCH:
                    w = msg.wrench
                    st.val.append(frames.wrench_flu_to_frd([w.force.x, w.force.y, w.force.z,
                                                            w.torque.x, w.torque.y, w.torque.z]))
                    st.frames.add(msg.header.frame_id)
                else:
                    curve, matrix, neutral, lat = pwm
                    widths = np.asarray(msg.pulse_width_us, dtype=float)
                    if not np.all(np.isfinite(widths)):
                        # output_state OUTPUT_UNKNOWN: NaN widths, what is on the wire is not known (armed or
                        # not): missing force, cut out of the spans by preprocess_bag, never neutral thrust
                        st.val.append(np.full(6, np.nan))
                    else:
                        st.val.append(matrix @ thrust_of_written_widths(cfg, curve, widths if msg.armed else neutral))
                    st.hdr.append(_hdr_ns(msg) + lat)
                    st.log.append(raw.log_time_ns + lat)
                    continue
            elif role == "velocity":
                att = None
                if ty == DVL:
                    smp = samples_from_dvl(msg)
                    v = np.concatenate([smp[-1][1].velocity_frd_m_s, np.full(3, np.nan)])
                    if len(smp) == 2:
                        a = smp[0][1]
                        att = np.array([a.roll_rad, a.pitch_rad, a.yaw_rad])
                    st.frames.add(msg.header.frame_id)
                else:
                    tw = msg.twist.twist if ty in (ODOM, TWIST_COV) else msg.twist
                    v = frames.twist_flu_to_frd([tw.linear.x, tw.linear.y, tw.linear.z,
                                                 tw.angular.x, tw.angular.y, tw.angular.z])
                    st.frames.add(msg.child_frame_id if ty == ODOM else msg.header.frame_id)
                    if ty == ODOM:
                        o = msg.pose.pose.orientation
                        q = np.array([o.x, o.y, o.z, o.w])
                        if np.linalg.norm(q) > 0.5:
                            att = frames.euler_ned_from_quaternion(frames.quaternion_ros_to_marine(q))
                st.val.append(v)
                if att is not None:
                    sa = streams["attitude"]
                    sa.hdr.append(_hdr_ns(msg))
                    sa.log.append(raw.log_time_ns)
                    sa.val.append(att)
            elif role == "imu":
                av = msg.angular_velocity
                st.val.append(frames.flu_to_frd([av.x, av.y, av.z]))
                st.frames.add(msg.header.frame_id)
            elif role == "allocation":
                a, q = msg.achieved_wrench, msg.requested_wrench
                st.val.append(frames.wrench_flu_to_frd([a.force.x - q.force.x, a.force.y - q.force.y,
                                                        a.force.z - q.force.z, a.torque.x - q.torque.x,
                                                        a.torque.y - q.torque.y, a.torque.z - q.torque.z]))
            elif role == "depth":
                if ty == PRESSURE:
                    rho = float(cfg.environment.water_density_kg_m3) if cfg is not None else 1000.0
                    g = float(cfg.environment.gravity_m_s2) if cfg is not None else 9.80665
                    st.val.append([float(msg.fluid_pressure) / (rho * g)])
                else:
                    p = msg.pose.pose.position if ty == ODOM else msg.pose.position
                    st.val.append([-float(p.z)])
            st.hdr.append(_hdr_ns(msg))
            st.log.append(raw.log_time_ns)
    for role in ("wrench", "velocity"):
        if not streams[role].val:
            raise FitInputError(f"{path}: {role} topic {streams[role].topic} [{streams[role].type}] has no messages")
    body = {f for role in ("wrench", "velocity") if role in streams for f in streams[role].frames if f}
    imu_note = None
    if "imu" in streams and streams["imu"].val:
        imu_frames = {f for f in streams["imu"].frames if f}
        ref = next(iter(body)) if len(body) == 1 else "base_link"
        if len(imu_frames) == 1 and imu_frames != {ref}:
            # an angular rate only needs the IMU frame's orientation: from /tf_static when the bag has it
            rot = _static_rotation(reader, ref, next(iter(imu_frames)))
            if rot is not None:
                r_frd = frames.R_FLU_FRD @ rot @ frames.R_FLU_FRD.T  # FRD-of-body <- FRD-of-imu
                streams["imu"].val = [r_frd @ np.asarray(v) for v in streams["imu"].val]
                imu_note = f"IMU frame {next(iter(imu_frames))} rotated into {ref} with /tf_static"
            else:
                body |= imu_frames
        else:
            body |= imu_frames
    if len(body) > 1:
        where = "; ".join(f"{role} {streams[role].topic}: {', '.join(sorted(f for f in streams[role].frames if f))}"
                          for role in ("wrench", "velocity", "imu") if role in streams and streams[role].frames - {""})
        raise FitInputError(f"{path}: frames disagree ({where}): force and velocity must be in the same body frame "
                            "(base_link, REP-103 FLU); an IMU in another frame needs that frame in /tf_static")
    info = {"topics": {role: f"{s.topic} [{s.type}]" for role, s in streams.items() if role != "attitude" and s.val},
            "body_frame": (next(iter(body)) if body else "(unset: assumed base_link)")}
    if imu_note:
        info["imu_frame"] = imu_note
    for role in ("attitude", "imu", "allocation"):
        if role in streams and not streams[role].val:
            del streams[role]
    return streams, info


def _dedupe(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop samples whose value equals the previous sample's exactly (a value published again before it updated)."""
    same = np.zeros(len(t), dtype=bool)
    fin = np.where(np.isfinite(v), v, 1e300)
    same[1:] = np.all(fin[1:] == fin[:-1], axis=1)
    return t[~same], v[~same], int(same.sum())


def _spans(t: np.ndarray, gap_s: float) -> list[tuple[float, float]]:
    """Continuous spans of sample times (no spacing above gap_s)."""
    if t.size < 2:
        return []
    cut = np.flatnonzero(np.diff(t) > gap_s)
    starts = np.concatenate([[0], cut + 1])
    ends = np.concatenate([cut, [len(t) - 1]])
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends) if b > a]


def _intersect(a: list, b: list) -> list:
    out = []
    for a0, a1 in a:
        for b0, b1 in b:
            lo, hi = max(a0, b0), min(a1, b1)
            if hi > lo:
                out.append((lo, hi))
    return out


def _gap_threshold(t: np.ndarray, opts: FitOptions) -> float:
    return max(opts.gap_min_s, 5.0 * float(np.median(np.diff(t)))) if t.size > 2 else opts.gap_min_s


@dataclass
class GridStretch:
    """A continuous stretch of a bag, all six DOFs on the uniform grid (split per DOF into the fit core's
    :class:`..fit.fit_core.Chunk` by :func:`dof_records`): t (n,) s from the bag's first force time; force (n, 6) FRD
    held; velocity (n, 6) FRD interpolated (NaN where not measured); attitude (n, 3) Euler NED (NaN without one);
    shortfall (n, 6) FRD or None: the allocation's achieved less requested wrench, held as the force."""

    t: np.ndarray
    force: np.ndarray
    velocity: np.ndarray
    attitude: np.ndarray
    shortfall: np.ndarray | None = None


@dataclass
class Preprocessed:
    """A bag after preprocessing: its stretches and what was done (``notes``, for the ``preprocessing`` section)."""

    path: Path
    stretches: list[GridStretch]
    notes: dict
    force_times: np.ndarray
    force_values: np.ndarray
    vel_times: np.ndarray
    vel_values: np.ndarray
    attitude: tuple[np.ndarray, np.ndarray] | None
    spans: list
    lag_s: float = 0.0
    shortfall_values: np.ndarray | None = None


def _savgol(x: np.ndarray, h: float, window_s: float, deriv: int = 0) -> np.ndarray:
    """Savitzky-Golay smoothing (``deriv`` 0) or derivative (1) of x (n,) on a uniform grid of
    step h s, quadratic over ``window_s``; shorter than the window: x or its finite differences."""
    win = max(5, int(round(window_s / h)) | 1)
    if len(x) < win:
        return x if deriv == 0 else np.gradient(x, h)
    return signal.savgol_filter(x, win, 2, deriv=deriv, delta=h)


#: sub-samples per grid step for the force's mean over the step (:func:`_grid_stretches` with ``step_mean``)
_SUB = 10


def _grid_stretches(pre: Preprocessed, grid_s: float, step_mean: bool = False,
                    lag_s: float | None = None) -> list[GridStretch]:
    """Chunks on the uniform grid. Force: without ``step_mean`` its value at each grid time t_j; with it, its mean over
    [t_j, t_j + grid_s) from ``_SUB`` sub-samples, the value the output-error simulation holds over the step (the value
    at t_j would apply a change inside the step half a step late on average, read by the fit as a smaller inertia). With
    a thruster lag (``lag_s``, default ``pre.lag_s``) the force is filtered on the sub-grid."""
    lag_s = pre.lag_s if lag_s is None else lag_s
    ft, fv = pre.force_times, pre.force_values
    sub = _SUB if step_mean else 1
    out = []
    for lo, hi in pre.spans:
        lo2, hi2 = max(lo, ft[0]), hi
        n = int(math.floor((hi2 - lo2) / grid_s)) + 1
        if n < 3:
            continue
        t = lo2 + grid_s * np.arange(n)
        tf = lo2 + grid_s / sub * (np.arange(n * sub) + (0.5 if step_mean else 0.0))
        i = np.clip(np.searchsorted(ft, tf + 1e-9, side="right") - 1, 0, len(ft) - 1)
        force = fv[i]
        if lag_s > 0:  # the thrust follows the command through a first-order lag (exact when held)
            lag = ThrustLag(lag_s)
            force = np.column_stack([lag.over_ticks(f, grid_s / sub)[0] for f in force.T])
        force = force.reshape(n, sub, -1).mean(axis=1)
        short = None
        if pre.shortfall_values is not None:
            short = pre.shortfall_values[i].reshape(n, sub, -1).mean(axis=1)
        vel = np.column_stack([np.interp(t, pre.vel_times, pre.vel_values[:, k], left=np.nan, right=np.nan)
                               if np.isfinite(pre.vel_values[:, k]).any() else np.full(n, np.nan) for k in range(6)])
        att = np.full((n, 3), np.nan)
        if pre.attitude is not None:
            ta, va = pre.attitude
            un = np.unwrap(va, axis=0)
            att = np.column_stack([np.interp(t, ta, un[:, k], left=np.nan, right=np.nan) for k in range(3)])
        out.append(GridStretch(t, force, vel, att, short))
    return out


def preprocess_bag(path: str | Path, choice: TopicChoice, cfg: VehicleConfig | None, opts: FitOptions,
                   t0: float | None = None) -> Preprocessed:
    """Read a bag's force, velocity, angular rate, attitude (and depth) and put them on one uniform grid (module
    docstring), without the delay (the fit core's). Raises :class:`FitInputError`
    or :class:`hindrax_bringup.recording.reader.BagError`."""
    path = Path(path)
    streams, info = _read_streams(path, choice, cfg)
    notes: dict[str, Any] = {"bag": str(path), **info, "time_base": {}}
    ft, fv, notes["time_base"]["force"] = streams["wrench"].series()
    short = None
    if "allocation" in streams:  # the status in force at each force sample (0 before the first)
        at, av, tb = streams["allocation"].series()
        j = np.searchsorted(at, ft + 1e-9, side="right") - 1
        short = np.where(j[:, None] >= 0, av[np.clip(j, 0, None)], 0.0)
        notes["saturation"] = (f"{streams['allocation'].topic} ({tb}): achieved less requested wrench, held from "
                               "each status; the saturation term is a candidate where it falls short")
    known = np.all(np.isfinite(fv), axis=1)  # ThrusterPwm OUTPUT_UNKNOWN (NaN widths): the force is not known
    notes["force_unknown_dropped"] = int((~known).sum())
    if not known.any():
        raise FitInputError(f"{path}: every force sample of {streams['wrench'].topic} is unknown (NaN: ESC output "
                            "state OUTPUT_UNKNOWN)")
    vt, vv, notes["time_base"]["velocity"] = streams["velocity"].series()
    n_pub = len(vt)
    lin_t, lin_v, n_rep = _dedupe(vt, vv[:, :3])
    ok = np.all(np.isfinite(lin_v), axis=1)  # an invalid DVL report (no lock) measures nothing
    notes["velocity_invalid_dropped"] = int((~ok).sum())
    lin_t, lin_v = lin_t[ok], lin_v[ok]
    notes["velocity_repeated_values_dropped"] = n_rep
    notes["velocity_published_hz"] = round(float((n_pub - 1) / (vt[-1] - vt[0])), 3) if n_pub > 1 else None
    notes["velocity_updated_hz"] = round(float((len(lin_t) - 1) / (vt[-1] - vt[0])), 3) if n_pub > 1 else None
    # angular rate: the velocity message's own, an IMU (takes precedence) or the differentiated attitude
    ang_t, ang_v = vt, vv[:, 3:]
    source = "velocity topic"
    if not np.isfinite(ang_v).any() or not np.any(ang_v != 0.0):
        ang_t, ang_v, source = vt, np.full_like(ang_v, np.nan), "none"
    if "imu" in streams:
        ang_t, ang_v, tb = streams["imu"].series()
        source = f"IMU {streams['imu'].topic} ({tb})"
    attitude = None
    if "attitude" in streams:
        at, av, _tb = streams["attitude"].series()
        at, av, _n = _dedupe(at, av)
        if len(at) > 3:
            attitude = (at, av)
            if source == "none":
                q = Rotation.from_euler("ZYX", av[:, ::-1])
                w = (q[:-1].inv() * q[1:]).as_rotvec() / np.diff(at)[:, None]
                ang_t, ang_v = 0.5 * (at[1:] + at[:-1]), w
                source = "differentiated attitude (body rates of consecutive orientations)"
    notes["angular_rate"] = source
    ang_t, ang_v, n_rep_a = _dedupe(ang_t, ang_v)
    if source == "velocity topic":
        notes["angular_rate_repeated_values_dropped"] = n_rep_a
    # one velocity table on the linear velocity's times, angular interpolated onto them when sources differ
    if np.isfinite(ang_v).any():  # only the velocity topic's own rates are held beyond their ends
        edge = {} if source == "velocity topic" else {"left": np.nan, "right": np.nan}
        ang_on = np.column_stack([np.interp(lin_t, ang_t, ang_v[:, k], **edge) for k in range(3)])
    else:
        ang_on = np.full((len(lin_t), 3), np.nan)
    vel = np.column_stack([lin_v, ang_on])
    if "depth" in streams:
        dt_, dz, _tb = streams["depth"].series()  # dz (n, 1)
        h = float(np.median(np.diff(dt_)))
        wz = _savgol(dz[:, 0], h, 1.0, 1) if len(dt_) > 7 else np.gradient(dz[:, 0], h)
        zdot = np.interp(lin_t, dt_, wz, left=np.nan, right=np.nan)  # NED down rate of the body origin
        notes["heave_velocity"] = f"derivative of the depth {streams['depth'].topic} (Savitzky-Golay, 1 s window)"
        if attitude is not None:  # z_dot = R[2, :] nu_lin (Fossen eq. 2.40): body w from the depth rate
            eul = np.column_stack([np.interp(lin_t, attitude[0], np.unwrap(attitude[1], axis=0)[:, k])
                                   for k in range(3)])
            rot = Rotation.from_euler("ZYX", eul[:, ::-1]).as_matrix()
            vel[:, 2] = (zdot - rot[:, 2, 0] * vel[:, 0] - rot[:, 2, 1] * vel[:, 1]) / rot[:, 2, 2]
            notes["heave_velocity"] += ", rotated into the body with the attitude and the surge/sway velocity"
        else:
            vel[:, 2] = zdot
            notes["heave_velocity"] += " (no attitude: taken as the body heave velocity, exact only when level)"
    ft, fv = ft[known], fv[known]
    short = None if short is None else short[known]
    if t0 is None:
        t0 = float(ft[0])
    ft, lin_t = ft - t0, lin_t - t0
    gf, gv = _gap_threshold(ft, opts), _gap_threshold(lin_t, opts)
    # an unknown force ends a span at the last known sample whatever its length (no hold across it)
    run = np.cumsum(np.concatenate([[0], np.diff(known.astype(int)) != 0]))[known]
    force_spans = [sp for r in np.unique(run) for sp in _spans(ft[run == r], gf)]
    spans = _intersect(force_spans, _spans(lin_t, gv))
    total = max(min(ft[-1], lin_t[-1]) - max(ft[0], lin_t[0]), 0.0)
    used = sum(b - a for a, b in spans)
    notes["gaps"] = {"force_threshold_s": round(gf, 3), "velocity_threshold_s": round(gv, 3),
                     "continuous_spans": len(spans), "dropped_s": round(total - used, 3)}
    pre = Preprocessed(path, [], notes, ft, fv, lin_t, vel, None if attitude is None else (attitude[0] - t0,
                                                                                            attitude[1]), spans,
                       shortfall_values=short)
    if streams["wrench"].type == PWM:
        pre.lag_s = float(cfg.thrusters.time_constant_s)
        notes["thrust"] = (f"thrust curves and allocation matrix of {cfg.source} (ThrusterPwm: reversal and trim "
                           f"undone), widths acting esc.output_latency_s = {cfg.esc.output_latency_s:g} s "
                           f"late, first-order lag thrusters.time_constant_s = {pre.lag_s:g} s")
    pre.stretches = _grid_stretches(pre, opts.grid_s)
    return pre


# ------------------------------------------------------------------------------------------------ excitation
def excitation(pres: Sequence[Preprocessed], dof: str) -> dict:
    """{force_std, velocity_std, thresholds, excited} of a DOF over the bags' stretches."""
    k = DOFS.index(dof)
    f = np.concatenate([c.force[:, k] for p in pres for c in p.stretches]) if pres else np.zeros(0)
    v = np.concatenate([c.velocity[:, k] for p in pres for c in p.stretches]) if pres else np.zeros(0)
    v = v[np.isfinite(v)]
    fmin, vmin = EXCITATION_MIN[fit_core.excited_kind(dof)]
    fs = float(np.std(f)) if f.size else 0.0
    vs = float(np.std(v)) if v.size else 0.0
    return {"force_std": fs, "velocity_std": vs, "force_std_min": fmin, "velocity_std_min": vmin,
            "velocity_measured": bool(v.size), "excited": bool(v.size) and fs >= fmin and vs >= vmin}


# ------------------------------------------------------------------------------------------------ to the core
def dof_records(pres: Sequence[Preprocessed], dofs: Sequence[str], opts: FitOptions, moving: Sequence[str] = (),
                force_from: Sequence[str] | None = None) -> dict[str, fit_core.DofRecord]:
    """One :class:`..fit.fit_core.DofRecord` per DOF of ``dofs`` from the preprocessed bags (module docstring,
    "Preprocessing"): per continuous stretch the force held over each grid step, the velocity samples, the smoothed
    velocity and its derivative, the restoring regressor (roll, pitch), the Coriolis products, and the other ``moving``
    DOFs' velocities and commanded forces (``force_from`` when given) as coupling candidates. A ThrusterPwm force keeps
    its known lag (``thrust_model``); a wrench is ``wrench`` (delay and lag estimated by the core)."""
    out: dict[str, fit_core.DofRecord] = {}
    h = opts.grid_s
    # the force's mean over each grid step, no lag: the fit core applies delay and lag (docs/identification.md §7)
    stretches_of = [_grid_stretches(p, opts.grid_s, step_mean=True, lag_s=0.0) for p in pres]
    for dof in dofs:
        k = DOFS.index(dof)
        cross_names = tuple(d for d in moving if d != dof and d not in ("roll", "pitch"))
        force_names = tuple(d for d in (moving if force_from is None else force_from) if d != dof)
        chunks = []
        for b, (pre, chs) in enumerate(zip(pres, stretches_of)):
            vt = pre.vel_times
            vz = pre.vel_values[:, k]
            okz = np.isfinite(vz)
            for c in chs:
                v = c.velocity[:, k]
                if not np.isfinite(v).all() or len(c.t) < 20:
                    continue
                lo, hi = np.searchsorted(vt, [c.t[0], c.t[-1]])
                sel = slice(lo, hi)
                pos = (vt[sel] - c.t[0]) / h
                z = vz[sel]
                good = okz[sel]
                rest = None
                if dof in ("roll", "pitch"):
                    rest = np.nan_to_num(restoring_regressor(dof, c.attitude[:, 0], c.attitude[:, 1]))
                cross = np.column_stack([np.nan_to_num(c.velocity[:, DOFS.index(d)]) for d in cross_names]) \
                    if cross_names else None
                vs, acc = _savgol(v, h, 0.5), _savgol(v, h, 0.5, 1)
                xf = c.force[:, [DOFS.index(d) for d in force_names]].copy() if force_names else None
                chunks.append(fit_core.Chunk(c.force[:, k].copy(), vs, np.zeros_like(vs), acc, pos[good], z[good],
                                             rest, fit_core.coriolis_products(c.velocity)[:, k, :], cross, b,
                                             float(c.t[0]), cross_force=xf,
                                             shortfall=None if c.shortfall is None else c.shortfall[:, k].copy()))
        src = "thrust_model" if any(p.lag_s > 0 or "thrust" in p.notes for p in pres) else "wrench"
        lag = max((p.lag_s for p in pres), default=0.0)
        out[dof] = fit_core.DofRecord(dof, h, "velocity", chunks, src, lag, cross_names, force_names=force_names,
                                      run_count=len(pres))
    return out

