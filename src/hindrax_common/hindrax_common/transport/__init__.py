"""Byte and register transports (serial, I2C, emulated buses) shared by the device drivers."""
