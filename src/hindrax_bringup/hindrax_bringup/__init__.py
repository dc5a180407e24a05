"""Hindrax device drivers, thrust allocation, safety and recording (docs/architecture.md §2)."""
