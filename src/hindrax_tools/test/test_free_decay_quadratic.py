"""Free decay with quadratic damping: ``hindrax ident free-decay --model quadratic`` and the ODE fit.

Records are generated here by an independent integrator (classical fixed-step Runge-Kutta 4 with 20 sub-steps per
sample: hindrax_test_support.decay) of M x'' + b1 x' + b2 |x'| x' + k x = 0 ([SmallROV] eq. 12 with the spring
of [Hindrax-AM] eq. 1), released from rest; the fit under test uses scipy's solve_ivp. Conditions: the
[Hindrax-AM] Table 5 rig (k_eq 659.9 N/m, m_b 0.39 kg, added mass 0.82 kg, A 20 mm, 330 Hz, 10 s) with
a quadratic damping of the [SmallROV] Table 10 order (b2 a few N s^2/m^2 for a body of this size) and a
small linear term, plus accelerometer noise and bias. With this damping the decrement depends on the amplitude,
so the log-decrement analysis (linear model) reports one equivalent linear damping several times b1: biased.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from hindrax_tools import cli
from hindrax_onboard.estimation.free_decay import fit_quadratic_free_decay
from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_test_support.decay import rk4_decay

K, MB, MAD, B1, B2, AMP, V = 659.9, 0.39, 0.82, 0.4, 5.0, 0.02, 0.00056


def _csv(path, seed=3):
    t, _x, _v, a = rk4_decay(K, MB + MAD, B1, B2, AMP, 10.0, 330.0)
    rng = np.random.default_rng(seed)
    t = np.concatenate([np.arange(-165, 0) / 330.0, t])          # 0.5 s held before the release
    a = np.concatenate([np.zeros(165), a]) + 0.15 + 0.05 * rng.standard_normal(t.size)
    with open(path, "w") as fh:
        fh.write("time_s,acceleration_m_s2\n")
        for ti, ai in zip(t, a):
            fh.write(f"{ti:.6f},{ai:.9f}\n")


def test_quadratic_model_recovers_damping_where_the_linear_analysis_is_biased(tmp_path, capsys):
    f = tmp_path / "decay.csv"
    _csv(f)
    base = ["ident", "free-decay", str(f), "--stiffness", str(K), "--mass", str(MB), "--volume", str(V)]
    assert cli.main(base) == 0
    linear = json.loads(capsys.readouterr().out)
    assert cli.main(base + ["--model", "linear"]) == 0
    assert json.loads(capsys.readouterr().out) == linear           # default is linear, output unchanged
    assert "quadratic_damping_n_s2_per_m2" not in linear
    assert cli.main(base + ["--model", "quadratic"]) == 0
    quad = json.loads(capsys.readouterr().out)
    # the linear keys are still there, with the same values
    assert {k: quad[k] for k in linear} == linear
    # the linear analysis is biased: its equivalent damping (eq. 6) is several times the true linear term
    assert linear["damping_n_s_per_m"] > 3.0 * B1
    # the ODE fit recovers both terms and the added mass, with intervals that cover the truth
    for key, truth, rel in (("linear_damping_n_s_per_m", B1, 0.10),
                            ("quadratic_damping_n_s2_per_m2", B2, 0.05),
                            ("added_mass_ode_kg", MAD, 0.01)):
        est, std = quad[key], quad[key + "_std"]
        assert est == pytest.approx(truth, rel=rel), key
        assert 0.0 < std < rel * truth, key
        assert abs(est - truth) < 4.0 * std, key
    assert quad["ode_rms_residual_m_s2"] == pytest.approx(0.05, rel=0.1)   # the noise level: nothing left


def test_rotational_decay_from_a_rate_gyro_gives_total_inertia():
    """Roll-like decay (restoring C, rigid + added inertia, hydrostatic restoring) seen through a noisy gyro."""
    C, I_RB, I_A, b1, b2 = 4.48, 0.4831, 0.48, 0.05, 1.29
    t, _phi, p, _a = rk4_decay(C, I_RB + I_A, b1, b2, 0.25, 20.0, 100.0)
    rng = np.random.default_rng(7)
    rate = p + 0.004 + 0.003 * rng.standard_normal(t.size)
    fit = fit_quadratic_free_decay(t + 3.0, rate, C, rigid_inertia=I_RB, output="velocity")
    assert fit.total_inertia == pytest.approx(I_RB + I_A, rel=0.01)
    assert fit.added_inertia == pytest.approx(I_A, rel=0.02)
    assert fit.quadratic_damping == pytest.approx(b2, rel=0.1)
    assert abs(fit.total_inertia - (I_RB + I_A)) < 4.0 * fit.total_inertia_std
    assert fit.bias == pytest.approx(0.004, abs=0.001)


def test_fit_rejects_bad_input():
    t = np.arange(100) / 100.0
    with pytest.raises(EstimationError, match="output must be one of"):
        fit_quadratic_free_decay(t, np.sin(5 * t), 1.0, output="jerk")
    with pytest.raises(EstimationError, match="stiffness"):
        fit_quadratic_free_decay(t, np.sin(5 * t), -1.0)
    with pytest.raises(EstimationError):
        fit_quadratic_free_decay(t[:10], np.sin(5 * t[:10]), 1.0)
