"""``hindrax ident fit`` and ``hindrax ident bag``: honest intervals and the config-ready flag.

* The reported covariance is the cluster-robust (sandwich) covariance with contiguous blocks of segments as
  clusters, blocks lengthened while their scores are correlated (lag-1 autocorrelation above 0.2) down to 6 clusters,
  at least the model-based one, with Student t on clusters - 1 degrees of freedom (docs/identification.md §7,
  [Liang-Zeger1986], [Bester-Conley-Hansen2011]). On a synthetic surge record whose dynamics carry an unrecorded,
  slowly varying force (Ornstein-Uhlenbeck, 60 s correlation time: residuals correlated across the 10 s segments)
  the blocks grow and the bias std follows the correlation; with white measurement noise only, the reported std stays
  the model-based one within a factor 1.5.
* Without ``--config`` the file holds ``inertia`` but no ``added_mass``: ``config_ready: false`` with the reason,
  printed too, and :func:`~hindrax_fit.assessment.results.to_config_overrides` refuses it in one line.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy import signal, stats

from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_fit.fit import fit_core
from hindrax_sim.piloted_bag import PilotSettings, write_piloted_bag
from hindrax_fit.assessment.results import IdentificationFileError, to_config_overrides

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

#: surge truth of the synthetic record: inertia kg, quadratic damping kg/m, linear damping kg/s, bias N
TRUTH = np.array([30.0, 20.0, 5.0, 0.0])
NAMES = ["inertia", "quadratic_damping", "linear_damping", "bias"]


def _record(seed: int, disturbance_std_n: float, segments: int = 36, h: float = 0.05) -> fit_core.DofRecord:
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
    win = 11
    ch = fit_core.Chunk(f, signal.savgol_filter(z, win, 2), np.zeros(n), signal.savgol_filter(z, win, 2, deriv=1,
                                                                                            delta=h),
                        np.arange(n, dtype=float), z, group=0)
    return fit_core.DofRecord("surge", h, "velocity", [ch], "thrust_model", 0.0)


def test_cluster_covariance_by_hand():
    """One parameter, residuals and Jacobian chosen by hand: model-based sigma^2 / sum J^2 (with the lag-1
    inflation), and the sandwich G / (G - 1) sum_g (J_g . r_g)^2 / (J . J)^2 with one cluster per segment."""
    J = np.array([[1.0], [2.0], [1.0], [1.0], [2.0], [2.0], [1.0], [3.0]])
    r = np.array([0.5, -0.5, 1.0, 0.25, -0.25, 0.5, 0.5, -1.0])
    seg = np.array([0, 0, 1, 1, 2, 2, 3, 3])
    m = 4
    sd = fit_core.SegmentData(0.1, 4, np.zeros((3, m, 4)), np.zeros((3, m, 4, 0)), np.zeros(m), np.zeros(m), seg,
                              np.ones(8, int), np.zeros(8), np.zeros(8), np.zeros(m, int), np.zeros((m, 2)),
                              np.ones(m, bool), np.zeros((m, 4)), np.zeros((m, 4)), np.zeros((m, 4)))
    fit = fit_core.FitOutcome([("a", "inertia", 0.0, np.inf)], np.array([1.0]), None, r,
                              np.ones(8), J, 1.0)
    cov = fit_core.cluster_covariance(fit, sd, min_clusters=2)
    jj = float(J[:, 0] @ J[:, 0])
    scores = np.array([J[seg == g, 0] @ r[seg == g] for g in range(m)])
    sand = m / (m - 1) * float(scores @ scores) / jj ** 2
    num = sum(r[i] * r[i - 1] for i in range(1, 8) if seg[i] == seg[i - 1])
    rho = max(0.0, num / float(r @ r))
    model = float(r @ r) / (8 - 1) / jj * (1 + rho) / (1 - rho)
    assert cov.sandwich[0, 0] == pytest.approx(sand, rel=1e-12)
    assert cov.model[0, 0] == pytest.approx(model, rel=1e-12)
    assert cov.cov[0, 0] == pytest.approx(max(sand, model), rel=1e-12)
    assert cov.clusters == 4 and cov.t_dof == 3


def _fit(rec):
    opts = fit_core.CoreOptions(select=False, terms=fit_core.Terms("both"), folds=6)
    r = fit_core.identify_dof(rec, opts)
    assert r.names == NAMES and r.terms == fit_core.Terms("both")
    return r


def test_coloured_disturbance_the_blocks_grow_and_the_std_follows():
    r = _fit(_record(seed=0, disturbance_std_n=3.0))
    i = NAMES.index("bias")
    cov = r.covariance
    sd_model = np.sqrt(cov.model[i, i])
    # the residuals are correlated across segments: blocks of several segments, the model-based std too small ...
    assert cov.block >= 2 and cov.clusters >= 6, (cov.block, cov.clusters, cov.rho)
    assert np.sqrt(cov.sandwich[i, i]) > 1.5 * sd_model
    # ... the reported one is the sandwich's, with t on clusters - 1 degrees of freedom
    assert r.std[i] == pytest.approx(np.sqrt(cov.sandwich[i, i]), rel=1e-9)
    tq = stats.t.ppf(0.975, cov.clusters - 1)
    assert r.ci95[i, 1] - r.theta[i] == pytest.approx(tq * r.std[i], rel=1e-9)
    assert r.ci95[i, 0] < TRUTH[i] < r.ci95[i, 1]
    for j in range(4):  # never narrower than either estimate
        assert r.std[j] >= np.sqrt(max(cov.model[j, j], cov.sandwich[j, j])) * (1 - 1e-12)


def test_white_noise_the_std_stays_the_model_based_std():
    r = _fit(_record(seed=0, disturbance_std_n=0.0))
    cov = r.covariance
    assert cov.t_dof >= 5  # never the 2 degrees of freedom of three folds
    for j, name in enumerate(NAMES):
        sm = np.sqrt(cov.model[j, j])
        assert r.std[j] <= 1.5 * sm, (name, r.std[j], sm)
        assert r.ci95[j, 0] < TRUTH[j] < r.ci95[j, 1], (name, r.theta[j], r.ci95[j])


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
    assert e["inertia"]["std_source"] in ("model", "cluster_robust")
    fit_sd = max(e["inertia"]["std_model"], e["inertia"]["std_cluster_robust"])
    assert e["inertia"]["std_fit"] == pytest.approx(fit_sd)  # no vehicle file: no priors
    # the thrust-curve uncertainty on top (the default 5 % reverse / 10 % forward, both directions weigh 1/2 in surge)
    thrust_sd = abs(e["inertia"]["value"]) * math.sqrt(0.25 * 0.05 ** 2 + 0.25 * 0.10 ** 2)
    assert e["inertia"]["std"] == pytest.approx(math.hypot(fit_sd, thrust_sd))
    # the printed table shows the file's std and interval (one verdict path), not the fit's alone
    row = next(x for x in printed.splitlines() if x.split()[:2] == ["surge", "inertia"])
    assert f"{e['inertia']['std']:.3g}" in row and f"{e['inertia']['ci95'][1]:.4g}" in row
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


def test_folds_hold_out_blocks_of_moving_segments_only():
    """A campaign moves one DOF after the other: sway only in segments 20..28 of 30. The folds are contiguous blocks
    of the moving validation segments (so every fold holds sway motion), and a fold's training leaves out the
    training segments that overlap its held-out ones."""
    m, L, h = 30, 50, 0.2
    n = m * L
    v = np.zeros(n)
    v[20 * L:29 * L] = 0.3
    ch = fit_core.Chunk(np.zeros(n), v, np.zeros(n), np.zeros(n), np.arange(n, dtype=float), v, group=0)
    rec = fit_core.DofRecord("sway", h, "velocity", [ch], "thrust_model")
    timing = fit_core.Timing()
    sv = fit_core.build_segments(rec, fit_core.Terms(), timing, L * h, excited_only=False)
    st = fit_core.build_segments(rec, fit_core.Terms(), timing, L * h / 2, excited_only=False)
    folds = fit_core.make_folds(st, sv, 3)
    assert [f.tolist() for f in folds.held] == [[20, 21, 22], [23, 24, 25], [26, 27, 28]]
    for held, train in zip(folds.held, folds.train):  # the half-length training segments of the held-out span
        out = sorted(set(range(st.m)) - set(train.tolist()))
        assert out == list(range(2 * held[0], 2 * held[-1] + 2))
