"""Accelerometer calibration: the sensor model, static detection, the ellipsoid fit."""
