"""
Recordings of raw accelerometer samples as CSV: ``t,ax,ay,az`` (seconds, m/s^2).

The same format is read by ``accelcal calibrate``/``apply``/``attitude``, written by
``accelcal record`` and ``accelcal apply``, and published by the driver's ``replay``
backend: a format the features share, so it lives below them. Reading checks the
header, the field count of every line (a truncated last line is reported with its
number), numbers, finiteness and strictly increasing time.
"""
import io
from typing import Tuple

from accelcal_ros.errors import FileFormatError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import RECORDING_CSV
from accelcal_ros.textformats import read_numeric_csv
import numpy as np
from numpy.typing import ArrayLike

CSV_HEADER = 't,ax,ay,az'


def load_recording(path: str) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(t [N] s, acceleration [N, 3] m/s^2)`` from a recording CSV."""
    columns = read_numeric_csv(path, RECORDING_CSV.required, RECORDING_CSV.optional,
                               finite=True, increasing='t')
    if columns['t'].size == 0:
        raise FileFormatError(path, 'recording has a header but no samples', 2)
    accel = np.stack([columns['ax'], columns['ay'], columns['az']], axis=1)
    return columns['t'], accel


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
