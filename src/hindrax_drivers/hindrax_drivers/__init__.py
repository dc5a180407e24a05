"""Hindrax device drivers: DVL-75, Ping1D, MS5837, ICM-20948, PCA9685 ESC, static TF (docs/architecture.md §2)."""
