"""The control model: the vehicle file's, identification.yaml with its verdicts, and bad input (docs/control.md §4).

Expected values are the vehicle file's printed numbers ([Hindrax-AM] Table 6, [Hindrax-Drag] Table 3) and the values
written into the test's own identification files, not recomputed by the loader."""
import math

import pytest
import yaml

from hindrax_common.config import default_config_path, load_config
from hindrax_onboard.control.model import VEHICLE_FILE, ModelFileError, load_model, model_from_config
from hindrax_onboard.vehicle.vehicle_match import vehicle_parameters


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def test_vehicle_file_model(cfg):
    m = model_from_config(cfg)
    heave = m.axis("heave")
    assert heave.inertia == pytest.approx(15.22 + 22.48)  # mass + [Hindrax-AM] Table 6 heave added mass
    assert heave.quadratic_damping_positive == pytest.approx(93.52)  # [Hindrax-Drag] Table 3, down
    assert heave.linear_damping_negative == pytest.approx(11.84)
    assert heave.bias == pytest.approx(1000.0 * 9.81 * 0.0153 - 15.22 * 9.81)  # (rho V - m) g
    assert m.axis("roll").restoring == pytest.approx(0.03 * 1000.0 * 9.81 * 0.0153)  # CB 3 cm above the CG
    assert m.axis("yaw").inertia == pytest.approx(0.7217 + 0.55)
    # no stated uncertainty of the file's added mass: the declared thrust uncertainty, RMS of [0.05, 0.10]
    assert heave.inertia_rel_std == pytest.approx(math.sqrt((0.05 ** 2 + 0.10 ** 2) / 2))
    assert heave.damping(0.2) == pytest.approx(5.26 * 0.2 + 93.52 * 0.04)
    assert heave.damping(-0.2) == pytest.approx(-(11.84 * 0.2 + 56.57 * 0.04))
    assert m.notes == ()
    assert set(heave.sources.values()) == {VEHICLE_FILE}


def _par(value, std, verdict="trusted", reasons=()):
    return {"value": value, "std": std, "unit": "x", "verdict": verdict, "reasons": list(reasons)}


def _doc(cfg, heave=None, sha=None, joint=None):
    heave = heave or {
        "inertia": _par(50.0, 2.0), "added_mass": _par(34.78, 2.0),
        "quadratic_damping_positive": _par(120.0, 10.0), "quadratic_damping_negative": _par(80.0, 5.0),
        "linear_damping_positive": _par(8.0, 1.0), "linear_damping_negative": _par(15.0, 1.0),
        "bias": _par(0.95, 0.1)}
    doc = {"schema_version": 1, "provenance": {"source": "simulation", "date": "2026-11-22T00:00:00+00:00",
                                               "configuration_sha256": cfg.sha256 if sha is None else sha,
                                               "water_density_kg_m3": 1000.0, "method": "test", "seed": 1},
           "dofs": {"heave": heave, "yaw": {"inertia": _par(1.8, 0.1), "added_mass": _par(1.08, 0.1),
                                            "quadratic_damping": _par(0.9, 0.05), "linear_damping": _par(2.5, 0.2),
                                            "bias": _par(0.0, 0.001)}},
           "a_future_key": {"anything": [1, 2, 3]}}
    if joint:
        doc["joint"] = joint
    return doc


def _write(tmp_path, doc, name="identification.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(doc))
    return p


def test_identified_values_and_their_sources(cfg, tmp_path):
    m = load_model(_write(tmp_path, _doc(cfg)), cfg)
    h = m.axis("heave")
    assert h.inertia == 50.0 and h.quadratic_damping_positive == 120.0 and h.linear_damping_negative == 15.0
    assert h.bias == 0.95
    assert h.inertia_rel_std == pytest.approx(2.0 / 50.0)
    assert h.sources["inertia"] == "identified" and h.sources["damping"] == "identified"
    assert m.axis("yaw").inertia == 1.8 and m.axis("yaw").quadratic_damping_negative == 0.9  # both directions
    # DOFs the file does not hold keep the vehicle file's values, and the notes say so
    assert m.axis("surge").inertia == pytest.approx(15.22 + 12.08)
    assert any("surge" in n and "vehicle file" in n for n in m.notes)


def test_suspect_parameter_falls_back_unless_the_reason_is_only_the_thrust_curve(cfg, tmp_path):
    whiteness = "residuals not white (lag-1 autocorrelation 0.44 > 0.2)"
    thrust = ("heave bias differs from the configured net buoyancy (z = +4.1): the thrust curves do not match the "
              "vehicle, every thrust-derived parameter is suspect")
    bias = ("bias +0.952 N differs from the expected +0.785 N (z = +3.3): an unmodelled force "
            "(current, tether, thrust offset)")
    doc = _doc(cfg)
    doc["dofs"]["heave"]["inertia"] = _par(50.0, 2.0, "suspect", [bias])
    doc["dofs"]["heave"]["quadratic_damping_positive"] = _par(120.0, 10.0, "suspect", [bias, whiteness])
    doc["dofs"]["yaw"]["inertia"] = _par(1.8, 0.1, "suspect", [thrust])
    doc["dofs"]["yaw"]["linear_damping"] = _par(-0.3, 0.2)
    m = load_model(_write(tmp_path, doc), cfg)
    h = m.axis("heave")
    assert h.inertia == 50.0  # suspect only because the holding force differs: used (commanded-thrust units)
    assert h.quadratic_damping_positive == pytest.approx(93.52)  # not white: the vehicle file's value
    assert "residuals not white" in h.sources["damping"]
    assert m.axis("yaw").inertia == 1.8  # suspect only because the thrust curve is off: used
    assert m.axis("yaw").linear_damping_positive == pytest.approx(1.47)  # negative: the vehicle file's
    assert "< 0" in m.axis("yaw").sources["damping"]


def test_calibrated_identification_is_divided_by_its_thrust_scale(cfg, tmp_path):
    joint = {"scales": {"vertical": {"value": 0.8, "std": 0.01, "dofs": ["heave"]}}}
    m = load_model(_write(tmp_path, _doc(cfg, joint=joint)), cfg)
    assert m.axis("heave").inertia == pytest.approx(50.0 / 0.8)
    assert m.axis("heave").bias == pytest.approx(0.95 / 0.8)
    assert m.axis("yaw").inertia == 1.8  # not in the vertical group
    assert any("thrust scale" in n for n in m.notes)


@pytest.mark.parametrize("content, words", [
    (None, "cannot read"),
    ("dofs: [unclosed", "not valid YAML"),
    ("just a string\n", "no 'dofs' mapping"),
])
def test_bad_files_are_an_error_of_one_line(cfg, tmp_path, content, words):
    """Issue 45.4: no silent fallback to the vehicle file."""
    p = tmp_path / "identification.yaml"
    if content is not None:
        p.write_text(content)
    with pytest.raises(ModelFileError) as exc:
        load_model(p, cfg)
    assert words in str(exc.value) and str(p) in str(exc.value) and "\n" not in str(exc.value)


def test_another_vehicle_is_an_error(cfg, tmp_path):
    with pytest.raises(ModelFileError, match="another vehicle file text"):  # a file from before vehicle_parameters
        load_model(_write(tmp_path, _doc(cfg, sha="ab" * 32)), cfg)
    doc = _doc(cfg)
    doc["provenance"]["configuration_sha256"] = None  # hindrax ident fit without --config
    with pytest.raises(ModelFileError, match="no provenance.vehicle_parameters"):
        load_model(_write(tmp_path, doc), cfg)


def test_the_vehicle_is_matched_by_the_parameters_the_identification_depends_on(cfg, tmp_path):
    """Issue 45.4: a comment, the ESC calibration or the disk floor changed in the vehicle file (other text, other
    SHA-256) keeps the identification; a changed rigid inertia does not, and the error names the key."""
    doc = _doc(cfg, sha="ab" * 32)  # the text differs ...
    doc["provenance"]["vehicle_parameters"] = vehicle_parameters(cfg)  # ... the parameters it depends on do not
    m = load_model(_write(tmp_path, doc), cfg)
    assert m.source != VEHICLE_FILE and m.axis("heave").inertia == pytest.approx(50.0)
    text = default_config_path().read_text()
    edited = tmp_path / "edited.yaml"
    assert "min_free_disk_mb: 2000.0" in text
    edited.write_text("# a comment\n" + text.replace("min_free_disk_mb: 2000.0", "min_free_disk_mb: 500.0"))
    assert load_model(_write(tmp_path, doc), load_config(edited)).axis("heave").inertia == pytest.approx(50.0)
    other = load_config(default_config_path(), {"vehicle.inertia_kg_m2": [0.5, 0.6444, 0.7217]})
    with pytest.raises(ModelFileError) as exc:
        load_model(_write(tmp_path, doc), other)
    assert "vehicle.inertia_kg_m2 [0.4831, 0.6444, 0.7217] -> [0.5, 0.6444, 0.7217]" in str(exc.value)


def test_a_holding_force_no_thrust_scale_explains_makes_the_force_terms_fall_back(cfg, tmp_path):
    """Forward thrust 5 % and reverse 15 % weak (scenario thrust_asymmetric): the heave fit put the net buoyancy into
    the per-direction linear damping, so its bias is near zero and every heave parameter is suspect for that bias
    alone. The bias and the damping are then no model to feed forward: they fall back; the inertia stays."""
    file_heave = model_from_config(cfg).axis("heave")
    assert file_heave.bias > 0.0  # the rule needs a holding force in the vehicle file
    why = (f"bias -0.0143 N differs from the expected {file_heave.bias:+.3g} N (z = -15.9): an unmodelled force "
           "(current, tether, thrust offset)")
    values = {"inertia": (41.9, 1.0), "added_mass": (26.7, 1.0), "quadratic_damping_positive": (80.9, 8.0),
              "quadratic_damping_negative": (88.5, 8.0), "linear_damping_positive": (12.3, 1.0),
              "linear_damping_negative": (5.7, 1.0), "bias": (-0.0143, 0.05)}
    doc = _doc(cfg, heave={k: _par(v, s, "suspect", [why]) for k, (v, s) in values.items()})
    h = load_model(_write(tmp_path, doc), cfg).axis("heave")
    assert h.inertia == 41.9 and h.sources["inertia"] == "identified"
    assert h.bias == file_heave.bias
    assert (h.linear_damping_positive, h.linear_damping_negative) == (file_heave.linear_damping_positive,
                                                                      file_heave.linear_damping_negative)
    assert (h.quadratic_damping_positive, h.quadratic_damping_negative) == (file_heave.quadratic_damping_positive,
                                                                            file_heave.quadratic_damping_negative)
    for key in ("bias", "damping"):
        assert h.sources[key].startswith(VEHICLE_FILE) and "force error" in h.sources[key]
    # the same reason with a bias a weak thrust explains (file / 0.85): the identified force terms are used
    scaled = file_heave.bias / 0.85
    why = f"bias {scaled:+.3g} N differs from the expected {file_heave.bias:+.3g} N (z = +3.3): an unmodelled force"
    values["bias"] = (scaled, 0.03)
    doc = _doc(cfg, heave={k: _par(v, s, "suspect", [why]) for k, (v, s) in values.items()})
    h = load_model(_write(tmp_path, doc), cfg).axis("heave")
    assert h.bias == pytest.approx(scaled) and h.linear_damping_positive == 12.3
    assert h.sources["bias"] == "identified" and h.sources["damping"] == "identified"
