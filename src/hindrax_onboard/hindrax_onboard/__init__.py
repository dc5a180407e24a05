"""What runs on the vehicle above the drivers: estimation, vehicle, control, identification (docs/architecture.md)."""
