"""
Parameters of the ``attitude`` node (pure specifications, checked without ROS).

The estimator settings' defaults are those of
:class:`~accelcal_ros.sensor.tilt.TiltEstimator` (one source: read from its signature)
and of :class:`~accelcal_ros.sensor.tilt_filter.FilterSettings` (the adaptive, gyro- and
odometry-aided filter).
"""
import inspect

from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.model import MODELS
from accelcal_ros.sensor.tilt import TiltEstimator
from accelcal_ros.sensor.tilt_filter import FilterSettings

_ESTIMATOR = {name: p.default
              for name, p in inspect.signature(TiltEstimator.__init__).parameters.items()}

_FILTER = FilterSettings()


def _rotation_reason(values):
    if len(values) == 9:
        import numpy as np

        matrix = np.array(values, dtype=float).reshape(3, 3)
        if not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-3) \
                or abs(np.linalg.det(matrix) - 1.0) > 1e-3:
            return 'must be a rotation matrix (orthonormal, determinant +1), row-major'
    return None


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
    ParamSpec('time_constant_s', _ESTIMATOR['time_constant_s'], 'Fixed low-pass time constant '
              'on the specific force, accelerometer only (0, the default: the adaptive filter '
              'of still_time_constant_s / moving_time_constant_s, with the gyro and odometry '
              'aids when present).', minimum=0.0, maximum=60.0, unit='s'),
    ParamSpec('still_time_constant_s', _FILTER.still_time_constant_s, 'Longest averaging '
              'while the stillness detector says still (a line, then a double low-pass: no '
              'lag behind a slow creep; noise 0.015 deg at 2 s).',
              minimum=0.01, maximum=60.0, unit='s'),
    ParamSpec('moving_time_constant_s', _FILTER.moving_time_constant_s, 'Low-pass while '
              'moving (double low-pass: no lag behind a steady turn; about this lag while '
              'the turn rate changes).', minimum=0.001, maximum=10.0, unit='s'),
    ParamSpec('gyro_time_constant_s', _FILTER.gyro_time_constant_s, 'Gyro-aided: time '
              'constant of the pull towards the accelerometer.', minimum=0.05, maximum=600.0,
              unit='s'),
    ParamSpec('rejection_deg', _FILTER.rejection_deg, 'Gyro-aided: accelerometer ignored '
              'while it disagrees with the gyro by more (the platform accelerates).',
              minimum=0.1, maximum=90.0, unit='deg'),
    ParamSpec('rejection_timeout_s', _FILTER.rejection_timeout_s, 'Gyro-aided: longest time '
              'the accelerometer is ignored.', minimum=0.1, maximum=3600.0, unit='s'),
    ParamSpec('bias_time_constant_s', _FILTER.bias_time_constant_s, 'Gyro bias: memory of '
              'its line fit within one still period.', minimum=0.05, maximum=600.0, unit='s'),
    ParamSpec('gyro_noise_std_rad_s', _FILTER.gyro_noise_std_rad_s, 'Gyro noise per sample '
              '(ITG-3205: 0.38 deg/s).', minimum=0.0, maximum=1.0, unit='rad/s'),
    ParamSpec('platform_accel_g', _FILTER.platform_accel_g, 'Steady acceleration the '
              'platform may have (0: a rig that does not ride a vehicle). Accelerometer only '
              'and > 0: the covariance says the tilt may be off by atan(this) and '
              '/diagnostics warns.', minimum=0.0, maximum=1.0, unit='g'),
    ParamSpec('gyro_topic', '', 'Second sensor_msgs/Imu topic with angular velocity (empty: '
              'the angular velocity of imu/data_raw when its covariance[0] is not -1).',
              read_only=True),
    ParamSpec('gyro_rotation', [], "Rotation from the gyro topic's frame to the "
              "accelerometer's (9 values, row-major); empty: the frames must match.",
              kind='double_array', lengths=(0, 9), minimum=-1.0, maximum=1.0,
              validator=_rotation_reason),
    ParamSpec('odometry_topic', '', 'nav_msgs/Odometry of the vehicle (twist.linear.x, '
              'twist.angular.z): its acceleration is removed from the specific force. '
              'Empty: none.', read_only=True),
    ParamSpec('lever_arm_m', [0.0, 0.0, 0.0], "Position of the sensor from the vehicle's "
              "reference point (the odometry's; one that does not slip sideways, e.g. the rear "
              'axle centre), vehicle frame (x fwd, y left, z up). With a gyro, non-zero: the '
              "rotation's acceleration there is removed and turns leave pitch to the "
              'accelerometer; all zero: unknown.', lengths=(3,),
              minimum=-100.0, maximum=100.0, unit='m'),
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
