"""Pure helpers every room stands on: frames, the PWM limits, the thrust curve, device clocks, the device table."""
