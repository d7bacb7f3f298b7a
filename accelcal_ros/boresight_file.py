"""
The LiDAR-IMU boresight file (shared floor): read by the LiDAR feature and the frame tree.

``R`` (9 numbers, row-major) maps LiDAR vectors into the IMU frame, ``v_imu = R v_lidar``;
``rpy_deg`` is the same rotation as REP-103 fixed-axis ``Rz(yaw) Ry(pitch) Rx(roll)``.
``accelcal boresight`` and the ``lidar_calibration`` node write both
(:mod:`accelcal_ros.lidar.boresight`); a hand-written file may hold either.
:data:`SCHEMA` lists every key a boresight file may hold; any other key is refused.
"""
import os
from typing import Any, Union

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.frames import rotation_from_rpy_radians, rotation_matrix_from_list
from accelcal_ros.schema import (check_mapping, is_integer, is_real, is_text, Key, list_of,
                                 number_rows, numbers, or_none, text_mapping)
from accelcal_ros.textformats import load_yaml_mapping
import numpy as np

PathLike = Union[str, 'os.PathLike[str]']


_TEXTS = list_of(is_text)
SCHEMA = {
    'R': Key('9 numbers (row-major rotation, LiDAR -> IMU)'),
    'rpy_deg': Key('3 numbers (roll, pitch, yaw, deg)'),
    'rpy_std_deg': Key('3 numbers (deg)', numbers(3, finite=False)),
    'convention': Key('text', is_text),
    'positions': Key('a list of position names', _TEXTS),
    'per_position_error_deg': Key('a list of numbers (deg)', numbers(finite=False)),
    'mean_error_deg': Key('a number (deg)', is_real),
    'max_error_deg': Key('a number (deg)', is_real),
    'holdout_error_deg': Key('a mapping', text_mapping),
    'rotation_covariance_rad2': Key('9 numbers (rad^2)', numbers(9, finite=False)),
    'floor_normals_lidar': Key('a list of [x, y, z]', number_rows(3, finite=False)),
    'gravity_imu_m_s2': Key('a list of [x, y, z] (m/s^2)', number_rows(3, finite=False)),
    'floor_inliers': Key('a list of integers', list_of(is_integer)),
    'dropped': Key('a mapping position -> reason', text_mapping),
    'warnings': Key('a list of text', _TEXTS),
    'prior_rpy_deg': Key('3 numbers (deg) or null', or_none(numbers(3))),
}
"""Every key of a boresight file (``R`` and ``rpy_deg`` are checked by :func:`load_boresight`
itself: one of them is required); the others are what ``accelcal boresight`` reports."""


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def load_boresight(path: PathLike) -> np.ndarray:
    """
    Return the 3x3 rotation (LiDAR -> IMU) from a boresight YAML (``R`` and/or ``rpy_deg``).

    Every field used is checked here, once, naming file and field: ``R`` 9 finite numbers
    forming a rotation (1e-4 tolerance), ``rpy_deg`` 3 finite numbers with roll and yaw in
    [-180, 180] and pitch in [-90, 90] deg; when both are present they must agree within
    0.01 deg (an edited ``rpy_deg`` beside a stale ``R`` is refused, not silently ignored).
    """
    data = load_yaml_mapping(path, 'boresight file')
    try:
        check_mapping(data, SCHEMA, 'a boresight file')
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None
    if 'R' not in data and 'rpy_deg' not in data:
        raise FileFormatError(path, 'boresight file has neither R (9 values) nor rpy_deg (3)')
    from_r = from_rpy = None
    if 'R' in data:
        try:
            from_r = rotation_matrix_from_list(_numbers(data['R'], 9, 'R'), 'R', tolerance=1e-4)
        except InputError as exc:
            raise FileFormatError(path, f'field {exc}') from None
    if 'rpy_deg' in data:
        try:
            rpy = _numbers(data['rpy_deg'], 3, 'rpy_deg')
        except InputError as exc:
            raise FileFormatError(path, f'field {exc}') from None
        limits = (180.0, 90.0, 180.0)
        for name, value, limit in zip(('roll', 'pitch', 'yaw'), rpy, limits):
            if abs(value) > limit:
                raise FileFormatError(path, f'field rpy_deg: {name} {value:g} deg is outside '
                                            f'[-{limit:g}, {limit:g}]')
        from_rpy = rotation_from_rpy_radians(*np.radians(rpy))
    if from_r is not None and from_rpy is not None:
        gap = _angle_deg(from_r, from_rpy)
        if gap > 0.01:
            raise FileFormatError(path, f'fields R and rpy_deg disagree by {gap:.3f} deg: fix '
                                        'or delete one of them')
    result = from_r if from_r is not None else from_rpy
    assert result is not None   # one of the two fields is present (checked above)
    return result


def _numbers(values: Any, count: int, name: str) -> np.ndarray:
    """Return ``count`` finite floats from a YAML list, else InputError naming ``name``."""
    from accelcal_ros.textformats import yaml_number

    numbers = [yaml_number(v) for v in values] if isinstance(values, list) else [None]
    if any(v is None for v in numbers):  # text, a bool (true is not 1.0), a nested list
        raise InputError(f'{name}: expected {count} numbers, got {values!r:.80}')
    arr = np.array(numbers, dtype=float)
    if arr.size != count:
        raise InputError(f'{name}: expected {count} numbers, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise InputError(f'{name}: contains NaN or infinity ({arr.tolist()})')
    return arr
