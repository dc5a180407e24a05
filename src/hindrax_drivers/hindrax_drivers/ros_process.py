"""The life of an rclpy process, written once: init, run, orderly shutdown on SIGINT/SIGTERM.

Every process entry point (a node run alone, :func:`~hindrax_drivers.node_common.run_node`; the whole graph,
``hindrax bringup``; ``hindrax bag play|record``; the recorder and player nodes run alone) is::

    with RosProcess(args, errors={ConfigError: "invalid configuration"}) as proc:
        node = proc.own(MyNode())
        proc.executor.add_node(node)
        proc.executor.spin()
    return proc.status

On leaving the block, whatever the reason, the registered clean-ups run, last registered first (for a node
from :meth:`RosProcess.own`: its ``close()`` if it has one, which is where the ESC node writes neutral, then
``destroy_node()``), then the executor shuts down and the rclpy context is shut down if still up.

Exceptions leaving the block:

- ``KeyboardInterrupt`` and rclpy's ``ExternalShutdownException`` (SIGINT/SIGTERM) end the process normally;
- an exception of a type listed in ``errors`` (e.g. an invalid configuration) is printed as one line,
  ``"<prefix>: <first line of the message>"``, on stderr and sets :attr:`RosProcess.status` to 1;
- any other exception is re-raised, except while the context is already shutting down: a callback that was
  running when the signal arrived may then fail inside rcl ("publisher's context is invalid"), which is part
  of the orderly shutdown, not a crash.

rclpy is imported when the block is entered, not when this module is.
"""
from __future__ import annotations

import sys
from typing import Any, Callable, Mapping, Sequence

__all__ = ["RosProcess"]


class RosProcess:
    """Context manager around one rclpy process (module docstring).

    args: command-line arguments for ``rclpy.init`` (``None``: ``sys.argv``, so ``--ros-args`` are honoured;
    ``[]`` for a process whose arguments are not ROS arguments). errors: {exception type: message prefix}.
    """

    def __init__(self, args: Sequence[str] | None = None, errors: Mapping[type, str] | None = None) -> None:
        self.args = list(args) if args is not None else list(sys.argv)
        self.errors = dict(errors or {})
        self.status = 0
        """Exit status: 0, or 1 after an exception listed in ``errors`` (a command may set it too)."""
        self._cleanups: list[Callable[[], Any]] = []
        self._executor: Any = None

    def __enter__(self) -> RosProcess:
        import rclpy

        rclpy.init(args=self.args)
        return self

    @property
    def executor(self) -> Any:
        """A ``SingleThreadedExecutor``, created on first use and shut down on exit (after every clean-up)."""
        if self._executor is None:
            from rclpy.executors import SingleThreadedExecutor

            self._executor = SingleThreadedExecutor()
        return self._executor

    def at_exit(self, cleanup: Callable[[], Any]) -> None:
        """Run ``cleanup()`` on exit (clean-ups run last registered first)."""
        self._cleanups.append(cleanup)

    def own(self, node: Any) -> Any:
        """Register ``node`` for clean-up on exit: ``node.close()`` when it has one, then ``node.destroy_node()``
        (after removing it from :attr:`executor`). Returns ``node``."""
        def cleanup() -> None:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            if self._executor is not None:
                self._executor.remove_node(node)
            node.destroy_node()

        self._cleanups.append(cleanup)
        return node

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: Any) -> bool:
        import rclpy
        from rclpy.executors import ExternalShutdownException

        shutting_down = not rclpy.ok()  # before the clean-up: SIGINT/SIGTERM already shut the context down
        failed: list[Exception] = []
        while self._cleanups:
            try:
                self._cleanups.pop()()
            except Exception as cleanup_exc:  # noqa: BLE001 - run the other clean-ups, report below
                failed.append(cleanup_exc)
        if self._executor is not None:
            self._executor.shutdown()
        rclpy.try_shutdown()
        if failed and exc_type is None:
            raise failed[0]
        for cleanup_exc in failed:
            print(f"shutdown: {type(cleanup_exc).__name__}: {cleanup_exc}", file=sys.stderr)
        if exc_type is None:
            return False
        if issubclass(exc_type, (KeyboardInterrupt, ExternalShutdownException)):
            return True
        for kind, prefix in self.errors.items():
            if isinstance(exc, kind):
                lines = str(exc).splitlines()
                print(f"{prefix}: {lines[0] if lines else exc_type.__name__}", file=sys.stderr)
                self.status = 1
                return True
        return isinstance(exc, Exception) and shutting_down
