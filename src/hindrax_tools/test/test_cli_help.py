"""``hindrax --help`` imports only the argument parser.

Structural, not timed (the time is in ``make bench``, benchmark ``cli``): a fresh interpreter runs the
``hindrax`` entry point with the given arguments and reports which heavy packages ended up in
``sys.modules``. Help of one subcommand imports that subcommand's module and its arguments, nothing else.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

HEAVY = ("numpy", "scipy", "rclpy", "yaml", "mcap", "hindrax_common", "hindrax_drivers", "hindrax_bringup")

_PROBE = """
import json, sys
from hindrax_tools import cli
try:
    status = cli.main(json.loads(sys.argv[1]))
except SystemExit as exc:
    status = exc.code
heavy = json.loads(sys.argv[2])
loaded = sorted({m.split(".")[0] for m in sys.modules if m.split(".")[0] in heavy})
commands = sorted(m for m in sys.modules if m.startswith(("hindrax_tools.commands.", "hindrax_onboard.commands.")))
sys.stderr.write(json.dumps({"status": status, "loaded": loaded, "commands": commands}) + "\\n")
"""


def probe(argv: list[str]) -> dict:
    """Run ``hindrax argv`` in a fresh interpreter: {status, loaded (heavy top-level packages), commands}."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    p = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(argv), json.dumps(HEAVY)], env=env,
                       capture_output=True, text=True, timeout=120)
    return {"stdout": p.stdout, **json.loads(p.stderr.strip().splitlines()[-1])}


@pytest.mark.parametrize("argv", [["--help"], ["bag", "--help"], ["ident", "--help"], ["config", "--help"]])
def test_help_of_the_command_tree_imports_no_command_module(argv):
    r = probe(argv)
    assert r["status"] == 0
    assert r["loaded"] == []
    assert r["commands"] == []
    assert "usage: hindrax" in r["stdout"]


def test_top_level_help_lists_every_command():
    from hindrax_tools.cli import COMMANDS

    out = probe(["--help"])["stdout"]
    assert all(words[0] in out for words, _m, _h in COMMANDS)


def test_help_of_one_command_imports_that_command_only():
    """``hindrax bag info --help`` shows its arguments, loading bag/info.py (and no ROS, no numpy)."""
    r = probe(["bag", "info", "--help"])
    assert r["status"] == 0 and "usage: hindrax bag info [-h] bag" in r["stdout"]
    assert r["commands"] == ["hindrax_onboard.commands.bag",
                             "hindrax_onboard.commands.bag.info"]
    assert r["loaded"] == []


def test_config_check_does_not_import_ros(tmp_path):
    r = probe(["config", "check", str(tmp_path / "missing.yaml")])
    assert r["status"] == 1
    assert "rclpy" not in r["loaded"]
