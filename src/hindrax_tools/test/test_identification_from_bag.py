"""Rebuilding the campaign record from recorded topics (identification/bag_input/from_bag.py): the thrust-model wrench
from the widths the ESC wrote (lag, allocation matrix), the DOF windows and runs from identification/status,
and clear errors for bags without what is needed."""
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sensor_msgs.msg import FluidPressure

from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import child_env
from hindrax_fit.bag_input.from_bag import BagContentError, record_from_messages
from hindrax_msgs.msg import ManeuverStatus, ThrusterPwm

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def _stamped(msg, t):
    msg.header.stamp.sec = int(t)
    msg.header.stamp.nanosec = int(round((t - int(t)) * 1e9))
    return msg


def _messages(cfg, level_pw_us=1700.0):
    """10 s: idle 1 s, positioning 1 s, a surge run 4 s at fixed widths, returning 2 s, done."""
    n = len(cfg.thrusters.thrusters)
    rev = np.array([t.reversed for t in cfg.thrusters.thrusters])
    msgs = []
    for k in range(501):
        t = 0.02 * k
        if t < 1.0:
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_IDLE)
        elif t < 2.0:
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_POSITIONING)
        elif t < 6.0:
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_RUNNING, dof="surge", level_command=10.0, level_count=1)
        elif t < 9.0:
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_RETURNING, dof="surge", level_count=1)
        else:
            st = ManeuverStatus(phase=ManeuverStatus.PHASE_DONE)
        msgs.append(("identification/status", _stamped(st, t)))
        logical = np.full(n, level_pw_us if 2.0 <= t < 6.0 else 1500.0)
        wire = np.where(rev, 3000.0 - logical, logical)  # as EscOutput writes them
        msgs.append(("thrusters/pulse_width", _stamped(ThrusterPwm(pulse_width_us=list(wire), armed=True), t)))
        if k % 5 == 0:
            msgs.append(("pressure/fluid_pressure", _stamped(FluidPressure(fluid_pressure=101325.0 + 9810.0), t)))
    return msgs


def test_record_wrench_windows_and_runs_from_status_and_esc_widths():
    cfg = load_config(default_config_path())
    core = AllocationCore(cfg)
    curve, matrix = core.allocator.curves[0], np.asarray(core.matrix_frd)
    msgs = _messages(cfg)
    rec = record_from_messages(reversed(msgs), cfg)  # order of arrival does not matter
    assert rec.tick_s == 0.01 and rec.t_s[0] == pytest.approx(1.0) and rec.t_s[-1] == pytest.approx(10.0)
    assert np.allclose(np.diff(rec.t_s), 0.01)
    t0, t1 = rec.windows["surge"]
    assert t0 == pytest.approx(2.0) and t1 == pytest.approx(8.99, abs=0.011)
    assert set(rec.run_id[(rec.t_s > 2.0) & (rec.t_s < 6.0)]) == {0}
    assert set(rec.run_id[rec.t_s > 6.05]) == {-1} and np.all(np.isnan(rec.level[rec.t_s > 6.05]))
    # commanded wrench: the same thrust on every thruster through the thrust allocation matrix ([Hindrax-Drag] eq. 9)
    expected = matrix @ np.full(matrix.shape[1], float(curve.thrust_n(1700.0)))
    mid = np.argmin(np.abs(rec.t_s - 4.0))
    assert rec.wrench_cmd_frd[mid] == pytest.approx(expected, abs=1e-9)
    # first-order lag: after 5 time constants within 1 %, and 63 % after one time constant
    tau = cfg.thrusters.time_constant_s
    k_big = int(np.argmax(np.abs(expected)))
    assert rec.wrench_frd[mid, k_big] == pytest.approx(expected[k_big], rel=0.01)
    i_tau = np.argmin(np.abs(rec.t_s - (2.0 + tau)))
    assert rec.wrench_frd[i_tau, k_big] / expected[k_big] == pytest.approx(1 - math.exp(-1), abs=0.05)
    # depth log from the pressure: 9810 Pa above the surface pressure = 1 m of fresh water at the port
    depth = np.array([v[0] for _, v in rec.sensors["depth"]])
    port_above_origin = -cfg.flat["sensors.ms5837.position_frd_m"][2]
    rho_g = cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2
    assert depth == pytest.approx(np.full(depth.size, 1000.0 * 9.81 / rho_g + port_above_origin), abs=1e-6)
    assert not rec.aborted


def test_esc_widths_act_after_the_configured_output_latency():
    """The force of a width stamped t starts at t + esc.output_latency_s (rounded to the 10 ms grid)."""
    for latency in (0.0, 0.03):
        cfg = load_config(default_config_path(), overrides={"esc.output_latency_s": latency})
        rec = record_from_messages(_messages(cfg), cfg)
        first = rec.t_s[np.flatnonzero(np.linalg.norm(rec.wrench_cmd_frd, axis=1) > 1e-9)[0]]
        assert first == pytest.approx(2.0 + latency, abs=1e-6)


def test_unknown_esc_output_is_missing_force_not_neutral_thrust():
    """Issue 27 item 4: widths NaN (ESC output state OUTPUT_UNKNOWN) from 3.0 to 3.5 s inside the surge run,
    disarmed then armed: the wrench is NaN (not the neutral zero) there and for 5 thrust time constants after,
    those ticks belong to no DOF and no run, and the force before and after is the thrust model's."""
    cfg = load_config(default_config_path())
    n = len(cfg.thrusters.thrusters)
    msgs = []
    for topic, m in _messages(cfg):
        t = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
        if topic == "thrusters/pulse_width" and 3.0 <= t < 3.5 - 1e-9:
            m = _stamped(ThrusterPwm(pulse_width_us=[math.nan] * n, armed=t >= 3.25), t)
        msgs.append((topic, m))
    rec = record_from_messages(msgs, cfg)
    lat, tau = float(cfg.flat["esc.output_latency_s"]), cfg.thrusters.time_constant_s
    t = rec.t_s
    gap = (t >= 3.0 + lat + 0.011) & (t < 3.5 + lat - 0.011)
    after = (t >= 3.5 + lat + 0.011) & (t < 3.5 + lat + 5 * tau - 0.011)
    assert np.all(np.isnan(rec.wrench_cmd_frd[gap])) and np.all(np.isnan(rec.wrench_frd[gap | after]))
    assert set(rec.active[gap | after]) == {-1} and set(rec.run_id[gap | after]) == {-1}
    edge = np.min(np.abs(t[:, None] - (lat + np.array([3.0, 3.5, 3.5 + 5 * tau]))), axis=1) <= 0.011  # +-1 tick
    known = ~(gap | after | edge)
    assert np.all(np.isfinite(rec.wrench_frd[known]))
    run = (t > 2.0) & (t < 6.0) & known
    assert set(rec.active[run]) == {0} and set(rec.run_id[run]) == {0}
    late = np.argmin(np.abs(t - 5.5))  # settled again: the lagged force equals the command
    assert rec.wrench_frd[late] == pytest.approx(rec.wrench_cmd_frd[late], rel=0.01)


def test_missing_topics_and_runs_are_reported():
    cfg = load_config(default_config_path())
    msgs = _messages(cfg)
    with pytest.raises(BagContentError, match="thrusters/pulse_width"):
        record_from_messages([m for m in msgs if m[0] != "thrusters/pulse_width"], cfg)
    with pytest.raises(BagContentError, match="no manoeuvre"):
        record_from_messages([m for m in msgs if m[0] != "identification/status"
                              or m[1].phase in (0, 1)], cfg)


def test_ident_bag_command_rejects_a_missing_or_wrong_bag(tmp_path):
    hindrax = str(Path(sys.executable).with_name("hindrax"))
    p = subprocess.run([hindrax, "ident", "bag", str(tmp_path / "nope")], env=child_env(), capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 1 and "no such file" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    (tmp_path / "empty").mkdir()
    p = subprocess.run([hindrax, "ident", "bag", str(tmp_path / "empty")], env=child_env(), capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 1 and p.stderr.startswith("ident bag:") and len(p.stderr.strip().splitlines()) == 1


def _same_record(a, b) -> None:
    for name in ("t_s", "wrench_frd", "wrench_cmd_frd", "active", "run_id", "level"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.windows == b.windows and a.aborted == b.aborted
    assert {k: [(s[0], list(s[1])) for s in v] for k, v in a.sensors.items()} == \
        {k: [(s[0], list(s[1])) for s in v] for k, v in b.sensors.items()}


def test_bag_record_is_the_messages_record_by_either_decoder(tmp_path, monkeypatch):
    """record_from_bag decodes installed types with the lean decoder (a type not installed: every
    topic from the bag's own definitions); both give the record of the rclpy messages themselves."""
    from rclpy.serialization import serialize_message

    from hindrax_bringup.recording import reader
    from hindrax_bringup.recording.msgtypes import TypeNotInstalledError
    from hindrax_bringup.recording.writer import BagWriter, WriterOptions
    from hindrax_fit.bag_input.from_bag import record_from_bag

    cfg = load_config(default_config_path())
    msgs = _messages(cfg)
    with BagWriter(tmp_path / "bag", WriterOptions(fsync=False)) as w:
        for topic, type_name in (("/identification/status", "hindrax_msgs/msg/ManeuverStatus"),
                                 ("/thrusters/pulse_width", "hindrax_msgs/msg/ThrusterPwm"),
                                 ("/pressure/fluid_pressure", "sensor_msgs/msg/FluidPressure"),
                                 ("/dvl/data", "hindrax_msgs/msg/Dvl"), ("/imu/data_raw", "sensor_msgs/msg/Imu")):
            w.add_topic(topic, type_name)
        for topic, m in msgs:
            w.write("/" + topic, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec, serialize_message(m))
    direct = record_from_messages(msgs, cfg)
    _same_record(record_from_bag(tmp_path / "bag", cfg), direct)

    def not_installed(self, topics, lean=False):
        raise TypeNotInstalledError("hindrax_msgs/msg/ThrusterPwm is not installed")
        yield  # a generator, as the reader's

    monkeypatch.setattr(reader.BagReader, "installed_messages", not_installed)
    _same_record(record_from_bag(tmp_path / "bag", cfg), direct)
