"""Thrust allocation: wrench to thruster forces and ESC pulse widths (docs/architecture.md §2)."""
