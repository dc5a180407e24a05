"""Vehicle configuration: the shipped file loads, the papers' numbers are where they should be, every error path
produces one line naming key, value and allowed range."""
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from hindrax_common.config import (DOFS, SCHEMA, ConfigError, config_from_parameters, default_config_path,
                                    flatten, load_config, ros_parameters_from_yaml)

CONFIG = default_config_path()


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIG)


def write(tmp_path: Path, params: dict) -> Path:
    p = tmp_path / "v.yaml"
    p.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return p


def base_params() -> dict:
    return ros_parameters_from_yaml(yaml.safe_load(CONFIG.read_text()))


def test_real_file_loads_cleanly(cfg):
    assert CONFIG.name == "hindrax.yaml" and CONFIG.parent.name == "config"
    assert len(cfg.sha256) == 64


def test_paper_numbers(cfg):
    # [Hindrax-AM] §2 / [Hindrax-Drag] §2.1
    assert cfg.vehicle.mass_kg == 15.22 and cfg.vehicle.displaced_volume_m3 == 0.0153
    assert (cfg.vehicle.length_m, cfg.vehicle.width_m, cfg.vehicle.height_m) == (0.59, 0.47, 0.40)
    # net buoyancy: [Hindrax-Drag] §5 computes f_b = 0.7845 N with rho = 1000 kg/m^3
    assert cfg.buoyancy_n - cfg.weight_n == pytest.approx(0.7845, abs=2e-3)
    # [Hindrax-AM] Table 6
    assert np.diag(cfg.added_mass_matrix)[:3].tolist() == [12.08, 19.43, 22.48]
    # [Hindrax-Drag] Table 3, including the direction-dependent heave rows
    assert cfg.dof_hydrodynamics("surge").quadratic_damping_positive == 66.48
    assert cfg.dof_hydrodynamics("sway").linear_damping_positive == 14.54
    heave = cfg.dof_hydrodynamics("heave")
    assert (heave.quadratic_damping_positive, heave.linear_damping_positive) == (93.52, 5.26)
    assert (heave.quadratic_damping_negative, heave.linear_damping_negative) == (56.57, 11.84)
    assert cfg.dof_hydrodynamics("yaw").quadratic_damping_positive == 0.55
    # substituted negative linear damping (roll -0.12, pitch -0.13 in Table 3) is non-negative
    assert all(cfg.dof_hydrodynamics(d).linear_damping_positive >= 0 for d in DOFS)
    # PWM range, [Hindrax-Drag] §2.2.1
    t = cfg.thrusters
    assert (t.pulse_width_min_us, t.pulse_width_neutral_us, t.pulse_width_max_us) == (1100.0, 1500.0, 1900.0)
    assert t.curve_negative == (-4.61e-7, 0.001794, -2.2726, 927.1827)


def test_negative_thrust_curve_as_printed_and_positive_is_its_point_reflection(cfg):
    t = cfg.thrusters
    neg = np.poly1d(t.curve_negative)
    pos = np.poly1d(t.curve_positive)
    assert neg(1100) == pytest.approx(-15.6, abs=0.1)  # docs/architecture.md §4
    assert neg(1500) == pytest.approx(-1.1, abs=0.05)
    for d in np.linspace(0, 400, 41):
        assert pos(1500 + d) == pytest.approx(-neg(1500 - d), abs=1e-6)
    printed_positive = np.poly1d([-3.52e-7, 1.82e-4, -0.3106, 174.3542])
    assert printed_positive(1500) == pytest.approx(-1070, abs=1)  # why the printed row is not used


def test_layout_is_55_degrees_and_symmetric(cfg):
    t = cfg.thrusters
    d = t.directions_frd
    a = math.radians(55)
    assert d[0] == pytest.approx([math.cos(a), math.sin(a), 0], abs=1e-6)  # T1: Fx = cos(a) F, Fy = sin(a) F
    assert np.allclose(d[4:], [0, 0, 1])
    p = t.positions_frd_m
    # T1+T2 surge pair mirrored about the xz plane, T1+T3 sway pair about the yz plane
    assert np.allclose(p[1] * [1, -1, 1], p[0]) and np.allclose(p[2] * [-1, 1, 1], p[0])
    assert sorted(th.esc_channel for th in t.thrusters) == list(range(8))


def one_line_error(tmp_path, mutate) -> str:
    params = base_params()
    mutate(params)
    with pytest.raises(ConfigError) as exc:
        load_config(write(tmp_path, params))
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_unknown_key(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p["vehicle"].update(mas_kg=3.0))
    assert "vehicle.mas_kg = 3.0: unknown key (did you mean vehicle.mass_kg?)" in msg


def test_unknown_section(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p.update(thruster={"x": 1}))
    assert "thruster.x = 1" in msg and "sections:" in msg


def test_wrong_type(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p["vehicle"].update(mass_kg="heavy"))
    assert "vehicle.mass_kg = 'heavy': allowed number in [0.1, 1000]" in msg


def test_out_of_range(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p["thrusters"]["t3"].update(esc_channel=17))
    assert "thrusters.t3.esc_channel = 17: allowed integer in [0, 14]" in msg


def test_bad_choice(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p["sensors"]["ms5837"].update(oversampling=300))
    assert "sensors.ms5837.oversampling = 300: allowed one of 256, 512, 1024, 2048, 4096, 8192" in msg


@pytest.mark.parametrize("name", ["2rov", "rov-a", "a__b", "", "rov/a", "x" * 64])
def test_vehicle_name_must_be_a_ros_name_token(tmp_path, name):
    """vehicle.name is the vehicle's namespace on the topside graph: rcl would refuse any of these there."""
    msg = one_line_error(tmp_path, lambda p: p["vehicle"].update(name=name))
    assert f"vehicle.name = {name!r}: allowed a ROS name token" in msg


def test_vehicle_name_tokens_accepted(tmp_path):
    params = base_params()
    params["vehicle"]["name"] = "rov_2B"
    assert load_config(write(tmp_path, params)).vehicle.name == "rov_2B"


def test_nan_and_bool_are_not_numbers(tmp_path):
    assert "environment.gravity_m_s2 = nan" in one_line_error(
        tmp_path, lambda p: p["environment"].update(gravity_m_s2=float("nan")))
    assert "thrusters.t1.esc_channel = True" in one_line_error(
        tmp_path, lambda p: p["thrusters"]["t1"].update(esc_channel=True))


def test_wrong_list_length_and_non_unit_direction(tmp_path):
    assert "vehicle.inertia_kg_m2 = [1.0, 2.0]: allowed list of numbers of length 3" in one_line_error(
        tmp_path, lambda p: p["vehicle"].update(inertia_kg_m2=[1.0, 2.0]))
    assert "unit length" in one_line_error(
        tmp_path, lambda p: p["thrusters"]["t2"].update(direction_frd=[1.0, 1.0, 0.0]))


def test_missing_key(tmp_path):
    msg = one_line_error(tmp_path, lambda p: p["thrusters"]["t8"].pop("esc_channel"))
    assert "thrusters.t8.esc_channel is missing: allowed integer in [0, 14]" in msg


def test_cross_checks(tmp_path):
    assert "a channel not already used by thrusters.t1" in one_line_error(
        tmp_path, lambda p: p["thrusters"]["t2"].update(esc_channel=0))
    assert "vehicle.net_buoyancy_n = 5.0: allowed within 0.10 N of (rho V - m) g = 0.785 N" in one_line_error(
        tmp_path, lambda p: p["vehicle"].update(net_buoyancy_n=5.0))
    assert "thrusters.pulse_width_neutral_us = 1950.0" in one_line_error(
        tmp_path, lambda p: p["thrusters"].update(pulse_width_neutral_us=1950.0))
    # a command held for a whole number of control ticks: 25 Hz / 20 Hz = 1.25 ticks is refused, 25 / 50 too
    for rate in (20.0, 50.0):
        assert f"identification.command_rate_hz = {rate}: allowed identification.estimate_rate_hz (25) divided " \
               "by a whole number" in one_line_error(
                   tmp_path, lambda p, r=rate: p["identification"].update(command_rate_hz=r))


def test_added_mass_coupling_must_keep_positive_definite(tmp_path):
    def mutate(p):
        c = [0.0] * 36
        c[1] = c[6] = 30.0  # surge-sway coupling larger than sqrt(12.08 * 19.43)
        p["hydrodynamics"]["added_mass_coupling"] = c
    assert "positive definite" in one_line_error(tmp_path, mutate)


def test_every_issue_reported(tmp_path):
    params = base_params()
    params["vehicle"]["mass_kg"] = -1.0
    params["pool"]["depth_m"] = "deep"
    with pytest.raises(ConfigError) as exc:
        load_config(write(tmp_path, params))
    lines = exc.value.lines()
    assert any(line.startswith("vehicle.mass_kg = -1.0") for line in lines)
    assert any(line.startswith("pool.depth_m = 'deep'") for line in lines)


def test_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="a readable file"):
        load_config(tmp_path / "absent.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match="valid YAML"):
        load_config(bad)
    flat_file = tmp_path / "flat.yaml"
    flat_file.write_text("vehicle:\n  mass_kg: 1.0\n")
    with pytest.raises(ConfigError, match="ros__parameters"):
        load_config(flat_file)


def test_ros_parameter_round_trip_and_node_mode(cfg):
    params = cfg.to_ros_parameters()
    params["use_sim_time"] = True  # not a configuration key: ignored in node mode
    again = config_from_parameters(params)
    assert again.flat == cfg.flat
    params["vehicle.mass_kg"] = 0.0
    with pytest.raises(ConfigError, match=r"vehicle.mass_kg = 0.0: allowed number in \[0.1, 1000\]"):
        config_from_parameters(params)


def test_overrides_revalidate(cfg):
    assert cfg.with_overrides({"pool.margin_m": 0.6}).pool.margin_m == 0.6
    with pytest.raises(ConfigError, match="net_buoyancy_n"):  # a heavier vehicle must restate its buoyancy
        cfg.with_overrides({"vehicle.mass_kg": 15.3})
    with pytest.raises(ConfigError):
        cfg.with_overrides({"vehicle.mass_kg": 1e9})


def test_schema_docs_and_units_in_names():
    unitless = {"name", "names", "variant", "mode_auto", "port", "reversed", "allocation_mode", "priority_dofs",
                "magnetometer_mode", "estimate_gyro_bias", "seed", "compression", "topics", "output_root",
                "esc_channel", "i2c_bus", "i2c_address", "baud_rate", "oversampling", "dlpf_config",
                "direction_frd", "curve_negative", "curve_positive", "levels_per_dof", "forgetting_factor",
                "allocation_weight", "added_mass_coupling", "dropout_probability", "level_fraction_min",
                "level_fraction_max", "real_time_factor", "converged_relative_std", "scale_error_fraction",
                "thrust_uncertainty_rel", "thrust_fit_uncertainty_rel", "rls_directional_forgetting",
                "rls_min_excitation", "rls_change_threshold", "rls_prior_std_rel", "prior_std_rel",
                "oscillator_calibrated", "oscillator_measured_on", "frozen_check_samples", "prom_reject_blank_words",
                "require_data_ready", "heave_repeats",
                "not_ready_error_polls", "excitation", "damping_ratio", "hold_fraction", "max_wrench_excess_ratio",
                "chip", "line", "dvl", "altimeter", "pressure", "imu"}  # /OE gpio; rate_check_disabled reasons
    units = ("_kg", "_m", "_m3", "_n", "_kg_m2", "_s", "_hz", "_us", "_pa", "_rad", "_m_s", "_m_s2", "_g", "_dps",
             "_bytes", "_mb", "_kg_m3", "_m2_s", "_kg_s", "_kg_m2_s", "_rad_s", "_t", "_us_per_s", "_frd_m", "_ned_m")
    for key, spec in SCHEMA.items():
        leaf = key.split(".")[-1]
        assert spec.doc, key
        assert leaf in unitless or leaf.endswith(units), f"{key}: unit missing from the name"


def test_flatten():
    assert flatten({"a": {"b": 1, "c": {"d": [1, 2]}}}) == {"a.b": 1, "a.c.d": [1, 2]}


@pytest.mark.parametrize("overrides, line", [
    # a never-armed vehicle holding 1560 us on all eight channels
    ({"thrusters.pulse_width_neutral_us": 1560.0},
     "thrusters.pulse_width_neutral_us = 1560.0: allowed inside the ESC's deadband (1475, 1525) us"),
    # deadband 120 with trim 100: 1600 us disarmed
    ({"thrusters.deadband_us": 120.0, "thrusters.t4.trim_us": 100.0},
     "thrusters.t4.trim_us = 100.0: allowed neutral + trim (1600 us) inside the ESC's deadband (1475, 1525) us"),
    ({"thrusters.t2.trim_us": -30.0}, "thrusters.t2.trim_us = -30.0: allowed neutral + trim (1470 us)"),
    # outside the PCA9685's 23-27 MHz: 1732 us on the wire for a commanded neutral
    ({"esc.oscillator_hz": 28.85e6}, "esc.oscillator_hz = 28850000.0: allowed number in [2.3e+07, 2.7e+07]"),
    ({"esc.oscillator_hz": 22.9e6}, "esc.oscillator_hz = 22900000.0: allowed number in [2.3e+07, 2.7e+07]"),
    # a negated thrust curve (positive thrust below neutral)
    ({"thrusters.curve_negative": [4.61e-7, -0.001794, 2.2726, -927.1827]},
     "thrusters.curve_negative = [4.61e-07, -0.001794, 2.2726, -927.1827]: allowed a cubic increasing with the right "
     "sign"),
    ({"thrusters.curve_positive": [4.61e-7, -0.002355, 3.9556, -2191.6173]}, "thrusters.curve_positive = "),
    # a 60 s rate window found a dead depth sensor after 48 s
    ({"supervisor.rate_window_s": 60.0},
     "supervisor.rate_window_s = 60.0: allowed at most supervisor.reaction_time_s (3 s)"),
    ({"supervisor.max_invalid_dvl_s": 5.0}, "supervisor.max_invalid_dvl_s = 5.0: allowed at most "
                                            "supervisor.reaction_time_s (3 s)"),
    # the output guard's own heartbeat timeout: its range, and two supervisor beats (20 Hz shipped) within it
    ({"esc.guard_heartbeat_timeout_s": 2.0}, "esc.guard_heartbeat_timeout_s = 2.0: allowed number in [0.05, 1]"),
    ({"esc.guard_heartbeat_timeout_s": 0.08, "esc.bus_call_timeout_s": 0.05},
     "esc.guard_heartbeat_timeout_s = 0.08: allowed at least two supervisor heartbeats (2 / "
     "supervisor.check_rate_hz = 0.1 s)"),
    # a bus call that hangs must be reported before the guard would miss the ESC's heartbeat anyway
    ({"esc.bus_call_timeout_s": 0.2},
     "esc.bus_call_timeout_s = 0.2: allowed < esc.guard_heartbeat_timeout_s = 0.2 s"),
])
def test_values_checked_against_the_hardware_one_line_each(overrides, line):
    with pytest.raises(ConfigError) as err:
        load_config(CONFIG, overrides)
    assert err.value.lines() == [err.value.lines()[0]] and err.value.lines()[0].startswith(line), err.value.lines()


def test_hardware_limits_accept_the_edges_inside():
    cfg = load_config(CONFIG, {"thrusters.t1.trim_us": 24.0, "thrusters.t2.trim_us": -24.0,
                               "esc.oscillator_hz": 23e6, "supervisor.rate_window_s": 3.0})
    assert cfg.flat["thrusters.t1.trim_us"] == 24.0 and cfg.esc.oscillator_hz == 23e6
