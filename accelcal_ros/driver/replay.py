"""
Recordings of raw accelerometer samples as CSV: ``t,ax,ay,az`` (seconds, m/s^2).

The same format is read by ``accelcal calibrate``/``apply``/``attitude``, written by
``accelcal record`` and ``accelcal apply``, and published by the driver's ``replay``
backend. Reading checks the header, the field count of every line (a truncated last line
is reported with its number), numbers, finiteness and strictly increasing time.
"""
import io

from accelcal_ros import STANDARD_GRAVITY
from accelcal_ros.errors import FileFormatError
from accelcal_ros.fileio import read_numeric_csv, write_text_atomic
import numpy as np

CSV_HEADER = 't,ax,ay,az'


def load_recording(path):
    """Return ``(t [N] s, acceleration [N, 3] m/s^2)`` from a recording CSV."""
    columns = read_numeric_csv(path, ('t', 'ax', 'ay', 'az'), finite=True, increasing='t')
    if columns['t'].size == 0:
        raise FileFormatError(path, 'recording has a header but no samples', 2)
    accel = np.stack([columns['ax'], columns['ay'], columns['az']], axis=1)
    return columns['t'], accel


def recording_text(t, accel_mps2):
    """Return CSV text (header ``t,ax,ay,az``) for times in s and accelerations in m/s^2."""
    t = np.asarray(t, dtype=float).reshape(-1)
    accel = np.asarray(accel_mps2, dtype=float).reshape(-1, 3)
    buffer = io.StringIO()
    buffer.write(CSV_HEADER + '\n')
    np.savetxt(buffer, np.column_stack([t, accel]), delimiter=',',
               fmt=['%.6f', '%.6f', '%.6f', '%.6f'])
    return buffer.getvalue()


def save_recording(path, t, accel_mps2):
    """Write a recording CSV atomically (nothing is left half-written)."""
    write_text_atomic(path, recording_text(t, accel_mps2))


def g_to_mps2(values_g):
    """Convert accelerations from g to m/s^2 (1 g = 9.80665 m/s^2)."""
    return np.asarray(values_g, dtype=float) * STANDARD_GRAVITY


def mps2_to_g(values_mps2):
    """Convert accelerations from m/s^2 to g."""
    return np.asarray(values_mps2, dtype=float) / STANDARD_GRAVITY
