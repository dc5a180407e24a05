"""`hindrax config check FILE` as users run it (the installed console script)."""
import subprocess
import sys
from pathlib import Path

import yaml

from hindrax_common.config import default_config_path

HINDRAX = str(Path(sys.executable).with_name("hindrax"))


def run(*args):
    return subprocess.run([HINDRAX, *args], capture_output=True, text=True, timeout=60)


def test_valid_file_prints_summary_and_exits_0():
    r = run("config", "check", str(default_config_path()))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "OK" in r.stdout and "mass 15.22 kg" in r.stdout and "t1, t2, t3, t4, t5, t6, t7, t8" in r.stdout


def test_each_error_is_one_line_and_exit_1(tmp_path):
    doc = yaml.safe_load(default_config_path().read_text())
    params = doc["/**"]["ros__parameters"]
    params["thrusters"]["t3"]["esc_channel"] = 17
    params["sensors"]["ms5837"]["variant"] = "100BA"
    params["vehicle"]["colour"] = "yellow"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    r = run("config", "check", str(bad))
    assert r.returncode == 1
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 3
    assert f"{bad}: thrusters.t3.esc_channel = 17: allowed integer in [0, 14]" in lines
    assert f"{bad}: sensors.ms5837.variant = '100BA': allowed one of 30BA, 02BA, auto" in lines
    assert f"{bad}: vehicle.colour = 'yellow': unknown key" in lines


def test_usage_error_exits_2():
    assert run("config", "check", "a.yaml", "b.yaml").returncode == 2  # one file at most


def test_without_a_file_the_shipped_vehicle_file_is_checked():
    from hindrax_common.config import default_config_path

    r = run("config", "check")
    assert r.returncode == 0 and r.stdout.startswith(f"{default_config_path()}: OK")


def test_every_command_reading_the_vehicle_file_reports_an_invalid_one_in_one_line(tmp_path, capsys):
    """One mechanism (commands/common.py load_vehicle): one line on stderr naming key, value, allowed range,
    exit 1, nothing on stdout, for each command that loads the vehicle file."""
    from hindrax_onboard import cli

    doc = yaml.safe_load(default_config_path().read_text())
    doc["/**"]["ros__parameters"]["thrusters"]["t3"]["esc_channel"] = 17
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(doc))
    before = bad.read_text()
    for argv in (["allocate", "--config", str(bad), "0", "0", "0", "0", "0", "0"],
                 ["esc", "calibrate", "--measured-us", "1500", "--config", str(bad), "--write"],
                 ["ident", "priors", "--config", str(bad)],
                 ["ident", "scenarios", "--config", str(bad), "--out", str(tmp_path / "suite")]):
        assert cli.main(argv) == 1, argv
        out, err = capsys.readouterr()
        assert out == "" and err.splitlines() == [
            f"invalid configuration: {bad}: thrusters.t3.esc_channel = 17: allowed integer in [0, 14]"], (argv, err)
    assert bad.read_text() == before and not (tmp_path / "suite").exists()


def _flat(tree, prefix=""):
    """[(dotted key, value)] of a nested mapping, in file order."""
    out = []
    for k, v in tree.items():
        out += _flat(v, f"{prefix}{k}.") if isinstance(v, dict) else [(prefix + str(k), v)]
    return out


def _comments(text):
    """Every comment of a YAML text: whole comment lines and the ``# ...`` tail of value lines."""
    return [line[line.index("#"):].rstrip() for line in text.splitlines() if "#" in line]


def test_update_vehicle_file_keeps_every_comment_key_order_and_other_value(tmp_path):
    """The one "edit the vehicle file in place" helper (esc calibrate --write, ident thruster-fit --write)
    edits a copy of the shipped file: the edited values change, one key is added where asked, and every
    comment, the key order and every other value of the original stay as they were."""
    import pytest

    from hindrax_common.config import ConfigError, load_config
    from hindrax_onboard.commands.common import update_vehicle_file

    conf = tmp_path / "hindrax.yaml"
    original = default_config_path().read_text()
    conf.write_text(original)
    update_vehicle_file(conf, {"esc.oscillator_hz": 24512345.6, "esc.oscillator_calibrated": True,
                               "thrusters.curve_positive": [1e-09, 0.0001, -0.3, 225.0],
                               "thrusters.thrust_fit_uncertainty_rel": [0.01, 0.02]},
                        new_keys={"thrusters.thrust_fit_uncertainty_rel": ("curve_positive", "fit std")})
    edited = conf.read_text()
    added = [line for line in edited.splitlines() if "thrust_fit_uncertainty_rel" in line]
    assert added == ["      thrust_fit_uncertainty_rel: [0.01, 0.02] # fit std"]
    assert _comments(edited.replace(added[0], "")) == _comments(original)
    before = _flat(yaml.safe_load(original)["/**"]["ros__parameters"])
    after = _flat(yaml.safe_load(edited)["/**"]["ros__parameters"])
    assert after[[k for k, _ in after].index("thrusters.curve_positive") + 1] == (
        "thrusters.thrust_fit_uncertainty_rel", [0.01, 0.02])
    assert dict(after)["esc.oscillator_hz"] == 24512345.6 and dict(after)["esc.oscillator_calibrated"] is True
    assert dict(after)["thrusters.curve_positive"] == [1e-09, 0.0001, -0.3, 225.0]  # 1e-09 read back as a float
    edited_keys = {"esc.oscillator_hz", "esc.oscillator_calibrated", "thrusters.curve_positive"}
    assert [k for k, _ in after if k != "thrusters.thrust_fit_uncertainty_rel"] == [k for k, _ in before]
    assert [kv for kv in after if kv[0] not in edited_keys | {"thrusters.thrust_fit_uncertainty_rel"}] == [
        kv for kv in before if kv[0] not in edited_keys]
    changed = [(a, b) for a, b in zip(original.splitlines(), edited.splitlines()) if a != b]
    assert changed[0] == ("      curve_positive: [-4.61e-7, 0.002355, -3.9556, 2191.6173]",
                          "      curve_positive: [1.0e-09, 0.0001, -0.3, 225.0]")
    assert load_config(conf).esc.oscillator_hz == 24512345.6
    with pytest.raises(ValueError, match="no key 'esc.no_such_key' to update"):
        update_vehicle_file(conf, {"esc.no_such_key": 1})
    with pytest.raises(ValueError, match="no section 'no_such_section'"):
        update_vehicle_file(conf, {"no_such_section.oscillator_hz": 1.0})
    with pytest.raises(ConfigError, match="oscillator_hz"):
        update_vehicle_file(conf, {"esc.oscillator_hz": 5.0})
    assert conf.read_text() == edited  # restored


def test_the_shipped_vehicle_file_survives_a_round_trip_byte_for_byte(tmp_path):
    """Setting a value to what it already is rewrites the file unchanged: the shipped file is in the layout the
    round-trip writer keeps (flow collections on one line), so an edit shows as the edited lines only."""
    from hindrax_onboard.commands.common import update_vehicle_file

    conf = tmp_path / "hindrax.yaml"
    conf.write_text(default_config_path().read_text())
    update_vehicle_file(conf, {"vehicle.name": "hindrax"})
    assert conf.read_text() == default_config_path().read_text()


def test_config_check_warns_when_the_vehicle_has_no_hardware_cut_off(tmp_path):
    """Issue 23: esc.output_enable_gpio null (the shipped file) -> a warning; wired -> none."""
    import yaml

    from hindrax_common.config import default_config_path

    res = run("config", "check", str(default_config_path()))
    assert res.returncode == 0 and "no hardware cut-off" in res.stdout
    doc = yaml.safe_load(default_config_path().read_text())
    doc["/**"]["ros__parameters"]["esc"]["output_enable_gpio"] = {"chip": "/dev/gpiochip0", "line": 17}
    wired = tmp_path / "wired.yaml"
    wired.write_text(yaml.safe_dump(doc))
    res = run("config", "check", str(wired))
    assert res.returncode == 0 and "no hardware cut-off" not in res.stdout, res.stdout
    # issue 44.2: without the /OE watchdog's feed, a warning too; fitted, none
    assert "no hardware watchdog" in res.stdout
    doc["/**"]["ros__parameters"]["esc"]["output_enable_feed_gpio"] = {"chip": "/dev/gpiochip0", "line": 27}
    wired.write_text(yaml.safe_dump(doc))
    res = run("config", "check", str(wired))
    assert res.returncode == 0 and "no hardware watchdog" not in res.stdout, res.stdout
