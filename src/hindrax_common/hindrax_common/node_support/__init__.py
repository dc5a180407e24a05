"""What every driver node shares: the base node, diagnostics, heartbeats, the I2C and serial node bases."""
