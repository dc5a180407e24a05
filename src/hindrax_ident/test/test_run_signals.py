"""Issue 45.6: ``hindrax run`` ends on SIGTERM (``docker stop``, ``kill``) as on Ctrl-C: the bag closed whole, the
emulated ports' temporary folders removed, no "coroutine ... was never awaited" at exit."""
import re
import signal
import subprocess
import sys
import threading

import pytest

from hindrax_drivers.recording.reader import BagReader
from hindrax_drivers.testing import own_domain_env, wait_until


@pytest.mark.ros
@pytest.mark.timeout(600)
def test_sigterm_during_the_campaign_closes_the_bag_and_leaves_nothing_behind(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "hindrax_ident.cli", "run", "--dofs", "surge", "--levels", "1",
                          "--out", str(out)], env=own_domain_env(TMPDIR=str(tmp)), stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(p.stdout), daemon=True)
    reader.start()
    try:
        wait_until(lambda: any("sending run_identification goal" in ln for ln in lines) or p.poll() is not None,
                   300, lambda: reader.join(0.1), "the campaign's goal sent")
        assert p.poll() is None, "".join(lines)
        assert list(tmp.glob("hindrax_pty_*")), "the run's emulated ports live in TMPDIR"
        p.send_signal(signal.SIGTERM)
        assert p.wait(timeout=120) == 130, "".join(lines)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    reader.join(10)
    text = "".join(lines)
    assert "never awaited" not in text and "Traceback" not in text, text
    assert not re.search(r"\w+Warning: |Exception ignored", text), text  # no warnings at exit either
    assert BagReader(out / "bag").truncated_files == []  # the recorder closed it: summary written
    assert not list(tmp.glob("hindrax_pty_*"))
