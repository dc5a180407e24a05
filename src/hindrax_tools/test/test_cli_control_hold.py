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
