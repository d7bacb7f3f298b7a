r"""
Static segments of an IMU log and the gravity (specific force) measured in each.

Paper B finds the still periods from the gyro signal and takes the mean accelerometer
reading minus the accelerometer bias as gravity in the IMU frame:
``g = (mean(a_x) - b_x, mean(a_y) - b_y, mean(a_z) - b_z)``.

The still periods come from the package's one stillness detector,
:func:`accelcal_ros.sensor.stillness.still_segments` (accelerometer, and gyro when logged;
its thresholds are stated once, in :class:`~accelcal_ros.sensor.stillness.StillnessThresholds`).
Segments shorter than ``min_duration_s`` are dropped and each is trimmed by ``trim_s`` at
both ends. The gravity of a segment is the mean specific force (REP-145: +g on the up axis,
m/s^2) with, when a :class:`~accelcal_ros.sensor.model.SensorModel` is given, the
calibration applied (``f = T diag(1/k) (a - b)`` in g, paper A eq. 1 / the full model).
"""
from dataclasses import dataclass
from typing import Any, List, Optional

from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.stillness import still_segments, StillnessThresholds
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
from numpy.typing import ArrayLike


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
    def duration_s(self) -> float:
        """Return the segment's duration in seconds."""
        return self.t_stop - self.t_start

    def direction_std_rad(self) -> float:
        """Return the angular standard error of the mean gravity direction (rad)."""
        norm = float(np.linalg.norm(self.gravity_m_s2))
        return float(np.linalg.norm(self.gravity_std_m_s2) / np.sqrt(max(self.count, 1))
                     / max(norm, 1e-9) / np.sqrt(1.5))


def find_static_segments(t: ArrayLike, accel: ArrayLike, gyro: Optional[ArrayLike] = None,
                         model: Optional[SensorModel] = None,
                         min_duration_s: Optional[float] = None,
                         trim_s: float = 0.1,
                         thresholds: Optional[StillnessThresholds] = None
                         ) -> List[StaticSegment]:
    """
    Return the :class:`StaticSegment` list of a log (time s, accel m/s^2, gyro rad/s).

    ``model`` (a SensorModel, in g) is applied to every sample before averaging;
    ``min_duration_s`` defaults to ``thresholds.min_still_s``; each segment is trimmed by
    ``trim_s`` at both ends. Non-finite and saturated samples are not used.
    """
    thresholds = thresholds or StillnessThresholds()
    t = np.asarray(t, dtype=float).reshape(-1)
    accel = np.asarray(accel, dtype=float).reshape(-1, 3)
    force = accel
    if model is not None:
        force = model.correct(accel / STANDARD_GRAVITY_M_S2) * STANDARD_GRAVITY_M_S2
    min_s = thresholds.min_still_s if min_duration_s is None else float(min_duration_s)
    found = still_segments(t, accel, gyro, thresholds, accel_unit_m_s2=1.0,
                           min_still_s=max(min_s, 1e-9))
    usable = np.all(np.isfinite(force), axis=1)
    segments = []
    for seg in found:
        ta, tb = seg.t_start_s + trim_s, seg.t_end_s - trim_s
        if tb - ta < min_s:
            continue
        i0 = int(np.searchsorted(t, ta))
        i1 = int(np.searchsorted(t, tb, side='right'))
        chunk = force[i0:i1][usable[i0:i1]]
        if len(chunk) < 2:
            continue
        segments.append(StaticSegment(i0, i1, float(t[i0]), float(t[i1 - 1]),
                                      chunk.mean(axis=0), chunk.std(axis=0), len(chunk)))
    return segments


def longest_static_segment(t: ArrayLike, accel: ArrayLike, gyro: Optional[ArrayLike] = None,
                           model: Optional[SensorModel] = None,
                           **kwargs: Any) -> Optional[StaticSegment]:
    """Return the longest :class:`StaticSegment` or None when the log is never still."""
    segments = find_static_segments(t, accel, gyro, model, **kwargs)
    if not segments:
        return None
    return max(segments, key=lambda s: s.duration_s)
