"""``hindrax`` on a binary or 5000-deep YAML file says so in one line, and a closed output pipe
(``| head``) ends it quietly (exit 141), never with a traceback."""
import subprocess
import sys

import pytest

from hindrax_common.testing import child_env
from hindrax_tools import cli


@pytest.fixture
def bad_inputs(tmp_path):
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(bytes(range(256)) * 8)
    deep = tmp_path / "deep.yaml"
    deep.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    return binary, deep


@pytest.mark.parametrize("argv", [["config", "check", "{}"], ["control", "model", "--model", "{}"],
                                  ["allocate", "1", "0", "0", "0", "0", "0", "--config", "{}"]])
def test_binary_or_deeply_nested_yaml_is_one_line(bad_inputs, argv, capsys):
    for path, words in zip(bad_inputs, ("UTF-8 text file", "nested")):
        rc = cli.main([a.format(path) for a in argv])
        captured = capsys.readouterr()
        said = [ln for ln in (captured.out + captured.err).splitlines() if path.name in ln]  # config check: stdout
        assert rc == 1
        assert len(said) == 1 and "Traceback" not in captured.out + captured.err, captured
        assert ("text file" if words.startswith("UTF") else "nested") in said[0], said


def test_a_closed_output_pipe_ends_quietly():
    p = subprocess.Popen([sys.executable, "-m", "hindrax_tools.cli", "config", "check"],
                         env=child_env(),
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # the reader is gone before the first line: every write meets a closed pipe (| head)
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipeError" not in err, err


@pytest.mark.parametrize("given", ["model_file", "config:=other.yaml"])
def test_pool_rehearse_refuses_a_malformed_or_reserved_launch_argument_in_one_line(given, capsys):
    """Issue 74.5: the rehearsal takes the block's launch arguments (model_file:=); the ones it sets are refused."""
    assert cli.main(["pool", "rehearse", given]) == 1
    err = capsys.readouterr().err
    assert err == (f"pool rehearse: launch argument {given!r}: expected NAME:=VALUE, NAME not one the rehearsal sets "
                   "(config, output_dir, topside_domain_id, topside_discovery_range)\n")


def test_pool_rehearse_says_why_a_domain_is_0_to_101(capsys):
    """Issue 74.8: the range error said 0-101 without why."""
    assert cli.main(["pool", "rehearse", "--topside-domain", "150"]) == 1
    assert capsys.readouterr().err == ("--topside-domain 150: allowed 0-101 (ROS 2 maps a domain id to UDP ports "
                                       "7400 + 250 x id; above 101 they meet Linux's ephemeral ports)\n")
