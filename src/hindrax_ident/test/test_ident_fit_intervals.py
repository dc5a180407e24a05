"""``hindrax ident fit`` (issue 18): honest intervals and the config-ready flag.

* The reported std is the larger of the output-error std and the delete-a-group jackknife std of the K fold
  estimates, var_J = (K - 1) / K sum_k (theta_k - mean)^2 (Efron and Stein 1981; Shao and Tu 1995 §2.3;
  docs/identification.md §7), with ``std_source`` naming it. On a synthetic surge record whose dynamics carry an
  unrecorded, slowly varying force (Ornstein-Uhlenbeck, 60 s correlation time: residuals correlated across the 10 s
  segments, which the output-error covariance treats as independent) the bias std follows the fold spread; with
  white measurement noise only, the reported std stays the output-error std within a factor 1.5.
* Without ``--config`` the file holds ``inertia`` but no ``added_mass``: ``config_ready: false`` with the reason,
  printed too, and :func:`~hindrax_ident.identification.results.to_config_overrides` refuses it in one line.
"""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from hindrax_drivers.config import default_config_path, load_config
from hindrax_ident import cli
from hindrax_ident.identification.fit_any import BagSegments, _folds, fit_dof, honest_interval, jackknife_std
from hindrax_ident.identification.piloted_bag import PilotSettings, write_piloted_bag
from hindrax_ident.identification.results import IdentificationFileError, to_config_overrides

#: surge truth of the synthetic record: inertia kg, quadratic damping kg/m, linear damping kg/s, bias N
TRUTH = np.array([30.0, 20.0, 5.0, 0.0])
NAMES = ["inertia", "quadratic_damping", "linear_damping", "bias"]


def _record(seed: int, disturbance_std_n: float, segments: int = 36, h: float = 0.05) -> BagSegments:
    """Surge record in 10 s segments on a grid of h: piecewise-constant recorded force (holds of 2-6 s, +-25 N);
    the vehicle (M u' + k_q |u| u + k_l u + b = force + d) also feels d, an unrecorded Ornstein-Uhlenbeck force
    (60 s correlation time, ``disturbance_std_n``); velocity measured with 0.01 m/s white noise. Integrated with
    10 RK4 sub-steps per grid step."""
    rng = np.random.default_rng(seed)
    L = int(round(10.0 / h))
    n = segments * L
    f = np.empty(n)
    i = 0
    while i < n:
        d = int(rng.uniform(2.0, 6.0) / h)
        f[i:i + d] = rng.uniform(-25.0, 25.0)
        i += d
    dist = np.zeros(n)
    a = np.exp(-h / 60.0)
    for j in range(1, n):
        dist[j] = a * dist[j - 1] + disturbance_std_n * np.sqrt(1 - a * a) * rng.standard_normal()
    m_, kq, kl, b = TRUTH

    def acc(u, force):
        return (force - kq * abs(u) * u - kl * u - b) / m_

    v = np.zeros(n)
    dt = h / 10
    for j in range(n - 1):
        u, force = v[j], f[j] + dist[j]
        for _ in range(10):
            k1 = acc(u, force)
            k2 = acc(u + 0.5 * dt * k1, force)
            k3 = acc(u + 0.5 * dt * k2, force)
            k4 = acc(u + dt * k3, force)
            u += dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        v[j + 1] = u
    z = v + 0.01 * rng.standard_normal(n)
    force6 = np.zeros((segments, L, 6))
    vel6 = np.full((segments, L, 6), np.nan)
    force6[..., 0] = f.reshape(segments, L)
    vel6[..., 0] = z.reshape(segments, L)
    return BagSegments(force6, vel6, np.zeros((segments, L, 3)), np.zeros(segments, int),
                       np.ones((segments, L), bool), h)


def test_jackknife_and_interval_by_hand():
    # fold estimates 1, 2, 3 (K = 3): mean 2, sum of squares 2, var_J = 2/3 * 2 = 4/3
    assert jackknife_std([[1.0], [2.0], [3.0]])[0] == pytest.approx(np.sqrt(4.0 / 3.0), rel=1e-12)
    std, ci, src, jk = honest_interval(np.array([2.0, 10.0]), np.array([0.5, 2.0]),
                                       [[1.0, 10.0], [2.0, 10.5], [3.0, 9.5]], n_segments=31)
    assert src == ["jackknife", "output_error"]
    assert std == pytest.approx([np.sqrt(4.0 / 3.0), 2.0])
    # Student t: 2 degrees of freedom (K - 1) for the jackknife, 30 (segments - 1) for the output error
    assert ci[0] == pytest.approx([2.0 - 4.302652729749 * np.sqrt(4.0 / 3.0), 2.0 + 4.302652729749 * np.sqrt(4.0 / 3.0)])
    assert ci[1] == pytest.approx([10.0 - 2.042272456301 * 2.0, 10.0 + 2.042272456301 * 2.0])
    # fewer than two folds: the output-error std alone
    std, _ci, src, jk = honest_interval(np.array([1.0]), np.array([0.1]), [[1.2]], n_segments=10)
    assert src == ["output_error"] and jk is None and std[0] == 0.1
    with pytest.raises(ValueError, match="at least 2"):
        jackknife_std([[1.0]])


def _fit(seg):
    m = len(seg)
    folds = np.array_split(np.arange(m), 6)  # contiguous blocks of 6 segments (60 s)
    r = fit_dof(seg, "surge", "surge", NAMES, folds, {})
    assert r.status == "fitted" and len(r.folds) == 6 and r.names == NAMES
    return r


def test_coloured_disturbance_the_std_follows_the_fold_spread():
    r = _fit(_record(seed=0, disturbance_std_n=3.0))
    i = NAMES.index("bias")
    folds = np.array(r.folds)[:, i]
    jk = np.sqrt(5.0 / 6.0 * np.sum((folds - folds.mean()) ** 2))
    # the residuals are correlated across segments: the fit's own std is too small for the bias ...
    assert jk > 1.5 * r.oe_std[i], (jk, r.oe_std[i])
    # ... and the reported one is the jackknife's, its interval from t with K - 1 = 5 degrees of freedom
    assert r.std_source[i] == "jackknife" and r.std[i] == pytest.approx(jk, rel=1e-9)
    assert r.ci95[i, 1] - r.theta[i] == pytest.approx(2.570581835636 * jk, rel=1e-9)
    assert r.ci95[i, 0] < TRUTH[i] < r.ci95[i, 1]
    for j in range(4):  # never narrower than either estimate
        assert r.std[j] >= max(r.oe_std[j], r.jackknife_std[j]) * (1 - 1e-12)


def test_white_noise_the_std_stays_the_output_error_std():
    r = _fit(_record(seed=0, disturbance_std_n=0.0))
    for j, name in enumerate(NAMES):
        assert r.std[j] <= 1.5 * r.oe_std[j], (name, r.std[j], r.oe_std[j], r.std_source[j])
        assert r.ci95[j, 0] < TRUTH[j] < r.ci95[j, 1], (name, r.theta[j], r.ci95[j])
    # with white noise either estimate may be the larger by chance; the two agree within the factor above
    assert all(0.5 * r.oe_std[j] < r.jackknife_std[j] < 1.5 * r.oe_std[j] for j in range(4)), (r.oe_std,
                                                                                             r.jackknife_std)


@pytest.fixture(scope="module")
def short_bag(tmp_path_factory):
    root = tmp_path_factory.mktemp("cfgready")
    cfg = load_config(default_config_path())
    return root, write_piloted_bag(root / "bag", cfg, seed=3, settings=PilotSettings(duration_s=60.0, gap=None,
                                                                                     axes=(0,)))


def test_without_config_the_file_is_not_config_ready(short_bag, capsys):
    root, bag = short_bag
    out = root / "no_cfg"
    assert cli.main(["ident", "fit", str(bag), "--dofs", "surge", "--folds", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "config_ready: false" in printed and "--config" in printed
    doc = yaml.safe_load((out / "identification.yaml").read_text())
    assert doc["config_ready"] is False and "--config" in doc["config_ready_reason"]
    e = doc["dofs"]["surge"]
    assert "inertia" in e and "added_mass" not in e
    assert e["inertia"]["std_source"] in ("output_error", "jackknife")
    assert e["inertia"]["std"] == max(e["inertia"]["std_output_error"], e["inertia"]["std_jackknife"])
    with pytest.raises(ValueError) as exc:
        to_config_overrides(doc)
    msg = str(exc.value)
    assert isinstance(exc.value, IdentificationFileError) and len(msg.splitlines()) == 1
    assert "not config-ready" in msg and "added_mass" in msg and "--config" in msg and "ident fit" in msg
    # an older file without the flag but without added_mass says the same
    doc.pop("config_ready")
    with pytest.raises(ValueError, match="not config-ready.*surge.*--config"):
        to_config_overrides(doc)


def test_with_config_the_file_is_config_ready(short_bag, capsys):
    root, bag = short_bag
    out = root / "cfg"
    assert cli.main(["ident", "fit", str(bag), "--dofs", "surge", "--folds", "2", "--config",
                     str(default_config_path()), "--out", str(out)]) == 0
    assert "config_ready: false" not in capsys.readouterr().out
    doc = yaml.safe_load((out / "identification.yaml").read_text())
    assert doc["config_ready"] is True
    over = to_config_overrides(doc)
    assert over["hydrodynamics.surge.added_mass_kg"] == pytest.approx(max(0.0, doc["dofs"]["surge"]["added_mass"]
                                                                             ["value"]))


def test_one_bag_folds_share_out_the_segments_that_move_the_dof():
    # a campaign moves one DOF after the other: sway only in segments 20..28 of 30; contiguous thirds would leave
    # two folds without sway motion (their estimates, and the jackknife of them, meaningless)
    m, L = 30, 50
    vel = np.zeros((m, L, 6))
    vel[20:29, :, 1] = 0.3
    seg = BagSegments(np.zeros((m, L, 6)), vel, np.zeros((m, L, 3)), np.zeros(m, int), np.ones((m, L), bool), 0.2)
    folds = _folds(seg, 1, 3, "sway")
    assert sorted(np.concatenate(folds).tolist()) == list(range(m))  # a partition
    assert [sorted(set(f.tolist()) & set(range(20, 29))) for f in folds] == [[20, 21, 22], [23, 24, 25], [26, 27, 28]]
    # the segments that do not move sway stay in contiguous blocks (a slow drift still moves the fold estimates)
    assert [sorted(set(f.tolist()) - set(range(20, 29))) for f in folds] == [
        list(range(0, 7)), list(range(7, 14)), list(range(14, 20)) + [29]]
    assert [f.tolist() for f in _folds(seg, 1, 3)] == [list(range(0, 10)), list(range(10, 20)), list(range(20, 30))]
