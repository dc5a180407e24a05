"""NXP PCA9685 PWM driver for the eight ESCs and the lights: protocol, emulator and node (docs/devices.md §5)."""
