"""Parameters of the ``calibration`` node (pure specifications, checked without ROS)."""
import os

from accelcal_ros.calibration.session import CalibratorConfig
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.model import MODELS


def _non_empty(value):
    return None if value.strip() else 'must not be empty'


DEFAULT_OUTPUT_FILE = os.path.join('~', '.ros', 'accelcal', 'calibration.yaml')

CALIBRATION_PARAMS = (
    ParamSpec('model', 'full', 'Calibration model: full (scale, bias and three misalignment '
              'angles, imu_tk; meets 0.1 deg on real ADXL345 data) or diagonal (paper A, '
              'scale and bias only).', choices=MODELS),
    ParamSpec('auto_capture', True, 'Capture every new still dwell automatically.'),
    ParamSpec('min_separation_deg', 20.0, 'A still dwell is a new position only if its '
              'direction is more than this from every captured one.', minimum=0.0,
              maximum=90.0, unit='deg'),
    ParamSpec('still_window_s', 0.3, 'Window of the moving-variance still detector.',
              minimum=0.05, maximum=10.0, unit='s'),
    ParamSpec('still_threshold_g', 0.01, 'The sensor is still while the std of its 20 ms '
              'block means over the window is below this on every axis.', minimum=1e-4,
              maximum=1.0, unit='g'),
    ParamSpec('min_still_s', 1.0, 'Minimum still time before a position is captured '
              '(averaging longer lowers the noise; 1 s reaches 0.1 deg).', minimum=0.1,
              maximum=600.0, unit='s'),
    ParamSpec('saturation_g', 1.9, 'Samples with any axis at or beyond this are rejected '
              '(saturated or shaken: a still reading is about 1 g).', minimum=1.0,
              maximum=16.0, unit='g'),
    ParamSpec('min_positions', 0, 'Positions required by finish (0: the parameter count of '
              'the model + 1, i.e. 10 for full, 7 for diagonal).', minimum=0, maximum=10000),
    ParamSpec('outlier_threshold', 6.0, 'A position whose studentized residual exceeds this '
              '(in noise standard deviations) is dropped with a warning.', minimum=2.0,
              maximum=1000.0),
    ParamSpec('coverage_radius_deg', 40.0, 'Sphere coverage counts orientations within this '
              'of a captured one.', minimum=5.0, maximum=90.0, unit='deg'),
    ParamSpec('output_file', DEFAULT_OUTPUT_FILE, 'Calibration YAML written by finish '
              '(atomically; the previous file is kept as .bak). ~ is expanded.',
              validator=_non_empty),
    ParamSpec('attitude_node', 'attitude', 'Node whose calibration.* parameters finish sets '
              'through its set_parameters service (empty: do not apply).'),
    ParamSpec('status_period_s', 1.0, 'Period of calibration/status while a session runs '
              '(it is also published after every capture).', minimum=0.05, maximum=60.0,
              unit='s'),
)


def calibrator_config(values):
    """Return the :class:`CalibratorConfig` of validated parameter ``values``."""
    return CalibratorConfig(
        model=values['model'], auto_capture=values['auto_capture'],
        min_separation_deg=values['min_separation_deg'], window_s=values['still_window_s'],
        still_threshold_g=values['still_threshold_g'], min_still_s=values['min_still_s'],
        saturation_g=values['saturation_g'],
        coverage_radius_deg=values['coverage_radius_deg'],
        min_positions=values['min_positions'],
        outlier_threshold=values['outlier_threshold'])
