"""
Sensor facts below every feature (pure core, no rclpy).

- :mod:`.units`            -- standard gravity and g <-> m/s^2 conversions (the one constant).
- :mod:`.model`            -- the accelerometer error model (identity default) and paper A's
  Table-1 values.
- :mod:`.datasheet`        -- ADXL345 datasheet facts (LSB size, output data rates, noise).
- :mod:`.recording`        -- the ``t,ax,ay,az`` recording CSV.
- :mod:`.calibration_file` -- the calibration YAML the calibration writes and others read.
- :mod:`.stillness`        -- the one stillness detector (streaming and offline).

Features (driver, calibration, attitude, lidar, p2p, panorama) import from here, never
from each other, for a shared fact.
"""
