"""RosProcess: the one rclpy process life every entry point uses (init, clean-up in order, shutdown, exit status)."""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import rclpy
from rclpy.executors import ExternalShutdownException

from hindrax_common.config import ConfigError
from hindrax_common.process import ros_process
from hindrax_common.process.ros_process import RosProcess, executor_kind, freeze_startup_heap
from hindrax_common.testing import child_env, child_process, interrupt, python_executable, wait_until

pytestmark = pytest.mark.ros


class FakeNode:
    """Records close/destroy calls into a shared log."""

    def __init__(self, name: str, log: list, close_error: Exception | None = None) -> None:
        self.name, self.log, self.close_error = name, log, close_error

    def close(self) -> None:
        self.log.append(f"close {self.name}")
        if self.close_error is not None:
            raise self.close_error

    def destroy_node(self) -> None:
        self.log.append(f"destroy {self.name}")


def test_normal_exit_runs_cleanups_last_first_and_shuts_rclpy_down():
    log: list = []
    with RosProcess([]) as proc:
        assert rclpy.ok()
        proc.own(FakeNode("a", log))
        proc.at_exit(lambda: log.append("extra"))
        proc.own(FakeNode("b", log))
        shutdown = proc.executor.shutdown
        proc.executor.shutdown = lambda *a, **k: (log.append("executor shutdown"), shutdown(*a, **k))[1]
    assert log == ["close b", "destroy b", "extra", "close a", "destroy a", "executor shutdown"]
    assert proc.status == 0 and not rclpy.ok()


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), ExternalShutdownException()])
def test_signals_end_the_process_normally(exc):
    log: list = []
    with RosProcess([]) as proc:
        proc.own(FakeNode("a", log))
        raise exc
    assert proc.status == 0 and log == ["close a", "destroy a"] and not rclpy.ok()


def test_listed_error_prints_one_line_and_sets_status_1(capsys):
    with RosProcess([], errors={ValueError: "invalid configuration"}) as proc:
        raise ConfigError([], source="x.yaml")  # a ValueError
    assert proc.status == 1
    assert capsys.readouterr().err == "invalid configuration: x.yaml: invalid configuration\n"


def test_other_errors_propagate_after_cleanup():
    log: list = []
    with pytest.raises(RuntimeError, match="boom"):
        with RosProcess([]):
            log.append("body")
            raise RuntimeError("boom")
    assert not rclpy.ok() and log == ["body"]


def test_an_error_during_shutdown_is_part_of_the_orderly_exit():
    """A callback failing because SIGINT/SIGTERM already shut the context down is not a crash."""
    with RosProcess([]) as proc:
        rclpy.shutdown()  # what the signal handler does
        raise RuntimeError("publisher's context is invalid")
    assert proc.status == 0


def test_an_interruption_renamed_by_a_c_extension_is_part_of_the_orderly_exit():
    """SIGINT's KeyboardInterrupt raised inside pybind11's call back into Python comes out as a RuntimeError (CI,
    a9227b6, rclpy's ``take_goal_response``), possibly before rclpy's own handler thread shut the context down."""
    log: list = []
    found = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with RosProcess([]) as proc:
            proc.own(FakeNode("a", log))
            try:
                proc._on_signal(signal.SIGINT, None)  # Python's handler, as the interpreter runs it
            except KeyboardInterrupt:
                assert rclpy.ok()  # the context is still up: only the recorded signal tells
                raise RuntimeError("Unable to convert call argument '1' to Python object") from None
        assert proc.status == 0 and log == ["close a", "destroy a"] and not rclpy.ok()
        # a process that got a stop signal ignores further ones until it has exited (module docstring)
        assert signal.getsignal(signal.SIGINT) == signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
    finally:
        # this worker goes on: a child it starts would inherit ignored SIGINT and SIGTERM (a fresh clone of
        # e0567a0: test_setup_progress's ticker then outlived its `kill`, and its bash never exited)
        for sig, handler in found.items():
            signal.signal(sig, handler)


def test_a_failing_cleanup_does_not_skip_the_others():
    log: list = []
    with pytest.raises(OSError, match="bus gone"):
        with RosProcess([]) as proc:
            proc.own(FakeNode("a", log))
            proc.own(FakeNode("b", log, close_error=OSError("bus gone")))
    assert log == ["close b", "close a", "destroy a"] and not rclpy.ok()


def test_executor_is_the_events_executor_unless_hindrax_executor_says_single(monkeypatch):
    from rclpy.executors import SingleThreadedExecutor

    monkeypatch.delenv("HINDRAX_EXECUTOR", raising=False)
    with RosProcess([]) as proc:
        assert type(proc.executor._ex).__name__ == "EventsExecutor"  # rclpy's C++ events executor
    monkeypatch.setenv("HINDRAX_EXECUTOR", "single")
    with RosProcess([]) as proc:
        assert isinstance(proc.executor, SingleThreadedExecutor)
    monkeypatch.setenv("HINDRAX_EXECUTOR", "")  # empty: as unset
    with RosProcess([]) as proc:
        assert type(proc.executor._ex).__name__ == "EventsExecutor"
    monkeypatch.delenv("HINDRAX_EXECUTOR")
    with RosProcess([], executor="single") as proc:  # a process that fixes its executor, whatever the environment
        assert isinstance(proc.executor, SingleThreadedExecutor)


def test_unknown_executor_names_the_variable_value_and_allowed_values(monkeypatch):
    monkeypatch.setenv("HINDRAX_EXECUTOR", "multi")
    with pytest.raises(ValueError, match=r"HINDRAX_EXECUTOR='multi': allowed values are events, single"):
        executor_kind()
    with pytest.raises(ValueError, match=r"executor='fast'"):
        RosProcess([], executor="fast")


def test_events_loop_spins_callbacks_and_ends_on_context_shutdown():
    """spin() of the events loop runs timers and returns via ExternalShutdownException once the context is shut
    down (what SIGINT/SIGTERM do), which RosProcess treats as a normal end."""
    ticks: list = []
    with RosProcess([], executor="events") as proc:
        node = proc.own(rclpy.create_node("events_loop_test"))
        node.create_timer(0.01, lambda: ticks.append(1) if len(ticks) < 5 else rclpy.shutdown())
        proc.executor.add_node(node)
        proc.executor.spin()
    assert len(ticks) == 5 and proc.status == 0 and not rclpy.ok()


def test_spin_loop_reads_rclpy_ok_at_most_every_check_period(monkeypatch):
    """The spin loop of every node process: with events streaming (a turn every 1 ms of a fake clock) it asks
    rclpy.ok() at most once per OK_CHECK_PERIOD_S, not once per event, and still ends within that period of the
    context going down; a false go_on() ends it at the next turn."""
    clock = [0.0]
    monkeypatch.setattr(ros_process.time, "monotonic", lambda: clock[0])
    asked: list = []

    def ok() -> bool:
        asked.append(clock[0])
        return clock[0] < 1.0  # the context shuts down at 1 s

    monkeypatch.setattr(ros_process.rclpy, "ok", ok)
    timeouts: list = []

    class Streaming:
        def spin_once(self, timeout_sec=None):
            timeouts.append(timeout_sec)
            clock[0] += 0.001

    ros_process._spin_while(Streaming(), lambda: True)
    assert len(timeouts) >= 1000 and set(timeouts) == {ros_process.SPIN_TIMEOUT_S}
    assert len(asked) <= 1.0 / ros_process.OK_CHECK_PERIOD_S + 2
    assert 1.0 <= clock[0] <= 1.0 + ros_process.OK_CHECK_PERIOD_S + 0.0011
    assert ros_process.SPIN_TIMEOUT_S + ros_process.OK_CHECK_PERIOD_S <= 0.1 + 1e-12  # the documented 0.1 s
    turns, clock[0] = len(timeouts), 0.0
    ros_process._spin_while(Streaming(), lambda: len(timeouts) < turns + 3)
    assert len(timeouts) == turns + 3


# A node process started by the shared runner (run_node -> RosProcess): prints "spinning" at its first tick (with
# the number of objects frozen for the garbage collector),
# "closing" when its close() starts, then waits in close() for the file argv[1] and, once run_node has returned
# ("returned <status>"), for argv[1] + ".2" before it exits with run_node's status. With argv[2] == "thread", its
# constructor ends with one SIGINT taken by another thread (what test_controller_node met on a loaded machine);
# with "thread-spinning", its first tick does. With "budget", its shutdown budget is 1 s instead of 8 and its
# close() never returns.
SIGNAL_PROBE = r"""
import ctypes, gc, os, signal, sys, threading, time
from pathlib import Path

from rclpy.node import Node

from hindrax_common.process.conditions import wait_until
from hindrax_common.process import ros_process
from hindrax_common.node_support.node_common import run_node

go, mode = Path(sys.argv[1]), sys.argv[2]
if mode == "budget":
    ros_process.SHUTDOWN_BUDGET_S = 1.0


def say(line):
    print(line, flush=True)


# One process-directed SIGINT that the kernel hands to a thread other than the main one (a DDS thread: the main
# thread blocks SIGINT from here on), then back to the caller as soon as that thread has taken it, without waiting
# for Python's handler: on Linux, CPython 3.11's C handler run in a thread that cannot handle signals marks the
# signal pending without setting the main thread's eval breaker (Python/ceval.c, _PyEval_SignalReceived: force = 0
# except on Windows), so the handler runs at the main thread's next look, which a loop that never releases the GIL
# may not make (the first version of this probe waited for the handler in such a loop: 60 s without it, 1 run in 30
# on a loaded machine). RosProcess.spin must make that look by itself (its spin_once waits without the GIL). If no
# other thread has taken the signal within 10 s, the main thread unblocks it and takes it.
def sigint_taken_by_another_thread():
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    ctypes.PyDLL(None).kill(os.getpid(), signal.SIGINT)  # PyDLL: the GIL held, no look for signals on the way back
    deadline = time.monotonic() + 10
    while signal.SIGINT in signal.sigpending() and time.monotonic() < deadline:
        pass  # C calls only (no look for signals, the GIL kept): until a thread has dequeued the signal
    if signal.SIGINT in signal.sigpending():
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


class Probe(Node):
    def __init__(self):
        super().__init__("signal_probe")
        self.ticks = 0
        self.create_timer(0.01, self.tick)
        if mode == "thread":
            sigint_taken_by_another_thread()

    def tick(self):
        self.ticks += 1
        if self.ticks == 1:
            say(f"spinning, {gc.get_freeze_count()} objects frozen")
            if mode == "thread-spinning":
                sigint_taken_by_another_thread()

    def close(self):
        say(f"closing, context {'up' if self.context.ok() else 'down'}")
        if mode == "budget":  # hung for good in one C wait: the dump reads still frames, not a 5 ms poll's
            threading.Event().wait()
        wait_until(go.exists, 60, message="go")


rc = run_node(Probe, [], exit_process=False)  # the tests below also look at what follows its return
say(f"returned {rc}")
wait_until(Path(f"{go}.2").exists, 60, message="go 2")
sys.exit(rc)
"""


class SignalProbe:
    """The probe process, its output lines collected by a thread (the test waits on them, never on a time)."""

    def __init__(self, tmp_path, mode: str = "outside") -> None:
        script = tmp_path / "signal_probe.py"
        script.write_text(SIGNAL_PROBE)
        self.go = tmp_path / "go"
        self.proc = subprocess.Popen([python_executable(), str(script), str(self.go), mode], env=child_env(),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)

    def wait_for(self, text: str) -> None:
        wait_until(lambda: any(text in line for line in self.lines) or self.proc.poll() is not None, 60,
                   message=f"{text!r} from the probe")
        assert any(text in line for line in self.lines), "".join(self.lines)

    def send(self, *signals: int) -> None:
        """Send ``signals`` and wait until the kernel has delivered them (none pending in /proc/<pid>/status)."""
        for sig in signals:
            self.proc.send_signal(sig)
        mask = sum(1 << (sig - 1) for sig in signals)

        def delivered() -> bool:
            if self.proc.poll() is not None:
                return True  # ended (by them: the assertion below)
            status = Path(f"/proc/{self.proc.pid}/status").read_text().splitlines()
            pending = [int(line.split()[1], 16) for line in status if line.startswith(("SigPnd:", "ShdPnd:"))]
            return not any(p & mask for p in pending)

        wait_until(delivered, 10, message="signals delivered")
        assert self.proc.poll() is None, "".join(self.lines)  # not ended by them

    def finish(self) -> int:
        """Let the probe leave close() and then exit; its exit status."""
        self.go.touch()
        self.wait_for("returned")
        (self.go.parent / "go.2").touch()
        return self.proc.wait(timeout=60)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


@pytest.mark.parametrize("first", ["SIGINT", "SIGTERM"])
def test_signals_during_and_after_the_shutdown_leave_exit_status_0(tmp_path, first):
    """The first signal ends the node process; SIGINT and SIGTERM sent while its clean-ups run (here: its close())
    and after run_node has returned change nothing: close() runs to its end and the process exits 0 (before: the
    second SIGINT raised KeyboardInterrupt in close(), exit -2)."""
    probe = SignalProbe(tmp_path)
    try:
        probe.wait_for("spinning")
        probe.send(getattr(signal, first))
        probe.wait_for("closing")
        probe.send(signal.SIGINT, signal.SIGTERM)
        probe.send(signal.SIGINT)
        probe.go.touch()
        probe.wait_for("returned 0")
        probe.send(signal.SIGINT, signal.SIGTERM)
        assert probe.finish() == 0, "".join(probe.lines)
    finally:
        probe.kill()


def test_a_hung_shutdown_dumps_every_thread_and_exits_1_after_its_budget(tmp_path):
    """A node process whose close() never returns (the probe waits for a file nobody writes) does not wait for
    ``ros2 launch``'s SIGKILL: after its shutdown budget it writes every thread's traceback to stderr, the hung
    close() among them, and exits with status 1. Signals during the shutdown are still absorbed."""
    probe = SignalProbe(tmp_path, mode="budget")
    try:
        probe.wait_for("spinning")
        probe.send(signal.SIGINT)
        probe.wait_for("closing")
        probe.send(signal.SIGTERM)
        assert probe.proc.wait(timeout=30) == 1, "".join(probe.lines)
        out = "".join(probe.lines)
        assert "most recent call first" in out and "in close" in out, out
        assert not any(line.startswith("returned") for line in probe.lines), out  # run_node never returned
    finally:
        probe.kill()


@pytest.mark.parametrize("when", ["thread", "thread-spinning"])
def test_one_sigint_taken_by_another_thread_leaves_exit_status_0(tmp_path, when):
    """One SIGINT that the kernel hands to a thread other than the main one: just after the node is built
    (test_controller_node sends it on "controller ready") or at the first tick. Before: rclpy shut the context down,
    the spin loop ended before the main thread had looked at the signal, and Python's KeyboardInterrupt came due in
    the clean-up (the flaky exit -2 of test_controller_node). Now a node process has no rclpy handler: the signal is
    recorded, spin() returns, the clean-ups run, exit 0. The probe does not wait for Python's handler
    (``sigint_taken_by_another_thread`` in the probe): spin() has to let it run by itself."""
    probe = SignalProbe(tmp_path, mode=when)
    try:
        probe.wait_for("closing")
        assert probe.finish() == 0, "".join(probe.lines)
        assert any("closing, context up" in line for line in probe.lines), "".join(probe.lines)
    finally:
        probe.kill()


def test_a_node_process_shuts_down_on_sigint_without_a_keyboard_interrupt_in_a_callback(tmp_path, monkeypatch):
    """run_nodes builds its RosProcess with ``interrupt=False``: SIGINT is recorded and ends the spin loop (no
    ``KeyboardInterrupt`` half way through a timer callback, no context shut down under one by rclpy's handler, and so
    no rclpy FATAL traceback at a launch's Ctrl-C); the default RosProcess of a command still raises it. Then the
    signal probe: SIGINT, the clean-ups run with the context up, exit 0."""
    import hindrax_common.node_support.node_common as node_common

    quiet, default = RosProcess([], interrupt=False), RosProcess([])
    quiet._on_signal(signal.SIGINT, None)  # a node process: recorded, nothing raised
    assert quiet.signals == [signal.SIGINT]
    with pytest.raises(KeyboardInterrupt):
        default._on_signal(signal.SIGINT, None)
    built: list[dict] = []

    class Recording(RosProcess):
        def __init__(self, *args, **kwargs):
            built.append(dict(kwargs))
            kwargs["exit_process"] = False  # this is pytest's worker: it must go on
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(node_common, "RosProcess", Recording)
    with pytest.raises(RuntimeError):  # the factory fails at once: only the construction is looked at here
        node_common.run_nodes([lambda: (_ for _ in ()).throw(RuntimeError("no node"))], [])
    assert built and built[0].get("interrupt") is False and built[0].get("exit_process") is True
    probe = SignalProbe(tmp_path)
    try:
        probe.wait_for("spinning")
        probe.send(signal.SIGINT)
        probe.wait_for("closing")
        assert probe.finish() == 0, "".join(probe.lines)
        assert not any("KeyboardInterrupt" in line or "FATAL" in line for line in probe.lines), "".join(probe.lines)
        # no rclpy handler shut the context down under a running callback: it is still up for the clean-ups
        assert any("closing, context up" in line for line in probe.lines), "".join(probe.lines)
    finally:
        probe.kill()


def test_a_node_process_spins_with_its_start_up_heap_frozen(tmp_path):
    """run_node spins through RosProcess.spin, which freezes the start-up heap first: at the first tick of the probe
    node every object of the imports (rclpy, the node) is out of the garbage collector's reach (tens of thousands;
    a bare interpreter has none frozen), so a full collection during the run cannot stop the process for the 14-59
    ms one takes here over that heap (ros_process.py, "Garbage collection")."""
    probe = SignalProbe(tmp_path)
    try:
        probe.wait_for("spinning")
        line = next(ln for ln in probe.lines if "spinning" in ln)
        frozen = int(line.split(", ")[1].split()[0])
        assert frozen > 20_000, line
        probe.send(signal.SIGTERM)
        probe.wait_for("closing")
        assert any("closing, context up" in line for line in probe.lines), "".join(probe.lines)  # as for SIGINT
        assert probe.finish() == 0, "".join(probe.lines)
    finally:
        probe.kill()


def test_freeze_startup_heap_collects_start_up_garbage_and_freezes_the_rest():
    """freeze_startup_heap(): cyclic garbage made before it is collected, not frozen; a live object is frozen (a
    later full collection no longer sees it); the count returned is gc's own."""
    import gc
    import weakref

    class Cell:
        pass

    garbage, alive = Cell(), Cell()
    garbage.me = garbage  # a reference cycle: only the collector frees it
    gone = weakref.ref(garbage)
    del garbage
    # Another thread of this worker (one an earlier test left, rclpy's) that frees a frozen object between the
    # freeze and the count lowers the count: a fresh clone of e0567a0 read 230836 returned and 230811 counted. A
    # long switch interval keeps the GIL in this thread from the freeze to the comparison.
    interval = sys.getswitchinterval()
    sys.setswitchinterval(60.0)
    try:
        frozen = freeze_startup_heap()
        counted = gc.get_freeze_count()
        sys.setswitchinterval(interval)
        assert gone() is None
        assert frozen == counted > 0
        assert not gc.is_tracked(alive) or all(obj is not alive for obj in gc.get_objects())
    finally:
        sys.setswitchinterval(interval)
        gc.unfreeze()


# A node process as the vehicle runs it (run_node, exit_process left at its default): a node publishing on
# exit_probe/beat, "spinning" at its first tick, "closed" when its close() has run; "returned" would follow run_node's
# return, which must not come.
EXIT_PROBE = r"""
from rclpy.node import Node
from std_msgs.msg import Empty

from hindrax_common.node_support.node_common import run_node


class ExitProbe(Node):
    def __init__(self):
        super().__init__("exit_probe")
        self.pub = self.create_publisher(Empty, "exit_probe/beat", 10)
        self.ticks = 0
        self.create_timer(0.02, self.tick)

    def tick(self):
        self.pub.publish(Empty())
        self.ticks += 1
        if self.ticks == 1:
            print("spinning", flush=True)

    def close(self):
        print("closed", flush=True)


rc = run_node(ExitProbe, [])
print(f"returned {rc}", flush=True)
"""


def test_a_node_process_ends_in_run_node_after_destroying_its_node(tmp_path):
    """A node process ends inside run_node (module docstring of ros_process, "Exit without the DDS participant's
    teardown"): on SIGINT its close() runs, it exits 0 with nothing after run_node run, and its node and publisher
    leave the graph of a process that watches it, as with an ordinary exit (only its participant is left to its
    lease)."""
    script = tmp_path / "exit_probe.py"
    script.write_text(EXIT_PROBE)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        watcher = rclpy.create_node("exit_watcher", context=context)

        def seen() -> bool:
            return "exit_probe" in watcher.get_node_names() and watcher.count_publishers("/exit_probe/beat") == 1

        with child_process([python_executable(), str(script)], env=child_env(), stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True) as proc:
            lines: list[str] = []
            reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
            reader.start()
            wait_until(lambda: any("spinning" in ln for ln in lines) and seen() or proc.poll() is not None, 60,
                       message="the probe spinning and on the graph")
            assert proc.poll() is None, "".join(lines)
            assert interrupt(proc, 30) == 0, "".join(lines)
        reader.join(10)
        out = "".join(lines)
        assert "closed" in out and "returned" not in out and "Traceback" not in out, out
        wait_until(lambda: "exit_probe" not in watcher.get_node_names()
                   and watcher.count_publishers("/exit_probe/beat") == 0, 10,
                   message="the probe's node and publisher off the graph")
    finally:
        rclpy.try_shutdown(context=context)
