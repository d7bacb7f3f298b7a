"""
The LiDAR-IMU boresight file (shared floor): read by the LiDAR feature and the frame tree.

``R`` (9 numbers, row-major) maps LiDAR vectors into the IMU frame, ``v_imu = R v_lidar``;
``rpy_deg`` is the same rotation as REP-103 fixed-axis ``Rz(yaw) Ry(pitch) Rx(roll)``.
``accelcal boresight`` and the ``lidar_calibration`` node write both
(:mod:`accelcal_ros.lidar.boresight`); a hand-written file may hold either.
"""
import os
from typing import Any, Union

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.frames import rotation_from_rpy_radians, rotation_matrix_from_list
from accelcal_ros.textformats import load_yaml_mapping
import numpy as np

PathLike = Union[str, 'os.PathLike[str]']


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
