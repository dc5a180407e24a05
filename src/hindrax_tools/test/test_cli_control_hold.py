"""``hindrax control hold / release`` refuse what cannot be a setpoint, and a vehicle that is not there, in one line
each, before anything is sent. The hold itself, on the launch flying in the live pool: test/test_pool_day.py."""
import pytest

from hindrax_tools import cli


@pytest.mark.parametrize("argv, said", [
    (["--altitude-m", "-0.5"], "--altitude-m -0.5: allowed > 0"),
    (["--altitude-m", "0"], "--altitude-m 0: allowed > 0"),
    (["--depth-m", "-1"], "--depth-m -1: allowed >= 0 (positive down)"),
    (["--depth-m", "nan"], "--depth-m nan: allowed a finite number"),
    (["--depth-m", "1.0", "--heading-deg", "inf"], "--heading-deg inf: allowed a finite number"),
])
def test_a_setpoint_that_cannot_be_is_one_line(argv, said, capsys):
    rc = cli.main(["control", "hold", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and err == [said], err


def test_depth_and_altitude_together_are_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["control", "hold", "--depth-m", "1", "--altitude-m", "1"])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


@pytest.mark.parametrize("verb", ["hold", "release"])
def test_no_such_vehicle_is_one_line(verb, capsys):
    rc = cli.main(["control", verb, "--vehicle", "no_such_vehicle", "--discovery-timeout", "0.5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "no_such_vehicle" in err[0], err


def test_the_hold_result_names_the_altitude_held_and_its_error():
    """Issue 74.5: ``control hold`` printed only "enabled"; it now says what was held and how well."""
    import math

    from hindrax_tools.commands.control_hold import hold_result
    from hindrax_msgs.msg import ControllerStatus, ControlSetpoint

    def status(altitude_m: float, heading_rad: float, enabled: bool = True) -> ControllerStatus:
        return ControllerStatus(enabled=enabled, vertical_mode=ControlSetpoint.VERTICAL_ALTITUDE,
                                altitude_setpoint_m=0.9, altitude_m=altitude_m, heading_setpoint_rad=0.0,
                                heading_rad=heading_rad, depth_m=math.nan, message="holding")

    # errors +0.02, -0.04, +0.02 m: mean 0, RMS sqrt(0.0024 / 3) = 0.028, largest 0.04; headings 0.02, 0, -0.02 rad
    line = hold_result([status(0.92, 0.02), status(0.86, 0.0), status(0.92, -0.02)], 10.0)
    assert line == ("over the last 10 s (3 statuses): altitude 0.900 m held: measured 0.900 m mean, error +0.000 m "
                    "mean, 0.028 m RMS, 0.040 m largest; heading error 0.9 deg RMS")
    assert hold_result([status(0.9, 0.0, enabled=False)], 5.0) == "not holding after 5 s: holding"
    assert hold_result([], 5.0) == "not holding after 5 s: no controller status arrived"
