r"""
Which plane is the floor at each position, without a prior on the mounting.

Every position gives a few dominant planes (:func:`accelcal_ros.lidar.plane_fit.find_planes`:
floor, walls, ceiling, furniture), each with its unit normal ``n`` (LiDAR frame, towards the
scanner) and offset ``d`` (m, the scanner's distance to the plane). One rotation ``R``
(LiDAR -> IMU) must carry the floor normal onto the specific force at every position,
``R n_i = f_i``. In a room with several large planes more than one assignment of planes to
positions can fit: in a box-shaped room whose ceiling and walls are seen as well as the
floor, each half turn about a LiDAR axis maps, under paper B's tilts, every position's floor
to another plane of the room (a wall or the ceiling), and the residuals are as small as the
truth's.

:func:`floor_candidates` finds every rotation that fits within the noise: hypotheses from
two positions and one plane each (Wahba), scored MSAC-style over all positions, clustered,
refined (per position, among the planes within ``tolerance_deg`` of up, the largest of
those lying within ``FLOOR_BAND_M`` of the lowest, so a table top never wins over the floor
under it and a small patch never over the floor it belongs to) and kept when they explain
about as many positions, as tightly, as the best and constrain all three angles.
:func:`select_floor` then applies the physical cues:

- **gravity side**: the chosen plane lies on the side the specific force points away from
  (the normal towards the scanner is carried onto ``f``), built into the assignment;
- **one floor height**: on a fixed base the floor is at the same distance below the scanner
  at every position; an assignment whose "floor" distances spread (largest deviation from
  their median) more than 3 times the tightest candidate's and by ``height_margin_m`` more
  is ruled out;
- **ceiling smaller**: a ceiling is usually cropped or seen with fewer points than the
  floor. A position where an assignment's "ceiling" (the plane facing its floor) holds
  ``size_ratio`` times more points than its "floor" counts against it; an assignment with
  at least 2 such positions more than the best one is ruled out.

When more than one candidate is left, :class:`AmbiguousFloorError` lists them (roll, pitch,
yaw in degrees) and says which prior decides.
"""
from dataclasses import dataclass, field
from itertools import combinations
from typing import Any, List, Optional, Sequence, Tuple

from accelcal_ros.errors import CalibrationError
from accelcal_ros.frames import rpy_radians_from_rotation
from accelcal_ros.lidar.wahba import (_unit, constraint_eigen, MIN_CONSTRAINT_EIGENVALUE,
                                      pair_errors_deg, rotation_angle_deg, solve_wahba)
import numpy as np
from numpy.typing import ArrayLike


FLOOR_BAND_M = 0.15
"""Planes facing up within this of the lowest one are taken as pieces of the floor (m)."""


class AmbiguousFloorError(CalibrationError):
    """More than one plane assignment fits without a prior; ``candidates`` lists them."""

    def __init__(self, message: str, candidates: Sequence['FloorCandidate']):
        super().__init__(message)
        self.candidates = list(candidates)


@dataclass
class PlaneSet:
    """Dominant planes of one position: normals (k, 3), offsets (k,) m, inlier counts (k,)."""

    normals: np.ndarray
    offsets_m: np.ndarray
    inliers: np.ndarray

    @classmethod
    def from_planes(cls, planes: Sequence[Any]) -> 'PlaneSet':
        """Build from :class:`accelcal_ros.lidar.plane_fit.Plane` objects."""
        return cls(np.array([p.normal for p in planes], dtype=float).reshape(-1, 3),
                   np.array([p.d for p in planes], dtype=float),
                   np.array([len(p.inliers) for p in planes], dtype=float))


@dataclass
class FloorCandidate:
    """One rotation and its plane per position (-1: none), with the cue figures."""

    rotation: np.ndarray
    choice: np.ndarray
    errors_deg: np.ndarray
    heights_m: np.ndarray
    smaller_floor_at: List[int] = field(default_factory=list)
    ruled_out: str = ''
    positions: List[int] = field(default_factory=list)

    @property
    def rpy_deg(self) -> np.ndarray:
        """Return roll, pitch, yaw (deg) of the rotation."""
        return np.degrees(rpy_radians_from_rotation(self.rotation))

    @property
    def count(self) -> int:
        """Return the number of positions with a floor under this rotation."""
        return int((self.choice >= 0).sum())

    @property
    def rms_deg(self) -> float:
        """Return the RMS angle (deg) between ``R n`` and ``f`` over its positions."""
        return float(np.sqrt(np.mean(self.errors_deg ** 2))) if self.count else np.inf

    @property
    def height_spread_m(self) -> float:
        """Return the largest deviation (m) of a floor distance from their median."""
        if not self.count:
            return np.inf
        return float(np.max(np.abs(self.heights_m - np.median(self.heights_m))))

    def describe(self) -> str:
        """Return one line: rpy, positions, residual and floor heights."""
        r, p, y = self.rpy_deg
        return (f'rpy [{r:.1f}, {p:.1f}, {y:.1f}] deg ({self.count} positions, rms '
                f'{self.rms_deg:.3f} deg, floor {self.heights_m.min():.2f}-'
                f'{self.heights_m.max():.2f} m below the scanner)')


def _floor_side(rotation, ps, f_i, tol_deg, sign=1.0):
    """Return the indices of the planes whose normal (times ``sign``) is within tol of up."""
    if not len(ps.normals):
        return np.zeros(0, dtype=int)
    up = np.repeat(f_i[None], len(ps.normals), 0)
    return np.flatnonzero(pair_errors_deg(rotation, sign * ps.normals, up) <= tol_deg)


def _choose(rotation, planes, f, tol_deg):
    """Return per position the floor: the largest plane near the lowest one facing up."""
    choice = np.full(len(planes), -1)
    for i, ps in enumerate(planes):
        ok = _floor_side(rotation, ps, f[i], tol_deg)
        if ok.size:
            low = ok[ps.offsets_m[ok] >= ps.offsets_m[ok].max() - FLOOR_BAND_M]
            choice[i] = low[np.argmax(ps.inliers[low])]
    return choice


def _refine(rotation, planes, f, tol_deg) -> Optional[FloorCandidate]:
    choice = np.full(len(planes), -1)
    for widen in (1.5, 1.0, 1.0):
        choice = _choose(rotation, planes, f, tol_deg * widen)
        sel = np.flatnonzero(choice >= 0)
        if len(sel) < 2:
            return None
        rotation = solve_wahba([planes[i].normals[choice[i]] for i in sel], f[sel])
    choice = _choose(rotation, planes, f, tol_deg)
    sel = np.flatnonzero(choice >= 0)
    if len(sel) < 2:
        return None
    normals = np.array([planes[i].normals[choice[i]] for i in sel])
    heights = np.array([planes[i].offsets_m[choice[i]] for i in sel])
    return FloorCandidate(rotation, choice, pair_errors_deg(rotation, normals, f[sel]), heights,
                          positions=[int(i) for i in sel])


def _hypotheses(planes, f, tol, max_pairs, seed):
    """Yield ``(cost, R)`` for rotations from two positions and one plane each."""
    pairs = []
    for i, j in combinations(range(len(planes)), 2):
        angle = np.arccos(np.clip(f[i] @ f[j], -1.0, 1.0))
        if np.radians(15) < angle < np.radians(165) and len(planes[i].normals) \
                and len(planes[j].normals):
            pairs.append((i, j, angle))
    if not pairs:
        raise CalibrationError('the gravity directions of the positions are all parallel: '
                               'the floor cannot be identified without --prior-rpy-deg; '
                               'add positions tilted by 45-90 deg about two axes')
    rng = np.random.default_rng(seed)
    if len(pairs) > max_pairs:
        pairs = [pairs[k] for k in rng.choice(len(pairs), max_pairs, replace=False)]
    owners = np.concatenate([np.full(len(p.normals), i) for i, p in enumerate(planes)])
    owners = owners.astype(int)
    stacked = _unit(np.concatenate([p.normals for p in planes]))
    counts = np.bincount(owners, minlength=len(planes))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    has = counts > 0
    out = []
    for i, j, angle in pairs:
        for a in planes[i].normals:
            for b in planes[j].normals:
                ab = np.arccos(np.clip(_unit(a) @ _unit(b), -1.0, 1.0))
                if abs(ab - angle) > 2 * tol:
                    continue
                r = solve_wahba([a, b], [f[i], f[j]])
                err = np.arccos(np.clip(np.einsum('ij,ij->i', stacked @ r.T, f[owners]),
                                        -1.0, 1.0))
                per = np.full(len(planes), np.pi)
                per[has] = np.minimum.reduceat(err, starts[has])
                out.append((float(np.minimum(per ** 2, tol ** 2).sum()), r))
    out.sort(key=lambda item: item[0])
    return out


def floor_candidates(planes: Sequence[PlaneSet], gravity: ArrayLike, tolerance_deg: float = 3.0,
                     max_pairs: int = 60, seed: int = 0,
                     max_candidates: int = 24) -> List[FloorCandidate]:
    """
    Return every rotation (with its plane per position) that fits within the noise.

    Fits: it explains at least 3/4 as many positions as the best one (and 3), its RMS
    residual is within 3 times the tightest candidate's (or 0.1 deg), and its positions
    constrain all three angles. Sorted by positions explained, then residual.
    """
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    if not any(len(p.normals) for p in planes):
        raise CalibrationError('no plane found at any position')
    tol = np.radians(tolerance_deg)
    found: List[FloorCandidate] = []
    seen = np.zeros((0, 3, 3))
    # rotations closer than 2 tolerances are one: trace(R1 R2^T) > 1 + 2 cos(2 tol)
    same = 1.0 + 2.0 * np.cos(np.radians(2 * tolerance_deg))
    for _, r in _hypotheses(planes, f, tol, max_pairs, seed):
        if len(found) >= max_candidates:
            break
        if np.any(np.einsum('kij,ij->k', seen, r) > same):
            continue
        seen = np.concatenate([seen, r[None]])
        cand = _refine(r, planes, f, tolerance_deg)
        if cand is None or any(np.sum(cand.rotation * c.rotation) > same for c in found):
            continue
        seen = np.concatenate([seen, cand.rotation[None]])
        found.append(cand)
    if not found:
        raise CalibrationError('no pair of planes is consistent with the gravity directions')
    best_count = max(c.count for c in found)
    found = [c for c in found if c.count >= max(min(3, best_count), 0.75 * best_count)]
    ref_rms = min(c.rms_deg for c in found)
    fits = [c for c in found if c.rms_deg <= max(3 * ref_rms, 0.1)
            and constraint_eigen(f[c.positions])[0][0] >= MIN_CONSTRAINT_EIGENVALUE]
    fits = fits or [min(found, key=lambda c: (-c.count, c.rms_deg))]
    fits.sort(key=lambda c: (-c.count, c.rms_deg))
    return fits


def _smaller_floor_at(cand, planes, f, tol_deg, size_ratio):
    """Return the positions where the planes facing the floor hold ``size_ratio`` x its."""
    out = []
    for i in cand.positions:
        ps = planes[i]
        floor = _floor_side(cand.rotation, ps, f[i], tol_deg)
        facing = _floor_side(cand.rotation, ps, f[i], tol_deg, -1.0)
        if facing.size and ps.inliers[facing].sum() >= size_ratio * ps.inliers[floor].sum():
            out.append(int(i))
    return out


def judged_candidates(planes: Sequence[PlaneSet], gravity: ArrayLike,
                      tolerance_deg: float = 3.0, height_margin_m: float = 0.1,
                      size_ratio: float = 2.0) -> List[FloorCandidate]:
    """
    Return every fitting assignment (:func:`floor_candidates`) with the physical cues applied.

    A candidate that the floor height or the ceiling size rules out has ``ruled_out`` set
    to the reason; the others are what the data alone leaves. Used by
    :func:`select_floor` and to check a prior against the data.
    """
    f = _unit(np.asarray(gravity, dtype=float).reshape(-1, 3))
    cands = floor_candidates(planes, f, tolerance_deg)
    if len(cands) > 1:
        tightest = min(c.height_spread_m for c in cands)
        limit = max(3 * tightest, tightest + height_margin_m)
        for c in cands:
            if c.height_spread_m > limit:
                c.ruled_out = (f'its floor would be {c.heights_m.min():.2f}-'
                               f'{c.heights_m.max():.2f} m below the scanner (one floor '
                               f'height is expected on a fixed base, spread <= {limit:.2f} m)')
    left = [c for c in cands if not c.ruled_out]
    if len(left) > 1:
        for c in left:
            c.smaller_floor_at = _smaller_floor_at(c, planes, f, tolerance_deg, size_ratio)
        fewest = min(len(c.smaller_floor_at) for c in left)
        for c in left:
            if len(c.smaller_floor_at) >= fewest + 2:
                c.ruled_out = (f'its ceiling would hold {size_ratio:g}+ times the points of '
                               f'its floor at {len(c.smaller_floor_at)} positions (a ceiling '
                               f'is usually cropped or smaller)')
    return cands


def select_floor(planes: Sequence[PlaneSet], gravity: ArrayLike, tolerance_deg: float = 3.0,
                 height_margin_m: float = 0.1, size_ratio: float = 2.0,
                 max_tilt_deg: float = 15.0) -> Tuple[np.ndarray, np.ndarray, List[str]]:
    """
    Return ``(R, choice, notes)``: the one assignment the cues leave, or raise.

    ``notes`` say which other assignments fitted and what ruled them out. Raises
    :class:`AmbiguousFloorError` (listing the candidates and the prior that decides) when
    more than one is left.
    """
    cands = judged_candidates(planes, gravity, tolerance_deg, height_margin_m, size_ratio)
    left = [c for c in cands if not c.ruled_out]
    if len(left) > 1:
        gap = min(rotation_angle_deg(a.rotation, b.rotation)
                  for a, b in combinations(left, 2))
        within = min(max_tilt_deg, gap / 2)
        listed = '; '.join(f'{k + 1}: {c.describe()}' for k, c in enumerate(left[:6]))
        if len(left) > 6:
            listed += f'; and {len(left) - 6} more'
        r, p, y = left[0].rpy_deg
        raise AmbiguousFloorError(
            f'without a prior, {len(left)} assignments of floor/walls/ceiling to the '
            f'positions fit within the noise (a box-shaped room?) and neither the floor height '
            f'nor the ceiling size tells them apart: {listed}. Give the nominal mounting with '
            f'--prior-rpy-deg R P Y (node: prior_rpy_deg), within {within:.0f} deg of the true '
            f'one; e.g. --prior-rpy-deg {r:.0f} {p:.0f} {y:.0f} selects candidate 1', left)
    chosen = left[0]
    others = [c for c in cands if c is not chosen]
    notes = [f'without a prior, {len(others)} other assignment(s) of floor/walls/ceiling also '
             f'fitted the normals and were ruled out by physical cues, e.g. '
             f'{others[0].describe()}: {others[0].ruled_out}'] if others else []
    return chosen.rotation, chosen.choice, notes
