"""Attitude: the node that publishes calibrated roll and pitch (math in sensor.tilt)."""
