"""``hindrax run`` ends on SIGTERM (``docker stop``, ``kill``) as on Ctrl-C: the bag closed whole, the
emulated ports' temporary folders removed, no "coroutine ... was never awaited" at exit."""
import os
import re
import signal
import subprocess
import sys
import threading
import time

import pytest

from hindrax_bringup.recording.reader import BagReader
from hindrax_common.testing import child_process, own_domain_env, wait_until
from hindrax_tools import cli
from hindrax_onboard.commands import decode


@pytest.mark.ros
@pytest.mark.timeout(600)
def test_sigterm_during_the_campaign_closes_the_bag_and_leaves_nothing_behind(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    lines: list[str] = []
    with child_process([sys.executable, "-m", "hindrax_tools.cli", "run", "--dofs", "surge",
                        "--levels", "1",
                        "--out", str(out)], env=own_domain_env(TMPDIR=str(tmp)), stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True) as p:
        reader = threading.Thread(target=lambda: lines.extend(p.stdout), daemon=True)
        reader.start()
        wait_until(lambda: any("sending run_identification goal" in ln for ln in lines) or p.poll() is not None,
                   300, lambda: reader.join(0.1), "the campaign's goal sent")
        assert p.poll() is None, "".join(lines)
        assert list(tmp.glob("hindrax_pty_*")), "the run's emulated ports live in TMPDIR"
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=120) == 130, "".join(lines)
    reader.join(10)
    text = "".join(lines)
    assert "never awaited" not in text and "Traceback" not in text, text
    assert not re.search(r"\w+Warning: |Exception ignored", text), text  # no warnings at exit either
    assert BagReader(out / "bag").truncated_files == []  # the recorder closed it: summary written
    assert not list(tmp.glob("hindrax_pty_*"))


def test_an_interruption_renamed_by_a_c_extension_still_ends_the_command_as_interrupted(monkeypatch, capsys):
    """CI, a9227b6: the SIGTERM of the test above reached Python inside rclpy's ``take_goal_response``, and pybind11
    replaced the ``KeyboardInterrupt`` by ``RuntimeError: Unable to convert call argument '1' to Python object``: the
    command ended with a traceback and status 1. Here a command's ``run`` does what pybind11 does."""
    cleaned = []

    def run(_args):
        try:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                deadline = time.monotonic() + 10.0
                while time.monotonic() < deadline:  # the handler runs at one of these bytecodes
                    pass
            except KeyboardInterrupt:
                raise RuntimeError("Unable to convert call argument '1' to Python object") from None
        finally:
            cleaned.append(True)  # the command's clean-up (its bag, its ports) still runs
        return 0

    monkeypatch.setattr(decode, "run", run)
    before = signal.getsignal(signal.SIGTERM)
    assert cli.main(["decode", "dvl75", "-"]) == 130
    assert cleaned == [True]
    assert capsys.readouterr().err.strip().splitlines()[-1] == "interrupted"
    assert signal.getsignal(signal.SIGTERM) is before  # the handlers found on entry are back


def test_a_failure_without_a_stop_signal_is_not_read_as_an_interruption(monkeypatch):
    def run(_args):
        raise RuntimeError("a real bug")

    monkeypatch.setattr(decode, "run", run)
    with pytest.raises(RuntimeError, match="a real bug"):
        cli.main(["decode", "dvl75", "-"])
