r"""
A levelled view rendered straight from the camera images: one ``cv2.remap`` per frame.

The :class:`~.view_warp.WarpPlan` of a pose splits the view into each camera's convex
region (eq. 6's half-planes, the camera's front and its frame's extent). Here the whole
view is one ``cv2.remap`` from the mosaic of the cameras' own images (no undistorted
plane in between: one resampling of the image, as the lookup renderer), through one map
(view pixel -> mosaic pixel) made per pose from each camera's map, a smooth function of
the view pixel over its region (the camera's homography, then its lens):

1. The camera's map is evaluated exactly on a coarse grid over the bounding box of its
   region (:meth:`~.rig_projection.RigProjection._evaluate_soa` with that camera only:
   the same ``K_i``, ``D_i`` as the panorama, no second copy), every
   :data:`GRID_STEP_PX` view pixels, half a cell beyond the box on every side;
2. ``cv2.resize`` (bilinear) spreads it to every pixel of the box: its sample positions
   ``(x + 1/2) / s - 1/2`` fall exactly on the nodes' placement, and the half cell of
   margin keeps the box's pixels off the resize's clamped border. The error of the
   bilinear interpolation is measured against the exact lens by
   ``test/panorama/test_view_grid.py`` (:data:`GRID_STEP_PX` is chosen for it);
3. The box's pixels in the region (a ``cv2.fillPoly`` mask through every row's first and
   last column) are copied into the view's map; rows some pixel of which no region holds
   are ``OUTSIDE`` first. A pixel just beyond a camera's frame reads the mosaic's black
   gap (``gap`` pixels: :attr:`~.mosaic.MosaicLayout.gap`), as the panorama's rule; a
   node the lens cannot take or one mapped beyond the gap holds :data:`FAR`, so no pixel
   reads a neighbour's image. A colour view is drawn in 4 channels (the cameras'
   rectangles the maps reach converted once per frame set for all the views: OpenCV 5
   remaps 8-bit 4-channel images from float maps about twice as fast as 3-channel ones,
   OpenCV 4.6 about as fast) and converted back.

Per pose: the plan and the view's map (the part that moves with the view); per frame
set: the 4-channel camera images; per frame: the remap.
"""
from typing import Any, cast, Dict, List, Optional, Tuple

from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.view_warp import grow, Rect, WarpPlan
import numpy as np

GRID_STEP_PX = 16
"""View pixels between the exactly evaluated nodes of a camera's map (halved, twice at
most, while the error at the cells' centres exceeds :data:`CHECK_FRACTION` of the
tolerance)."""
FAR = -1.0e8
"""A map node no pixel may read from: a pixel with any weight on it (at least
``1 / (2 s)^2`` at node spacing ``s``) lands far outside the mosaic."""
FIXED_POINT_BEFORE = 5
"""OpenCV major versions below this get each pose's map in 16-bit fixed point: OpenCV 4.6
remaps an 8-bit 4-channel 1280x720 image from a fixed-point map about 0.6 ms faster than
from a float map (the conversion costs 0.5 ms); OpenCV 5 remaps from the float map
faster (1.9 against 2.5 ms)."""
CHECK_FRACTION = 0.75
"""Share of ``tolerance_px`` the error at a cell's centre may reach (as the lookup's)."""


class CameraSources:
    """
    The rig cameras' images as the remaps read them, per frame set (shared by views).

    ``layout`` is the mosaic's :class:`~.mosaic.MosaicLayout`; :meth:`get` returns camera
    ``i``'s part of the mosaic: for a colour mosaic a 4-channel copy of which only the
    rectangle asked for is sure to be converted (once per ``version``: a view asking for
    more converts only what is new), for grey the mosaic's own slice.
    """

    def __init__(self, layout: Any, sizes: List[Tuple[int, int]]) -> None:
        self.offsets = [(int(x), int(y)) for x, y in layout.offsets]
        self.sizes = sizes
        self._done: Dict[int, Rect] = {}
        self._buffer: Optional[np.ndarray] = None
        self._version: Any = object()

    def get(self, mosaic: np.ndarray, i: int, rect: Rect, version: Any = None) -> np.ndarray:
        """Return camera ``i``'s image of ``mosaic``, right within ``rect`` (camera pixels)."""
        import cv2

        (x0, y0), (w, h) = self.offsets[i], self.sizes[i]
        part = mosaic[y0:y0 + h, x0:x0 + w]
        if not (mosaic.ndim == 3 and mosaic.shape[2] == 3):
            return part
        if version is None or version != self._version:
            self._done.clear()
            self._version = object() if version is None else version
        buffer = self.image(mosaic)[y0:y0 + h, x0:x0 + w]
        parts, done = grow(self._done.get(i), rect)   # convert only what is new
        for a0, b0, a1, b1 in parts:
            if a1 > a0 and b1 > b0:
                cv2.cvtColor(part[b0:b1, a0:a1], cv2.COLOR_BGR2BGRA, dst=buffer[b0:b1, a0:a1])
        self._done[i] = done
        return buffer

    def image(self, mosaic: np.ndarray) -> np.ndarray:
        """
        Return the whole mosaic as the remaps read it (4 channels for colour, else itself).

        Of a colour mosaic only what :meth:`get` converted is current; the gaps stay black.
        """
        if not (mosaic.ndim == 3 and mosaic.shape[2] == 3):
            return mosaic
        shape = mosaic.shape[:2] + (4,)
        if self._buffer is None or self._buffer.shape != shape:
            self._buffer = np.zeros(shape, np.uint8)
            self._done.clear()
        return self._buffer


class GridMaps:
    """
    One map over one pose's view (view pixel -> mosaic pixel), each camera's part in it.

    ``plan`` is the pose's :class:`~.view_warp.WarpPlan`, ``projection`` the view's
    builder (:class:`~.rig_projection.RigProjection`) and ``rotations`` its camera
    rotations ``A_i`` (view pixel offsets -> camera ``i``) with the view's centre
    ``(cx, cy)``. Each camera's interpolated map is copied into :attr:`map` through the
    mask of its region; the rows no camera fully holds are first set to ``OUTSIDE``.
    """

    def __init__(self, plan: WarpPlan, projection: Any, rotations: np.ndarray, cx: float,
                 cy: float, step: int = GRID_STEP_PX, tolerance_px: float = 0.1) -> None:
        import cv2

        self.plan = plan
        self.worst_px = 0.0
        """The largest interpolation error found at the cells' centres (camera pixels)."""
        self.map = np.empty((plan.height, plan.width, 2), np.float32)
        """View pixel -> mosaic pixel (float32, ``OUTSIDE`` where no camera is)."""
        self.rects: Dict[int, Rect] = {}  # camera: the pixels its map reaches
        for r0, r1 in plan.blank_rows:
            self.map[r0:r1] = OUTSIDE
        layout = projection.layout
        for i, (y0, lo, hi) in plan.regions.items():
            box = (int(lo.min()), y0, int(hi.max()) + 1, y0 + len(lo))
            for s in (step, step // 2, step // 4):
                s = max(2, s)
                coarse, error, rect = self._camera_map(projection, rotations, i, box, cx, cy,
                                                       s, layout)
                if error <= CHECK_FRACTION * tolerance_px:
                    break
            self.rects[i] = rect
            self.worst_px = max(self.worst_px, error)
            ny, nx = coarse.shape[:2]
            fine = cv2.resize(coarse, (nx * s, ny * s), interpolation=cv2.INTER_LINEAR)
            ox, oy = box[0] - s // 2, box[1] - s // 2
            x0, x1, y1 = box[0], box[2], box[3]
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            rows = np.arange(y1 - y0, dtype=np.int32)
            edge = np.concatenate([np.stack([lo - x0, rows], axis=1),
                                   np.stack([hi - x0, rows], axis=1)[::-1]])
            cv2.fillPoly(mask, [edge.astype(np.int32)], 1)
            cv2.copyTo(fine[y0 - oy:y1 - oy, x0 - ox:x1 - ox], mask, self.map[y0:y1, x0:x1])
        self._fixed = cv2.convertMaps(self.map, cast(Any, None), cv2.CV_16SC2) \
            if int(cv2.__version__.split('.')[0]) < FIXED_POINT_BEFORE else None

    @staticmethod
    def _camera_map(projection: Any, rotations: np.ndarray, i: int, box: Rect, cx: float,
                    cy: float, step: int, layout: Any) -> Tuple[np.ndarray, float, Rect]:
        """
        Return camera ``i``'s coarse map over ``box`` (mosaic pixels), its error and reach.

        Nodes at spacing ``step``; a node the lens cannot take (behind the camera, past
        its validity limit) or one mapped beyond the gap around the camera's image holds
        :data:`FAR`: every pixel of its cells then lands outside the mosaic (black), never
        on a neighbour's image.
        """
        x0, y0, x1, y1 = box
        nx = -(-(x1 - x0 + step) // step)
        ny = -(-(y1 - y0 + step) // step)
        # node k at box pixel k s - 1/2: the resize's sample position of node k is fine
        # pixel (k + 1/2) s - 1/2, the box starting at fine pixel s/2; the cells' centres
        # are evaluated too, to bound the bilinear interpolation's error
        us = (np.arange(nx) * step - 0.5 + x0 - cx).astype(np.float32)
        vs = (np.arange(ny) * step - 0.5 + y0 - cy).astype(np.float32)
        nodes, centres = nx * ny, (nx - 1) * (ny - 1)
        rays = np.empty((3, nodes + centres), np.float32)
        rays[0, :nodes].reshape(ny, nx)[:] = us
        rays[1, :nodes].reshape(ny, nx)[:] = vs[:, None]
        rays[0, nodes:].reshape(ny - 1, nx - 1)[:] = us[:-1] + 0.5 * step
        rays[1, nodes:].reshape(ny - 1, nx - 1)[:] = vs[:-1, None] + 0.5 * step
        rays[2] = 1.0
        _, px, py, side = projection._evaluate_soa(rays, rotations, only=i)
        bad = (side & 16) != 0
        b = bad[:nodes].reshape(ny, nx)
        good = ~(b[:-1, :-1] | b[1:, :-1] | b[:-1, 1:] | b[1:, 1:] |
                 bad[nodes:].reshape(ny - 1, nx - 1))
        error = 0.0
        for q in (px, py):  # the bilinear value at a cell's centre against the exact one
            c = q[:nodes].reshape(ny, nx)
            e = np.abs(0.25 * (c[:-1, :-1] + c[1:, :-1] + c[:-1, 1:] + c[1:, 1:])
                       - q[nodes:].reshape(ny - 1, nx - 1))
            error = max(error, float(e[good].max(initial=0.0)))
        coarse = np.empty((ny, nx, 2), np.float32)
        coarse[..., 0] = px[:nodes].reshape(ny, nx)
        coarse[..., 1] = py[:nodes].reshape(ny, nx)
        w, h = projection.rig.cameras[i].width, projection.rig.cameras[i].height
        ok = ~b
        if ok.any():  # the camera pixels the map can reach, with the bilinear taps
            xs, ys = coarse[..., 0][ok], coarse[..., 1][ok]
            rect = (min(w, max(0, int(np.floor(xs.min())))),
                    min(h, max(0, int(np.floor(ys.min())))),
                    max(0, min(w, int(np.floor(xs.max())) + 2)),
                    max(0, min(h, int(np.floor(ys.max())) + 2)))
        else:
            rect = (0, 0, 0, 0)
        # beyond the gap (less a tap) a pixel would read a neighbour's image: such a
        # node is far out; the pixels of its cells lie beyond the frame by more than the
        # bilinear taps reach (a cell spanning fewer camera pixels than the gap), black
        # in the camera's own image as well
        reach = layout.gap - 2.0
        beyond = (coarse[..., 0] < -reach) | (coarse[..., 0] > w - 1 + reach) | \
            (coarse[..., 1] < -reach) | (coarse[..., 1] > h - 1 + reach)
        coarse += np.asarray(layout.offsets[i], np.float32)
        coarse[b | beyond] = FAR
        return coarse, error, rect

    def render(self, sources: CameraSources, mosaic: np.ndarray, version: Any,
               out: np.ndarray, canvas: np.ndarray, scratch: np.ndarray) -> None:
        """Fill ``out`` from the cameras' images by one remap (``canvas`` as the warp's)."""
        import cv2

        for i, rect in self.rects.items():
            sources.get(mosaic, i, rect, version)
        if self._fixed is not None:
            m1, m2 = self._fixed
        else:
            m1, m2 = self.map, cast(Any, None)
        cv2.remap(sources.image(mosaic), m1, m2, cv2.INTER_LINEAR, dst=canvas,
                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if canvas is not out:
            cv2.cvtColor(canvas, cv2.COLOR_BGRA2BGR, dst=out)
