"""
The calibration file: YAML, written atomically with the previous file kept as ``.bak``.

Keys (vectors in sensor axes x, y, z; readings in g, 1 g = 9.80665 m/s^2):

* ``format``: ``accelcal_ros/calibration 1``; ``model``: ``diagonal`` or ``full``;
* ``scale`` [3], ``bias`` [3] (g), ``misalignment`` [3] (rad: m_yz, m_zy, m_zx);
* ``scale_std``, ``bias_std``, ``misalignment_std`` [3] (one standard deviation);
* ``residual_rms_g``, ``holdout_rms_g``, ``positions``, ``dropped_positions``,
  ``condition_number``, ``predicted_tilt_error_deg`` (p95 roll/pitch);
* ``equation``: the correction written out, so the file can be applied without this
  package; ``captures_g`` (mean reading of each position) and ``residuals_g``;
* ``created``: UTC time.

:func:`load_sensor_model` reads it back as a
:class:`~accelcal_ros.sensor.model.SensorModel`; a missing, truncated or
wrong-shaped file raises :class:`~accelcal_ros.errors.FileFormatError`, and so does a
value outside its plausible range (:data:`PLAUSIBLE_RANGES`: a scale of 1e-300 or a
bias of 1e300 g is a broken file, not a calibration), naming the field.

The file is written by the calibration feature and read by attitude, the LiDAR
boresight and the offline commands, so its format lives here, below them.
"""
from dataclasses import dataclass
import datetime

from typing import Any, Optional

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import dump_yaml, load_yaml_mapping, write_text_atomic
from accelcal_ros.sensor.model import MODELS, SensorModel
import numpy as np

FORMAT = 'accelcal_ros/calibration 1'
EQUATION = (
    'f = T * diag(1/scale) * (a - bias), with a the raw reading and f the calibrated '
    'specific force, both in g (1 g = 9.80665 m/s^2) along the sensor axes x, y, z, and '
    'T = [[1, -m_yz, m_zy], [0, 1, -m_zx], [0, 0, 1]] with [m_yz, m_zy, m_zx] = '
    'misalignment (T = I for the diagonal model, i.e. f_i = (a_i - bias_i) / scale_i, '
    'paper A eq. 4). At rest |f| = 1; roll = atan2(f_y, f_z), '
    'pitch = atan2(-f_x, sqrt(f_y^2 + f_z^2)) (REP-103, +1 g on the axis pointing up).')


PLAUSIBLE_RANGES = {
    'scale': (0.1, 10.0),
    'bias': (-2.0, 2.0),
    'misalignment': (-0.2, 0.2),
    'scale_std': (0.0, 10.0),
    'bias_std': (0.0, 10.0),
    'misalignment_std': (0.0, 10.0),
}
"""Closed range of every value of each vector field (scale 1, g, rad as the field's unit);
the same as the ``attitude`` node's ``calibration.*`` parameter ranges.

A field calibration of an accelerometer has scales near 1 (the ADXL345: 0.8-1.2), biases
below 0.2 g and misalignments below a degree; the ranges are wide around that and only
catch files no calibration wrote."""
PREDICTED_TILT_ERROR_RANGE_DEG = (0.0, 180.0)


def _floats(values):
    return [float(round(v, 9)) for v in np.asarray(values, dtype=float).ravel()]


def calibration_dict(result: Any) -> dict:
    """Return the mapping written for a fit result (calibration's ``FitResult``)."""
    sm = result.sensor_model
    return {
        'format': FORMAT,
        'model': result.model,
        'scale': _floats(sm.scale),
        'bias': _floats(sm.bias),
        'misalignment': _floats(sm.misalignment),
        'scale_std': _floats(result.scale_std),
        'bias_std': _floats(result.bias_std),
        'misalignment_std': _floats(result.misalignment_std),
        'residual_rms_g': float(result.residual_rms_g),
        'holdout_rms_g': None if result.holdout_rms_g is None else float(result.holdout_rms_g),
        'positions': int(result.positions),
        'dropped_positions': list(result.dropped),
        'condition_number': float(result.condition_number),
        'predicted_tilt_error_deg': float(result.predicted_tilt_error_deg),
        'units': 'scale: dimensionless; bias, captures, residuals: g; misalignment: rad',
        'equation': EQUATION,
        'created': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
        'captures_g': [_floats(c) for c in result.captures_g],
        'residuals_g': _floats(result.residuals_g),
    }


def save_calibration(path: str, result: Any) -> None:
    """Write the calibration of ``result`` to ``path`` atomically; the old file -> ``.bak``."""
    write_text_atomic(path, '# accelcal_ros accelerometer calibration\n'
                      + dump_yaml(calibration_dict(result)), backup=True)


@dataclass
class CalibrationRecord:
    """A loaded calibration: the model, its kind and its uncertainty."""

    sensor_model: SensorModel
    model: str
    scale_std: np.ndarray
    bias_std: np.ndarray
    misalignment_std: np.ndarray
    predicted_tilt_error_deg: float
    data: dict


def _vector(path: str, data: dict, key: str, required: bool = True,
            default: Optional[np.ndarray] = None) -> np.ndarray:
    if key not in data or data[key] is None:
        if required:
            raise FileFormatError(path, f'missing key "{key}" (a calibration file needs '
                                  'model, scale and bias; was it truncated?)')
        return np.asarray(default, dtype=float)
    value = data[key]
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise FileFormatError(path, f'"{key}" must be a list of 3 numbers, got {value!r}') \
            from None
    if arr.shape != (3,):
        raise FileFormatError(path, f'"{key}" must be a list of 3 numbers, got {value!r}')
    if not np.all(np.isfinite(arr)):
        raise FileFormatError(path, f'"{key}" contains NaN or infinity: {value!r}; '
                              'recalibrate or fix the file')
    low, high = PLAUSIBLE_RANGES[key]
    if np.any(arr < low) or np.any(arr > high):
        raise FileFormatError(path, f'"{key}" = {arr.tolist()} is outside the plausible range '
                              f'{low:g} .. {high:g} of every value; the file is broken or not '
                              'an accelerometer calibration: recalibrate or fix the file')
    return arr


def load_calibration(path: str) -> CalibrationRecord:
    """Return the :class:`CalibrationRecord` in ``path``; FileFormatError if it is unusable."""
    data = load_yaml_mapping(path, 'calibration file')
    model = data.get('model', 'full' if 'misalignment' in data else 'diagonal')
    if model not in MODELS:
        raise FileFormatError(path, f'"model" must be one of {", ".join(MODELS)}, got {model!r}')
    scale = _vector(path, data, 'scale')
    bias = _vector(path, data, 'bias')
    misalignment = _vector(path, data, 'misalignment', required=False, default=np.zeros(3))
    if model == 'diagonal' and np.any(misalignment != 0.0):
        raise FileFormatError(path, 'a diagonal model cannot have a non-zero misalignment')
    try:
        sensor_model = SensorModel(scale, bias, misalignment)
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None
    zeros = np.zeros(3)
    predicted = data.get('predicted_tilt_error_deg')
    try:
        predicted = float(predicted) if predicted is not None else float('nan')
    except (TypeError, ValueError):
        raise FileFormatError(path, f'"predicted_tilt_error_deg" must be a number, '
                              f'got {predicted!r}') from None
    low, high = PREDICTED_TILT_ERROR_RANGE_DEG
    if np.isfinite(predicted) and not low <= predicted <= high or np.isinf(predicted):
        raise FileFormatError(path, f'"predicted_tilt_error_deg" = {predicted!r} is outside '
                              f'{low:g} .. {high:g} deg; recalibrate or fix the file')
    return CalibrationRecord(
        sensor_model, model,
        _vector(path, data, 'scale_std', required=False, default=zeros),
        _vector(path, data, 'bias_std', required=False, default=zeros),
        _vector(path, data, 'misalignment_std', required=False, default=zeros),
        predicted, data)


def load_sensor_model(path: str) -> SensorModel:
    """Return the :class:`SensorModel` in calibration file ``path`` (FileFormatError if bad)."""
    return load_calibration(path).sensor_model
