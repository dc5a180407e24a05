"""Run a launch file's process list the way ``ros2 launch`` runs it: one process per node, respawned, stopped in
order (docs/deployment.md §9).

:func:`~hindrax_bringup.layout.launch_xml.read_launch` gives the processes; :class:`ProcessRunner` starts each one with
the command ``launch_ros`` would build (:meth:`NodeProcess.ros_arguments`), restarts a process whenever it ends
while the runner runs and the node asks for it (``respawn``, after ``respawn_delay``; ``launch.actions
.ExecuteLocal`` does the same on any exit), and on :meth:`ProcessRunner.stop` sends SIGINT to every process, then
SIGTERM after ``sigterm_timeout_s`` and SIGKILL after ``sigkill_timeout_s`` more (``ros2 launch``'s
``sigterm_timeout`` and ``sigkill_timeout``, 5 s each by default). Each process's output goes to
``<log_dir>/<label>.log``, appended across respawns with one header line per start.

Why our own runner: ``launch`` is not installable on the development machines (docs/architecture.md §11.3), and
the pool-day test must start exactly what the vehicle's launch file declares. It is a test and development tool;
the vehicle runs ``ros2 launch``.

Executables are found as ``ros2 run`` finds them (:func:`installed_command`): ``<prefix>/lib/<package>/<exec>``
for the package's prefix in the ament index; in a development venv where the package is an editable pip install
(no ``lib/<package>``), the console script of that name next to the interpreter, if it belongs to the package."""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Callable, Mapping, Sequence

from ament_index_python.packages import PackageNotFoundError, get_package_prefix

from .launch_xml import NodeProcess, write_parameter_file

__all__ = ["ProcessRunner", "ProcessState", "installed_command"]


def installed_command(process: NodeProcess) -> list[str]:
    """The executable of ``process`` as ``ros2 run <package> <exec>`` finds it (module docstring).

    Raises ``LookupError`` naming the places searched."""
    searched = []
    try:
        exe = Path(get_package_prefix(process.package), "lib", process.package, process.executable)
        if os.access(exe, os.X_OK):
            return [str(exe)]
        searched.append(str(exe))
    except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
        searched.append(f"ament index (no package {process.package})")
    script = Path(sys.executable).parent / process.executable
    if os.access(script, os.X_OK) and _console_script_of(process.package, process.executable):
        return [str(script)]
    searched.append(str(script))
    raise LookupError(f"{process.package}/{process.executable}: no executable; searched {', '.join(searched)}")


def _console_script_of(package: str, name: str) -> bool:
    return any(ep.name == name and ep.dist is not None and ep.dist.name.replace("-", "_") == package
               for ep in entry_points(group="console_scripts"))


@dataclass
class ProcessState:
    """What the runner knows about one process: ``pid`` (current or last), ``running``, ``starts`` (1 + respawns),
    ``exit_codes`` (one per ended run, negative = killed by that signal)."""

    label: str
    pid: int | None
    running: bool
    starts: int
    exit_codes: tuple[int, ...]


class _Slot:
    def __init__(self, process: NodeProcess, command: list[str], log_path: Path) -> None:
        self.process, self.command, self.log_path = process, command, log_path
        self.popen: subprocess.Popen | None = None
        self.starts = 0
        self.exit_codes: list[int] = []
        self.thread: threading.Thread | None = None


class ProcessRunner:
    """Starts, respawns and stops the processes of a launch file (module docstring).

    processes: from :func:`~hindrax_bringup.layout.launch_xml.read_launch`. command: process -> executable argv (default
    :func:`installed_command`). env: environment of every process (default: this one's), updated by the launch file's
    (``<set_env>``, ``<env>``: :attr:`NodeProcess.env`), then by ``extra_env``: per-label additions (e.g. an emulated
    device for one driver). log_dir: output files (default: a temporary directory, :attr:`log_dir`). extra_ros_args:
    per-label arguments appended after the launch file's (``-p key:=value`` overrides, e.g. an emulated port). Use as a
    context manager or call :meth:`start` / :meth:`stop`. Raises ``LookupError`` from :meth:`start` when an executable
    cannot be found (nothing is started then), and ``ValueError`` for two processes with the same label."""

    def __init__(self, processes: Sequence[NodeProcess], *,
                 command: Callable[[NodeProcess], list[str]] = installed_command,
                 env: Mapping[str, str] | None = None, extra_env: Mapping[str, Mapping[str, str]] | None = None,
                 extra_ros_args: Mapping[str, Sequence[str]] | None = None, log_dir: str | os.PathLike | None = None,
                 sigterm_timeout_s: float = 5.0, sigkill_timeout_s: float = 5.0) -> None:
        labels = [p.label for p in processes]
        duplicates = sorted({n for n in labels if labels.count(n) > 1})
        if duplicates:
            raise ValueError(f"processes with the same name: {', '.join(duplicates)}")
        self.processes = list(processes)
        self._command = command
        self._env = dict(os.environ if env is None else env)
        self._extra_env = {k: dict(v) for k, v in (extra_env or {}).items()}
        self._extra_args = {k: list(v) for k, v in (extra_ros_args or {}).items()}
        self.log_dir = Path(tempfile.mkdtemp(prefix="hindrax-launch-")) if log_dir is None else Path(log_dir)
        self.sigterm_timeout_s = float(sigterm_timeout_s)
        self.sigkill_timeout_s = float(sigkill_timeout_s)
        self._slots: dict[str, _Slot] = {}
        self._lock = threading.Lock()
        self._spawn_lock = threading.Lock()  # no spawn once stop() has begun
        self._stopping = threading.Event()
        self._params_dir = self.log_dir / "params"

    # -- life cycle -------------------------------------------------------------------------------
    def __enter__(self) -> ProcessRunner:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Resolve every executable (LookupError before anything starts), then start the processes in order."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        slots = [_Slot(p, self.argv(p), self.log_dir / f"{p.label}.log") for p in self.processes]
        self._stopping.clear()
        for slot in slots:
            self._slots[slot.process.label] = slot
            self._spawn(slot)
            slot.thread = threading.Thread(target=self._watch, args=(slot,), name=f"runner-{slot.process.label}",
                                           daemon=True)
            slot.thread.start()

    def stop(self) -> dict[str, ProcessState]:
        """SIGINT to every running process (last started first), SIGTERM to those still running after
        ``sigterm_timeout_s``, SIGKILL after ``sigkill_timeout_s`` more; no respawn from then on. Returns
        :meth:`states`."""
        with self._spawn_lock:
            self._stopping.set()
        slots = list(self._slots.values())
        for sig, timeout in ((signal.SIGINT, self.sigterm_timeout_s), (signal.SIGTERM, self.sigkill_timeout_s),
                             (signal.SIGKILL, 10.0)):
            alive = [s for s in reversed(slots) if s.popen is not None and s.popen.poll() is None]
            for s in alive:
                with contextlib.suppress(ProcessLookupError):
                    s.popen.send_signal(sig)
            deadline = time.monotonic() + timeout
            for s in alive:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    s.popen.wait(max(0.0, deadline - time.monotonic()))
        for s in slots:
            if s.thread is not None:
                s.thread.join(timeout=5.0)
        return self.states()

    # -- inspection and faults ----------------------------------------------------------------------
    def states(self) -> dict[str, ProcessState]:
        """label -> :class:`ProcessState`, in launch order."""
        with self._lock:
            return {label: ProcessState(label, s.popen.pid if s.popen else None,
                                        s.popen is not None and s.popen.poll() is None, s.starts,
                                        tuple(s.exit_codes)) for label, s in self._slots.items()}

    def argv(self, p: NodeProcess) -> list[str]:
        """What ``p`` is started with, as ``launch_ros`` builds it: its ``launch-prefix``, the executable, then
        :meth:`NodeProcess.ros_arguments` and this runner's extra arguments for it (writes its parameter files)."""
        self._params_dir.mkdir(parents=True, exist_ok=True)
        def write(values: Mapping) -> Path:  # <param> runs as a file keyed /**, as launch_ros does
            return write_parameter_file(values, self._params_dir)

        return (list(p.launch_prefix) + self._command(p) + p.ros_arguments(write) + self._extra_args.get(p.label, []))

    def environment(self, p: NodeProcess) -> dict[str, str]:
        """The environment ``p`` is started with: this runner's, then the launch file's for it (``<set_env>``,
        ``<env>``: its real-time priority), then this runner's ``extra_env`` for it."""
        return dict(self._env, **dict(p.env), **self._extra_env.get(p.label, {}))

    def log(self, label: str) -> str:
        """Everything process ``label`` wrote so far (all its runs)."""
        try:
            return self._slots[label].log_path.read_text(errors="replace")
        except OSError:
            return ""

    def kill(self, label: str, sig: int = signal.SIGKILL) -> int:
        """Send ``sig`` to the running process ``label`` (a crash, for tests); returns its pid. Raises
        ``ProcessLookupError`` when it is not running."""
        with self._lock:
            popen = self._slots[label].popen
            if popen is None or popen.poll() is not None:
                raise ProcessLookupError(f"{label} is not running")
            popen.send_signal(sig)
            return popen.pid

    # -- internals --------------------------------------------------------------------------------
    def _spawn(self, slot: _Slot) -> None:
        env = self.environment(slot.process)
        with open(slot.log_path, "a") as log:
            log.write(f"--- start {slot.starts + 1}: {' '.join(slot.command)}\n")
            log.flush()
            popen = subprocess.Popen(slot.command, env=env, stdout=log, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        with self._lock:
            slot.popen = popen
            slot.starts += 1

    def _watch(self, slot: _Slot) -> None:
        while True:
            code = slot.popen.wait()
            with self._lock:
                slot.exit_codes.append(code)
            with open(slot.log_path, "a") as log:
                log.write(f"--- exit {code}\n")
            if self._stopping.is_set() or not slot.process.respawn:
                return
            if self._stopping.wait(slot.process.respawn_delay_s):
                return
            with self._spawn_lock:
                if self._stopping.is_set():
                    return
                self._spawn(slot)
