r"""
Personal regions of interest: a levelled rectilinear (pinhole) view rendered from the rig.

Paper A: "navigation through the video panorama implies user-controlled personal regions
of interest with adjustable electronic zoom and resolution". A *view* is a virtual
pinhole camera that sits at the rig's centre, levelled by the attitude, and looks along
``azimuth`` (rad, 0 = the panorama's centre column, i.e. the body heading; positive to the
right) and ``elevation`` (rad, positive up), with a horizontal field of view ``fov_h``
(the zoom) and an output size ``W x H``. Its intrinsics are

.. math::  f_x = f_y = \frac{W/2}{\tan(fov_h/2)},\quad c_x = \frac{W-1}{2},\quad
           c_y = \frac{H-1}{2}

(OpenCV pixel centres at integers, as the panorama). Frames: the view's optical frame
``V`` (x right, y down, z along the view) goes into the panorama frame ``P``
(:mod:`.projection`: levelled, x right, y down along gravity, z the heading) by
``R_PV = [x_V | y_V | z_V]`` with ``z_V = [cos el sin az, -sin el, cos el cos az]``,
``x_V = [cos az, 0, -sin az]`` (horizontal, so the view's rows are parallel to the true
horizon whatever the rig's roll and pitch) and ``y_V = z_V x x_V``. The true horizon
(``el = 0``) is then the image row ``c_y + f tan(elevation)`` in every column.

Pixels are rendered straight from the camera images, through the same code as the
panorama (one home for both, no second copy): a view pixel's ray ``[u - c_x, v - c_y, f]``
goes into camera ``i`` by ``Q_i R_PV diag(1, 1, f)`` with ``Q_i = R_0i T(roll, pitch)``
(:meth:`~.rig_projection.RigProjection.camera_rotations`, eq. 7), the camera is chosen
by eq. 6 and the pixel found through that camera's lens (``K_i``, ``D_i``), all in
:class:`~.rig_projection.RigProjection`. Scaling a ray changes neither the camera choice
(the largest ``z`` in every camera scales alike) nor its pixel, so the view's pixel
offsets are fixed tables and only that 3x3 product moves with the attitude, the direction
and the zoom.

A frame is drawn one of three ways (``renderer``). ``'grid'`` (the default): a frame
set's first frame (live video: every frame) straight from the camera images, one
``cv2.remap`` through a map interpolated from a coarse exact grid (:mod:`.view_grid`),
a frame set drawn again (moving over it, or another view posed alike) as ``'warp'``:
up to the lens, a view pixel's ray in camera ``i`` is a homography, so each camera's
part of the view (a convex region bounded by eq. 6's great circles, straight lines in a
rectilinear view) is one ``cv2.warpPerspective`` of its undistorted image plane, made
from the mosaic once per frame set for all the views sharing it (:mod:`.view_warp`).
``'map'``: the lookup (view pixel -> mosaic pixel) by the panorama's fast builder
(:class:`~.lookup.LookupBuilder`, within ``tolerance_px`` camera pixels at every pixel:
``test/panorama/test_view.py``), one fixed-point ``cv2.remap`` per frame. A ``'grid'``
or ``'warp'`` view still for :data:`STILL_FRAMES_BEFORE_MAP` frames remaps its lookup
from then on (the cheapest frame). The view follows the attitude and its pose when its
rotation in the cameras moves by more than ``rebuild_threshold_deg`` or the zoom
changes. Pixels no camera sees are black; :meth:`LevelledView.covered_fraction` says
how many are seen.
"""
import math
from typing import Any, cast, Optional, Tuple

from accelcal_ros.camera.rig import resolve_imu_to_camera
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.lookup import LookupBuilder
from accelcal_ros.panorama.mosaic import MosaicLayout, OUTSIDE
from accelcal_ros.panorama.rig_projection import RigProjection, tilt_matrix
from accelcal_ros.panorama.view_grid import CameraSources, four_channels, GridMaps
from accelcal_ros.panorama.view_pose import (check_view_size, finite_number, focal_px,
                                             horizon_row, view_camera_matrix, view_rotation,
                                             ViewPose)
from accelcal_ros.panorama.view_warp import CameraPlanes, DEFAULT_PLANE_SCALE, WarpPlan
import numpy as np
from numpy.typing import ArrayLike

DEFAULT_VIEW_GAP_PX = 64
"""Black gap between the images of a views-only mosaic (:class:`ViewMosaic`)."""
RENDERERS = ('grid', 'warp', 'map')
"""How :meth:`LevelledView.render` draws: from the cameras by interpolated maps
(:mod:`.view_grid`, the default; a frame set drawn again as ``'warp'``), a homography
per camera (:mod:`.view_warp`) or a ``cv2.remap`` of the lookup map."""
STILL_FRAMES_BEFORE_MAP = 3
"""A ``'grid'`` or ``'warp'`` view still for this many frames builds its lookup and remaps
from then on."""
COVERAGE_SAMPLES = 96
"""Samples along the longer side of a view for :meth:`LevelledView.covered_fraction`
(the other side as far apart, at least one)."""


def coverage_samples(size: int, step: float) -> np.ndarray:
    """
    Return the pixel indices sampled along a side of ``size`` pixels, about ``step`` apart.

    The centres of ``round(size / step)`` equal parts, at least one (a side shorter than
    ``step`` is sampled at its middle) and at most ``size``.
    """
    count = min(size, max(1, int(round(size / step))))
    centres = (np.arange(count) + 0.5) * (size / count) - 0.5
    return np.unique(np.clip(np.round(centres), 0, size - 1)).astype(np.intp)


class _ViewGrid:
    """
    The view as the fast builder sees it: pixel offsets ``u - c_x``, ``v - c_y`` and 1.

    :class:`~.lookup.LookupBuilder` asks its geometry for a size and for rays; the view's
    rays ``[u - c_x, v - c_y, 1]`` are separable like the panorama's, and the focal length
    and direction are folded into the rotations (:meth:`ViewLookupBuilder.camera_rotations`).
    """

    projection = 'rectilinear'

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.cx, self.cy = (width - 1) / 2.0, (height - 1) / 2.0

    @property
    def shape(self) -> Tuple[int, int]:
        return self.height, self.width

    def azimuth_rad(self, u: ArrayLike) -> np.ndarray:
        # the builder takes sin/cos of these for its panorama tables; the view replaces
        # those tables (ViewLookupBuilder._set_ray_tables), so any finite value does
        return np.asarray(u, dtype=float) * 0.0

    def elevation_rad(self, v: ArrayLike) -> np.ndarray:
        return np.asarray(v, dtype=float) * 0.0

    def rays(self, u: ArrayLike, v: ArrayLike) -> np.ndarray:
        x, y = np.broadcast_arrays(np.asarray(u, float) - self.cx,
                                   np.asarray(v, float) - self.cy)
        return np.stack([x, y, np.ones_like(x)], axis=-1)


class ViewLookupBuilder(LookupBuilder):
    """
    The panorama's fast lookup builder (:class:`~.lookup.LookupBuilder`) for one view.

    Maps view pixels to the coordinates of the mosaic ``layout`` (shared with the stitcher
    or a :class:`ViewMosaic`). :meth:`set_view` sets the direction and zoom; then
    :meth:`~.lookup.LookupBuilder.build_fast` ``(roll, pitch)`` (or ``build_exact``) gives
    the ``(H, W, 2)`` map.
    """

    resize_in_worker = False

    def __init__(self, rig: Any, width: int, height: int, layout: MosaicLayout,
                 imu_to_camera: ArrayLike, grid_step: int = 16,
                 tolerance_px: float = 0.1) -> None:
        width, height = check_view_size(width, height)
        self._shared_layout = layout
        self._focal = focal_px(width, math.radians(60.0))
        self._view_matrix = np.diag([1.0, 1.0, self._focal])
        self._density: Optional[float] = None
        self._grid = _ViewGrid(width, height)
        LookupBuilder.__init__(self, rig, cast(Any, self._grid), imu_to_camera, grid_step,
                               tolerance_px)
        # pixel-edge tables of the sub-block corners (the builder made panorama ones)
        s = self.step
        self._sin_az_e = (np.arange(-s, (self._tiles_w + 1) * s + 1) - 0.5
                          - self._grid.cx).astype(np.float32)
        self._cos_az_e = np.ones_like(self._sin_az_e)
        self._sin_el_e = -(np.arange(-s, (self._tiles_h + 1) * s + 1) - 0.5
                           - self._grid.cy).astype(np.float32)
        self._cos_el_e = np.ones_like(self._sin_el_e)

    def _place_images(self, gap: int) -> None:
        """Use the shared mosaic layout (its gap, not one sized for this view)."""
        self.layout = self._shared_layout
        self._offsets = np.asarray(self.layout.offsets, dtype=np.float32)

    def _set_ray_tables(self, pad: int, cols_end: int, rows_end: int) -> None:
        """Tables of ``u - c_x`` and ``v - c_y`` (as ``sin az`` and ``-sin el``, cosines 1)."""
        self._pad = pad
        g = self._grid
        self._sin_az = (np.arange(-pad, cols_end) - g.cx).astype(np.float32)
        self._cos_az = np.ones_like(self._sin_az)
        self._sin_el = -(np.arange(-pad, rows_end) - g.cy).astype(np.float32)
        self._cos_el = np.ones_like(self._sin_el)

    def seen_rows(self, q: np.ndarray) -> Tuple[int, int]:
        """Every row of a view is evaluated (a view is small and mostly seen)."""
        return 0, self.geometry.height

    def cell_extent_px(self, step: int) -> float:
        """Bound on a ``step`` cell's extent in camera pixels: diagonal / f times the density."""
        if self._density is None:
            self._density = max(self._pixel_density(c, lim) for c, lim in
                                zip(self.rig.cameras, self._limits2))
        return math.sqrt(2.0) * step / self._focal * self._density

    def set_view(self, pose: ViewPose) -> None:
        """Set the direction and zoom of the next build."""
        self._focal = focal_px(self.geometry.width, pose.fov_h_rad)
        self._view_matrix = view_rotation(pose.azimuth_rad, pose.elevation_rad) @ np.diag(
            [1.0, 1.0, self._focal])
        self._far = self.cell_extent_px(self.step)
        frame_gap_px = np.array([(math.sqrt(lim) - radius) * min(c.K[0, 0], c.K[1, 1])
                                 for c, (radius, lim) in zip(self.rig.cameras, self._radii)])
        self._invalid_is_far = frame_gap_px > self._far

    def camera_rotations(self, roll: float, pitch: float) -> np.ndarray:
        """Return ``Q_i R_PV diag(1, 1, f)``: view pixel offsets -> camera ``i`` (eq. 7)."""
        return RigProjection.camera_rotations(self, roll, pitch) @ self._view_matrix


class ViewMosaic:
    """
    The rig's images side by side (:class:`~.mosaic.MosaicLayout`) for views without a stitcher.

    :meth:`set_image` copies camera ``index``'s image (uint8 HxW or HxWx3, the rig's size)
    in; grey images are expanded for a colour mosaic.
    """

    def __init__(self, rig: Any, channels: int = 3, gap: int = DEFAULT_VIEW_GAP_PX) -> None:
        if channels not in (1, 3):
            raise InputError(f'channels must be 1 or 3, got {channels!r}')
        self.rig = rig
        self.channels = channels
        self.layout = MosaicLayout.for_rig(rig, gap=gap)
        shape = (self.layout.height, self.layout.width) + ((3,) if channels == 3 else ())
        self.image = np.zeros(shape, np.uint8)
        self.version = 0
        """Counts :meth:`set_image` calls: views reuse per-frame-set work while it stays."""

    def set_image(self, index: int, image: Optional[np.ndarray]) -> None:
        """Copy camera ``index``'s image into the mosaic (None blacks it out)."""
        import cv2

        cam = self.rig.cameras[index]
        self.version += 1
        x0, y0 = self.layout.offsets[index]
        view = self.image[y0:y0 + cam.height, x0:x0 + cam.width]
        if image is None:
            view[...] = 0
            return
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.shape[:2] != (cam.height, cam.width) or \
                image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3)):
            raise InputError(f'camera {index} ({cam.name!r}): expected an 8-bit '
                             f'{cam.width}x{cam.height} image (HxW or HxWx3), got '
                             f'{image.dtype} {image.shape}')
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[:, :, 0]
        if self.channels == 3 and image.ndim == 2:
            cv2.cvtColor(image, cv2.COLOR_GRAY2BGR, dst=view)
        elif self.channels == 1 and image.ndim == 3:
            view[...] = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        else:
            np.copyto(view, image)


class LevelledView:
    """
    One levelled virtual camera: pose, attitude, lookup and rendering from a mosaic.

    ``layout`` is the mosaic the frames come in (:class:`ViewMosaic` or the stitcher's
    ``builder.layout``); ``imu_to_camera`` defaults to the rig file's. Typical use::

        mosaic = ViewMosaic(rig)
        view = LevelledView(rig, mosaic.layout, 1280, 720, ViewPose.from_degrees(30, 0, 60))
        view.set_attitude(roll, pitch)               # radians, REP-103
        for i, image in enumerate(images):
            mosaic.set_image(i, image)
        frame = view.render(mosaic.image, mosaic.version)  # owned by the view: copy to keep

    ``renderer`` (:data:`RENDERERS`): ``'grid'`` draws a frame set's first frame from the
    camera images (:mod:`.view_grid`; ``sources`` may be shared) and the rest as
    ``'warp'``, by a homography per camera from its undistorted plane (:mod:`.view_warp`;
    ``planes`` may be shared by the views of one mosaic); ``'map'`` by one ``cv2.remap``
    of the lookup. Bad values raise :class:`InputError` and leave the view as it was.
    """

    def __init__(self, rig: Any, layout: MosaicLayout, width: int, height: int,
                 pose: Optional[ViewPose] = None, imu_to_camera: Optional[ArrayLike] = None,
                 grid_step: int = 16, tolerance_px: float = 0.1,
                 rebuild_threshold_deg: float = 0.005, renderer: str = 'grid',
                 planes: Optional[CameraPlanes] = None,
                 sources: Optional[CameraSources] = None,
                 plane_scale: float = DEFAULT_PLANE_SCALE) -> None:
        import cv2

        if imu_to_camera is None:
            imu_to_camera = resolve_imu_to_camera(rig)[0]
        if not (math.isfinite(rebuild_threshold_deg) and rebuild_threshold_deg >= 0):
            raise InputError(f'rebuild_threshold_deg must be >= 0, got {rebuild_threshold_deg!r}')
        if renderer not in RENDERERS:
            raise InputError(f'renderer must be one of {", ".join(RENDERERS)}, got {renderer!r}')
        self._cv2 = cv2
        self.rig = rig
        self.renderer = renderer
        self.width, self.height = check_view_size(width, height)
        self.builder = ViewLookupBuilder(rig, self.width, self.height, layout, imu_to_camera,
                                         grid_step, tolerance_px)
        self.planes = planes
        self.sources = sources
        self.tolerance_px = float(tolerance_px)
        self.plane_scale = float(plane_scale)
        self.rebuild_threshold_deg = float(rebuild_threshold_deg)
        self.pose = pose if pose is not None else ViewPose()
        self.attitude: Optional[Tuple[float, float]] = None
        self._built: Optional[Tuple[np.ndarray, float]] = None  # (rotation, fov) of the map
        self._map: Optional[np.ndarray] = None
        self._plan: Optional[WarpPlan] = None
        self._grid: Optional[GridMaps] = None
        self._grid_buffer: Any = None  # reused from pose to pose
        self._target: Tuple[Any, ...] = (None,)  # (attitude, pose), R, A_i or None
        self._last_version: Any = None
        self._fixed: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._band = (0, 0)
        self._frames_on_map = 0
        self._covered: Optional[float] = None
        self._out: Optional[np.ndarray] = None
        self._scratch: Optional[np.ndarray] = None
        self._canvas: Any = None
        self.last_frame_key: Any = None
        """What the frame in the buffer shows (set by :class:`~.view_set.ViewSet`)."""
        self.rebuild_count = 0

    @property
    def camera_matrix(self) -> np.ndarray:
        """Return the view's ``K`` (3x3, pixels) for its current zoom."""
        return view_camera_matrix(self.width, self.height, self.pose.fov_h_rad)

    def horizon_row(self) -> Optional[float]:
        """Row of the true horizon in this view (every column), None when not in view."""
        return horizon_row(self.height, self.width, self.pose)

    def set_pose(self, pose: ViewPose) -> None:
        """Point the view (the lookup is rebuilt at the next frame if it moved)."""
        if not isinstance(pose, ViewPose):
            raise InputError(f'expected a ViewPose, got {type(pose).__name__}')
        self.pose = pose

    def set_attitude(self, roll: float, pitch: float) -> None:
        """Set the rig's roll and pitch (radians, REP-103); NaN/inf raise, keeping the last."""
        roll, pitch = finite_number('roll', roll), finite_number('pitch', pitch)
        self.attitude = (roll, pitch)

    def _rotation(self) -> Tuple[np.ndarray, float]:
        assert self.attitude is not None
        if self._target[0] != (self.attitude, self.pose):  # computed once per pose
            t = tilt_matrix(self.attitude[0], self.attitude[1], self.builder.imu_to_camera)
            self._target = ((self.attitude, self.pose), t @ view_rotation(
                self.pose.azimuth_rad, self.pose.elevation_rad), None)
        return self._target[1], self.pose.fov_h_rad

    def needs_rebuild(self, target: Optional[Tuple[np.ndarray, float]] = None) -> bool:
        """Return True when the attitude or the view moved past the threshold since the map."""
        if self._built is None:
            return True
        rotation, fov = self._rotation() if target is None else target
        old_rotation, old_fov = self._built
        cosine = (np.trace(rotation @ old_rotation.T) - 1.0) / 2.0
        moved = math.degrees(math.acos(min(1.0, max(-1.0, cosine))))
        return moved > self.rebuild_threshold_deg or fov != old_fov

    def update(self) -> bool:
        """
        Follow the attitude and the view if they moved; return True if they did.

        The ``'map'`` renderer rebuilds its lookup; the ``'warp'`` one recomputes its
        homographies and regions (the lookup is then built only when asked for).
        """
        if self.attitude is None:
            raise InputError('no attitude yet: call set_attitude() before rendering a view')
        target = self._rotation()
        if not self.needs_rebuild(target):
            return False
        self.builder.set_view(self.pose)
        self._map = None
        self._plan = None
        self._grid = None
        if self.renderer == 'map':
            self._build_map()
        self._built = target
        self._fixed = None
        self._frames_on_map = 0
        self._covered = None
        self.rebuild_count += 1
        return True

    def _build_map(self) -> np.ndarray:
        assert self.attitude is not None
        self._map = self.builder.build_fast(*self.attitude)
        self._band = self.builder.band
        return self._map

    def shared_planes(self) -> CameraPlanes:
        """Return the undistorted camera planes this view draws from (made on first use)."""
        if self.planes is None:
            self.planes = CameraPlanes(self.builder, self.plane_scale)
        return self.planes

    def _planes_hold(self, version: Any) -> bool:
        """Return True when this frame set is drawn again (its planes pay off from now)."""
        if version is None:
            return False
        return version == self._last_version or (
            self.planes is not None and self.planes.holds(version))

    def shared_sources(self) -> CameraSources:
        """Return the camera images the ``'grid'`` renderer reads (made on first use)."""
        if self.sources is None:
            self.sources = CameraSources(self.builder.layout,
                                         [(c.width, c.height) for c in self.rig.cameras])
        return self.sources

    def camera_rotations(self) -> np.ndarray:
        """Return ``A_i``: view pixel offsets -> camera ``i`` (n, 3, 3), once per pose."""
        if self.update() or self._target[2] is None:
            attitude = cast(Tuple[float, float], self.attitude)
            self._target = (*self._target[:2], self.builder.camera_rotations(*attitude))
        return self._target[2]

    def plan(self) -> WarpPlan:
        """Return the current :class:`~.view_warp.WarpPlan` (regions and homographies)."""
        rotations = self.camera_rotations()
        if self._plan is None:
            self._plan = WarpPlan(rotations, self.shared_planes(), self.width, self.height,
                                  self.builder._grid.cx, self.builder._grid.cy)
        return self._plan

    def lookup(self) -> np.ndarray:
        """Return the current map ``(H, W, 2)`` (rows outside the band hold no camera)."""
        self.update()
        if self._map is None:
            self._build_map()
        assert self._map is not None
        full = np.full((self.height, self.width, 2), OUTSIDE, np.float32)
        r0, r1 = self._band
        full[r0:r1] = self._map[r0:r1]
        return full

    def render(self, mosaic: np.ndarray, version: Any = None) -> np.ndarray:
        """
        Return the view of ``mosaic`` (an internal buffer, overwritten next frame: copy it).

        ``version`` (e.g. :attr:`ViewMosaic.version`) lets views share per frame set work
        (colour conversion, planes); None: done on every call. Pixels no camera sees are 0.
        """
        self.update()
        self.last_frame_key = None
        shape = (self.height, self.width) + mosaic.shape[2:]
        if self._out is None or self._out.shape != shape:
            self._out = np.zeros(shape, np.uint8)
        self._frames_on_map += 1
        if self.renderer != 'map' and self._frames_on_map <= STILL_FRAMES_BEFORE_MAP:
            plan = self.plan()
            work = (self.height, self.width, 4) if len(shape) == 3 else shape
            if self._scratch is None or self._scratch.shape != work:
                self._scratch = np.zeros(work, np.uint8)
                self._canvas = np.zeros(work, np.uint8) if len(shape) == 3 else self._out
            if self.renderer == 'grid' and not self._planes_hold(version):
                if self._grid is None:
                    g = self.builder._grid
                    self._grid = GridMaps(plan, self.builder, self.camera_rotations(), g.cx,
                                          g.cy, tolerance_px=self.tolerance_px,
                                          buffers=self._grid_buffer)
                    self._grid_buffer = self._grid.buffers
                canvas = self._canvas if len(shape) == 3 and four_channels() else self._out
                self._grid.render(self.shared_sources(), mosaic, version, self._out, canvas)
            else:
                self.shared_planes().prepare(mosaic, plan.needs, version)
                plan.render(cast(CameraPlanes, self.planes), self._out, self._canvas,
                            self._scratch)
            self._last_version = version
            return self._out
        if self._map is None:
            self._build_map()
        return self._render_map(mosaic)

    def copy_frame(self, other: 'LevelledView', key: Any = None) -> np.ndarray:
        """Take ``other``'s last frame (same pose, attitude and size) as this view's."""
        self.update()
        assert other._out is not None
        if self._out is None or self._out.shape != other._out.shape:
            self._out = np.empty_like(other._out)
        np.copyto(self._out, other._out)
        self.last_frame_key = key
        return self._out

    def _render_map(self, mosaic: np.ndarray) -> np.ndarray:
        cv2 = self._cv2
        out = self._out
        assert out is not None
        r0, r1 = self._band
        out[:r0] = 0
        out[r1:] = 0
        if r1 <= r0:
            return out
        fine = self._map
        assert fine is not None
        if self._fixed is None:  # converting costs less than a remap from floats saves
            self._fixed = cv2.convertMaps(fine[r0:r1], None, cv2.CV_16SC2)
        cv2.remap(mosaic, self._fixed[0], self._fixed[1], cv2.INTER_LINEAR,
                  dst=out[r0:r1], borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return out

    def covered_fraction(self) -> float:
        """
        Fraction of the view's pixels some camera sees (once per pose).

        A pixel counts when its point lies within the chosen camera's frame to half a pixel
        beyond its outermost pixel centres; counted at :data:`COVERAGE_SAMPLES` pixels along
        the longer side and as far apart along the other (at least one: a 4096 x 16 view),
        off the pose's ``'grid'`` map if any (:meth:`.GridMaps.seen`).
        """
        self.update()
        if self._covered is None:
            step = max(1.0, max(self.width, self.height) / COVERAGE_SAMPLES)
            u, v = (coverage_samples(n, step) for n in (self.width, self.height))
            if self._grid is not None:
                seen = self._grid.seen(v, u)
            else:
                rays = self.builder.geometry.rays(u[None, :], v[:, None]).reshape(-1, 3)
                label, x, y, side = self.builder.evaluate(
                    rays, self.builder.camera_rotations(*cast(Tuple[float, float],
                                                              self.attitude)))
                size = self.builder._sizes[label]
                seen = ((side & 16) == 0) & (x >= -0.5) & (x <= size[:, 0] - 0.5) & \
                    (y >= -0.5) & (y <= size[:, 1] - 0.5)
            self._covered = float(seen.mean())
        return self._covered
