"""Hindrax identification, simulation, control and the ``hindrax`` command line (docs/architecture.md §2)."""
