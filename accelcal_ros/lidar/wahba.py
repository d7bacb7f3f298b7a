r"""
Wahba's problem for the boresight: solution, uncertainty, observability and hold-out.

``R`` maps LiDAR vectors into the IMU frame (``v_imu = R v_lidar``). Each static position
``i`` gives a pair: the floor normal ``n_i`` (LiDAR frame, unit, towards the scanner) and
the specific force ``f_i`` (IMU frame, up). The rotation minimises

.. math::  \sum_i w_i \| \hat f_i - R \hat n_i \|^2,

solved by the SVD of ``B = sum w_i f_i n_i^T`` (Markley 1988).

Uncertainty. With ``R_true = exp([dtheta]x) R`` the information matrix of the small
rotation vector ``dtheta`` (rad, IMU frame) is ``J = sum w_i (I - f_i f_i^T)`` (Shuster's
QUEST covariance ``J^-1`` for unit noise). Only what the positions constrain enters: an
angle about a direction every ``f_i`` is parallel to has no information. The noise is
estimated from the residuals, ``s^2 = sum w_i |f_i - R n_i|^2 / (2N - 3)`` (2 components per
pair, 3 parameters), and the covariance ``s^2 J^-1`` is widened by the small-sample factor
``(t_{0.975}(2N - 3) / z_{0.975})^2`` so that ``2 sigma`` is the Student-t 95 % interval:
with 2 positions (1 degree of freedom) the residual alone says little about the noise, and
the factor is 42 (6.5 in sigma); with paper B's 15 positions it is 1.09.
"""
from typing import Any, Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.frames import rpy_radians_from_rotation
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation
from scipy.stats import norm, t as student_t

MIN_CONSTRAINT_EIGENVALUE = 0.03
"""Smallest eigenvalue of mean(I - f f^T) below which an axis is reported unconstrained
(about 10 deg of spread of the gravity directions around that axis)."""

MIN_SPREAD_DEG = 1.0
"""Below this spread of the gravity directions around one axis the rotation about that
axis is refused as unconstrained (a warning between this and MIN_CONSTRAINT_EIGENVALUE)."""


class UnconstrainedBoresightError(CalibrationError):
    """The positions leave a rotation angle undetermined (all gravity vectors parallel)."""


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def solve_wahba(normals: ArrayLike, gravity: ArrayLike,
                weights: Optional[ArrayLike] = None) -> np.ndarray:
    """
    Return the rotation ``R`` (3x3, LiDAR -> IMU) minimising ``sum w |f - R n|^2``.

    ``normals`` (N, 3) in the LiDAR frame, ``gravity`` (N, 3) in the IMU frame (any
    length; only directions are used). Needs two non-parallel pairs.
    """
    n = _unit(np.asarray(normals, dtype=float).reshape(-1, 3))
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    if len(n) != len(f) or len(n) < 2:
        raise CalibrationError(f'need at least 2 vector pairs, got {len(n)} normals and '
                               f'{len(f)} gravity vectors')
    w = np.ones(len(n)) if weights is None else np.asarray(weights, dtype=float)
    if np.any(~np.isfinite(n)) or np.any(~np.isfinite(f)) or np.any(w < 0):
        raise InputError('vector pairs contain NaN, zero vectors or negative weights')
    b = (w[:, None, None] * f[:, :, None] * n[:, None, :]).sum(axis=0)
    u, _, vt = np.linalg.svd(b)
    sign = np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0
    return u @ np.diag([1.0, 1.0, sign]) @ vt


def pair_errors_deg(rotation: ArrayLike, normals: ArrayLike, gravity: ArrayLike) -> np.ndarray:
    """Return per-pair angles (deg) between ``R n_i`` and ``f_i`` (paper B Fig. 10)."""
    rn = _unit(np.asarray(normals, dtype=float).reshape(-1, 3)) @ np.asarray(rotation).T
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    sin = np.linalg.norm(np.cross(rn, f), axis=1)
    return np.degrees(np.arctan2(sin, np.einsum('ij,ij->i', rn, f)))


def constraint_eigen(gravity: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """Return eigenvalues (ascending) and eigenvectors of ``mean(I - f f^T)``."""
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    m = np.eye(3) - np.einsum('ij,ik->jk', f, f) / len(f)
    return np.linalg.eigh(m)


def weakest_axis(gravity: ArrayLike) -> Tuple[np.ndarray, float]:
    """
    Return ``(axis, spread_deg)``: the IMU axis the gravity directions constrain least.

    ``spread_deg`` is the RMS angle of the gravity directions around that axis: 0 when all
    are parallel to it (the rotation about it is then undetermined).
    """
    values, vectors = constraint_eigen(gravity)
    axis = vectors[:, 0] * np.sign(vectors[np.argmax(np.abs(vectors[:, 0])), 0])
    spread = np.degrees(np.arcsin(np.sqrt(min(1.0, 2 * max(values[0], 0.0)))))
    return axis, float(spread)


def observability_warnings(gravity: ArrayLike,
                           threshold: float = MIN_CONSTRAINT_EIGENVALUE) -> List[str]:
    """Return warnings when the gravity directions leave an angle poorly constrained."""
    values, _ = constraint_eigen(gravity)
    if values[0] >= threshold:
        return []
    axis, spread = weakest_axis(gravity)
    return [f'the positions do not constrain the rotation about the IMU axis '
            f'[{axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f}] (gravity directions spread only '
            f'~{spread:.1f} deg around it): add positions tilted about another axis']


def check_constrained(gravity: ArrayLike, names: Optional[Sequence[str]] = None,
                      min_spread_deg: float = MIN_SPREAD_DEG) -> None:
    """
    Raise :class:`UnconstrainedBoresightError` when an angle is not determined.

    That is the case when all gravity directions lie within ``min_spread_deg`` of one axis
    (six copies of one position, several positions with the same tilt): the rotation about
    that axis can take any value.
    """
    axis, spread = weakest_axis(gravity)
    if spread >= min_spread_deg:
        return
    count = len(np.asarray(gravity).reshape(-1, 3))
    which = f' ({", ".join(names)})' if names else ''
    raise UnconstrainedBoresightError(
        f'the gravity directions of all {count} positions{which} are within {spread:.2f} deg '
        f'of the IMU axis [{axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f}]: the rotation about '
        f'that axis is not determined. Add positions tilted by 45-90 deg about two different '
        f'horizontal axes (paper B: tilts about the scanner X of -90..90 deg in 45 deg steps '
        f'and about Y of -90, 0, 90 deg)')


def small_sample_factor(dof: int) -> float:
    """Return ``(t_0.975(dof) / z_0.975)^2``: widens a residual-based variance for few dof."""
    if dof < 1:
        return float('inf')
    return float((student_t.ppf(0.975, dof) / norm.ppf(0.975)) ** 2)


def rotation_covariance(rotation: ArrayLike, normals: ArrayLike, gravity: ArrayLike,
                        weights: Optional[ArrayLike] = None) -> Tuple[np.ndarray, float]:
    """
    Return ``(cov, sigma0_sq)``: covariance (rad^2) of the small rotation vector (IMU frame).

    ``cov = k s^2 J^-1`` with ``J = sum w (I - f f^T)``, the a-posteriori variance factor
    ``s^2 = sum w r^2 / (2N - 3)`` and the small-sample factor ``k``
    (:func:`small_sample_factor`). ``weights`` are relative ``1 / sigma_i^2``. An
    unconstrained direction (``J`` singular) or no degree of freedom gives ``inf``.
    """
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    rn = _unit(np.asarray(normals, dtype=float).reshape(-1, 3)) @ np.asarray(rotation).T
    w = np.ones(len(f)) if weights is None else np.asarray(weights, dtype=float)
    info = np.einsum('i,ijk->jk', w, np.eye(3)[None] - f[:, :, None] * f[:, None, :])
    resid2 = np.sum((f - rn) ** 2, axis=1)
    dof = 2 * len(f) - 3
    if dof < 1:
        return np.full((3, 3), np.inf), float('inf')
    sigma0_sq = float(np.sum(w * resid2) / dof)
    values, vectors = np.linalg.eigh(info)
    if values[0] <= 1e-12 * max(values[-1], 1e-300):
        return np.full((3, 3), np.inf), sigma0_sq
    cov = vectors @ np.diag(1.0 / values) @ vectors.T
    return cov * sigma0_sq * small_sample_factor(dof), sigma0_sq


def rpy_std_deg(rotation: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Return roll/pitch/yaw standard deviations (deg) from a rotation-vector covariance."""
    if not np.all(np.isfinite(cov)):
        return np.full(3, np.inf)
    base = np.array(rpy_radians_from_rotation(rotation))
    jac = np.zeros((3, 3))
    eps = 1e-6
    for k in range(3):
        delta = np.zeros(3)
        delta[k] = eps
        moved = Rotation.from_rotvec(delta).as_matrix() @ rotation
        diff = np.array(rpy_radians_from_rotation(moved)) - base
        jac[:, k] = (diff + np.pi) % (2 * np.pi) - np.pi
    jac /= eps
    var = np.diag(jac @ cov @ jac.T)
    return np.degrees(np.sqrt(np.maximum(var, 0.0)))


def rotation_angle_deg(r1: ArrayLike, r2: ArrayLike) -> float:
    """Return the angle (deg) of the rotation ``r1 r2^T``."""
    rel = np.asarray(r1) @ np.asarray(r2).T
    u, _, vt = np.linalg.svd(rel)
    return float(np.degrees(Rotation.from_matrix(u @ vt).magnitude()))


def holdout(normals: ArrayLike, gravity: ArrayLike,
            weights: Optional[ArrayLike] = None) -> Dict[str, Any]:
    """
    Paper B's hold-out: fit on even positions, test on odd ones and vice versa.

    Returns a dict with each position's error (deg) under the fit that excluded it,
    their mean and max, the two half-fit means and the angle between the two half fits
    (None entries when a half cannot determine a rotation).
    """
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    f = np.asarray(gravity, dtype=float).reshape(-1, 3)
    w = np.ones(len(n)) if weights is None else np.asarray(weights, dtype=float)
    idx = np.arange(len(n))
    per = np.full(len(n), np.nan)
    fits = {}
    for name, fit_mask in (('even', idx % 2 == 0), ('odd', idx % 2 == 1)):
        if fit_mask.sum() < 2 or constraint_eigen(f[fit_mask])[0][0] < MIN_CONSTRAINT_EIGENVALUE:
            continue
        r = solve_wahba(n[fit_mask], f[fit_mask], w[fit_mask])
        fits[name] = r
        test = ~fit_mask
        per[test] = pair_errors_deg(r, n[test], f[test])
    result: Dict[str, Any] = {'per_position': [None if np.isnan(v) else float(v)
                                               for v in per]}
    ok = per[~np.isnan(per)]
    result['mean'] = float(ok.mean()) if ok.size else None
    result['max'] = float(ok.max()) if ok.size else None
    result['fit_even_test_odd_mean'] = (float(np.nanmean(per[idx % 2 == 1]))
                                        if 'even' in fits and (idx % 2 == 1).any() else None)
    result['fit_odd_test_even_mean'] = (float(np.nanmean(per[idx % 2 == 0]))
                                        if 'odd' in fits else None)
    result['even_vs_odd_rotation'] = (rotation_angle_deg(fits['even'], fits['odd'])
                                      if len(fits) == 2 else None)
    return result
