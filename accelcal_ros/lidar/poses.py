"""
Navigation pose streams: CSV ``t,x,y,z,qx,qy,qz,qw``.

A pose is the IMU (body) frame in the navigation frame at time ``t`` (s): position
``(x, y, z)`` (m) and the unit quaternion ``(qx, qy, qz, qw)`` rotating body vectors into
the navigation frame (scipy / ROS order, scalar last). Times must increase strictly: an
out-of-order stream is an error naming the line, never re-sorted silently.
"""
from dataclasses import dataclass
from typing import Optional, Tuple

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import POSES_CSV
from accelcal_ros.textformats import read_numeric_csv
import numpy as np

POSE_COLUMNS = POSES_CSV.required
MAX_POSITION_M = 1e8
"""Largest plausible coordinate (m): ECEF and UTM stay below 1e7 m."""
MAX_TIME_S = 1e11
"""Largest plausible time (s): the year 5138 in Unix time; nanosecond stamps exceed it."""


@dataclass
class PoseStream:
    """Times ``t`` (N,) s, positions (N, 3) m, quaternions (N, 4) xyzw (body -> nav)."""

    t: np.ndarray
    position: np.ndarray
    quat_xyzw: np.ndarray

    def __post_init__(self) -> None:
        """Check shapes, finiteness, strictly increasing time; normalise quaternions."""
        self.t = np.asarray(self.t, dtype=float).reshape(-1)
        self.position = np.asarray(self.position, dtype=float).reshape(-1, 3)
        self.quat_xyzw = np.asarray(self.quat_xyzw, dtype=float).reshape(-1, 4)
        n = self.t.size
        if self.position.shape[0] != n or self.quat_xyzw.shape[0] != n:
            raise InputError(f'pose stream: {n} times, {self.position.shape[0]} positions and '
                             f'{self.quat_xyzw.shape[0]} quaternions')
        if n < 2:
            raise InputError(f'pose stream needs at least 2 poses to interpolate, got {n}')
        problem = check_pose_arrays(self.t, self.position, self.quat_xyzw)
        if problem is not None:
            index, reason = problem
            raise InputError(f'pose stream: pose {index}: {reason}')
        self.quat_xyzw = self.quat_xyzw / np.linalg.norm(self.quat_xyzw, axis=1, keepdims=True)

    @property
    def span(self) -> Tuple[float, float]:
        """Return ``(t_first, t_last)`` in seconds."""
        return float(self.t[0]), float(self.t[-1])


def check_pose_arrays(t: np.ndarray, position: np.ndarray,
                      quat: np.ndarray) -> Optional[Tuple[int, str]]:
    """Return ``(index, reason)`` of the first bad pose, or None when all are fine."""
    values = np.hstack([t[:, None], position, quat])
    bad = np.flatnonzero(~np.all(np.isfinite(values), axis=1))
    if bad.size:
        return int(bad[0]), 'NaN or infinite value'
    bad = np.flatnonzero(np.any(np.abs(position) > MAX_POSITION_M, axis=1))
    if bad.size:
        k = int(bad[0])
        return k, (f'position {position[k].tolist()} m is beyond {MAX_POSITION_M:g} m from '
                   'the origin (wrong units or columns?)')
    bad = np.flatnonzero(np.abs(t) > MAX_TIME_S)
    if bad.size:
        return int(bad[0]), (f'time {t[bad[0]]:g} s is beyond {MAX_TIME_S:g} s (not seconds? '
                             'nanoseconds must be divided by 1e9)')
    with np.errstate(over='ignore'):   # a component of 1e308: norm inf, refused below
        norms = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= 1e-3))
    if bad.size:
        k = int(bad[0])
        return k, f'quaternion norm {norms[k]:.6f} is not 1 (wrong column order?)'
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        k = int(back[0]) + 1
        return k, (f'time {t[k]:.6f} s is not after the previous pose ({t[k - 1]:.6f} s): '
                   'the stream is out of order or has duplicates; sort it by time')
    return None


def read_poses_csv(path: str) -> 'PoseStream':
    """Read a pose CSV into a :class:`PoseStream`; errors name the file and line."""
    cols = read_numeric_csv(path, POSE_COLUMNS)
    t = cols['t']
    position = np.stack([cols['x'], cols['y'], cols['z']], axis=1)
    quat = np.stack([cols['qx'], cols['qy'], cols['qz'], cols['qw']], axis=1)
    if t.size < 2:
        raise FileFormatError(path, f'needs at least 2 poses, found {t.size}')
    problem = check_pose_arrays(t, position, quat)
    if problem is not None:
        index, reason = problem
        raise FileFormatError(path, reason, index + 2)
    return PoseStream(t, position, quat)


def write_poses_csv(path: str, poses: 'PoseStream') -> None:
    """Write a :class:`PoseStream` as CSV atomically."""
    table = np.hstack([poses.t[:, None], poses.position, poses.quat_xyzw])
    lines = [','.join(POSE_COLUMNS)]
    lines += [','.join(f'{v:.17g}' for v in row) for row in table.tolist()]
    write_text_atomic(path, '\n'.join(lines) + '\n')
