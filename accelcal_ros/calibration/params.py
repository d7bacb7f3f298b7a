"""
Parameters of the ``calibration`` node (pure specifications, checked without ROS).

The session settings' defaults are those of :class:`CalibratorConfig` (one source):
:data:`CONFIG_FIELDS` names the config field of each such parameter.
"""
from typing import Any, Mapping

from accelcal_ros.calibration.session import CalibratorConfig
from accelcal_ros.outputs import default_output, output_validator
from accelcal_ros.paramspec import ParamSpec
from accelcal_ros.sensor.model import MODELS
from accelcal_ros.session_interface import status_period_spec


DEFAULT_OUTPUT_FILE = default_output('calibration.yaml')

CONFIG_FIELDS = {
    'model': 'model', 'auto_capture': 'auto_capture', 'min_separation_deg': 'min_separation_deg',
    'still_window_s': 'window_s', 'still_threshold_g': 'still_threshold_g',
    'min_still_s': 'min_still_s', 'saturation_g': 'saturation_g',
    'min_positions': 'min_positions', 'outlier_threshold': 'outlier_threshold',
    'coverage_radius_deg': 'coverage_radius_deg',
}
"""Parameter name -> :class:`CalibratorConfig` field."""

_CONFIG = CalibratorConfig()


def _session(name, description, **kwargs):
    """Return the spec of a session setting (default from :class:`CalibratorConfig`)."""
    return ParamSpec(name, getattr(_CONFIG, CONFIG_FIELDS[name]), description, **kwargs)


CALIBRATION_PARAMS = (
    _session('model', 'Calibration model: full (scale, bias and three misalignment '
             'angles, imu_tk; meets 0.1 deg on real ADXL345 data) or diagonal (paper A, '
             'scale and bias only).', choices=MODELS),
    _session('auto_capture', 'Capture every new still dwell automatically.'),
    _session('min_separation_deg', 'A still dwell is a new position only if its '
             'direction is more than this from every captured one.', minimum=0.0,
             maximum=90.0, unit='deg'),
    _session('still_window_s', 'Window of the moving-variance still detector.',
             minimum=0.05, maximum=10.0, unit='s'),
    _session('still_threshold_g', 'The sensor is still while the std of its 20 ms '
             'block means over the window is below this on every axis.', minimum=1e-4,
             maximum=1.0, unit='g'),
    _session('min_still_s', 'Minimum still time before a position is captured '
             '(averaging longer lowers the noise; 1 s reaches 0.1 deg).', minimum=0.1,
             maximum=600.0, unit='s'),
    _session('saturation_g', 'Samples with any axis at or beyond this are rejected '
             '(saturated or shaken: a still reading is about 1 g).', minimum=1.0,
             maximum=16.0, unit='g'),
    _session('min_positions', 'Positions required by finish (0: the parameter count of '
             'the model + 1, i.e. 10 for full, 7 for diagonal).', minimum=0, maximum=10000),
    _session('outlier_threshold', 'A position whose studentized residual exceeds this '
             '(in noise standard deviations) is dropped with a warning.', minimum=2.0,
             maximum=1000.0),
    _session('coverage_radius_deg', 'Sphere coverage counts orientations within this '
             'of a captured one.', minimum=5.0, maximum=90.0, unit='deg'),
    ParamSpec('output_file', DEFAULT_OUTPUT_FILE, 'Calibration YAML written by finish '
              '(atomically; the previous file is kept as .bak). ~ is expanded.',
              validator=output_validator(('.yaml', '.yml'))),
    ParamSpec('attitude_node', 'attitude', 'Node whose calibration.* parameters finish sets '
              'through its set_parameters service (empty: do not apply).'),
    status_period_spec('calibration'),
)


def calibrator_config(values: Mapping[str, Any]) -> CalibratorConfig:
    """Return the :class:`CalibratorConfig` of validated parameter ``values``."""
    return CalibratorConfig(**{field: values[name] for name, field in CONFIG_FIELDS.items()})
