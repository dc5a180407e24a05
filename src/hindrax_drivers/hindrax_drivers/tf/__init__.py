"""Static TF of the vehicle: ``base_link`` to every sensor and thruster frame, from the vehicle file."""
