"""The process runner (hindrax_bringup/layout/process_runner.py): launch_ros's command, respawn after the delay on any
exit, SIGINT -> SIGTERM -> SIGKILL on stop, nothing respawned after stop.

The "executables" are small Python scripts that record their argv and the signals they get."""
from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from hindrax_bringup.layout.launch_xml import NodeProcess
from hindrax_bringup.layout.process_runner import ProcessRunner, installed_command
from hindrax_common.testing import wait_until

SCRIPT = r"""
import json, os, signal, sys, time
out = sys.argv[1]
mode = sys.argv[2]
def note(what):
    with open(out, "a") as f:
        f.write(json.dumps({"pid": os.getpid(), "what": what, "argv": sys.argv[3:]}) + "\n")
def on_signal(sig, _frame):
    note(signal.Signals(sig).name)
    if mode == "obeys":
        sys.exit(0)
for s in (signal.SIGINT, signal.SIGTERM):
    signal.signal(s, on_signal if mode != "deaf" else signal.SIG_IGN)
if mode == "stubborn":  # notes SIGINT and SIGTERM, stays
    pass
note("start")
if mode == "exits":
    sys.exit(3)
while True:
    time.sleep(0.05)
"""


def events(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


@pytest.fixture
def script(tmp_path):
    f = tmp_path / "fake_node.py"
    f.write_text(SCRIPT)
    return f


def runner_for(tmp_path, script, procs, modes, **kw):
    notes = {p.label: tmp_path / f"{p.label}.jsonl" for p in procs}
    command = lambda p: [sys.executable, str(script), str(notes[p.label]), modes[p.label]]  # noqa: E731
    return ProcessRunner(procs, command=command, log_dir=tmp_path / "logs", **kw), notes


def test_command_is_launch_ros_s_and_values_go_to_a_params_file(tmp_path, script):
    cfg = tmp_path / "vehicle.yaml"
    cfg.write_text("/**:\n  ros__parameters: {}\n")
    proc = NodeProcess("pkg", "rec_node", "recorder", parameters=(cfg, {"recording.output_root": "/x",
                                                                          "autostart": True}))
    runner, notes = runner_for(tmp_path, script, [proc], {"recorder": "obeys"},
                               extra_ros_args={"recorder": ["-p", "a:=1"]})
    with runner:
        wait_until(lambda: events(notes["recorder"]), 20, None, "started")
    argv = events(notes["recorder"])[0]["argv"]
    assert argv[:6] == ["--ros-args", "-r", "__node:=recorder", "--params-file", str(cfg), "--params-file"]
    assert argv[7:] == ["-p", "a:=1"]
    assert yaml.safe_load(Path(argv[6]).read_text()) == {
        "/**": {"ros__parameters": {"recording.output_root": "/x", "autostart": True}}}


def test_a_killed_process_respawns_after_its_delay_and_one_that_exits_does_too(tmp_path, script):
    procs = [NodeProcess("pkg", "a", "crashy", respawn=True, respawn_delay_s=0.5),
             NodeProcess("pkg", "b", "quitter", respawn=True, respawn_delay_s=0.2),
             NodeProcess("pkg", "c", "once", respawn=False)]
    runner, notes = runner_for(tmp_path, script, procs, {"crashy": "obeys", "quitter": "exits", "once": "exits"})
    with runner:
        wait_until(lambda: events(notes["crashy"]), 20, None, "crashy started")
        first = runner.states()["crashy"].pid
        t_kill = time.monotonic()
        runner.kill("crashy")
        wait_until(lambda: runner.states()["crashy"].starts == 2 and runner.states()["crashy"].running, 20, None,
                   "crashy respawned")
        respawned_after = time.monotonic() - t_kill
        wait_until(lambda: runner.states()["quitter"].starts >= 3, 20, None, "quitter respawned twice")
        st = runner.states()
    assert st["crashy"].pid != first and st["crashy"].exit_codes[0] == -signal.SIGKILL
    assert respawned_after >= 0.5  # not before respawn_delay
    assert set(st["quitter"].exit_codes) == {3}  # launch respawns on any exit, a failure or not
    assert st["once"].starts == 1 and st["once"].exit_codes == (3,) and not st["once"].running
    assert "--- start 2:" in runner.log("crashy") and "--- exit -9" in runner.log("crashy")


def test_stop_escalates_sigint_sigterm_sigkill_and_nothing_respawns(tmp_path, script):
    procs = [NodeProcess("pkg", "a", "polite", respawn=True, respawn_delay_s=0.0),
             NodeProcess("pkg", "b", "stubborn", respawn=True),
             NodeProcess("pkg", "c", "deaf", respawn=True)]
    modes = {"polite": "obeys", "stubborn": "stubborn", "deaf": "deaf"}
    runner, notes = runner_for(tmp_path, script, procs, modes, sigterm_timeout_s=0.5, sigkill_timeout_s=0.5)
    runner.start()
    wait_until(lambda: all(events(n) for n in notes.values()), 20, None, "all started")
    t0 = time.monotonic()
    st = runner.stop()
    took = time.monotonic() - t0
    assert [e["what"] for e in events(notes["polite"])] == ["start", "SIGINT"] and st["polite"].exit_codes == (0,)
    assert [e["what"] for e in events(notes["stubborn"])] == ["start", "SIGINT", "SIGTERM"]
    assert st["stubborn"].exit_codes == (-signal.SIGKILL,) and st["deaf"].exit_codes == (-signal.SIGKILL,)
    assert took < 5.0  # 0.5 s + 0.5 s of escalation, not the launch defaults
    # stop() returns after the watcher threads ended: no respawn can follow (polite's delay is 0)
    assert all(s.starts == 1 and not s.running for s in runner.states().values())
    assert not any(t.is_alive() for t in threading.enumerate() if t.name.startswith("runner-"))


def test_an_executable_that_is_not_installed_starts_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    procs = [NodeProcess("hindrax_drivers", "dvl75_node", "dvl75"),
             NodeProcess("hindrax_bringup", "no_such_node", "ghost")]
    # in the development venv the console script of the editable install is found (as ros2 run finds lib/<pkg>/)
    assert installed_command(procs[0]) == [str(Path(sys.executable).parent / "dvl75_node")]
    runner = ProcessRunner(procs, log_dir=tmp_path)
    with pytest.raises(LookupError, match="hindrax_bringup/no_such_node"):
        runner.start()
    assert runner.states() == {}
    with pytest.raises(LookupError, match="foxglove_bridge"):  # a console script of another package is not it
        installed_command(NodeProcess("foxglove_bridge", "dvl75_node", "x"))
