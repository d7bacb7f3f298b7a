"""
Parameters of the ``attitude`` node (pure specifications, checked without ROS).

The estimator settings' defaults are those of
:class:`~accelcal_ros.sensor.tilt.TiltEstimator` (one source: read from its signature).
"""
import inspect

from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.model import MODELS
from accelcal_ros.sensor.tilt import TiltEstimator

_ESTIMATOR = {name: p.default
              for name, p in inspect.signature(TiltEstimator.__init__).parameters.items()}

CALIBRATION_KEYS = ('calibration.model', 'calibration.scale', 'calibration.bias',
                    'calibration.misalignment', 'calibration.tilt_std_deg')

ATTITUDE_PARAMS = (
    ParamSpec('calibration_file', '', 'Calibration YAML to load (written by the calibration '
              'node or accelcal calibrate). Setting it at run time loads the file; a bad '
              'file is rejected and the last good calibration kept. Empty: use the '
              'calibration.* values.'),
    ParamSpec('calibration.model', 'full', 'Model of the calibration.* values.',
              choices=MODELS),
    ParamSpec('calibration.scale', [1.0, 1.0, 1.0], 'Scale factors k (f = T diag(1/k) '
              '(a - b)).', lengths=(3,), minimum=0.1, maximum=10.0),
    ParamSpec('calibration.bias', [0.0, 0.0, 0.0], 'Biases b.', lengths=(3,), minimum=-2.0,
              maximum=2.0, unit='g'),
    ParamSpec('calibration.misalignment', [0.0, 0.0, 0.0], 'Misalignment [m_yz, m_zy, m_zx] '
              '(full model; must be 0 for diagonal).', lengths=(3,), minimum=-0.2,
              maximum=0.2, unit='rad'),
    ParamSpec('calibration.tilt_std_deg', 0.0, 'Standard deviation of roll and pitch due to '
              'the calibration itself (added to the noise in the covariance).', minimum=0.0,
              maximum=90.0, unit='deg'),
    ParamSpec('time_constant_s', _ESTIMATOR['time_constant_s'], 'Low-pass time constant on '
              'the specific force (0: none).', minimum=0.0, maximum=60.0, unit='s'),
    ParamSpec('accel_threshold_g', _ESTIMATOR['accel_threshold_g'], 'When | |f| - 1 g | '
              'exceeds this the sensor is accelerating: the last good tilt is held and the '
              'covariance inflated.', minimum=0.001, maximum=1.0, unit='g'),
    ParamSpec('max_hold_s', _ESTIMATOR['max_hold_s'], 'Longest hold of the last good tilt '
              'while accelerating; a magnitude that stays off 1 g longer is a calibration '
              'problem, and the measured tilt is published (flagged) again.', minimum=0.0,
              maximum=3600.0, unit='s'),
    ParamSpec('noise_std_g', [], 'Raw noise std per axis (empty: ADXL345 datasheet at the '
              'measured sample rate).', kind='double_array', lengths=(0, 3), minimum=0.0,
              maximum=1.0, unit='g'),
    ParamSpec('yaw_variance', 1.0e6, 'Yaw variance reported in imu/data (yaw is not '
              'observable from an accelerometer).', minimum=0.0, unit='rad^2'),
)
