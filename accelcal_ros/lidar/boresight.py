r"""
LiDAR-IMU boresight rotation from static positions (paper B, "finding the DCM").

Frames: ``R`` maps LiDAR vectors into the IMU frame, ``v_imu = R v_lidar``; its angles are
REP-103 fixed-axis ``R = Rz(yaw) Ry(pitch) Rx(roll)``. At a static position ``i`` the
accelerometer reads the specific force ``f_i`` (IMU frame, up, REP-145) and the floor's
normal ``n_i`` (LiDAR frame, oriented towards the scanner, i.e. up) is found in the cloud
(:mod:`.plane_fit`). Paper B solves ``min_R sum ||R n_i - g_i||`` by least squares; here
the same problem is solved exactly as Wahba's problem,

.. math::  \min_R \sum_i w_i \| \hat f_i - R \hat n_i \|^2,

by the SVD of ``B = sum w_i f_i n_i^T`` (Markley 1988): ``R = U diag(1, 1, det U det V) V^T``.
The weights are all equal (the paper; the default) or, optionally, ``1 / sigma_i^2`` from
each pair's noise (plane-fit normal covariance plus the standard error of the mean gravity
direction). On the simulated protocol equal weights are better (0.009 vs 0.026 deg): the
per-position normal errors (~0.03 deg) are dominated by systematic effects (wall and
furniture points near the floor inside the inlier band) that the noise model ignores.

Uncertainty: with ``R_true = exp([dtheta]x) R``, ``cov(dtheta) = (sum w_i [f_i]x^T
[f_i]x)^-1`` (Shuster's QUEST covariance) scaled by the a-posteriori variance factor;
the roll/pitch/yaw standard deviations follow by linearisation. The positions constrain
all three angles only when the gravity directions are not all (anti)parallel: a small
eigenvalue of ``sum (I - f f^T)`` gives a warning naming the unconstrained axis.

Validation as in paper B (Fig. 10): the angle between ``R n_i`` and ``f_i`` per position,
and a hold-out: fit on the even positions and test on the odd ones, and vice versa.
"""
from dataclasses import dataclass, field
from itertools import combinations
from typing import List

from accelcal_ros.errors import CalibrationError, InputError
from accelcal_ros.frames import rotation_matrix_from_list, rpy_radians_from_rotation
from accelcal_ros.lidar.plane_fit import find_floor, find_planes, FloorSearch
import numpy as np
from scipy.spatial.transform import Rotation

MIN_CONSTRAINT_EIGENVALUE = 0.03
"""Smallest eigenvalue of mean(I - f f^T) below which an axis is reported unconstrained
(about 10 deg of spread of the gravity directions around that axis)."""


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def solve_wahba(normals, gravity, weights=None):
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


def pair_errors_deg(rotation, normals, gravity):
    """Return per-pair angles (deg) between ``R n_i`` and ``f_i`` (paper B Fig. 10)."""
    rn = _unit(np.asarray(normals, dtype=float).reshape(-1, 3)) @ np.asarray(rotation).T
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    sin = np.linalg.norm(np.cross(rn, f), axis=1)
    return np.degrees(np.arctan2(sin, np.einsum('ij,ij->i', rn, f)))


def constraint_eigen(gravity):
    """Return eigenvalues (ascending) and eigenvectors of ``mean(I - f f^T)``."""
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    m = np.eye(3) - np.einsum('ij,ik->jk', f, f) / len(f)
    return np.linalg.eigh(m)


def observability_warnings(gravity, threshold=MIN_CONSTRAINT_EIGENVALUE):
    """Return warnings when the gravity directions leave an angle unconstrained."""
    values, vectors = constraint_eigen(gravity)
    if values[0] >= threshold:
        return []
    axis = vectors[:, 0] * np.sign(vectors[np.argmax(np.abs(vectors[:, 0])), 0])
    spread = np.degrees(np.arcsin(np.sqrt(min(1.0, 2 * max(values[0], 0.0)))))
    return [f'the positions do not constrain the rotation about the IMU axis '
            f'[{axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f}] (gravity directions spread only '
            f'~{spread:.1f} deg around it): add positions tilted about another axis']


def rotation_covariance(rotation, normals, gravity, weights=None):
    """
    Return ``(cov, sigma0_sq)``: covariance (rad^2) of the small rotation vector (IMU frame).

    ``weights`` are ``1 / sigma_i^2`` (rad^-2) when known; the covariance is scaled by the
    a-posteriori variance factor ``sigma0^2 = sum w r^2 / (2N - 3)`` (1 when N < 3).
    """
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    rn = _unit(np.asarray(normals, dtype=float).reshape(-1, 3)) @ np.asarray(rotation).T
    w = np.ones(len(f)) if weights is None else np.asarray(weights, dtype=float)
    info = sum(wi * (np.eye(3) - np.outer(fi, fi)) for wi, fi in zip(w, f))
    resid2 = np.sum((f - rn) ** 2, axis=1)
    dof = 2 * len(f) - 3
    sigma0_sq = float(np.sum(w * resid2) / dof) if dof > 0 else 1.0
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.inf)
    return cov * sigma0_sq, sigma0_sq


def rpy_std_deg(rotation, cov):
    """Return roll/pitch/yaw standard deviations (deg) from a rotation-vector covariance."""
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


def rotation_angle_deg(r1, r2):
    """Return the angle (deg) of the rotation ``r1 r2^T``."""
    rel = np.asarray(r1) @ np.asarray(r2).T
    u, _, vt = np.linalg.svd(rel)
    return float(np.degrees(Rotation.from_matrix(u @ vt).magnitude()))


def holdout(normals, gravity, weights=None):
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
    result = {'per_position': [None if np.isnan(v) else float(v) for v in per]}
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


def assign_floors(candidates, gravity, tolerance_deg=3.0, max_pairs=60, seed=0):
    """
    Pick per position the plane consistent with one rotation across all positions.

    ``candidates[i]`` is an (k_i, 3) array of plane normals (oriented towards the scanner)
    at position ``i``; ``gravity[i]`` the specific force there. Hypotheses ``R`` come from
    two positions and one candidate each (rotations keep the angle between the pair, a
    cheap pre-filter); each is scored MSAC-style over all positions. Returns
    ``(R, choice)`` with ``choice[i]`` the chosen candidate index or -1.
    """
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    cands = [np.asarray(c, dtype=float).reshape(-1, 3) for c in candidates]
    owners = np.concatenate([np.full(len(c), i) for i, c in enumerate(cands)]).astype(int)
    if owners.size == 0:
        raise CalibrationError('no plane found at any position')
    stacked = _unit(np.concatenate(cands))
    tol = np.radians(tolerance_deg)
    pairs = []
    for i, j in combinations(range(len(cands)), 2):
        angle = np.arccos(np.clip(f[i] @ f[j], -1.0, 1.0))
        if np.radians(15) < angle < np.radians(165) and len(cands[i]) and len(cands[j]):
            pairs.append((i, j, angle))
    if not pairs:
        raise CalibrationError('the gravity directions of the positions are all parallel: '
                               'the floor cannot be identified without --prior-rpy-deg')
    rng = np.random.default_rng(seed)
    if len(pairs) > max_pairs:
        pairs = [pairs[k] for k in rng.choice(len(pairs), max_pairs, replace=False)]
    best = None
    counts = np.bincount(owners, minlength=len(cands))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    has = counts > 0
    for i, j, angle in pairs:
        for a in cands[i]:
            for b in cands[j]:
                ab = np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))
                if abs(ab - angle) > 2 * tol:
                    continue
                r = solve_wahba([a, b], [f[i], f[j]])
                err = np.arccos(np.clip(np.einsum('ij,ij->i', stacked @ r.T, f[owners]),
                                        -1.0, 1.0))
                per = np.full(len(cands), np.pi)
                per[has] = np.minimum.reduceat(err, starts[has])
                cost = float(np.minimum(per ** 2, tol ** 2).sum())
                if best is None or cost < best[0]:
                    best = (cost, r)
    if best is None:
        raise CalibrationError('no pair of planes is consistent with the gravity directions')
    r = best[1]
    choice = np.full(len(cands), -1)
    normals, grav = [], []
    for k in range(2):
        for i, c in enumerate(cands):
            if not len(c):
                continue
            err = pair_errors_deg(r, c, np.repeat(f[i:i + 1], len(c), axis=0))
            m = int(np.argmin(err))
            if err[m] <= tolerance_deg * (1 if k else 1.5):
                choice[i] = m
        sel = np.flatnonzero(choice >= 0)
        if len(sel) >= 2:
            normals = [cands[i][choice[i]] for i in sel]
            grav = [f[i] for i in sel]
            r = solve_wahba(normals, grav)
    return r, choice


@dataclass
class StaticPosition:
    """One static position: name, LiDAR points (N, 3) m, specific force (IMU frame)."""

    name: str
    points: np.ndarray
    gravity_m_s2: np.ndarray
    gravity_std_rad: float = 0.0


@dataclass
class BoresightResult:
    """Everything the boresight calibration found (angles in degrees where named so)."""

    rotation: np.ndarray
    rpy_deg: np.ndarray
    rpy_std_deg: np.ndarray
    covariance_rad2: np.ndarray
    positions: List[str]
    normals: np.ndarray
    gravity: np.ndarray
    weights: np.ndarray
    per_position_error_deg: np.ndarray
    holdout: dict
    dropped: dict = field(default_factory=dict)
    warnings: List[str] = field(default_factory=list)
    inliers: List[int] = field(default_factory=list)

    @property
    def mean_error_deg(self):
        """Return the mean per-position error (deg)."""
        return float(np.mean(self.per_position_error_deg))

    def to_dict(self):
        """Return the YAML mapping (keys documented in docs/lidar.md)."""
        return {
            'R': [float(v) for v in self.rotation.reshape(-1)],
            'rpy_deg': [float(v) for v in self.rpy_deg],
            'rpy_std_deg': [float(v) for v in self.rpy_std_deg],
            'convention': 'R maps LiDAR vectors into the IMU frame; '
                          'R = Rz(yaw) Ry(pitch) Rx(roll) (REP-103 fixed axes)',
            'positions': list(self.positions),
            'per_position_error_deg': [float(v) for v in self.per_position_error_deg],
            'mean_error_deg': self.mean_error_deg,
            'max_error_deg': float(np.max(self.per_position_error_deg)),
            'holdout_error_deg': self.holdout,
            'rotation_covariance_rad2': [float(v) for v in self.covariance_rad2.reshape(-1)],
            'floor_normals_lidar': [[float(x) for x in n] for n in self.normals],
            'gravity_imu_m_s2': [[float(x) for x in g] for g in self.gravity],
            'floor_inliers': [int(v) for v in self.inliers],
            'dropped': dict(self.dropped),
            'warnings': list(self.warnings),
        }


def calibrate_boresight(positions, prior=None, search=None, weighting='equal',
                        tolerance_deg=3.0, max_pair_error_deg=2.0):
    """
    Calibrate the boresight from :class:`StaticPosition` list; returns BoresightResult.

    ``prior`` (3x3, LiDAR -> IMU, the nominal mounting) guides the floor search (ceiling
    removal and gravity-guided MSAC). Without it every position's dominant planes are
    candidates and :func:`assign_floors` picks the floor consistent with one rotation; the
    floors are then searched again with that rotation as the prior. A position without a
    usable floor, or whose pair disagrees with the others by more than
    ``max_pair_error_deg`` after a first solution, is dropped with the reason.
    """
    search = search or FloorSearch()
    if weighting not in ('noise', 'equal'):
        raise InputError(f'weighting must be noise or equal, got {weighting!r}')
    dropped = {}
    valid = []
    for pos in positions:
        g = np.asarray(pos.gravity_m_s2, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) < 1.0:
            dropped[pos.name] = f'no usable gravity vector ({g})'
            continue
        pts = np.asarray(pos.points, dtype=float).reshape(-1, 3)
        finite = np.all(np.isfinite(pts), axis=1)
        if not finite.any():
            dropped[pos.name] = 'empty cloud (no finite points)'
            continue
        valid.append((pos, pts[finite]))
    if prior is None:
        if len(valid) < 2:
            raise CalibrationError(_too_few(valid, dropped))
        cands = []
        for pos, pts in valid:
            planes = find_planes(pts, search)
            cands.append(np.array([p.normal for p in planes]).reshape(-1, 3))
        prior, choice = assign_floors(cands, [p.gravity_m_s2 for p, _ in valid],
                                      tolerance_deg)
        for (pos, _), c in zip(valid, choice):
            if c < 0:
                dropped[pos.name] = ('no plane consistent with the rotation found at the '
                                     'other positions (floorless cloud?)')
        valid = [v for v, c in zip(valid, choice) if c >= 0]
    prior = rotation_matrix_from_list(np.asarray(prior, dtype=float).reshape(-1), 'prior')
    names, normals, gravity, variances, inliers = [], [], [], [], []
    for pos, pts in valid:
        f = _unit(np.asarray(pos.gravity_m_s2, dtype=float))
        up = prior.T @ f
        try:
            plane = find_floor(pts, search, up)
        except Exception as exc:  # GeometryError: drop this position, go on
            dropped[pos.name] = str(exc)
            continue
        names.append(pos.name)
        normals.append(plane.normal)
        gravity.append(np.asarray(pos.gravity_m_s2, dtype=float))
        variances.append(plane.normal_std_rad() ** 2 / 2 + pos.gravity_std_rad ** 2 / 2)
        inliers.append(len(plane.inliers))
    if len(names) < 2:
        raise CalibrationError(_too_few(names, dropped))
    normals, gravity = np.array(normals), np.array(gravity)
    var = np.maximum(np.array(variances), (1e-5) ** 2)
    weights = 1.0 / var if weighting == 'noise' else np.ones(len(names))
    weights = weights / weights.mean()
    r = solve_wahba(normals, gravity, weights)
    errors = pair_errors_deg(r, normals, gravity)
    bad = errors > max_pair_error_deg
    if bad.any() and (~bad).sum() >= 2:
        for k in np.flatnonzero(bad):
            dropped[names[k]] = (f'floor normal disagrees with the other positions by '
                                 f'{errors[k]:.2f} deg (> {max_pair_error_deg:g} deg)')
        keep = ~bad
        names = [n for n, k in zip(names, keep) if k]
        normals, gravity, weights = normals[keep], gravity[keep], weights[keep]
        inliers = [v for v, k in zip(inliers, keep) if k]
        r = solve_wahba(normals, gravity, weights)
        errors = pair_errors_deg(r, normals, gravity)
    warn = observability_warnings(gravity)
    cov, _ = rotation_covariance(r, normals, gravity, weights)
    rpy = np.degrees(rpy_radians_from_rotation(r))
    return BoresightResult(r, rpy, rpy_std_deg(r, cov), cov, names, normals, gravity,
                           weights, errors, holdout(normals, gravity, weights), dropped,
                           warn, inliers)


def _too_few(kept, dropped):
    reasons = '; '.join(f'{k}: {v}' for k, v in dropped.items()) or 'none given'
    return (f'only {len(kept)} usable position(s), need at least 2 (3 or more with '
            f'different tilts to constrain all angles); dropped: {reasons}')


def load_boresight(path):
    """Return the 3x3 rotation (LiDAR -> IMU) from a boresight YAML (``R`` or ``rpy_deg``)."""
    from accelcal_ros.errors import FileFormatError
    from accelcal_ros.fileio import load_yaml_mapping
    from accelcal_ros.frames import rotation_from_rpy_radians

    data = load_yaml_mapping(path, 'boresight file')
    try:
        if 'R' in data:
            return rotation_matrix_from_list(data['R'], 'R', tolerance=1e-4)
        if 'rpy_deg' in data:
            rpy = np.radians(np.asarray(data['rpy_deg'], dtype=float).reshape(3))
            return rotation_from_rpy_radians(*rpy)
    except (InputError, ValueError, TypeError) as exc:
        raise FileFormatError(path, f'bad boresight: {exc}') from None
    raise FileFormatError(path, 'boresight file has neither R (9 values) nor rpy_deg (3)')
