"""Ping1D byte stream -> typed messages, with every rejected byte classified (pure, no I/O).

The one decoding path of the Ping altimeter driver: the ROS node (:mod:`hindrax_drivers.ping1d.node`) and
``hindrax decode ping1d`` both use :class:`Ping1dStreamDecoder`. Frames are extracted by the protocol layer's
:class:`~hindrax_drivers.ping1d.protocol.Ping1dFramer` (docs/devices.md §2.2: ``BR``, u16 length, u16 id, src, dst,
payload, u16 sum checksum) and decoded with :func:`~hindrax_drivers.ping1d.protocol.decode_message`.

The binary protocol has no terminator, so a frame cut short is only visible as a checksum failure
inside the framer. This module tells the cases apart by looking at the bytes *between* two accepted
frames (the "gap"), which it keeps in a window with their stream offsets:

- a ``BR`` header whose claimed frame (10 + payload_length bytes) contains no other plausible header and
  ends exactly where the gap ends or where another such complete frame starts is a whole frame that
  failed its checksum: ``bad_checksum`` (so is a whole frame followed only by noise);
- a ``BR`` header whose claimed frame contains the next plausible header, or runs past the start of the next good frame
  (or the end of the stream / a reconnect), was cut short: ``truncated`` (the framer found the next frame inside it). A
  ``BR`` pair inside a corrupted payload that happens to carry a plausible length can make a corrupted frame count as
  truncated: the counts are diagnostics, the data path does not depend on them;
- a header claiming more than ``max_payload_bytes`` is a false start, and every other byte is
  ``garbage_bytes`` (line noise, auto-baud ``U``...).

Frames that pass the checksum but cannot be decoded are ``unknown_message`` (id not in docs/devices.md §2.4)
or ``malformed`` (wrong payload size or value). Bytes older than two maximal frames are classified
without waiting for the next good frame, so a stream of pure garbage is still reported."""
from __future__ import annotations

import bisect
import collections
from dataclasses import dataclass
from typing import Dict, List, Optional, Union

from .protocol import (CHECKSUM_BYTES, HEADER_BYTES, PAYLOAD_TYPES, Ping1dFramer, Ping1dMessage,
                       Ping1dParseError, Ping1dPayload, decode_message)

__all__ = ["Ping1dStreamDecoder", "Ping1dStreamError", "Ping1dDecoded", "ERROR_KINDS"]

#: Error kinds counted by :class:`Ping1dStreamDecoder` (see the module docstring).
ERROR_KINDS = ("garbage_bytes", "truncated", "bad_checksum", "unknown_message", "malformed")


@dataclass(frozen=True)
class Ping1dStreamError:
    """One rejected item: ``kind`` (one of :data:`ERROR_KINDS`), ``offset`` (stream byte offset where it
    starts), ``count`` (bytes for ``garbage_bytes``, frames otherwise) and a one-line ``reason``."""

    kind: str
    offset: int
    count: int
    reason: str


@dataclass(frozen=True)
class Ping1dDecoded:
    """A valid frame: the raw :class:`~hindrax_drivers.ping1d.protocol.Ping1dMessage`, its typed payload
    and the stream offset of its first byte."""

    message: Ping1dMessage
    payload: Ping1dPayload
    offset: int


class Ping1dStreamDecoder:
    """Incremental Ping1D decoder: ``feed(bytes) -> [Ping1dDecoded]`` with classified error counters.

    Args:
        max_payload_bytes: longest accepted payload (framer limit; a 200-point profile is 226 bytes).
        keep_errors: keep every :class:`Ping1dStreamError` in :attr:`errors` (offline decoding).
    Attributes:
        counts: error kind -> total (all keys of :data:`ERROR_KINDS` present).
        messages: payload type name -> number decoded.
        errors: list of errors (only with ``keep_errors``); last_error: the most recent one or None."""

    def __init__(self, max_payload_bytes: int = 1024, keep_errors: bool = False) -> None:
        self._framer = Ping1dFramer(max_payload_bytes)
        self.max_payload_bytes = int(max_payload_bytes)
        self._max_frame = HEADER_BYTES + self.max_payload_bytes + CHECKSUM_BYTES
        self._window = bytearray()
        self._window_offset = 0  # stream offset of _window[0]
        self._keep = bool(keep_errors)
        self.counts: Dict[str, int] = {k: 0 for k in ERROR_KINDS}
        self.messages: Dict[str, int] = collections.Counter()
        self.errors: List[Ping1dStreamError] = []
        self.last_error: Optional[Ping1dStreamError] = None

    def _error(self, kind: str, offset: int, count: int, reason: str) -> None:
        self.counts[kind] += count
        err = Ping1dStreamError(kind, offset, count, reason)
        self.last_error = err
        if self._keep:
            self.errors.append(err)

    def _classify_gap(self, gap: bytes, offset: int, stop: Optional[int] = None) -> int:
        """Classify bytes that are not part of any good frame; return how many were consumed.

        A ``BR`` header with a plausible length is a *complete* frame (so its checksum failed) when no other plausible
        header starts inside its claimed span and its claimed end is the end of the gap or the start of another complete
        frame ("chain-consistent"); otherwise it was cut short (truncated) by the next plausible header inside its
        claimed span, or by the end of the gap (where a good frame starts, or the stream stopped). Without ``stop`` the
        whole gap is classified; with ``stop`` only headers starting before ``stop`` (each consumed with its claimed
        frame, which the caller guarantees lies inside ``gap``); the return value is then >= ``stop``."""
        n = len(gap)
        limit = n if stop is None else min(stop, n)
        starts: List[int] = []  # header candidates with a plausible length (or cut before the length)
        totals: Dict[int, int] = {}
        k = gap.find(b"BR")
        while k >= 0:
            if k + 4 > n:
                starts.append(k)
                totals[k] = -1  # header cut before its length field
            else:
                length = gap[k + 2] | (gap[k + 3] << 8)
                if length <= self.max_payload_bytes:
                    starts.append(k)
                    totals[k] = HEADER_BYTES + length + CHECKSUM_BYTES
            k = gap.find(b"BR", k + 1)
        complete: Dict[int, bool] = {}
        for pos, k in reversed(list(enumerate(starts))):
            end = k + totals[k]
            inner = pos + 1 < len(starts) and starts[pos + 1] < end
            complete[k] = totals[k] > 0 and not inner and (end == n or (end < n and complete.get(end, False)))

        def garbage(a: int, b: int) -> None:
            if b > a:
                self._error("garbage_bytes", offset + a, b - a, f"{b - a} byte(s) outside any frame")

        i = idx = 0
        while i < limit:
            idx = bisect.bisect_left(starts, i, idx)
            j = starts[idx] if idx < len(starts) else n
            if j >= limit:
                garbage(i, limit)
                i = limit
                break
            garbage(i, j)
            total = totals[j]
            name = f"id {gap[j + 4] | (gap[j + 5] << 8)}" if j + 6 <= n else "of unknown id"
            inner = starts[idx + 1] if idx + 1 < len(starts) and starts[idx + 1] < min(j + total, n) else None
            if total < 0:  # only possible at the very end
                self._error("truncated", offset + j, 1, f"frame cut after {n - j} byte(s) of its header")
                i = n
            elif complete[j]:
                self._error("bad_checksum", offset + j, 1, f"frame {name} ({total} bytes): checksum mismatch")
                i = j + total
            elif inner is not None:
                self._error("truncated", offset + j, 1, f"frame {name} claims {total} bytes, cut after {inner - j}")
                i = inner
            elif j + total > n:
                self._error("truncated", offset + j, 1, f"frame {name} claims {total} bytes, cut after {n - j}")
                i = n
            else:  # whole frame present, followed by noise: its checksum failed
                self._error("bad_checksum", offset + j, 1, f"frame {name} ({total} bytes): checksum mismatch")
                i = j + total
        return i

    def feed(self, data: Union[bytes, bytearray]) -> List[Ping1dDecoded]:
        """Decode a chunk; return the valid frames it completes, in stream order."""
        data = bytes(data)
        self._window += data
        out: List[Ping1dDecoded] = []
        for message in self._framer.feed(data):
            frame = message.encode()
            idx = self._window.find(frame)
            if idx < 0:  # cannot happen with a consistent framer; never lose the message
                idx = 0
                frame_len = 0
            else:
                frame_len = len(frame)
            if idx:
                self._classify_gap(bytes(self._window[:idx]), self._window_offset)
            start = self._window_offset + idx
            del self._window[: idx + frame_len]
            self._window_offset += idx + frame_len
            try:
                payload = decode_message(message)
            except Ping1dParseError as exc:
                kind = "malformed" if message.message_id in PAYLOAD_TYPES else "unknown_message"
                self._error(kind, start, 1, f"frame id {message.message_id}: {exc}")
                continue
            self.messages[type(payload).__name__] += 1
            out.append(Ping1dDecoded(message, payload, start))
        # A frame still pending in the framer starts within the last maximal frame of the window, and any
        # rejected header starting two maximal frames back has its whole claimed frame in the window:
        # classify those old bytes now, so that pure garbage is reported without waiting for a good frame.
        stop = len(self._window) - 2 * self._max_frame
        if stop > 0:
            used = self._classify_gap(bytes(self._window), self._window_offset, stop=stop)
            del self._window[:used]
            self._window_offset += used
        return out

    def finish(self) -> None:
        """End of stream or reconnect: classify the bytes still held (a partial frame is truncated)."""
        if self._window:
            self._classify_gap(bytes(self._window), self._window_offset)
            self._window_offset += len(self._window)
            self._window.clear()
        self._framer.reset()

    reset = finish  # after a reconnect the held bytes are the remains of the lost connection
