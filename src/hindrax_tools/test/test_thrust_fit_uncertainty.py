"""The thrust curve's own uncertainty in the identification intervals:
`hindrax ident thruster-fit --write` stores the fit's relative thrust std per direction as
``thrusters.thrust_fit_uncertainty_rel``, and the intervals use it instead of the declared
``thrusters.thrust_uncertainty_rel``."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_onboard.estimation.thruster_fit import fit_thruster_curve, point_reflection
from hindrax_onboard.identification.model.dof_model import (DofIdentification, parameter_names, parameter_units,
                                                        truth_parameters)
from hindrax_fit.assessment.verdicts import assess_dof

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def _bollard(cfg, noise_n, seed=4, repeats=1):
    neg = cfg.thrusters.curve_negative
    pos = point_reflection(*neg)
    pw = np.tile(np.concatenate([np.arange(1100, 1480, 10.0), np.arange(1530, 1901, 10.0)]), repeats)
    f = np.where(pw < 1500, np.polyval(neg, pw), np.polyval(pos, pw))
    return pw, f + np.random.default_rng(seed).normal(0.0, noise_n, pw.size)


def _independent_relative_std(pw, f, lo, hi):
    """The same definition computed with numpy.polyfit's covariance (not the code under test): sqrt(sum sd^2 /
    sum f^2) of the fitted mean thrust on 101 widths over the data's range."""
    s = (pw - 1500.0) / 400.0
    coef, cov = np.polyfit(s, f, 3, cov="unscaled")
    resid = f - np.polyval(coef, s)
    cov = cov * float(resid @ resid) / (f.size - 4)
    grid = (np.linspace(lo, hi, 101) - 1500.0) / 400.0
    X = np.vander(grid, 4)
    sd2 = np.einsum("ij,jk,ik->i", X, cov, X)
    return float(np.sqrt(sd2.sum() / np.sum(np.polyval(coef, grid) ** 2)))


def test_relative_std_matches_an_independent_computation_and_scales_with_the_noise():
    cfg = load_config(default_config_path())
    pw, f = _bollard(cfg, 0.05)
    fit = fit_thruster_curve(pw, f)
    neg_rel, pos_rel = fit.relative_std()
    m = pw < 1500
    assert neg_rel == pytest.approx(_independent_relative_std(pw[m], f[m], 1100.0, 1470.0), rel=0.05)
    assert pos_rel == pytest.approx(_independent_relative_std(pw[~m], f[~m], 1530.0, 1900.0), rel=0.05)
    assert 1e-4 < neg_rel < 0.02
    loud = fit_thruster_curve(*_bollard(cfg, 1.0)).relative_std()
    assert 10.0 < loud[0] / neg_rel < 40.0  # 20 x the noise: 20 x the std (and a different noise draw)


def _surge_ident(cfg):
    truth = truth_parameters(cfg, "surge")
    names = parameter_names("surge")
    values = {n: truth[n] for n in names}
    values["added_mass"] = truth["added_mass"]
    std = {n: 0.005 * abs(v) + 1e-3 for n, v in values.items()}
    return DofIdentification(dof="surge", names=names, values=values, std=std, ci95={}, method="output-error",
                             residual_dof=5000, equation_error={}, online={}, steady=None, steady_note="",
                             truth=truth, units=parameter_units("surge"), pool_time_s=90.0, rls_time_s=None,
                             steady_time_s=None, signals={"covariance": np.diag([std[n] ** 2 for n in names]),
                                                          "residual_autocorrelation": 0.05,
                                                          "velocity": np.linspace(-0.4, 0.4, 201), "windows": []})


def _width(cfg_path, name="quadratic_damping"):
    cfg = load_config(cfg_path)
    p = assess_dof(_surge_ident(cfg), cfg)["parameters"][name]
    return p["ci95"][1] - p["ci95"][0], p


@pytest.mark.parametrize("noise_n, narrower", [(0.02, True), (5.0, False)])
def test_thruster_fit_write_sets_the_interval_width(tmp_path, capsys, noise_n, narrower):
    """A bollard-pull fit with a small covariance narrows the intervals below the declared default
    ([0.05, 0.10]); one with a large covariance widens them."""
    cfg = load_config(default_config_path())
    csv = tmp_path / "bollard.csv"
    pw, f = _bollard(cfg, noise_n)
    csv.write_text("pulse_width_us,thrust_n\n" + "".join(f"{p},{x}\n" for p, x in zip(pw, f)))
    conf = tmp_path / "hindrax.yaml"
    shutil.copy(default_config_path(), conf)
    declared_width, declared = _width(conf)
    assert cli.main(["ident", "thruster-fit", str(csv), "--write", str(conf)]) == 0
    out = json.loads(capsys.readouterr().out)
    rel = out["thrust_fit_uncertainty_rel"]
    assert rel == [out["negative"]["thrust_relative_std"], out["positive"]["thrust_relative_std"]]
    cfg2 = load_config(conf)
    assert cfg2.flat["thrusters.thrust_fit_uncertainty_rel"] == pytest.approx(rel, rel=1e-9)
    width, p = _width(conf)
    assert p["std_fit"] == pytest.approx(declared["std_fit"])  # the fit's own part is unchanged
    # surge uses both directions with weight 1/2: var = std_fit^2 + theta^2 (rel_neg^2 + rel_pos^2) / 4
    theta = declared["value"]
    expected = np.sqrt(p["std_fit"] ** 2 + theta ** 2 * (rel[0] ** 2 + rel[1] ** 2) / 4.0)
    assert p["std"] == pytest.approx(expected, rel=1e-9)
    if narrower:
        assert max(rel) < 0.01 and width < 0.5 * declared_width
    else:
        assert min(rel) > 0.10 and width > 1.2 * declared_width
    # a second --write replaces the line it added instead of adding another
    assert cli.main(["ident", "thruster-fit", str(csv), "--write", str(conf)]) == 0
    assert conf.read_text().count("thrust_fit_uncertainty_rel:") == 1


def test_the_joint_estimate_scale_prior_follows_the_fit_too():
    """Each rotation direction's scale has the prior of its own curve (issue 26 item 1)."""
    from hindrax_fit.fit.calibration import scale_prior_stds

    declared = load_config(default_config_path())
    fitted = load_config(default_config_path(), {"thrusters.thrust_fit_uncertainty_rel": [0.006, 0.008]})
    neg, pos = declared.flat["thrusters.thrust_uncertainty_rel"]
    assert scale_prior_stds(declared) == {"forward": pos, "reverse": neg}
    assert scale_prior_stds(fitted) == {"forward": 0.008, "reverse": 0.006}
