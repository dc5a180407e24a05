"""Real-time scheduling of the safety processes (hindrax_common/process/scheduling.py, docs/deployment.md §1).

Each case runs in a child interpreter: a process made real-time here would be the test runner itself. The child
reports the policy and priority of its threads as the kernel gives them (``os.sched_getscheduler`` /
``os.sched_getparam`` on each thread id), including a thread started after the call, which must inherit them.
"""
from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys

import pytest

from hindrax_common.process.scheduling import PRIORITY_ENV, requested_priority
from hindrax_common.testing import child_env
from hindrax_test_support.helpers import may_set_fifo

CHILD = r"""
import json, os, threading
from hindrax_common.process.scheduling import apply_realtime_priority, describe
result = apply_realtime_priority()
started = threading.Event(); done = threading.Event()
def later():
    started.set(); done.wait(10)
t = threading.Thread(target=later); t.start(); started.wait(10)
threads = {tid: (os.sched_getscheduler(int(tid)), os.sched_getparam(int(tid)).sched_priority)
           for tid in os.listdir("/proc/self/task")}
done.set(); t.join()
print(json.dumps({"granted": result.granted, "reason": result.reason, "log": describe(result),
                  "threads": threads, "later": str(t.native_id)}))
"""


def run_child(priority: str, prefix: tuple[str, ...] = ()) -> dict:
    env = dict(child_env(), **{PRIORITY_ENV: priority})
    out = subprocess.run([*prefix, sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_requested_priority_is_checked_and_named_in_one_line():
    assert requested_priority({}) == 0 and requested_priority({PRIORITY_ENV: ""}) == 0
    assert requested_priority({PRIORITY_ENV: "0"}) == 0 and requested_priority({PRIORITY_ENV: " 12 "}) == 12
    for bad in ("99", "-3", "high", "10.5", "50"):
        with pytest.raises(ValueError) as err:
            requested_priority({PRIORITY_ENV: bad})
        assert str(err.value) == f"{PRIORITY_ENV}={bad!r}: allowed 0 (not real-time) or an integer 1..49"


def test_every_thread_runs_fifo_at_the_priority_when_permitted_and_later_threads_inherit_it():
    child = run_child("11")
    if may_set_fifo(11):
        assert child["granted"] and child["reason"] == "", child
        assert child["later"] in child["threads"]
        assert set(map(tuple, child["threads"].values())) == {(os.SCHED_FIFO, 11)}, child
        assert child["log"][0] == "info" and "SCHED_FIFO priority 11" in child["log"][1]
    else:  # an unprivileged runner: refused, the process as it was, and the warning says how to allow it
        assert not child["granted"] and "RLIMIT_RTPRIO" in child["reason"], child
        assert set(map(tuple, child["threads"].values())) == {(os.SCHED_OTHER, 0)}, child
        assert child["log"][0] == "warn" and "refused" in child["log"][1]


def test_without_the_privilege_it_is_refused_with_one_warning_and_nothing_changes():
    if os.geteuid() == 0:  # drop CAP_SYS_NICE from the child (util-linux setpriv, part of every Debian)
        setpriv = shutil.which("setpriv")
        assert setpriv, "setpriv (util-linux) is needed to run a child without CAP_SYS_NICE"
        prefix: tuple[str, ...] = (setpriv, "--bounding-set=-sys_nice", "--inh-caps=-sys_nice")
    else:
        prefix = ()
    hard = resource.getrlimit(resource.RLIMIT_RTPRIO)[1]
    if hard >= 12:  # a limit that allows it (set by a unit's LimitRTPRIO): lower it for the child
        prefix = ("prlimit", "--rtprio=0:0", *prefix)
    child = run_child("12", prefix)
    assert not child["granted"], child
    assert child["reason"].startswith("not permitted: needs CAP_SYS_NICE or RLIMIT_RTPRIO >= 12"), child
    assert set(map(tuple, child["threads"].values())) == {(os.SCHED_OTHER, 0)}, child
    level, text = child["log"]
    assert level == "warn" and text.startswith("real-time scheduling SCHED_FIFO priority 12 refused (not permitted")
    assert "running at nice" in text and "docs/deployment.md §1" in text


def test_not_asked_is_not_touched():
    child = run_child("")
    assert not child["granted"] and child["log"] == ["", ""]
    assert set(map(tuple, child["threads"].values())) == {(os.SCHED_OTHER, 0)}, child


def test_a_node_process_refuses_a_bad_priority_with_one_line_and_reports_a_good_one(tmp_path):
    """The output guard's entry point (``run_node``): ``HINDRAX_REALTIME_PRIORITY=99`` stops it at start-up with
    exit status 1 and one ``invalid configuration`` line naming the variable, the value and the range; ``12`` starts
    it and the log says what the kernel granted (or, unprivileged, that it was refused), then SIGINT ends it."""
    import signal

    from hindrax_common.config import default_config_path
    from hindrax_common.testing import child_process, wait_until

    argv = [sys.executable, "-m", "hindrax_bringup.guard.node", "--ros-args", "--params-file",
            str(default_config_path())]
    bad = subprocess.run(argv, env=dict(child_env(), **{PRIORITY_ENV: "99"}), capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 1, bad.stderr
    lines = [x for x in bad.stderr.splitlines() if x.startswith("invalid configuration: ")]
    assert lines == [f"invalid configuration: {PRIORITY_ENV}='99': allowed 0 (not real-time) or an integer 1..49"], \
        bad.stderr
    log = tmp_path / "guard.log"
    with open(log, "w") as out, child_process(argv, env=dict(child_env(), **{PRIORITY_ENV: "12"}), stdout=out,
                                              stderr=subprocess.STDOUT) as proc:
        wait_until(lambda: "real-time scheduling" in log.read_text() or proc.poll() is not None, 120.0,
                   message="the guard's scheduling line")
        text = log.read_text()
        if may_set_fifo(12):
            assert "real-time scheduling: SCHED_FIFO priority 12" in text, text
            assert os.sched_getscheduler(proc.pid) == os.SCHED_FIFO
            assert os.sched_getparam(proc.pid).sched_priority == 12
        else:
            assert "refused" in text, text
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 0, log.read_text()


def test_emulated_devices_serve_from_real_time_threads_only(tmp_path):
    """The hardware stand-in of the pool-day tests (EmulatedDevices, served from the test's own process) answers within
    the drivers' deadlines on a loaded machine: its serving threads run SCHED_FIFO at HARDWARE_STAND_IN_PRIORITY,
    above the vehicle's processes, and the rest of the test process stays SCHED_OTHER. (A full-suite run lost an
    armed pool-day test to an emulated I2C call that took 0.18 s against the ESC's 0.15 s bound.)"""
    import threading

    from hindrax_common.config import default_config_path, load_config
    from hindrax_bringup.layout.emulated_devices import EmulatedDevices
    from hindrax_common.process.scheduling import HARDWARE_STAND_IN_PRIORITY
    from hindrax_common.process.conditions import ConditionTimeout
    from hindrax_common.testing import wait_until
    from hindrax_common.transport.socket_i2c import SocketI2CBus

    cfg = load_config(default_config_path())
    serving = {"i2c-socket-accept", "i2c-socket", "PtyDevice"}
    earlier = set(threading.enumerate())  # the worker's earlier tests may leave threads of these names behind
    with EmulatedDevices(cfg, tmp_path) as dev:
        client = SocketI2CBus(dev.socket_path)
        try:
            client.read_byte_data(int(cfg.esc.i2c_address), 0x00)  # MODE1: a connection, so a serving thread

            def policies() -> dict[str, set]:
                out: dict[str, set] = {}
                for t in set(threading.enumerate()) - earlier:
                    if t.name in serving and t.native_id is not None:
                        out.setdefault(t.name, set()).add((os.sched_getscheduler(t.native_id),
                                                           os.sched_getparam(t.native_id).sched_priority))
                return out
            if may_set_fifo(HARDWARE_STAND_IN_PRIORITY):
                fifo = {(os.SCHED_FIFO, HARDWARE_STAND_IN_PRIORITY)}
                try:
                    wait_until(lambda: (lambda p: set(p) == serving and all(v == fifo for v in p.values()))(
                        policies()), 5, None, "the serving threads SCHED_FIFO")
                except ConditionTimeout:
                    raise AssertionError(f"(policy, priority) by thread: {policies()}") from None
            else:
                wait_until(lambda: all(pty.scheduling_refused for pty in dev.serial.values()), 5, None, "refusals")
                assert all("refused" in pty.scheduling_refused for pty in dev.serial.values())
            assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the test's own thread: untouched
        finally:
            client.close()
