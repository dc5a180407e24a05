"""The pool day's churn rows (hindrax_tools.benchmarks.participant_churn.pool_day_rows)
listen where they claim and measure each heartbeat: the topside subscriber's topics are ones the
gateway publishes, with their types; the internal one's are /diagnostics and the three heartbeats;
the gap of each heartbeat is its own, and a silent one is infinite."""
from __future__ import annotations

import pytest
from hindrax_bringup.gateway.interface import INTERFACE
from hindrax_common.node_support.liveness import HEARTBEAT_NAMES

from hindrax_tools.benchmarks.participant_churn import (INTERNAL_TOPICS, _Watch,
                                                        subscriber_argv, topside_topics)


def _spec(topic_spec: str) -> tuple[str, str]:
    """``module:Type=topic`` -> (``pkg/msg/Type``, topic)."""
    kind, topic = topic_spec.split("=", 1)
    module, name = kind.split(":")
    return f"{module.split('.')[0]}/msg/{name}", topic


def test_the_topside_subscriber_listens_to_what_the_gateway_publishes_there():
    published = {f"/alpha/{r.topside}": r.type for r in INTERFACE if r.kind == "topic_out"}
    specs = [_spec(s) for s in topside_topics("alpha")]
    assert specs and all(published.get(topic) == kind for kind, topic in specs), (specs, published)


def test_the_internal_subscriber_listens_to_diagnostics_and_every_heartbeat():
    topics = {topic for _kind, topic in map(_spec, INTERNAL_TOPICS)}
    assert topics == {"/diagnostics", *HEARTBEAT_NAMES.values()}
    argv = subscriber_argv("x", 1.0)
    assert argv[3:5] == ["x", "1"] and argv[5:] == list(INTERNAL_TOPICS)


class _Node:
    def create_subscription(self, *_args, **_kwargs):
        return None


def test_each_heartbeat_has_its_own_largest_gap_and_a_silent_one_is_infinite():
    watch = _Watch(_Node())
    watch.arrivals = {"supervisor": [0.0, 0.05, 0.10], "guard": [0.0, 0.12, 0.15], "esc": [0.0, 0.04, 0.08]}
    assert watch.gaps_s() == pytest.approx({"supervisor": 0.05, "guard": 0.12, "esc": 0.04})
    watch.arrivals["esc"] = [0.0]
    assert watch.gaps_s()["esc"] == float("inf")
    assert watch.rows("x_", "", 100.0)[1]["value"] == float("inf")
