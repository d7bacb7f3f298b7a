r"""
Georeferencing: LiDAR points with per-point time -> navigation frame (paper B, Fig. 4).

For a point ``p_L`` (LiDAR frame, m) measured at time ``t`` (s):

.. math::  p_N = C(t) (R\, p_L + l) + r(t)

with ``R`` the boresight (LiDAR -> IMU), ``l`` the lever arm (LiDAR origin in the IMU
frame, m; paper B's ``X_sh, Y_sh, Z_sh``), and the body pose ``C(t)`` (IMU -> navigation)
and ``r(t)`` (IMU origin in the navigation frame) interpolated from the pose stream:
position linearly, orientation by spherical linear interpolation (slerp) between the two
neighbouring poses -- the same quantity as :class:`scipy.spatial.transform.Slerp`
(``C = C_k exp(alpha log(C_k^T C_{k+1}))``), evaluated here with vectorised quaternion
algebra because scipy's per-point path costs about 1 s per million points (the tests
check both agree to 1e-12). Points outside the pose stream's time span, and non-finite
points, are dropped and counted, never extrapolated.
"""
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
import os
from typing import Optional, Tuple, Union

from accelcal_ros.errors import InputError
from accelcal_ros.frames import rotation_matrix_from_list
from accelcal_ros.lidar.poses import PoseStream
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation


@dataclass
class GeorefStats:
    """Counts of a georeferencing run."""

    total: int
    kept: int
    before_span: int
    after_span: int
    non_finite: int
    in_gap: int = 0

    def summary(self) -> str:
        """Return a one-line human-readable summary."""
        return (f'{self.kept} of {self.total} points georeferenced; dropped '
                f'{self.before_span} before and {self.after_span} after the pose stream, '
                + (f'{self.in_gap} in pose gaps, ' if self.in_gap else '')
                + f'{self.non_finite} non-finite')


class PoseInterpolator:
    """Linear position / slerp orientation interpolation of a :class:`PoseStream`."""

    def __init__(self, poses: PoseStream) -> None:
        self.t = poses.t
        self.position = poses.position
        rot = Rotation.from_quat(poses.quat_xyzw)
        self.quat = rot.as_quat()
        self.delta_rotvec = (rot[:-1].inv() * rot[1:]).as_rotvec()
        self.dt = np.diff(self.t)
        self.dpos = np.diff(self.position, axis=0)

    @property
    def span(self) -> Tuple[float, float]:
        """Return ``(t_first, t_last)``."""
        return float(self.t[0]), float(self.t[-1])

    def segment(self, times: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return ``(index, alpha)`` of each time (inside the span) in the pose stream."""
        idx = np.searchsorted(self.t, times, side='right') - 1
        np.clip(idx, 0, len(self.t) - 2, out=idx)
        alpha = (times - self.t[idx]) / self.dt[idx]
        return idx, alpha

    def quaternions(self, idx: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Return interpolated quaternions ``(N, 4)`` xyzw (slerp)."""
        v = self.delta_rotvec[idx] * alpha[:, None]
        angle = np.sqrt(np.einsum('ij,ij->i', v, v))
        half = 0.5 * angle
        small = angle < 1e-6
        scale = np.where(small, 0.5 - angle * angle / 48.0,
                         np.sin(half) / np.where(small, 1.0, angle))
        bx, by, bz = v[:, 0] * scale, v[:, 1] * scale, v[:, 2] * scale
        bw = np.cos(half)
        q0 = self.quat[idx]
        ax, ay, az, aw = q0[:, 0], q0[:, 1], q0[:, 2], q0[:, 3]
        return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                         aw * by - ax * bz + ay * bw + az * bx,
                         aw * bz + ax * by - ay * bx + az * bw,
                         aw * bw - ax * bx - ay * by - az * bz], axis=1)

    def positions(self, idx: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """Return linearly interpolated positions ``(N, 3)``."""
        return self.position[idx] + self.dpos[idx] * alpha[:, None]


def rotate_by_quaternions(quat: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Rotate ``(N, 3)`` vectors by ``(N, 4)`` unit quaternions (xyzw)."""
    ux, uy, uz, w = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    vx, vy, vz = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    out = np.empty_like(vectors)
    out[:, 0] = vx + w * tx + (uy * tz - uz * ty)
    out[:, 1] = vy + w * ty + (uz * tx - ux * tz)
    out[:, 2] = vz + w * tz + (ux * ty - uy * tx)
    return out


def _transform_chunk(interp, boresight, lever, points, times):
    body = points @ boresight.T + lever
    idx, alpha = interp.segment(times)
    return rotate_by_quaternions(interp.quaternions(idx, alpha), body) \
        + interp.positions(idx, alpha)


def georeference(points: ArrayLike, times: ArrayLike,
                 poses: Union[PoseStream, 'PoseInterpolator'], boresight: ArrayLike,
                 lever_arm_m: ArrayLike = (0.0, 0.0, 0.0), threads: Optional[int] = None,
                 chunk: int = 262144, max_gap_s: Optional[float] = None
                 ) -> Tuple[np.ndarray, np.ndarray, GeorefStats]:
    """
    Return ``(points_nav (M, 3), kept_mask (N,), GeorefStats)``.

    ``points`` (N, 3) LiDAR frame, ``times`` (N,) absolute seconds in the pose stream's
    clock, ``poses`` a :class:`~accelcal_ros.lidar.poses.PoseStream` (body -> nav),
    ``boresight`` 3x3 (LiDAR -> IMU), ``lever_arm_m`` (IMU frame). Work is split in
    chunks over ``threads`` (default: the CPU count, at most 4) -- numpy releases the GIL.
    With ``max_gap_s``, points between two poses further apart than that are dropped and
    counted (``in_gap``), never interpolated across the gap.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if times.shape[0] != pts.shape[0]:
        raise InputError(f'{pts.shape[0]} points but {times.shape[0]} per-point times')
    boresight = rotation_matrix_from_list(boresight, 'boresight', tolerance=1e-4)
    lever = np.asarray(lever_arm_m, dtype=float).reshape(3)
    if not np.all(np.isfinite(lever)):
        raise InputError('lever arm contains NaN or infinity')
    interp = poses if isinstance(poses, PoseInterpolator) else PoseInterpolator(poses)
    t0, t1 = interp.span
    finite = np.all(np.isfinite(pts), axis=1) & np.isfinite(times)
    before = finite & (times < t0)
    after = finite & (times > t1)
    keep = finite & ~before & ~after
    gap = np.zeros(len(pts), dtype=bool)
    if max_gap_s is not None and np.any(interp.dt > max_gap_s):
        idx, _ = interp.segment(np.where(keep, times, t0))
        gap = keep & (interp.dt[idx] > max_gap_s)
        keep &= ~gap
    stats = GeorefStats(int(len(pts)), int(keep.sum()), int(before.sum()), int(after.sum()),
                        int((~finite).sum()), int(gap.sum()))
    sel_pts = pts[keep] if stats.kept < len(pts) else pts
    sel_t = times[keep] if stats.kept < len(pts) else times
    n = len(sel_pts)
    threads = threads or min(4, os.cpu_count() or 1)
    if n <= chunk or threads <= 1:
        out = (_transform_chunk(interp, boresight, lever, sel_pts, sel_t) if n
               else np.zeros((0, 3)))
        return out, keep, stats
    out = np.empty((n, 3))
    bounds = list(range(0, n, chunk)) + [n]

    def work(k):
        a, b = bounds[k], bounds[k + 1]
        out[a:b] = _transform_chunk(interp, boresight, lever, sel_pts[a:b], sel_t[a:b])

    with ThreadPoolExecutor(max_workers=threads) as pool:
        list(pool.map(work, range(len(bounds) - 1)))
    return out, keep, stats
