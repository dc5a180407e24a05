"""Samples lost between writers and a reader, from gaps in their publication sequence numbers.

A DDS writer numbers its samples 1, 2, 3, ... (DDS 1.4 §8.3.5.4 ``SequenceNumber_t``, RTPS 2.5 §8.2.2; the rmw message
info's ``publication_sequence_number``, rmw ``rmw_message_info_t``, rclpy's callback ``MessageInfo`` dict) and a reader
gets each writer's samples in that order, each at most once. A sample that never reaches the reader (a best-effort
reader's full socket buffer, a keep-last history overwritten before the take) leaves a gap: the next sample's number
exceeds the last one's by more than 1. Pure: no ROS."""
from __future__ import annotations

from collections.abc import Callable, Hashable

#: ``RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED`` (UINT64_MAX): an rmw that numbers no samples
SEQUENCE_NUMBER_UNSUPPORTED = 2**64 - 1


class SequenceGaps:
    """Counts the samples each writer lost on the way to one reader, from gaps in its numbering.

    ``writer``: any hashable key naming one writer (rmw_fastrtps_cpp's message info carries no
    publisher gid here: the recorder keys by topic, see ``writer_count``). ``writer_count(writer)``:
    how many writers publish under that key, asked only when a gap shows: a gap is counted only when
    it is 1, since several writers' interleaved numbers make gaps that are no loss (default: 1).

    Rules per writer: the first sample sets the baseline (a reader that joins late does not count what came before it);
    a number 1 above the last is in order; more than 1 above, the difference less 1 is lost; the same number again is a
    duplicate (not counted); a smaller number is a new incarnation of the writer (a restarted process numbers from
    1 again; one writer's samples never arrive out of order), a new baseline, no loss."""

    __slots__ = ("_last", "_lost", "_writer_count")

    def __init__(self, writer_count: Callable[[Hashable], int] = lambda writer: 1) -> None:
        self._last: dict[Hashable, int] = {}
        self._lost: dict[Hashable, int] = {}
        self._writer_count = writer_count

    def observe(self, writer: Hashable, seq: int) -> int:
        """Take one received sample's sequence number ``seq`` (int, >= 1) from ``writer``; returns the samples lost just
        before it (0 unless a gap shows). A number the rmw does not give (None, not an int, or
        :data:`SEQUENCE_NUMBER_UNSUPPORTED`) counts nothing and raises nothing."""
        if not isinstance(seq, int) or seq == SEQUENCE_NUMBER_UNSUPPORTED:
            return 0
        last = self._last.get(writer)
        self._last[writer] = seq
        if last is None or seq <= last + 1 or self._writer_count(writer) != 1:
            return 0
        gap = seq - last - 1
        self._lost[writer] = self._lost.get(writer, 0) + gap
        return gap

    @property
    def lost(self) -> int:
        """Samples lost, all writers together."""
        return sum(self._lost.values())

    def lost_by_writer(self) -> dict[Hashable, int]:
        """{writer: samples lost}, writers that lost some only."""
        return dict(self._lost)
