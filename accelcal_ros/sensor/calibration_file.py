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

:data:`SCHEMA` lists every key with its type; ``model``, ``scale``, ``bias`` (and
``misalignment`` for ``model: full``) are required, and anything else (an unknown key or
``format`` version, ``true`` where a number belongs) is refused.

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

from typing import Any, List, Optional

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import check_mapping, Key
from accelcal_ros.sensor.model import MODELS, SensorModel
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping, yaml_number
from accelcal_ros.uncertainty import floor_at_known_error, KnownError
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
    notes: tuple = ()
    """Why a reported value was changed on reading (an uncertainty raised to a known error)."""


def tilt_error_known_deg(holdout_rms_g: Optional[float],
                         residual_rms_g: Optional[float]) -> List[KnownError]:
    """
    Return the tilt errors (deg) a calibration's own residuals already show.

    A residual of ``r`` g (eq. 5: ``|f| - 1`` at a position) is an error of the corrected
    field of at least ``r`` g; in a direction the fit did not see (the hold-out) it can
    tilt ``f`` by ``asin(r)``. A predicted roll/pitch error below that is overconfident.
    """
    known = []
    for value, what in ((holdout_rms_g, 'hold-out'), (residual_rms_g, 'fit')):
        if value is not None and np.isfinite(value) and value > 0:
            known.append(KnownError(
                float(np.degrees(np.arcsin(min(1.0, value)))),
                f'the {what} residual RMS {value * 1e3:.2f} mg is an error of the corrected '
                f'field that can tilt it by asin({value:.2g}) (calibration check)'))
    return known


def _is_number(value: Any) -> bool:
    """Return whether ``value`` is a YAML number (a bool is not: :func:`yaml_number`)."""
    return yaml_number(value) is not None


def _vector(path: str, data: dict, key: str, required: bool = True,
            default: Optional[np.ndarray] = None) -> np.ndarray:
    if key not in data or data[key] is None:
        if required:
            raise FileFormatError(path, f'missing key "{key}" (a calibration file needs '
                                  'model, scale and bias, and misalignment for the full model; '
                                  'was it truncated?)')
        return np.asarray(default, dtype=float)
    value = data[key]
    if not isinstance(value, list) or len(value) != 3 or not all(map(_is_number, value)):
        raise FileFormatError(path, f'"{key}" must be a list of 3 numbers, got {value!r}')
    arr = np.array([yaml_number(v) for v in value], dtype=float)
    if not np.all(np.isfinite(arr)):
        raise FileFormatError(path, f'"{key}" contains NaN or infinity: {value!r}; '
                              'recalibrate or fix the file')
    low, high = PLAUSIBLE_RANGES[key]
    if np.any(arr < low) or np.any(arr > high):
        raise FileFormatError(path, f'"{key}" = {arr.tolist()} is outside the plausible range '
                              f'{low:g} .. {high:g} of every value; the file is broken or not '
                              'an accelerometer calibration: recalibrate or fix the file')
    return arr


def _number_or_none(value: Any) -> bool:
    return value is None or _is_number(value)


def _number_list(value: Any) -> bool:
    return isinstance(value, list) and all(map(_is_number, value))


def _text(value: Any) -> bool:
    return isinstance(value, str)


def _created(value: Any) -> bool:  # written quoted; a hand-written date parses as one
    return isinstance(value, (str, datetime.date))


def _index_list(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value)


def _captures(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(v, list) and len(v) == 3 and all(map(_is_number, v)) for v in value)


def _count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


SCHEMA = {key: Key(what, check) for key, (what, check) in {
    'format': ('the string "' + FORMAT + '"', _text),
    'model': (f'one of {", ".join(MODELS)}', _text),
    'scale': ('3 numbers', None),
    'bias': ('3 numbers (g)', None),
    'misalignment': ('3 numbers (rad)', None),
    'scale_std': ('3 numbers', None),
    'bias_std': ('3 numbers (g)', None),
    'misalignment_std': ('3 numbers (rad)', None),
    'residual_rms_g': ('a number or null', _number_or_none),
    'holdout_rms_g': ('a number or null', _number_or_none),
    'positions': ('a non-negative integer', _count),
    'dropped_positions': ('a list of position indices', _index_list),
    'condition_number': ('a number or null', _number_or_none),
    'predicted_tilt_error_deg': ('a number or null', _number_or_none),
    'units': ('text', _text),
    'equation': ('text', _text),
    'created': ('a UTC time', _created),
    'captures_g': ('a list of [x, y, z] (g)', _captures),
    'residuals_g': ('a list of numbers (g)', _number_list),
}.items()}
"""Every key a calibration file may hold: ``(what it must be, check)`` (the vectors are
checked by ``_vector``). Required: ``model``, ``scale``, ``bias``, and ``misalignment`` for
``model: full``; ``format`` when present must be :data:`FORMAT`. Any other key is refused
(a misspelt ``misalignement`` would otherwise read as zero misalignment)."""


def _check_schema(path: str, data: dict) -> None:
    try:  # required keys: _vector, with the calibration's own message
        check_mapping(data, SCHEMA, 'a calibration file')
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None
    if 'format' in data and data['format'] != FORMAT:
        raise FileFormatError(path, f'unknown format {data["format"]!r}: this version reads '
                              f'"{FORMAT}" (written by a newer accelcal_ros? update it)')


def load_calibration(path: str) -> CalibrationRecord:
    """
    Return the :class:`CalibrationRecord` in ``path``; FileFormatError if it is unusable.

    The file must follow :data:`SCHEMA`: ``model``, ``scale`` and ``bias`` are required, a
    ``full`` model needs its ``misalignment``, numbers are numbers (``true`` is not 1.0),
    an unknown ``format`` or key is refused.
    """
    data = load_yaml_mapping(path, 'calibration file')
    _check_schema(path, data)
    if 'model' not in data:
        raise FileFormatError(path, f'missing key "model" ({" or ".join(MODELS)}); was the '
                              'file truncated?')
    model = data['model']
    if model not in MODELS:
        raise FileFormatError(path, f'"model" must be one of {", ".join(MODELS)}, got {model!r}')
    scale = _vector(path, data, 'scale')
    bias = _vector(path, data, 'bias')
    misalignment = _vector(path, data, 'misalignment', required=model == 'full',
                           default=np.zeros(3))
    if model == 'diagonal' and np.any(misalignment != 0.0):
        raise FileFormatError(path, 'a diagonal model cannot have a non-zero misalignment')
    try:
        sensor_model = SensorModel(scale, bias, misalignment)
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None
    zeros = np.zeros(3)
    predicted = data.get('predicted_tilt_error_deg')
    number = yaml_number(predicted)  # a number (SCHEMA) or None
    predicted = float('nan') if number is None else number
    low, high = PREDICTED_TILT_ERROR_RANGE_DEG
    if np.isfinite(predicted) and not low <= predicted <= high or np.isinf(predicted):
        raise FileFormatError(path, f'"predicted_tilt_error_deg" = {predicted!r} is outside '
                              f'{low:g} .. {high:g} deg; recalibrate or fix the file')
    notes = []
    if np.isfinite(predicted):  # never below the error the file's own residuals show
        predicted, note = floor_at_known_error(
            predicted, tilt_error_known_deg(yaml_number(data.get('holdout_rms_g')),
                                            yaml_number(data.get('residual_rms_g'))),
            ' deg', 'predicted roll/pitch error')
        notes += [note] if note else []
    return CalibrationRecord(
        sensor_model, model,
        _vector(path, data, 'scale_std', required=False, default=zeros),
        _vector(path, data, 'bias_std', required=False, default=zeros),
        _vector(path, data, 'misalignment_std', required=False, default=zeros),
        predicted, data, tuple(notes))


def load_sensor_model(path: str) -> SensorModel:
    """Return the :class:`SensorModel` in calibration file ``path`` (FileFormatError if bad)."""
    return load_calibration(path).sensor_model
