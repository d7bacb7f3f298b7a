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

Uncertainty (:mod:`.wahba`): the information matrix ``sum w_i (I - f_i f_i^T)`` of the
small rotation, the residual-based noise estimate and a Student-t small-sample factor; the
roll/pitch/yaw standard deviations follow by linearisation. When all gravity directions are
(within 1 deg) parallel the rotation about them is undetermined and the calibration is
refused (:class:`.wahba.UnconstrainedBoresightError`); a spread under ~10 deg warns.

Without a prior the floor of each position is chosen by :mod:`.floor_assign`, which refuses
(:class:`.floor_assign.AmbiguousFloorError`) when several plane assignments fit. A prior is
checked against the same search: when it is farther than the floor search's cone
(``max_tilt_deg``) from every assignment the data leave (e.g. a yaw 180 deg off that picks
an assignment the floor height rules out), the data win when they leave one assignment
(said in the warnings), else the calibration is refused with the reason.

Validation as in paper B (Fig. 10): the angle between ``R n_i`` and ``f_i`` per position,
and a hold-out: fit on the even positions and test on the odd ones, and vice versa.
"""
from dataclasses import dataclass, field
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from accelcal_ros.boresight_file import load_boresight  # noqa: F401 - its home is the ground floor
from accelcal_ros.errors import CalibrationError, GeometryError, InputError
from accelcal_ros.frames import rotation_matrix_from_list, rpy_radians_from_rotation
from accelcal_ros.lidar.floor_assign import (FloorCandidate, judged_candidates, PlaneSet,
                                             select_floor)
from accelcal_ros.lidar.plane_fit import find_floor, find_planes, FloorSearch
from accelcal_ros.lidar.wahba import (check_constrained, holdout, observability_warnings,
                                      pair_errors_deg, rotation_angle_deg, rotation_covariance,
                                      rpy_std_deg, solve_wahba)
from accelcal_ros.recording.progress import track
from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2
from accelcal_ros.uncertainty import floor_each_at_known_error, KnownError
import numpy as np
from numpy.typing import ArrayLike

PathLike = Union[str, 'os.PathLike[str]']

MAX_CALIBRATED_GRAVITY_ERROR = 0.03
"""Largest relative deviation of |f| from 1 g after an accelerometer calibration."""


@dataclass
class StaticPosition:
    """One static position: name, LiDAR points (N, 3) m, specific force (IMU frame)."""

    name: str
    points: np.ndarray
    gravity_m_s2: np.ndarray
    gravity_std_rad: float = 0.0
    calibrated: bool = False
    """True when an accelerometer calibration was applied: then |g| must be ~1 g."""


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
    def mean_error_deg(self) -> float:
        """Return the mean per-position error (deg)."""
        return float(np.mean(self.per_position_error_deg))

    def to_dict(self) -> Dict[str, Any]:
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


def calibrate_boresight(positions: Sequence[StaticPosition], prior: Optional[ArrayLike] = None,
                        search: Optional[FloorSearch] = None, weighting: str = 'equal',
                        tolerance_deg: float = 3.0, max_pair_error_deg: float = 2.0,
                        height_margin_m: float = 0.1) -> 'BoresightResult':
    """
    Calibrate the boresight from :class:`StaticPosition` list; returns BoresightResult.

    ``prior`` (3x3, LiDAR -> IMU, the nominal mounting) guides the floor search (ceiling
    removal and gravity-guided MSAC). Without it every position's dominant planes are
    candidates and :func:`accelcal_ros.lidar.floor_assign.select_floor` picks the floor
    consistent with one rotation (refusing when several assignments fit; floor heights that
    spread much more than the tightest assignment's, by ``height_margin_m`` at least, rule an
    assignment out); the floors are then searched again with that rotation as the prior.
    Positions whose gravity directions leave an angle undetermined are refused
    (:class:`UnconstrainedBoresightError`). A position without a usable floor, or whose pair
    disagrees with the others by more than ``max_pair_error_deg`` after a first solution, is
    dropped with the reason.
    """
    search = search or FloorSearch()
    notes = calibration_fit_warnings(positions)
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
        check_constrained([p.gravity_m_s2 for p, _ in valid], [p.name for p, _ in valid])
        cands = [PlaneSet.from_planes(find_planes(pts, search))
                 for _, pts in track(valid, 'boresight: planes per position')]
        prior, choice, floor_notes = select_floor(cands, [p.gravity_m_s2 for p, _ in valid],
                                                  tolerance_deg, height_margin_m,
                                                  max_tilt_deg=search.max_tilt_deg)
        notes += floor_notes
        for (pos, _), c in zip(valid, choice):
            if c < 0:
                dropped[pos.name] = ('no plane consistent with the rotation found at the '
                                     'other positions (floorless cloud?)')
        valid = [v for v, c in zip(valid, choice) if c >= 0]
    else:
        prior = rotation_matrix_from_list(np.asarray(prior, dtype=float).reshape(-1), 'prior')
        prior, prior_notes = _check_prior(prior, valid, search, tolerance_deg,
                                          height_margin_m)
        notes += prior_notes
    prior = rotation_matrix_from_list(np.asarray(prior, dtype=float).reshape(-1), 'prior')
    names: List[str] = []
    normal_list: List[np.ndarray] = []
    gravity_list: List[np.ndarray] = []
    variances: List[float] = []
    inliers: List[int] = []
    for pos, pts in track(valid, 'boresight: floor per position'):
        f = np.asarray(pos.gravity_m_s2, dtype=float)
        f = f / np.linalg.norm(f)
        up = prior.T @ f
        try:
            plane = find_floor(pts, search, up)
        except (GeometryError, InputError) as exc:  # drop this position, go on
            dropped[pos.name] = str(exc)
            continue
        names.append(pos.name)
        normal_list.append(plane.normal)
        gravity_list.append(np.asarray(pos.gravity_m_s2, dtype=float))
        variances.append(plane.normal_std_rad() ** 2 / 2 + pos.gravity_std_rad ** 2 / 2)
        inliers.append(len(plane.inliers))
    if len(names) < 2:
        raise CalibrationError(_too_few(names, dropped))
    normals, gravity = np.array(normal_list), np.array(gravity_list)
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
    check_constrained(gravity, names)
    warn = observability_warnings(gravity) + notes
    off = rotation_angle_deg(r, prior)
    if off >= 0.9 * search.max_tilt_deg:  # floors found at the edge of the search cone
        warn.append(f'the result is {off:.1f} deg from the prior the floors were searched '
                    f'around, near the search limit of {search.max_tilt_deg:g} deg: the prior '
                    'is probably wrong and the floors found may be other planes; rerun with a '
                    'closer prior or without one')
    cov, _ = rotation_covariance(r, normals, gravity, weights)
    rpy = np.degrees(rpy_radians_from_rotation(r))
    checks = holdout(normals, gravity, weights)
    std, cov = _honest_std(r, cov, checks, off if off >= 0.9 * search.max_tilt_deg else None,
                           warn)
    return BoresightResult(r, rpy, std, cov, names, normals, gravity, weights, errors, checks,
                           dropped, warn, inliers)


HALVES_95 = float(np.sqrt(-2.0 * np.log(0.05)))
"""95 % radius of a 2-D unit normal (chi-square, 2 degrees of freedom): 2.45."""


def _honest_std(rotation: np.ndarray, cov: np.ndarray, checks: Dict[str, Any],
                off_limit_deg: Optional[float],
                warn: List[str]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return ``(rpy_std_deg, covariance)`` never below the errors the checks know of.

    Two half fits (even and odd positions, :func:`holdout`) each have twice the full fit's
    variance, their difference four times: over two constrained axes a difference of ``d``
    deg is beyond the 95 % level (``2.45`` standard deviations, chi-square with 2 degrees
    of freedom) unless the per-angle standard deviation is at least ``d / (2 x 2.45)``;
    a smaller one is refuted by the check. A result at the floor search's limit
    (``off_limit_deg`` from the prior) may have its floors on other planes: its error is not
    below that distance. The covariance is scaled with the largest raise; the reason goes
    into ``warn``.
    """
    std = rpy_std_deg(rotation, cov)
    known = []
    halves = checks.get('even_vs_odd_rotation')
    if halves is not None:
        known.append(KnownError(halves / (2.0 * HALVES_95), f'the two half fits (even and '
                                f'odd positions) differ by {halves:.3g} deg (hold-out check)'))
    if off_limit_deg is not None:
        known.append(KnownError(off_limit_deg, f'the result is {off_limit_deg:.1f} deg from '
                                'the prior, at the floor search limit: the floors may be other '
                                'planes (search-limit check)'))
    raised, note = floor_each_at_known_error(std, known, ' deg', 'rpy_std_deg')
    if note is None:
        return std, cov
    warn.append(note)
    ratio = float(np.max(raised / np.maximum(std, 1e-300)))
    return raised, cov * ratio ** 2


def _rpy_text(rotation: np.ndarray) -> str:
    r, p, y = np.degrees(rpy_radians_from_rotation(rotation))
    return f'[{r:.1f}, {p:.1f}, {y:.1f}] deg'


def _check_prior(prior: np.ndarray, valid: Sequence[Any], search: FloorSearch,
                 tolerance_deg: float, height_margin_m: float) -> Tuple[np.ndarray, List[str]]:
    """
    Return ``(rotation to search the floors with, notes)``: the prior unless data refute it.

    The floor assignments the data allow without a prior (:func:`judged_candidates`: the
    floor height and ceiling size cues applied) are compared with the prior. A prior
    within ``search.max_tilt_deg`` (the floor search's cone) of one that is left is
    consistent. Otherwise the prior contradicts the data: when the data leave exactly one
    assignment the data win (its rotation is used, said in the notes); when they leave
    several, :class:`CalibrationError` gives the reason and the candidates. When the data
    alone cannot tell (gravity directions too alike, no planes) the prior decides.
    """
    gravity = [p.gravity_m_s2 for p, _ in valid]
    try:
        check_constrained(gravity, [p.name for p, _ in valid])
        planes = [PlaneSet.from_planes(find_planes(pts, search))
                  for _, pts in track(valid, 'boresight: checking the prior')]
        cands = judged_candidates(planes, gravity, tolerance_deg, height_margin_m)
    except (CalibrationError, GeometryError):  # the data alone cannot tell: the prior decides
        return prior, []
    left = [c for c in cands if not c.ruled_out]
    agree = search.max_tilt_deg

    def off(c: FloorCandidate) -> float:
        return rotation_angle_deg(c.rotation, prior)

    if not left or min(off(c) for c in left) <= agree:
        return prior, []
    ruled = sorted((c for c in cands if c.ruled_out and off(c) <= agree), key=off)
    why = (f'it selects the assignment {ruled[0].describe()}, ruled out because '
           f'{ruled[0].ruled_out}' if ruled else
           f'no assignment of floor/walls/ceiling within {agree:g} deg of it fits the data')
    said = f'the prior (nominal mounting) rpy {_rpy_text(prior)} contradicts the data: {why}'
    if len(left) == 1:
        data = left[0]
        return data.rotation, [f'{said}; the data win: the floor assignment found without '
                               f'the prior, rpy {_rpy_text(data.rotation)} '
                               f'({off(data):.1f} deg from the prior), is used']
    listed = '; '.join(f'{k + 1}: {c.describe()}' for k, c in enumerate(left[:6]))
    raise CalibrationError(f'{said}; without the prior {len(left)} assignments are left '
                           f'({listed}): give a prior within {agree:g} deg of the true '
                           'mounting')


def calibration_fit_warnings(positions: Sequence[StaticPosition],
                             tolerance: float = MAX_CALIBRATED_GRAVITY_ERROR) -> List[str]:
    """
    Return a warning when calibrated gravity magnitudes are far from 1 g.

    After a fitting accelerometer calibration every still position reads ``|f| = 1 g``
    within a fraction of a percent; a calibration of another sensor (or with other axes or
    units) moves it by percents and tilts the gravity directions, so floors disagree and
    positions get dropped. Names the positions outside ``1 +- tolerance`` g.
    """
    bad = []
    for pos in positions:
        g = np.asarray(pos.gravity_m_s2, dtype=float).reshape(-1)
        if not pos.calibrated or g.shape != (3,) or not np.all(np.isfinite(g)):
            continue
        ratio = float(np.linalg.norm(g) / STANDARD_GRAVITY_M_S2)
        if abs(ratio - 1.0) > tolerance:
            bad.append((pos.name, ratio))
    if not bad:
        return []
    listed = ', '.join(f'{name} {ratio:.3f} g' for name, ratio in bad)
    total = sum(1 for p in positions if p.calibrated)
    return [f'the accelerometer calibration does not fit these IMU logs: after it |g| is '
            f'{listed} at {len(bad)} of {total} positions (expected 1 g within '
            f'{100 * tolerance:g} %); check that the calibration file belongs to this sensor '
            f'and its axes and units (the gravity directions, hence the boresight, are biased)']


def _too_few(kept, dropped):
    reasons = '; '.join(f'{k}: {v}' for k, v in dropped.items()) or 'none given'
    return (f'only {len(kept)} usable position(s), need at least 2 (3 or more with '
            f'different tilts to constrain all angles); dropped: {reasons}')
