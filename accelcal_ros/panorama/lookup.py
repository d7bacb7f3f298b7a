r"""
Lookup maps: for every panorama pixel, the camera and the point of its image to sample.

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

Maps are expressed in the coordinates of a *mosaic*: all camera images side by side,
separated by black gaps (:class:`MosaicLayout`), so a whole panorama frame is one
``cv2.remap`` of the mosaic. Pixel coordinates follow OpenCV (integers at pixel
centres). Bilinear interpolation treats everything outside a frame as black: a point
between the outermost pixel centres and one pixel beyond them fades linearly to black,
a point farther out is black (step 5); the gaps make that hold in the mosaic too.

Two builders give the same map:

- :meth:`LookupBuilder.build_exact` evaluates every pixel (about a second at 3600x2400).
- :meth:`LookupBuilder.build_fast` evaluates exactly a coarse grid of nodes every
  ``grid_step`` pixels and classifies each cell (:meth:`LookupBuilder.classify`) as
  *pure* -- the same camera at its corners, within the mosaic gap around that camera's
  frame, and a bilinear interpolation error, estimated from the nodes' second
  differences (next to a seam, from the stencil on the cell's side of it) or, where
  that fails, measured at the cell's centre and edge midpoints, within 3/4 of the
  tolerance (the centre of a quadratic is where its bilinear error peaks; the margin
  covers higher-order terms) --, *empty* (outside the frame on
  one side, or, across a seam, every camera present has a point farther out of its
  frame than a cell can extend) or *mixed*. Pure cells are interpolated bilinearly by
  one ``cv2.resize`` of the node map (a cell across a frame edge is pure: its outer part
  lands in the black gap), empty cells are set to "outside", mixed cells (seams between
  cameras, the panorama border) are refined by sub-blocks of a few pixels, classified
  the same way from their exactly evaluated corners and centre, and evaluated pixel by
  pixel only where a seam crosses a sub-block. Only rows some camera can see are
  evaluated (:meth:`LookupBuilder.seen_rows` bounds them beforehand from the frames'
  borders) and built.
  ``test/panorama/test_lookup.py`` measures the maximum error over every pixel against
  :meth:`LookupBuilder.build_exact`.
"""
from dataclasses import dataclass
import math
import time

from accelcal_ros.camera import distort_normalized, PLUMB_BOB, undistort_normalized  # noqa: F401
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rot_z, rotation_from_rpy_radians
import numpy as np

OUTSIDE = -1000.0
"""Map value of a pixel no camera sees: far outside the mosaic, so ``cv2.remap`` gives 0."""
FIXED_POINT_LIMIT = 32000
"""Mosaic sides are kept below this so maps convert to OpenCV's 16-bit fixed point."""
CENTRE_CHECK_FRACTION = 0.75
"""A pure cell's error at its centre and edge midpoints must be below this fraction of
``tolerance_px`` (the rest covers higher-order terms; the tests measure every pixel)."""
DISTORTION_RADIUS_MARGIN = 1.5
"""Rays farther from the axis than this times the frame's largest radius are rejected."""

_SIDE_LEFT, _SIDE_RIGHT, _SIDE_TOP, _SIDE_BOTTOM, _SIDE_INVALID = 1, 2, 4, 8, 16


def reference_heading_rad(imu_to_camera):
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


def tilt_matrix(roll, pitch, imu_to_camera=DEFAULT_IMU_TO_CAMERA):
    """
    Rotation ``T`` taking panorama-frame rays into the reference camera frame.

    ``roll``, ``pitch`` in radians (REP-103 body attitude). See the module docstring.
    """
    if not (math.isfinite(roll) and math.isfinite(pitch)):
        raise InputError(f'attitude must be finite, got roll={roll!r}, pitch={pitch!r}')
    c = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
    yaw0 = reference_heading_rad(c)
    return c @ rotation_from_rpy_radians(roll, pitch).T @ rot_z(yaw0) @ DEFAULT_IMU_TO_CAMERA.T


def normalized_from_pixels(camera, px, py):
    """Return normalized undistorted coordinates ``(x, y)`` of pixels of ``camera``."""
    return getattr(camera, 'model', camera).normalized_from_pixels(px, py)


def frame_border_pixels(camera, outset=0.0, per_side=64):
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


def frame_radius_and_limit2(camera):
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
    if camera.has_distortion():
        r = np.linspace(0.0, limit, 2001)[1:]
        k1, k2, _, _, k3 = camera.D
        r2 = r * r
        mapped = r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        bad = np.nonzero(np.diff(mapped) <= 0.0)[0]
        if bad.size:
            limit = min(limit, float(r[bad[0]]))
            if limit <= radius:
                raise InputError(f'camera {camera.name!r}: distortion D={camera.D.tolist()} '
                                 'is not invertible over the frame (radial mapping folds '
                                 'back); check the calibration')
    return radius, limit * limit


@dataclass(frozen=True)
class MosaicLayout:
    """
    Where each camera's image sits in the mosaic: ``offsets[i] = (x0, y0)``, size, gap.

    Images are separated from each other and from the mosaic's edges by ``gap`` black
    pixels.
    """

    offsets: tuple
    width: int
    height: int
    gap: int

    @classmethod
    def for_rig(cls, rig, gap=32, limit=FIXED_POINT_LIMIT):
        """Place the images left to right, wrapping to a new row before ``limit`` px."""
        offsets, x, y, row_h, width = [], gap, gap, 0, 0
        for cam in rig.cameras:
            if cam.width + 2 * gap > limit:
                raise InputError(f'camera {cam.name!r}: width {cam.width} exceeds {limit}')
            if x + cam.width + gap > limit:
                x, y, row_h = gap, y + row_h + gap, 0
            offsets.append((x, y))
            x += cam.width + gap
            row_h = max(row_h, cam.height)
            width = max(width, x)
        height = y + row_h + gap
        if height > limit:
            raise InputError(f'rig images do not fit a {limit}x{limit} mosaic')
        return cls(tuple(offsets), width, height, gap)


class LookupBuilder:
    """
    Build panorama lookup maps for a rig, a panorama geometry and an ``imu_to_camera``.

    A map is a float32 array ``(height, width, 2)`` of mosaic coordinates ``(x, y)``;
    pixels no camera sees hold :data:`OUTSIDE`. ``grid_step`` (even, >= 4) is the cell
    size of the fast builder; it is reduced to the largest even divisor of the panorama
    width not above it when there is one (so that cells tile the width exactly).
    ``tolerance_px`` bounds the interpolation error of a pure cell (in camera pixels,
    checked at its centre).
    """

    def __init__(self, rig, geometry, imu_to_camera=DEFAULT_IMU_TO_CAMERA, grid_step=20,
                 tolerance_px=0.1):
        if isinstance(grid_step, bool) or int(grid_step) != grid_step or grid_step < 4:
            raise InputError(f'grid_step must be an integer >= 4, got {grid_step!r}')
        if not (math.isfinite(tolerance_px) and tolerance_px > 0):
            raise InputError(f'tolerance_px must be positive, got {tolerance_px!r}')
        for cam in rig.cameras:
            if cam.distortion_model != PLUMB_BOB:
                raise InputError(f'camera {cam.name!r}: the panorama supports the plumb_bob '
                                 f'lens model only, not {cam.distortion_model}')
        self.rig = rig
        self.geometry = geometry
        self.imu_to_camera = np.asarray(imu_to_camera, dtype=float).reshape(3, 3)
        reference_heading_rad(self.imu_to_camera)
        self.tolerance_px = float(tolerance_px)
        self.step = self._choose_step(int(grid_step), geometry.width)
        s = self.step
        radii = [frame_radius_and_limit2(c) for c in rig.cameras]
        self._limits2 = np.array([lim for _, lim in radii])
        # Bound on a cell's extent in camera pixels: its diagonal in radians times the
        # largest pixel density any camera has within its accepted cone (f / cos^2 of the
        # cone's half angle, times the distortion's largest radial stretch). The gap
        # around each image in the mosaic holds the outer part of a pure cell straddling
        # a frame edge; a point farther than the bound outside a frame proves the whole
        # cell outside it; a ray past the distortion limit is that far when the limit's
        # margin exceeds the bound.
        el = geometry.elevation_rad(np.arange(geometry.height + 1) - 0.5)
        rad_per_px = max(np.radians(geometry.fov_h_deg) / geometry.width,
                         float(np.abs(np.diff(el)).max()))
        density = max(self._pixel_density(c, lim) for c, lim in zip(rig.cameras,
                                                                    self._limits2))
        self._far = math.sqrt(2.0) * s * rad_per_px * density
        gap = int(min(512, math.ceil(self._far) + 4))
        self.layout = MosaicLayout.for_rig(rig, gap=gap + gap % 2)
        self._margin = self.layout.gap - 2.0
        frame_gap_px = np.array([(math.sqrt(lim) - radius) * min(c.K[0, 0], c.K[1, 1])
                                 for c, (radius, lim) in zip(rig.cameras, radii)])
        self._invalid_is_far = frame_gap_px > self._far
        self._sizes = np.array([[c.width, c.height] for c in rig.cameras], dtype=np.float32)
        # per camera: fx, skew, cx, fy, cy, k1, k2, p1, p2, k3, limit^2, width, height
        self._camera_table = np.array(
            [[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2], *c.D, lim, c.width,
              c.height] for c, lim in zip(rig.cameras, self._limits2)], np.float32).T.copy()
        self._offsets = np.asarray(self.layout.offsets, dtype=np.float32)
        self._tiles_w = -(-geometry.width // s)
        self._tiles_h = -(-geometry.height // s)
        # Separable ray tables of pixels -s .. n s + s - 1 per axis (index = pixel + s):
        # the cells at the border reach half a cell beyond the panorama.
        self._pad = s
        cols = np.arange(-s, (self._tiles_w + 1) * s)
        rows = np.arange(-s, (self._tiles_h + 1) * s)
        az = geometry.azimuth_rad(cols)
        el = geometry.elevation_rad(rows)
        self._sin_az = np.sin(az).astype(np.float32)
        self._cos_az = np.cos(az).astype(np.float32)
        self._sin_el = np.sin(el).astype(np.float32)
        self._cos_el = np.cos(el).astype(np.float32)
        # the same at pixel edges (continuous coordinate k - 1/2), for sub-block corners
        az_e = geometry.azimuth_rad(np.arange(-s, (self._tiles_w + 1) * s + 1) - 0.5)
        el_e = geometry.elevation_rad(np.arange(-s, (self._tiles_h + 1) * s + 1) - 0.5)
        self._sin_az_e = np.sin(az_e).astype(np.float32)
        self._cos_az_e = np.cos(az_e).astype(np.float32)
        self._sin_el_e = np.sin(el_e).astype(np.float32)
        self._cos_el_e = np.cos(el_e).astype(np.float32)
        half_step = s // 2
        self.sub_step = next((d for d in (5, 4, 3, 2) if half_step % d == 0), 0)
        # bilinear weights of a sub-block's pixels (row-major) on its corners 00, 01, 10, 11
        f = (np.arange(max(1, self.sub_step)) + 0.5) / max(1, self.sub_step)
        fy, fx = np.repeat(f, len(f)), np.tile(f, len(f))
        self._sub_weights = np.stack([(1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx),
                                      fy * fx], axis=1).astype(np.float32)
        half = s // 2
        # Nodes (what cv2.resize interpolates) sit at pixel positions k*s + s/2 - 1/2,
        # k = 0..n-1; with the extra rows/columns at k = -1 and k = n they bound n + 1
        # cells per axis: cell b covers pixels [b*s - s/2, b*s + s/2), centre b*s - 1/2.
        node_u = np.arange(-1, self._tiles_w + 1) * s + half - 0.5
        node_v = np.arange(-1, self._tiles_h + 1) * s + half - 0.5
        centre_u = np.arange(self._tiles_w + 1) * s - 0.5
        centre_v = np.arange(self._tiles_h + 1) * s - 0.5
        self._node_rays = geometry.rays(node_u[None, :], node_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._centre_rays = geometry.rays(centre_u[None, :], centre_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        # midpoints of the horizontal and of the vertical cell edges
        self._hmid_rays = geometry.rays(centre_u[None, :], node_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._vmid_rays = geometry.rays(node_u[None, :], centre_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._node_soa = np.ascontiguousarray(self._node_rays.T)
        self._centre_soa = np.ascontiguousarray(self._centre_rays.T)
        self._hmid_soa = np.ascontiguousarray(self._hmid_rays.T)
        self._vmid_soa = np.ascontiguousarray(self._vmid_rays.T)
        self.workers = 1
        self._pool = None
        self._buffer = None
        self._resize_pool = None
        self._borders = [self._border_rays(c) for c in rig.cameras]
        self.band = (0, geometry.height)
        self.last_stats = {}

    @staticmethod
    def _pixel_density(camera, limit2):
        """Largest camera pixels per radian within the accepted cone of ``camera``."""
        r = np.linspace(0.0, math.sqrt(limit2), 200)
        k1, k2, _, _, k3 = camera.D
        r2 = r * r
        stretch = max(1.0, float((1.0 + r2 * (3 * k1 + r2 * (5 * k2 + 7 * k3 * r2))).max()))
        tangential = float(np.abs(camera.D[2:4]).sum()) * 6.0 * math.sqrt(limit2)
        return max(camera.K[0, 0], camera.K[1, 1]) * (1.0 + limit2) * (stretch + tangential)

    @staticmethod
    def _choose_step(step, width):
        step -= step % 2
        for s in range(step, 3, -2):
            if width % s == 0:
                return s
        return step

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

    def seen_rows(self, q):
        """
        Return ``(first, last + 1)``: a row range holding every pixel any camera sees.

        ``q`` are :meth:`camera_rotations`. A frame's region on the sphere is bounded by
        its border, so its highest and lowest points lie on the border (sampled, with the
        sampling gap as margin) unless the region holds the zenith or the nadir, where
        elevation peaks; both are tested by projecting them into the frame. Rows outside
        the range need no evaluation: no camera sees them.
        """
        top, bottom = -np.inf, np.inf
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
        first = g.row_from_elevation(min(float(top), limit))
        last = g.row_from_elevation(max(float(bottom), -limit))
        first = max(0, int(math.floor(first)) - 1)
        last = min(g.height, int(math.ceil(last)) + 2)
        return (first, last) if last > first else (0, 0)

    # -- geometry -------------------------------------------------------------------------
    def camera_rotations(self, roll, pitch):
        """Return ``Q_i = R_0i T`` (n, 3, 3): panorama frame -> camera ``i``, float64."""
        t = tilt_matrix(roll, pitch, self.imu_to_camera)
        return np.stack([cam.R @ t for cam in self.rig.cameras])

    def evaluate(self, rays, rotations, only=None):
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

        Every ray is rotated into every camera by one product (a few flops more than
        needed, but a fixed, small number of numpy calls whatever the number of
        cameras); each ray's camera constants are gathered from ``_camera_table``.
        ``einsum``, not ``@``: a BLAS product of this size wakes OpenBLAS's threads,
        which then spin and slow the ``cv2.remap`` that follows by a third.
        """
        q = np.asarray(rotations, dtype=np.float32)
        n = rays.shape[1]
        if only is not None or len(q) == 1:
            target = 0 if only is None else int(only)
            label = np.full(n, target, np.intp)
            cx, cy, cz = np.einsum('ij,jn->in', q[target], rays)
            constants = self._camera_table[:, target]
        else:
            every = np.einsum('ij,jn->in', q.reshape(-1, 3), rays).reshape(len(q), 3, n)
            # eq. 6: the largest z component in any camera (first camera on ties)
            label = np.zeros(n, np.intp)
            best = every[0, 2].copy()
            for i in range(1, len(q)):
                label[every[i, 2] > best] = i
                np.maximum(best, every[i, 2], out=best)
            at = label * (3 * n) + np.arange(n)  # element (label, 0, i) of ``every``
            flat = every.reshape(-1)
            cx, cy, cz = flat.take(at), flat.take(at + n), flat.take(at + 2 * n)
            constants = np.take(self._camera_table, label, axis=1)
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
        return label, px, py, code

    def evaluate_parallel(self, rays, rotations, min_chunk=16384):
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
        return tuple(np.concatenate([r[k] for r in results]) for k in range(4))

    def to_mosaic(self, label, x, y, side):
        """Mosaic coordinates ``(N, 2)`` float32 of :meth:`evaluate`'s output."""
        out = np.empty((len(label), 2), np.float32)
        out[:, 0] = x + self._offsets[label, 0]
        out[:, 1] = y + self._offsets[label, 1]
        out[side != 0] = OUTSIDE
        return out

    def _pixel_rays(self, u, v):
        """Rays ``(3, ...)`` float32 of integer pixel coordinates from the separable tables."""
        u, v = u + self._pad, v + self._pad
        ce = self._cos_el[v]
        rays = np.empty((3,) + np.broadcast(u, v).shape, np.float32)
        np.multiply(ce, self._sin_az[u], out=rays[0])
        rays[1] = -self._sin_el[v]
        np.multiply(ce, self._cos_az[u], out=rays[2])
        return rays

    # -- builders -------------------------------------------------------------------------
    def build_exact(self, roll, pitch, with_labels=False, rows_per_chunk=8):
        """
        Evaluate every pixel: map ``(H, W, 2)`` float32 (and labels, -1 where unseen).

        The reference against which the fast builder is tested.
        """
        q = self.camera_rotations(roll, pitch)
        h, w = self.geometry.height, self.geometry.width
        out = np.empty((h, w, 2), np.float32)
        labels = np.empty((h, w), np.int8) if with_labels else None
        cols = np.arange(w)
        for r0 in range(0, h, rows_per_chunk):
            rows = np.arange(r0, min(h, r0 + rows_per_chunk))
            rays = self._pixel_rays(cols[None, :], rows[:, None]).reshape(3, -1)
            label, x, y, side = self._evaluate_soa(rays, q)
            out[rows[0]:rows[-1] + 1] = self.to_mosaic(label, x, y, side).reshape(
                len(rows), w, 2)
            if with_labels:
                labels[rows[0]:rows[-1] + 1] = np.where(side == 0, label, -1).reshape(
                    len(rows), w)
        covered = np.nonzero((out[..., 0] != OUTSIDE).any(axis=1))[0]
        self.band = (int(covered[0]), int(covered[-1]) + 1) if covered.size else (0, 0)
        return (out, labels) if with_labels else out

    def build_blend(self, roll, pitch, width_rad, rows_per_chunk=8):
        """
        Exact maps for feathered blending: ``(map1, map2, weight1)``.

        Among the cameras whose frame holds a ray, ``map1`` samples the one with the
        closest optical axis (eq. 6 restricted to cameras that see the ray) and ``map2``
        the next one (:data:`OUTSIDE` if none). ``weight1`` (float32) is 1 farther than
        ``width_rad / 2`` from the seam plane between the two axes and falls linearly to
        0.5 on it, so the panorama is continuous across the seam.
        """
        q = self.camera_rotations(roll, pitch)
        h, w = self.geometry.height, self.geometry.width
        n = len(self.rig)
        map1 = np.full((h, w, 2), OUTSIDE, np.float32)
        map2 = np.full((h, w, 2), OUTSIDE, np.float32)
        weight = np.ones((h, w), np.float32)
        axes = q[:, 2, :]
        cols = np.arange(w)
        for r0 in range(0, h, rows_per_chunk):
            rows = np.arange(r0, min(h, r0 + rows_per_chunk))
            rays = self._pixel_rays(cols[None, :], rows[:, None]).reshape(3, -1)
            count = rays.shape[1]
            score = np.full((count, n), -np.inf, np.float32)
            coords = np.empty((n, count, 2), np.float32)
            for i in range(n):
                _, x, y, side = self._evaluate_soa(rays, q, only=i)
                seen = side == 0
                a = axes[i].astype(np.float32)
                score[seen, i] = (a[0] * rays[0] + a[1] * rays[1] + a[2] * rays[2])[seen]
                coords[i] = self.to_mosaic(np.full(count, i), x, y, side)
            order = np.argsort(-score, axis=1)[:, :2]
            best, second = order[:, 0], order[:, 1] if n > 1 else order[:, 0]
            index = np.arange(count)
            has1 = np.isfinite(score[index, best])
            has2 = (np.isfinite(score[index, second]) & (second != best)) & has1
            m1 = np.where(has1[:, None], coords[best, index], OUTSIDE)
            m2 = np.where(has2[:, None], coords[second, index], OUTSIDE)
            gap = np.linalg.norm(axes[best] - axes[second], axis=1)
            dist = np.arcsin(np.clip((score[index, best] - np.where(has2, score[
                index, second], 0.0)) / np.maximum(gap, 1e-9), 0.0, 1.0))
            w1 = np.where(has2, np.clip(0.5 + dist / width_rad, 0.5, 1.0), 1.0)
            sl = slice(rows[0], rows[-1] + 1)
            map1[sl] = m1.reshape(len(rows), w, 2)
            map2[sl] = m2.reshape(len(rows), w, 2)
            weight[sl] = w1.reshape(len(rows), w)
        covered = np.nonzero((map1[..., 0] != OUTSIDE).any(axis=1))[0]
        self.band = (int(covered[0]), int(covered[-1]) + 1) if covered.size else (0, 0)
        return map1, map2, weight

    def classify(self, q, node_rows=None):
        """
        Classify the cells from the exact values at the nodes (and, where needed, more).

        Returns ``(node_map, empty, exact, pure)``: ``node_map`` ``(n_h, n_w, 2)`` holds
        the nodes' mosaic coordinates (what pure cells interpolate); the masks are per
        cell. Most cells are decided from the nodes alone: the same camera at the 4
        corners, all valid and within the gap around its frame, and the bilinear error
        estimated from the second differences at the corners, ``(|d2_u| + |d2_v|) / 8``
        (the error at the centre of a quadratic; where a corner's three-node stencil
        crosses a seam, the next stencil along, which holds that corner and so lies on
        its camera's side), within 3/4 of the tolerance -> pure; every camera present
        with a corner farther out than a cell
        reaches, or all corners outside on one side by more than a pixel -> empty. The
        other cells (seams, frame edges, the border) get their centre and edge midpoints
        evaluated: pure if the same camera is at all nine points, all near, with the
        bilinear error at the centre and midpoints within 3/4 of the tolerance.

        ``node_rows = (k0, k1)`` restricts the work to node rows ``k0 .. k1 - 1`` (at
        least 3): the arrays returned then cover those nodes and the cells between them
        (cell row ``j`` is the grid's ``k0 + j``). The first and last of those cell rows
        lack the nodes beyond them for the second differences and are decided the slow
        way.
        """
        tw = self._tiles_w
        k0, k1 = (0, self._tiles_h + 2) if node_rows is None else node_rows
        th = k1 - k0 - 2
        if th < 1:
            raise ValueError(f'node_rows {node_rows!r}: need at least 3 node rows')
        shape_n, shape_c = (th + 2, tw + 2), (th + 1, tw + 1)
        n_label, n_x, n_y, n_side = (a.reshape(shape_n) for a in self.evaluate_parallel(
            self._node_soa[:, k0 * (tw + 2):k1 * (tw + 2)], q))
        size = self._sizes[n_label]
        m = self._margin
        valid = (n_side & _SIDE_INVALID) == 0
        dist = np.maximum(np.maximum(-1.0 - n_x, n_x - size[..., 0]),
                          np.maximum(-1.0 - n_y, n_y - size[..., 1]))
        near = valid & (dist <= m - 1.0)
        node_map = np.stack([n_x + self._offsets[n_label, 0],
                             n_y + self._offsets[n_label, 1]], axis=-1)
        top, bottom, left, right = slice(0, -1), slice(1, None), slice(0, -1), slice(1, None)
        corners = [(top, left), (top, right), (bottom, left), (bottom, right)]
        limit = CENTRE_CHECK_FRACTION * self.tolerance_px
        # -- quick decisions from the nodes ----------------------------------------------
        same4 = np.ones(shape_c, bool)
        near4 = np.ones(shape_c, bool)
        common_side = np.full(shape_c, 255, np.uint8)
        min_dist = np.full(shape_c, np.inf, np.float32)
        c_label0 = n_label[top, left]
        for rs, cs in corners:
            same4 &= n_label[rs, cs] == c_label0
            near4 &= near[rs, cs]
            common_side &= n_side[rs, cs]
            min_dist = np.minimum(min_dist, np.where(valid[rs, cs], dist[rs, cs], np.inf))
        # second differences along u (rows of nodes) and v, with their label checks
        smooth = valid[:, 1:-1] & valid[:, :-2] & valid[:, 2:] \
            & (n_label[:, :-2] == n_label[:, 1:-1]) & (n_label[:, 2:] == n_label[:, 1:-1])
        d2u = np.maximum(np.abs(n_x[:, :-2] - 2 * n_x[:, 1:-1] + n_x[:, 2:]),
                         np.abs(n_y[:, :-2] - 2 * n_y[:, 1:-1] + n_y[:, 2:]))
        d2u = np.where(smooth, d2u, np.inf)  # (th + 2, tw): nodes columns 1..tw
        smooth = valid[1:-1] & valid[:-2] & valid[2:] \
            & (n_label[:-2] == n_label[1:-1]) & (n_label[2:] == n_label[1:-1])
        d2v = np.maximum(np.abs(n_x[:-2] - 2 * n_x[1:-1] + n_x[2:]),
                         np.abs(n_y[:-2] - 2 * n_y[1:-1] + n_y[2:]))
        d2v = np.where(smooth, d2v, np.inf)  # (th, tw + 2): node rows 1..th
        # Next to a seam or an invalid node, a node's three-point stencil fails; the
        # stencil one node further on (same camera, same curvature to first order)
        # stands in, so that only cells a seam crosses need the slow path.
        d2u = self._fill_from_neighbours(d2u, axis=1)
        d2v = self._fill_from_neighbours(d2v, axis=0)
        estimate = np.full(shape_c, np.inf, np.float32)
        inner = (slice(1, -1), slice(1, -1))  # cells whose 4x4 stencil exists
        est = np.zeros((th - 1, tw - 1), np.float32)
        for di in (0, 1):
            for dj in (0, 1):
                du = d2u[1 + di:th + di, dj:tw - 1 + dj]
                dv = d2v[di:th - 1 + di, 1 + dj:tw + dj]
                est = np.maximum(est, (du + dv) / 8.0)
        estimate[inner] = est
        quick_pure = same4 & near4 & (estimate <= limit)
        n_far = self._far_outside(n_label, n_x, n_y, n_side)
        covered = self._witnessed([n_label[rs, cs] for rs, cs in corners],
                                  [n_far[rs, cs] for rs, cs in corners], shape_c)
        quick_empty = ~quick_pure & (covered | (same4 & ((common_side & 15) != 0)
                                                & (min_dist >= 1.0)))
        fallback = ~(quick_pure | quick_empty)
        # -- the other cells (few): centre and edge midpoints, as vectors ---------------
        f_idx = np.flatnonzero(fallback)
        pure = quick_pure.copy()
        empty = quick_empty.copy()
        if f_idx.size:
            fa, fb = np.divmod(f_idx, tw + 1)
            corner_ids = [(fa + di, fb + dj) for di in (0, 1) for dj in (0, 1)]
            k_label = [n_label[ij] for ij in corner_ids]
            k_x = [n_x[ij] for ij in corner_ids]
            k_y = [n_y[ij] for ij in corner_ids]
            c_label, c_x, c_y, c_side = self.evaluate_parallel(
                self._centre_soa[:, f_idx + k0 * (tw + 1)], q)
            same = np.ones(f_idx.size, bool)
            all_near = (c_side & _SIDE_INVALID) == 0
            common5 = c_side.copy()
            all_invalid = c_side == _SIDE_INVALID
            for ij, la in zip(corner_ids, k_label):
                same &= la == c_label
                all_near &= near[ij]
                common5 &= n_side[ij]
                all_invalid &= n_side[ij] == _SIDE_INVALID
            error = np.maximum(np.abs(0.25 * sum(k_x) - c_x), np.abs(0.25 * sum(k_y) - c_y))
            candidate = same & all_near & (error <= limit)
            same5 = same.copy()
            cand = np.flatnonzero(candidate)
            if cand.size:
                ca, cb = fa[cand], fb[cand]
                # midpoints: top, bottom (horizontal edges), left, right (vertical edges)
                h_top = (ca + k0) * (tw + 1) + cb
                h_bottom = (ca + k0 + 1) * (tw + 1) + cb
                v_left = (ca + k0) * (tw + 2) + cb
                v_right = (ca + k0) * (tw + 2) + cb + 1
                rays = np.concatenate([self._hmid_soa[:, h_top], self._hmid_soa[:, h_bottom],
                                       self._vmid_soa[:, v_left], self._vmid_soa[:, v_right]],
                                      axis=1)
                m_label, m_x, m_y, m_side = (a.reshape(4, -1) for a in
                                             self.evaluate_parallel(rays, q))
                pairs = [(0, 1), (2, 3), (0, 2), (1, 3)]  # corner indices of each edge
                ok = np.ones(cand.size, bool)
                err = error[cand]
                for e, (ka, kb) in enumerate(pairs):
                    ok &= (m_label[e] == c_label[cand]) & ((m_side[e] & _SIDE_INVALID) == 0)
                    err = np.maximum(err, np.abs(0.5 * (k_x[ka][cand] + k_x[kb][cand])
                                                 - m_x[e]))
                    err = np.maximum(err, np.abs(0.5 * (k_y[ka][cand] + k_y[kb][cand])
                                                 - m_y[e]))
                candidate[cand] = ok & (err <= limit)
            pure.reshape(-1)[f_idx] = candidate
            # empty: the same camera at all five points, all outside its frame on one
            # side; or every camera present is witnessed far outside.
            c_far = self._far_outside(c_label, c_x, c_y, c_side)
            covered5 = self._witnessed(
                [c_label] + k_label, [c_far] + [n_far[ij] for ij in corner_ids],
                (f_idx.size,))
            slow_empty = ~candidate & ((same5 & (((common5 & 15) != 0) | all_invalid))
                                       | covered5)
            empty.reshape(-1)[f_idx] = slow_empty
        exact = ~empty & ~pure
        self.last_classes = {'quick_pure': int(quick_pure.sum()),
                             'quick_empty': int(quick_empty.sum()),
                             'fallback': int(fallback.sum())}
        return node_map, empty, exact, pure

    @staticmethod
    def _fill_from_neighbours(d2, axis):
        """Replace infinite second differences by the larger finite neighbour along ``axis``."""
        d = d2 if axis == 1 else d2.T
        finite = np.where(np.isfinite(d), d, -np.inf)
        neighbour = np.full_like(d, -np.inf)
        neighbour[:, 1:] = finite[:, :-1]
        np.maximum(neighbour[:, :-1], finite[:, 1:], out=neighbour[:, :-1])
        filled = np.where(np.isfinite(d), d, neighbour)
        filled[filled == -np.inf] = np.inf
        return filled if axis == 1 else filled.T

    def _witnessed(self, labels, fars, shape):
        """Return True where every camera present among the points has a far point."""
        if len(self.rig) <= 64:
            present = np.zeros(shape, np.uint64)
            witnessed = np.zeros(shape, np.uint64)
            for la, fa in zip(labels, fars):
                bit = np.left_shift(np.uint64(1), np.maximum(la, 0).astype(np.uint64))
                present |= bit
                witnessed |= bit * fa.astype(np.uint64)
            return (present & ~witnessed) == 0
        covered = np.ones(shape, bool)
        for la in labels:
            witness = np.zeros(shape, bool)
            for lb, fb in zip(labels, fars):
                witness |= (lb == la) & fb
            covered &= witness
        return covered

    def _far_outside(self, label, x, y, side):
        """Return True where a point is farther outside its camera's frame than a cell spans."""
        size = self._sizes[label]
        dist = np.maximum(np.maximum(-1.0 - x, x - size[..., 0]),
                          np.maximum(-1.0 - y, y - size[..., 1]))
        invalid = (side & _SIDE_INVALID) != 0
        return np.where(invalid, self._invalid_is_far[label], dist >= self._far)

    def build_fast(self, roll, pitch):
        """
        Return the map from the coarse grid, interpolation, and exact mixed cells.

        The returned array is a view of a buffer owned by the builder (rows padded by one
        cell on each side, so not contiguous) and is overwritten by the next call. Only
        the rows in :attr:`band` (``(first, last + 1)``, the rows some camera sees) are
        defined; the others are left as they were.
        """
        import cv2

        start = time.perf_counter()
        s, half = self.step, self.step // 2
        tw, th = self._tiles_w, self._tiles_h
        height, width = self.geometry.shape
        q = self.camera_rotations(roll, pitch)
        node_map, empty, exact, pure = self._classify_seen_rows(q)
        t_grid = time.perf_counter()
        # Buffer pixel (r, c) is panorama pixel (r - s, c - s): the nodes one cell beyond
        # the panorama (k = -1 and k = n) sit inside it, so cv2.resize interpolates the
        # half cells at the border as well, and every cell is a full s x s block.
        if self._buffer is None:
            self._buffer = np.empty(((th + 2) * s, (tw + 2) * s, 2), np.float32)
        buf = self._buffer
        panorama = buf[s:s + height, s:s + width]
        # Only the rows of cells that some camera sees are built (and later remapped).
        active_rows = np.nonzero((~empty).any(axis=1))[0]
        if active_rows.size == 0:
            self.band = (0, 0)
            self.last_stats = {'total_s': time.perf_counter() - start, 'exact_pixels': 0}
            return panorama
        a0, a1 = int(active_rows[0]), int(active_rows[-1])
        # Nodes whose four cells are all empty are set to "outside": cv2.resize then
        # fills the cells between such nodes by itself, and only the ring of empty cells
        # next to seen ones needs filling.
        empty_cells = int(empty.sum())
        padded = np.pad(empty, 1, constant_values=True)
        lonely = padded[:-1, :-1] & padded[1:, :-1] & padded[:-1, 1:] & padded[1:, 1:]
        node_map[lonely] = OUTSIDE
        done = lonely[:-1, :-1] & lonely[1:, :-1] & lonely[:-1, 1:] & lonely[1:, 1:]
        empty &= ~done
        empty[:a0] = empty[a1 + 1:] = False
        exact[:a0] = exact[a1 + 1:] = False
        self.band = (max(0, a0 * s - half), min(height, a1 * s + half))
        # node rows k0 - 1 .. k1 + 1 (node_map rows k0 .. k1 + 2) cover cell rows a0..a1
        k0, k1 = max(0, a0 - 2), min(th - 1, a1 + 1)
        coarse = node_map[k0:k1 + 3]
        # The resize (OpenCV, no GIL) runs while numpy computes the cells it cannot do;
        # those are written into the buffer once it is done.
        if self._resize_pool is None:
            from concurrent.futures import ThreadPoolExecutor

            self._resize_pool = ThreadPoolExecutor(max_workers=1,
                                                   thread_name_prefix='lookup_resize')
        resized = self._resize_pool.submit(
            cv2.resize, coarse, ((tw + 2) * s, (k1 - k0 + 3) * s),
            dst=buf[k0 * s:(k1 + 3) * s], interpolation=cv2.INTER_LINEAR)
        # cell (a, b) covers panorama pixels [a s - s/2, a s + s/2) x [b s - s/2, ...)
        blocks = self._blocks(buf[half:half + (th + 1) * s, half:half + (tw + 1) * s],
                              th + 1, s, tw + 1, s)
        values, count = None, 0
        if exact.any():
            by, bx = np.nonzero(exact)
            rows, cols = by * s - half, bx * s - half
            if self.sub_step:
                values, count = self._refine(rows, cols, s, s, q)
            else:
                values = self._exact_pixels(rows, cols, s, s, q)
                count = int(values.size // 2)
        t_values = time.perf_counter()
        resized.result()
        t_resize = time.perf_counter()
        if empty.any():
            blocks[empty] = OUTSIDE
        if values is not None:
            blocks[exact] = values
        end = time.perf_counter()
        self.last_stats = {
            'total_s': end - start, 'grid_s': t_grid - start,
            'cells_s': t_values - t_grid, 'resize_wait_s': t_resize - t_values,
            'write_s': end - t_resize, 'exact_pixels': count, 'cells': int(pure.size),
            'pure_cells': int(pure.sum()), 'empty_cells': empty_cells, 'step': s}
        return panorama

    def _classify_seen_rows(self, q):
        """
        :meth:`classify` over the cell rows :meth:`seen_rows` leaves; the others are empty.

        Returns the full-size ``(node_map, empty, exact, pure)``.
        """
        s, half = self.step, self.step // 2
        tw, th = self._tiles_w, self._tiles_h
        node_map = np.full((th + 2, tw + 2, 2), OUTSIDE, np.float32)
        empty = np.ones((th + 1, tw + 1), bool)
        exact = np.zeros_like(empty)
        pure = np.zeros_like(empty)
        r0, r1 = self.seen_rows(q)
        if r1 <= r0:
            self.last_classes = {'quick_pure': 0, 'quick_empty': 0, 'fallback': 0}
            return node_map, empty, exact, pure
        # cell b covers rows [b s - s/2, b s + s/2); its second differences need the node
        # rows b - 1 .. b + 2, so one more node row on each side than the cells' corners
        c0, c1 = (r0 + half) // s, (r1 - 1 + half) // s
        k0, k1 = max(0, c0 - 1), min(th + 2, c1 + 3)
        if k1 - k0 < 3:
            k0, k1 = max(0, k1 - 3), max(0, k1 - 3) + 3
        part = self.classify(q, (k0, k1))
        node_map[k0:k1] = part[0]
        for full, local in zip((empty, exact, pure), part[1:]):
            full[k0:k1 - 1] = local
        return node_map, empty, exact, pure

    @staticmethod
    def _blocks(region, nby, bh, nbx, bw):
        """View ``(nby, nbx, bh, bw, 2)`` of a buffer region made of equal blocks."""
        blocks = region.reshape(nby, bh, nbx, bw, 2)
        if not np.shares_memory(blocks, region):  # pragma: no cover - numpy guarantees it
            raise RuntimeError('block view is not a view')
        return blocks.transpose(0, 2, 1, 3, 4)

    def _exact_pixels(self, row0, col0, bh, bw, q):
        """Exact map values ``(n, bh, bw, 2)`` of blocks starting at pixels row0, col0."""
        rows = row0[:, None] + np.arange(bh)[None, :]
        cols = col0[:, None] + np.arange(bw)[None, :]
        rays = self._rays_at(rows, cols, self._cos_el, self._sin_el, self._sin_az,
                             self._cos_az).reshape(3, -1)
        values = self.to_mosaic(*self.evaluate_parallel(rays, q))
        return values.reshape(len(row0), bh, bw, 2)

    def _refine(self, row0, col0, bh, bw, q):
        """
        Map values of mixed blocks by sub-blocks of :attr:`sub_step` pixels.

        The corners and centre of every sub-block are evaluated exactly; a sub-block with
        the same camera at all five, all within the gap around its frame and the bilinear
        error at the centre within 3/4 of the tolerance is interpolated; one outside its
        frame on one side at all five points by more than a pixel is empty; the others
        (where a seam crosses) are evaluated pixel by pixel. Returns ``(values, number of
        pixels evaluated exactly)``.
        """
        sub = self.sub_step
        n, ny, nx = len(row0), bh // sub, bw // sub
        corners = self._rays_of_sub_edges(row0, col0, ny, nx)
        centres = self._rays_of_sub_centres(row0, col0, ny, nx, edges=sub % 2 == 0)
        count_c = n * (ny + 1) * (nx + 1)
        label, x, y, side = self.evaluate_parallel(
            np.concatenate([corners.reshape(3, -1), centres.reshape(3, -1)], axis=1), q)
        size = self._sizes[label]
        dist = np.maximum(np.maximum(-1.0 - x, x - size[:, 0]),
                          np.maximum(-1.0 - y, y - size[:, 1]))
        valid = (side & _SIDE_INVALID) == 0
        near = valid & (dist <= self._margin - 1.0)
        mx = x + self._offsets[label, 0]
        my = y + self._offsets[label, 1]
        shape_k, shape_s = (n, ny + 1, nx + 1), (n, ny, nx)
        k_label, k_near, k_side = (a[:count_c].reshape(shape_k) for a in (label, near, side))
        k_dist = np.where(valid, dist, np.inf)[:count_c].reshape(shape_k)
        k_mx, k_my = mx[:count_c].reshape(shape_k), my[:count_c].reshape(shape_k)
        s_label, s_near, s_side = (a[count_c:].reshape(shape_s) for a in (label, near, side))
        s_mx, s_my = mx[count_c:].reshape(shape_s), my[count_c:].reshape(shape_s)
        s_dist = np.where(valid, dist, np.inf)[count_c:].reshape(shape_s)
        top, bottom = slice(None, -1), slice(1, None)
        corner_sl = [(top, top), (top, bottom), (bottom, top), (bottom, bottom)]
        same, all_near = np.ones(shape_s, bool), s_near.copy()
        common = s_side.copy()
        min_dist = s_dist.copy()
        for rs, cs in corner_sl:
            same &= k_label[:, rs, cs] == s_label
            all_near &= k_near[:, rs, cs]
            common &= k_side[:, rs, cs]
            min_dist = np.minimum(min_dist, k_dist[:, rs, cs])
        c00, c01, c10, c11 = ([k_mx[:, rs, cs], k_my[:, rs, cs]] for rs, cs in corner_sl)
        error = np.maximum(np.abs(0.25 * (c00[0] + c01[0] + c10[0] + c11[0]) - s_mx),
                           np.abs(0.25 * (c00[1] + c01[1] + c10[1] + c11[1]) - s_my))
        pure = same & all_near & (error <= CENTRE_CHECK_FRACTION * self.tolerance_px)
        empty = same & ~pure & ((common & 15) != 0) & (min_dist >= 1.0)
        # bilinear interpolation of the pure sub-blocks: the fixed weights (sub * sub, 4)
        # times the four corners (4, 2) of each
        values = np.empty((n, ny, sub, nx, sub, 2), np.float32)
        view = values.transpose(0, 1, 3, 2, 4, 5)  # (n, ny, nx, sub, sub, 2)
        if pure.any():
            k = np.stack([k_mx, k_my], axis=-1)  # (n, ny+1, nx+1, 2)
            corners4 = np.stack([k[:, rs, cs][pure] for rs, cs in corner_sl], axis=1)
            view[pure] = np.matmul(self._sub_weights, corners4).reshape(-1, sub, sub, 2)
        if empty.any():
            view[empty] = OUTSIDE
        rest = ~pure & ~empty
        count = 0
        if rest.any():
            bi, byy, bxx = np.nonzero(rest)
            exact = self._exact_pixels(row0[bi] + byy * sub, col0[bi] + bxx * sub, sub, sub, q)
            view[rest] = exact
            count = int(exact.size // 2)
        return values.reshape(n, bh, bw, 2), count

    def _rays_of_sub_edges(self, row0, col0, ny, nx):
        """Rays ``(3, n, ny + 1, nx + 1)`` at the corners of the sub-blocks (pixel edges)."""
        sub = self.sub_step
        rows = row0[:, None] + sub * np.arange(ny + 1)[None, :]
        cols = col0[:, None] + sub * np.arange(nx + 1)[None, :]
        return self._rays_at(rows, cols, self._cos_el_e, self._sin_el_e, self._sin_az_e,
                             self._cos_az_e)

    def _rays_of_sub_centres(self, row0, col0, ny, nx, edges):
        """Rays ``(3, n, ny, nx)`` at the centres of the sub-blocks."""
        sub = self.sub_step
        offset = sub // 2
        rows = row0[:, None] + sub * np.arange(ny)[None, :] + offset
        cols = col0[:, None] + sub * np.arange(nx)[None, :] + offset
        if edges:
            return self._rays_at(rows, cols, self._cos_el_e, self._sin_el_e, self._sin_az_e,
                                 self._cos_az_e)
        return self._rays_at(rows, cols, self._cos_el, self._sin_el, self._sin_az,
                             self._cos_az)

    def _rays_at(self, rows, cols, cos_el, sin_el, sin_az, cos_az):
        """Rays ``(3, n, len_rows, len_cols)`` from per-block pixel rows and columns."""
        rows, cols = rows + self._pad, cols + self._pad
        ce = cos_el[rows][:, :, None]
        rays = np.empty((3,) + rows.shape + (cols.shape[1],), np.float32)
        np.multiply(ce, sin_az[cols][:, None, :], out=rays[0])
        rays[1] = -sin_el[rows][:, :, None]
        np.multiply(ce, cos_az[cols][:, None, :], out=rays[2])
        return rays
