r"""
``imu_to_camera`` from gravity: the accelerometer and the board both see the vertical.

In still pose ``k`` the accelerometer's mean specific force ``f_k`` (IMU frame, up,
REP-145) and the board's up direction ``n`` (board frame; the board lies on a floor or
table) seen in the reference camera through the joint fit, ``R_0b,k n``, are the same
direction (J. Lobo, J. Dias, IJRR 26(6), 2007):

.. math::  C \hat f_k = R_{0b,k}\, n, \qquad C = \text{imu\_to\_camera}.

The board need not be level: ``n = R_x(a) R_y(b) n_0`` (``n_0 = \pm e_z``, the board's
normal on the cameras' side) carries its tilt. Turning the rig about the vertical
between poses moves a tilted board's normal in the rig frame while gravity stays, so
``C`` and ``(a, b)`` are fitted together by least squares over all poses (start:
Wahba's solution with a level board, ``Rotation.align_vectors``). Without such turns
the tilt is indistinguishable from ``C``: it is then held at zero and a warning says so.
``C = exp([d]_x) C_0``: ``d`` is a small rotation about the reference camera's x, y, z
axes; 1-sigma from ``s^2 (J^T J)^{-1}``.
"""
from dataclasses import dataclass, field
from typing import Dict, List, Tuple

from accelcal_ros.errors import CalibrationError
from accelcal_ros.frames import rot_x, rot_y
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

MIN_TILT_INFORMATION = 0.05
"""Smallest eigenvalue per pose of the tilt's information (after C is solved for) below
which the board's tilt is reported unconstrained (poses never turn about the vertical)."""


@dataclass
class MountFit:
    """``imu_to_camera`` (IMU body -> reference optical), its 1-sigma and the board tilt."""

    imu_to_camera: np.ndarray
    std_deg: np.ndarray
    board_up: np.ndarray
    board_tilt_deg: float
    board_tilt_std_deg: float
    tilt_estimated: bool
    pose_error_deg: Dict[str, float]
    heading_spread_deg: float
    warnings: List[str] = field(default_factory=list)


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def heading_spread_deg(headings_rad: np.ndarray) -> float:
    """Smallest arc (deg) holding every heading: 360 minus the largest gap between them."""
    h = np.sort(np.mod(np.asarray(headings_rad, dtype=float), 2 * np.pi))
    if h.size < 2:
        return 0.0
    gaps = np.diff(np.concatenate([h, [h[0] + 2 * np.pi]]))
    return float(np.degrees(2 * np.pi - gaps.max()))


def fit_imu_to_camera(board_poses: Dict[str, Tuple[np.ndarray, np.ndarray]],
                      gravity: Dict[str, np.ndarray], estimate_tilt: bool = True) -> MountFit:
    """
    Fit ``imu_to_camera`` (and the board's tilt) to the poses in both dicts.

    ``board_poses[pose] = (R_0b, t_0b)`` (board -> reference camera, m) from the rig fit,
    ``gravity[pose]`` the mean specific force (IMU frame, any unit).
    """
    poses = sorted(set(board_poses) & set(gravity))
    if len(poses) < 2:
        raise CalibrationError(f'imu_to_camera needs at least 2 poses with both a board view '
                               f'and a still accelerometer, got {len(poses)}: add poses')
    forces = np.array([gravity[p] for p in poses], dtype=float)
    usable = np.all(np.isfinite(forces), axis=1) & np.any(forces != 0, axis=1)
    if not np.all(usable):
        bad = poses[int(np.flatnonzero(~usable)[0])]
        raise CalibrationError(f'{bad}: the mean specific force {list(gravity[bad])} has no '
                               'direction (zero or not finite): drop the pose')
    scaled = forces / np.abs(forces).max(axis=1, keepdims=True)   # no overflow on 1e300
    f = _unit(scaled)
    rots = np.array([board_poses[p][0] for p in poses])
    centres_z = np.array([-(board_poses[p][0].T @ board_poses[p][1])[2] for p in poses])
    n0 = np.array([0.0, 0.0, 1.0 if np.mean(centres_z) > 0 else -1.0])
    up_cam0 = rots @ n0
    c0, _ = Rotation.align_vectors(up_cam0, f)
    c0 = c0.as_matrix()

    def up(x):
        return rot_x(x[3]) @ rot_y(x[4]) @ n0

    def residuals(x):
        c = Rotation.from_rotvec(x[:3]).as_matrix() @ c0
        return (f @ c.T - rots @ up(x)).ravel()

    full = least_squares(residuals, np.zeros(5), method='lm', xtol=1e-12, ftol=1e-12)
    jac = full.jac
    info = jac.T @ jac
    schur = info[3:, 3:] - info[3:, :3] @ np.linalg.solve(info[:3, :3], info[:3, 3:])
    tilt_information = float(np.linalg.eigvalsh(schur)[0]) / len(poses)
    c_full = Rotation.from_rotvec(full.x[:3]).as_matrix() @ c0
    # heading of the rig about the board's normal in each pose (IMU x axis on the board)
    x_on_board = np.einsum('kji,j->ki', rots, c_full @ np.array([1.0, 0.0, 0.0]))
    spread = heading_spread_deg(np.arctan2(x_on_board[:, 1], x_on_board[:, 0]))
    warnings = []
    constrained = tilt_information >= MIN_TILT_INFORMATION
    if estimate_tilt and constrained:
        res, free = full, 5
    else:
        if estimate_tilt:
            warnings.append(
                f'the poses hardly turn the rig about the vertical (headings over the board '
                f'span {spread:.0f} deg): the board tilt cannot be told from imu_to_camera and '
                'is taken as level (any tilt goes into imu_to_camera); add poses with the rig '
                'turned by 90-180 deg about the vertical')
        res = least_squares(lambda x: residuals(np.concatenate([x, [0.0, 0.0]])),
                            np.zeros(3), method='lm', xtol=1e-12, ftol=1e-12)
        free = 3
    x = np.concatenate([res.x, np.zeros(5 - res.x.size)])
    c = Rotation.from_rotvec(x[:3]).as_matrix() @ c0
    dof = max(1, res.fun.size - free)
    s2 = float(res.fun @ res.fun / dof)
    try:
        cov = np.linalg.inv(res.jac.T @ res.jac) * s2
    except np.linalg.LinAlgError:
        cov = np.full((free, free), np.inf)
    std = np.degrees(np.sqrt(np.maximum(np.diag(cov), 0.0)))
    n = up(x)
    tilt = float(np.degrees(np.arccos(np.clip(abs(n @ n0), -1.0, 1.0))))
    tilt_std = float(np.sqrt(std[3] ** 2 + std[4] ** 2) / np.sqrt(2)) if free == 5 else 0.0
    resid = _unit(f @ c.T)
    pred = _unit(rots @ n)
    err = np.degrees(np.arccos(np.clip(np.einsum('ij,ij->i', resid, pred), -1.0, 1.0)))
    return MountFit(c, std[:3], n, tilt, tilt_std, free == 5,
                    dict(zip(poses, err.tolist())), spread, warnings)


def gravity_spread_warning(gravity: Dict[str, np.ndarray], min_spread_deg: float = 10.0
                           ) -> List[str]:
    """Warn when the gravity directions in the IMU frame all lie within a narrow cone."""
    f = _unit(np.array(list(gravity.values())))
    if len(f) < 2:
        return []
    mean = _unit(f.mean(axis=0))
    spread = float(np.degrees(np.arccos(np.clip(f @ mean, -1.0, 1.0))).max())
    if spread >= min_spread_deg:
        return []
    return [f'the rig was held at nearly one attitude (gravity within {spread:.1f} deg): '
            'the rotation about the vertical is weakly determined; add poses tilted by '
            '20-40 deg forwards, backwards and sideways']
