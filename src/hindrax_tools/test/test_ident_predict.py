"""``hindrax ident predict``: the CSV it writes, scored by an independent script written from the
definition the tool documents (nrmse = RMS(predicted - measured) / std(measured) over the rows with a segment),
gives the nrmse the tool prints for its own segment rule; ``--segment-s`` restarts every S seconds."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_tools import cli
from hindrax_sim.piloted_bag import PilotSettings, write_piloted_bag


def _read(path):
    """(header comment, rows as float arrays t, segment, measured, predicted (NaN when empty))."""
    with open(path, newline="") as fh:
        first = fh.readline()
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    seg = np.array([int(r["segment"]) for r in rows])
    meas = np.array([float(r["measured"]) for r in rows])
    pred = np.array([float(r["predicted"]) if r["predicted"] else math.nan for r in rows])
    return first, t, seg, meas, pred


def _independent_nrmse(seg, meas, pred):
    use = (seg >= 0) & ~np.isnan(pred)
    e = pred[use] - meas[use]
    return math.sqrt(float(np.mean(e * e))) / float(np.std(meas[use]))


def _printed(out: str) -> dict:
    rows = {}
    for line in out.splitlines():
        f = line.split()
        if len(f) == 8 and f[1] in ("surge", "yaw"):
            rows[f[1]] = {"segments": int(f[2]), "samples": int(f[3]), "nrmse": float(f[4])}
    return rows


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A model of surge and yaw fitted on one piloted bag, and a held-out bag."""
    root = tmp_path_factory.mktemp("predict")
    cfg = load_config(default_config_path())
    train = write_piloted_bag(root / "train", cfg, seed=2, settings=PilotSettings(duration_s=120.0))
    hold = write_piloted_bag(root / "hold", cfg, seed=9, settings=PilotSettings(duration_s=60.0))
    assert cli.main(["ident", "fit", str(train), "--dofs", "surge,yaw", "--out", str(root / "fit")]) == 0
    return root, hold


def test_predict_csv_scored_independently_matches_the_printed_nrmse(fitted, capsys):
    root, hold = fitted
    capsys.readouterr()
    out = root / "pred"
    assert cli.main(["ident", "predict", str(hold), "--model", str(root / "fit" / "identification.yaml"),
                     "--out", str(out)]) == 0
    printed = _printed(capsys.readouterr().out)
    assert set(printed) == {"surge", "yaw"}
    for dof, unit in (("surge", "m/s"), ("yaw", "rad/s")):
        first, t, seg, meas, pred = _read(out / f"hold_{dof}.csv")
        assert first.startswith(f"# {dof} velocity") and unit in first and "FRD" in first
        assert np.all(np.diff(t) > 0) and t.size > 400  # the 10 Hz measurements of 60 s
        use = (seg >= 0) & ~np.isnan(pred)
        assert use.sum() == printed[dof]["samples"] and np.unique(seg[use]).size == printed[dof]["segments"]
        assert np.all(np.isnan(pred[seg < 0]))
        nrmse = _independent_nrmse(seg, meas, pred)
        assert nrmse == pytest.approx(printed[dof]["nrmse"], abs=6e-4)
        assert nrmse < 0.5  # the model predicts the held-out bag (a broken simulation would not)
        # the tool's rule: 10 s segments, each re-initialised
        for s in np.unique(seg[use]):
            assert np.ptp(t[seg == s]) < 10.0
    # --segment-s: restarts every S seconds from the first instant with force and velocity
    out = root / "pred5"
    capsys.readouterr()
    assert cli.main(["ident", "predict", str(hold), "--model", str(root / "fit" / "identification.yaml"),
                     "--out", str(out), "--segment-s", "5"]) == 0
    printed = _printed(capsys.readouterr().out)
    _first, t, seg, meas, pred = _read(out / "hold_surge.csv")
    use = (seg >= 0) & ~np.isnan(pred)
    assert _independent_nrmse(seg, meas, pred) == pytest.approx(printed["surge"]["nrmse"], abs=6e-4)
    # segments of at most 5 s whose first measurements lie on one 5 s grid (within the 0.1 s between measurements)
    starts = []
    for s in np.unique(seg[use]):
        ts = t[seg == s]
        assert np.ptp(ts) < 5.0
        starts.append(ts.min())
    d = np.array(starts) - starts[0]
    assert np.all(np.abs(d - 5.0 * np.round(d / 5.0)) <= 0.1 + 1e-6)
    # 60 s with a gap: about 12 segments, more than the tool's rule would give
    assert 10 <= np.unique(seg[use]).size <= 15


def test_residual_autocorrelation_of_the_report_follows_its_definition():
    from hindrax_fit.assessment.report import residual_acf

    rng = np.random.default_rng(4)
    # an AR(1) residual with coefficient 0.8 in 40 segments of 100 samples: lag-k autocorrelation 0.8^k
    seg = np.repeat(np.arange(40), 100)
    e = np.zeros(seg.size)
    w = rng.normal(size=seg.size)
    for i in range(1, seg.size):
        e[i] = (0.8 * e[i - 1] if seg[i] == seg[i - 1] else 0.0) + w[i]
    acf = residual_acf(seg, e, 3)
    assert acf[0] == pytest.approx(1.0)
    assert acf[1:] == pytest.approx([0.8, 0.64, 0.512], abs=0.05)
    # pairs across segments do not count: shuffled segments of white noise stay near 0
    assert abs(residual_acf(seg, w, 1)[1]) < 0.05
