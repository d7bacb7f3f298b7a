"""
Recordings of raw accelerometer samples as CSV: ``t,ax,ay,az`` (seconds, m/s^2).

The same format is read by ``accelcal calibrate``/``apply``/``attitude``, written by
``accelcal record`` and ``accelcal apply``, and published by the driver's ``replay``
backend: a format the features share, so it lives below them. Reading checks the
header, the field count of every line (a truncated last line is reported with its
number), numbers, finiteness and strictly increasing time.
"""
from dataclasses import dataclass
import io
from typing import Optional, Tuple

from accelcal_ros.errors import FileFormatError, PathLike
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import RECORDING_CSV
from accelcal_ros.textformats import read_numeric_csv
import numpy as np
from numpy.typing import ArrayLike

CSV_HEADER = 't,ax,ay,az'
GYRO_COLUMNS = ('gx', 'gy', 'gz')


@dataclass
class Recording:
    """A recording CSV: ``t`` [N] s, ``accel`` [N, 3] m/s^2, ``gyro`` [N, 3] rad/s or None."""

    t: np.ndarray
    accel: np.ndarray
    gyro: Optional[np.ndarray] = None


def read_recording(path: PathLike, finite: bool = True) -> Recording:
    """
    Read a recording CSV ``t,ax,ay,az[,gx,gy,gz]``; an error names the file and the line.

    The times must be finite and increase strictly (a reversed or constant ``t`` is
    refused at its first line that does not increase); the gyro columns come all three
    or none. ``finite=False`` keeps NaN samples (calibrate skips them), never a NaN time.
    """
    columns = read_numeric_csv(path, RECORDING_CSV.required, RECORDING_CSV.optional,
                               finite=finite, increasing='t')
    if columns['t'].size == 0:
        raise FileFormatError(path, 'recording has a header but no samples', 2)
    present = [c for c in GYRO_COLUMNS if c in columns]
    if present and len(present) != len(GYRO_COLUMNS):
        raise FileFormatError(path, f'gyro columns {present}: give all of gx,gy,gz (rad/s) '
                              'or none', 1)
    accel = np.stack([columns['ax'], columns['ay'], columns['az']], axis=1)
    gyro = np.stack([columns[c] for c in GYRO_COLUMNS], axis=1) if present else None
    return Recording(columns['t'], accel, gyro)


def load_recording(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(t [N] s, acceleration [N, 3] m/s^2)`` from a recording CSV (all finite)."""
    recording = read_recording(path)
    return recording.t, recording.accel


def recording_text(t: ArrayLike, accel_mps2: ArrayLike) -> str:
    """Return CSV text (header ``t,ax,ay,az``) for times in s and accelerations in m/s^2."""
    t = np.asarray(t, dtype=float).reshape(-1)
    accel = np.asarray(accel_mps2, dtype=float).reshape(-1, 3)
    buffer = io.StringIO()
    buffer.write(CSV_HEADER + '\n')
    np.savetxt(buffer, np.column_stack([t, accel]), delimiter=',',
               fmt=['%.6f', '%.6f', '%.6f', '%.6f'])
    return buffer.getvalue()


def save_recording(path: str, t: ArrayLike,
                   accel_mps2: ArrayLike) -> None:
    """Write a recording CSV atomically (nothing is left half-written)."""
    write_text_atomic(path, recording_text(t, accel_mps2))
