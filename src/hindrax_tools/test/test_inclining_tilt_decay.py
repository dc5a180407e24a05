"""Roll/pitch references without the thrust curve: ``hindrax ident inclining`` and ``hindrax ident tilt-decay``.

Inclining: a test mass at known arms tilts a vehicle of known restoring C; the tilts are computed by hand here from
w d cos(phi) = C sin(phi) + M0 (exact equilibrium, solved by bisection in this file), plus 0.05 deg of IMU noise.
Tilt decay: the configured Hindrax roll (rigid 0.4831 kg m^2, added 0.48 kg m^2, C = W BG = 4.48 N m/rad, linear
0.05 and quadratic 1.29 damping: ros_ws/config/hindrax.yaml) integrated by the fixed-step RK4 of
hindrax_test_support.decay, seen through a gyro with bias and noise.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from hindrax_tools import cli
from hindrax_onboard.estimation.free_decay import restoring_from_inclining
from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_test_support.decay import rk4_decay

C_TRUE, M0, G = 4.4792, 0.02, 9.81
M_TEST, V_TEST = 0.5, 0.5 / 7850.0          # 0.5 kg of steel


def _tilt(arm):
    """Solve w d cos(phi) = C sin(phi) + M0 for phi by bisection (independent of the estimator)."""
    w = (M_TEST - 1000.0 * V_TEST) * G
    lo, hi = -1.5, 1.5
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        f = w * arm * math.cos(mid) - C_TRUE * math.sin(mid) - M0
        lo, hi = (mid, hi) if f > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _inclining_csv(path, degrees=False):
    rng = np.random.default_rng(2)
    arms = [-0.2, -0.1, 0.0, 0.1, 0.2]
    with open(path, "w") as fh:
        fh.write("arm_m,tilt\n")
        for d in arms:
            phi = _tilt(d) + math.radians(0.05) * rng.standard_normal()
            fh.write(f"{d},{math.degrees(phi) if degrees else phi}\n")


def test_inclining_gives_the_restoring_stiffness_and_bg(tmp_path, capsys):
    f = tmp_path / "incl.csv"
    _inclining_csv(f, degrees=True)
    rc = cli.main(["ident", "inclining", str(f), "--test-mass-kg", str(M_TEST), "--test-volume-m3", str(V_TEST),
                   "--vehicle-mass-kg", "15.22", "--degrees"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["restoring_n_m_per_rad"] == pytest.approx(C_TRUE, rel=0.02)
    assert abs(out["restoring_n_m_per_rad"] - C_TRUE) < 4 * out["restoring_n_m_per_rad_std"]
    assert out["bg_m"] == pytest.approx(C_TRUE / (15.22 * G), rel=0.02)
    assert out["offset_n_m"] == pytest.approx(M0, abs=0.01)
    assert out["n_points"] == 5


def test_inclining_rejects_bad_input():
    with pytest.raises(EstimationError, match="two different arms"):
        restoring_from_inclining([0.1, 0.1], [0.01, 0.02], 1.0)
    with pytest.raises(EstimationError, match="heavier than the water"):
        restoring_from_inclining([0.0, 0.1], [0.0, 0.02], 1.0, test_volume_m3=0.002)
    with pytest.raises(EstimationError, match="check the signs"):
        restoring_from_inclining([0.0, 0.1, 0.2], [0.0, -0.02, -0.04], 1.0)


def _roll_decay_csv(path, signal="rate"):
    t, phi, p, _ = rk4_decay(C_TRUE, 0.4831 + 0.48, 0.05, 1.29, 0.3, 25.0, 100.0)
    rng = np.random.default_rng(11)
    t = np.concatenate([np.arange(-100, 0) / 100.0, t]) + 10.0     # held for 1 s before the release
    if signal == "rate":
        y = np.concatenate([np.zeros(100), p]) + 0.003 + 0.004 * rng.standard_normal(t.size)
    else:
        y = np.concatenate([np.full(100, 0.3), phi]) + 0.002 * rng.standard_normal(t.size)
    with open(path, "w") as fh:
        fh.write("time_s,value\n")
        for ti, yi in zip(t, y):
            fh.write(f"{ti:.4f},{yi:.7f}\n")


@pytest.mark.parametrize("signal", ["rate", "angle"])
def test_tilt_decay_gives_rigid_plus_added_inertia_and_compares_with_the_campaign(tmp_path, capsys, signal):
    f = tmp_path / "roll.csv"
    _roll_decay_csv(f, signal)
    args = ["ident", "tilt-decay", str(f), "--stiffness", str(C_TRUE), "--rigid-inertia", "0.4831",
            "--signal", signal]
    assert cli.main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["total_inertia_kg_m2"] == pytest.approx(0.9631, rel=0.01)
    assert out["added_inertia_kg_m2"] == pytest.approx(0.48, rel=0.03)
    assert abs(out["total_inertia_kg_m2"] - 0.9631) < 4 * out["total_inertia_kg_m2_std"]
    assert out["quadratic_damping_kg_m2"] == pytest.approx(1.29, rel=0.15)
    assert "self_propelled" not in out


def test_tilt_decay_verdict_against_identification_yaml(tmp_path, capsys, monkeypatch):
    """A self-propelled roll inertia 10 % high (thrust curve 10 % optimistic) with a tight interval is suspect;
    one within its interval agrees."""
    from hindrax_fit.assessment import results

    f = tmp_path / "roll.csv"
    _roll_decay_csv(f)
    doc_path = tmp_path / "identification.yaml"
    # only dofs.roll.inertia matters here; the full schema is tested in test_identification_results
    monkeypatch.setattr(results, "read_identification", lambda path: yaml.safe_load(open(path).read()))
    for value, std, verdict in ((1.1 * 0.9631, 0.01, "suspect"), (0.9631 * 1.01, 0.02, "agrees")):
        doc_path.write_text(yaml.safe_dump({"dofs": {"roll": {"inertia": {"value": value, "std": std}}}}))
        assert cli.main(["ident", "tilt-decay", str(f), "--stiffness", str(C_TRUE),
                         "--identification", str(doc_path), "--dof", "roll"]) == 0
        sp = json.loads(capsys.readouterr().out)["self_propelled"]
        assert sp["verdict"] == verdict, sp
