"""Roll and pitch inertia from an inclining test and a free decay, under the
"thrust x0.90" truth (ros_ws/config/truth/scenarios/thrust_0.90.yaml: every thruster 10 % weaker than its curve).

The in-process simulator is driven here; its IMU records are written to CSV and analysed offline by the commands
(`hindrax ident inclining`, `hindrax ident tilt-decay`), as one would with records from the vehicle:

1. Inclining: a 0.5 kg steel mass hangs at signed arms of -0.15 .. 0.15 m from the CG (across for roll, along
   for pitch); its moment about the CG is applied as an external moment, w d cos(phi) cos(theta) with the
   simulated attitude each step (the physics of a hanging mass; its weight is taken as carried by the depth
   hold, so no force). The moment is ramped in over 8 s (slower than the roll period), held, and the tilt is
   the mean over the last 8 s of the accelerometer's gravity direction (atan2 of the measured specific force).
2. Free decay: the vertical thrusters (allocated with the vehicle file, so 10 % short in this pool) tilt the
   vehicle to about 0.25 rad over 6 s; then neutral widths release it and the gyro rate is recorded for 25 s.

Throughout, an external vertical force cancels the net buoyancy (the simulator has no depth controller here;
``pool=False``: a submerged vehicle without walls or surface). Truth: the truth file's rigid inertia
(vehicle.inertia_kg_m2) + added inertia (hydrodynamics.<dof>.added_mass_kg_m2); the simulator's restoring is
B BG (buoyancy 150.1 N, BG 0.03 m: 4.50 N m/rad), compared here with m g BG = 4.48 N m/rad within 3 %.
The issue's criterion: within 10 % of the truth under the thrust x0.90 truth.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_sim.simulator import Simulator
from hindrax_sim.truth import truth_dir

TRUTH = truth_dir() / "scenarios" / "thrust_0.90.yaml"
W_TEST = (0.5 - 1000.0 * 0.5 / 7850.0) * 9.81      # 0.5 kg of steel in water, N
ARMS = (-0.15, -0.075, 0.0, 0.075, 0.15)
AXIS = {"roll": 0, "pitch": 1}


class _Recorder:
    def __init__(self, sim):
        self.accel, self.gyro = [], []
        sim.add_sensor_listener(self)

    def __call__(self, name, sample):
        if name == "icm20948_accel":
            self.accel.append((sample.stamp_s, frames.flu_to_frd(np.asarray(sample.specific_force_m_s2))))
        elif name == "icm20948_gyro":
            self.gyro.append((sample.stamp_s, frames.flu_to_frd(np.asarray(sample.angular_rate_rad_s))))


def _hold_force(sim):
    """Body-frame force cancelling the net buoyancy (FRD, N)."""
    net_up = float(sim.config.vehicle.net_buoyancy_n)
    return sim.rotation.T @ np.array([0.0, 0.0, net_up])


def _tilt_from_accel(f):
    """Roll and pitch (rad) of the gravity direction in a measured FRD specific force at rest."""
    return math.atan2(-f[1], -f[2]), math.atan2(f[0], math.hypot(f[1], f[2]))


def _inclining_record(dof, seed):
    sim = Simulator(load_config(default_config_path()), truth=str(TRUTH), seed=seed, pool=False,
                    sensors=["icm20948_accel"])
    rows = []
    for d in ARMS:
        sim.reset(position_ned_m=[0.0, 0.0, 2.0], rpy_rad=[0.0, 0.0, 0.0])
        rec = _Recorder(sim)
        n = int(round(20.0 / sim.step_s))
        for k in range(n):
            ramp = min(1.0, k * sim.step_s / 8.0)
            phi, theta, _ = sim.euler_rad
            moment = ramp * W_TEST * d * math.cos(phi) * math.cos(theta)
            wrench = np.zeros(6)
            wrench[:3] = _hold_force(sim)
            wrench[3 + AXIS[dof]] = moment if dof == "roll" else -moment   # mass forward: nose down (M < 0)
            sim.step(external_wrench_frd=wrench)
        sim.remove_sensor_listener(rec)
        tilts = [_tilt_from_accel(f)[AXIS[dof]] for t, f in rec.accel if t >= 12.0]
        tilt = float(np.mean(tilts))
        rows.append((d, tilt if dof == "roll" else -tilt))                # arm sign = moment sign
    return rows


def _decay_record(dof, seed):
    vehicle = load_config(default_config_path())
    sim = Simulator(vehicle, truth=str(TRUTH), seed=seed, pool=False, sensors=["icm20948_gyro"])
    sim.reset(position_ned_m=[0.0, 0.0, 2.0], rpy_rad=[0.0, 0.0, 0.0])
    core = AllocationCore(vehicle)
    c_nominal = 15.22 * 9.81 * 0.03
    moment_frd = 0.25 * c_nominal * 1.1
    rec = _Recorder(sim)
    t_release = 6.0 + 4.0
    for k in range(int(round((t_release + 25.0) / sim.step_s))):
        t = k * sim.step_s
        if k % 20 == 0:   # new widths every 0.1 s (the allocation node's rate)
            if t < t_release:
                w_flu = np.zeros(6)
                m = min(1.0, t / 6.0) * moment_frd
                w_flu[3 + AXIS[dof]] = m if dof == "roll" else -m        # FLU Ty = -FRD M
                pw = core.allocate(w_flu).pulse_width_us
            else:
                pw = core.neutral()
        else:
            pw = None
        wrench = np.zeros(6)
        wrench[:3] = _hold_force(sim)
        sim.step(pw, external_wrench_frd=wrench)
    return [(t, g[AXIS[dof]]) for t, g in rec.gyro if t >= t_release], sim


def _truth(sim, dof):
    i = float(sim.config.vehicle.inertia_kg_m2[AXIS[dof]])
    return i, i + float(sim.config.get(f"hydrodynamics.{dof}.added_mass_kg_m2"))


def _write(path, header, rows):
    with open(path, "w") as fh:
        fh.write(header + "\n")
        for a, b in rows:
            fh.write(f"{a:.6f},{b:.8f}\n")


@pytest.mark.parametrize("dof", ["roll", "pitch"])
def test_free_decay_inertia_within_10_percent_under_thrust_0_90(tmp_path, capsys, dof):
    incl = tmp_path / f"{dof}_inclining.csv"
    _write(incl, "arm_m,tilt_rad", _inclining_record(dof, seed=3))
    assert cli.main(["ident", "inclining", str(incl), "--test-mass-kg", "0.5", "--test-volume-m3",
                     str(0.5 / 7850.0), "--vehicle-mass-kg", "15.22"]) == 0
    c = json.loads(capsys.readouterr().out)
    c_truth = 15.22 * 9.81 * 0.03                       # truth file: m g BG, CB 3 cm above the CG
    assert c["restoring_n_m_per_rad"] == pytest.approx(c_truth, rel=0.03)

    rows, sim = _decay_record(dof, seed=3)
    decay = tmp_path / f"{dof}_decay.csv"
    _write(decay, "time_s,rate_rad_s", rows)
    rigid, total = _truth(sim, dof)
    assert cli.main(["ident", "tilt-decay", str(decay), "--stiffness", str(c["restoring_n_m_per_rad"]),
                     "--stiffness-std", str(c["restoring_n_m_per_rad_std"]), "--rigid-inertia", str(rigid),
                     "--dof", dof]) == 0
    out = json.loads(capsys.readouterr().out)
    print(f"{dof}: C {c['restoring_n_m_per_rad']:.4f} (truth {c_truth:.4f}), inertia "
          f"{out['total_inertia_kg_m2']:.4f} +- {out['total_inertia_kg_m2_std']:.4f} (truth {total:.4f})")
    assert out["total_inertia_kg_m2"] == pytest.approx(total, rel=0.10)
    # Not asserted: interval coverage. The std (fit + inclining LS, white residuals) is about 0.1 % while the
    # inclining stiffness is off by up to about 1 % (the holds end before the oscillation has fully decayed,
    # and the simulator's restoring uses the buoyancy rho V g, 0.5 % above m g): the std is optimistic.
    assert out["total_inertia_kg_m2_std"] >= out["total_inertia_kg_m2_std_fit"]
