r"""
Floor plane in a LiDAR cloud: thinning, crop, ceiling removal and MSAC (paper B).

Frames and units: points in the LiDAR frame (m); the scanner origin is ``(0, 0, 0)``.
A plane is ``n . x + d = 0`` with unit ``n`` (paper B's ``Ax + By + Cz + D = 0``). The
normal is oriented **towards the scanner** (``d > 0``: the origin lies on the positive
side), so a floor's normal points up -- the direction of the specific force ``f`` an
accelerometer reads at rest -- and a ceiling's points down. No prior is needed for that.

Paper B's preparation, made general (:class:`FloorSearch`):

- thinning: one point per voxel of ``voxel_m`` (centroid), as PCL's VoxelGrid;
- crop: points further than ``max_range_m`` (or nearer than ``min_range_m``) are dropped
  (the paper keeps a sphere smaller than the one touching the floor);
- ceiling removal, when the up direction is known in the LiDAR frame (a prior): paper B
  lifts the origin ``ceiling_lift_m`` (10 m) along up and drops every point within
  ``ceiling_radius_m`` (11.6 m) of it; with ``ceiling_radius_m = 0`` the simpler half
  space "drop points higher than ``max_height_m`` above the scanner" is used instead.
- gravity-guided MSAC: with a prior, only hypotheses whose normal is within
  ``max_tilt_deg`` of up are scored (as PCL's SACMODEL_PERPENDICULAR_PLANE).

MSAC (Torr & Zisserman 2000) scores a hypothesis by ``sum(min(r_i^2, t^2))`` instead of
RANSAC's inlier count; hypotheses are drawn in vectorised batches, the number of
iterations adapts to the inlier ratio (confidence ``confidence``), and the best model is
refitted by total least squares (SVD of the centred inliers) with the inliers
re-selected, ``refit_iterations`` times.
"""
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

from accelcal_ros.errors import GeometryError, InputError
import numpy as np
from numpy.typing import ArrayLike


@dataclass
class Plane:
    """Unit normal ``normal`` (towards the scanner), offset ``d`` (m), inlier indices."""

    normal: np.ndarray
    d: float
    inliers: np.ndarray
    rms_m: float
    normal_cov: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    extent_m: tuple = (0.0, 0.0)

    def distances(self, points: ArrayLike) -> np.ndarray:
        """Compute the signed distance (m) of each of ``(N, 3)`` points to the plane."""
        return np.asarray(points) @ self.normal + self.d

    def normal_std_rad(self) -> float:
        """Return the angular standard deviation (rad) of the normal (total, 2 axes)."""
        return float(np.sqrt(max(np.trace(self.normal_cov), 0.0)))


@dataclass
class FloorSearch:
    """Parameters of the floor search (see the module docstring)."""

    voxel_m: float = 0.0
    min_range_m: float = 0.3
    max_range_m: float = 30.0
    ceiling_lift_m: float = 10.0
    ceiling_radius_m: float = 0.0
    max_height_m: float = -0.2
    max_tilt_deg: float = 15.0
    distance_threshold_m: float = 0.05
    max_iterations: int = 1000
    confidence: float = 0.999
    refit_iterations: int = 3
    min_inliers: int = 100
    min_extent_m: float = 0.5
    max_planes: int = 6
    seed: int = 0

    def check(self) -> None:
        """Raise InputError for inconsistent values."""
        if self.distance_threshold_m <= 0:
            raise InputError('distance_threshold_m must be positive')
        if self.max_range_m <= self.min_range_m:
            raise InputError('max_range_m must exceed min_range_m')
        if not 0 < self.confidence < 1:
            raise InputError('confidence must be in (0, 1)')
        if self.max_iterations < 1 or self.min_inliers < 3:
            raise InputError('max_iterations must be >= 1 and min_inliers >= 3')


def voxel_downsample(points: ArrayLike, voxel_m: float) -> np.ndarray:
    """Return one point (the centroid) per occupied voxel of edge ``voxel_m`` (m)."""
    points = np.asarray(points, dtype=float)
    if voxel_m <= 0 or len(points) == 0:
        return points
    keys = np.floor(points / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = np.zeros((counts.size, 3))
    for k in range(3):
        sums[:, k] = np.bincount(inverse, weights=points[:, k], minlength=counts.size)
    return sums / counts[:, None]


def prepare_floor_candidates(points: ArrayLike, search: FloorSearch,
                             up: Optional[ArrayLike] = None) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the points (and their indices into ``points``) that may belong to the floor.

    Drops non-finite points, thins, crops by range and, with ``up`` (unit, LiDAR frame)
    known, removes the ceiling as paper B does.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    index = np.flatnonzero(np.all(np.isfinite(points), axis=1))
    pts = points[index]
    rng = np.linalg.norm(pts, axis=1)
    keep = (rng >= search.min_range_m) & (rng <= search.max_range_m)
    if up is not None:
        up_unit = np.asarray(up, dtype=float) / np.linalg.norm(up)
        if search.ceiling_radius_m > 0:
            centre = search.ceiling_lift_m * up_unit
            keep &= np.linalg.norm(pts - centre, axis=1) > search.ceiling_radius_m
        else:
            keep &= pts @ up_unit <= search.max_height_m
    pts, index = pts[keep], index[keep]
    if search.voxel_m > 0 and len(pts):
        thinned = voxel_downsample(pts, search.voxel_m)
        return thinned, np.full(len(thinned), -1)
    return pts, index


def _hypotheses(pts, rng, count):
    n = len(pts)
    idx = rng.integers(0, n, size=(count, 3))
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    normal = np.cross(b - a, c - a)
    norm = np.linalg.norm(normal, axis=1)
    ok = norm > 1e-9
    normal = normal[ok] / norm[ok, None]
    d = -np.einsum('ij,ij->i', normal, a[ok])
    return normal, d


def _refit(pts, inliers):
    sel = pts[inliers]
    centre = sel.mean(axis=0)
    centred = sel - centre
    _, sing, vt = np.linalg.svd(centred, full_matrices=False)
    normal = vt[2]
    return normal, -float(normal @ centre), sing, vt


def msac_plane(points: ArrayLike, search: Optional[FloorSearch] = None,
               up: Optional[ArrayLike] = None,
               exclude: Optional[np.ndarray] = None) -> Optional[Plane]:
    """
    Fit one plane by MSAC with a least-squares refit; returns a :class:`Plane` or None.

    ``up`` (unit, same frame) restricts hypotheses to normals within
    ``search.max_tilt_deg`` of it (gravity-guided). ``exclude`` is a boolean mask of
    points not to use (planes found before). Inlier indices refer to ``points``.
    """
    search = search or FloorSearch()
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    usable = np.all(np.isfinite(pts), axis=1)
    if exclude is not None:
        usable &= ~exclude
    sub_index = np.flatnonzero(usable)
    sub = pts[sub_index]
    if len(sub) < max(3, search.min_inliers):
        return None
    rng = np.random.default_rng(search.seed)
    thr2 = search.distance_threshold_m ** 2
    cos_tilt = np.cos(np.radians(search.max_tilt_deg))
    if up is not None:
        up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    # score hypotheses on a random subset for speed, the final refit uses all points
    score_pts = sub if len(sub) <= 20000 else sub[rng.choice(len(sub), 20000, replace=False)]
    best_cost, best = np.inf, None
    needed = search.max_iterations
    done = 0
    batch = 64
    while done < min(needed, search.max_iterations):
        normal, d = _hypotheses(sub, rng, batch)
        done += batch
        if up is not None and len(normal):
            keep = np.abs(normal @ up) >= cos_tilt
            normal, d = normal[keep], d[keep]
        if not len(normal):
            continue
        resid = score_pts @ normal.T + d
        cost = np.minimum(resid * resid, thr2).sum(axis=0)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best_cost, best = cost[k], (normal[k], d[k])
            ratio = float(np.mean(np.abs(resid[:, k]) < search.distance_threshold_m))
            if ratio > 0:
                fail = 1.0 - ratio ** 3
                needed = int(np.ceil(np.log(1 - search.confidence)
                                     / np.log(max(fail, 1e-12)))) if fail > 0 else batch
    if best is None:
        return None
    normal, d = best
    inliers = np.flatnonzero(np.abs(sub @ normal + d) < search.distance_threshold_m)
    sing, vt = np.zeros(3), np.eye(3)
    for _ in range(max(1, search.refit_iterations)):
        if len(inliers) < 3:
            return None
        normal, d, sing, vt = _refit(sub, inliers)
        new = np.flatnonzero(np.abs(sub @ normal + d) < search.distance_threshold_m)
        if np.array_equal(new, inliers):
            break
        inliers = new
    if len(inliers) < search.min_inliers:
        return None
    if up is not None and abs(normal @ up) < cos_tilt:
        return None
    if d < 0:
        normal, d = -normal, -d
    resid = sub[inliers] @ normal + d
    rms = float(np.sqrt(np.mean(resid ** 2)))
    n_in = len(inliers)
    spread = sing[:2] / np.sqrt(n_in)
    sigma2 = max(rms, 1e-4) ** 2
    cov = np.zeros((3, 3))
    for k in range(2):
        cov += sigma2 / max(sing[k] ** 2, 1e-12) * np.outer(vt[k], vt[k])
    return Plane(normal, float(d), sub_index[inliers], rms, cov,
                 (float(2 * spread[0]), float(2 * spread[1])))


def find_floor(points: ArrayLike, search: Optional[FloorSearch] = None,
               up: Optional[ArrayLike] = None) -> Plane:
    """
    Return the floor :class:`Plane` in a LiDAR cloud, or raise GeometryError with why not.

    Without ``up``: the plane with the best MSAC score among the candidates. Use
    :func:`find_planes` plus :func:`accelcal_ros.lidar.floor_assign.select_floor` when no
    prior is known (it picks per position the plane consistent with one rotation).
    """
    search = search or FloorSearch()
    search.check()
    cand, index = prepare_floor_candidates(points, search, up)
    if len(cand) < search.min_inliers:
        raise GeometryError(f'only {len(cand)} points left after cropping (need '
                            f'{search.min_inliers}): empty cloud, or no floor in range')
    plane = msac_plane(cand, search, up)
    if plane is None:
        what = (f'within {search.max_tilt_deg:g} deg of the expected floor normal '
                if up is not None else '')
        raise GeometryError(f'no plane {what}with at least {search.min_inliers} inliers '
                            f'(threshold {search.distance_threshold_m:g} m): no floor seen')
    if min(plane.extent_m) < search.min_extent_m:
        raise GeometryError(f'floor patch too narrow ({plane.extent_m[0]:.2f} x '
                            f'{plane.extent_m[1]:.2f} m, need {search.min_extent_m:g} m): '
                            'the normal is not constrained')
    if index[0:1].size and index[0] >= 0:
        plane.inliers = index[plane.inliers]
    return plane


def find_planes(points: ArrayLike, search: Optional[FloorSearch] = None,
                max_planes: Optional[int] = None) -> List[Plane]:
    """
    Return up to ``max_planes`` dominant planes (sequential MSAC), largest first.

    Used without a gravity prior: each plane is a floor candidate (floor, walls, ceiling,
    furniture); the boresight solver picks the one consistent across positions.
    """
    search = search or FloorSearch()
    search.check()
    cand, index = prepare_floor_candidates(points, search, None)
    planes = []
    used = np.zeros(len(cand), dtype=bool)
    for k in range(max_planes or search.max_planes):
        if (~used).sum() < search.min_inliers:
            break
        sub_search = FloorSearch(**{**search.__dict__, 'seed': search.seed + k})
        plane = msac_plane(cand, sub_search, None, exclude=used)
        if plane is None:
            break
        used[plane.inliers] = True
        if min(plane.extent_m) < search.min_extent_m:
            continue
        if index[0:1].size and index[0] >= 0:
            plane.inliers = index[plane.inliers]
        planes.append(plane)
    return planes


def plane_angle_deg(n1: ArrayLike, n2: ArrayLike, signed: bool = True) -> float:
    """Return the angle (deg) between two normals (``signed=False``: up to sign)."""
    c = float(np.dot(n1, n2) / (np.linalg.norm(n1) * np.linalg.norm(n2)))
    if not signed:
        c = abs(c)
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


@dataclass
class FloorResult:
    """Per-position outcome used by the boresight solver: plane or a reason it failed."""

    plane: Optional[Plane]
    reason: str = ''
