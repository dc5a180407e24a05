"""The local channel between the gateway's two processes: framed messages over a Unix socket pair.

A frame is ``<u32 header length, u32 payload length>`` (little-endian), a JSON header (an object with ``k``, the
kind) and the payload: a serialized ROS message (CDR), never decoded here. The kinds (docs/architecture.md §8.2):

* topside -> internal: ``call`` (``id``, ``name`` = an internal service of the interface), ``publish`` (``name`` = an
  internal topic of the interface), ``goal`` (``id``), ``cancel`` (``id``), ``status`` (the gateway's
  DiagnosticStatus, for ``/diagnostics``);
* internal -> topside: ``settings`` (the gateway's settings and request bounds, first), ``answer`` (``id``, ``ok``,
  ``why``), ``topic`` (``name`` = a topside topic of the interface), ``accepted`` (``id``, ``ok``, ``why``),
  ``feedback`` (``id``), ``result`` (``id``, ``status``).

:class:`Channel` sends from any thread (one lock) and receives in one reader thread. Standard library only."""
from __future__ import annotations

import contextlib
import json
import socket
import struct
import threading
from typing import Any

__all__ = ["Channel"]

_HEAD = struct.Struct("<II")
#: the largest frame accepted, bytes (a message of the interface is far smaller; a larger one means a broken peer)
MAX_FRAME = 64 << 20


class Channel:
    """One end of the socket pair ``sock``."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self._reader = sock.makefile("rb")
        self._lock = threading.Lock()

    def send(self, header: dict[str, Any], payload: bytes = b"") -> bool:
        """Send one frame; False when the other process is gone."""
        head = json.dumps(header).encode()
        try:
            with self._lock:
                self.sock.sendall(_HEAD.pack(len(head), len(payload)) + head + bytes(payload))
            return True
        except OSError:
            return False

    def recv(self) -> tuple[dict[str, Any], bytes] | None:
        """The next frame, or None at the end (the other process is gone, or sent a malformed frame)."""
        raw = self._exactly(_HEAD.size)
        if raw is None:
            return None
        n_head, n_payload = _HEAD.unpack(raw)
        if n_head + n_payload > MAX_FRAME:
            return None
        head, payload = self._exactly(n_head), self._exactly(n_payload)
        if head is None or payload is None:
            return None
        try:
            return json.loads(head), payload
        except ValueError:
            return None

    def _exactly(self, n: int) -> bytes | None:
        try:
            data = self._reader.read(n)
        except (OSError, ValueError):  # ValueError: closed by another thread
            return None
        return data if len(data) == n else None

    def close(self) -> None:
        """Close this end (the other process sees the end of the channel)."""
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self._reader.close()
        self.sock.close()

