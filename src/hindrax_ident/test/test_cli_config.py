"""`hindrax config check FILE` as users run it (the installed console script)."""
import subprocess
import sys
from pathlib import Path

import yaml

from hindrax_drivers.config import default_config_path

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
    assert f"{bad}: thrusters.t3.esc_channel = 17: allowed integer in [0, 15]" in lines
    assert f"{bad}: sensors.ms5837.variant = '100BA': allowed one of 30BA, 02BA, auto" in lines
    assert f"{bad}: vehicle.colour = 'yellow': unknown key" in lines


def test_usage_error_exits_2():
    assert run("config", "check", "a.yaml", "b.yaml").returncode == 2  # one file at most


def test_without_a_file_the_shipped_vehicle_file_is_checked():
    from hindrax_drivers.config import default_config_path

    r = run("config", "check")
    assert r.returncode == 0 and r.stdout.startswith(f"{default_config_path()}: OK")


def test_every_command_reading_the_vehicle_file_reports_an_invalid_one_in_one_line(tmp_path, capsys):
    """One mechanism (commands/common.py load_vehicle): one line on stderr naming key, value, allowed range,
    exit 1, nothing on stdout, for each command that loads the vehicle file."""
    from hindrax_ident import cli

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
            f"invalid configuration: {bad}: thrusters.t3.esc_channel = 17: allowed integer in [0, 15]"], (argv, err)
    assert bad.read_text() == before and not (tmp_path / "suite").exists()


def test_update_vehicle_file_sets_scalars_and_lists_keeps_comments_and_restores_an_invalid_result(tmp_path):
    """The one "edit the vehicle file in place" helper (esc calibrate --write, ident thruster-fit --write)."""
    import pytest

    from hindrax_drivers.config import ConfigError, load_config
    from hindrax_ident.commands.common import update_vehicle_file

    conf = tmp_path / "hindrax.yaml"
    conf.write_text(default_config_path().read_text())
    original = conf.read_text()
    update_vehicle_file(conf, {"oscillator_hz": "24500000.0", "curve_positive": "[0.0, 0.0001, -0.3, 225.0]"})
    cfg = load_config(conf)
    assert cfg.esc.oscillator_hz == 24.5e6
    assert list(cfg.thrusters.curve_positive) == [0.0, 0.0001, -0.3, 225.0]
    changed = [(a, b) for a, b in zip(original.splitlines(), conf.read_text().splitlines()) if a != b]
    assert len(changed) == 2 and any("# nominal; calibrate per board" in b for _, b in changed)  # comment kept
    edited = conf.read_text()
    with pytest.raises(ValueError, match="expected exactly one 'no_such_key:' line to update, found 0"):
        update_vehicle_file(conf, {"no_such_key": "1"})
    with pytest.raises(ConfigError, match="oscillator_hz"):
        update_vehicle_file(conf, {"oscillator_hz": "5.0"})
    assert conf.read_text() == edited  # restored


def test_config_check_warns_when_the_vehicle_has_no_hardware_cut_off(tmp_path):
    """Issue 23: esc.output_enable_gpio null (the shipped file) -> a warning; wired -> none."""
    import yaml

    from hindrax_drivers.config import default_config_path

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
