"""SequenceGaps: samples lost per writer from gaps in publication sequence numbers (table tests)."""
from __future__ import annotations

import pytest

from hindrax_bringup.recording.sequence_gaps import SequenceGaps

# (name, [(writer, sequence number)], returned per sample, lost per writer at the end)
CASES = [
    ("in order", [("a", 1), ("a", 2), ("a", 3)], [0, 0, 0], {}),
    ("late join: the first sample is the baseline", [("a", 41), ("a", 42)], [0, 0], {}),
    ("gap", [("a", 1), ("a", 2), ("a", 5), ("a", 6), ("a", 8)], [0, 0, 2, 0, 1], {"a": 3}),
    ("duplicate", [("a", 1), ("a", 2), ("a", 2), ("a", 3)], [0, 0, 0, 0], {}),
    ("out of order: a step back is a new baseline", [("a", 1), ("a", 3), ("a", 2), ("a", 3)], [0, 1, 0, 0],
     {"a": 1}),
    ("two writers, each its own numbers", [("a", 1), ("b", 7), ("a", 2), ("b", 9), ("a", 3), ("b", 10)],
     [0, 0, 0, 1, 0, 0], {"b": 1}),
    ("writer restart: back to 1 is no loss", [("a", 1), ("a", 2), ("a", 900), ("a", 1), ("a", 2), ("a", 4)],
     [0, 0, 897, 0, 0, 1], {"a": 898}),
    ("an rmw without sequence numbers: None or UINT64_MAX count nothing",
     [("a", 1), ("a", None), ("a", 2), ("b", 5), ("b", 2**64 - 1), ("b", 6)], [0] * 6, {}),
]


@pytest.mark.parametrize("name, samples, returned, lost", CASES, ids=[c[0] for c in CASES])
def test_gaps(name, samples, returned, lost):
    gaps = SequenceGaps()
    assert [gaps.observe(w, s) for w, s in samples] == returned
    assert gaps.lost_by_writer() == lost
    assert gaps.lost == sum(lost.values())


def test_a_gap_counts_only_while_the_key_has_one_writer():
    writers = {"t": 2}
    gaps = SequenceGaps(lambda key: writers[key])
    # two writers on one key interleave their numbers: gaps and steps back, none a loss
    assert [gaps.observe("t", s) for s in (1, 1, 2, 5, 3, 6)] == [0] * 6
    asked = []
    writers["t"] = 1
    gaps = SequenceGaps(lambda key: asked.append(key) or writers[key])
    assert [gaps.observe("t", s) for s in (1, 2, 3, 6)] == [0, 0, 0, 2]
    assert asked == ["t"]  # asked on the gap only
    assert gaps.lost == 2
