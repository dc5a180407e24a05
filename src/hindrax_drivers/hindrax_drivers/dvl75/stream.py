"""DVL-75 byte stream -> typed records, with every rejected byte and line classified (pure, no I/O).

The one decoding path of the DVL driver: the ROS node (:mod:`hindrax_drivers.dvl75.node`) and
``hindrax decode dvl75`` both use :class:`DvlStreamDecoder`, which wraps the protocol layer's
:class:`~hindrax_drivers.dvl75.protocol.DvlLineFramer` and :func:`~hindrax_drivers.dvl75.protocol.parse_line`
(docs/devices.md §1.2-§1.3) and adds the accounting a driver reports in its diagnostics.

Error kinds (keys of :attr:`DvlStreamDecoder.counts`):

- ``garbage_bytes``: bytes the framer discarded while resynchronising: line noise before a ``$``,
  non-printable lines, over-long lines, and the remains of truncated sentences.
- ``truncated``: sentences cut short: a ``$`` whose sentence never reached its line end because another
  sentence started first (the framer keeps only the last ``$`` of a line), a partial line dropped at a
  reconnect, or a ``$`` data sentence ending without its ``*hh`` checksum.
- ``bad_checksum``: complete ``$...*hh`` sentences whose checksum does not verify (docs/devices.md §1.2:
  XOR of the bytes between ``$`` and ``*``).
- ``malformed``: sentences with a valid checksum whose fields do not parse (wrong count, bad number).
- ``unknown_sentence``: well-formed lines of a type the driver does not use (``$DVNVM``, ``IMU:``,
  ``GPS:$...``, ``$DVKFA``...; returned as :class:`~hindrax_drivers.dvl75.protocol.DvlUnknown`).

Counting truncated sentences without access to the framer's internals: every DVL sentence starts with
exactly one ``$`` (``$DVTXT`` free text and ``GPS:$`` re-tweets are kept whole by the framer), so the
``$`` bytes of the completed lines that do not reappear in the lines the framer returns belong to
sentences that were cut short. The count is exact for any chunking of the stream."""
from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Dict, List, Optional, Union

from .protocol import DvlLineFramer, DvlParseError, DvlRecord, DvlUnknown, nmea_checksum, parse_line

__all__ = ["DvlStreamDecoder", "DvlStreamError", "ERROR_KINDS", "classify_line_error"]

#: Error kinds counted by :class:`DvlStreamDecoder` (see the module docstring).
ERROR_KINDS = ("garbage_bytes", "truncated", "bad_checksum", "malformed", "unknown_sentence")
_HEX = b"0123456789abcdefABCDEF"


@dataclass(frozen=True)
class DvlStreamError:
    """One rejected item of the stream.

    Attributes:
        kind: one of :data:`ERROR_KINDS`.
        line: 1-based number of the line (LF-terminated segment of the stream) where it was detected;
            exact when the stream is fed line by line, else the last line completed by that chunk.
        count: how many (bytes for ``garbage_bytes``, sentences otherwise).
        reason: one-line human-readable reason."""

    kind: str
    line: int
    count: int
    reason: str


def classify_line_error(line: bytes) -> str:
    """Error kind of a complete line (no CR/LF) that :func:`parse_line` rejected.

    ``$...*hh`` with a wrong checksum -> ``bad_checksum``; ``$...*hh`` with a right one -> ``malformed``
    (its fields are wrong); ``$...`` without checksum -> ``truncated`` (only data sentences require one,
    so the end was lost); anything else -> ``malformed``."""
    raw = bytes(line).rstrip(b"\r\n")
    if raw.startswith(b"$"):
        if len(raw) >= 4 and raw[-3:-2] == b"*" and raw[-2] in _HEX and raw[-1] in _HEX:
            return "bad_checksum" if nmea_checksum(raw[1:-3]) != int(raw[-2:], 16) else "malformed"
        return "truncated"
    return "malformed"


class DvlStreamDecoder:
    """Incremental DVL decoder: ``feed(bytes) -> [records]`` with classified error counters.

    Args:
        max_line_bytes: longest accepted line (the framer's limit; a ``$DVEXT`` is about 250 bytes).
        keep_errors: keep every :class:`DvlStreamError` in :attr:`errors` (for offline decoding); a node
            leaves it False and reads :attr:`counts` and :attr:`last_error`.
    Attributes:
        counts: error kind -> total (keys :data:`ERROR_KINDS`, all present).
        records: record type name -> number decoded.
        lines_seen: LF-terminated segments completed so far.
        errors: list of :class:`DvlStreamError` (only with ``keep_errors``).
        last_error: the most recent :class:`DvlStreamError` or None."""

    def __init__(self, max_line_bytes: int = 1024, keep_errors: bool = False) -> None:
        self._framer = DvlLineFramer(max_line_bytes)
        self._pending_dollars = 0
        self._keep = bool(keep_errors)
        self.counts: Dict[str, int] = {k: 0 for k in ERROR_KINDS}
        self.records: Dict[str, int] = collections.Counter()
        self.lines_seen = 0
        self.errors: List[DvlStreamError] = []
        self.last_error: Optional[DvlStreamError] = None

    def _error(self, kind: str, count: int, reason: str) -> None:
        if count <= 0:
            return
        self.counts[kind] += count
        err = DvlStreamError(kind, self.lines_seen, count, reason)
        self.last_error = err
        if self._keep:
            self.errors.append(err)

    def feed(self, data: Union[bytes, bytearray]) -> List[DvlRecord]:
        """Decode a chunk; return the records of the lines it completes, in stream order."""
        data = bytes(data)
        last_lf = data.rfind(b"\n")
        if last_lf < 0:
            self._pending_dollars += data.count(b"$")
            completed_dollars = 0
        else:
            completed_dollars = self._pending_dollars + data.count(b"$", 0, last_lf + 1)
            self._pending_dollars = data.count(b"$", last_lf + 1)
            self.lines_seen += data.count(b"\n")
        discarded_before = self._framer.discarded_bytes
        lines = self._framer.feed(data)
        lost_dollars = completed_dollars - sum(line.count(b"$") for line in lines)
        self._error("truncated", lost_dollars, f"{lost_dollars} sentence(s) cut short by the next '$'")
        discarded = self._framer.discarded_bytes - discarded_before
        self._error("garbage_bytes", discarded, f"{discarded} byte(s) discarded while resynchronising")
        out: List[DvlRecord] = []
        for line in lines:
            try:
                record = parse_line(line)
            except DvlParseError as exc:
                self._error(classify_line_error(line), 1, str(exc))
                continue
            if isinstance(record, DvlUnknown):
                self._error("unknown_sentence", 1, f"unused sentence {record.sentence_id!r}")
            self.records[type(record).__name__] += 1
            out.append(record)
        return out

    def reset(self) -> None:
        """Drop a partial line (after a reconnect): a started sentence counts as truncated, other bytes as garbage."""
        discarded_before = self._framer.discarded_bytes
        self._framer.reset()
        discarded = self._framer.discarded_bytes - discarded_before
        self._error("truncated", self._pending_dollars, "partial sentence dropped at reconnect")
        self._error("garbage_bytes", discarded, f"{discarded} byte(s) of a partial line dropped")
        self._pending_dollars = 0
