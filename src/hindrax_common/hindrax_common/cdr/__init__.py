"""CDR bytes without rclpy objects, and the message definitions they are read with."""
