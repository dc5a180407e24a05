"""Identification from any bag: force and velocity by message type, prediction-error fit, cross-validation.

The pure pipeline behind ``hindrax ident fit`` (:mod:`hindrax_ident.commands.ident_fit`); no ROS runtime (bags are
decoded by :class:`hindrax_drivers.recording.reader.BagReader` from their stored definitions).

Inputs (:data:`ACCEPTED`), every vector converted to body FRD with :mod:`hindrax_drivers.frames` (messages are
REP-103 FLU in ``base_link``):

* force: ``geometry_msgs/msg/WrenchStamped`` (commanded or measured wrench about base_link), or our
  ``hindrax_msgs/msg/ThrusterPwm`` through the configured thrust curves and allocation matrix
  (:func:`.signals.thrust_of_written_widths`; needs ``--config``; the widths act ``esc.output_latency_s`` late);
* velocity: ``nav_msgs/msg/Odometry`` (twist in ``child_frame_id``), ``TwistWithCovarianceStamped``,
  ``TwistStamped`` or our ``hindrax_msgs/msg/Dvl`` (:func:`.signals.samples_from_dvl`);
* angular rate: the velocity message's angular part, else ``sensor_msgs/msg/Imu`` (``--imu-topic``, which then
  takes precedence; found by type with a Dvl velocity; an IMU frame other than the body frame is rotated with the
  bag's ``/tf_static``, else refused), else the attitude differentiated (odometry pose or DVL attitude);
* depth (optional, ``--depth-topic``): ``sensor_msgs/msg/FluidPressure`` or the pose of an Odometry/PoseStamped;
  when given, the heave velocity is its derivative (Savitzky-Golay) instead of the velocity topic's.

Preprocessing (:class:`Preprocessed`, reported in the ``preprocessing`` section): per topic, header stamps when
every stamp is set, else receive (log) times; messages sorted by that time; repeated velocity values (a velocity
that updates slower than it is published) dropped, keeping the first of each run; gaps longer than
``max(gap_min_s, 5 x median spacing)`` in force or velocity cut the record (nothing is interpolated across them);
force held (zero-order: for the fit its mean over each step, :func:`_grid_chunks`) and velocity linearly
interpolated on a uniform grid of ``grid_s``; the delay between force
and velocity chosen by minimising the equation-error residual over delays 0..``max_delay_s`` (a cross-correlation
weighted by the model, sub-grid by a parabola through the minimum), then applied to the force times.

Model and fit (per DOF, the campaign's model, :mod:`.output_error`): ``M nu_dot + k_q |nu| nu + k_l nu + b
(+ k_r s(eta)) = tau``, heave by direction (``k_q+, k_q-, k_l+, k_l-``) when both directions are excited, else one
pair for both. Start: equation-error least squares on Savitzky-Golay derivatives; then segment-wise output error
(:class:`.output_error.OutputErrorFit`): the record is cut into ``segment_s`` (10 s) segments, each simulated
open-loop from the force and re-initialised from the measured velocity at its start. Several bags are fitted jointly
(their segments pooled). The other DOFs' motion enters through the Coriolis and centripetal terms of a diagonal
rigid + added inertia (:func:`coupling_force`, Fossen 2011): the force of each DOF is taken less C(nu) nu computed
from the measured velocities and the equation-error inertias of the fitted DOFs (two passes), so a piloted run that
turns while it translates is not read as extra damping (measured on the virtual pool: without it the yaw quadratic
damping came out 0.03 instead of 0.55 kg m^2 and the surge one 16 % low). A DOF whose force or velocity standard deviation is below :data:`EXCITATION_MIN` is
"not excited" (reported with both numbers).

Validation (issue 18): K-fold by bag (by contiguous blocks of segments with one bag) and ``holdout`` bags. Per DOF
``nrmse`` = RMS(v_pred - v_meas) / std(v_meas) over the validation samples, v_pred the model's simulation from the
recorded force (less the coupling terms of the measured velocities) re-initialised from the measured velocity at
each segment's start; ``nrmse_hold``: v_pred held at
the segment's initial value; ``nrmse_zero``: v_pred = 0. Fold parameters give the spread beside each interval.

Intervals (:func:`honest_interval`, docs/identification.md §7): per parameter the larger of the output-error std and
the delete-a-group jackknife std of the K fold estimates (Efron and Stein 1981; Shao and Tu 1995 §2.3), with
``std_source`` saying which; ci95 from it (Student t, n_segments - 1 or K - 1 degrees of freedom).

Errors: :class:`FitInputError` (one line: the topic, the type found, the types accepted; disagreeing frame ids;
how much data is needed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy import signal, stats
from scipy.spatial.transform import Rotation

from hindrax_drivers import frames
from hindrax_drivers.config import DOFS, VehicleConfig

from ..estimation.least_squares import EstimationError
from .estimators import parameter_names, parameter_units, regressor_matrix, restoring_regressor, rigid_inertia
from .output_error import DofModel, OutputErrorFit, rk4_step
from .signals import samples_from_dvl, thrust_of_written_widths

__all__ = ["ACCEPTED", "EXCITATION_MIN", "FitInputError", "FitOptions", "TopicChoice", "Preprocessed", "BagSegments",
           "preprocess_bag", "fit_bags", "fit_dof", "jackknife_std", "honest_interval", "DofFit", "FitResult",
           "CONFIG_READY_REASON"]

WRENCH, PWM = "geometry_msgs/msg/WrenchStamped", "hindrax_msgs/msg/ThrusterPwm"
ODOM, TWIST_COV, TWIST, DVL = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistWithCovarianceStamped",
                               "geometry_msgs/msg/TwistStamped", "hindrax_msgs/msg/Dvl")
IMU, PRESSURE, POSE = "sensor_msgs/msg/Imu", "sensor_msgs/msg/FluidPressure", "geometry_msgs/msg/PoseStamped"

#: role -> accepted message types
ACCEPTED: dict[str, tuple[str, ...]] = {
    "wrench": (WRENCH, PWM),
    "velocity": (ODOM, TWIST_COV, TWIST, DVL),
    "imu": (IMU,),
    "depth": (PRESSURE, ODOM, POSE),
}

#: (force std, velocity std) below which a DOF is "not excited": translational (N, m/s), rotational (N m, rad/s)
EXCITATION_MIN = {"translational": (0.5, 0.03), "rotational": (0.05, 0.05)}


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
    """grid_s: resampling step, s; segment_s: output-error segment, s; max_delay_s: largest delay searched, s;
    gap_min_s: shortest spacing treated as a gap, s; folds: K of the cross-validation."""

    grid_s: float = 0.05
    segment_s: float = 10.0
    max_delay_s: float = 0.5
    gap_min_s: float = 0.5
    folds: int = 3


def _norm(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _select(path: Path, topics: dict[str, str], role: str, given: str | None, required: bool) -> tuple[str, str] | None:
    accepted = ACCEPTED[role]
    if given is not None:
        name = given if given in topics else _norm(given) if _norm(given) in topics else None
        if name is None:
            cands = [t for t, ty in topics.items() if ty in accepted]
            raise FitInputError(f"{path}: {role} topic {given} not in the bag (accepted types: {', '.join(accepted)}; "
                                f"topics of those types: {', '.join(cands) or 'none'})")
        if topics[name] not in accepted:
            raise FitInputError(f"{path}: {role} topic {name} has type {topics[name]}; accepted: {', '.join(accepted)}")
        return name, topics[name]
    cands = [t for t, ty in topics.items() if ty in accepted]
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
    is installed (standard messages: several times faster), else the reader's mcap_ros2 decoding from the stored
    definitions (:meth:`hindrax_drivers.recording.reader.BagReader.decoded`)."""
    import importlib

    classes: dict[str, Any] = {}
    for t in topics:
        pkg, _sub, name = reader.topics[t].partition("/msg/")
        try:
            classes[t] = getattr(importlib.import_module(f"{pkg}.msg"), name)
        except (ImportError, AttributeError, ValueError):
            classes[t] = None
    if any(c is None for c in classes.values()):
        yield from reader.decoded(list(topics))
        return
    from rclpy.serialization import deserialize_message

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

    def times(self) -> tuple[np.ndarray, str]:
        """Seconds (float64, relative values kept exact enough) and the time base used."""
        hdr = np.asarray(self.hdr, dtype=np.int64)
        if hdr.size and np.all(hdr > 0):
            return hdr.astype(np.float64) * 1e-9, "header stamps"
        return np.asarray(self.log, dtype=np.int64).astype(np.float64) * 1e-9, "receive times (header stamps unset)"


def _read_streams(path: Path, choice: TopicChoice, cfg: VehicleConfig | None) -> tuple[dict[str, _Stream], dict]:
    from hindrax_drivers.recording.reader import BagReader

    reader = BagReader(path)
    topics = reader.topics
    sel = {"wrench": _select(path, topics, "wrench", choice.wrench, True),
           "velocity": _select(path, topics, "velocity", choice.velocity, True),
           "imu": _select(path, topics, "imu", choice.imu, False) if choice.imu is not None else None,
           "depth": _select(path, topics, "depth", choice.depth, False) if choice.depth is not None else None}
    if sel["wrench"][1] == PWM and cfg is None:
        raise FitInputError(f"{path}: force from {sel['wrench'][0]} [{PWM}] needs the thrust curves: give --config")
    if sel["velocity"][1] == DVL and sel["imu"] is None:
        imu = _select(path, topics, "imu", None, False)
        sel["imu"] = imu
    by_topic: dict[str, list[str]] = {}
    for role, s in sel.items():
        if s is not None:
            by_topic.setdefault(s[0], []).append(role)
    streams: dict[str, _Stream] = {role: _Stream(s[0], s[1]) for role, s in sel.items() if s is not None}
    streams["attitude"] = _Stream(sel["velocity"][0], sel["velocity"][1])
    pwm = None
    if sel["wrench"][1] == PWM:
        from hindrax_drivers.allocation.core import AllocationCore

        core = AllocationCore(cfg)
        pwm = (core.allocator.curves[0], np.asarray(core.matrix_frd, dtype=float),
               np.full(len(cfg.thrusters.thrusters), float(cfg.thrusters.pulse_width_neutral_us)),
               int(round(float(cfg.flat["esc.output_latency_s"]) * 1e9)))
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
                    widths = np.asarray(msg.pulse_width_us, dtype=float) if msg.armed else neutral
                    st.val.append(matrix @ thrust_of_written_widths(cfg, curve, widths))
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
            elif role == "depth":
                if ty == PRESSURE:
                    rho = float(cfg.water_density_kg_m3) if cfg is not None else 1000.0
                    g = float(cfg.gravity_m_s2) if cfg is not None else 9.80665
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
    if not streams["attitude"].val:
        del streams["attitude"]
    if "imu" in streams and not streams["imu"].val:
        del streams["imu"]
    return streams, info


def _dedupe(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Drop samples whose value equals the previous sample's exactly (a value published again before it updated)."""
    same = np.zeros(len(t), dtype=bool)
    fin = np.where(np.isfinite(v), v, 1e300)
    same[1:] = np.all(fin[1:] == fin[:-1], axis=1)
    return t[~same], v[~same], int(same.sum())


def _sorted(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    o = np.argsort(t, kind="stable")
    t, v = t[o], v[o]
    keep = np.ones(len(t), dtype=bool)
    keep[1:] = np.diff(t) > 0
    return t[keep], v[keep]


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
class Chunk:
    """A continuous stretch on the uniform grid: t (n,) s from the bag's first force time; force (n, 6) FRD held;
    velocity (n, 6) FRD interpolated (NaN where not measured); attitude (n, 3) Euler NED (NaN without one)."""

    t: np.ndarray
    force: np.ndarray
    velocity: np.ndarray
    attitude: np.ndarray


@dataclass
class Preprocessed:
    """A bag after preprocessing: its chunks and what was done (``notes``, for the ``preprocessing`` section)."""

    path: Path
    chunks: list[Chunk]
    notes: dict
    force_times: np.ndarray
    force_values: np.ndarray
    vel_times: np.ndarray
    vel_values: np.ndarray
    attitude: tuple[np.ndarray, np.ndarray] | None
    spans: list
    lag_s: float = 0.0


def _derivative(t: np.ndarray, x: np.ndarray, window_s: float = 0.5) -> np.ndarray:
    """Savitzky-Golay derivative of x (n,) sampled on the uniform grid t."""
    h = float(np.median(np.diff(t)))
    win = max(5, int(round(window_s / h)) | 1)
    if len(x) < win:
        return np.gradient(x, h)
    return signal.savgol_filter(x, win, 2, deriv=1, delta=h)


#: sub-samples per grid step for the force's mean over the step (:func:`_grid_chunks` with ``step_mean``)
_SUB = 10


def _grid_chunks(pre: Preprocessed, delay_s: float, grid_s: float, step_mean: bool = False) -> list[Chunk]:
    """Chunks on the uniform grid. Force: without ``step_mean`` its value at each grid time t_j (the delay
    estimate's convention, :func:`estimate_delay`: the 50 ms of the piloted test bag come out 49 ms); with it, its
    mean over [t_j, t_j + grid_s) from ``_SUB`` sub-samples, the value the output-error simulation holds over the step
    (:func:`apply_delay`). The value at t_j applies a change inside the step at its end, half a step late on average,
    and the fit reads that as a smaller inertia (campaign bag, 20 Hz grid: surge -3.3 %, sway -5.4 %, yaw -9.7 %;
    with the step mean -0.5 %, +0.3 %, -4 %). With a thruster lag the force is filtered on the sub-grid."""
    ft, fv = pre.force_times + delay_s, pre.force_values
    sub = _SUB if step_mean else 1
    chunks = []
    for lo, hi in pre.spans:
        lo2, hi2 = max(lo, ft[0]), hi
        n = int(math.floor((hi2 - lo2) / grid_s)) + 1
        if n < 3:
            continue
        t = lo2 + grid_s * np.arange(n)
        tf = lo2 + grid_s / sub * (np.arange(n * sub) + (0.5 if step_mean else 0.0))
        i = np.clip(np.searchsorted(ft, tf + 1e-9, side="right") - 1, 0, len(ft) - 1)
        force = fv[i]
        if pre.lag_s > 0:  # the thrust follows the commanded force through a first-order lag (exact for a held input)
            k = math.exp(-grid_s / sub / pre.lag_s)
            force = signal.lfilter([0.0, 1.0 - k], [1.0, -k], force - force[0], axis=0) + force[0]
        force = force.reshape(n, sub, -1).mean(axis=1)
        vel = np.column_stack([np.interp(t, pre.vel_times, pre.vel_values[:, k], left=np.nan, right=np.nan)
                               if np.isfinite(pre.vel_values[:, k]).any() else np.full(n, np.nan) for k in range(6)])
        att = np.full((n, 3), np.nan)
        if pre.attitude is not None:
            ta, va = pre.attitude
            un = np.unwrap(va, axis=0)
            att = np.column_stack([np.interp(t, ta, un[:, k], left=np.nan, right=np.nan) for k in range(3)])
        chunks.append(Chunk(t, force, vel, att))
    return chunks


def preprocess_bag(path: str | Path, choice: TopicChoice, cfg: VehicleConfig | None, opts: FitOptions,
                   t0: float | None = None) -> Preprocessed:
    """Read a bag's force, velocity, angular rate, attitude (and depth) and put them on one uniform grid (module
    docstring), without the delay (:func:`estimate_delay` then :func:`apply_delay`). Raises :class:`FitInputError`
    or :class:`hindrax_drivers.recording.reader.BagError`."""
    path = Path(path)
    streams, info = _read_streams(path, choice, cfg)
    notes: dict[str, Any] = {"bag": str(path), **info, "time_base": {}}
    ft, tb = streams["wrench"].times()
    notes["time_base"]["force"] = tb
    ft, fv = _sorted(ft, np.asarray(streams["wrench"].val, dtype=float))
    vt, tb = streams["velocity"].times()
    notes["time_base"]["velocity"] = tb
    vt, vv = _sorted(vt, np.asarray(streams["velocity"].val, dtype=float))
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
        it, tb = streams["imu"].times()
        ang_t, ang_v = _sorted(it, np.asarray(streams["imu"].val, dtype=float))
        source = f"IMU {streams['imu'].topic} ({tb})"
    attitude = None
    if "attitude" in streams:
        at, _tb = streams["attitude"].times()
        at, av = _sorted(at, np.asarray(streams["attitude"].val, dtype=float))
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
    if np.isfinite(ang_v).any():
        ang_on = np.column_stack([np.interp(lin_t, ang_t, ang_v[:, k], left=np.nan, right=np.nan) for k in range(3)])
        if source == "velocity topic":
            ang_on = np.column_stack([np.interp(lin_t, ang_t, ang_v[:, k]) for k in range(3)])
    else:
        ang_on = np.full((len(lin_t), 3), np.nan)
    vel = np.column_stack([lin_v, ang_on])
    if "depth" in streams:
        dt_, tb = streams["depth"].times()
        dt_, dz = _sorted(dt_, np.asarray(streams["depth"].val, dtype=float)[:, 0:1])
        h = float(np.median(np.diff(dt_)))
        wz = _derivative(dt_, dz[:, 0], 1.0) if len(dt_) > 7 else np.gradient(dz[:, 0], h)
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
    if t0 is None:
        t0 = float(ft[0])
    ft, lin_t = ft - t0, lin_t - t0
    gf, gv = _gap_threshold(ft, opts), _gap_threshold(lin_t, opts)
    spans = _intersect(_spans(ft, gf), _spans(lin_t, gv))
    total = max(min(ft[-1], lin_t[-1]) - max(ft[0], lin_t[0]), 0.0)
    used = sum(b - a for a, b in spans)
    notes["gaps"] = {"force_threshold_s": round(gf, 3), "velocity_threshold_s": round(gv, 3),
                     "continuous_spans": len(spans), "dropped_s": round(total - used, 3)}
    pre = Preprocessed(path, [], notes, ft, fv, lin_t, vel, None if attitude is None else (attitude[0] - t0,
                                                                                            attitude[1]), spans)
    if streams["wrench"].type == PWM:
        pre.lag_s = float(cfg.thrusters.time_constant_s)
        notes["thrust"] = (f"thrust curves and allocation matrix of {cfg.source} (ThrusterPwm: reversal and trim "
                           f"undone), widths acting esc.output_latency_s = {cfg.flat['esc.output_latency_s']:g} s "
                           f"late, first-order lag thrusters.time_constant_s = {pre.lag_s:g} s")
    pre.chunks = _grid_chunks(pre, 0.0, opts.grid_s)
    return pre


# ------------------------------------------------------------------------------------------------ excitation
def _kind(dof: str) -> str:
    return "rotational" if dof in ("roll", "pitch", "yaw") else "translational"


def excitation(pres: Sequence[Preprocessed], dof: str) -> dict:
    """{force_std, velocity_std, thresholds, excited} of a DOF over the bags' chunks."""
    k = DOFS.index(dof)
    f = np.concatenate([c.force[:, k] for p in pres for c in p.chunks]) if pres else np.zeros(0)
    v = np.concatenate([c.velocity[:, k] for p in pres for c in p.chunks]) if pres else np.zeros(0)
    v = v[np.isfinite(v)]
    fmin, vmin = EXCITATION_MIN[_kind(dof)]
    fs = float(np.std(f)) if f.size else 0.0
    vs = float(np.std(v)) if v.size else 0.0
    return {"force_std": fs, "velocity_std": vs, "force_std_min": fmin, "velocity_std_min": vmin,
            "velocity_measured": bool(v.size), "excited": bool(v.size) and fs >= fmin and vs >= vmin}


# ------------------------------------------------------------------------------------------------ delay
def _ee_residual(pres: Sequence[Preprocessed], dofs: Sequence[str], shift: int, kmax: int) -> float:
    total = 0.0
    for dof in dofs:
        k = DOFS.index(dof)
        rows, rhs = [], []
        for p in pres:
            for c in p.chunks:
                n = len(c.t)
                if n < kmax + 20:
                    continue
                v = c.velocity[:, k]
                if not np.isfinite(v).all():
                    continue
                a = _derivative(c.t, v)
                sl = slice(kmax, n)
                f = c.force[kmax - shift:n - shift, k]
                rows.append(regressor_matrix(_model_dof(dof, True), a[sl], v[sl], None))
                rhs.append(f)
        if not rows:
            continue
        X, y = np.concatenate(rows), np.concatenate(rhs)
        th, *_ = np.linalg.lstsq(X, y, rcond=None)
        total += float(np.mean((y - X @ th) ** 2) / max(np.var(y), 1e-12))
    return total


def estimate_delay(pres: Sequence[Preprocessed], dofs: Sequence[str], opts: FitOptions) -> tuple[float, list]:
    """Delay (s) of the velocity after the force: the shift of the force minimising the summed normalised
    equation-error residual of ``dofs`` over 0..max_delay_s (grid steps), refined by a parabola. Returns
    (delay, [(delay, residual)])."""
    kmax = int(round(opts.max_delay_s / opts.grid_s))
    res = [_ee_residual(pres, dofs, s, kmax) for s in range(kmax + 1)]
    j = int(np.argmin(res))
    d = float(j)
    if 0 < j < kmax:
        a, b, c = res[j - 1], res[j], res[j + 1]
        den = a - 2 * b + c
        if den > 0:
            d = j + 0.5 * (a - c) / den
    return d * opts.grid_s, [(round(s * opts.grid_s, 4), round(r, 6)) for s, r in enumerate(res)]


def apply_delay(pre: Preprocessed, delay_s: float, opts: FitOptions) -> None:
    """Rebuild the chunks with the force times moved by ``delay_s``, the force the mean over each grid step (the
    value the output-error fit holds over it, :func:`_grid_chunks`)."""
    pre.chunks = _grid_chunks(pre, delay_s, opts.grid_s, step_mean=True)
    pre.notes["delay_s"] = round(delay_s, 4)


# ------------------------------------------------------------------------------------------------ segments
@dataclass
class BagSegments:
    """Equal segments of ``L`` grid ticks over all bags: force, velocity (m, L, 6), attitude (m, L, 3), bag (m,)
    index of the bag, valid (m, L) True on ticks inside the record (False in the padding of a last segment)."""

    force: np.ndarray
    velocity: np.ndarray
    attitude: np.ndarray
    bag: np.ndarray
    valid: np.ndarray
    h: float

    @classmethod
    def build(cls, pres: Sequence[Preprocessed], opts: FitOptions, min_fraction: float = 0.5) -> "BagSegments":
        """Cut every chunk into segments of ``segment_s``; a last part of at least ``min_fraction`` of a segment is
        kept (padded with the last force and no measurement)."""
        L = int(round(opts.segment_s / opts.grid_s))
        F, V, A, B, M = [], [], [], [], []
        for b, p in enumerate(pres):
            for c in p.chunks:
                n = len(c.t)
                for s0 in range(0, n, L):
                    m = min(L, n - s0)
                    if m < max(10, min_fraction * L):
                        continue
                    if not np.isfinite(c.velocity[s0]).any():
                        continue
                    pad = L - m
                    f = np.concatenate([c.force[s0:s0 + m], np.repeat(c.force[s0 + m - 1:s0 + m], pad, axis=0)])
                    v = np.concatenate([c.velocity[s0:s0 + m], np.full((pad, 6), np.nan)])
                    a = np.concatenate([c.attitude[s0:s0 + m], np.repeat(c.attitude[s0 + m - 1:s0 + m], pad, axis=0)])
                    F.append(f), V.append(v), A.append(a), B.append(b), M.append(np.arange(L) < m)
        if not F:
            return cls(np.zeros((0, L, 6)), np.zeros((0, L, 6)), np.zeros((0, L, 3)), np.zeros(0, int),
                       np.zeros((0, L), bool), opts.grid_s)
        return cls(np.array(F), np.array(V), np.array(A), np.array(B), np.array(M), opts.grid_s)

    def __len__(self) -> int:
        return self.force.shape[0]

    def with_coupling(self, inertia: np.ndarray) -> "BagSegments":
        """The same segments with the force less :func:`coupling_force` of the measured velocities."""
        return BagSegments(self.force - coupling_force(self.velocity, inertia), self.velocity, self.attitude,
                           self.bag, self.valid, self.h)

    def subset(self, idx) -> "BagSegments":
        return BagSegments(self.force[idx], self.velocity[idx], self.attitude[idx], self.bag[idx], self.valid[idx],
                           self.h)


def coupling_force(velocity: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """Coriolis and centripetal terms C(nu) nu (..., 6) of a diagonal rigid + added inertia ``inertia`` (6,) with the
    body origin at the CG (Fossen 2011 eqs. 6.43 and 6.45 with M = diag(M1..M6); docs/identification.md §1.A):
    ``[q M3 w - r M2 v, r M1 u - p M3 w, p M2 v - q M1 u, (M3 - M2) v w + (M6 - M5) q r,
    (M1 - M3) u w + (M4 - M6) p r, (M2 - M1) u v + (M5 - M4) p q]`` for nu = [u v w p q r] (..., 6), FRD.
    A term whose inertia is unknown (NaN: the DOF was not fitted) is left out; NaN velocities count as 0."""
    u, v, w, p, q, r = np.moveaxis(np.nan_to_num(np.asarray(velocity, dtype=float)), -1, 0)
    M1, M2, M3, M4, M5, M6 = (float(x) for x in inertia)

    def t(coef, a, b):
        return 0.0 if not math.isfinite(coef) else coef * a * b

    out = [t(M3, q, w) - t(M2, r, v), t(M1, r, u) - t(M3, p, w), t(M2, p, v) - t(M1, q, u),
           t(M3 - M2, v, w) + t(M6 - M5, q, r), t(M1 - M3, u, w) + t(M4 - M6, p, r),
           t(M2 - M1, u, v) + t(M5 - M4, p, q)]
    return np.stack([np.broadcast_to(np.asarray(o, dtype=float), u.shape) for o in out], axis=-1)


def _model_dof(dof: str, by_direction: bool) -> str:
    """The :func:`.output_error.model_terms` name: heave with one pair for both directions is the symmetric model."""
    return dof if dof != "heave" or by_direction else "heave_one_direction"


def _restoring(seg: BagSegments, dof: str) -> np.ndarray | None:
    if dof not in ("roll", "pitch"):
        return None
    return restoring_regressor(dof, seg.attitude[..., 0], seg.attitude[..., 1])


def _names(dof: str, by_direction: bool) -> list[str]:
    return parameter_names(dof) if dof != "heave" or by_direction else ["inertia", "quadratic_damping",
                                                                        "linear_damping", "bias"]


def _equation_error(seg: BagSegments, dof: str, model: str) -> np.ndarray:
    k = DOFS.index(dof)
    rows, rhs = [], []
    rest = _restoring(seg, dof)
    for i in range(len(seg)):
        ok = seg.valid[i] & np.isfinite(seg.velocity[i, :, k])
        if ok.sum() < 10:
            continue
        t = np.arange(ok.sum()) * seg.h
        v = seg.velocity[i, ok, k]
        a = _derivative(t, v)
        rows.append(regressor_matrix(model, a, v, None if rest is None else rest[i, ok]))
        rhs.append(seg.force[i, ok, k])
    X, y = np.concatenate(rows), np.concatenate(rhs)
    th, *_ = np.linalg.lstsq(X, y, rcond=None)
    return th


def _fit(seg: BagSegments, dof: str, model: str, theta0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Segment-wise output error on ``seg`` (theta, covariance) from ``theta0`` (default: the equation-error
    estimate). Raises EstimationError."""
    k = DOFS.index(dof)
    m, L = seg.valid.shape
    z = np.where(seg.valid, seg.velocity[..., k], np.nan).reshape(-1)
    f = seg.force[..., k].reshape(-1)
    rest = _restoring(seg, dof)
    rest = None if rest is None else np.nan_to_num(rest).reshape(-1)
    v_start = z.copy()
    t = np.arange(m * L) * seg.h
    fit = OutputErrorFit(model, t, f, f, 0.0, rest, z, "velocity", np.zeros(m * L), v_start, L * seg.h)
    th0 = _equation_error(seg, dof, model) if theta0 is None else np.asarray(theta0, dtype=float)
    res = fit.fit(th0)
    return res.theta, res.covariance


def predict(seg: BagSegments, dof: str, model: str, theta: np.ndarray) -> np.ndarray:
    """Open-loop velocity (m, L) of every segment from its measured initial velocity under the force (held over each
    grid step; :func:`.output_error.rk4_step`, as :meth:`.output_error.OutputErrorFit.simulate` without a lag)."""
    k = DOFS.index(dof)
    mdl = DofModel(model, np.asarray(theta, dtype=float))
    m, L = seg.valid.shape
    rest = _restoring(seg, dof)
    v = seg.velocity[:, 0, k].copy()
    x = np.zeros(m)
    out = np.empty((m, L))
    out[:, 0] = v
    for i in range(L - 1):
        f = seg.force[:, i, k]
        r = (None, None, None) if rest is None else (rest[:, i], 0.5 * (rest[:, i] + rest[:, i + 1]), rest[:, i + 1])
        v, x = rk4_step(mdl.acceleration, v, x, seg.h, (f, f, f), r)
        out[:, i + 1] = v
    return out


def validation_measures(seg: BagSegments, dof: str, v_pred: np.ndarray) -> dict:
    """nrmse, nrmse_hold, nrmse_zero and samples over the measured ticks after each segment's first (issue 18);
    segments whose first tick has no measured velocity (no initial value) are left out, as in the fit."""
    k = DOFS.index(dof)
    z = seg.velocity[..., k]
    mask = seg.valid & np.isfinite(z) & np.isfinite(z[:, :1])  # a segment without an initial value is not simulated
    mask[:, 0] = False
    zm = z[mask]
    if zm.size < 2:
        return {"nrmse": math.nan, "nrmse_hold": math.nan, "nrmse_zero": math.nan, "samples": int(zm.size)}
    sd = float(np.std(zm))
    hold = np.broadcast_to(z[:, :1], z.shape)[mask]

    def rms(e):
        return float(np.sqrt(np.mean(e ** 2)))

    return {"nrmse": rms(v_pred[mask] - zm) / sd, "nrmse_hold": rms(hold - zm) / sd, "nrmse_zero": rms(zm) / sd,
            "samples": int(zm.size)}


# ------------------------------------------------------------------------------------------------ results
@dataclass
class DofFit:
    """One DOF: status "fitted" | "not excited" | "failed"; excitation numbers; model name; parameter names,
    theta, std, ci95, fold thetas; validation {cv, holdout}; v_meas/v_pred (m, L) of the validation data for the
    report; reason when not fitted."""

    dof: str
    status: str
    excitation: dict
    model: str = ""
    names: list = field(default_factory=list)
    theta: np.ndarray | None = None
    std: np.ndarray | None = None
    ci95: np.ndarray | None = None
    segments: int = 0
    folds: list = field(default_factory=list)
    validation: dict = field(default_factory=dict)
    plot: dict = field(default_factory=dict)
    reason: str = ""
    std_source: list = field(default_factory=list)
    oe_std: np.ndarray | None = None
    jackknife_std: np.ndarray | None = None


@dataclass
class FitResult:
    """Per-DOF fits, the preprocessing notes and the validation design."""

    dofs: dict
    preprocessing: dict
    design: str


def jackknife_std(fold_thetas) -> np.ndarray:
    """Delete-a-group jackknife standard deviation (p,) of the full-data estimate from ``fold_thetas`` (K, p), the
    estimates each fitted without one of K disjoint groups (the K cross-validation folds):
    ``sqrt((K - 1) / K * sum_k (theta_k - mean_k theta_k)^2)`` (Efron and Stein 1981; Shao and Tu 1995 §2.3, the
    delete-d jackknife with the groups as the deleted sets; docs/references.md [Efron-Stein1981], [Shao-Tu1995]).
    Raises ValueError with fewer than 2 fold estimates."""
    th = np.asarray(fold_thetas, dtype=float)
    if th.ndim != 2 or th.shape[0] < 2:
        raise ValueError(f"jackknife: {th.shape[0] if th.ndim == 2 else 0} fold estimates; at least 2 are needed")
    k = th.shape[0]
    return np.sqrt((k - 1) / k * np.sum((th - th.mean(axis=0)) ** 2, axis=0))


def honest_interval(theta: np.ndarray, oe_std: np.ndarray, fold_thetas, n_segments: int
                    ) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray | None]:
    """Per parameter, std = max(output-error std, jackknife std) and its 95 % interval (docs/identification.md §7).

    theta, oe_std (p,): the full fit and its own std (:class:`.output_error.OutputErrorFit`: residual variance,
    AR(1) and cluster-robust widening); fold_thetas (K, p): the cross-validation folds' estimates (fewer than 2:
    the output-error std alone). The output-error std assumes the model's residuals independent across segments;
    a misfit that drifts over minutes (a slowly varying disturbance, a model error that depends on the manoeuvre)
    moves the estimate from one part of the record to another, which the jackknife of the folds sees. The larger
    of the two is taken (both estimate the same variance: summing them would double it when both are right).
    ci95 = theta +- t std, t the Student quantile with n_segments - 1 degrees of freedom for the output-error std,
    K - 1 for the jackknife's (a variance estimated from K group estimates).
    Returns (std (p,), ci95 (p, 2), std_source per parameter ``"output_error"`` | ``"jackknife"``, jackknife std
    (p,) or None)."""
    theta = np.asarray(theta, dtype=float)
    oe_std = np.asarray(oe_std, dtype=float)
    t_oe = float(stats.t.ppf(0.975, max(n_segments - 1, 1)))
    folds = np.asarray(fold_thetas, dtype=float) if len(fold_thetas) else np.zeros((0, theta.size))
    if folds.shape[0] < 2:
        return oe_std.copy(), np.column_stack([theta - t_oe * oe_std, theta + t_oe * oe_std]), \
            ["output_error"] * theta.size, None
    jk = jackknife_std(folds)
    t_jk = float(stats.t.ppf(0.975, folds.shape[0] - 1))
    use_jk = jk > oe_std
    std = np.where(use_jk, jk, oe_std)
    half = np.where(use_jk, t_jk, t_oe) * std
    return std, np.column_stack([theta - half, theta + half]), \
        ["jackknife" if u else "output_error" for u in use_jk], jk


def fit_dof(seg: BagSegments, dof: str, model: str, names: list, folds: Sequence[np.ndarray], excitation_: dict,
            theta0: np.ndarray | None = None) -> DofFit:
    """Output-error fit of ``dof`` on all of ``seg``, refitted without each index set of ``folds`` (the fold
    estimates, each validated on its left-out segments), and the interval of :func:`honest_interval`.
    Raises EstimationError, LinAlgError or ValueError when the full fit fails."""
    k = DOFS.index(dof)
    theta, cov = _fit(seg, dof, model, theta0)
    oe_std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    r = DofFit(dof, "fitted", excitation_, model, names, theta, oe_std, None, len(seg))
    preds = []
    for idx in folds:
        train = np.setdiff1d(np.arange(len(seg)), idx)
        try:
            th_f, _ = _fit(seg.subset(train), dof, model, theta)  # from the full fit: fewer iterations
        except (EstimationError, np.linalg.LinAlgError, ValueError):
            continue
        r.folds.append(th_f)
        vs = seg.subset(idx)
        preds.append((vs, predict(vs, dof, model, th_f)))
    r.std, r.ci95, r.std_source, r.jackknife_std = honest_interval(theta, oe_std, r.folds, len(seg))
    r.oe_std = oe_std
    if preds:
        cat = BagSegments(*(np.concatenate([getattr(p[0], a) for p in preds]) for a in
                            ("force", "velocity", "attitude", "bag", "valid")), seg.h)
        vp = np.concatenate([p[1] for p in preds])
        r.validation["cross_validation"] = {**validation_measures(cat, dof, vp), "folds": len(r.folds)}
        r.plot = {"data": "cross-validation", "measured": cat.velocity[..., k], "predicted": vp, "valid": cat.valid}
    return r


def _folds(seg: BagSegments, n_bags: int, k: int, dof: str | None = None) -> list[np.ndarray]:
    """Validation index sets: by bag when there are several bags, else contiguous blocks of segments. With ``dof``
    (one bag), the segments that move it (RMS velocity within the segment at least the velocity threshold of
    :data:`EXCITATION_MIN`) and the others are each cut into k contiguous blocks, block j of both forming fold j: a
    campaign that moves one DOF after the other would otherwise leave a fold with none of that DOF's motion
    (its estimate then is the starting value or diverges, and the jackknife of the folds means nothing)."""
    if n_bags >= 2:
        k = max(2, min(k, n_bags))
        return [np.flatnonzero(seg.bag % k == j) for j in range(k)]
    m = len(seg)
    k = max(2, min(k, m))
    if dof is None:
        return [a for a in np.array_split(np.arange(m), k) if a.size]
    i = DOFS.index(dof)
    v_min = EXCITATION_MIN[_kind(dof)][1]
    v = np.where(seg.valid & np.isfinite(seg.velocity[..., i]), seg.velocity[..., i], 0.0)
    n = np.maximum((seg.valid & np.isfinite(seg.velocity[..., i])).sum(axis=1), 1)
    moving = np.sqrt((v ** 2).sum(axis=1) / n) >= v_min  # RMS velocity: a steady level counts, a held DOF not
    if moving.sum() < k:
        return [a for a in np.array_split(np.arange(m), k) if a.size]
    blocks = [np.sort(np.concatenate([a, b])) for a, b in zip(np.array_split(np.flatnonzero(moving), k),
                                                               np.array_split(np.flatnonzero(~moving), k))]
    return [b for b in blocks if b.size]


def fit_bags(bags: Sequence[str | Path], choice: TopicChoice, cfg: VehicleConfig | None = None,
             dofs: Sequence[str] | None = None, holdout: Sequence[str | Path] = (), opts: FitOptions = FitOptions()
             ) -> FitResult:
    """The whole pipeline (module docstring) over ``bags`` (fitted jointly), validated by K-fold and on ``holdout``.

    dofs: the DOFs to identify (default all six; a DOF without excitation is reported "not excited"); the other
    excited DOFs are fitted too, for their inertias in the coupling terms, but not reported.
    Raises :class:`FitInputError` (bad topics, frames, too little data) or ``BagError``.
    """
    dofs = list(dofs or DOFS)
    for d in dofs:
        if d not in DOFS:
            raise FitInputError(f"--dofs: {d!r} is not a DOF (one of {', '.join(DOFS)})")
    pres = [preprocess_bag(b, choice, cfg, opts) for b in bags]
    hold = [preprocess_bag(b, choice, cfg, opts) for b in holdout]
    ex = {d: excitation(pres, d) for d in DOFS}  # all six: the coupling needs every moving DOF's inertia
    excited = [d for d in dofs if ex[d]["excited"]]
    pre_notes: dict[str, Any] = {"grid_s": opts.grid_s, "resampling": f"uniform grid of {opts.grid_s:g} s "
                                 f"({1 / opts.grid_s:g} Hz): force held (zero-order; its mean over each step for the fit, its value at "
                                 "the step's start for the delay estimate), velocity interpolated linearly",
                                 "segment_s": opts.segment_s}
    if excited:
        delay, curve = estimate_delay(pres, excited, opts)
    else:
        delay, curve = 0.0, []
    pre_notes["delay_s"] = round(delay, 4)
    pre_notes["delay_method"] = (f"force shifted by 0..{opts.max_delay_s:g} s; the shift minimising the normalised "
                                 f"equation-error residual of {', '.join(excited) or 'no DOF'} (parabola refinement)")
    for p in pres + hold:
        apply_delay(p, delay, opts)
    pre_notes["bags"] = [p.notes for p in pres]
    if hold:
        pre_notes["holdout_bags"] = [p.notes for p in hold]
    seg = BagSegments.build(pres, opts)
    seg_hold = BagSegments.build(hold, opts) if hold else None
    need = 2 * opts.segment_s
    have = float(seg.valid.sum() * opts.grid_s)
    if len(seg) < 2:
        raise FitInputError(f"too little data: {have:.1f} s of continuous force and velocity in segments; "
                            f"at least 2 segments of {opts.segment_s:g} s ({need:g} s) are needed, 2 per fold for "
                            f"cross-validation")
    folds = _folds(seg, len(pres), opts.folds)
    design = (f"{len(folds)}-fold cross-validation by bag" if len(pres) >= 2 else
              f"{len(folds)}-fold cross-validation by blocks of {opts.segment_s:g} s segments (one bag; per DOF "
              "the segments exciting it and the others each cut into contiguous blocks)")
    if hold:
        design += f"; holdout: {', '.join(str(b) for b in holdout)}"
    out: dict[str, DofFit] = {}
    plan: dict[str, tuple[str, list]] = {}
    for dof in DOFS:
        e = ex[dof]
        if dof not in dofs:  # not asked for: fitted only for the coupling terms, when it can be
            if e["excited"] and (dof not in ("roll", "pitch") or np.isfinite(seg.attitude[..., :2]).all()):
                plan[dof] = (_model_dof(dof, False), _names(dof, False))
            continue
        if not e["excited"]:
            why = ("no velocity measured" if not e["velocity_measured"] else
                   f"force std {e['force_std']:.3g} (min {e['force_std_min']:g}), velocity std "
                   f"{e['velocity_std']:.3g} (min {e['velocity_std_min']:g})")
            out[dof] = DofFit(dof, "not excited", e, reason=why)
            continue
        if dof in ("roll", "pitch") and not np.isfinite(seg.attitude[..., :2]).all():
            out[dof] = DofFit(dof, "failed", e, reason="no attitude for the restoring moment (odometry pose or DVL)")
            continue
        k = DOFS.index(dof)
        zk = seg.velocity[..., k][seg.valid]
        zk = zk[np.isfinite(zk)]
        # both directions excited: each holds at least 10 % of the moving samples (|w| > 0.05 m/s; a campaign
        # bag also holds the other DOFs' runs, with heave near 0)
        up, down = (zk > 0.05).sum(), (zk < -0.05).sum()
        by_dir = dof == "heave" and min(up, down) >= 0.1 * max(up + down, 1) and min(up, down) >= 100
        plan[dof] = (_model_dof(dof, by_dir), _names(dof, by_dir))
    # coupling: inertias of the fitted DOFs by equation error, twice (without, then with the coupling terms)
    inertia = np.full(6, np.nan)
    for _ in range(2):
        new = np.full(6, np.nan)
        seg_c = seg.with_coupling(inertia)
        for dof, (model, _n) in plan.items():
            try:
                new[DOFS.index(dof)] = max(float(_equation_error(seg_c, dof, model)[0]), 0.0)
            except (ValueError, np.linalg.LinAlgError):
                pass
        inertia = new
    # then once with the output-error inertias (the equation-error ones are ~10 % high on noisy derivatives, and the
    # Munk moment (M2 - M1) u v of a piloted run is of the order of the yaw damping)
    seg_c = seg.with_coupling(inertia)
    first: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for dof, (model, _n) in plan.items():
        try:
            first[dof] = _fit(seg_c, dof, model)
            inertia[DOFS.index(dof)] = float(first[dof][0][0])
        except (EstimationError, np.linalg.LinAlgError, ValueError):
            pass
    pre_notes["coupling"] = ("force less the Coriolis and centripetal terms C(nu) nu of the diagonal inertia "
                             "(Fossen 2011) from the measured velocities, with the fitted inertias ("
                             + ", ".join(f"{d} {inertia[DOFS.index(d)]:.4g}" for d in plan)
                             + "; equation error twice, then output error); terms of DOFs not fitted left out")
    seg_c = seg.with_coupling(inertia)
    hold_c = seg_hold.with_coupling(inertia) if seg_hold is not None and len(seg_hold) else None
    for dof, (model, names) in plan.items():
        if dof not in dofs:
            continue
        e = ex[dof]
        k = DOFS.index(dof)
        try:
            r = fit_dof(seg_c, dof, model, names, _folds(seg, len(pres), opts.folds, dof), e,
                        first[dof][0] if dof in first else None)
        except (EstimationError, np.linalg.LinAlgError, ValueError) as exc:
            out[dof] = DofFit(dof, "failed", e, reason=str(exc))
            continue
        theta = r.theta
        r.excitation["by_direction"] = model == "heave" if dof == "heave" else None
        if hold_c is not None:
            vp = predict(hold_c, dof, model, theta)
            r.validation["holdout"] = validation_measures(hold_c, dof, vp)
            r.plot = {"data": "holdout", "measured": hold_c.velocity[..., k], "predicted": vp,
                      "valid": hold_c.valid}
        out[dof] = r
    out = {d: out[d] for d in dofs}
    return FitResult(out, pre_notes, design)


# ------------------------------------------------------------------------------------------------ document
def _param_entries(r: DofFit, cfg: VehicleConfig | None) -> dict:
    units = parameter_units(r.dof)
    folds = np.array(r.folds) if r.folds else None
    entries: dict = {}

    def put(name, i, unit):
        e = {"value": float(r.theta[i]), "std": float(r.std[i]), "unit": unit,
             "ci95": [float(r.ci95[i, 0]), float(r.ci95[i, 1])]}
        if r.std_source:  # which estimate set std (docs/identification.md §7), and both
            e["std_source"] = r.std_source[i]
            e["std_output_error"] = float(r.oe_std[i])
            if r.jackknife_std is not None:
                e["std_jackknife"] = float(r.jackknife_std[i])
        if folds is not None and len(folds) >= 2:
            e["fold_spread"] = {"std": float(np.std(folds[:, i], ddof=1)), "min": float(folds[:, i].min()),
                                "max": float(folds[:, i].max()), "folds": int(len(folds))}
        return e

    for i, name in enumerate(r.names):
        if r.dof == "heave" and name in ("quadratic_damping", "linear_damping"):
            for d in ("positive", "negative"):  # one coefficient for both directions
                entries[f"{name}_{d}"] = put(name, i, units[f"{name}_{d}"])
                entries[f"{name}_{d}"]["note"] = "one coefficient for both directions (only one was excited)"
        else:
            entries[name] = put(name, i, units.get(name, ""))
    if cfg is not None:
        rigid = rigid_inertia(cfg, r.dof)
        am = dict(entries["inertia"])
        am["value"] = entries["inertia"]["value"] - rigid
        am["ci95"] = [entries["inertia"]["ci95"][0] - rigid, entries["inertia"]["ci95"][1] - rigid]
        am.pop("fold_spread", None)
        am["unit"] = units["added_mass"]
        entries["added_mass"] = am
    return entries


#: Why ``hindrax ident fit`` without ``--config`` writes ``config_ready: false`` (and no ``added_mass``).
CONFIG_READY_REASON = ("no vehicle file (--config): only the rigid + added inertia is identified, not the added mass; "
                       "applying it to a vehicle file (results.to_config_overrides) needs --config")


def _plain(x):
    """numpy scalars and arrays, tuples and nested mappings as plain YAML-safe Python values."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_plain(v) for v in x]
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    return x


def build_document(res: FitResult, cfg: VehicleConfig | None, bags: Sequence[str | Path],
                   holdout: Sequence[str | Path] = ()) -> dict:
    """identification.yaml: ``dofs.<dof>.<param>.{value,std,unit,ci95,fold_spread,std_source,std_output_error,
    std_jackknife}`` of the fitted DOFs (the schema of :mod:`.results`; std the larger of the output-error and the
    jackknife std, ``std_source`` naming it, :func:`honest_interval`; ``added_mass`` only with a configuration, which
    gives the rigid-body inertia: without one ``config_ready: false`` and ``config_ready_reason``; per DOF
    ``verdict`` suspect with ``reasons`` for a negative damping, a fold spread above 3 std or a validation nrmse of
    0.5 or more),
    ``not_excited``/``failed`` with their numbers, ``validation.<dof>.{nrmse,nrmse_hold,nrmse_zero,samples}`` (the
    holdout when given, else the cross-validation; both under their own keys too) and ``preprocessing``."""
    import datetime as _dt

    from .results import SCHEMA_VERSION

    dofs, val, other = {}, {}, {}
    for dof, r in res.dofs.items():
        if r.status != "fitted":
            other[dof] = {"status": r.status, "reason": r.reason,
                          **{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.excitation.items()}}
            continue
        e = _param_entries(r, cfg)
        e["method"] = "output-error (segment-wise, prediction error)"
        e["model"] = "heave by direction" if r.model == "heave" else ("one pair for both directions"
                                                                      if r.dof == "heave" else "one DOF")
        e["segments"] = r.segments
        reasons = [f"{n} {v['value']:.4g} < 0 (unphysical)" for n, v in e.items()
                   if isinstance(v, dict) and "damping" in n and v.get("value", 0.0) < 0]
        # the fold spread against the fit's own std (the reported std already covers the spread, §7)
        reasons += [f"{n}: fold spread {v['fold_spread']['std']:.3g} > 3 x output-error std "
                    f"{v.get('std_output_error', v['std']):.3g}" for n, v in e.items()
                    if isinstance(v, dict) and "fold_spread" in v
                    and v["fold_spread"]["std"] > 3 * v.get("std_output_error", v["std"])]
        main = r.validation.get("holdout") or r.validation.get("cross_validation")
        if main and not main["nrmse"] < 0.5:
            reasons.append(f"validation nrmse {main['nrmse']:.3f} >= 0.5")
        e["verdict"] = "suspect" if reasons else "trusted"
        e["reasons"] = reasons
        e["excitation"] = {k: v for k, v in r.excitation.items() if v is not None}
        dofs[dof] = e
        main = r.validation.get("holdout") or r.validation.get("cross_validation")
        if main:
            val[dof] = {**{k: main[k] for k in ("nrmse", "nrmse_hold", "nrmse_zero", "samples")},
                        "data": "holdout" if "holdout" in r.validation else "cross-validation",
                        **{k: v for k, v in r.validation.items()}}
    return _plain({
        "schema_version": SCHEMA_VERSION,
        "provenance": {"source": ", ".join(str(b) for b in bags),
                       "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
                       "configuration_sha256": cfg.sha256 if cfg is not None else None,
                       "water_density_kg_m3": float(cfg.water_density_kg_m3) if cfg is not None else None,
                       "method": "hindrax ident fit: segment-wise output error (prediction error) over free-form "
                                 "excitation, equation-error start; model of [Hindrax-Drag] eq. 2 with "
                                 "inertia and bias",
                       "seed": None, "bags": [str(b) for b in bags], "holdout": [str(b) for b in holdout],
                       "validation_design": res.design},
        "config_ready": cfg is not None,
        "config_ready_reason": (CONFIG_READY_REASON if cfg is None else
                                "added_mass = inertia - the vehicle file's rigid-body inertia"),
        "dofs": dofs,
        "not_identified": other,
        "validation": val,
        "preprocessing": res.preprocessing,
    })
