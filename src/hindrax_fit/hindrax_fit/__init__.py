"""Topside identification from recorded bags (docs/architecture.md §2): rooms, lowest first, :mod:`.fit` <
:mod:`.bag_input` < :mod:`.assessment`; below them the shared per-DOF model, :mod:`hindrax_onboard.identification`."""
