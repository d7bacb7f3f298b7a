r"""
Closed-form Perspective-2-Point with a known vertical direction (pure core).

Paper A (Kalinkin et al. 2020), eq. (8), after Kukelova, Bujnak and Pajdla (ACCV 2010):
one calibrated camera sees two emitters ``M1``, ``M2`` with known object coordinates;
the accelerometer gives the direction of gravity in the camera frame. Unknown: the yaw
about the vertical and the translation (4 degrees of freedom, 4 equations).

Frames (the contract)
---------------------
- Camera optical frame: x right, y down, z forward (REP-103 ``_optical``).
- Object frame: z up (gravity along -z), metres; emitter coordinates within
  +-:data:`MAX_COORDINATE_M`.
- Vertical input ``down``: the unit gravity direction in the camera frame (any finite
  nonzero length is accepted: divided by its largest absolute component, then
  normalised, so 1e-200 or 1e200 neither underflow nor overflow; rays alike); from IMU
  roll/pitch use
  :func:`down_from_roll_pitch` (:func:`accelcal_ros.frames.down_in_camera`).
- Output: ``X_cam = R X_obj + t`` (object to camera; ``t`` is the object origin in the
  camera frame, ``-R^T t`` the camera centre in the object frame), and the yaw of
  :func:`yaw_from_rotation`.

Method (no angle parametrisation, hence no singularity)
-------------------------------------------------------
Every rotation with ``R [0, 0, 1]^T = -down`` is ``R = A R_z(psi)`` with a fixed ``A``
(:func:`level_basis`, built without a branch point). With unit rays ``b_i`` and level
rays ``r_i = A^T b_i``, eq. (8) says ``lambda_i r_i = R_z(psi) M_i + s`` (``s = A^T t``,
``lambda_i`` the distances along the rays). Subtracting the two equations removes ``s``;
``R_z`` keeps heights and horizontal lengths, which leaves, for ``dM = M1 - M2``,

.. math::

    \lambda_1 r_{1z} - \lambda_2 r_{2z} = dM_z                    \quad\text{(a line)}

    \|\lambda_1 r_{1h} - \lambda_2 r_{2h}\|^2 = \|dM_h\|^2         \quad\text{(an ellipse)}

in the unknowns ``(lambda_1, lambda_2)``: a line meets a conic in a **quadratic**
(the same degree as the paper's quadratic in ``q = tan(psi/2)``, but ``psi`` never
appears as an unknown). ``(cos psi, sin psi)`` is then the unit 2-vector rotating
``dM_h`` onto ``lambda_1 r_{1h} - lambda_2 r_{2h}``: a point on the circle, valid for
every yaw including 180 deg, where ``tan(psi/2)`` is infinite. Finally
``s = lambda_i r_i - R_z M_i`` and ``t = A s``.

Every real root with both emitters in front of the camera (positive depth) is
returned; there are at most two. Degenerate input is reported, never solved:
emitters on one vertical line (yaw unobservable), a zero baseline, both emitters on one
ray, a camera at the emitters' height with both emitters at one height (range
unobservable: the line equation vanishes), NaN.

Yaw
---
:func:`yaw_from_rotation`: the heading of the camera's optical axis in the object's
horizontal plane, ``atan2(a_y, a_x)`` with ``a = R^T [0, 0, 1]^T``, measured from object
+x towards +y (counter-clockwise seen from above, REP-103), in ``(-pi, pi]``. It equals the
REP-103 yaw of a camera body (x forward along the optical axis) mounted with
:data:`accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA`. When the optical axis is vertical
it is the heading of the image's top edge direction (looking down) or bottom edge
direction (looking up): the limit of a camera pitched towards vertical.
"""
from dataclasses import dataclass
from enum import IntEnum
import math
from typing import Any, Dict, List, Tuple, Union

from accelcal_ros.errors import GeometryError, InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, specific_force_from_roll_pitch
import numpy as np
from numpy.typing import ArrayLike


class SolveStatus(IntEnum):
    """Outcome of one P2P problem (:attr:`BatchSolution.status` holds these codes)."""

    OK = 0
    NOT_FINITE = 1
    ZERO_BASELINE = 2
    VERTICAL_LINE = 3
    SAME_RAY = 4
    LEVEL_DEGENERATE = 5
    LEVEL_INCONSISTENT = 6
    NO_REAL_SOLUTION = 7
    BEHIND_CAMERA = 8
    BAD_DOWN = 9
    RAY_BACKWARD = 10
    OUT_OF_RANGE = 11


OK = SolveStatus.OK
NOT_FINITE = SolveStatus.NOT_FINITE
ZERO_BASELINE = SolveStatus.ZERO_BASELINE
VERTICAL_LINE = SolveStatus.VERTICAL_LINE
SAME_RAY = SolveStatus.SAME_RAY
LEVEL_DEGENERATE = SolveStatus.LEVEL_DEGENERATE
LEVEL_INCONSISTENT = SolveStatus.LEVEL_INCONSISTENT
NO_REAL_SOLUTION = SolveStatus.NO_REAL_SOLUTION
BEHIND_CAMERA = SolveStatus.BEHIND_CAMERA
BAD_DOWN = SolveStatus.BAD_DOWN
RAY_BACKWARD = SolveStatus.RAY_BACKWARD
OUT_OF_RANGE = SolveStatus.OUT_OF_RANGE

MAX_COORDINATE_M = 1e6
"""Largest absolute emitter coordinate (object frame, m) the solver takes: beyond it the
squared baselines and ranges lose the precision (or overflow) the geometry tests need."""

REASONS: Dict[SolveStatus, str] = {
    OK: 'ok',
    NOT_FINITE: 'input contains NaN or infinity',
    ZERO_BASELINE: 'the two emitters coincide (zero baseline): give two distinct points',
    VERTICAL_LINE: 'the emitters lie on one vertical line: yaw is unobservable; use emitters '
                   'with a horizontal separation',
    SAME_RAY: 'both emitters lie on one camera ray (same image point): move the camera or '
              'check the detection',
    LEVEL_DEGENERATE: "the camera is at the emitters' height and both emitters are at one "
                      'height: the range is unobservable; raise or lower the camera',
    LEVEL_INCONSISTENT: 'both rays are horizontal but the emitters differ in height: the '
                        'vertical, the image points and the emitter coordinates disagree',
    NO_REAL_SOLUTION: 'no real solution: the image points, the vertical and the emitter '
                      'baseline are inconsistent (check the emitter order, the vertical '
                      'and the camera matrix)',
    BEHIND_CAMERA: 'no solution with both emitters in front of the camera',
    BAD_DOWN: 'the vertical ("down") vector has zero length',
    RAY_BACKWARD: 'an image ray points backwards (z <= 0 in the camera frame)',
    OUT_OF_RANGE: f'an emitter coordinate is beyond +-{MAX_COORDINATE_M:,.0f} m: give the '
                  'emitters in metres in a local object frame',
}
"""Human-readable reason of each :class:`SolveStatus`."""

_SAME_RAY_SIN = 1e-12
_VERTICAL_RELATIVE = 1e-9
_LEVEL_SIN = 1e-12
_DISCRIMINANT_RELATIVE = 1e-10


@dataclass(frozen=True)
class P2PSolution:
    """
    One pose: ``X_cam = rotation @ X_obj + translation``.

    ``yaw`` (rad) is :func:`yaw_from_rotation` of ``rotation``; ``depths`` are the two
    emitters' depths (camera z, m) in the order of the input.
    """

    rotation: np.ndarray
    translation: np.ndarray
    yaw: float
    depths: np.ndarray

    @property
    def camera_position(self) -> np.ndarray:
        """Return the camera centre in the object frame, ``-R^T t`` (m)."""
        return -self.rotation.T @ self.translation

    @property
    def range_m(self) -> float:
        """Return the distance from the camera centre to the object origin, ``||t||`` (m)."""
        return float(np.linalg.norm(self.translation))

    def to_dict(self) -> Dict[str, Any]:
        """Return the JSON form of ``accelcal p2p-solve``: ``R`` (9 row-major), ``t``, ``yaw``."""
        return {'R': [float(v) for v in self.rotation.reshape(-1)],
                't': [float(v) for v in self.translation],
                'yaw': float(self.yaw)}


@dataclass
class BatchResult:
    """
    Result of :func:`solve_batch` for ``N`` problems, two solution slots each.

    ``rotations`` ``(N, 2, 3, 3)``, ``translations`` ``(N, 2, 3)``, ``yaw`` ``(N, 2)``,
    ``depths`` ``(N, 2, 2)``: NaN where ``valid`` ``(N, 2)`` is False. ``status`` ``(N,)``
    holds :class:`SolveStatus` codes (``OK`` when at least one slot is valid). Valid
    slots come first (slot 0 is valid whenever any is).
    """

    rotations: np.ndarray
    translations: np.ndarray
    yaw: np.ndarray
    depths: np.ndarray
    valid: np.ndarray
    status: np.ndarray

    def __len__(self):
        """Return the number of problems."""
        return len(self.status)

    def reason(self, index: int) -> str:
        """Return the text reason of problem ``index``."""
        return REASONS[SolveStatus(int(self.status[index]))]

    def solutions(self, index: int) -> List['P2PSolution']:
        """Return the valid :class:`P2PSolution` list of problem ``index``."""
        out = []
        for slot in range(2):
            if self.valid[index, slot]:
                out.append(P2PSolution(self.rotations[index, slot].copy(),
                                       self.translations[index, slot].copy(),
                                       float(self.yaw[index, slot]),
                                       self.depths[index, slot].copy()))
        return out


def level_basis(up: ArrayLike) -> np.ndarray:
    """
    Return rotations ``A`` ``(..., 3, 3)`` with ``A @ [0, 0, 1] = up`` for unit ``up``.

    Columns ``(b1, b2, up)`` form a right-handed orthonormal basis, built with Duff et
    al., "Building an orthonormal basis, revisited" (JCGT 2017): continuous and free of
    division by zero for every direction, so no vertical direction is special.
    """
    up = np.asarray(up, dtype=float)
    x, y, z = up[..., 0], up[..., 1], up[..., 2]
    sign = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    b1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    b2 = np.stack([b, sign + y * y * a, -y], axis=-1)
    return np.stack([b1, b2, up], axis=-1)


def yaw_from_rotation(rotation: ArrayLike) -> Union[float, np.ndarray]:
    """
    Return the camera's yaw (rad, ``(-pi, pi]``) from ``R`` (object to camera), ``(..., 3, 3)``.

    Heading of the optical axis ``a = R^T e_z`` in the object's horizontal plane,
    ``atan2(a_y, a_x)`` (0 = looking along object +x, positive counter-clockwise seen
    from above). For a vertical optical axis: heading of the image-up direction
    ``-R^T e_y`` when looking down and of ``+R^T e_y`` when looking up (the continuous
    limit). Equals ``rpy_radians_from_rotation(R.T @ DEFAULT_IMU_TO_CAMERA)[2]``.
    """
    r = np.asarray(rotation, dtype=float)
    axis = r[..., 2, :]
    image_y = r[..., 1, :]
    horizontal = np.hypot(axis[..., 0], axis[..., 1])
    flip = np.where(axis[..., 2] < 0.0, -1.0, 1.0)[..., None]
    use = np.where((horizontal > 1e-9)[..., None], axis, flip * image_y)
    yaw = np.arctan2(use[..., 1], use[..., 0])
    return float(yaw) if np.ndim(yaw) == 0 else yaw


def down_from_roll_pitch(roll: ArrayLike, pitch: ArrayLike,
                         imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """
    Return the unit "down" direction(s) in the camera frame from IMU roll/pitch (rad).

    REP-103 roll/pitch of the IMU body (x forward, y left, z up);
    ``down_cam = imu_to_camera @ (-f)`` with ``f`` the unit specific force
    (:func:`accelcal_ros.frames.down_in_camera`), vectorised over arrays: ``(..., 3)``.
    """
    down_body = -specific_force_from_roll_pitch(roll, pitch)
    return down_body @ np.asarray(imu_to_camera, dtype=float).T


def rays_from_pixels(uv: ArrayLike, camera_matrix: ArrayLike) -> np.ndarray:
    """
    Return normalised rays ``[x, y, 1]`` ``(..., 3)`` of undistorted pixels ``uv`` ``(..., 2)``.

    ``[x, y, 1]^T ~ K^-1 [u, v, 1]^T`` (``K`` 3x3, pixel centres at integer coordinates
    as in OpenCV).
    """
    k = np.asarray(camera_matrix, dtype=float).reshape(3, 3)
    uv = np.asarray(uv, dtype=float)
    homogeneous = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    rays = homogeneous @ np.linalg.inv(k).T
    return rays / rays[..., 2:3]


def _quadratic_roots(a, b, c):
    """Return both roots of ``a x^2 + 2 b x + c = 0`` (cancellation-free) and the flags."""
    disc = b * b - a * c
    scale = b * b + np.abs(a * c)
    tiny_negative = (disc < 0.0) & (disc >= -_DISCRIMINANT_RELATIVE * scale)
    real = disc >= 0.0
    disc = np.where(tiny_negative, 0.0, disc)
    real = real | tiny_negative
    root = np.sqrt(np.where(real, disc, 0.0))
    q = -(b + np.where(b >= 0.0, root, -root))
    safe_q = np.where(q == 0.0, 1.0, q)
    safe_a = np.where(a == 0.0, 1.0, a)
    first = np.where(q == 0.0, 0.0, q / safe_a)
    second = np.where(q == 0.0, 0.0, c / safe_q)
    double = root == 0.0
    return first, second, real, double


def _scaled_norm(vectors: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return ``(norm, scaled)`` of vectors along the last axis, free of overflow/underflow.

    ``scaled`` is ``vectors`` divided by their largest absolute component (zero vectors
    kept), ``norm`` the length of each scaled vector (0, or 1 to sqrt 3).
    """
    largest = np.abs(vectors).max(axis=-1)
    scaled = vectors / np.where(largest == 0.0, 1.0, largest)[..., None]
    return np.where(largest == 0.0, 0.0, np.linalg.norm(scaled, axis=-1)), scaled


def solve_batch(rays: ArrayLike, points: ArrayLike, down: ArrayLike) -> 'BatchResult':
    """
    Solve ``N`` P2P problems at once (vectorised numpy; see the module text for the method).

    ``rays`` ``(N, 2, 3)``: the emitters' rays in the camera frame (any positive length,
    z > 0; e.g. :func:`rays_from_pixels`); ``points`` ``(2, 3)`` or ``(N, 2, 3)``: M1, M2
    in the object frame (m, within +-:data:`MAX_COORDINATE_M`); ``down`` ``(N, 3)`` or
    ``(3,)``: gravity direction in the camera frame (any finite nonzero length). Returns a
    :class:`BatchResult`; never raises for degenerate problems (their ``status`` says
    why), :class:`InputError` only for wrong shapes.
    """
    rays = np.asarray(rays, dtype=float)
    if rays.ndim != 3 or rays.shape[1:] != (2, 3):
        raise InputError(f'rays: expected shape (N, 2, 3), got {rays.shape}')
    n = rays.shape[0]
    points = np.asarray(points, dtype=float)
    if points.shape == (2, 3):
        points = np.broadcast_to(points, (n, 2, 3))
    if points.shape != (n, 2, 3):
        raise InputError(f'points: expected shape (2, 3) or ({n}, 2, 3), got {points.shape}')
    down = np.asarray(down, dtype=float)
    if down.shape == (3,):
        down = np.broadcast_to(down, (n, 3))
    if down.shape != (n, 3):
        raise InputError(f'down: expected shape (3,) or ({n}, 3), got {down.shape}')

    status = np.zeros(n, dtype=np.int64)

    def flag(mask, code):
        status[(status == OK) & mask] = code

    with np.errstate(invalid='ignore', divide='ignore', over='ignore'):
        finite = (np.isfinite(rays).all(axis=(1, 2)) & np.isfinite(points).all(axis=(1, 2))
                  & np.isfinite(down).all(axis=1))
        flag(~finite, NOT_FINITE)
        rays = np.where(finite[:, None, None], rays, 1.0)
        points = np.where(finite[:, None, None], points, 0.0)
        down = np.where(finite[:, None], down, 1.0)
        flag(np.abs(points).max(axis=(1, 2)) > MAX_COORDINATE_M, OUT_OF_RANGE)
        points = np.where((status == OK)[:, None, None], points, 0.0)

        down_norm, down = _scaled_norm(down)
        flag(down_norm == 0.0, BAD_DOWN)
        up = -down / np.where(down_norm == 0.0, 1.0, down_norm)[..., None]
        basis = level_basis(up)                                  # A: level -> camera

        ray_norm, rays = _scaled_norm(rays)
        flag((rays[:, :, 2] <= 0.0).any(axis=1) | (ray_norm == 0.0).any(axis=1), RAY_BACKWARD)
        unit = rays / np.where(ray_norm == 0.0, 1.0, ray_norm)[:, :, None]
        level = np.einsum('nij,njk->nik', unit, basis)           # r_i = A^T b_i

        delta = points[:, 0] - points[:, 1]
        baseline = np.linalg.norm(delta, axis=1)
        flag(baseline == 0.0, ZERO_BASELINE)
        horizontal = np.hypot(delta[:, 0], delta[:, 1])
        flag(horizontal <= _VERTICAL_RELATIVE * baseline, VERTICAL_LINE)
        cross = np.linalg.norm(np.cross(unit[:, 0], unit[:, 1]), axis=1)
        flag(cross <= _SAME_RAY_SIN, SAME_RAY)

        z1, z2 = level[:, 0, 2], level[:, 1, 2]
        line_norm = np.hypot(z1, z2)
        level_rays = line_norm <= _LEVEL_SIN
        same_height = np.abs(delta[:, 2]) <= _VERTICAL_RELATIVE * baseline
        flag(level_rays & same_height, LEVEL_DEGENERATE)
        flag(level_rays, LEVEL_INCONSISTENT)
        safe_norm = np.where(level_rays, 1.0, line_norm)

        # Line lambda1 z1 - lambda2 z2 = dz: lambda = p0 + mu * direction.
        p0 = (delta[:, 2] / safe_norm ** 2)[:, None] * np.stack([z1, -z2], axis=1)
        direction = np.stack([z2, z1], axis=1) / safe_norm[:, None]
        h1, h2 = level[:, 0, :2], level[:, 1, :2]
        w0 = p0[:, 0:1] * h1 - p0[:, 1:2] * h2
        w1 = direction[:, 0:1] * h1 - direction[:, 1:2] * h2
        qa = np.einsum('ni,ni->n', w1, w1)
        qb = np.einsum('ni,ni->n', w0, w1)
        qc = np.einsum('ni,ni->n', w0, w0) - horizontal ** 2
        first, second, real, double = _quadratic_roots(qa, qb, qc)
        flag(~real, NO_REAL_SOLUTION)

        mu = np.stack([first, second], axis=1)                   # (N, 2 roots)
        lambdas = p0[:, None, :] + mu[:, :, None] * direction[:, None, :]   # (N, root, pt)
        depth = lambdas * unit[:, None, :, 2]
        valid = (depth > 0.0).all(axis=2)
        valid[:, 1] &= ~double
        valid &= (status == OK)[:, None]
        flag(~valid.any(axis=1), BEHIND_CAMERA)

        # Yaw as a point on the circle: rotate dM_h onto lambda1 r1h - lambda2 r2h.
        target = lambdas[:, :, 0:1] * h1[:, None, :] - lambdas[:, :, 1:2] * h2[:, None, :]
        dx, dy = delta[:, None, 0], delta[:, None, 1]
        cos_part = dx * target[..., 0] + dy * target[..., 1]
        sin_part = dx * target[..., 1] - dy * target[..., 0]
        length = np.hypot(cos_part, sin_part)
        length = np.where(length == 0.0, 1.0, length)
        cos_yaw, sin_yaw = cos_part / length, sin_part / length
        zeros, ones = np.zeros_like(cos_yaw), np.ones_like(cos_yaw)
        rz = np.stack([np.stack([cos_yaw, -sin_yaw, zeros], axis=-1),
                       np.stack([sin_yaw, cos_yaw, zeros], axis=-1),
                       np.stack([zeros, zeros, ones], axis=-1)], axis=-2)  # (N, 2, 3, 3)
        rotations = np.einsum('nij,nsjk->nsik', basis, rz)
        rotated = np.einsum('nsij,nkj->nski', rz, points)        # R_z M_k, (N, s, k, 3)
        shift = lambdas[..., None] * level[:, None, :, :] - rotated
        shift = shift.mean(axis=2)                                # s = A^T t
        translations = np.einsum('nij,nsj->nsi', basis, shift)

    # Valid slots first.
    swap = ~valid[:, 0] & valid[:, 1]
    order = np.where(swap[:, None], np.array([1, 0]), np.array([0, 1]))
    take = np.arange(n)[:, None]
    rotations = rotations[take, order]
    translations = translations[take, order]
    depth = depth[take, order]
    valid = valid[take, order]
    rotations = np.where(valid[..., None, None], rotations, np.nan)
    translations = np.where(valid[..., None], translations, np.nan)
    depth = np.where(valid[..., None], depth, np.nan)
    yaw = np.where(valid, yaw_from_rotation(np.nan_to_num(rotations)), np.nan)
    return BatchResult(rotations, translations, np.asarray(yaw, dtype=float).reshape(n, 2),
                       depth, valid, status)


def solve(rays: ArrayLike, points: ArrayLike, down: ArrayLike) -> List['P2PSolution']:
    """
    Solve one P2P problem; return every valid :class:`P2PSolution` (one or two).

    ``rays`` ``(2, 3)`` (camera frame, z > 0), ``points`` ``(2, 3)`` (object frame, m),
    ``down`` ``(3,)`` (camera frame). Raises :class:`InputError` for wrong shapes, NaN or
    points beyond +-:data:`MAX_COORDINATE_M` and :class:`GeometryError` (with the reason)
    for degenerate geometry or when no real solution has both emitters in front of the
    camera.
    """
    rays = np.asarray(rays, dtype=float)
    points = np.asarray(points, dtype=float)
    down = np.asarray(down, dtype=float)
    for name, value, shape in (('rays', rays, (2, 3)), ('points', points, (2, 3)),
                               ('down', down, (3,))):
        if value.shape != shape:
            raise InputError(f'{name}: expected shape {shape}, got {value.shape}')
        if not np.all(np.isfinite(value)):
            raise InputError(f'{name} contains NaN or infinity')
    status, solutions = _solve_one(rays.tolist(), points.tolist(), down.tolist())
    if status == OUT_OF_RANGE:
        raise InputError(REASONS[status])
    if status != OK:
        raise GeometryError(REASONS[status])
    return solutions


def _solve_one(rays: List[List[float]], points: List[List[float]], down: List[float]
               ) -> Tuple[SolveStatus, List['P2PSolution']]:
    """
    Scalar form of :func:`solve_batch` for one problem (plain floats: ~13x faster).

    Kept beside the batch form because ``benchmarks/bench_p2p.py`` shows it is needed:
    one problem takes about 15 us here and 200 us through :func:`solve_batch` (a numpy
    call costs microseconds whatever its size), so a whole frame (detection, undistortion,
    solve) would take 1.6x longer with the batch form alone; the batch form in turn
    solves the study's 100000 problems 7x faster than this one in a loop. Same steps,
    thresholds and status order as the batch form (tests hold them equal).
    Returns ``(status, [P2PSolution, ...])``.
    """
    if max(abs(c) for point in points for c in point) > MAX_COORDINATE_M:
        return OUT_OF_RANGE, []
    largest = max(abs(c) for c in down)
    if largest == 0.0:
        return BAD_DOWN, []
    gx, gy, gz = (c / largest for c in down)
    norm = math.sqrt(gx * gx + gy * gy + gz * gz)
    x, y, z = -gx / norm, -gy / norm, -gz / norm
    sign = 1.0 if z >= 0.0 else -1.0
    a = -1.0 / (sign + z)
    b = x * y * a
    col1 = (1.0 + sign * x * x * a, sign * b, -sign * x)
    col2 = (b, sign + y * y * a, -y)
    col3 = (x, y, z)
    units, level = [], []
    for ray in rays:
        largest = max(abs(c) for c in ray)
        if ray[2] <= 0.0 or largest == 0.0:
            return RAY_BACKWARD, []
        ray = [c / largest for c in ray]
        length = math.sqrt(ray[0] * ray[0] + ray[1] * ray[1] + ray[2] * ray[2])
        u = (ray[0] / length, ray[1] / length, ray[2] / length)
        units.append(u)
        level.append(tuple(c[0] * u[0] + c[1] * u[1] + c[2] * u[2]
                           for c in (col1, col2, col3)))
    (m1x, m1y, m1z), (m2x, m2y, m2z) = points
    dx, dy, dz = m1x - m2x, m1y - m2y, m1z - m2z
    baseline = math.sqrt(dx * dx + dy * dy + dz * dz)
    if baseline == 0.0:
        return ZERO_BASELINE, []
    horizontal = math.hypot(dx, dy)
    if horizontal <= _VERTICAL_RELATIVE * baseline:
        return VERTICAL_LINE, []
    u1, u2 = units
    cx = u1[1] * u2[2] - u1[2] * u2[1]
    cy = u1[2] * u2[0] - u1[0] * u2[2]
    cz = u1[0] * u2[1] - u1[1] * u2[0]
    if math.sqrt(cx * cx + cy * cy + cz * cz) <= _SAME_RAY_SIN:
        return SAME_RAY, []
    (h1x, h1y, z1), (h2x, h2y, z2) = level
    line_norm = math.hypot(z1, z2)
    if line_norm <= _LEVEL_SIN:
        if abs(dz) <= _VERTICAL_RELATIVE * baseline:
            return LEVEL_DEGENERATE, []
        return LEVEL_INCONSISTENT, []
    p0a, p0b = dz / line_norm ** 2 * z1, -dz / line_norm ** 2 * z2
    da, db = z2 / line_norm, z1 / line_norm
    w0x, w0y = p0a * h1x - p0b * h2x, p0a * h1y - p0b * h2y
    w1x, w1y = da * h1x - db * h2x, da * h1y - db * h2y
    qa = w1x * w1x + w1y * w1y
    qb = w0x * w1x + w0y * w1y
    qc = w0x * w0x + w0y * w0y - horizontal * horizontal
    disc = qb * qb - qa * qc
    if disc < 0.0:
        if disc < -_DISCRIMINANT_RELATIVE * (qb * qb + abs(qa * qc)):
            return NO_REAL_SOLUTION, []
        disc = 0.0
    root = math.sqrt(disc)
    q = -(qb + (root if qb >= 0.0 else -root))
    if q == 0.0:
        roots = (0.0, 0.0)
    else:
        roots = (q / (qa if qa != 0.0 else 1.0), qc / q)
    basis = np.array([col1, col2, col3]).T
    solutions = []
    for index, mu in enumerate(roots):
        if index == 1 and root == 0.0:
            break
        lam1, lam2 = p0a + mu * da, p0b + mu * db
        depth1, depth2 = lam1 * u1[2], lam2 * u2[2]
        if not (depth1 > 0.0 and depth2 > 0.0):
            continue
        tx, ty = lam1 * h1x - lam2 * h2x, lam1 * h1y - lam2 * h2y
        cos_part = dx * tx + dy * ty
        sin_part = dx * ty - dy * tx
        length = math.hypot(cos_part, sin_part) or 1.0
        c, s = cos_part / length, sin_part / length
        shift = [0.5 * (lam1 * level[0][k] + lam2 * level[1][k]) for k in range(3)]
        mx, my = 0.5 * (m1x + m2x), 0.5 * (m1y + m2y)
        shift[0] -= c * mx - s * my
        shift[1] -= s * mx + c * my
        shift[2] -= 0.5 * (m1z + m2z)
        rows = [(col1[i] * c + col2[i] * s, col2[i] * c - col1[i] * s, col3[i])
                for i in range(3)]
        axis = rows[2]
        if math.hypot(axis[0], axis[1]) > 1e-9:
            yaw = math.atan2(axis[1], axis[0])
        else:
            flip = -1.0 if axis[2] < 0.0 else 1.0
            yaw = math.atan2(flip * rows[1][1], flip * rows[1][0])
        solutions.append(P2PSolution(np.array(rows), basis @ shift, yaw,
                                     np.array([depth1, depth2])))
    if not solutions:
        return BEHIND_CAMERA, []
    return OK, solutions


def solve_pixels(uv: ArrayLike, camera_matrix: ArrayLike, points: ArrayLike,
                 down: ArrayLike) -> List['P2PSolution']:
    """
    Solve from undistorted pixel coordinates ``uv`` ``(2, 2)`` and the camera matrix ``K``.

    See :func:`solve`; ``K`` is 9 row-major values or 3x3 (must be invertible).
    """
    k = np.asarray(camera_matrix, dtype=float)
    if k.size != 9:
        raise InputError(f'K: expected 9 values (3x3 row-major), got {k.size}')
    k = k.reshape(3, 3)
    uv = np.asarray(uv, dtype=float)
    if uv.shape != (2, 2):
        raise InputError(f'uv: expected [[u1, v1], [u2, v2]], got shape {uv.shape}')
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(uv))):
        raise InputError('uv or K contains NaN or infinity')
    if abs(np.linalg.det(k)) < 1e-12 * max(1.0, np.abs(k).max()) ** 3:
        raise InputError('K is singular: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1]')
    rays = np.concatenate([uv, np.ones((2, 1))], axis=1) @ np.linalg.inv(k).T
    if np.any(rays[:, 2] <= 0.0):
        raise InputError('K maps the pixels to rays behind the camera: expected K[2,2] > 0')
    return solve(rays, points, down)
