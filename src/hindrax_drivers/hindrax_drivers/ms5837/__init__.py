"""TE MS5837 pressure sensor driver: protocol, emulator and node (docs/devices.md §3)."""
