"""
Online capture of static positions for the boresight calibration (core of ``lidar_calibration``).

IMU samples (time s, specific force m/s^2, optional gyro rad/s) and LiDAR scans (time s,
points (N, 3) m in the LiDAR frame) are fed as they arrive. The IMU is *still* when,
over the last ``min_static_s``, every gyro axis (or, without a gyro, every accelerometer
axis) varies less than its threshold (standard deviation) and the mean rate is below
``gyro_rate_threshold_rad_s``. While still, scans are
collected; once ``clouds_per_capture`` scans arrived the position is captured (auto mode)
with the mean specific force over the still period so far. One capture per still period;
motion re-arms it. A few missing samples keep the state; a gap longer than half of
``min_static_s`` ends the still period (the rig may have moved unseen). A scan stamped
inside the still period that just ended but arriving after the IMU moved on (the topics
are not ordered) still counts for that period. If no motion was
seen and gravity agrees within 1 deg with the last capture afterwards, it is the same
position and is not captured again.
:meth:`StaticCapture.capture_now` captures on request.
"""
from collections import deque
from dataclasses import dataclass
from itertools import takewhile

from accelcal_ros.lidar.boresight import StaticPosition
from accelcal_ros.lidar.static_segments import STANDARD_GRAVITY_M_S2
import numpy as np


@dataclass
class CaptureSettings:
    """Thresholds of :class:`StaticCapture` (see the module docstring)."""

    min_static_s: float = 1.0
    gyro_std_threshold_rad_s: float = 0.01
    gyro_rate_threshold_rad_s: float = 0.05
    accel_std_threshold_m_s2: float = 0.08
    clouds_per_capture: int = 1
    buffer_s: float = 60.0
    auto: bool = True


class StaticCapture:
    """Detect still periods in an IMU stream and pair them with LiDAR scans."""

    def __init__(self, settings=None, model=None):
        self.settings = settings or CaptureSettings()
        self.model = model
        self._imu = deque()
        self._still_since = None
        self._captured_this_still = False
        self._clouds = []
        self._last_still_t = None
        self._closed = None  # [start, end, clouds, ended_by_motion] of the last still period
        self._pending = []
        self.positions = []
        self.out_of_order = 0
        self._motion_since_capture = True

    def add_imu(self, t, accel, gyro=None):
        """Add one IMU sample; returns True when still. Out-of-order samples are counted."""
        if self._imu and t <= self._imu[-1][0]:
            self.out_of_order += 1
            return self.still
        if self._imu and t - self._imu[-1][0] > 0.5 * self.settings.min_static_s:
            # a long gap: the rig may have moved unseen, never average across it
            self._end_still(ended_by_motion=False)
        accel = np.asarray(accel, dtype=float)
        if self.model is not None:
            accel = self.model.correct(accel / STANDARD_GRAVITY_M_S2) * STANDARD_GRAVITY_M_S2
        self._imu.append((float(t), accel, None if gyro is None else np.asarray(gyro, float)))
        while self._imu and self._imu[0][0] < t - self.settings.buffer_s:
            self._imu.popleft()
        still = self._window_still(t)
        if still is None:  # too few samples (a gap in the stream): keep the previous state
            still = self._still_since is not None
        elif still and self._still_since is None:
            self._still_since = t - self.settings.min_static_s
        elif not still and self._still_since is not None:
            self._motion_since_capture = True
            self._end_still(ended_by_motion=True)
        if still:
            self._last_still_t = t
        self._drain()
        return still

    def _window_still(self, t):
        s = self.settings
        window = list(takewhile(lambda x: x[0] >= t - s.min_static_s, reversed(self._imu)))
        window.reverse()
        if len(window) < 5 or window[-1][0] - window[0][0] < 0.8 * s.min_static_s:
            return None
        if all(x[2] is not None for x in window):
            gyro = np.array([x[2] for x in window])
            return bool(np.all(gyro.std(axis=0) < s.gyro_std_threshold_rad_s)
                        and np.linalg.norm(gyro.mean(axis=0)) < s.gyro_rate_threshold_rad_s)
        acc = np.array([x[1] for x in window])
        return bool(np.all(acc.std(axis=0) < s.accel_std_threshold_m_s2))

    @property
    def still(self):
        """Return True while the IMU is still."""
        return self._still_since is not None

    def add_cloud(self, t, points):
        """
        Add a scan; returns the captured :class:`StaticPosition` when auto-captured.

        A scan newer than the newest IMU sample waits until the IMU stream reaches its
        stamp (scans and IMU arrive on separate topics, in any interleaving), so it is
        always judged against the stillness at its own time.
        """
        self._pending.append((float(t), np.asarray(points, dtype=float).reshape(-1, 3)))
        # keep enough scans for one capture (packetised drivers send many small ones)
        del self._pending[:-max(10, 2 * self.settings.clouds_per_capture)]
        return self._drain()

    def _drain(self):
        if not self._imu:
            return None
        newest = self._imu[-1][0]
        captured = None
        keep = []
        for t, pts in self._pending:
            if t > newest:
                keep.append((t, pts))
                continue
            closed = self._closed
            if closed is not None and closed[0] <= t <= closed[1]:
                # stamped inside the still period that just ended: it arrived late (scans
                # and IMU come on separate topics), so it still belongs to that period
                closed[2].append(pts)
                if self.settings.auto and len(closed[2]) >= self.settings.clouds_per_capture:
                    captured = self._capture_closed()
                continue
            if self._still_since is None or t < self._still_since or self._captured_this_still:
                continue
            if self._same_as_last_capture():
                self._captured_this_still = True
                continue
            self._clouds.append(pts)
            if self.settings.auto and len(self._clouds) >= self.settings.clouds_per_capture:
                captured = self._capture()
        self._pending = keep
        return captured

    def _same_as_last_capture(self):
        """Return True when no motion was seen since the last capture and gravity agrees."""
        if self._motion_since_capture or not self.positions:
            return False
        accel = np.array([x[1] for x in self._imu if x[0] >= self._still_since])
        if not len(accel):
            return False
        now = accel.mean(axis=0)
        last = self.positions[-1].gravity_m_s2
        cos = now @ last / (np.linalg.norm(now) * np.linalg.norm(last))
        return bool(cos > np.cos(np.radians(1.0)))

    def capture_now(self):
        """Capture the current position; returns ``(position or None, reason)``."""
        if self._still_since is None:
            return None, 'the IMU is not still (wait until the rig rests)'
        if self._captured_this_still:
            return None, 'this still period is already captured (move to the next position)'
        if not self._clouds:
            return None, 'no LiDAR scan received since the rig came to rest'
        return self._capture(), 'captured'

    def _end_still(self, ended_by_motion):
        """Close the current still period, keeping it for scans that arrive late."""
        self._closed = None
        if self._still_since is not None and not self._captured_this_still \
                and self._last_still_t is not None:
            self._closed = [self._still_since, self._last_still_t, self._clouds,
                            ended_by_motion]
        self._still_since = None
        self._captured_this_still = False
        self._clouds = []

    def _capture_closed(self):
        start, end, clouds, ended_by_motion = self._closed
        self._closed = None
        position = self._make_position(start, end, clouds)
        self._motion_since_capture = ended_by_motion
        return position

    def _capture(self):
        position = self._make_position(self._still_since, np.inf, self._clouds)
        self._captured_this_still = True
        self._motion_since_capture = False
        self._clouds = []
        return position

    def _make_position(self, start, end, clouds):
        samples = [x[1] for x in self._imu if start <= x[0] <= end]
        accel = np.array(samples)
        gravity = accel.mean(axis=0)
        std = float(np.linalg.norm(accel.std(axis=0)) / np.sqrt(len(accel) * 1.5)
                    / max(np.linalg.norm(gravity), 1e-9))
        name = f'pos{len(self.positions) + 1:02d}'
        position = StaticPosition(name, np.vstack(clouds), gravity, std)
        self.positions.append(position)
        return position

    def reset(self):
        """Forget every captured position."""
        self.positions = []
        self._captured_this_still = False
        self._clouds = []
        self._closed = None
