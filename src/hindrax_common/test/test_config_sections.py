"""Typed configuration sections: the generated dataclasses and SCHEMA agree exactly, and the typed objects carry
the file's values (docs: the config.py module docstring)."""
import dataclasses
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hindrax_common import config as c
from hindrax_common.config import SCHEMA, VehicleConfig, default_config_path, load_config
from hindrax_common.config.typed_sections import Section

ROOT = Path(__file__).resolve().parents[3]
KIND_TYPES = {"float": float, "int": int, "str": str, "bool": bool, "float[]": tuple[float, ...],
              "str[]": tuple[str, ...]}


def _leaf_fields(cls: type, prefix: str) -> dict[str, object]:
    """Dotted key -> annotated type of every leaf field of a generated section class."""
    out: dict[str, object] = {}
    for f in dataclasses.fields(cls):
        if isinstance(f.type, type) and issubclass(f.type, Section):
            out.update(_leaf_fields(f.type, f"{prefix}.{f.name}"))
        else:
            out[f"{prefix}.{f.name}"] = f.type
    return out


def _section_class(section: str) -> type:
    return getattr(VehicleConfig, section).cls


def test_generated_sections_are_current():
    res = subprocess.run([sys.executable, str(ROOT / "scripts" / "gen_config_sections.py"), "--check"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr


def test_every_schema_key_has_a_field_of_its_kind_and_every_field_a_key():
    fields: dict[str, object] = {}
    for section in c.SECTIONS:
        if section == "thrusters":
            continue
        cls = _section_class(section)
        assert cls.PREFIX == section
        fields.update(_leaf_fields(cls, section))
    keys = {k for k in SCHEMA if not k.startswith("thrusters.")}
    assert set(fields) == keys, (sorted(set(fields) - keys), sorted(keys - set(fields)))
    for key, typ in fields.items():
        want = KIND_TYPES[SCHEMA[key].kind]
        if c.is_optional(key):
            assert typ == (want | None), (key, typ)
        else:
            assert typ == want, (key, typ)


def test_thruster_keys_map_to_the_thruster_dataclasses():
    per_thruster = {k.split(".")[2] for k in SCHEMA if k.startswith("thrusters.<thruster>.")}
    shared = {k.split(".")[1] for k in SCHEMA if k.startswith("thrusters.") and k.count(".") == 1} - {"names"}
    assert {f.name for f in dataclasses.fields(c.ThrusterConfig)} - {"name"} == per_thruster
    assert {f.name for f in dataclasses.fields(c.ThrustersConfig)} - {"thrusters"} == shared


def test_typed_sections_hold_the_validated_values():
    cfg = load_config(default_config_path())
    seen = 0
    for section in c.SECTIONS:
        if section == "thrusters":
            continue
        obj = getattr(cfg, section)  # every section under its own name
        for key in _leaf_fields(type(obj), section):
            value = obj
            for part in key.split(".")[1:]:
                value = getattr(value, part)
            if key in cfg.flat:
                flat = cfg.flat[key]
                assert value == (tuple(flat) if isinstance(flat, list) else flat), key
                seen += 1
            else:
                assert value is None and c.is_optional(key), key
    assert seen > 150
    # values from the shipped file itself ([Hindrax-Drag] §2.1), not from the code under test
    assert cfg.vehicle.mass_kg == 15.22 and cfg.vehicle.height_m == 0.40
    t = cfg.thrusters
    assert t.thrust_uncertainty_rel is not None and len(t.thrust_uncertainty_rel) == 2


def test_a_key_outside_a_nodes_selection_raises_key_error_naming_it():
    cfg = load_config(default_config_path())
    partial = VehicleConfig({"sensors.ms5837.rate_hz": 10.0, "environment.surface_pressure_pa": 101325.0})
    assert partial.sensors.ms5837.rate_hz == 10.0
    assert partial.environment.surface_pressure_pa == 101325.0
    with pytest.raises(KeyError, match="environment.water_density_kg_m3"):
        _ = partial.environment.water_density_kg_m3
    with pytest.raises(KeyError, match="sensors.dvl75.port"):
        _ = partial.sensors.dvl75.port
    with pytest.raises(AttributeError):
        _ = cfg.esc.output_latency  # misspelt: no such field
    assert isinstance(cfg.sensors.dvl75.position_frd_m, tuple)
    np.testing.assert_allclose(np.asarray(cfg.sensors.dvl75.position_frd_m), cfg.flat["sensors.dvl75.position_frd_m"])


def test_optional_keys_are_none_when_absent():
    cfg = load_config(default_config_path())
    flat = {k: v for k, v in cfg.flat.items() if not k.startswith(("control.", "esc.output_enable_gpio."))}
    bare = VehicleConfig(flat)
    assert bare.control.rate_hz is None and bare.esc.output_enable_gpio.chip is None
    assert bare.esc.output_latency_s == cfg.flat["esc.output_latency_s"]


#: Where a dotted key by string is the point: the schema and its generated sections, and the validation of a node's
#: raw parameter mapping (config.node_parameters.validate_selection, before any VehicleConfig exists).
DECLARE_KEYS = ("hindrax_common/config/",)
LOOKUP = re.compile(r"""flat\[\s*f?["']|flat\.get\(\s*f?["']|\.section\("""
                    r"""|\.get\(\s*f?["'][a-z0-9_]+\.[a-z0-9_.{}]+["']"""
                    r"""|\[\s*f?["'](?:""" + "|".join(c.SECTIONS) + r""")\.[a-z0-9_.{}]+["']\s*\](?!\s*=[^=])"""
                    r"""|["'](?:""" + "|".join(c.SECTIONS) + r""")\.[a-z0-9_.{}]+["']\s+(?:not\s+)?in\s""")


def test_no_configuration_lookup_by_string_outside_config():
    """Modules read the typed sections (cfg.esc.output_latency_s), never cfg.flat["esc.output_latency_s"],
    cfg.get("esc.output_latency_s") or cfg.section("esc")[...]: a misspelt key must fail at import/type check."""
    offenders = []
    for pkg in ("hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard", "hindrax_fit", "hindrax_sim",
                "hindrax_tools"):
        root = ROOT / "src" / pkg
        for path in sorted((root / pkg).rglob("*.py")):
            rel = f"{pkg}/{path.relative_to(root / pkg).as_posix()}"
            if rel.startswith(DECLARE_KEYS):
                continue
            for i, line in enumerate(path.read_text().splitlines(), 1):
                if LOOKUP.search(line):
                    offenders.append(f"{rel}:{i}: {line.strip()}")
    assert not offenders, "\n".join(offenders)


def test_the_safety_timeouts_nodes_widen_are_declared_in_the_configuration():
    """The four node parameters that widen a safety timeout (the ESC's and the guard's heartbeat timeouts, the ESC's
    steady-clock watchdog, the supervisor's clock stall) take their range from a section module of the configuration,
    not from a node module (issue 75): each ``declare_node_parameter(node, "..._timeout_s", SPEC, default)`` names a
    Spec imported from ``hindrax_common.config.sections``, and those ranges hold the vehicle's own keys."""
    import ast

    found = {}
    for path in sorted((ROOT / "src").glob("hindrax_*/hindrax_*/**/*.py")):
        tree = ast.parse(path.read_text())
        source = {a.asname or a.name: n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                  for a in n.names}
        for n in ast.walk(tree):
            if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "declare_node_parameter" and \
                    isinstance(n.args[1], ast.Constant) and n.args[1].value.endswith("_timeout_s"):
                found[f"{path.parent.name}/{path.stem}: {n.args[1].value}"] = source.get(getattr(n.args[2], "id", ""))
    sections = "hindrax_common.config.sections"
    assert found == {"pca9685/peers: heartbeat_timeout_s": f"{sections}.esc",
                     "pca9685/node: steady_watchdog_timeout_s": f"{sections}.esc",
                     "guard/node: heartbeat_timeout_s": f"{sections}.esc",
                     "supervisor/node: clock_stall_timeout_s": f"{sections}.supervisor"}
    from hindrax_common.config.sections import esc, supervisor

    for spec, key in ((esc.ESC_HEARTBEAT_TIMEOUT, "esc.heartbeat_timeout_s"),
                      (esc.STEADY_WATCHDOG_TIMEOUT, "esc.watchdog_timeout_s"),
                      (esc.GUARD_HEARTBEAT_TIMEOUT, "esc.guard_heartbeat_timeout_s"),
                      (supervisor.CLOCK_STALL_TIMEOUT, "supervisor.rate_window_s")):
        assert spec.lo <= SCHEMA[key].lo and SCHEMA[key].hi <= spec.hi and key in spec.doc, key  # default fits


def test_the_lookup_guard_sees_each_form():
    for line in ('cfg.flat["esc.output_latency_s"]', "cfg.flat.get('recording.topics')", 'cfg.section("esc")',
                 'cfg.get("simulation.seed")', 'cfg.flat[f"thrusters.{n}.trim_us"]', 'cfg.get(f"vehicle.{k}")',
                 'c["esc.i2c_address"]', 'if "esc.oscillator_calibrated" in cfg.flat:'):
        assert LOOKUP.search(line), line
    for line in ("cfg.esc.output_latency_s", "flat[key]", 'd.get("name")', "self.flat.get(k)",
                 'overrides["simulation.seed"] = 3'):  # an override by ROS parameter name is fine
        assert not LOOKUP.search(line), line
    assert all((ROOT / "src" / p.split("/")[0] / p).exists() for p in DECLARE_KEYS)


def test_a_partial_thruster_selection_reads_typed_and_names_the_missing_key():
    """The static TF node declares only names, positions and directions: those read typed, the rest raise KeyError
    naming the per-thruster key."""
    partial = VehicleConfig({"thrusters.names": ["t1"], "thrusters.t1.position_frd_m": [0.2, -0.1, 0.0],
                             "thrusters.t1.direction_frd": [0.0, 3.0, 4.0]})
    t1 = partial.thrusters.thrusters[0]
    np.testing.assert_allclose(t1.position_frd_m, [0.2, -0.1, 0.0])
    np.testing.assert_allclose(t1.direction_frd, [0.0, 0.6, 0.8])  # unit length, as the allocation uses it
    with pytest.raises(KeyError, match=r"thrusters\.t1\.esc_channel"):
        _ = t1.esc_channel
    with pytest.raises(KeyError, match=r"thrusters\.deadband_us"):
        _ = partial.thrusters.deadband_us
    assert "esc_channel=<absent>" in repr(t1)


def test_each_key_has_one_name_on_the_configuration():
    """A key is read through its section (``cfg.vehicle.mass_kg``), never also through a second name on the
    configuration itself (the flat-era ``cfg.mass_kg``, ``cfg.gravity_m_s2``, ``cfg.centre_of_gravity_frd_m`` were
    such aliases): no public attribute of VehicleConfig is named after a key's last segment."""
    leaves = {k.rsplit(".", 1)[-1] for k in SCHEMA}
    names = {n for n in dir(VehicleConfig) if not n.startswith("_")}
    assert not names & leaves, sorted(names & leaves)
    cfg = load_config(default_config_path())
    for gone in ("mass_kg", "displaced_volume_m3", "water_density_kg_m3", "gravity_m_s2", "centre_of_gravity_frd_m"):
        assert not hasattr(cfg, gone), gone
    assert cfg.vehicle.mass_kg == cfg.flat["vehicle.mass_kg"]
