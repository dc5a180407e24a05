"""Pure estimation cores: least squares, RLS, filters, free decay, priors and thruster fits (no rclpy)."""
