"""ADXL345 sources: the I2C driver, the simulated sensor and CSV replay, and their node."""
