"""Cerulean Sonar DVL-75 driver: protocol, emulator and node (docs/devices.md §1)."""
