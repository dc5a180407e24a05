"""One writer thread in front of a :class:`~hindrax_bringup.recording.writer.BagWriter`.

``mcap.writer.Writer`` is not thread-safe and a chunk close (compression + fsync) can take milliseconds to tens of
milliseconds on an SD card, so the recorder node's subscription callbacks only enqueue ``(topic, log_time_ns, data)``
and this thread owns the BagWriter: it writes in arrival order, closes the open chunk when ``flush_interval_s`` has
passed (crash safety, see :mod:`.writer`) and finishes the bag on :meth:`ThreadedBagWriter.close`.

Hand-off: the producers append to a ``collections.deque`` (an atomic append, no lock, no wake-up) and the
writer thread drains it every ``drain_period_s`` (and at once on :meth:`~ThreadedBagWriter.close`):
no wake-up per message, as a ``queue.Queue`` would cost. What a crash loses grows by at most
``drain_period_s`` of messages.

Back-pressure: the queue holds at most ``max_queue`` messages; beyond that (disk stalled) messages are counted in
:attr:`ThreadedBagWriter.dropped` instead of growing memory without bound. A file-system error in the thread (disk full)
is kept in :attr:`ThreadedBagWriter.error`; later messages are counted as dropped and :meth:`close` re-raises it.

Pure (threads and a deque only; no ROS)."""
from __future__ import annotations

import collections
import threading
from pathlib import Path
from typing import Any, Iterable, Mapping

from .metadata import BagMetadata
from .writer import BagWriter, WriterOptions

_STOP = object()


class ThreadedBagWriter:
    """Thread-safe front of a BagWriter: ``add_topic``/``write`` from any thread, one writer thread.

    bag_dir, options: as :class:`BagWriter` (the directory is created here, in the caller's thread, so
    a bad path fails at once). max_queue: bound of the message queue (messages). drain_period_s: how often the
    writer thread takes what was queued, s (module docstring)."""

    def __init__(self, bag_dir: str | Path, options: WriterOptions | None = None, max_queue: int = 100_000,
                 drain_period_s: float = 0.05) -> None:
        self._writer = BagWriter(bag_dir, options)
        self.bag_dir = self._writer.bag_dir
        self._queue: collections.deque = collections.deque()
        self._max_queue = int(max_queue)
        self._drain_period_s = float(drain_period_s)
        self._wake = threading.Event()
        self.dropped = 0
        self.error: BaseException | None = None
        self.written = 0
        self._topic_counts: dict[str, int] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f"bag-writer:{self.bag_dir.name}", daemon=True)
        self._thread.start()

    # -- producer side (any thread) ---------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, offered_qos_profiles: Iterable[Mapping[str, Any]] = ()) -> None:
        """Queue a topic registration (see :meth:`BagWriter.add_topic`); ordered before later writes."""
        self._queue.append(("topic", name, type_name, [dict(p) for p in offered_qos_profiles]))

    def write(self, topic: str, log_time_ns: int, data: bytes) -> bool:
        """Queue one message (publish time = log time); False (and counted in
        :attr:`dropped`) if the queue is full or closed."""
        if self._closed or self.error is not None or len(self._queue) >= self._max_queue:
            self.dropped += 1
            return False
        self._queue.append(("msg", topic, log_time_ns, data))
        return True

    def topic_counts(self) -> dict[str, int]:
        """Messages written per topic so far (a copy; written by the writer thread)."""
        with self._lock:
            return dict(self._topic_counts)

    @property
    def current_file(self) -> Path:
        return self._writer.current_file

    @property
    def pending(self) -> int:
        """Messages queued and not yet handed to the BagWriter."""
        return len(self._queue)

    def close(self, timeout_s: float = 30.0) -> BagMetadata:
        """Write everything queued, finish the bag and stop the thread; returns the final metadata.

        Raises the writer thread's error if it failed, TimeoutError if it did not finish in time."""
        if not self._closed:
            self._closed = True
            self._queue.append((_STOP,))
            self._wake.set()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            raise TimeoutError(f"{self.bag_dir}: writer thread did not finish within {timeout_s:g} s")
        if self.error is not None:
            raise self.error
        return self._final

    # -- writer thread ----------------------------------------------------------------------------
    def _run(self) -> None:
        w = self._writer
        q = self._queue
        try:
            stop = False
            while not stop:
                while q:
                    item = q.popleft()
                    if item[0] is _STOP:
                        stop = True
                        break
                    self._handle(w, item)
                w.flush_if_due()
                if not stop:
                    due = w.seconds_until_flush()
                    self._wake.wait(self._drain_period_s if due is None else min(due, self._drain_period_s))
        except BaseException as exc:  # noqa: BLE001 - kept and re-raised by close()
            self.error = exc
            self._drain_after_error()
        finally:
            try:
                self._final = w.close()
            except BaseException as exc:  # noqa: BLE001
                if self.error is None:
                    self.error = exc
                self._final = w.metadata()

    def _handle(self, w: BagWriter, item: tuple) -> None:
        if item[0] == "msg":
            _, topic, t_ns, data = item
            w.write(topic, t_ns, data)
            self.written += 1
            with self._lock:
                self._topic_counts[topic] = self._topic_counts.get(topic, 0) + 1
        else:
            _, name, type_name, qos = item
            w.add_topic(name, type_name, qos)
            with self._lock:
                self._topic_counts.setdefault(name, 0)

    def _drain_after_error(self) -> None:
        while True:
            while self._queue:
                item = self._queue.popleft()
                if item[0] is _STOP:
                    return
                if item[0] == "msg":
                    self.dropped += 1
            self._wake.wait(self._drain_period_s)

    @property
    def warnings(self) -> list[str]:
        return list(self._writer.warnings)
