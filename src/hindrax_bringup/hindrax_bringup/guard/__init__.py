"""The ESC output guard: PCA9685 /OE line held by a heartbeat (docs/architecture.md §8)."""
