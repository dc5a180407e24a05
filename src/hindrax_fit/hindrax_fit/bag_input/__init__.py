"""What a campaign recorded and how it is read back: message adapters, calibration topic, record, bag reader."""
