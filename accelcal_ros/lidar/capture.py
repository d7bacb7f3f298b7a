"""
Online capture of static positions for the boresight calibration (core of ``lidar_calibration``).

IMU samples (time s, specific force m/s^2, optional gyro rad/s) and LiDAR scans (time s,
points (N, 3) m in the LiDAR frame) are fed as they arrive, the two streams in any
interleaving.

Still periods. Stillness is judged by the package's one detector,
:class:`accelcal_ros.sensor.stillness.StillnessDetector` (accelerometer, and gyro when every
sample has one; thresholds from :class:`~accelcal_ros.sensor.stillness.StillnessThresholds`,
which also give the defaults of :class:`CaptureSettings`). The IMU is *still* once the
detector's still segment has lasted ``min_static_s``; the still period starts where the
segment began. Motion ends it (at the detector's trimmed end). A gap in the IMU stream
longer than half of ``min_static_s`` ends it too, because the rig may have moved unseen;
but if no motion is seen afterwards and the next still period's mean gravity agrees with
it within ``same_position_deg``, the rig did not change its attitude (a yaw turn or a
shift changes neither the gravity in the IMU frame nor the floor normal in the LiDAR
frame, the pair a position contributes), so that period is continued: scans from
before and after the gap add up, scans stamped inside the gap are not used, and a period
already captured is not captured twice.

Scans. A scan is judged by its own stamp against the IMU stream: it joins the still
period whose time span holds its stamp (the current one once the IMU has reached the
stamp, or one of the last ``recent_periods`` that ended within ``buffer_s``, since scans
may arrive seconds late after a stall of the receiving process). A scan no period holds
yet waits (at most ``max_pending_scans``, oldest dropped) until the IMU stream is
``min_static_s`` past its stamp: a still period is only recognised ``min_static_s``
after it began (longer after a gap), and then reaches back to its beginning. After that
the scan was taken while moving and is dropped. Once a
period holds ``clouds_per_capture`` scans it is captured (auto mode) with the mean
specific force over the period (:class:`~accelcal_ros.lidar.boresight.StaticPosition`);
one capture per period. :meth:`StaticCapture.capture_now` captures the current period on
request.
"""
from collections import deque
from dataclasses import dataclass, field
from typing import Deque, List, Optional, Tuple

from accelcal_ros.lidar.boresight import StaticPosition
from accelcal_ros.sensor.model import SensorModel
from accelcal_ros.sensor.stillness import StillnessDetector, StillnessThresholds
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
import numpy as np
from numpy.typing import ArrayLike

_STILL = StillnessThresholds()


@dataclass
class CaptureSettings:
    """
    Settings of :class:`StaticCapture` (see the module docstring).

    The three stillness thresholds default to the shared detector's
    (:class:`~accelcal_ros.sensor.stillness.StillnessThresholds`; the accelerometer one
    converted from g to m/s^2): spreads of 20 ms block means over its window.
    """

    min_static_s: float = 1.0
    gyro_std_threshold_rad_s: float = _STILL.gyro_std_rad_s
    gyro_rate_threshold_rad_s: float = _STILL.gyro_rate_rad_s
    accel_std_threshold_m_s2: float = _STILL.accel_std_g * STANDARD_GRAVITY_M_S2
    clouds_per_capture: int = 1
    buffer_s: float = 60.0
    auto: bool = True
    same_position_deg: float = 1.0
    max_pending_scans: int = 100
    recent_periods: int = 10

    def stillness_thresholds(self) -> StillnessThresholds:
        """Return the detector thresholds (gaps are handled by the capture, not the detector)."""
        return StillnessThresholds(
            window_s=min(_STILL.window_s, self.min_static_s),
            accel_std_g=self.accel_std_threshold_m_s2 / STANDARD_GRAVITY_M_S2,
            gyro_std_rad_s=self.gyro_std_threshold_rad_s,
            gyro_rate_rad_s=self.gyro_rate_threshold_rad_s, min_still_s=self.min_static_s,
            block_s=_STILL.block_s, saturation_g=_STILL.saturation_g,
            max_gap_s=max(self.buffer_s, self.min_static_s))


@dataclass
class _StillPeriod:
    """One still period: ``[start_s, end_s]`` (open: ``end_s`` inf) minus its IMU gaps."""

    start_s: float
    last_still_s: float
    end_s: float = np.inf
    clouds: list = field(default_factory=list)
    captured: bool = False
    ended_by_motion: bool = False
    gaps: list = field(default_factory=list)   # (t0, t1) not seen still (IMU gaps)
    gravity_m_s2: Optional[np.ndarray] = None   # mean specific force, set when a gap ends it

    def covers(self, t):
        """Return True when a scan stamped ``t`` s was taken in this period."""
        return self.start_s <= t <= self.end_s and not any(a < t < b for a, b in self.gaps)


class StaticCapture:
    """Detect still periods in an IMU stream and pair them with LiDAR scans."""

    def __init__(self, settings: Optional[CaptureSettings] = None,
                 model: Optional[SensorModel] = None) -> None:
        self.settings = settings or CaptureSettings()
        self.model = model
        self._thresholds = self.settings.stillness_thresholds()
        self._detector = StillnessDetector(self._thresholds, accel_unit_m_s2=1.0)
        self._imu: Deque[Tuple[float, np.ndarray, Optional[np.ndarray]]] = deque()
        self._current: Optional[_StillPeriod] = None
        self._ended: Deque[_StillPeriod] = deque()   # recent ended periods, newest last
        self._motion_since_end = False
        self._seen_since_s = -np.inf   # first IMU sample after the last gap
        self._pending: List[Tuple[float, np.ndarray]] = []
        self.positions: List[StaticPosition] = []
        self.out_of_order = 0
        self.scans_overflowed = 0
        self._segment_start_s = -np.inf
        self._still_end_s = None

    @property
    def still(self) -> bool:
        """Return True while the IMU is still."""
        return self._current is not None

    def add_imu(self, t: float, accel: ArrayLike, gyro: Optional[ArrayLike] = None) -> bool:
        """
        Add one IMU sample; returns True when still. Out-of-order samples are counted.

        Scans waiting for the IMU stream are resolved here, so a position may be captured
        by this call (new entries in :attr:`positions`).
        """
        t = float(t)
        if self._imu and t <= self._imu[-1][0]:
            self.out_of_order += 1
            return self.still
        if self._imu and t - self._imu[-1][0] > 0.5 * self.settings.min_static_s:
            self._end(ended_by_motion=False)  # the rig may have moved unseen
            self._seen_since_s = t
            self._detector = StillnessDetector(self._thresholds, accel_unit_m_s2=1.0)
        force = np.asarray(accel, dtype=float).reshape(3)
        if self.model is not None:
            force = self.model.correct(force / STANDARD_GRAVITY_M_S2) * STANDARD_GRAVITY_M_S2
        rate = None if gyro is None else np.asarray(gyro, dtype=float).reshape(3)
        if not self._detector.add(t, force.tolist(), None if rate is None else rate.tolist()):
            return self.still   # NaN or saturated: not used (a shock ends the segment)
        self._imu.append((t, force, rate))
        while self._imu[0][0] < t - self.settings.buffer_s:
            self._imu.popleft()
        while self._ended and self._ended[0].end_s < self._imu[0][0]:
            self._ended.popleft()   # its samples are gone
        still = self._window_still(t)
        if still is False:
            self._end(ended_by_motion=True)
            self._motion_since_end = True
        elif still and self._current is None:
            self._start(t)
        if self._current is not None:
            self._current.last_still_s = t
        self._drain()
        return self.still

    def _window_still(self, t):
        """
        Return True (still for ``min_static_s``), False (motion) or None (not judged yet).

        A still period must not reach back before the last gap; ended segments' trimmed
        ends are kept in ``self._still_end_s`` for :meth:`_end`.
        """
        det = self._detector
        while det.ended:
            final = det.ended.pop(0).final
            self._still_end_s = None if final is None else final.t_end_s
        seg = det.segment
        if seg is None:
            return None if np.isnan(det.motion_std) else False
        self._segment_start_s = max(seg.t_start_s, self._seen_since_s)
        return True if t - self._segment_start_s >= self.settings.min_static_s else None

    def _mean_accel(self, start, end):
        samples = [x[1] for x in self._imu if start <= x[0] <= end]
        return np.mean(samples, axis=0) if samples else None

    def _accel_in(self, period):
        """Specific force samples (n, 3) the period holds (none from its gaps)."""
        return np.array([x[1] for x in self._imu if period.covers(x[0])]).reshape(-1, 3)

    def _start(self, t):
        """Open a still period, or continue the last one when only a gap ended it."""
        start = self._segment_start_s
        last = self._ended[-1] if self._ended else None
        if (last is not None and not last.ended_by_motion and not self._motion_since_end
                and last.gravity_m_s2 is not None
                and self._same_direction(last.gravity_m_s2, self._mean_accel(start, t))):
            self._ended.pop()
            last.gaps.append((last.end_s, start))   # unseen: no scan from then counts
            last.end_s = np.inf
            self._current = last
        else:
            self._current = _StillPeriod(start, t)

    def _same_direction(self, a, b):
        if b is None:
            return False
        cos = a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12)
        return bool(cos > np.cos(np.radians(self.settings.same_position_deg)))

    def _end(self, ended_by_motion):
        """Close the current still period, keeping it for scans that arrive late."""
        period, self._current = self._current, None
        if period is None:
            return
        period.end_s = period.last_still_s
        if ended_by_motion and self._still_end_s is not None:
            # the detector's trimmed end: its last window already held the motion
            period.end_s = max(period.start_s, min(period.end_s, self._still_end_s))
        self._still_end_s = None
        period.ended_by_motion = ended_by_motion
        if not ended_by_motion:   # only a gap-ended period may be continued (_start)
            accel = self._accel_in(period)
            period.gravity_m_s2 = accel.mean(axis=0) if len(accel) else None
        self._ended.append(period)
        self._motion_since_end = False
        while len(self._ended) > self.settings.recent_periods:
            self._ended.popleft()

    def add_cloud(self, t: float, points: ArrayLike) -> Optional[StaticPosition]:
        """Add a scan; returns the :class:`StaticPosition` it completed (auto mode), else None."""
        self._pending.append((float(t), np.asarray(points, dtype=float).reshape(-1, 3)))
        limit = max(self.settings.max_pending_scans, 2 * self.settings.clouds_per_capture)
        if len(self._pending) > limit:   # counted: the node reports them as dropped
            self.scans_overflowed += len(self._pending) - limit
            del self._pending[:-limit]
        return self._drain()

    def _period_at(self, t):
        for period in ([self._current] if self._current else []) + list(reversed(self._ended)):
            if period.covers(t):
                return period
        return None

    def _drain(self):
        """Hand every scan the IMU stream has reached to its still period."""
        if not self._imu:
            return None
        newest = self._imu[-1][0]
        captured = None
        keep = []
        for t, pts in self._pending:
            period = self._period_at(t) if t <= newest else None
            if period is None:
                if t + self.settings.min_static_s > newest:
                    keep.append((t, pts))   # a still period may yet be found to cover it
                continue
            if period.captured:
                continue
            period.clouds.append(pts)
            del period.clouds[:-self.settings.clouds_per_capture]   # manual mode: the latest
            if self.settings.auto and len(period.clouds) >= self.settings.clouds_per_capture:
                captured = self._capture(period)
        self._pending = keep
        return captured

    def capture_now(self) -> Tuple[Optional[StaticPosition], str]:
        """
        Capture the current position; returns ``(position or None, reason)``.

        The position merges the latest ``clouds_per_capture`` scans of the current period.
        """
        if self._current is None:
            return None, 'the IMU is not still (wait until the rig rests)'
        if self._current.captured:
            return None, 'this still period is already captured (move to the next position)'
        if not self._current.clouds:
            return None, 'no LiDAR scan received since the rig came to rest'
        return self._capture(self._current), 'captured'

    def _capture(self, period):
        accel = self._accel_in(period)
        gravity = accel.mean(axis=0)
        std = float(np.linalg.norm(accel.std(axis=0)) / np.sqrt(len(accel) * 1.5)
                    / max(np.linalg.norm(gravity), 1e-9))
        name = f'pos{len(self.positions) + 1:02d}'
        position = StaticPosition(name, np.vstack(period.clouds), gravity, std,
                                  calibrated=self.model is not None)
        self.positions.append(position)
        period.captured = True
        period.clouds = []
        return position
