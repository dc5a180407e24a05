"""The vehicle's ``hindrax`` (hindrax_onboard.cli): the topside's commands come through the ``hindrax.commands``
entry point; without them (the vehicle's build) a topside command answers one line. From the install space:
test/test_ros_install.py."""
import pytest

from hindrax_onboard import cli


def test_the_topside_adds_its_commands_through_the_entry_point_group():
    rows = cli.all_commands()
    assert rows[:len(cli.COMMANDS)] == cli.COMMANDS
    topside = {words: module for words, module, _h in rows[len(cli.COMMANDS):]}
    assert topside[("ident", "bag")] == "hindrax_tools.commands.ident_bag" and ("control", "model") in topside
    assert all(module.startswith("hindrax_onboard.commands.") for _w, module, _h in cli.COMMANDS)


@pytest.mark.parametrize("argv", [["ident", "bag", "/var/lib/hindrax/runs/b"], ["control", "model", "--model", "m"]])
def test_without_the_topside_a_topside_command_answers_one_line(monkeypatch, capsys, argv):
    monkeypatch.setattr(cli, "all_commands", lambda: list(cli.COMMANDS))
    assert cli.main(argv) == 1
    out = capsys.readouterr()
    assert out.out == "" and out.err == (f"`hindrax {' '.join(argv[:2])}` is not a vehicle command: topside commands "
                                         "run on the topside PC (hindrax_tools is not installed here)\n")


@pytest.mark.parametrize("given, expected", [(None, "1"), ("3", "3")])
def test_hindrax_pins_openblas_to_one_thread_unless_told(given, expected):
    """One OpenBLAS thread before any command imports numpy (the command module's comment): with
    two threads `hindrax run`'s identification.yaml differed from one thread's in the last bits of
    six entries (the equation-error comparison's standard deviations), so the table would follow
    the machine's core count. A user's own setting stands."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = "import os, hindrax_onboard.cli; print(os.environ['OPENBLAS_NUM_THREADS'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == expected, out.stdout + out.stderr
