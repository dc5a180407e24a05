"""The safety supervisor: core rules and node (docs/architecture.md §8)."""
