r"""
Static segments of an IMU log and the gravity (specific force) measured in each.

Paper B finds the still periods from the gyro signal and takes the mean accelerometer
reading minus the accelerometer bias as gravity in the IMU frame:
``g = (mean(a_x) - b_x, mean(a_y) - b_y, mean(a_z) - b_z)``.

Here a sample is static when, over a centred window of ``window_s``, the standard
deviation of every gyro axis is below ``gyro_std_threshold_rad_s`` and the gyro mean
magnitude below ``gyro_rate_threshold_rad_s`` (when a gyro is logged), or else when the
standard deviation of every accelerometer axis is below ``accel_std_threshold_m_s2``.
Runs of static samples shorter than ``min_duration_s`` are dropped. The gravity of a
segment is the mean specific force (REP-145: +g on the up axis, m/s^2) with, when a
:class:`~accelcal_ros.sensor.model.SensorModel` is given, the calibration applied
(``f = T diag(1/k) (a - b)`` in g, paper A eq. 1 / the full model).
"""
from dataclasses import dataclass

from accelcal_ros.errors import InputError
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np


@dataclass
class StaticSegment:
    """Samples ``[start, stop)`` of a log, their times and the mean specific force."""

    start: int
    stop: int
    t_start: float
    t_stop: float
    gravity_m_s2: np.ndarray
    gravity_std_m_s2: np.ndarray
    count: int

    @property
    def duration_s(self):
        """Return the segment's duration in seconds."""
        return self.t_stop - self.t_start

    def direction_std_rad(self):
        """Return the angular standard error of the mean gravity direction (rad)."""
        norm = float(np.linalg.norm(self.gravity_m_s2))
        return float(np.linalg.norm(self.gravity_std_m_s2) / np.sqrt(max(self.count, 1))
                     / max(norm, 1e-9) / np.sqrt(1.5))


def _moving_std(values, half):
    """Centred moving standard deviation of each column over ``2 * half + 1`` samples."""
    n = values.shape[0]
    pad = np.pad(values, ((half + 1, half), (0, 0)), mode='edge')
    c1 = np.cumsum(pad, axis=0)
    c2 = np.cumsum(pad * pad, axis=0)
    width = 2 * half + 1
    s1 = c1[width:width + n] - c1[:n]
    s2 = c2[width:width + n] - c2[:n]
    mean = s1 / width
    var = np.maximum(s2 / width - mean * mean, 0.0)
    return np.sqrt(var), mean


def static_mask(t, accel, gyro=None, window_s=0.5, gyro_std_threshold_rad_s=0.01,
                gyro_rate_threshold_rad_s=0.05, accel_std_threshold_m_s2=0.08):
    """Return a boolean mask of static samples (see the module docstring)."""
    t = np.asarray(t, dtype=float)
    accel = np.asarray(accel, dtype=float).reshape(-1, 3)
    if t.size != accel.shape[0]:
        raise InputError(f'{t.size} times for {accel.shape[0]} accelerometer samples')
    if t.size < 3:
        return np.zeros(t.size, dtype=bool)
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise InputError('IMU times do not increase')
    half = max(1, int(round(window_s / dt / 2)))
    if gyro is not None:
        gyro = np.asarray(gyro, dtype=float).reshape(-1, 3)
        std, mean = _moving_std(gyro, half)
        return (np.all(std < gyro_std_threshold_rad_s, axis=1)
                & (np.linalg.norm(mean, axis=1) < gyro_rate_threshold_rad_s))
    std, _ = _moving_std(accel, half)
    return np.all(std < accel_std_threshold_m_s2, axis=1)


def find_static_segments(t, accel, gyro=None, model=None, min_duration_s=1.0,
                         trim_s=0.1, **thresholds):
    """
    Return the :class:`StaticSegment` list of a log, longest stillness first kept in order.

    ``model`` (a SensorModel, in g) is applied to every sample before averaging; each
    segment is trimmed by ``trim_s`` at both ends.
    """
    t = np.asarray(t, dtype=float)
    accel = np.asarray(accel, dtype=float).reshape(-1, 3)
    mask = static_mask(t, accel, gyro, **thresholds)
    force = accel
    if model is not None:
        force = model.correct(accel / STANDARD_GRAVITY_M_S2) * STANDARD_GRAVITY_M_S2
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    segments = []
    for a, b in zip(starts, stops):
        ta, tb = t[a] + trim_s, t[b - 1] - trim_s
        if tb - ta < min_duration_s:
            continue
        i0 = int(np.searchsorted(t, ta))
        i1 = int(np.searchsorted(t, tb, side='right'))
        if i1 - i0 < 2:
            continue
        chunk = force[i0:i1]
        segments.append(StaticSegment(i0, i1, float(t[i0]), float(t[i1 - 1]),
                                      chunk.mean(axis=0), chunk.std(axis=0), i1 - i0))
    return segments


def longest_static_segment(t, accel, gyro=None, model=None, **kwargs):
    """Return the longest :class:`StaticSegment` or None when the log is never still."""
    segments = find_static_segments(t, accel, gyro, model, **kwargs)
    if not segments:
        return None
    return max(segments, key=lambda s: s.duration_s)


def load_calibration_model(path):
    """
    Load an accelerometer calibration (issue 3's file) as a SensorModel.

    Uses :func:`accelcal_ros.sensor.calibration_file.load_sensor_model`, which raises
    FileFormatError for missing, truncated or wrong-shape files.
    """
    from accelcal_ros.sensor.calibration_file import load_sensor_model

    return load_sensor_model(path)
