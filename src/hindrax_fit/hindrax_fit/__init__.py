"""Topside identification from bags (docs/architecture.md §2): :mod:`.fit` < :mod:`.bag_input` < :mod:`.assessment`."""
