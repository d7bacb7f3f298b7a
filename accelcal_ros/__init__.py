"""
accelcal_ros: ADXL345 field calibration, attitude and the applications built on it.

Layout: every feature is a subpackage holding a pure core (numpy/scipy/OpenCV, never
rclpy) and, beside it, a thin ROS 2 node module (``node.py`` or ``*_node.py``) that only
does parameters, QoS, message conversion and wiring. Shared pieces:

- :mod:`accelcal_ros.sensor`   -- sensor facts below every feature: the accelerometer model,
  ADXL345 datasheet, recording and calibration file formats, standard gravity, stillness.
- :mod:`accelcal_ros.errors`   -- the exception hierarchy every module raises.
- :mod:`accelcal_ros.frames`   -- frame and sign conventions (REP-103/145, paper A).
- :mod:`accelcal_ros.fileio`   -- atomic file writing, YAML/CSV reading with line numbers.
- :mod:`accelcal_ros.paramspec` -- parameter specifications and validation (pure).
- :mod:`accelcal_ros.rosutil`  -- the small ROS helpers (parameters, images, clouds).
"""

__version__ = '0.1.0'
