"""hindrax run keeps its graph to itself: without ROS_DOMAIN_ID it reserves a domain that no other run holds."""
from __future__ import annotations

from hindrax_sim.graph.graph_campaign import run_domain


def test_two_runs_get_different_reserved_domains_and_say_which(monkeypatch):
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    said: list[str] = []
    with run_domain(said.append) as first, run_domain(said.append) as second:
        assert 1 <= first <= 100 and 1 <= second <= 100 and first != second
    assert said == [f"ROS domain {first} (reserved for this run; set ROS_DOMAIN_ID to choose one)",
                    f"ROS domain {second} (reserved for this run; set ROS_DOMAIN_ID to choose one)"]


def test_an_explicit_domain_is_used_as_it_is(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    said: list[str] = []
    with run_domain(said.append) as did:
        assert did == 42
    assert said == []
