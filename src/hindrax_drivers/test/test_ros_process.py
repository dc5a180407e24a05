"""RosProcess: the one rclpy process life every entry point uses (init, clean-up in order, shutdown, exit status)."""
from __future__ import annotations

import pytest
import rclpy
from rclpy.executors import ExternalShutdownException

from hindrax_drivers.config import ConfigError
from hindrax_drivers.ros_process import RosProcess

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
