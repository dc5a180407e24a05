"""The campaign bag reader: rebuild the campaign record (:class:`~.campaign_record.CampaignRecord`) from a bag.

``hindrax ident bag BAG [--out DIR] [--config FILE]`` (:mod:`hindrax_tools.commands.ident_bag`), and
``hindrax ident fit`` on a bag with the campaign's topics (:func:`is_campaign_bag`), identify the record it returns with
:func:`~..assessment.pipeline.identify_bag`: the same analysis as the in-process campaign and ``hindrax run``
(docs/identification.md §7).

Topics read (the identification node's inputs and outputs, README "Topics"): ``dvl/data``,
``pressure/fluid_pressure``, ``imu/data_raw``, ``ping/altitude`` (sensor samples through the same adapters as the
node, :mod:`...vehicle.signals`, into :class:`~hindrax_onboard.vehicle.state.SensorState`), ``thrusters/pulse_width``
(the widths the ESC node wrote: thrust model of [Hindrax-Drag] eq. 1, first-order lag, thrust allocation matrix),
``identification/status`` (DOF under test, level, run boundaries, the still window used for the gyro and
accelerometer biases), ``identification/estimates`` (the online RLS history, for the report) and, when present,
``identification/calibration`` (the calibration steps' results the node published, :mod:`.calibration_topic`:
the record's ``calibration``, ``inclining`` and ``decays``).

Time base: header stamps (ROS time). The record is built on a uniform grid of ``grid_s`` (default 10 ms, the simulator's
/clock period): the status is held from its stamps and the ESC widths from their stamps plus ``esc.output_latency_s``
(zero-order hold, as the ESC output; a force 10 ms ahead of the true thrust puts the heave bias 2 N and the downward
quadratic damping 90 % off), and every sensor stamp is rounded to the grid (<= grid_s / 2 moved), because the
output-error fit compares the model with samples at grid instants. Sensor stamps are the drivers' times of validity (the
DVL's device time, the MS5837's conversion midpoint), which is what the fit needs. Raises :class:`BagContentError` (one
line) when the bag lacks what is needed."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig
from hindrax_drivers.icm20948.mounting import mounting_rotation
from hindrax_bringup.recording.msgtypes import TypeNotInstalledError
from hindrax_bringup.recording.reader import BagReader

from hindrax_onboard.vehicle.state import SensorState
from hindrax_onboard.vehicle.thrust_lag import ThrustLag
from hindrax_onboard.identification.model import calibration_topic
from hindrax_onboard.identification.model.campaign_record import CampaignRecord
from hindrax_onboard.vehicle.signals import (STILL_MESSAGE, sample_from_pressure, sample_from_range,
                                samples_from_dvl, samples_from_imu, thrust_of_written_widths)

__all__ = ["BagContentError", "OnlineHistory", "record_from_messages", "record_from_bag", "is_campaign_bag",
           "CAMPAIGN_TOPICS"]

SENSOR_TOPICS = ("dvl/data", "pressure/fluid_pressure", "imu/data_raw", "ping/altitude")
TOPICS = SENSOR_TOPICS + ("thrusters/pulse_width", "identification/status", "identification/estimates",
                          calibration_topic.TOPIC)
_RUNNING = 2  # ManeuverStatus.PHASE_RUNNING
#: The topics without which a bag is not a campaign's (:func:`record_from_bag` refuses it)
CAMPAIGN_TOPICS = ("thrusters/pulse_width", "identification/status", "dvl/data", "imu/data_raw",
                   "pressure/fluid_pressure")


class BagContentError(ValueError):
    """The bag misses a topic or an identification window (the message says which)."""


class OnlineHistory:
    """Stand-in for :class:`~..online.estimators.OnlineDofEstimator` built from recorded HydroEstimate messages.

    ``history`` {t, theta, std, excitation} and :meth:`result` as the live estimator provides them."""

    def __init__(self, dof: str) -> None:
        self.dof = dof
        self.history: dict[str, list] = {"t": [], "theta": [], "std": [], "excitation": []}
        self.names: list[str] = []
        self.n_samples = 0
        self.converged_at_s: float | None = None

    def add(self, t_s: float, msg) -> None:
        """Append one HydroEstimate (``method`` rls)."""
        self.names = list(msg.parameter_names)
        self.history["t"].append(t_s)
        self.history["theta"].append(np.asarray(msg.values, dtype=float))
        self.history["std"].append(np.where(np.asarray(msg.std, dtype=float) < 0, np.nan,
                                            np.asarray(msg.std, dtype=float)))
        self.history["excitation"].append(float(msg.excitation))
        self.n_samples = int(msg.sample_count)
        if msg.converged and self.converged_at_s is None:
            self.converged_at_s = t_s

    def result(self) -> dict:
        """Last {name: (value, std)}, n_samples, excitation, converged_at_s."""
        if not self.history["t"]:
            return {"parameters": {}, "n_samples": 0, "excitation_normalised": math.nan, "converged_at_s": None}
        th, sd = self.history["theta"][-1], self.history["std"][-1]
        return {"parameters": {n: (float(v), float(s)) for n, v, s in zip(self.names, th, sd)},
                "n_samples": self.n_samples, "excitation_normalised": self.history["excitation"][-1],
                "converged_at_s": self.converged_at_s}


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def record_from_messages(messages, cfg: VehicleConfig, grid_s: float = 0.01) -> CampaignRecord:
    """CampaignRecord from (topic, message) pairs (any order; rclpy or bag-decoded messages).

    Raises :class:`BagContentError` without ESC widths, status or an identification run, or with an
    ``identification/calibration`` status missing a value."""
    mount_t = mounting_rotation(cfg.sensors.icm20948.mounting_rpy_rad).T
    samples: list = []
    pwm: list = []
    online: dict[str, OnlineHistory] = {}
    status, estimates, calibrations = [], [], []  # (stamp, message) each
    stamped = {"identification/status": status, "identification/estimates": estimates,
               calibration_topic.TOPIC: calibrations}
    for topic, msg in messages:
        if topic == "dvl/data":
            samples.extend(samples_from_dvl(msg))
        elif topic == "imu/data_raw":
            samples.extend(samples_from_imu(msg, mount_t))
        elif topic == "pressure/fluid_pressure":
            samples.append(sample_from_pressure(msg))
        elif topic == "ping/altitude":
            samples.append(sample_from_range(msg))
        elif topic == "thrusters/pulse_width":
            pwm.append((_stamp(msg), np.asarray(msg.pulse_width_us, dtype=float), bool(msg.armed)))
        elif topic in stamped:
            stamped[topic].append((_stamp(msg), msg))
    if not pwm:
        raise BagContentError("no thrusters/pulse_width messages (the widths the ESC wrote)")
    if not status:
        raise BagContentError("no identification/status messages (was the identification node running?)")
    status.sort(key=lambda x: x[0])
    pwm.sort(key=lambda x: x[0])
    active_t = [t for t, m in status if m.dof in DOFS]
    if not active_t:
        raise BagContentError("identification/status never names a DOF under test: no manoeuvre in this bag")
    busy = [ts for ts, m in status if m.phase != 0]  # not PHASE_IDLE
    t_first = busy[0] if busy else status[0][0]
    t_last = busy[-1] if busy else status[-1][0]
    n = int(math.floor((t_last - t_first) / grid_s)) + 1
    t = np.round((t_first + grid_s * np.arange(n)) / grid_s) * grid_s
    # zero-order hold of status and widths on the grid
    st_t = np.array([s[0] for s in status])
    ist = np.clip(np.searchsorted(st_t, t + 1e-9, side="right") - 1, 0, len(status) - 1)
    pw_t = np.array([p[0] for p in pwm]) + float(cfg.esc.output_latency_s)
    ipw = np.searchsorted(pw_t, t + 1e-9, side="right") - 1
    core = AllocationCore(cfg)
    curve = core.allocator.curves[0]
    matrix = np.asarray(core.matrix_frd, dtype=float)
    # NaN widths: ESC output state OUTPUT_UNKNOWN (armed or not), the force on the wire is not known: missing
    # (NaN), never neutral thrust; the lagged force stays unknown until 5 time constants after it ends
    widths, armed = np.array([p[1] for p in pwm]), np.array([[p[2]] for p in pwm])
    known = np.all(np.isfinite(widths), axis=1)[:, None]
    forces = np.where(known, thrust_of_written_widths(cfg, curve, np.where(
        known & armed, widths, float(cfg.thrusters.pulse_width_neutral_us))), np.nan)
    f_cmd = np.where(ipw[:, None] >= 0, forces[np.clip(ipw, 0, None)], 0.0)
    tau = float(cfg.thrusters.time_constant_s)
    thrust_lag = ThrustLag(tau)
    settle = int(math.ceil(5.0 * tau / grid_s)) if tau > 0 else 0
    f_lag = np.zeros_like(f_cmd)
    lag = np.zeros(matrix.shape[1])
    wait = 0
    known = np.all(np.isfinite(f_cmd), axis=1)
    for i in range(n):
        if not known[i]:
            f_lag[i], lag, wait = np.nan, f_cmd[i], settle
            continue
        if wait:
            # the lag starts again from the first known force
            lag = f_cmd[i] if i and not known[i - 1] else lag
            wait -= 1
            f_lag[i] = np.nan
        else:
            f_lag[i] = lag
        lag = thrust_lag.advance(lag, f_cmd[i], grid_s)
    dof_of = np.array([DOFS.index(m.dof) if m.dof in DOFS else -1 for _, m in status])
    running = np.array([m.phase == _RUNNING for _, m in status])
    level = np.array([m.level_command if m.phase == _RUNNING else math.nan for _, m in status], dtype=float)
    active = np.where(np.all(np.isfinite(f_lag), axis=1), dof_of[ist], -1)  # unknown force: in no DOF's window
    # run counter: a new run at every status that starts RUNNING (or changes the level while running)
    run_of_status = np.full(len(status), -1)
    run = -1
    for j in range(len(status)):
        if running[j]:
            if j == 0 or not running[j - 1] or level[j] != level[j - 1]:
                run += 1
            run_of_status[j] = run
    run_id = np.where(active >= 0, run_of_status[ist], -1)
    windows: dict[str, tuple[float, float]] = {}
    for d, name in enumerate(DOFS):
        idx = np.flatnonzero(active == d)
        if idx.size:
            windows[name] = (float(t[idx[0]]), float(t[idx[-1]]))
    still = [ts for ts, m in status if m.message.startswith(STILL_MESSAGE)]
    # sensor samples through SensorState, oldest first, stamps on the grid
    state = SensorState(cfg)
    samples.sort(key=lambda ds: ds[1].stamp_s)
    bias_on = False
    for dev, s in samples:
        s.stamp_s = round(s.stamp_s / grid_s) * grid_s
        if still:
            if not bias_on and still[0] <= s.stamp_s <= still[-1]:
                state.start_gyro_bias()
                bias_on = True
            elif bias_on and state.collecting_gyro_bias and s.stamp_s > still[-1]:
                state.finish_gyro_bias()
        state.on_sample(dev, s)
    if state.collecting_gyro_bias:
        state.finish_gyro_bias()
    for ts, m in estimates:
        if m.dof in DOFS and m.method == "rls":
            online.setdefault(m.dof, OnlineHistory(m.dof)).add(ts, m)
    calibrations.sort(key=lambda x: x[0])
    try:
        calibration, inclining, decays = calibration_topic.merge_results(m for _, m in calibrations)
    except ValueError as exc:
        raise BagContentError(str(exc)) from exc
    # the node's message holds every result since it started: a free decay recorded before this bag has no data here
    if samples:
        lo, hi = samples[0][1].stamp_s - grid_s, samples[-1][1].stamp_s + grid_s
        decays = {d: w for d, w in decays.items() if lo <= w[0] and w[1] <= hi}
    last = [m for _, m in status if m.phase != 0][-1] if busy else status[-1][1]
    aborted = last.phase == 5  # PHASE_ABORTED
    return CampaignRecord(
        t_s=t, wrench_frd=f_lag @ matrix.T, wrench_cmd_frd=f_cmd @ matrix.T, active=active.astype(int),
        level=level[ist], run_id=run_id.astype(int), truth_position_ned_m=np.full((n, 3), np.nan),
        truth_euler_rad=np.full((n, 3), np.nan), sensors=state.log, windows=windows, online=online,
        levels={}, authority={}, aborted=aborted, abort_reason=last.message if aborted else "", wall_time_s=0.0,
        tick_s=grid_s, time_constant_s=tau, seed=-1, final_pulse_width_us=pwm[-1][1], calibration=calibration,
        decays=decays, inclining=inclining, thrust_cmd_n=f_cmd)


def record_from_bag(bag_path: str | Path, cfg: VehicleConfig, grid_s: float = 0.01) -> CampaignRecord:
    """:func:`record_from_messages` over the topics of a bag (:class:`~hindrax_bringup.recording.reader.BagReader`).

    Raises :class:`~hindrax_bringup.recording.reader.BagError` for an unreadable bag and
    :class:`BagContentError` when a needed topic is missing."""
    reader = BagReader(bag_path)
    present = set(reader.topics)
    missing = [tp for tp in CAMPAIGN_TOPICS if tp not in present and "/" + tp not in present]
    if missing:
        raise BagContentError(f"{bag_path}: missing topic(s) {', '.join(missing)}")
    wanted = [tp for tp in present if tp.lstrip("/") in TOPICS]
    # the installed types' lean decoder (a type changed since: from the bag's definition); a type
    # not installed here: every topic from the bag's definitions (mcap_ros2)
    try:
        return record_from_messages(((m.topic.lstrip("/"), obj)
                                     for m, obj in reader.installed_messages(wanted, lean=True)),
                                    cfg, grid_s)
    except TypeNotInstalledError:
        return record_from_messages(((m.topic.lstrip("/"), obj) for m, obj in reader.decoded(wanted)), cfg, grid_s)


def truncation(bag_path: str | Path) -> list[str]:
    """What a campaign bag lacks, one phrase each; empty for a whole campaign. A bag is truncated when a file has no
    summary (the recorder did not close it: :attr:`BagReader.truncated_files`) or when ``identification/status``
    ends while the campaign still runs (its last non-idle phase neither DONE nor ABORTED); then the DOF under test
    and its levels not reached are named, and every DOF whose levels stop short of its level count, with the
    campaign time the bag holds. Raises :class:`~hindrax_bringup.recording.reader.BagError` for an unreadable bag."""
    reader = BagReader(bag_path)
    out = []
    if reader.truncated_files:
        out.append("file(s) without a summary (recorder not closed): "
                   + ", ".join(f.name for f in reader.truncated_files))
    topic = next((tp for tp in reader.topics if tp.lstrip("/") == "identification/status"), None)
    if topic is None:
        return out
    busy = [(m.log_time_ns, obj) for m, obj in reader.decoded([topic]) if obj.phase != 0]
    if not busy:
        return out
    reached: dict[str, tuple[int, int]] = {}  # dof -> (levels reached, level count)
    for _t, s in busy:
        if s.dof in DOFS and s.level_count > 0:
            done = max(reached.get(s.dof, (0, 0))[0], int(s.level_index) + 1)
            reached[s.dof] = (done, int(s.level_count))
    last = busy[-1][1]
    if last.phase not in (4, 5):  # PHASE_DONE, PHASE_ABORTED
        held_s = (busy[-1][0] - busy[0][0]) * 1e-9
        out.append(f"the campaign was still running when the bag ends, {held_s:.1f} s after it started "
                   f"({last.dof or 'no DOF'}, level {int(last.level_index) + 1} of {int(last.level_count)}); "
                   "DOFs of the goal after it are not in the bag")
    short = [f"{d} {n} of {c} levels" for d, (n, c) in reached.items() if n < c]
    if short and out:
        out.append("levels missing: " + ", ".join(short))
    return out


def is_campaign_bag(bag_path: str | Path) -> bool:
    """True when the bag has every topic of :data:`CAMPAIGN_TOPICS` (with or without the leading slash). Raises
    :class:`~hindrax_bringup.recording.reader.BagError` for an unreadable bag."""
    present = {tp.lstrip("/") for tp in BagReader(bag_path).topics}
    return all(tp in present for tp in CAMPAIGN_TOPICS)
