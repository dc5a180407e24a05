"""Empirical priors ([NTNU-Thesis] Sec. 3.1, App. A.1/A.2) against the thesis's printed "Empirical" columns.

Expected numbers are copied by hand from the thesis's tables (cited at each case); a printed value counts as
reproduced when our value rounds to it (half a unit of its last printed digit, plus 1e-4 relative for the
thesis's rounding of values that sit on a rounding boundary, e.g. Table 4.4 sway 18.840 vs 18.84050).

Which printed inputs produced which table (what the thesis prints, and what it does not):

* Table 4.4 (ROV Neptunus added mass): the App. A.1 script's own inputs (L 404, H 214, W 108 mm, rho 1000,
  front 22256, side 86456, top 27500 mm^2). All six reproduced.
* Tables 4.2/4.3 (SF-30k damping): the App. A.2 script's own inputs (L 2500, H 1500, W 1600 mm, rho 1025, front
  1678091, side 1956253, top 3384000 mm^2, I44 525, I55 794, A44 356, A55 980, C 7073). Eleven of twelve
  reproduced; Table 4.3 surge 792.7 is not (see the test: it contradicts the same run's Table 4.2 surge).
* Table 4.1 (SF-30k added mass): the box of App. E.1 (LWH 2500 x 1500 x 1600 mm, i.e. height 1600 and width
  1500: Table 1.1 prints them the other way round), Table 1.1's areas (top 4 000 000 mm^2) and rho 1025.
  Surge, sway, heave reproduced; the three rotations are not (common factor, see the test).
* Tables 4.5/4.6 (Neptunus damping): no script inputs printed. Table 1.2's front area 23112 mm^2 with the App.
  A.1 side and top (Table 1.2's side, 1956253, is the SF-30k value and its top is A.1's side) reproduces surge,
  sway, roll and yaw quadratic and surge and sway linear; heave and pitch quadratic are left out (not reproduced
  by any printed input; the thesis's own article, App. F Table 3, prints heave 19.2536 for the value Table 4.6
  prints as 16.2536), and roll/pitch/yaw linear need I44, I55, A44, A55, C of that run, which are not printed.
* Table 4.10 (Seabotix LBV600-6 added mass): Table 1.3's box with the 300 mm width of "484(300)" and rho 1025
  comes within 2.5 % of all six but does not reproduce them (the areas of that run are not printed exactly).
* Tables 4.7-4.9 (VideoRay PRO-4), 4.11-4.12 (Seabotix damping), 4.13-4.15 (AC-ROV 100): left out; the
  dimensions and areas of Tables 1.3-1.5 (and App. E) give values up to a factor 2 away, so the inputs of
  those runs are not the printed ones.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from hindrax_common.config import DOFS, default_config_path, load_config
from hindrax_tools import cli
from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_onboard.estimation.priors import (Geometry, PriorInputs, added_mass_priors, empirical_priors,
                                             priors_from_config, quadratic_damping_priors)

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

MM, MM2 = 1e-3, 1e-6


def _printed(value: float, printed: str) -> bool:
    """True when ``value`` rounds to the printed number (half a unit of its last digit, + 1e-4 relative)."""
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    p = float(printed)
    return abs(value - p) <= 0.5 * 10.0 ** -decimals + 1e-4 * abs(p)


def _check(values, printed_row):
    bad = [(i, float(v), p) for i, (v, p) in enumerate(zip(values, printed_row))
           if p is not None and not _printed(v, p)]
    assert not bad, bad


# [NTNU-Thesis] App. A.1 script inputs (ROV Neptunus)
NEPTUNUS_A1 = Geometry(404 * MM, 108 * MM, 214 * MM, 1000.0, 22256 * MM2, 86456 * MM2, 27500 * MM2)
# [NTNU-Thesis] App. A.2 script inputs (SF-30k)
SF30K_A2 = Geometry(2500 * MM, 1600 * MM, 1500 * MM, 1025.0, 1678091 * MM2, 1956253 * MM2, 3384000 * MM2)
SF30K_A2_RIGID = PriorInputs(roll_inertia_kg_m2=525.0, pitch_inertia_kg_m2=794.0, roll_added_kg_m2=356.0,
                             pitch_added_kg_m2=980.0, restoring_n_m_per_rad=7073.0)


def test_table_4_4_neptunus_added_mass_from_the_app_a1_inputs():
    _check(added_mass_priors(NEPTUNUS_A1), ["1.926", "18.840", "5.993", "0.014", "0.052", "0.091"])


def test_tables_4_2_and_4_3_sf30k_damping_from_the_app_a2_inputs():
    out = empirical_priors(SF30K_A2, SF30K_A2_RIGID)
    _check(out["linear_damping"], ["126.9", "175.0", "315.9", "124.8", "177.1", "107.4"])        # Table 4.2
    _check(out["quadratic_damping"], [None, "1093.6", "1974.2", "275.4", "943.6", "572.1"])       # Table 4.3
    # Table 4.3 surge prints 792.7, which the same run's Table 4.2 surge contradicts: the script sets
    # BL11 = 0.16 BQ11, and 0.16 x 792.7 = 126.83 would print 126.8, not 126.9. Our BQ11 (792.97) is the value
    # consistent with the printed 126.9; 792.7 is not reproduced (a transcription slip in Table 4.3).
    bq11 = out["quadratic_damping"][0]
    assert _printed(0.16 * bq11, "126.9") and not _printed(0.16 * 792.7, "126.9")
    assert not _printed(bq11, "792.7") and _printed(bq11, "793.0")


def test_table_4_1_sf30k_added_mass_translations_and_the_rotations_common_factor():
    g = Geometry(2500 * MM, 1500 * MM, 1600 * MM, 1025.0, 1678091 * MM2, 1956253 * MM2, 4000000 * MM2)
    A = added_mass_priors(g)
    _check(A[:3], ["932.9", "1516.5", "3100.8"])
    # Not reproduced: roll, pitch, yaw print 201.9, 657.0, 515.1; ours are larger by one common factor
    # (1/0.9147), i.e. a different input entering all three rotations alike (Cp product or lambda), which the
    # printed inputs do not show. Asserted as documented: the three ratios agree to 0.1 %.
    ratios = np.array([201.9, 657.0, 515.1]) / A[3:]
    assert np.ptp(ratios) < 1e-3 * ratios.mean()
    assert ratios.mean() == pytest.approx(0.9147, abs=5e-4)


def test_tables_4_5_and_4_6_neptunus_damping_where_the_inputs_are_printed():
    g = Geometry(404 * MM, 108 * MM, 214 * MM, 1000.0, 23112 * MM2, 86456 * MM2, 27500 * MM2)
    bq = quadratic_damping_priors(g)
    # heave (16.2536) and pitch (0.0552) left out: not reproduced by any printed input (module docstring)
    _check(bq, ["12.459", "83.2442", None, "0.022", None, "0.1698"])                             # Table 4.6
    bl = empirical_priors(g)["linear_damping"]
    _check(bl[:1], ["1.993"])                                                                     # Table 4.5
    # Table 4.5 sway prints 13.139; the script's 0.16 x 83.2442 (Table 4.6) = 13.319, which the thesis's
    # article prints (App. F Table 3: 13.32): 13.139 is a digit transposition, not reproduced.
    assert _printed(bl[1], "13.32") and not _printed(bl[1], "13.139")
    assert bl[3:] == [None, None, None]   # roll/pitch/yaw linear need I, A, C: not printed for Neptunus


def test_table_4_10_seabotix_added_mass_is_within_the_documented_band_only():
    g = Geometry(540 * MM, 300 * MM, 270 * MM, 1025.0, 69063 * MM2, 103104 * MM2, 142275 * MM2)
    A = added_mass_priors(g)
    printed = np.array([10.6322, 23.5517, 32.7863, 0.0719, 0.2925, 0.2736])
    rel = A / printed - 1.0
    # documented discrepancy: within 2.5 % of every printed value, but not reproduced to the printed digits
    assert np.all(np.abs(rel) < 0.025), rel
    assert not all(_printed(a, f"{p}") for a, p in zip(A, printed))


def test_priors_from_the_vehicle_file_and_units():
    cfg = load_config(default_config_path())
    out = priors_from_config(cfg)
    for key in ("added_mass", "linear_damping", "quadratic_damping"):
        assert len(out[key]) == 6 and all(v is not None and v > 0 for v in out[key]), key
    # restoring from the file: m g BG with BG = 0.03 m (CB 3 cm above the CG)
    assert out["inputs"]["restoring_n_m_per_rad"] == pytest.approx(15.22 * 9.81 * 0.03)
    assert "solid prism" in out["notes"][0]
    # a smaller projected area (open frame) lowers the surge terms: Cp enters squared in A11's 3D value
    open_frame = priors_from_config(cfg, frontal_area_m2=0.5 * 0.47 * 0.40)
    assert open_frame["added_mass"][0] < out["added_mass"][0]
    assert open_frame["quadratic_damping"][0] == pytest.approx(0.5 * out["quadratic_damping"][0])


def test_geometry_is_validated():
    with pytest.raises(EstimationError, match="width_m"):
        Geometry(1.0, -1.0, 1.0, 1000.0, 1.0, 1.0, 1.0)


def test_cli_priors_geometry_and_config(tmp_path, capsys):
    args = ["ident", "priors", "--length-m", "0.404", "--width-m", "0.108", "--height-m", "0.214",
            "--density-kg-m3", "1000", "--frontal-area-m2", "0.022256", "--side-area-m2", "0.086456",
            "--top-area-m2", "0.0275"]
    assert cli.main(args) == 0
    out = json.loads(capsys.readouterr().out)
    _check(out["added_mass"], ["1.926", "18.840", "5.993", "0.014", "0.052", "0.091"])       # Table 4.4
    assert len(out["linear_damping"]) == len(out["quadratic_damping"]) == 6
    assert cli.main(["ident", "priors", "--config", str(default_config_path())]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["inputs"]["length_m"] == pytest.approx(0.59)
    assert cli.main(["ident", "priors", "--length-m", "1"]) == 1
    assert "missing --width-m" in capsys.readouterr().err


def test_identification_yaml_shows_the_priors_beside_the_identified_values():
    from hindrax_onboard.identification.model.dof_model import (DofIdentification, parameter_names, parameter_units,
                                                            truth_parameters)
    from hindrax_fit.assessment.results import build_results

    cfg = load_config(default_config_path())
    truth = truth_parameters(cfg, "surge")
    names = parameter_names("surge")
    std = {n: 0.01 * abs(truth[n]) + 1e-3 for n in names}
    ident = DofIdentification(dof="surge", names=names, values=dict(truth), std=std,
                              ci95={n: (truth[n] - 2 * std[n], truth[n] + 2 * std[n]) for n in names},
                              method="output-error", residual_dof=100,
                              equation_error={n: (truth[n], std[n]) for n in names},
                              online={n: (truth[n], std[n]) for n in names}, steady=None, steady_note="none",
                              truth=truth, units=parameter_units("surge"), pool_time_s=50.0, rls_time_s=20.0,
                              steady_time_s=None)
    doc = build_results({"surge": ident}, cfg)
    prior = doc["dofs"]["surge"]["prior"]
    expected = priors_from_config(cfg)
    assert prior["added_mass"] == pytest.approx(expected["added_mass"][DOFS.index("surge")])
    assert prior["quadratic_damping"] == pytest.approx(expected["quadratic_damping"][0])
    assert "NTNU-Thesis" in prior["source"]
    # the report's references section shows the prior beside the identified value, and the calibration
    from hindrax_fit.fit.calibration import calibration_section
    from hindrax_fit.assessment.report import references_html

    doc["calibration"] = calibration_section({"vertical": {"value": 0.9012, "std": 0.0044, "known_force_n": 8.56,
                                                           "holding_force_n": [0.85, -8.65], "method": "ballast"}})
    page = references_html(doc)
    assert "References" in page and "0.9012" in page and "ballast" in page
    ratio = expected["added_mass"][0] / truth["added_mass"]
    assert f"{ratio:.3g}" in page and "outside" in page      # the solid-prism prior is far above Table 6's 12.08 kg
    assert references_html({"dofs": {}}) == ""


def test_table_spline_is_scipys_not_a_knot_spline():
    """The priors' tables are interpolated by the module's own not-a-knot spline (scipy.interpolate stays out of the
    identification node's process): the same values as scipy's CubicSpline(bc_type="not-a-knot"), inside the
    table and extrapolated, for 2 to 9 points (the tables have 4-9) and for each table of the module."""
    import numpy as np
    from scipy.interpolate import CubicSpline

    from hindrax_onboard.estimation.priors import ADDED_MASS_2D, ADDED_MASS_3D, DRAG_2D, DRAG_3D, not_a_knot_spline

    rng = np.random.default_rng(3)
    cases = [(np.sort(rng.choice(np.linspace(0.0, 10.0, 201), n, replace=False)), rng.normal(size=n))
             for n in (2, 3, 4, 5, 7, 9) for _ in range(10)]
    for table in (ADDED_MASS_3D, DRAG_2D, DRAG_3D):
        rows = sorted(table)
        cases.append((np.array([r[0] for r in rows]), np.array([r[1] for r in rows])))
    rows = sorted(ADDED_MASS_2D)
    cases += [(np.array([r[0] for r in rows]), np.array([r[k] for r in rows])) for k in (1, 2)]
    for x, y in cases:
        ours, ref = not_a_knot_spline(x, y), CubicSpline(x, y, bc_type="not-a-knot")
        for v in np.linspace(x[0] - 2.0, x[-1] + 2.0, 41):
            assert ours(v) == pytest.approx(float(ref(v)), rel=1e-9, abs=1e-9)
    with pytest.raises(EstimationError):
        not_a_knot_spline([1.0, 1.0, 2.0], [0.0, 1.0, 2.0])
