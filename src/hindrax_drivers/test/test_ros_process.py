"""RosProcess: the one rclpy process life every entry point uses (init, clean-up in order, shutdown, exit status)."""
from __future__ import annotations

import pytest
import rclpy
from rclpy.executors import ExternalShutdownException

from hindrax_drivers.config import ConfigError
from hindrax_drivers.ros_process import RosProcess, executor_kind

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
