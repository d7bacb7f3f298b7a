"""
IMU logs as CSV: header ``t,ax,ay,az[,gx,gy,gz]`` (s, m/s^2 specific force, rad/s).

Read with :func:`accelcal_ros.textformats.read_numeric_csv` (errors name file and line);
times must increase strictly and every value must be finite.
"""
from dataclasses import dataclass
from typing import Optional

from accelcal_ros.errors import FileFormatError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import RECORDING_CSV
from accelcal_ros.textformats import read_numeric_csv
import numpy as np


@dataclass
class ImuLog:
    """Time ``t`` (N,), specific force ``accel`` (N, 3) m/s^2, optional ``gyro`` rad/s."""

    t: np.ndarray
    accel: np.ndarray
    gyro: Optional[np.ndarray] = None


def read_imu_csv(path: str) -> 'ImuLog':
    """Read an IMU CSV log into an :class:`ImuLog`."""
    cols = read_numeric_csv(path, RECORDING_CSV.required, RECORDING_CSV.optional)
    t = cols['t']
    accel = np.stack([cols['ax'], cols['ay'], cols['az']], axis=1)
    gyro = None
    present = [k for k in ('gx', 'gy', 'gz') if k in cols]
    if present and len(present) != 3:
        raise FileFormatError(path, f'gyro columns {present}: give all of gx,gy,gz (rad/s) '
                              'or none', 1)
    if present:
        gyro = np.stack([cols['gx'], cols['gy'], cols['gz']], axis=1)
    if t.size == 0:
        raise FileFormatError(path, 'no samples after the header')
    values = accel if gyro is None else np.hstack([accel, gyro])
    bad = ~(np.isfinite(t) & np.all(np.isfinite(values), axis=1))
    if bad.any():
        raise FileFormatError(path, 'NaN or infinite value', int(np.flatnonzero(bad)[0]) + 2)
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        raise FileFormatError(path, f'time {t[k]:.6f} s does not increase (previous '
                              f'{t[k - 1]:.6f} s); sort the log by time', k + 2)
    return ImuLog(t, accel, gyro)


def write_imu_csv(path: str, log: 'ImuLog') -> None:
    """Write an :class:`ImuLog` as CSV atomically."""
    cols = [log.t[:, None], log.accel]
    header = 't,ax,ay,az'
    if log.gyro is not None:
        cols.append(log.gyro)
        header += ',gx,gy,gz'
    table = np.hstack(cols)
    lines = [header] + [f'{row[0]:.17g},' + ','.join(f'{v:.9g}' for v in row[1:])
                        for row in table.tolist()]
    write_text_atomic(path, '\n'.join(lines) + '\n')
