"""
Streaming georeferencing (core of ``cloud_assembler``): scans + navigation poses -> map.

Poses (time s, position m, quaternion xyzw; IMU body -> navigation frame) are appended in
time order; one older than the newest is rejected (counted) -- a stream out of order is
reported, never re-sorted. A scan (structured array with a per-point time field, plus its
stamp) waits until the pose buffer covers its last point, then is georeferenced with
:func:`accelcal_ros.lidar.georef.georeference`. The wait ends early when no pose has
arrived for ``max_wait_s`` (counted from the later of the scan's and the newest pose's
arrival, on the clock of :meth:`CloudAssembler.process`: the node's
:class:`RunningClock`; odometry that arrives late on a busy machine is waited for while it
still comes, a stream that stopped is not) or when the waiting scans hold more than
``max_pending_points`` (the oldest goes first); points outside the buffered poses are
then dropped and counted, as are those between two poses further apart than
``max_gap_s`` (lost odometry: never interpolated across). Georeferenced points are
accumulated (up to ``max_points``, oldest first out) for saving to a file.
"""
from collections import deque
from typing import Any, Deque, List, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.frames import rotation_matrix_from_list
from accelcal_ros.lidar.cloud import make_cloud, point_times, xyz
from accelcal_ros.lidar.georef import georeference
from accelcal_ros.lidar.poses import PoseStream
import numpy as np
from numpy.typing import ArrayLike


RUNNING_STEP_S = 0.1
"""The most one tick of a :class:`RunningClock` advances it (s): 5 periods of the node's
20 ms timer."""


class RunningClock:
    """
    The seconds a node has been running: its ticks' wall clock, less every stall between them.

    :meth:`tick` (once per timer callback, with the monotonic time) advances the clock by
    the time since the previous tick, at most ``max_step_s``. A process starved of CPU
    for a while (a loaded machine) ran none of its callbacks meanwhile: its odometry was
    queued, not stopped. When the timer runs first after such a stall, a scan's wait for
    odometry measured on the wall clock had already run out, and the scan went with the
    poses that were there (CI: 4 scans, 30239 of 828000 points "after the poses" in
    ``test_cloud_assembler_keeps_every_pose_of_a_drive``); on this clock the stall
    counts as one step, so the scan waits for the callbacks to run. A steady tick period
    under ``max_step_s`` is the wall clock.
    """

    def __init__(self, max_step_s: float = RUNNING_STEP_S) -> None:
        self.max_step_s = float(max_step_s)
        self.now_s = 0.0
        """The clock (s; 0 at the first tick)."""
        self.stalled_s = 0.0
        """The wall time left out (s): the stalls beyond ``max_step_s`` between ticks."""
        self._last: Optional[float] = None

    def tick(self, monotonic_s: float) -> float:
        """Advance to the wall time ``monotonic_s`` (s); return the clock."""
        if self._last is not None:
            step = max(0.0, monotonic_s - self._last)
            self.now_s += min(step, self.max_step_s)
            self.stalled_s += max(0.0, step - self.max_step_s)
        self._last = monotonic_s
        return self.now_s


class CloudAssembler:
    """Buffer poses and scans; georeference scans once the poses cover them."""

    def __init__(self, boresight: ArrayLike, lever_arm_m: ArrayLike = (0.0, 0.0, 0.0),
                 time_field: Optional[str] = None, pose_buffer_s: float = 30.0,
                 max_wait_s: float = 3.0, max_points: int = 5_000_000,
                 max_pending_points: int = 2_000_000,
                 max_gap_s: Optional[float] = None) -> None:
        self.boresight = rotation_matrix_from_list(boresight, 'boresight', tolerance=1e-4)
        self.lever_arm_m = np.asarray(lever_arm_m, dtype=float).reshape(3)
        if not np.all(np.isfinite(self.lever_arm_m)):
            raise InputError(f'lever arm {self.lever_arm_m.tolist()} contains NaN or infinity')
        self.time_field = time_field or None
        self.pose_buffer_s = pose_buffer_s
        self.max_wait_s = max_wait_s
        self.max_points = max_points
        self.max_pending_points = max_pending_points
        self.max_gap_s = max_gap_s
        """Longest pose gap (s) interpolated across; None: no limit."""
        self._pending_points = 0
        self._pose_arrival_s = -np.inf
        self._poses: Deque[Tuple[float, np.ndarray, np.ndarray]] = deque()
        self._pending: Deque[Tuple[float, np.ndarray, np.ndarray]] = deque()
        self._map: Deque[np.ndarray] = deque()
        self._map_points = 0
        self.rejected_poses = 0
        self.totals = {'points': 0, 'kept': 0, 'before': 0, 'after': 0, 'non_finite': 0,
                       'in_gap': 0, 'scans': 0}

    def add_pose(self, t: float, position: ArrayLike, quat_xyzw: ArrayLike,
                 now_s: Optional[float] = None) -> Optional[str]:
        """
        Append a pose; returns None or the reason it was rejected (out of order, NaN).

        ``now_s`` is its arrival (the clock of :meth:`process`); a pose without one does
        not extend a scan's wait.
        """
        values = np.concatenate([[t], position, quat_xyzw]).astype(float)
        if not np.all(np.isfinite(values)):
            self.rejected_poses += 1
            return 'pose contains NaN'
        if abs(np.linalg.norm(quat_xyzw) - 1.0) > 1e-3:
            self.rejected_poses += 1
            return f'quaternion norm {np.linalg.norm(quat_xyzw):.4f} is not 1'
        if self._poses and t <= self._poses[-1][0]:
            self.rejected_poses += 1
            return (f'pose at {t:.6f} s is not after the previous one ({self._poses[-1][0]:.6f}'
                    ' s): odometry out of order, dropped')
        self._poses.append((float(t), np.asarray(position, float), np.asarray(quat_xyzw, float)))
        if now_s is not None:
            self._pose_arrival_s = float(now_s)
        while self._poses and self._poses[0][0] < t - self.pose_buffer_s:
            self._poses.popleft()
        return None

    def add_scan(self, stamp_s: float, cloud: np.ndarray, now_s: float) -> None:
        """Queue a scan; raises InputError when it has no per-point time field."""
        times = point_times(cloud, stamp_s, self.time_field)
        self._pending.append((now_s, cloud, times))
        self._pending_points += len(cloud)

    @property
    def waiting(self) -> int:
        """Return how many scans wait for odometry to cover them."""
        return len(self._pending)

    def pose_stream(self) -> Optional[PoseStream]:
        """Return the buffered poses as a PoseStream (None with fewer than 2)."""
        if len(self._poses) < 2:
            return None
        t = np.array([p[0] for p in self._poses])
        return PoseStream(t, np.array([p[1] for p in self._poses]),
                          np.array([p[2] for p in self._poses]))

    def process(self, now_s: float, force: bool = False) -> List[Tuple[np.ndarray, Any]]:
        """
        Georeference every ready scan; returns ``[(cloud_nav, stats)]``.

        A scan is ready when the poses cover its last point, when no pose arrived within
        ``max_wait_s`` of ``now_s`` (nor the scan itself), when the waiting scans hold more
        than ``max_pending_points``, or with ``force``.
        """
        out = []
        while self._pending:
            queued, cloud, times = self._pending[0]
            newest = self._poses[-1][0] if self._poses else -np.inf
            finite_t = times[np.isfinite(times)]
            last = finite_t.max() if finite_t.size else -np.inf
            waiting = now_s - max(queued, self._pose_arrival_s) < self.max_wait_s
            if (not force and newest < last and waiting
                    and self._pending_points <= self.max_pending_points):
                break
            self._pending.popleft()
            self._pending_points -= len(cloud)
            out.append(self._georeference(cloud, times))
        return out

    def _georeference(self, cloud, times):
        poses = self.pose_stream()
        names = cloud.dtype.names
        if poses is None:
            pts, keep = np.zeros((0, 3)), np.zeros(len(cloud), dtype=bool)
            stats = None
        else:
            pts, keep, stats = georeference(xyz(cloud), times, poses, self.boresight,
                                            self.lever_arm_m, max_gap_s=self.max_gap_s)
        nav = make_cloud(pts, cloud['intensity'][keep] if 'intensity' in names else None,
                         cloud['ring'][keep] if 'ring' in names else None, times[keep],
                         'timestamp', double=True)
        self.totals['scans'] += 1
        self.totals['points'] += len(cloud)
        if stats is None:
            self.totals['before'] += len(cloud)
        else:
            self.totals['kept'] += stats.kept
            self.totals['before'] += stats.before_span
            self.totals['after'] += stats.after_span
            self.totals['non_finite'] += stats.non_finite
            self.totals['in_gap'] += stats.in_gap
        if len(nav):
            self._map.append(nav)
            self._map_points += len(nav)
            while self._map_points > self.max_points and len(self._map) > 1:
                self._map_points -= len(self._map.popleft())
        return nav, stats

    def map_cloud(self) -> np.ndarray:
        """Return every accumulated georeferenced point as one structured array."""
        if not self._map:
            return make_cloud(np.zeros((0, 3)), None, None, np.zeros(0), 'timestamp',
                              double=True)
        return np.concatenate(list(self._map))

    def summary(self) -> str:
        """Return a one-line summary of what was processed."""
        t = self.totals
        return (f'{t["scans"]} scans, {t["kept"]} of {t["points"]} points georeferenced '
                f'({t["before"]} before / {t["after"]} after the poses, {t["in_gap"]} in pose '
                f'gaps, {t["non_finite"]} non-finite dropped), {self.rejected_poses} poses '
                'rejected')


def check_time_field(cloud: np.ndarray, field: Optional[str] = None) -> str:
    """Raise InputError when a scan has no per-point time (see cloud.time_field_of)."""
    from accelcal_ros.lidar.cloud import time_field_of

    if cloud.dtype.names is None:
        raise InputError('scan is not a structured array')
    return time_field_of(cloud, field)
