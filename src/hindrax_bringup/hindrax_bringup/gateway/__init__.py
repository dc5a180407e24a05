"""The gateway: the vehicle's one process on the topside graph (docs/architecture.md §8.2)."""
