"""Blue Robotics Ping1D echosounder driver: protocol, emulator and node (docs/devices.md §2)."""
