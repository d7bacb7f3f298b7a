r"""
Projection into the rig (paper A, eqs. 6-7): a panorama ray to a camera and its pixel.

Frames (see :mod:`.projection` and :mod:`.rig`): a panorama ray ``M`` in the levelled
panorama frame ``P`` goes into the reference camera's optical frame by the tilt

.. math::  T(\phi, \theta) = C\, R_{bl}(\phi, \theta)^T R_z(\psi_0)\, C_0^T

where ``R_bl = R_y(pitch) R_x(roll)`` takes body vectors into the level frame (REP-103,
:func:`accelcal_ros.frames.rotation_from_rpy_radians`), ``C`` is ``imu_to_camera``,
``C_0`` is :data:`accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA` and ``psi_0`` is the
heading of the reference camera's optical axis in the body frame (0 for the default
``C``, so that ``T = C R_bl^T C^T = R_z(-roll) R_x(pitch)``: paper A's eq. 7
``R_phitheta = R_z(phi) R_x(theta)`` in the optical frame, with ``phi = -roll`` and
``theta = pitch``). Camera ``i`` sees the ray as ``c_i = R_0i T M`` (the projection
step ``lambda m = K_i R_0i R_phitheta M`` with a far scene).

Camera choice (eq. 6): the camera whose optical axis is closest to the ray, i.e. the
largest ``z`` component of ``c_i`` (the third row of ``R_0i T`` dotted with ``M``). The
pixel is then projected through ``K_i`` and the OpenCV distortion ``D_i``; if it falls
outside that camera's frame the panorama pixel is black (step 5), as in the paper.

:class:`RigProjection` evaluates rays (numpy, float32, vectorised over rays and
cameras); the map builders (:mod:`.maps`, :mod:`.lookup`) build on it. The lens is the
rig cameras' :class:`~accelcal_ros.camera.CameraModel` (``plumb_bob`` only here: its
forward model is evaluated in float32 from a per-camera table).
"""
from enum import IntFlag
import math
from typing import Any, Optional, Sequence, Tuple, TYPE_CHECKING

from accelcal_ros.camera import distort_normalized, PLUMB_BOB
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_z, rotation_from_rpy_radians
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from concurrent.futures import ThreadPoolExecutor

    from accelcal_ros.camera.rig import Rig
    from accelcal_ros.panorama.projection import PanoramaGeometry

DISTORTION_RADIUS_MARGIN = 1.5
"""Rays farther from the axis than this times the frame's largest radius are rejected."""

Evaluation = Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""``(label, x, y, side)`` of :meth:`RigProjection.evaluate`."""


class Side(IntFlag):
    """
    Where a ray falls relative to its camera's frame: the bits of the ``side`` code (uint8).

    0: inside the frame; ``LEFT``/``RIGHT``/``TOP``/``BOTTOM``: beyond that edge (pixel
    ``x <= -1``, ``x >= width``, ``y <= -1``, ``y >= height``); ``INVALID`` alone: the
    ray has no pixel (behind the camera or beyond the lens model's valid radius).
    """

    LEFT = 1
    RIGHT = 2
    TOP = 4
    BOTTOM = 8
    INVALID = 16


# plain ints for the array code: an IntFlag operand makes NumPy 2 promote uint8 to int64
_SIDE_LEFT = int(Side.LEFT)
_SIDE_RIGHT = int(Side.RIGHT)
_SIDE_TOP = int(Side.TOP)
_SIDE_BOTTOM = int(Side.BOTTOM)
_SIDE_INVALID = int(Side.INVALID)


def reference_heading_rad(imu_to_camera: ArrayLike) -> float:
    """
    Return the heading (yaw, rad, REP-103) of the reference camera's axis in the body frame.

    The panorama's azimuth 0 is this direction, levelled. Raises :class:`InputError` when
    the camera looks straight up or down (heading undefined).
    """
    c = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
    axis_body = c[2]  # C^T e_z
    if math.hypot(axis_body[0], axis_body[1]) < 1e-6:
        raise InputError('imu_to_camera: the reference camera looks straight up or down; '
                         'the panorama heading is undefined')
    return math.atan2(axis_body[1], axis_body[0])


def tilt_matrix(roll: float, pitch: float,
                imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA) -> np.ndarray:
    """
    Rotation ``T`` taking panorama-frame rays into the reference camera frame.

    ``roll``, ``pitch`` in radians (REP-103 body attitude). See the module docstring.
    """
    if not (math.isfinite(roll) and math.isfinite(pitch)):
        raise InputError(f'attitude must be finite, got roll={roll!r}, pitch={pitch!r}')
    c = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
    yaw0 = reference_heading_rad(c)
    return c @ rotation_from_rpy_radians(roll, pitch).T @ rot_z(yaw0) @ DEFAULT_IMU_TO_CAMERA.T


def normalized_from_pixels(camera: Any, px: ArrayLike,
                           py: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
    """Return normalized undistorted coordinates ``(x, y)`` of pixels of ``camera``."""
    return getattr(camera, 'model', camera).normalized_from_pixels(px, py)


def frame_border_pixels(camera: Any, outset: float = 0.0,
                        per_side: int = 64) -> Tuple[np.ndarray, np.ndarray]:
    """
    Pixel coordinates ``(xs, ys)`` walking once around a frame, clockwise from top left.

    The rectangle runs from ``-outset`` to ``width - 1 + outset`` (``height`` alike);
    each side has ``per_side`` evenly spaced points, starting at its first corner.
    """
    x0, y0 = -outset, -outset
    x1, y1 = camera.width - 1 + outset, camera.height - 1 + outset
    t = np.linspace(0.0, 1.0, per_side, endpoint=False)
    xs = np.concatenate([x0 + t * (x1 - x0), np.full_like(t, x1), x1 - t * (x1 - x0),
                         np.full_like(t, x0)])
    ys = np.concatenate([np.full_like(t, y0), y0 + t * (y1 - y0), np.full_like(t, y1),
                         y1 - t * (y1 - y0)])
    return xs, ys


def frame_radius_and_limit2(camera: Any) -> Tuple[float, float]:
    """
    Return the frame's largest normalized radius and the largest squared radius accepted.

    For a distorted camera the OpenCV model is only invertible up to some radius; past
    it, far-off rays fold back into the frame. The accepted limit is
    ``DISTORTION_RADIUS_MARGIN`` times the largest undistorted radius of the frame's
    border, cut where the radial mapping stops increasing.
    """
    xn, yn = normalized_from_pixels(camera, *frame_border_pixels(camera))
    radius = float(np.sqrt(xn * xn + yn * yn).max())
    limit = radius * DISTORTION_RADIUS_MARGIN
    folds = not math.isfinite(radius)  # a border pixel without a ray: NaN (camera.distortion)
    if camera.has_distortion() and not folds:
        r = np.linspace(0.0, limit, 2001)[1:]
        k1, k2, _, _, k3 = camera.D
        r2 = r * r
        mapped = r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        bad = np.nonzero(np.diff(mapped) <= 0.0)[0]
        if bad.size:
            limit = min(limit, float(r[bad[0]]))
            folds = limit <= radius
    if folds:
        raise InputError(f'camera {camera.name!r}: distortion D={camera.D.tolist()} '
                         'is not invertible over the frame (radial mapping folds '
                         'back); check the calibration')
    return radius, limit * limit


class RigProjection:
    """
    Project panorama-frame rays into a rig at a tilt: the chosen camera and its pixel.

    ``rig`` (:class:`~.rig.Rig`), ``geometry`` (:class:`~.projection.PanoramaGeometry`),
    ``imu_to_camera`` (IMU body -> reference camera optical frame). Raises
    :class:`InputError` for a lens model other than ``plumb_bob``, a lens that folds
    back within its frame or a reference camera looking straight up or down.
    """

    def __init__(self, rig: 'Rig', geometry: 'PanoramaGeometry',
                 imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA) -> None:
        for cam in rig.cameras:
            if cam.distortion_model != PLUMB_BOB:
                raise InputError(f'camera {cam.name!r}: the panorama supports the plumb_bob '
                                 f'lens model only, not {cam.distortion_model}')
        self.rig = rig
        self.geometry = geometry
        self.imu_to_camera = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
        reference_heading_rad(self.imu_to_camera)
        self._radii = [frame_radius_and_limit2(c) for c in rig.cameras]
        self._limits2 = np.array([lim for _, lim in self._radii])
        self._sizes = np.array([[c.width, c.height] for c in rig.cameras], dtype=np.float32)
        # per camera: fx, skew, cx, fy, cy, k1, k2, p1, p2, k3, limit^2, width, height
        self._camera_table = np.array(
            [[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2], *c.D, lim, c.width,
              c.height] for c, lim in zip(rig.cameras, self._limits2)], np.float32).T.copy()
        self.workers = 1
        self._pool: Optional['ThreadPoolExecutor'] = None
        self._borders = [self._border_rays(c) for c in rig.cameras]

    @staticmethod
    def _pixel_density(camera, limit2):
        """Largest camera pixels per radian within the accepted cone of ``camera``."""
        r = np.linspace(0.0, math.sqrt(limit2), 200)
        k1, k2, _, _, k3 = camera.D
        r2 = r * r
        stretch = max(1.0, float((1.0 + r2 * (3 * k1 + r2 * (5 * k2 + 7 * k3 * r2))).max()))
        tangential = float(np.abs(camera.D[2:4]).sum()) * 6.0 * math.sqrt(limit2)
        return max(camera.K[0, 0], camera.K[1, 1]) * (1.0 + limit2) * (stretch + tangential)

    def cell_extent_px(self, step: int) -> float:
        """
        Bound on the extent in camera pixels of a ``step`` x ``step`` panorama cell.

        Its diagonal in radians times the largest pixel density any camera has within
        its accepted cone (f / cos^2 of the cone's half angle, times the distortion's
        largest radial stretch).
        """
        geometry = self.geometry
        el = geometry.elevation_rad(np.arange(geometry.height + 1) - 0.5)
        rad_per_px = max(np.radians(geometry.fov_h_deg) / geometry.width,
                         float(np.abs(np.diff(el)).max()))
        density = max(self._pixel_density(c, lim) for c, lim in zip(self.rig.cameras,
                                                                    self._limits2))
        return math.sqrt(2.0) * step * rad_per_px * density

    @staticmethod
    def _border_rays(camera, per_side=128):
        """
        Rays (camera frame, unit, ``(3, 4 per_side)``) around the frame's bilinear support.

        The support is ``-1 <= x <= width``, ``-1 <= y <= height`` (:meth:`evaluate`'s
        side code 0), walked once around. Returns ``(rays, half_gap_rad)``: the largest
        angle between consecutive rays, halved, bounds how far any point of the border
        lies from the nearest sample.
        """
        xn, yn = normalized_from_pixels(camera, *frame_border_pixels(camera, 1.0, per_side))
        rays = np.stack([xn, yn, np.ones_like(xn)])
        rays /= np.linalg.norm(rays, axis=0)
        cosine = np.clip(np.sum(rays * np.roll(rays, -1, axis=1), axis=0), -1.0, 1.0)
        return rays, 0.5 * float(np.arccos(cosine).max())

    def seen_rows(self, q: np.ndarray) -> Tuple[int, int]:
        """
        Return ``(first, last + 1)``: a row range holding every pixel any camera sees.

        ``q`` are :meth:`camera_rotations`. A frame's region on the sphere is bounded by
        its border, so its highest and lowest points lie on the border (sampled, with the
        sampling gap as margin) unless the region holds the zenith or the nadir, where
        elevation peaks; both are tested by projecting them into the frame. Rows outside
        the range need no evaluation: no camera sees them.
        """
        top, bottom = -math.inf, math.inf
        poles = np.array([[0.0, 0.0], [-1.0, 1.0], [0.0, 0.0]], np.float32)  # zenith, nadir
        # A pole outside a camera's accepted cone (behind it or past the distortion
        # limit) is not in its frame; only a pole inside the cone is projected.
        in_camera = np.einsum('nij,jk->nik', q, poles)  # (cameras, 3, 2)
        depth = in_camera[:, 2]
        safe = np.where(depth > 1e-6, depth, 1.0)
        radius2 = (in_camera[:, 0] ** 2 + in_camera[:, 1] ** 2) / safe ** 2
        in_cone = (depth > 1e-6) & (radius2 <= self._limits2[:, None])
        for i, (rays, half_gap) in enumerate(self._borders):
            pano = q[i].T @ rays  # camera -> panorama frame P (y down)
            elevation = np.arcsin(np.clip(-pano[1], -1.0, 1.0))
            high = float(elevation.max()) + half_gap
            low = float(elevation.min()) - half_gap
            if in_cone[i].any():
                side = self._evaluate_soa(poles, q, only=i)[3]
                if side[0] == 0:
                    high = math.pi / 2
                if side[1] == 0:
                    low = -math.pi / 2
            top, bottom = max(top, high), min(bottom, low)
        g = self.geometry
        limit = np.radians(g.fov_v_deg) / 2 if g.projection == 'spherical' else \
            np.radians(89.9)
        first_row = float(g.row_from_elevation(min(top, float(limit))))
        last_row = float(g.row_from_elevation(max(bottom, -float(limit))))
        first = max(0, int(math.floor(first_row)) - 1)
        last = min(g.height, int(math.ceil(last_row)) + 2)
        return (first, last) if last > first else (0, 0)

    def camera_rotations(self, roll: float, pitch: float) -> np.ndarray:
        """Return ``Q_i = R_0i T`` (n, 3, 3): panorama frame -> camera ``i``, float64."""
        t = tilt_matrix(roll, pitch, self.imu_to_camera)
        return np.stack([cam.R @ t for cam in self.rig.cameras])

    def evaluate(self, rays: ArrayLike, rotations: np.ndarray,
                 only: Optional[int] = None) -> Evaluation:
        """
        Project panorama-frame rays ``(N, 3)`` into the rig (eq. 6, eq. 7, projection).

        ``rotations`` are :meth:`camera_rotations`. Returns ``(label, x, y, side)``: the
        chosen camera (eq. 6; camera ``only`` for every ray when given), its pixel
        coordinates (float32; undefined where ``side & 16``), and a bit set saying where
        the point lies relative to that camera's frame: 0 within the bilinear support of
        its pixels (``-1 < x < width``, ``-1 < y < height``), 1/2/4/8 left of / right of
        / above / below it, 16 behind the camera or past the distortion limit.
        """
        soa = np.ascontiguousarray(np.asarray(rays, dtype=np.float32).reshape(-1, 3).T)
        return self._evaluate_soa(soa, rotations, only)

    def _evaluate_soa(self, rays, rotations, only=None):
        """
        :meth:`evaluate` for rays stored as ``(3, N)`` float32.

        ``only``: one camera for every ray, or an array of ``N`` cameras, one per ray
        (instead of eq. 6's choice).

        Every ray is rotated into every camera by one product (a few flops more than
        needed, but a fixed, small number of numpy calls whatever the number of
        cameras); each ray's camera constants are gathered from ``_camera_table``.
        ``einsum``, not ``@``: a BLAS product of this size wakes OpenBLAS's threads,
        which then spin and slow the ``cv2.remap`` that follows by a third.
        """
        q = np.asarray(rotations, dtype=np.float32)
        n = rays.shape[1]
        one = only is not None and np.ndim(only) == 0
        if one or (only is None and len(q) == 1):
            target = int(only) if one else 0
            label = np.full(n, target, np.intp)
            cx, cy, cz = np.einsum('ij,jn->in', q[target], rays)
            constants = self._camera_table[:, target]
        else:
            every = np.einsum('ij,jn->in', q.reshape(-1, 3), rays).reshape(len(q), 3, n)
            if only is not None:  # the camera given per ray
                label = np.asarray(only, np.intp)
            else:  # eq. 6: the largest z component in any camera (first camera on ties)
                label = np.zeros(n, np.intp)
                best = every[0, 2].copy()
                for i in range(1, len(q)):
                    label[every[i, 2] > best] = i
                    np.maximum(best, every[i, 2], out=best)
            at = label * (3 * n) + np.arange(n)  # element (label, 0, i) of ``every``
            flat = every.reshape(-1)
            cx, cy, cz = flat.take(at), flat.take(at + n), flat.take(at + 2 * n)
            constants = np.take(self._camera_table, label, axis=1)
        return (label,) + self._lens_soa(cx, cy, cz, constants)

    def _evaluate_runs(self, rays: np.ndarray, rotations: np.ndarray, cameras: Sequence[int],
                       counts: Sequence[int]) -> Evaluation:
        """
        :meth:`_evaluate_soa` for rays ``(3, N)`` float32 in runs, each through one camera.

        Run ``k`` is the next ``counts[k]`` rays, all through camera ``cameras[k]`` (a
        grid's nodes camera by camera, :mod:`.view_grid`): each run is rotated by its own
        3x3 product and the camera constants repeated per run, where a camera per ray
        (``only``) rotates every ray into every camera and gathers the constants ray by
        ray: 6000 rays in 3 runs 0.17 -> 0.09 ms (OpenCV 4.6 stack, one thread), the
        same values.
        """
        q = np.asarray(rotations, dtype=np.float32)
        runs = np.asarray(cameras, np.intp)
        sizes = np.asarray(counts, np.intp)
        rotated = np.empty((3, rays.shape[1]), np.float32)
        start = 0
        for camera, size in zip(runs.tolist(), sizes.tolist()):
            if size:
                np.einsum('ij,jn->in', q[camera], rays[:, start:start + size],
                          out=rotated[:, start:start + size])
            start += size
        constants = np.repeat(self._camera_table[:, runs], sizes, axis=1)
        label = np.repeat(runs, sizes)
        return (label,) + self._lens_soa(rotated[0], rotated[1], rotated[2], constants)

    @staticmethod
    def _lens_soa(cx: np.ndarray, cy: np.ndarray, cz: np.ndarray,
                  constants: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return ``(x, y, side)`` of camera-frame points through their cameras' lenses."""
        fx, skew, ppx, fy, ppy, k1, k2, p1, p2, k3, limit2, width, height = constants
        front = cz > 1e-6
        inv = np.float32(1.0) / np.where(front, cz, np.float32(1.0))
        xn, yn = cx * inv, cy * inv
        invalid = ~front | (xn * xn + yn * yn > limit2)
        # rays nearly perpendicular to the axis (invalid: past the limit) may overflow
        with np.errstate(over='ignore', invalid='ignore'):
            xn, yn = distort_normalized(xn, yn, (k1, k2, p1, p2, k3))
            px = fx * xn + skew * yn + ppx
            py = fy * yn + ppy
        code = (px <= -1.0).view(np.uint8) * np.uint8(_SIDE_LEFT)
        code |= (px >= width).view(np.uint8) * np.uint8(_SIDE_RIGHT)
        code |= (py <= -1.0).view(np.uint8) * np.uint8(_SIDE_TOP)
        code |= (py >= height).view(np.uint8) * np.uint8(_SIDE_BOTTOM)
        code[invalid] = _SIDE_INVALID
        return px, py, code

    def evaluate_parallel(self, rays: np.ndarray, rotations: np.ndarray,
                          min_chunk: int = 16384) -> Evaluation:
        """
        Return :meth:`evaluate` of rays stored ``(3, N)``, split over :attr:`workers` threads.

        numpy releases the GIL in its array operations, so two threads can use both
        cores for the large arrays of a rebuild (``workers`` = 1 by default: on a busy
        2-core machine the split does not pay).
        """
        count = rays.shape[1]
        if self.workers < 2 or count < 2 * min_chunk:
            return self._evaluate_soa(rays, rotations)
        if self._pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=self.workers,
                                            thread_name_prefix='lookup')
        bounds = np.linspace(0, count, self.workers + 1).astype(int)
        futures = [self._pool.submit(self._evaluate_soa, rays[:, a:b], rotations)
                   for a, b in zip(bounds[:-1], bounds[1:])]
        results = [f.result() for f in futures]
        label, x, y, side = (np.concatenate([r[k] for r in results]) for k in range(4))
        return label, x, y, side
