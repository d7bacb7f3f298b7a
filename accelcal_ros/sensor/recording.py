"""
Recordings of raw accelerometer samples as CSV: ``t,ax,ay,az`` (seconds, m/s^2).

The same format is read by ``accelcal calibrate``/``apply``/``attitude``, written by
``accelcal record`` and ``accelcal apply``, and published by the driver's ``replay``
backend: a format the features share, so it lives below them. Reading checks the
header, the field count of every line (a truncated last line is reported with its
number), numbers, finiteness, strictly increasing time and the unit (a file in g is
refused: :data:`G_UNITS_MEDIAN`).
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
G_UNITS_MEDIAN = (0.5, 2.0)
"""A recording whose median |a| lies here is in g, not m/s^2 (at rest or moving by hand it
is near 9.8 m/s^2; read as m/s^2 it would be a sensor in near free fall: calibrate found
"0 positions, sensor moving", attitude skipped 9527 of 9600 samples with status 0)."""
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
    with np.errstate(over='ignore', invalid='ignore'):   # a corrupt 1e300 sample: inf
        magnitude = np.linalg.norm(accel, axis=1)
    magnitude = magnitude[np.isfinite(magnitude) & (magnitude > 0.0)]
    median = float(np.median(magnitude)) if magnitude.size else 0.0
    if G_UNITS_MEDIAN[0] <= median <= G_UNITS_MEDIAN[1]:
        raise FileFormatError(path, f'the accelerations look like g (median |a| {median:.3f}); '
                              'a recording is in m/s^2 (multiply ax, ay, az by 9.80665)', 2)
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
