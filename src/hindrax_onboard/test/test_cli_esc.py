"""`hindrax esc calibrate` as users run it (the installed console script), and `config check`'s note about it."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

from hindrax_common.config import default_config_path, load_config

HINDRAX = str(Path(sys.executable).with_name("hindrax"))


def run(*args):
    return subprocess.run([HINDRAX, *args], capture_output=True, text=True, timeout=60)


def test_calibrate_from_one_scope_reading_and_write(tmp_path):
    """A 24.06 MHz part, 25 MHz assumed, 200 Hz: prescale 30, 1500 us is round(1500 * 25e6 / 31e6) = 1210 counts;
    the part holds them for 1210 * 31 / 24.06e6 s = 1559.02 us (hand arithmetic). The reading gives the part's
    oscillator back, and --write stores it with the calibrated flag, comments kept."""
    cfg = tmp_path / "vehicle.yaml"
    shutil.copy(default_config_path(), cfg)
    measured = 1210 * 31 / 24.06e6 * 1e6
    r = run("esc", "calibrate", "--measured-us", f"{measured:.4f}", "--config", str(cfg), "--write")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert abs(out["oscillator_hz"] - 24.06e6) < 50.0 and out["prescale_used"] == 30 and out["written"]
    assert abs(out["calibrated_pulse_us"] - 1500.0) < 1.3  # within one count at the calibrated prescale
    c = load_config(cfg)
    assert c.esc.oscillator_calibrated is True and abs(c.esc.oscillator_hz - 24.06e6) < 50.0
    assert "# nominal; calibrate per board" in cfg.read_text()  # the file's comments survive
    # config check no longer prints the calibration note
    assert "oscillator_calibrated is false" not in run("config", "check", str(cfg)).stdout
    unmeasured = run("config", "check", str(default_config_path())).stdout
    # an unmeasured 23-27 MHz is not taken as neutral-safe: the check says the outputs stay off and where to measure
    assert "warning: esc.oscillator_calibrated is false" in unmeasured, unmeasured
    assert "keeps the thruster outputs off (no pulses)" in unmeasured and "channel 15" in unmeasured
    assert "hindrax esc calibrate" in unmeasured


def test_calibrate_rejects_an_impossible_reading_and_leaves_the_file(tmp_path):
    cfg = tmp_path / "vehicle.yaml"
    shutil.copy(default_config_path(), cfg)
    before = cfg.read_text()
    r = run("esc", "calibrate", "--measured-us", "15.6", "--config", str(cfg), "--write")
    assert r.returncode == 1 and "outside 20-30 MHz" in r.stderr
    assert cfg.read_text() == before


def test_calibrate_refuses_a_reading_outside_the_parts_range_and_keeps_the_flag_false(tmp_path):
    """1300 us read for the 1500 us neutral (1210 counts, prescale 30): 1210 * 31 / 1300e-6 = 28.85 MHz (hand
    arithmetic), outside the PCA9685's 23-27 MHz; it must not be written nor set oscillator_calibrated."""
    cfg = tmp_path / "vehicle.yaml"
    shutil.copy(default_config_path(), cfg)
    before = cfg.read_text()
    r = run("esc", "calibrate", "--measured-us", "1300", "--config", str(cfg), "--write")
    assert r.returncode == 1 and "esc.oscillator_hz = 28853846.2: allowed 23-27 MHz" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert cfg.read_text() == before and load_config(cfg).esc.oscillator_calibrated is False


def test_config_check_warns_when_the_oscillator_was_not_measured_on_this_board(tmp_path):
    """Issue 71.8: a vehicle file marked calibrated without a measurement of this board (copied from another vehicle,
    or the flag set by hand) put 1559-1631 us on the wire as neutral and passed `config check`. The calibration
    records the board; the check warns when the record is absent or another board's."""
    import yaml

    from hindrax_common.config.sections.esc import board_id

    doc = yaml.safe_load(default_config_path().read_text())
    esc = doc["/**"]["ros__parameters"]["esc"]
    esc["oscillator_calibrated"] = True
    cfg = tmp_path / "vehicle.yaml"
    cfg.write_text(yaml.safe_dump(doc))
    out = run("config", "check", str(cfg)).stdout
    assert "warning: esc.oscillator_calibrated is true but no measurement is recorded" in out, out
    assert "1500 us" in out and "hindrax esc calibrate" in out
    esc["oscillator_measured_on"] = "10000000deadbeef 2026-01-01 1559 us"
    cfg.write_text(yaml.safe_dump(doc))
    out = run("config", "check", str(cfg)).stdout
    assert "measured on board 10000000deadbeef, not this one" in out, out
    shutil.copy(default_config_path(), cfg)
    assert run("esc", "calibrate", "--measured-us", "1500", "--config", str(cfg), "--write").returncode == 0
    assert load_config(cfg).esc.oscillator_measured_on.startswith(board_id() + " ")
    out = run("config", "check", str(cfg)).stdout
    assert "measurement is recorded" not in out and "measured on board" not in out, out
