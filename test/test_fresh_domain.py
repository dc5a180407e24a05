"""The tests' fresh ROS domains (``hindrax_test_support.helpers.fresh_domain``): never the one the
worker's last test just left, never one another process holds."""
from __future__ import annotations

from domain_coordinator import domain_id

from hindrax_test_support.helpers import FRESH_DOMAINS, fresh_domain


def test_a_fresh_domain_is_not_the_one_just_left_nor_a_held_one():
    with fresh_domain() as first:
        pass
    with fresh_domain() as second:
        assert second != first
        # the next one skips a domain held meanwhile (by this block, or another process's port lock)
        i = FRESH_DOMAINS.index(second) + 1
        after = list(FRESH_DOMAINS[i:]) + list(FRESH_DOMAINS[:i])
        with domain_id(iter(after).__next__) as held:
            with fresh_domain() as third:
                assert third not in (first, second, held) and third in FRESH_DOMAINS
