"""`hindrax allocate` and `hindrax thruster-test --dry-run` as users run them."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config

HINDRAX = str(Path(sys.executable).with_name("hindrax"))


def run(*args):
    return subprocess.run([HINDRAX, *args], capture_output=True, text=True, timeout=60)


def independent_model():
    """Matrix (FLU) and forward curve rebuilt here from the YAML numbers with plain numpy ([Hindrax-Drag] eqs. 1, 9)."""
    cfg = load_config(default_config_path())
    t = cfg.thrusters
    flu = np.diag([1.0, -1.0, -1.0])
    cols = []
    for th in t.thrusters:
        d, r = th.direction_frd, th.position_frd_m
        cols.append(np.concatenate([flu @ d, flu @ np.cross(r, d)]))
    neg, pos = np.poly1d(t.curve_negative), np.poly1d(t.curve_positive)

    def thrust(p):
        return np.where(p < 1475.0, neg(p), np.where(p > 1525.0, pos(p), 0.0))

    return np.array(cols).T, thrust


def test_allocate_prints_the_documented_json():
    r = run("allocate", "10", "-4", "5", "0.2", "0", "-0.3")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert set(out) == {"force_n", "pulse_width_us", "achieved_wrench", "scale", "saturated"}
    assert len(out["force_n"]) == len(out["pulse_width_us"]) == len(out["saturated"]) == 8
    b, thrust = independent_model()
    forces = thrust(np.array(out["pulse_width_us"]))
    assert np.allclose(forces, out["force_n"], atol=1e-3)
    assert np.allclose(b @ forces, out["achieved_wrench"], atol=1e-3)
    # unsaturated and away from the curves' 1.2 N minimum thrust: the request is met within 1 % of authority
    authority = np.abs(b) @ np.full(8, 15.5)
    assert np.all(np.abs(b @ forces - [10, -4, 5, 0.2, 0, -0.3]) < 0.05 * authority)


def test_allocate_small_surge_runs_a_pair_instead_of_rounding_every_thruster_up():
    """Issue 26: with each horizontal thruster rounded up to its smallest thrust (1.2 N) this gave -2.77 N of surge
    and 0.28 N m of pitch; the deadband search runs one symmetric pair at about 1.74 N."""
    r = run("allocate", "-2", "0", "0", "0", "0", "0")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    b, thrust = independent_model()
    forces = thrust(np.array(out["pulse_width_us"]))
    achieved = b @ forces
    assert np.allclose(achieved, out["achieved_wrench"], atol=1e-3)
    assert abs(achieved[0] - -2.0) <= 0.15
    assert np.all(np.abs(achieved[[1, 5]]) < 1e-3)  # no sway, no yaw
    assert np.all(np.abs(achieved[2:5]) < 0.05)  # heave, roll and pitch: what the pulse-width step leaves
    p = np.array(out["pulse_width_us"])
    assert np.all((np.abs(p - 1500.0) <= 0.62) | (np.abs(p - 1500.0) >= 25.0))  # neutral or outside the deadband
    assert np.count_nonzero(forces[:4]) == 2


def test_allocate_keeps_heave_when_surge_saturates():
    """The shipped priority mode: [60 0 -40 0 0 3] keeps the -40 N heave and the 3 N m yaw, surge gets the rest."""
    out = json.loads(run("allocate", "60", "0", "-40", "0", "0", "3").stdout)
    b, thrust = independent_model()
    achieved = b @ thrust(np.array(out["pulse_width_us"]))
    assert abs(achieved[2] - -40.0) <= 0.15 and abs(achieved[5] - 3.0) <= 0.05
    assert 0.0 < achieved[0] < 60.0 and any(out["saturated"])


def test_allocate_saturates_with_scale():
    out = json.loads(run("allocate", "200", "0", "0", "0", "0", "0").stdout)
    assert 0 < out["scale"] < 1 and any(out["saturated"])


def test_allocate_rejects_nan():
    r = run("allocate", "nan", "0", "0", "0", "0", "0")
    assert r.returncode == 1 and "finite" in r.stderr


def test_thruster_test_dry_run_predicts_each_thruster():
    r = run("thruster-test", "--dry-run", "--force-n", "3")
    assert r.returncode == 0, r.stderr
    rows = [json.loads(line) for line in r.stdout.splitlines()]
    assert [row["thruster"] for row in rows] == [f"t{i}" for i in range(1, 9)]
    b, thrust = independent_model()
    for i, row in enumerate(rows):
        assert thrust(np.array([row["pulse_width_us"]]))[0] == pytest.approx(3.0, abs=0.01)
        assert np.allclose(row["expected_wrench_base_link"], b[:, i] * row["force_n"], atol=1e-3)
    # T1 pushes forward and to starboard (base_link: +x, -y) at 55 degrees
    assert rows[0]["expected_wrench_base_link"][0] > 0 > rows[0]["expected_wrench_base_link"][1]
