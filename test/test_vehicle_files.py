"""The tests' vehicle-file writer (test support, :mod:`hindrax_test_support.vehicle_files`): the
keys it sets are what the loader reads, the rest is the shipped file's, and a key the loader does
not know is refused."""
import pytest
from hindrax_test_support.vehicle_files import SHORT_HOLDS, vehicle_file

from hindrax_common.config import default_config_path, load_config


def test_the_keys_set_are_read_back_and_the_rest_is_the_shipped_file(tmp_path):
    shipped = load_config(default_config_path())
    path = vehicle_file(tmp_path / "v.yaml", {**SHORT_HOLDS, "esc.oscillator_calibrated": True})
    written = load_config(path)
    assert (written.calibration.hold_settle_s, written.calibration.hold_window_s) == (3.0, 9.0)
    assert written.esc.oscillator_calibrated is True
    assert shipped.calibration.hold_settle_s != 3.0 and shipped.esc.oscillator_calibrated is False
    assert written.flat["vehicle.mass_kg"] == shipped.flat["vehicle.mass_kg"]
    edited = shipped.with_overrides({**SHORT_HOLDS, "esc.oscillator_calibrated": True})
    assert written.flat == edited.flat


def test_a_key_the_file_lacks_is_refused(tmp_path):
    with pytest.raises(KeyError, match="no vehicle-file key calibration.hold_settle"):
        vehicle_file(tmp_path / "v.yaml", {"calibration.hold_settle": 3.0})
