"""TDK ICM-20948 IMU driver: protocol, emulator and node (docs/devices.md §4)."""
