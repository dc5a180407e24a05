"""The life of an rclpy process, written once: init, run, orderly shutdown on SIGINT/SIGTERM.

Every process entry point (:func:`~hindrax_common.node_support.node_common.run_node`, ``hindrax bringup``,
``hindrax bag play|record``) is::

    with RosProcess(args, errors={ConfigError: "invalid configuration"}) as proc:
        node = proc.own(MyNode())
        proc.executor.add_node(node)
        proc.spin()
    return proc.status

On leaving the block the clean-ups run, last registered first (for a node from :meth:`RosProcess.own`: its ``close()``,
where the ESC writes neutral, then ``RawDataPublisher.flush_pending``, then ``destroy_node()``), then the executor and
the context shut down.

Exceptions leaving the block: ``KeyboardInterrupt`` and ``ExternalShutdownException`` end the
process normally; a type listed in ``errors`` is printed as one line ``"<prefix>: <first line>"``
on stderr, status 1; any other is re-raised, except during a shutdown (a callback failing inside
rcl, or a ``KeyboardInterrupt`` renamed by pybind11: the orderly shutdown, not a crash).

The executor is rclpy's ``EventsExecutor`` (docs/architecture.md §10) unless ``HINDRAX_EXECUTOR``
says ``single``; a subscription callback takes the message info only through
:class:`WithMessageInfo` (rclpy 7.1, docs/architecture.md §11.5).

Signals: any number of SIGINT/SIGTERM at any moment after start-up end the process with status 0. In the main thread
Python's handlers are set before ``rclpy.init`` (rclpy's chain to them): while the block runs SIGINT raises
``KeyboardInterrupt`` and SIGTERM shuts the context down; with ``interrupt=False`` (node processes) both are only
recorded, :meth:`RosProcess.spin` returns at its next turn (:data:`SPIN_TIMEOUT_S`) and the context is shut down after
the clean-ups, never under a running callback; from ``__exit__`` on both are absorbed; at the end the handlers found on
entry are restored, unless a signal arrived (they then stay ignored: finalization would reset SIGINT, status -2). In
another thread the handlers are left as they are.

``shutdown_budget_s`` (node processes: :data:`SHUTDOWN_BUDGET_S`): a shutdown still running after it
writes every thread's traceback and exits with status 1 (``faulthandler``), before ``ros2 launch``'s
SIGKILL. ``exit_process=True``: ``__exit__`` ends the process (``os._exit``) after the clean-ups; a
hidden node (``_exit_<pid>``) holds the DDS participant to the end, since Fast DDS 2.14 can spin for
seconds in ``set_listener(nullptr)`` (Fast-DDS issue 6513); main thread only, context still up.

:meth:`RosProcess.spin` collects once and freezes (``gc.freeze``) every object alive at start-up, so
that a full collection cannot stall the safety ticks against their 0.2 s heartbeat timeouts
(docs/architecture.md §8; ``make bench``: ``gc_full_collection_cpu_ms_*``).

rclpy is imported when the block is entered, not when this module is."""
from __future__ import annotations

import contextlib
import faulthandler
import gc
import inspect
import os
import signal
import sys
import threading
import time
import traceback
from types import FrameType
from typing import Any, Callable, Mapping, Sequence

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options, uninstall_signal_handlers

__all__ = ["BEFORE_PROCESS_END", "EXECUTORS", "RosProcess", "SHUTDOWN_BUDGET_S", "WithMessageInfo", "executor_kind",
           "freeze_startup_heap"]

#: values of ``HINDRAX_EXECUTOR``
EXECUTORS = ("events", "single")

#: the longest a node process's shutdown may take before it dumps its threads' tracebacks and exits with status 1
#: (module docstring): below ``ros2 launch``'s SIGKILL, 10 s after its SIGINT; the slowest
#: clean-up measured, the recorder finishing a bag, takes well under a second
SHUTDOWN_BUDGET_S = 8.0

#: callables run, in order, by a process that ends itself (``exit_process=True``) just before ``os._exit``: what a
#: program would have put in ``atexit`` or a ``finally`` after the block (the bench's cProfile dump), which that exit
#: skips; an exception out of one is printed and the others still run
BEFORE_PROCESS_END: list[Callable[[], Any]] = []

#: the signals that end a process (module docstring, "Signals")
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def executor_kind(environ: Mapping[str, str] | None = None) -> str:
    """The executor a process spins: ``HINDRAX_EXECUTOR`` (``events`` when unset or empty). Raises ``ValueError`` naming
    the variable, its value and the allowed values when it is set to anything else."""
    value = (os.environ if environ is None else environ).get("HINDRAX_EXECUTOR", "").strip().lower() or "events"
    if value not in EXECUTORS:
        raise ValueError(f"HINDRAX_EXECUTOR={value!r}: allowed values are {', '.join(EXECUTORS)}")
    return value


def freeze_startup_heap() -> int:
    """Collect the garbage of start-up once, then move every object still tracked by the garbage collector to its
    permanent generation (``gc.collect()``, ``gc.freeze()``; module docstring): no later
    collection traverses them again. Returns the number of frozen objects (``gc.get_freeze_count()``)."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


#: spin loops (:func:`_spin_while`): the longest wait in one ``spin_once`` and the longest time between two looks at
#: ``rclpy.ok()``; together the 0.1 s within which a loop notices a shut-down context or a recorded signal
SPIN_TIMEOUT_S = 0.08
OK_CHECK_PERIOD_S = 0.02


def _spin_while(executor: Any, go_on: Callable[[], bool]) -> None:
    """``executor.spin_once`` until the default context is shut down or ``go_on()`` is false. ``go_on`` (cheap) is
    asked at every turn; ``rclpy.ok()`` (a lock and a call into rcl, 2-4 us here) at most every
    :data:`OK_CHECK_PERIOD_S`: a node process handles 50-100 events a second, each one a turn of this loop."""
    next_check = 0.0
    while go_on():
        now = time.monotonic()
        if now >= next_check:
            if not rclpy.ok():
                return
            next_check = now + OK_CHECK_PERIOD_S
        executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)


class WithMessageInfo:
    """A subscription callback ``fn(msg, info)`` that every executor here calls with the message and its info.

    ``info``: rclpy's ``MessageInfo`` dict of the rmw message info (``source_timestamp``, ``received_timestamp``, ns;
    ``publication_sequence_number``, int; ``reception_sequence_number``, None with rmw_fastrtps_cpp; no publisher
    gid). rclpy marks a callback "with message info" when its signature binds two arguments (``Subscription.callback``);
    the ``SingleThreadedExecutor`` and ``LeanWaitExecutor`` then call it with two, rclpy 7.1's ``EventsExecutor``
    with the ``(msg, info)`` tuple as one (its ``HandleSubscriptionReady``; a plain ``def cb(msg, info)`` fails there
    with "SystemError: null argument to internal routine"). This adapter takes both forms."""

    __slots__ = ("_fn",)
    __signature__ = inspect.Signature([inspect.Parameter(n, inspect.Parameter.POSITIONAL_ONLY)
                                       for n in ("msg", "info")])

    def __init__(self, fn: Callable[[Any, dict], None]) -> None:
        self._fn = fn

    def __call__(self, msg: Any, info: dict | None = None) -> None:
        if info is None:  # the EventsExecutor's one tuple
            msg, info = msg
        self._fn(msg, info)


class _EventsLoop:
    """rclpy's ``EventsExecutor`` (every other method passed through) with its own :meth:`spin`.

    Its own ``spin()`` (rclpy 7.x, Jazzy) does not return when SIGINT/SIGTERM shut the context down, so
    :meth:`spin` is a loop of ``spin_once`` (:func:`_spin_while`), which raises rclpy's
    ``ExternalShutdownException`` then (handled by :class:`RosProcess`)."""

    def __init__(self) -> None:
        self._ex = EventsExecutor()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ex, name)

    def spin(self) -> None:
        _spin_while(self._ex, lambda: True)


class RosProcess:
    """Context manager around one rclpy process (module docstring).

    args: command-line arguments for ``rclpy.init`` (``None``: ``sys.argv``, so ``--ros-args`` are honoured;
    ``[]`` for a process whose arguments are not ROS arguments). errors: {exception type: message prefix}.
    executor: ``events`` or ``single`` to fix the executor, None to follow ``HINDRAX_EXECUTOR``. Raises
    ``ValueError`` for another value. interrupt: whether SIGINT raises ``KeyboardInterrupt`` in the block.
    shutdown_budget_s: seconds the exit may take (module docstring); None, unbounded.
    exit_process: end the process on leaving the block, without the DDS participant's teardown
    (module docstring); only in the main thread."""

    def __init__(self, args: Sequence[str] | None = None, errors: Mapping[type, str] | None = None,
                 executor: str | None = None, interrupt: bool = True,
                 shutdown_budget_s: float | None = None, exit_process: bool = False) -> None:
        if executor is not None and executor not in EXECUTORS:
            raise ValueError(f"executor={executor!r}: allowed values are {', '.join(EXECUTORS)}")
        self.executor_kind = executor
        self.args = list(args) if args is not None else list(sys.argv)
        self.shutdown_budget_s = shutdown_budget_s
        self.exit_process = bool(exit_process)
        self.interrupt = bool(interrupt)
        self.errors = dict(errors or {})
        self.status = 0
        """Exit status: 0, or 1 after an exception listed in ``errors`` (a command may set it too)."""
        self._cleanups: list[Callable[[], Any]] = []
        self._executor: Any = None
        self.signals: list[int] = []
        """The SIGINT/SIGTERM received, in order (main thread only)."""
        self._stopping = False
        self._previous: dict[int, Any] = {}
        self._holder: Any = None

    def __enter__(self) -> RosProcess:
        if threading.current_thread() is threading.main_thread():
            _uninstall_rclpy_handlers()  # an earlier context's (rclpy.try_shutdown leaves them): reinstalled below
            self._previous = {sig: signal.getsignal(sig) for sig in _STOP_SIGNALS}
            for sig in _STOP_SIGNALS:  # before rclpy.init: rclpy's handlers chain to these
                signal.signal(sig, self._on_signal)
        try:  # node processes: no rclpy handler (module docstring, "Signals"), the signals end spin() instead
            rclpy.init(args=self.args, signal_handler_options=SignalHandlerOptions.ALL if self.interrupt
                       else SignalHandlerOptions.NO)
        except BaseException:
            self._stopping = True
            self._release_signals(rclpy_handlers=False)
            raise
        if self.signals:  # a SIGTERM during rclpy.init, before rclpy's handler was there: end at once
            rclpy.try_shutdown()
        return self

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        """Python's handler of SIGINT and SIGTERM (module docstring, "Signals"): records the signal; raises
        ``KeyboardInterrupt`` for SIGINT while the block runs, absorbs both once it is left."""
        self.signals.append(signum)
        if signum == signal.SIGINT and self.interrupt and not self._stopping and not _in_exit(frame):
            raise KeyboardInterrupt

    def _release_signals(self, rclpy_handlers: bool = True) -> None:
        """rclpy's signal handlers out of the chain (``rclpy_handlers``), then the handlers found on entry back, or
        SIGINT and SIGTERM ignored if one arrived (module docstring, "Signals")."""
        if not self._previous:
            return
        if rclpy_handlers:
            _uninstall_rclpy_handlers()  # puts ours back: they were there when rclpy installed its own
        for sig in _STOP_SIGNALS:  # signal.signal runs the handlers of signals already received (absorbed here)
            signal.signal(sig, self._on_signal)
        for sig, previous in self._previous.items():
            signal.signal(sig, signal.SIG_IGN if self.signals else previous if previous is not None else signal.SIG_DFL)
        self._previous = {}

    @property
    def executor(self) -> Any:
        """The process's executor (module docstring: ``EventsExecutor`` unless ``HINDRAX_EXECUTOR=single``),
        created on first use and shut down on exit (after every clean-up). Raises ``ValueError`` for an unknown
        ``HINDRAX_EXECUTOR``."""
        if self._executor is None:
            if (self.executor_kind or executor_kind()) == "events":
                self._executor = _EventsLoop()
            else:
                self._executor = SingleThreadedExecutor()
        return self._executor

    def spin(self, executor: Any = None) -> None:
        """Spin ``executor`` (default :attr:`executor`) until the context shuts down, after freezing the start-up
        heap for the garbage collector (:func:`freeze_startup_heap`; module docstring): call it
        once every node of the process is built. With ``interrupt=False`` it returns
        at most 0.1 s after a SIGINT or SIGTERM (module docstring, "Signals"); otherwise it raises what the
        executor's spin raises (``ExternalShutdownException`` on SIGINT/SIGTERM, handled on leaving the block)."""
        freeze_startup_heap()
        executor = self.executor if executor is None else executor
        if self.interrupt:
            executor.spin()
            return
        _spin_while(executor, lambda: not self.signals)  # interrupt=False: a recorded SIGINT/SIGTERM ends the loop

    def at_exit(self, cleanup: Callable[[], Any]) -> None:
        """Run ``cleanup()`` on exit (clean-ups run last registered first)."""
        self._cleanups.append(cleanup)

    def own(self, node: Any) -> Any:
        """Register ``node`` for clean-up on exit: ``node.close()`` when it has one, ``node.raw.flush_pending()`` when
        it has that (a driver's RawDataPublisher), then ``node.destroy_node()`` (after removing it from
        :attr:`executor`). Returns ``node``."""
        def cleanup() -> None:
            close = getattr(node, "close", None)
            if callable(close):
                close()
            # raw device data a driver's RawDataPublisher still holds (I2C records wait up to 0.1 s), the ESC's
            # neutral write in close() included: published before the node goes
            flush_pending = getattr(getattr(node, "raw", None), "flush_pending", None)
            if callable(flush_pending):
                flush_pending()
            self._hold_participant()  # after close(): the ESC's neutral write is not delayed by it
            if self._executor is not None:
                self._executor.remove_node(node)
            node.destroy_node()

        self._cleanups.append(cleanup)
        return node

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: Any) -> bool:
        self._stopping = True  # first: from here on SIGINT and SIGTERM are absorbed (_on_signal)
        if self.shutdown_budget_s is not None:
            faulthandler.dump_traceback_later(self.shutdown_budget_s, exit=True)
        try:  # _end_process never returns: the budget stays armed until the process has ended
            try:
                handled = self._shut_down(exc_type, exc)
            except BaseException as failure:
                if self._holder is not None:
                    self._end_process(failure)
                raise
            if self._holder is not None:
                self._end_process(None if handled or exc_type is None else exc)
            return handled
        finally:
            self._release_signals()
            if self.shutdown_budget_s is not None:
                faulthandler.cancel_dump_traceback_later()

    def _hold_participant(self) -> None:
        """With :attr:`exit_process`, in the main thread, once: the hidden node that keeps the DDS participant to the
        process's end (:func:`_participant_holder`), before the first node is destroyed."""
        if self.exit_process and self._holder is None and threading.current_thread() is threading.main_thread():
            self._holder = _participant_holder()

    def _end_process(self, failure: BaseException | None) -> None:
        """End the process now (module docstring): the traceback of ``failure`` and status 1, or :attr:`status`."""
        status = self.status
        if failure is not None:
            traceback.print_exception(failure)
            status = 1
        for hook in BEFORE_PROCESS_END:
            try:
                hook()
            except Exception as error:  # noqa: BLE001 - the exit goes on; say what failed
                traceback.print_exception(error)
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):  # a closed pipe or stream
                stream.flush()
        os._exit(status)

    def _shut_down(self, exc_type: type | None, exc: BaseException | None) -> bool:
        """The exit (class docstring): clean-ups, executor and context shutdown; returns whether ``exc`` is handled."""
        shutting_down = not rclpy.ok()  # before the clean-up: SIGINT/SIGTERM already shut the context down
        failed: list[Exception] = []
        while self._cleanups:
            try:
                self._cleanups.pop()()
            except Exception as cleanup_exc:  # noqa: BLE001 - run the other clean-ups, report below
                failed.append(cleanup_exc)
        if self._executor is not None:
            self._executor.shutdown()
        try:
            rclpy.try_shutdown()
        except Exception:  # noqa: BLE001 - rclpy's SIGINT handler shut the context down between its check and ours
            if rclpy.ok():
                raise
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
        return isinstance(exc, Exception) and (shutting_down or bool(self.signals))


def _participant_holder() -> Any:
    """A hidden node whose only purpose is to keep the process's DDS participant (rmw_fastrtps destroys it with the
    context's last node) until the process ends (module docstring).
    No global arguments (a launch's ``-r __node:=esc`` would name it ``esc``), no rosout, no parameter services.
    None when the context is already shut down (the ordinary exit follows)."""
    if not rclpy.ok():
        return None
    try:
        return rclpy.create_node(f"_exit_{os.getpid()}", use_global_arguments=False, enable_rosout=False,
                                 start_parameter_services=False)
    except Exception:  # noqa: BLE001 - the context went down meanwhile: the ordinary exit follows
        return None


def _in_exit(frame: FrameType | None) -> bool:
    """Whether ``frame`` or a caller is :meth:`RosProcess.__exit__`: a signal whose handler runs at its very
    start, before it sets ``_stopping``, is part of the shutdown too."""
    while frame is not None:
        if frame.f_code is RosProcess.__exit__.__code__:
            return True
        frame = frame.f_back
    return False


def _uninstall_rclpy_handlers() -> None:
    """rclpy's SIGINT/SIGTERM handlers out of the chain, if installed (``rclpy.shutdown`` does this for the default
    context, ``rclpy.try_shutdown`` does not); rclpy restores the handlers it found."""
    if get_current_signal_handlers_options() != SignalHandlerOptions.NO:
        uninstall_signal_handlers()
