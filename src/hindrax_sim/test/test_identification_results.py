"""identification.yaml (docs/architecture.md §5): schema, round trip, provenance, and the configuration overrides the
simulator reads; plus the configured truth used by the acceptance test ([Hindrax-Drag] §5)."""
from __future__ import annotations


import numpy as np
import pytest
import yaml

from hindrax_common.config import DOFS, default_config_path, load_config
from hindrax_onboard.identification.model.dof_model import (DofIdentification, parameter_names, parameter_units,
                                                        regressor_matrix, truth_parameters)
from hindrax_fit.assessment.report import write_report
from hindrax_fit.assessment.results import (IdentificationFileError, build_results,
                                                             read_identification, to_config_overrides,
                                                             write_identification)
from hindrax_sim.simulator import Simulator

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module")
def cfg():
    # no empirical priors: the file must show the fake fits' values unchanged (the priors: test_joint_estimation.py)
    return load_config(default_config_path(), {"identification.prior_std_rel": 0.0})


def _fake(cfg, dof, scale=1.1):
    """A DofIdentification whose values are the configured ones times ``scale`` (std 1 % of the value)."""
    truth = truth_parameters(cfg, dof)
    names = parameter_names(dof)
    values = {n: truth[n] * scale for n in names}
    values["added_mass"] = values["inertia"] - (truth["inertia"] - truth["added_mass"])
    std = {n: 0.01 * abs(v) + 1e-3 for n, v in values.items()}
    ci = {n: (values[n] - 2 * std[n], values[n] + 2 * std[n]) for n in values}
    return DofIdentification(dof=dof, names=names, values=values, std=std, ci95=ci, method="output-error",
                             residual_dof=100, equation_error={n: (values[n], std[n]) for n in names},
                             online={n: (values[n], std[n]) for n in names}, steady=None, steady_note="none",
                             truth=truth, units=parameter_units(dof), pool_time_s=50.0, rls_time_s=20.0,
                             steady_time_s=None)


def test_truth_values_follow_the_seeds(cfg):
    heave = truth_parameters(cfg, "heave")
    # [Hindrax-Drag] §5: f_b = (rho V - m) g = (1000 * 0.0153 - 15.22) * 9.81 = 0.785 N, FRD force holding depth
    assert heave["bias"] == pytest.approx((1000 * 0.0153 - 15.22) * 9.81)
    assert heave["inertia"] == pytest.approx(15.22 + 22.48)  # rigid + [Hindrax-AM] Table 6
    assert heave["quadratic_damping_positive"] == pytest.approx(93.52)  # [Hindrax-Drag] Table 3
    roll = truth_parameters(cfg, "roll")
    # restoring: z_g W - z_b B with the CB 3 cm above the CG -> 0.03 rho g V
    assert roll["restoring"] == pytest.approx(0.03 * 1000 * 9.81 * 0.0153)
    assert truth_parameters(cfg, "surge")["bias"] == 0.0


def test_regressor_rows():
    X = regressor_matrix("heave", [1.0, 2.0], [0.5, -0.5])
    assert X.tolist() == [[1.0, 0.25, 0.0, 0.5, 0.0, 1.0], [2.0, 0.0, -0.25, 0.0, -0.5, 1.0]]
    X = regressor_matrix("roll", [0.0], [-2.0], [0.5])
    assert X.tolist() == [[0.0, -4.0, -2.0, 1.0, 0.5]]


def test_round_trip_and_schema(cfg, tmp_path):
    idents = {d: _fake(cfg, d) for d in DOFS}
    doc = build_results(idents, cfg, source="simulation", seed=5)
    path = write_identification(tmp_path / "identification.yaml", doc)
    back = read_identification(path)
    assert back["provenance"]["configuration_sha256"] == cfg.sha256
    assert back["provenance"]["water_density_kg_m3"] == 1000.0
    assert back["provenance"]["seed"] == 5 and back["provenance"]["source"] == "simulation"
    for key in ("date", "method"):
        assert back["provenance"][key]
    assert back["dofs"]["surge"]["inertia"]["value"] == pytest.approx(idents["surge"].values["inertia"])
    assert back["dofs"]["surge"]["inertia"]["unit"] == "kg"
    assert back["dofs"]["yaw"]["quadratic_damping"]["unit"] == "kg m^2"
    assert back["dofs"]["heave"]["quadratic_damping_negative"]["std"] > 0
    assert "restoring" in back["dofs"]["pitch"]


def test_drag_coefficient_and_reynolds_range_of_table_4(cfg):
    """[Hindrax-Drag] Table 4 columns: C_D = 2 k_q / (rho A_p) with A_p the box face normal to the motion, and the
    Reynolds range |v| V^(1/3) / nu of the speeds above 0.05 m/s; none for rotations."""
    surge = _fake(cfg, "surge", scale=1.0)
    surge.signals = {"velocity": np.array([0.0, 0.02, 0.2, -0.45, 0.3])}
    doc = build_results({"surge": surge, "heave": _fake(cfg, "heave", scale=1.0), "yaw": _fake(cfg, "yaw")}, cfg)
    d = doc["dofs"]["surge"]["drag_coefficient"]
    area = 0.47 * 0.40  # width x height, [Hindrax-Drag] §2.1
    assert d["projected_area_m2"] == pytest.approx(area)
    assert d["c_d"][0] == pytest.approx(2 * 66.48 / (1000.0 * area))  # k_q of [Hindrax-Drag] Table 3 -> 0.707
    assert d["c_d"][1] == pytest.approx(2 * surge.std["quadratic_damping"] / (1000.0 * area))
    length = 0.0153 ** (1 / 3)  # [Hindrax-AM] eq. 10: V^(1/3) = 0.2483 m
    assert d["reynolds_range"] == pytest.approx([0.2 * length / 1.01e-6, 0.45 * length / 1.01e-6])
    h = doc["dofs"]["heave"]["drag_coefficient"]
    assert h["c_d_positive"][0] == pytest.approx(2 * 93.52 / (1000.0 * 0.59 * 0.47))
    assert h["c_d_negative"][0] == pytest.approx(2 * 56.57 / (1000.0 * 0.59 * 0.47))
    assert h["reynolds_range"] is None  # no speeds recorded in this fake
    assert "drag_coefficient" not in doc["dofs"]["yaw"]


@pytest.mark.parametrize("mutate, key", [
    (lambda d: d["dofs"]["surge"].pop("inertia"), "dofs.surge.inertia"),
    (lambda d: d["dofs"]["heave"]["bias"].pop("unit"), "dofs.heave.bias.unit"),
    (lambda d: d["dofs"]["roll"]["inertia"].update(value="big"), "dofs.roll.inertia.value"),
    (lambda d: d["provenance"].pop("configuration_sha256"), "provenance.configuration_sha256"),
    (lambda d: d["dofs"].update(swirl=d["dofs"]["surge"]), "dofs.swirl"),
])
def test_schema_errors_name_the_key(cfg, tmp_path, mutate, key):
    doc = build_results({d: _fake(cfg, d) for d in DOFS}, cfg)
    doc = yaml.safe_load(yaml.safe_dump(doc))
    mutate(doc)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(IdentificationFileError, match=key.replace(".", r"\.")):
        read_identification(p)


def test_unreadable_file(tmp_path):
    with pytest.raises(IdentificationFileError, match="cannot read"):
        read_identification(tmp_path / "missing.yaml")
    (tmp_path / "x.yaml").write_text("a: [1, 2\n")
    with pytest.raises(IdentificationFileError, match="not valid YAML"):
        read_identification(tmp_path / "x.yaml")


def test_overrides_feed_configuration_and_simulator(cfg, tmp_path):
    doc = build_results({d: _fake(cfg, d, scale=1.2) for d in DOFS}, cfg)
    overrides = to_config_overrides(doc)
    cfg2 = load_config(default_config_path(), overrides=overrides)
    for d in DOFS:
        h0, h2 = cfg.dof_hydrodynamics(d), cfg2.dof_hydrodynamics(d)
        assert h2.added_mass == pytest.approx(doc["dofs"][d]["added_mass"]["value"])
        assert h2.quadratic_damping_positive == pytest.approx(1.2 * h0.quadratic_damping_positive)
        assert h2.linear_damping_negative == pytest.approx(1.2 * h0.linear_damping_negative)
    sim = Simulator(cfg2, sensors=False)
    assert sim.model.damping_quadratic_negative[2] == pytest.approx(1.2 * 56.57)
    assert sim.model.mass_matrix[0, 0] == pytest.approx(doc["dofs"]["surge"]["inertia"]["value"])


def test_negative_damping_is_clipped_in_overrides(cfg):
    f = _fake(cfg, "roll")
    f.values["linear_damping"] = -0.1
    doc = build_results({"roll": f}, cfg)
    assert to_config_overrides(doc)["hydrodynamics.roll.linear_damping_kg_m2_s"] == 0.0


def test_report_writes_html_and_pngs(cfg, tmp_path):
    import numpy as np
    f = _fake(cfg, "surge")
    t = np.linspace(0, 10, 200)
    v = 0.5 * np.sin(t)
    f.signals = {"t": t, "velocity": v, "acceleration": 0.5 * np.cos(t), "force": 66.48 * np.abs(v) * v,
                 "restoring": None, "windows": [(0.3, 6.0)], "covariance": np.eye(4) * 0.01,
                 "online_history": {"t": list(t[:20]), "theta": [np.ones(4)] * 20, "std": [np.ones(4) * 0.1] * 20,
                                    "excitation": [0.1] * 20}}
    doc = build_results({"surge": f}, cfg)
    index = write_report(tmp_path / "report", {"surge": f}, doc)
    text = index.read_text()
    assert "surge_force_velocity.png" in text and "surge_rls.png" in text
    assert (tmp_path / "report" / "surge_force_velocity.png").stat().st_size > 1000
    assert (tmp_path / "report" / "surge_rls.png").stat().st_size > 1000


def test_a_report_plot_is_laid_out_once_and_drawn_once(tmp_path, monkeypatch):
    """The report's plots (a dozen per campaign) are laid out by tight_layout and then drawn once by
    savefig, not twice (the placeholder engine tight_layout leaves makes savefig draw the figure
    before drawing it again)."""
    import matplotlib.figure
    import matplotlib.pyplot as plt

    from hindrax_fit.assessment import report

    draws = []
    draw = matplotlib.figure.Figure.draw
    monkeypatch.setattr(matplotlib.figure.Figure, "draw",
                        lambda self, r: (draws.append(self), draw(self, r))[1])
    fig, ax = plt.subplots(2, 1)
    ax[0].plot([0.0, 1.0], [0.0, 1.0])
    ax[1].set_ylabel("a long label that tight_layout has to make room for")
    report._save(fig, tmp_path / "p.png")
    assert len(draws) == 1 and (tmp_path / "p.png").read_bytes().startswith(b"\x89PNG")
