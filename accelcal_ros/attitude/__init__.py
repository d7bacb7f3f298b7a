"""Attitude: calibrated roll and pitch from the accelerometer (tilt estimator and node)."""
